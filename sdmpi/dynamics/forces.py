"""Interparticle forces between sphere pairs: the `Force` interface, pair force laws and
the forces of interparticle.kind (registered in `sdmpi.registry.FORCES`).

A `Force` acts on the pairs of each step (the hydrodynamic evaluation's pair list within
the lubrication cut-off, periodic images included), with its own sample fields and state;
the step sums a realisation's forces in order (`sdmpi.dynamics.realisation`). A
`PairForce` is the central force of a law (`PairLaw`): magnitude F(h) at surface gap h of
a pair of radii a_i, a_j along the line of centres, positive when repulsive, F = -dU/dh.
A force must vanish beyond the cut-off: the repulsion decays there (checked by the
loader), the van der Waals force and the double layer are shifted to vanish there.

Laws:

* `Repulsion` (Dratler & Schowalter, J. Fluid Mech. 325, 53 (1996), eq. 9):
  F = F0 tau e^(-tau h)/(1 + e^(-tau h)), U = F0 ln(1 + e^(-tau h)).
* `VanDerWaals` (Hamaker, Physica 4, 1058 (1937); Finke et al. 2020, eqs. 4-5), centre
  distance r = a_i + a_j + h:
      U(h) = -(A/6) [2 a_i a_j/(h (2a_i + 2a_j + h)) + 2 a_i a_j/((2a_i + h)(2a_j + h))
                     + ln(h (2a_i + 2a_j + h)/((2a_i + h)(2a_j + h)))],
      F(h) = -(32/3) A a_i^3 a_j^3 (a_i + a_j + h) / (h^2 (2a_i + 2a_j + h)^2
                                                      ((2a_i + h)(2a_j + h))^2),
  held at F(cap_gap) below ``cap_gap`` (U continued linearly).
* `DoubleLayer` (constant low surface potential, Derjaguin approximation; Hogg, Healy &
  Fuerstenau, Trans. Faraday Soc. 62, 1638 (1966)): U = psi^2 R ln(1 + e^(-h/lambda_D)),
  R = a_i a_j/(a_i + a_j).
* `CriticalLoadRepulsion` (Mari, Seto, Morris & Denn, J. Rheol. 58 (2014)): F0 exp(-h/length)
  for h > 0, F0 at contact (the frictional contacts' repulsion, `contacts`).
* `Combined`: a sum of laws (DLVO = van der Waals + double layer).

Shifted-force truncation (van der Waals, double layer) at h_c = cut-off x (a_i + a_j)/2:
F_s(h) = F(h) - F(h_c), U_s(h) = U(h) - U(h_c) + F(h_c) (h - h_c) for h < h_c, both 0
beyond; the job checks (`checks`) require |F(h_c)| <= ``TAIL`` |F(contact)|.

Limits, the reduced double-layer potential and the validity of each law: docs/physics.md,
"Interparticle forces".

Units: in the job file forces are in the job's force unit 6 pi eta_m a^2 / (time unit)
(kT/a for Brownian jobs, 6 pi eta_m a^2 gamma_dot for non-Brownian steady shear),
energies in force unit x a, lengths in a; the builders multiply every strength by
``FORCE_UNIT`` = 6 pi into the Stokes units of the hydrodynamics (eta_m = a = 1).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from .component import NoState, SampleFields, Stateful

if TYPE_CHECKING:
    from ..hydro.lubrication import PairList

#: the job's force unit, 6 pi eta_m a^2 / (time unit), in Stokes units (eta_m = a = 1)
FORCE_UNIT = 6 * math.pi
#: largest allowed |F(cut-off)| / |F(contact)| of the truncated (shifted) laws
TAIL = 1e-3


class PairLaw(Protocol):
    """A central pair force law between spheres of radii a_i, a_j at surface gap h; every
    law below implements it."""

    def magnitude(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        """Force magnitude F(h), positive when repulsive.

        Args:
            gap: surface gaps h, scalar or shape (P,), in a.
            a_i: radii of the first spheres, scalar or (P,), in a.
            a_j: radii of the second spheres, scalar or (P,), in a.

        Returns:
            F(h), shaped like gap, in the law's force unit (Stokes units in `PairForce`).
        """
        raise NotImplementedError

    def potential(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        """Pair potential U(h), with F = -dU/dh.

        Args:
            gap: surface gaps h, scalar or shape (P,), in a.
            a_i: radii of the first spheres, scalar or (P,), in a.
            a_j: radii of the second spheres, scalar or (P,), in a.

        Returns:
            U(h), shaped like gap, in the law's force unit x a.
        """
        raise NotImplementedError


@dataclass(frozen=True)
class Repulsion:
    """F(h) = F0 tau exp(-tau h) / (1 + exp(-tau h)) (Dratler & Schowalter 1996, Brady & Bossis
    1985): an electrostatic-like repulsion of range 1/tau; F(0) = F0 tau / 2, F -> F0 tau e^{-tau h}
    far away, and F(h) = -dU/dh with U = F0 ln(1 + exp(-tau h))."""

    f0: float
    tau: float

    def magnitude(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        e = np.exp(-self.tau * np.maximum(gap, 0.0))
        return self.f0 * self.tau * e / (1.0 + e)

    def potential(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        return self.f0 * np.log1p(np.exp(-self.tau * np.maximum(gap, 0.0)))

    @property
    def reach(self) -> float:
        """Gap beyond which F < 1e-12 F0 tau."""
        return 12 * math.log(10) / self.tau


@dataclass(frozen=True)
class CriticalLoadRepulsion:
    """F(h) = F0 exp(-h/length) for h > 0, F0 for h <= 0 (Mari et al. 2014); F = -dU/dh
    with U = F0 length exp(-h/length), continued linearly for h < 0. Radii unused."""

    f0: float
    length: float

    def magnitude(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        return self.f0 * np.exp(-np.maximum(gap, 0.0) / self.length)

    def potential(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        gap = np.asarray(gap, float)
        return self.f0 * (self.length * np.exp(-np.maximum(gap, 0.0) / self.length)
                          - np.minimum(gap, 0.0))

    @property
    def reach(self) -> float:
        """Gap beyond which F < 1e-12 F0."""
        return 12 * math.log(10) * self.length


class _Truncated:
    """Shifted-force truncation at cut-off x mean radius (module docstring); subclasses
    give the untruncated _force(h, a_i, a_j) and _energy(h, a_i, a_j)."""

    def _h_cut(self, a_i, a_j):
        return self.cutoff * 0.5 * (np.asarray(a_i, float) + a_j)

    def magnitude(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        gap = np.asarray(gap, float)
        if math.isinf(self.cutoff):
            return self._force(gap, a_i, a_j)
        hc = self._h_cut(a_i, a_j)
        return np.where(gap < hc, self._force(gap, a_i, a_j) - self._force(hc, a_i, a_j), 0.0)

    def potential(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        gap = np.asarray(gap, float)
        if math.isinf(self.cutoff):
            return self._energy(gap, a_i, a_j)
        hc = self._h_cut(a_i, a_j)
        u = self._energy(gap, a_i, a_j) - self._energy(hc, a_i, a_j) \
            + self._force(hc, a_i, a_j) * (gap - hc)
        return np.where(gap < hc, u, 0.0)


@dataclass(frozen=True)
class VanDerWaals(_Truncated):
    """Hamaker's sphere-sphere van der Waals attraction (module docstring), capped below
    ``cap_gap`` (a) and truncated at ``cutoff`` mean radii (inf: not truncated).
    ``hamaker`` in energy units; magnitude < 0 (attraction)."""

    hamaker: float
    cap_gap: float
    cutoff: float = math.inf

    def _force_free(self, h, a_i, a_j):
        h = np.asarray(h, float)
        p, q, s = 2 * a_i + h, 2 * a_j + h, 2 * (a_i + a_j) + h
        return -(32.0 / 3.0) * self.hamaker * (a_i * a_j) ** 3 * (a_i + a_j + h) \
            / (h * h * s * s * (p * q) ** 2)

    def _energy_free(self, h, a_i, a_j):
        h = np.asarray(h, float)
        p, q, s = 2 * a_i + h, 2 * a_j + h, 2 * (a_i + a_j) + h
        return -(self.hamaker / 6.0) * (2 * a_i * a_j / (h * s) + 2 * a_i * a_j / (p * q)
                                        + np.log(h * s / (p * q)))

    def _force(self, h, a_i, a_j):
        return self._force_free(np.maximum(h, self.cap_gap), a_i, a_j)

    def _energy(self, h, a_i, a_j):
        h = np.asarray(h, float)
        hh = np.maximum(h, self.cap_gap)
        # below the cap: constant force, energy continued linearly (F = -dU/dh)
        return self._energy_free(hh, a_i, a_j) - self._force_free(hh, a_i, a_j) * (h - hh)


@dataclass(frozen=True)
class DoubleLayer(_Truncated):
    """Electrostatic double-layer repulsion, U = strength R ln(1 + e^(-h/debye_length)),
    R = a_i a_j/(a_i + a_j) (module docstring; strength = psi^2 in energy units / a),
    truncated at ``cutoff`` mean radii. Overlaps (h < 0) feel the contact force."""

    strength: float
    debye_length: float
    cutoff: float = math.inf

    def _force(self, h, a_i, a_j):
        e = np.exp(-np.maximum(np.asarray(h, float), 0.0) / self.debye_length)
        reff = a_i * a_j / (np.asarray(a_i, float) + a_j)
        return self.strength * reff / self.debye_length * e / (1.0 + e)

    def _energy(self, h, a_i, a_j):
        h = np.asarray(h, float)
        hh = np.maximum(h, 0.0)
        reff = a_i * a_j / (np.asarray(a_i, float) + a_j)
        u = self.strength * reff * np.log1p(np.exp(-hh / self.debye_length))
        return u - self._force(hh, a_i, a_j) * (h - hh)


@dataclass(frozen=True)
class Combined:
    """The sum of several pair laws (e.g. DLVO: van der Waals + double layer)."""

    parts: tuple

    def magnitude(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        return sum(p.magnitude(gap, a_i, a_j) for p in self.parts)

    def potential(
        self, gap: float | np.ndarray, a_i: float | np.ndarray = 1.0, a_j: float | np.ndarray = 1.0
    ) -> float | np.ndarray:
        return sum(p.potential(gap, a_i, a_j) for p in self.parts)


def tail_ratios(
    cap_gap: float | None, debye_length: float | None, cutoff: float, class_radii: tuple[float, ...]
) -> dict[str, tuple[float, tuple[float, float]]]:
    """|F(cut-off)| / |F(contact)| of each truncated part of a law, for the pair of size
    classes where it is largest (the cut-off gap is cut-off x the pair's mean radius, the
    van der Waals cap a fixed gap, so the ratio depends on both radii):
    {"interparticle.<key>": (ratio, (a_i, a_j))} for the job check against TAIL (`checks`).

    Args:
        cap_gap: the van der Waals cap (a), or None without van der Waals force.
        debye_length: the double layer's Debye length (a), or None without double layer.
        cutoff: the lubrication cut-off (mean radii).
        class_radii: the radii of the size classes (a).

    Returns:
        Per truncated part, its largest ratio (dimensionless) and the radii (a) where it
        occurs; empty for laws without truncation.
    """
    pairs = [(a, b) for k, a in enumerate(class_radii) for b in class_radii[k:]]
    laws = {}
    if cap_gap is not None:
        laws["interparticle.cap_gap"] = (VanDerWaals(1.0, cap_gap), cap_gap)
    if debye_length is not None:
        laws["interparticle.debye_length"] = (DoubleLayer(1.0, debye_length), 0.0)
    out = {}
    for path, (law, contact) in laws.items():
        ratios = [(float(abs(law.magnitude(cutoff * 0.5 * (a + b), a, b)
                             / law.magnitude(contact, a, b))), (a, b)) for a, b in pairs]
        out[path] = max(ratios)
    return out


def pair_forces(
    law: PairLaw, pairs: PairList, n: int, radii: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Forces (N, 3) on the particles and the virial sum_pairs dx F_ij (3, 3) for the
    close pairs (a PairList: dx = x_j - x_i, true gaps). The force on i is
    -F(h) dx/|dx| (repulsion pushes i away from j), and +F(h) dx/|dx| on j. radii (N,)
    give each pair's a_i, a_j; None: each pair's mean radius (radii_sum / 2) for both.

    Args:
        law: the pair law.
        pairs: the close pairs, P of them.
        n: number of particles N.
        radii: particle radii, shape (N,), in a, or None.

    Returns:
        (forces (N, 3), virial (3, 3)) in the law's force unit and force unit x a.
    """
    forces = np.zeros((n, 3))
    virial = np.zeros((3, 3))
    if len(pairs.i) == 0:
        return forces, virial
    if radii is None:
        a_i = a_j = 0.5 * pairs.radii_sum
    else:
        a_i, a_j = radii[pairs.i], radii[pairs.j]
    unit = pairs.dx / np.linalg.norm(pairs.dx, axis=1)[:, None]
    f_on_j = law.magnitude(pairs.gap, a_i, a_j)[:, None] * unit
    np.add.at(forces, pairs.j, f_on_j)
    np.add.at(forces, pairs.i, -f_on_j)
    # sum over particles of x F = sum over pairs of (x_j - x_i) F_on_j (true separations)
    virial = (pairs.distance[:, None] * unit).T @ f_on_j
    return forces, virial


