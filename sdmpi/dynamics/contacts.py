"""Frictional contacts with a critical-load repulsion: the shear-thickening model of
Seto, Mari, Morris & Denn, Phys. Rev. Lett. 111, 218301 (2013) and Mari, Seto, Morris &
Denn, J. Rheol. 58, 1693 (2014), on top of SD's lubrication (minimum-gap rule); the
forces of interparticle.kind = "frictional" (`frictional`, registered in
`sdmpi.registry.FORCES`). The model, its units and its time-step limit: docs/physics.md,
"Frictional contact".

Pair i, j with radii a_i, a_j, n the unit vector from i to j, h = |x_j - x_i| - a_i - a_j
the surface gap (negative = overlap = contact). Forces on j (those on i are opposite):

* repulsion (`forces.CriticalLoadRepulsion`, a `forces.PairForce` on every lubrication
  pair): F_R = F_R0 exp(-h/lambda) n for h > 0, F_R0 n for h <= 0;
* normal spring (h < 0): F_n = k_n |h| n;
* tangential spring (h < 0): F_t = -k_t xi, the stretch xi integrated from the sliding
  velocity of j's contact point relative to i's,
      d xi/dt = u_s = (I - n n) [U_j - U_i - (l_i Omega_i + l_j Omega_j) x n]
  (U, Omega total rigid-body velocities), kept tangent (turned into the plane normal to
  the current n, its length kept) and reset to 0 when the pair separates;
* Coulomb friction |F_t| <= mu |F_n|: where k_t |xi| > mu k_n |h| the stretch is scaled
  back to mu k_n |h| / k_t (the contact slides);
* torques at the contact point: T_i = l_i n x (k_t xi), T_j = l_j n x (k_t xi), lever arms
  l = a r / (a_i + a_j) (r the centre distance), so that l_i + l_j = r and the pair's
  forces and torques carry no net angular momentum.

Stress: that of every interparticle force, -(1/V) sum (x F + R_SU R_FU^-1 (F, T)), the
virial summed over pairs as dx (F on j), dx = x_j - x_i.

History (`FrictionalContacts`, the force's state): per particle at most ``max_contacts``
partners of larger index (partner -1 = empty slot) with their stretch as seen from the
smaller index, fixed-shape arrays for the checkpoints; stretches are updated at the end of
each step (`advance`, after the velocities are known) and turned tangent at the next.

Units: strengths in the job's force unit multiplied by FORCE_UNIT = 6 pi into Stokes
units; lengths in a, times in t_D, forces in eta_m a^2/t_D, velocities in a/t_D.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numba
import numpy as np

from .component import SampleFields, StateFields
from .forces import FORCE_UNIT, CriticalLoadRepulsion, Force, ForceSetting, ForceTerms, PairForce

if TYPE_CHECKING:
    from ..hydro.lubrication import PairList

#: the normal relative mobility of touching unit spheres at minimum gap h_min is about
#: SQUEEZE x h_min (job units; leading lubrication term, dh/dt = 2 F h / (3 pi) in Stokes units)
SQUEEZE = 4.0


def sliding_mobility(min_gap: float) -> float:
    """Sliding velocity of the contact points of two touching unit spheres at gap min_gap
    per unit tangential force pair with its torques (job units): 1/(0.245 + 0.165
    ln(1/min_gap)), a fit to `solve_mobility` (0.568, 0.726, 1.002 at 1e-4, 1e-3, 1e-2;
    within 1% for 1e-4..3e-2, 3% at 0.1).

    Args:
        min_gap: the lubrication's minimum gap h_min, in a.

    Returns:
        The sliding mobility, in 1/(eta_m a).
    """
    return 1.0 / (0.245 + 0.165 * math.log(1.0 / min_gap))


@dataclass(frozen=True)
class ContactLaw:
    """Contact springs and friction in Stokes units: k_n, k_t (force / a), mu."""

    mu: float
    k_n: float
    k_t: float

    def springs(
        self, n: np.ndarray, gap: np.ndarray, stretch: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contact forces on j (P, 3) for contacting pairs with unit vectors n (P, 3) from
        i to j, gaps < 0 (P,) and tangential stretches (P, 3) already tangent. Returns
        (forces on j, the Coulomb-limited stretch, sliding (P,) bool).

        Args:
            n: unit vectors from i to j, shape (P, 3).
            gap: surface gaps, shape (P,), negative, in a.
            stretch: tangential stretches, shape (P, 3), in a.

        Returns:
            (forces on j (P, 3) in eta_m a^2/t_D, stretches (P, 3) in a, sliding (P,) bool).
        """
        normal = self.k_n * -gap
        length = np.linalg.norm(stretch, axis=1)
        limit = self.mu * normal / self.k_t
        sliding = length > limit
        scale = np.where(sliding, limit / np.where(sliding, length, 1.0), 1.0)
        stretch = stretch * scale[:, None]
        return normal[:, None] * n - self.k_t * stretch, stretch, sliding


