"""Hard-sphere collisions: the potential-free overlap correction and the stress it implies.

A pair is in contact when its surface gap is below the lubrication's floor ``min_gap``
(mean radii): the hard-sphere surface of the correction is the gap min_gap. After each
time step the pairs in contact, overlapping pairs included, are moved apart along their
lines of centres by one of two rules (``hydrodynamics.collisions``), and the correction is
repeated while it brings other pairs into contact:

* ``separate`` (Bossis & Brady, J. Chem. Phys. 80, 5141 (1984); Heyes & Melrose, J.
  Non-Newtonian Fluid Mech. 46, 1 (1993)): the two spheres are moved apart symmetrically
  to a gap of SEPARATION x min_gap. The default of the stokesian model.
* ``reflect``: pairs in contact after the step's deterministic part are separated to
  SEPARATION x min_gap, and after its Brownian part reflected at the hard-sphere surface,
  gap -> 2 min_gap - gap (Strating, Phys. Rev. E 59, 2175 (1999)). Both corrections are
  contact impulses acting through the step's mobility M = R_FU^-1 (`through_mobility`): an
  impulse lambda_p along the unit pair force f_p (e_p on j, -e_p on i) moves the particles
  by lambda_p M f_p, lambda_p = s_p/G_p, G_p = f_p.M.f_p, for a separation change s_p;
  pairs in contact at once each get their own impulse, the sweep repeated while pairs are
  left in contact. The default of the far-field and free-draining models.

Why the reflection keeps the equilibrium and why it acts through M (oblique reflection,
Lions & Sznitman, Comm. Pure Appl. Math. 37, 511 (1984)), the contact theorem and the
measurements: docs/physics.md, "Hard-sphere collisions".

Collision stress (Heyes & Melrose 1993; Strating 1999; Foss & Brady, J. Fluid Mech. 407,
167 (2000)): a correction that changes a pair's separation by s along e within dt is the
displacement of the pair force f = s/(G dt) (G = e.(M_jj + M_ii - M_ij - M_ji).e; through
the mobility f = lambda/dt, summed over the sweeps), whose stress is that of any
interparticle force (Batchelor 1977; `realisation`),

    Sigma_C = -(1/V) [sum_pairs r f e + sum_i R_SU R_FU^-1 F_C],

r the pair's separation after the correction, F_C the collision forces on the particles.

Units: lengths in particle radii a, times in t_D, forces in eta_m a^2/t_D, mobilities in
1/(eta_m a).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..hydro.lubrication import close_pairs
from ..registry import HYDRODYNAMIC_MODELS

if TYPE_CHECKING:
    from ..hydro.geometry import Lattice
    from ..hydro.lubrication import PairList

#: separated pairs are left at this many times hydrodynamics.min_gap
SEPARATION = 2.0
#: hydrodynamics.collisions choices
RULES = ("separate", "reflect")


def default_rule(model: str) -> str:
    """The collision rule of the hydrodynamic model named ``model`` when
    hydrodynamics.collisions is absent (module docstring): separate for a model with
    lubrication (`sdmpi.registry.ModelSpec`), reflect without.

    Args:
        model: a registered hydrodynamic model name (hydrodynamics.model).

    Returns:
        "separate" or "reflect" (one of RULES).
    """
    return "separate" if HYDRODYNAMIC_MODELS[model].lubrication else "reflect"


@dataclass
class Collisions:
    """The pairs a correction moved: indices i, j (N_c,), unit lines of centres e (N_c, 3),
    separations r after the correction (N_c,), separation changes s (N_c,), the number
    of pairs in contact and the smallest gap found before any correction, and the impulses
    lambda (N_c,) of a correction through the mobility (NaN where the pairs were moved
    apart symmetrically: the impulse is then s/G, `forces`)."""

    i: np.ndarray
    j: np.ndarray
    e: np.ndarray
    r: np.ndarray
    s: np.ndarray
    n_overlaps: int
    deepest: float
    impulse: np.ndarray = None

    def __post_init__(self):
        if self.impulse is None:
            self.impulse = np.full(len(self.i), np.nan)

    @classmethod
    def joined(cls, first: Collisions, second: Collisions) -> Collisions:
        """The pairs of two corrections of one step, their contacts counted together and
        the deeper of their smallest gaps.

        Args:
            first: the first correction's pairs.
            second: the second correction's pairs.

        Returns:
            A new `Collisions` holding the pairs of both, first's before second's.
        """
        arrays = [np.concatenate([getattr(first, k), getattr(second, k)]) for k in "ijers"]
        return cls(*arrays, first.n_overlaps + second.n_overlaps, min(first.deepest, second.deepest),
                   np.concatenate([first.impulse, second.impulse]))

    @classmethod
    def none(cls, n_overlaps: int = 0, deepest: float = np.inf) -> Collisions:
        """No corrected pair (overlaps counted but kept, or none found).

        Args:
            n_overlaps: number of pairs found in contact.
            deepest: smallest gap found (mean radii), inf for none.

        Returns:
            A `Collisions` with zero pairs.
        """
        empty = np.zeros(0)
        return cls(empty.astype(np.int64), empty.astype(np.int64), np.zeros((0, 3)), empty, empty,
                   n_overlaps, deepest)

    def forces(
        self,
        mobility: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
        dt: float,
        n: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Collision forces (N, 6) on the particles and their virial sum r f e e^T (3, 3):
        f = lambda/dt, or s/(G dt) where no impulse was recorded; mobility(i, j, e) -> each
        pair's relative mobility G.

        Args:
            mobility: mobility(i (P,), j (P,), e (P, 3)) -> G (P,), relative mobilities
                along the lines of centres (1/(eta_m a)).
            dt: the step's duration (t_D).
            n: number of particles N.

        Returns:
            (forces, virial): forces (N, 6) in eta_m a^2/t_D (columns 0-2; the torque
            columns zero), virial (3, 3) in eta_m a^3/t_D.
        """
        forces, virial = np.zeros((n, 6)), np.zeros((3, 3))
        if len(self.i) == 0:
            return forces, virial
        impulse = self.impulse.copy()
        symmetric = np.isnan(impulse)
        if symmetric.any():
            impulse[symmetric] = self.s[symmetric] / mobility(self.i[symmetric], self.j[symmetric],
                                                              self.e[symmetric])
        f = impulse / dt
        on_j = f[:, None] * self.e
        np.add.at(forces[:, :3], self.j, on_j)
        np.add.at(forces[:, :3], self.i, -on_j)
        virial = (self.r[:, None] * self.e).T @ on_j
        return forces, virial


