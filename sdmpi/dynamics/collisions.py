"""Hard-sphere collisions: the potential-free overlap correction and the stress it implies.

A pair is in contact when its surface gap is below the lubrication's floor ``min_gap``
(mean radii; below it the lubrication is that of the floor, so the model cannot tell such
a pair from touching spheres): the hard-sphere surface of the correction is the gap
min_gap. After each time step the pairs in contact, overlapping pairs included, are moved
apart symmetrically along their lines of centres, by one of two rules
(``hydrodynamics.collisions``), and the sweep is repeated while a correction brings other
pairs into contact:

* ``separate`` (Bossis & Brady, J. Chem. Phys. 80, 5141 (1984); Heyes & Melrose, J.
  Non-Newtonian Fluid Mech. 46, 1 (1993)): the pair is placed at a gap of SEPARATION x
  min_gap, twice the floor, so that a pair just separated still sees the gradient of its
  lubrication (`models`, the rfd drift). The default of the stokesian model, whose
  lubrication keeps pairs from contact in continuous time.
* ``reflect``: the step is split into its deterministic part (imposed flow, interparticle
  forces), after which pairs in contact are separated as above, and its Brownian part,
  after which they are reflected at the hard-sphere surface, gap -> 2 min_gap - gap. For a
  deterministic approach the contact force is the one that stops the normal motion, which
  the placement realises; for diffusion of a pair's separation x >= 0 against a hard wall
  the reflected Gaussian p(y) = G(y - x) + G(y + x) is the exact transition density (the
  method of images; Smoluchowski 1917; Strating, Phys. Rev. E 59, 2175 (1999), treats the
  Brownian displacement as a path and resolves its collisions elastically), so the pair
  density stays flat up to contact. Placing diffusing pairs at contact instead deposits
  them there and depletes the gaps beyond (Heyes & Melrose's algorithm converges only like
  dt^1/2). The default of the far-field and free-draining models, whose relative mobility
  stays finite at contact.

Collision stress (Heyes & Melrose 1993; Strating 1999; Foss & Brady, J. Fluid Mech. 407,
167 (2000)). A correction that changes a pair's separation by s along its unit line of
centres e within a step dt is the displacement that a pair force f e on j (and -f e on i)
acting over dt would produce through the pair's relative mobility
G = e.(M_jj + M_ii - M_ij - M_ji).e:

    f = s / (G dt),

(free draining: G = 1/(6 pi a_i) + 1/(6 pi a_j), the hard-sphere impulse of Brownian
dynamics). Its stress is that of any interparticle force (Batchelor 1977; `realisation`):

    Sigma_C = -(1/V) [sum_pairs r f e + sum_i R_SU R_FU^-1 F_C],

r the pair's separation after the correction (at contact), F_C the collision forces on the
particles. Free draining, this is the hard-sphere collision stress whose trace gives the
contact value of the osmotic pressure, Pi - n kT = -(1/3) tr Sigma_C = n kT 4 phi g(2).
With reflection it holds at any dt for a flat contact: pairs of density rho per unit
separation at contact, each diffusing with D = kT G over a step of variance
sigma^2 = 2 D dt, are reflected by s = 2 max(0, -(x + sigma z)), whose sum per step is
2 rho int_0^inf <max(0, -x - sigma z)> dx = rho sigma^2/2 = rho D dt, so sum f = rho kT:
the contact theorem. With placement it converges from below like dt^1/2 (Strating 1999).
With lubrication, pairs never touch in continuous time, and Sigma_C measures the time
step's discretisation error (it vanishes as dt and min_gap go to 0).
"""

from dataclasses import dataclass

import numpy as np

from ..hydro.lubrication import close_pairs

#: separated pairs are left at this many times hydrodynamics.min_gap
SEPARATION = 2.0
#: hydrodynamics.collisions choices
RULES = ("separate", "reflect")


def default_rule(model):
    """The collision rule of a hydrodynamic model when hydrodynamics.collisions is absent
    (module docstring): separate with lubrication, reflect without."""
    return "separate" if model == "stokesian" else "reflect"