def tangent(stretch: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Stretches (P, 3) turned into the planes normal to n (P, 3), lengths kept.

    Args:
        stretch: stretches, shape (P, 3), in a.
        n: unit normals, shape (P, 3).

    Returns:
        Tangent stretches, shape (P, 3), in a (zero where the stretch is along n).
    """
    t = stretch - np.sum(stretch * n, axis=1)[:, None] * n
    old, new = np.linalg.norm(stretch, axis=1), np.linalg.norm(t, axis=1)
    return t * np.where(new > 0, old / np.where(new > 0, new, 1.0), 0.0)[:, None]


def sliding_velocity(
    n: np.ndarray, arm_i: np.ndarray, arm_j: np.ndarray, v_i: np.ndarray, v_j: np.ndarray
) -> np.ndarray:
    """u_s (P, 3) of j's contact point relative to i's, tangential part: lever arms l_i,
    l_j (P,), v_i, v_j (P, 6) total (U, Omega) of i and of j's image.

    Args:
        n: unit vectors from i to j, shape (P, 3).
        arm_i: lever arms of i, shape (P,), in a.
        arm_j: lever arms of j, shape (P,), in a.
        v_i: (U, Omega) of i, shape (P, 6), in a/t_D and 1/t_D.
        v_j: (U, Omega) of j's image, shape (P, 6), same units.

    Returns:
        Tangential sliding velocities, shape (P, 3), in a/t_D.
    """
    rel = v_j[:, :3] - v_i[:, :3] - np.cross(arm_i[:, None] * v_i[:, 3:] + arm_j[:, None] * v_j[:, 3:], n)
    return rel - np.sum(rel * n, axis=1)[:, None] * n


@numba.njit(cache=True)
def _lookup(lo, hi, partner, stretch, out):
    """out[p] = the stored stretch of pair (lo[p], hi[p]), 0 if it is a new contact."""
    for p in range(lo.shape[0]):
        out[p, :] = 0.0
        for k in range(partner.shape[1]):
            if partner[lo[p], k] == hi[p]:
                out[p, :] = stretch[lo[p], k, :]
                break


@numba.njit(cache=True)
def _store(lo, hi, xi, partner, stretch):
    """Fill the (cleared) tables with the contacts. Returns (-1, 0), or (p, 1) if pair p
    found its row full, (p, 2) if its row already holds the partner (two images)."""
    count = np.zeros(partner.shape[0], dtype=np.int64)
    for p in range(lo.shape[0]):
        row = lo[p]
        for k in range(count[row]):
            if partner[row, k] == hi[p]:
                return p, 2
        if count[row] == partner.shape[1]:
            return p, 1
        partner[row, count[row]] = hi[p]
        stretch[row, count[row], :] = xi[p, :]
        count[row] += 1
    return -1, 0


@dataclass
class ContactForces:
    """Contact forces (N, 3), torques (N, 3), virial sum dx F_on_j (3, 3), counts."""

    forces: np.ndarray
    torques: np.ndarray
    virial: np.ndarray
    n_contacts: int
    n_sliding: int


class FrictionalContacts(Force):
    """The contact springs of one realisation and their history (module docstring): a
    `Force` whose ``terms`` are taken at the start of a step, then ``advance`` with the
    step's velocities; its state is the history, its sample stress_contact, n_contacts and
    n_sliding."""

    def __init__(self, law: ContactLaw, radii: np.ndarray, max_contacts: int):
        self.law, self.radii = law, radii
        self.partners = np.full((len(radii), max_contacts), -1, dtype=np.int64)
        self.stretch = np.zeros((len(radii), max_contacts, 3))
        self._contacts = None

    def terms(self, pairs: PairList) -> ForceTerms:
        contact = self.forces(pairs)
        return ForceTerms(np.hstack([contact.forces, contact.torques]), contact.virial,
                          {"n_contacts": contact.n_contacts, "n_sliding": contact.n_sliding})

    def sample_fields(self, stress_unit: str) -> SampleFields:
        return {"stress_contact": ((6,), "f8", stress_unit, "contact springs' part of stress_interparticle"),
                "n_contacts": ((), "i4", "1", "touching pairs (gap < 0)"),
                "n_sliding": ((), "i4", "1", "touching pairs at the Coulomb limit")}

    def sample(self, terms: ForceTerms, stress: Callable[[ForceTerms], np.ndarray]) -> dict[str, Any]:
        return {"stress_contact": stress(terms), **terms.counts}

    def state_fields(self) -> StateFields:
        return {"contact_partners": (self.partners.shape, "i8"), "contact_stretch": (self.stretch.shape, "f8")}

    def get_state(self) -> dict[str, np.ndarray]:
        return {"contact_partners": self.partners.copy(), "contact_stretch": self.stretch.copy()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.partners[:] = state["contact_partners"]
        self.stretch[:] = state["contact_stretch"]

    def forces(self, pairs: PairList) -> ContactForces:
        """Contact forces of the pairs with gap < 0 (a PairList: true gaps, dx = x_j +
        shift - x_i, possibly stretched to the minimum gap; only its direction is used).

        Args:
            pairs: the step's lubrication pair list.

        Returns:
            The `ContactForces`: forces and torques (N, 3) in eta_m a^2/t_D and
            eta_m a^3/t_D, virial (3, 3) in eta_m a^3/t_D, contact and sliding counts.
        """
        n_particles, radii = len(self.partners), self.radii
        touching = np.flatnonzero(pairs.gap < 0)
        i, j = pairs.i[touching], pairs.j[touching]
        n = pairs.dx[touching] / np.linalg.norm(pairs.dx[touching], axis=1)[:, None]
        gap = pairs.gap[touching]
        dist = gap + pairs.radii_sum[touching]
        scale = dist / pairs.radii_sum[touching]
        arm_i, arm_j = radii[i] * scale, radii[j] * scale
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        xi = np.empty((len(touching), 3))
        _lookup(lo, hi, self.partners, self.stretch, xi)
        # a stretch stored as seen from the smaller index: from j's side it is reversed
        xi = tangent(np.where((i == lo)[:, None], xi, -xi), n)
        f_on_j, xi, sliding = self.law.springs(n, gap, xi)
        f_t = self.law.k_t * xi  # tangential force on i
        forces, torques = np.zeros((n_particles, 3)), np.zeros((n_particles, 3))
        np.add.at(forces, j, f_on_j)
        np.add.at(forces, i, -f_on_j)
        np.add.at(torques, i, arm_i[:, None] * np.cross(n, f_t))
        np.add.at(torques, j, arm_j[:, None] * np.cross(n, f_t))
        dx = dist[:, None] * n
        self._contacts = (i, j, lo, hi, n, dx, arm_i, arm_j, xi)
        return ContactForces(forces, torques, dx.T @ f_on_j, len(touching), int(sliding.sum()))

    def advance(self, velocities: np.ndarray, rate: float, dt: float) -> None:
        """Integrate the stretches of the contacts found by ``forces`` over dt with the
        step's velocities (N, 6) relative to the imposed simple shear u = rate y e_x
        (Omega_inf = -rate/2 e_z), and store them as the history.

        Args:
            velocities: (U, Omega) relative to the imposed flow, shape (N, 6), in a/t_D
                and 1/t_D.
            rate: the step's shear rate (1/t_D).
            dt: the step's duration (t_D).

        Raises:
            RuntimeError: a particle has more than max_contacts contacts, or a pair
                touches through two periodic images.
        """
        i, j, lo, hi, n, dx, arm_i, arm_j, xi = self._contacts
        spin = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -0.5 * rate])
        v_i, v_j = velocities[i] + spin, velocities[j] + spin
        v_j[:, 0] += rate * dx[:, 1]  # j's image relative to i in the imposed flow
        xi = xi + dt * sliding_velocity(n, arm_i, arm_j, v_i, v_j)
        xi = np.where((i == lo)[:, None], xi, -xi)
        self.partners[:] = -1
        self.stretch[:] = 0.0
        bad, why = _store(lo, hi, xi, self.partners, self.stretch)
        if why == 1:
            raise RuntimeError(f"particle {lo[bad]} has more than interparticle.max_contacts = "
                               f"{self.partners.shape[1]} contacts with larger-numbered "
                               "particles; raise interparticle.max_contacts")
        if why == 2:
            raise RuntimeError(f"particles {lo[bad]} and {hi[bad]} touch through two periodic "
                               "images: the box is too small for contact history")


def frictional(
    setting: ForceSetting, *, mu: float, k_n: float, k_t: float, f_r0: float, repulsion_length: float,
    max_contacts: int
) -> list[Force]:
    """interparticle.kind = "frictional": the critical-load repulsion on every pair, then the
    contact springs (a fresh history), strengths in the job's force unit.

    Args:
        setting: the realisation's spheres and cut-off.
        mu: Coulomb friction coefficient.
        k_n: normal stiffness (force unit / a).
        k_t: tangential stiffness (force unit / a).
        f_r0: the repulsion at contact (force unit).
        repulsion_length: its decay length (a).
        max_contacts: contacts stored per particle.

    Returns:
        [the repulsion's `PairForce`, the `FrictionalContacts`], in that order.
    """
    repulsion = PairForce(CriticalLoadRepulsion(FORCE_UNIT * f_r0, repulsion_length), setting.radii)
    law = ContactLaw(mu, FORCE_UNIT * k_n, FORCE_UNIT * k_t)
    return [repulsion, FrictionalContacts(law, setting.radii, max_contacts)]