# --------------------------------------------------------------------------- forces on the step's pairs

@dataclass(frozen=True)
class ForceSetting:
    """What every force of a realisation may need besides its own job keys.

    Attributes:
        radii: (N,) sphere radii, in a.
        cutoff: the lubrication cut-off (mean radii), beyond which the step's pair list
            ends: truncated laws vanish there.
    """

    radii: np.ndarray
    cutoff: float


@dataclass(frozen=True)
class ForceTerms:
    """One force's forces and torques (N, 6) (eta_m a^2/t_D, eta_m a^3/t_D) and virial
    sum over pairs of dx F_on_j (3, 3) (eta_m a^3/t_D), with its counts for the sample."""

    forces: np.ndarray
    virial: np.ndarray
    counts: dict[str, int]


class Force(Stateful, Protocol):
    """An interparticle force on the pairs of a step (the hydrodynamic evaluation's pair
    list, `sdmpi.hydro.lubrication.PairList`), with its own sample fields and state.
    Registered by interparticle.kind in `sdmpi.registry.FORCES` (docs/extending.md)."""

    def terms(self, pairs: PairList) -> ForceTerms:
        """The forces at the step's start.

        Args:
            pairs: the pairs within the cut-off, with true gaps (dx = x_j - x_i, a).

        Returns:
            Its `ForceTerms`.
        """
        raise NotImplementedError

    def sample_fields(self, stress_unit: str) -> SampleFields:
        """Its own fields of the sample stream (beyond stress_interparticle, which holds
        every force's stress).

        Args:
            stress_unit: the job's stress unit (for stress fields).

        Returns:
            name -> (shape per sample, dtype, unit, description); empty for none.
        """
        raise NotImplementedError

    def sample(self, terms: ForceTerms, stress: Callable[[ForceTerms], np.ndarray]) -> dict[str, Any]:
        """Its sample of the step (the fields of sample_fields).

        Args:
            terms: what `terms` returned for the step.
            stress: stress(terms) -> the 6-vector -(1/V) (sum R_SU R_FU^-1 F + sum x F)
                of such terms (one more solve).

        Returns:
            name -> value.
        """
        raise NotImplementedError

    def advance(self, velocities: np.ndarray, rate: float, dt: float) -> None:
        """Advance its state over the step (after `terms`).

        Args:
            velocities: (U, Omega) relative to the imposed flow, (N, 6), a/t_D and 1/t_D.
            rate: the step's shear rate (1/t_D).
            dt: the step's duration (t_D).
        """
        raise NotImplementedError