@dataclass
class Collisions:
    """The pairs a correction moved: indices i, j (N_c,), unit lines of centres e (N_c, 3),
    separations r after the correction (N_c,), separation changes s (N_c,), and the number
    of pairs in contact and the smallest gap found before any correction."""

    i: np.ndarray
    j: np.ndarray
    e: np.ndarray
    r: np.ndarray
    s: np.ndarray
    n_overlaps: int
    deepest: float

    @classmethod
    def joined(cls, first, second):
        """The pairs of two corrections of one step, their contacts counted together and
        the deeper of their smallest gaps."""
        arrays = (np.concatenate([getattr(first, k), getattr(second, k)]) for k in "ijers")
        return cls(*arrays, first.n_overlaps + second.n_overlaps, min(first.deepest, second.deepest))

    @classmethod
    def none(cls, n_overlaps=0, deepest=np.inf):
        """No corrected pair (overlaps counted but kept, or none found)."""
        empty = np.zeros(0)
        return cls(empty.astype(np.int64), empty.astype(np.int64), np.zeros((0, 3)), empty, empty,
                   n_overlaps, deepest)

    def forces(self, mobility, dt, n):
        """Collision forces (N, 6) on the particles and their virial sum r f e e^T (3, 3);
        mobility(i, j, e) -> each pair's relative mobility G."""
        forces, virial = np.zeros((n, 6)), np.zeros((3, 3))
        if len(self.i) == 0:
            return forces, virial
        f = self.s / (mobility(self.i, self.j, self.e) * dt)
        on_j = f[:, None] * self.e
        np.add.at(forces[:, :3], self.j, on_j)
        np.add.at(forces[:, :3], self.i, -on_j)
        virial = (self.r[:, None] * self.e).T @ on_j
        return forces, virial


def remove_overlaps(positions, radii, pairs, min_gap, reflect=False, sweeps=100):
    """Potential-free correction (module docstring) of the pairs in contact of one pair
    list, placed at SEPARATION x min_gap (reflect: reflected at the gap min_gap), repeated
    (up to `sweeps` times) while a correction creates new contacts within the list.
    Returns the corrected positions and each listed pair's total separation change along
    its line of centres (0 for the pairs never moved)."""
    pos = positions.copy()
    moved = np.zeros(len(pairs.i))
    for _ in range(sweeps):
        dx = pos[pairs.j] + pairs.shift - pos[pairs.i]
        dist = np.linalg.norm(dx, axis=1)
        asum = radii[pairs.i] + radii[pairs.j]
        surface = asum * (1 + 0.5 * min_gap)
        target = 2 * surface - dist if reflect else asum * (1 + 0.5 * SEPARATION * min_gap)
        bad = dist < surface
        if not bad.any():
            break
        push = 0.5 * ((target - dist) / dist)[bad, None] * dx[bad]
        np.add.at(pos, pairs.j[bad], push)
        np.add.at(pos, pairs.i[bad], -push)
        moved[bad] += (target - dist)[bad]
    return pos, moved


def separate(positions, radii, lattice, min_gap, reflect=False, rounds=10):
    """Pairs in contact (closer than min_gap mean radii; periodic images included) found
    and corrected (placed, or reflected: `remove_overlaps`), with a new pair search after
    each correction while it creates new contacts. Returns the corrected positions and
    their `Collisions`."""
    parts, found, deepest = [], 0, np.inf
    for _ in range(rounds):
        pairs = close_pairs(positions, radii, lattice, cutoff=min_gap)
        if len(pairs.i) == 0:
            break
        if found == 0:
            found, deepest = len(pairs.i), pairs.min_gap
        positions, moved = remove_overlaps(positions, radii, pairs, min_gap, reflect)
        hit = moved > 0
        dx = positions[pairs.j[hit]] + pairs.shift[hit] - positions[pairs.i[hit]]
        r = np.linalg.norm(dx, axis=1)
        parts.append((pairs.i[hit], pairs.j[hit], dx / r[:, None], r, moved[hit]))
    if not parts:
        return positions, Collisions.none()
    i, j, e, r, s = (np.concatenate(c) for c in zip(*parts))
    return positions, Collisions(i, j, e, r, s, found, deepest)