def _contacts(pos, radii, pairs, min_gap, reflect):
    """For the listed pairs: separation vectors dx (P, 3) (j's image minus i), distances,
    the hard-sphere surface distance (gap min_gap, mean radii) and the distance a
    correction moves them to (reflected at the surface, or SEPARATION x min_gap)."""
    dx = pos[pairs.j] + pairs.shift - pos[pairs.i]
    dist = np.linalg.norm(dx, axis=1)
    asum = radii[pairs.i] + radii[pairs.j]
    surface = asum * (1 + 0.5 * min_gap)
    target = 2 * surface - dist if reflect else asum * (1 + 0.5 * SEPARATION * min_gap)
    return dx, dist, surface, target


def remove_overlaps(
    positions: np.ndarray,
    radii: np.ndarray,
    pairs: PairList,
    min_gap: float,
    reflect: bool = False,
    sweeps: int = 100,
) -> tuple[np.ndarray, np.ndarray]:
    """Potential-free correction (module docstring) of the pairs in contact of one pair
    list, placed at SEPARATION x min_gap (reflect: reflected at the gap min_gap), repeated
    (up to `sweeps` times) while a correction creates new contacts within the list.
    Returns the corrected positions and each listed pair's total separation change along
    its line of centres (0 for the pairs never moved).

    Args:
        positions: particle centres, shape (N, 3), in a (not modified).
        radii: particle radii, shape (N,), in a.
        pairs: the pair list to correct (`close_pairs`), P pairs.
        min_gap: the hard-sphere surface gap, in mean radii.
        reflect: reflect at the surface instead of placing at SEPARATION x min_gap.
        sweeps: maximum number of correction sweeps.

    Returns:
        (positions (N, 3) in a, separation changes (P,) in a).
    """
    pos = positions.copy()
    moved = np.zeros(len(pairs.i))
    for _ in range(sweeps):
        dx, dist, surface, target = _contacts(pos, radii, pairs, min_gap, reflect)
        bad = dist < surface
        if not bad.any():
            break
        push = 0.5 * ((target - dist) / dist)[bad, None] * dx[bad]
        np.add.at(pos, pairs.j[bad], push)
        np.add.at(pos, pairs.i[bad], -push)
        moved[bad] += (target - dist)[bad]
    return pos, moved


