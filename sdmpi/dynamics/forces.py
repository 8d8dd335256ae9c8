"""Interparticle forces between sphere pairs, and the potential-free overlap correction.

Pair forces act along the line of centres; a `PairForce` gives the magnitude F(h) of the
repulsion (positive pushes apart) at surface gap h. Totals are summed over the pair list
of the hydrodynamics (periodic images included), so the force range must lie within the
lubrication cut-off. Units: forces in kT/a for Brownian jobs (kT = 6 pi in sdmpi's
reduced units), in 6 pi eta a^2 gamma_dot otherwise.
"""

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Repulsion:
    """F(h) = F0 tau exp(-tau h) / (1 + exp(-tau h)) (seed 001, Brady & Bossis 1985):
    an electrostatic-like repulsion of range 1/tau; F(0) = F0 tau / 2, F -> F0 tau e^{-tau h}
    far away, and F(h) = -dU/dh with U = F0 ln(1 + exp(-tau h))."""

    f0: float
    tau: float

    def magnitude(self, gap):
        e = np.exp(-self.tau * np.maximum(gap, 0.0))
        return self.f0 * self.tau * e / (1.0 + e)

    def potential(self, gap):
        return self.f0 * np.log1p(np.exp(-self.tau * np.maximum(gap, 0.0)))

    @property
    def reach(self):
        """Gap beyond which F < 1e-12 F0 tau."""
        return 12 * math.log(10) / self.tau


def pair_forces(force_law, pairs, n):
    """Forces (N, 3) on the particles and the virial sum_pairs dx F_ij (3, 3) for the
    close pairs (a PairList: dx = x_j - x_i, true gaps). The force on i is
    -F(h) dx/|dx| (repulsion pushes i away from j), and +F(h) dx/|dx| on j."""
    forces = np.zeros((n, 3))
    virial = np.zeros((3, 3))
    if force_law is None or len(pairs.i) == 0:
        return forces, virial
    unit = pairs.dx / np.linalg.norm(pairs.dx, axis=1)[:, None]
    f_on_j = force_law.magnitude(pairs.gap)[:, None] * unit
    np.add.at(forces, pairs.j, f_on_j)
    np.add.at(forces, pairs.i, -f_on_j)
    # sum over particles of x F = sum over pairs of (x_j - x_i) F_on_j (true separations)
    virial = (pairs.distance[:, None] * unit).T @ f_on_j
    return forces, virial


def remove_overlaps(positions, radii, pairs, min_gap, sweeps=100):
    """Potential-free overlap correction (Bossis & Brady 1984; Heyes & Melrose 1993):
    each overlapping pair of the list is moved apart symmetrically along its line of
    centres to a gap of min_gap mean radii. Repeated (up to `sweeps` times) while a
    correction creates new overlaps within the list. Returns corrected positions."""
    pos = positions.copy()
    for _ in range(sweeps):
        dx = pos[pairs.j] + pairs.shift - pos[pairs.i]
        dist = np.linalg.norm(dx, axis=1)
        asum = radii[pairs.i] + radii[pairs.j]
        target = asum * (1 + 0.5 * min_gap)
        bad = dist < asum
        if not bad.any():
            break
        push = 0.5 * ((target - dist) / dist)[bad, None] * dx[bad]
        np.add.at(pos, pairs.j[bad], push)
        np.add.at(pos, pairs.i[bad], -push)
    return pos