class Stateless(NoState, Force):
    """A `Force` without state or sample fields of its own: those members, empty."""

    def sample_fields(self, stress_unit: str) -> SampleFields:
        return {}

    def sample(self, terms: ForceTerms, stress: Callable[[ForceTerms], np.ndarray]) -> dict[str, Any]:
        return {}

    def advance(self, velocities: np.ndarray, rate: float, dt: float) -> None:
        pass


class PairForce(Stateless):
    """The central pair forces of a law (`PairLaw`, Stokes units) on the step's pairs of
    spheres of these radii (`pair_forces`); no torques."""

    def __init__(self, law: PairLaw, radii: np.ndarray):
        self.law, self.radii = law, radii

    def terms(self, pairs: PairList) -> ForceTerms:
        n = len(self.radii)
        forces, virial = pair_forces(self.law, pairs, n, self.radii)
        return ForceTerms(np.hstack([forces, np.zeros((n, 3))]), virial, {})


def repulsion(setting: ForceSetting, *, f0: float, tau: float) -> list[Force]:
    """interparticle.kind = "repulsion": `Repulsion` with F0 = f0 in the job's force unit.

    Args:
        setting: the realisation's spheres and cut-off.
        f0: F0 (force unit x a).
        tau: inverse range (1/a).

    Returns:
        The one pair force.
    """
    return [PairForce(Repulsion(FORCE_UNIT * f0, tau), setting.radii)]