def through_mobility(
    positions: np.ndarray,
    radii: np.ndarray,
    pairs: PairList,
    min_gap: float,
    mobility: Callable[[np.ndarray], np.ndarray],
    reflect: bool = False,
    sweeps: int = 100,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Correction (module docstring) of the pairs in contact of one pair list through the
    mobility: each is moved apart by s_p along its line of centres, to SEPARATION x min_gap
    (mean radii), or reflected at the gap min_gap (reflect: s_p twice its depth below it),
    by its own impulse lambda_p = s_p/G_p along its unit pair force f_p (G_p = f_p.M.f_p),
    which moves the particles by lambda_p M f_p; the displacements of the pairs in contact
    at once are added, and the sweep is repeated (up to `sweeps` times) while pairs of the
    list are in contact, as `remove_overlaps` does for the symmetric move (which it equals
    for free draining of equal spheres). mobility(forces (N, 6)) -> velocities (N, 6),
    M = R_FU^-1 of the step. Returns the new positions and each listed pair's total
    separation change and impulse (0 for the pairs never moved).

    Args:
        positions: particle centres, shape (N, 3), in a (not modified).
        radii: particle radii, shape (N,), in a.
        pairs: the pair list to correct (`close_pairs`), P pairs.
        min_gap: the hard-sphere surface gap, in mean radii.
        mobility: forces (N, 6) -> velocities (N, 6), M of the step.
        reflect: reflect at the surface instead of placing at SEPARATION x min_gap.
        sweeps: maximum number of correction sweeps.

    Returns:
        (positions (N, 3) in a, separation changes (P,) in a, impulses (P,) in
        eta_m a^2).
    """
    n = len(positions)
    pos = positions.copy()
    moved, impulse = np.zeros(len(pairs.i)), np.zeros(len(pairs.i))
    force = np.zeros((n, 6))
    for _ in range(sweeps):
        dx, dist, surface, target = _contacts(pos, radii, pairs, min_gap, reflect)
        bad = np.flatnonzero(dist < surface)
        if len(bad) == 0:
            break
        displacement = np.zeros((n, 3))
        for p in bad:
            i, j, e = pairs.i[p], pairs.j[p], dx[p] / dist[p]
            force[i, :3], force[j, :3] = -e, e
            velocities = mobility(force)
            force[i, :3] = force[j, :3] = 0.0
            lam = (target[p] - dist[p]) / (e @ (velocities[j, :3] - velocities[i, :3]))
            displacement += lam * velocities[:, :3]
            moved[p] += target[p] - dist[p]
            impulse[p] += lam
        pos += displacement
    return pos, moved, impulse


def separate(
    positions: np.ndarray,
    radii: np.ndarray,
    lattice: Lattice,
    min_gap: float,
    reflect: bool = False,
    rounds: int = 10,
    mobility: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, Collisions]:
    """Pairs in contact (closer than min_gap mean radii; periodic images included) found
    and corrected (placed, or reflected), with a new pair search after each correction
    while it creates new contacts; mobility(forces (N, 6)) -> velocities (N, 6): the
    correction acts through it (`through_mobility`), else the two spheres of a pair are
    moved symmetrically (`remove_overlaps`). Returns the corrected positions and their
    `Collisions`.

    Args:
        positions: particle centres, shape (N, 3), in a.
        radii: particle radii, shape (N,), in a.
        lattice: the periodic (Lees-Edwards) lattice of the current strain.
        min_gap: the hard-sphere surface gap, in mean radii.
        reflect: reflect at the surface instead of placing at SEPARATION x min_gap.
        rounds: maximum number of pair searches.
        mobility: forces (N, 6) -> velocities (N, 6), or None for the symmetric move.

    Returns:
        (positions (N, 3) in a, the corrected pairs' `Collisions`).
    """
    parts, found, deepest = [], 0, np.inf
    for _ in range(rounds):
        pairs = close_pairs(positions, radii, lattice, cutoff=min_gap)
        if len(pairs.i) == 0:
            break
        if found == 0:
            found, deepest = len(pairs.i), pairs.min_gap
        if mobility is None:
            positions, moved = remove_overlaps(positions, radii, pairs, min_gap, reflect)
            impulse = np.full(len(moved), np.nan)
        else:
            positions, moved, impulse = through_mobility(positions, radii, pairs, min_gap, mobility, reflect)
        hit = moved > 0
        dx = positions[pairs.j[hit]] + pairs.shift[hit] - positions[pairs.i[hit]]
        r = np.linalg.norm(dx, axis=1)
        parts.append((pairs.i[hit], pairs.j[hit], dx / r[:, None], r, moved[hit], impulse[hit]))
    if not parts:
        return positions, Collisions.none()
    i, j, e, r, s, impulse = (np.concatenate(c) for c in zip(*parts))
    return positions, Collisions(i, j, e, r, s, found, deepest, impulse)