def van_der_waals(setting: ForceSetting, *, hamaker: float, cap_gap: float) -> list[Force]:
    """interparticle.kind = "vdw": `VanDerWaals` truncated at the lubrication cut-off.

    Args:
        setting: the realisation's spheres and cut-off.
        hamaker: Hamaker constant (energy unit).
        cap_gap: gap below which the force is constant (a).

    Returns:
        The one pair force.
    """
    return [PairForce(VanDerWaals(FORCE_UNIT * hamaker, cap_gap, setting.cutoff), setting.radii)]


def dlvo(
    setting: ForceSetting, *, hamaker: float, cap_gap: float, surface_potential: float, debye_length: float
) -> list[Force]:
    """interparticle.kind = "dlvo": van der Waals plus `DoubleLayer`, both truncated at the
    lubrication cut-off, as one `Combined` law.

    Args:
        setting: the realisation's spheres and cut-off.
        hamaker: Hamaker constant (energy unit).
        cap_gap: gap below which the van der Waals force is constant (a).
        surface_potential: reduced surface potential psi (sqrt(energy unit / a)).
        debye_length: Debye length (a).

    Returns:
        The one pair force.
    """
    vdw = VanDerWaals(FORCE_UNIT * hamaker, cap_gap, setting.cutoff)
    layer = DoubleLayer(FORCE_UNIT * surface_potential ** 2, debye_length, setting.cutoff)
    return [PairForce(Combined((vdw, layer)), setting.radii)]
