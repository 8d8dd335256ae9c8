"""Drift schemes of the resistance models and the near-contact correction beside them.

A drift scheme (``brownian.scheme``, registered in `sdmpi.registry.DRIFT_SCHEMES`) turns
the step's standard normal noise z into the step's `BrownianTerms` for the Ito equation

    dx = [... + kT div R_FU^-1] dt + sqrt(2 kT dt) R_FU^-1/2 dW:

the Brownian velocities R_FU^-1 F_B + kT div R_FU^-1 (F_B = sqrt(2 kT/dt) C z of covariance
2 kT R_FU / dt, C C^T = R_FU) and the Brownian stresslets -kT div(R_SU R_FU^-1) (Schaink et
al. 2000, eq. 16). Each acts on a `SolverEvaluation` (a resistance model at one
configuration: `sdmpi.dynamics.models.ResistanceEvaluation`):

* `RandomFiniteDifference` (``rfd``): the divergences by a random finite difference along
  the noise's own directions over a length RFD_STEP hydrodynamics.min_gap, to first order in
  the change of R (Delong, Balboa Usabiaga & Donev, J. Chem. Phys. 140, 134110 (2014);
  Sprinkle et al., J. Chem. Phys. 147, 244103 (2017));
* `SplitRandomFiniteDifference` (``rfd-split``): the same, with the stresslets' difference
  taken along an independent draw of their own;
* `Midpoint` (``midpoint``): Fixman's midpoint as used for SD by Banchio & Brady, J. Chem.
  Phys. 118, 10323 (2003).

The near-contact correction (`near_contact_velocities`) replaces the radial part of one
explicit step of close pairs by the exact squared-Bessel transition of their gap. The
derivations, accuracies and measurements are in docs/numerics.md, "Drift schemes and the
near-contact correction".
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..hydro.backend import FORM_ACCURACY
from ..hydro.lubrication import PairList
from ..hydro.two_sphere import squeeze_slope

#: the random finite difference's length in units of hydrodynamics.min_gap (mean radii)
RFD_STEP = 1e-2
#: pairs with surface gaps below this (mean radii) get the near-contact correction
#: (docs/numerics.md); there lubrication dominates: D_rr/h = 4.0 (h -> 0) to 3.1
#: (h = 5e-2) D0/a for an isolated pair of equal spheres
NEAR_CONTACT_GAP = 5e-2
#: ... of which those within FLOOR_REACH c dt of contact (c = D_rr/h of the isolated pair)
#: can reach the floor in one step (the squared Bessel transition's probability falls like
#: exp(-h/(c dt))), and kappa_p's error there moves the floor hits: their relative
#: mobilities G_p are asked to the solver's default accuracy (`mobility_forms`), those of
#: the farther pairs only to NEAR_CONTACT_FAR_ACCURACY (relative), where an error in kappa
#: changes the step's variance by ~ its error times c dt / h. (Measured, N = 125,
#: phi = 0.45: kappa 3% too large beyond 3 c dt alone leaves 1.18 times the exact floor
#: hits, against 2.0 for every pair, and the estimates of `petsc-krylov` from 3 to 6 c dt
#: lie within ~5e-3 of exact: docs/numerics.md)
FLOOR_REACH = 3.0
NEAR_CONTACT_FAR_ACCURACY = 2e-2


@dataclass
class BrownianTerms:
    """One step's Brownian velocities (N, 6), drift included, and Brownian stresslets (N, 5),
    and how many overlapping pairs its displaced evaluation had to separate (midpoint)."""

    velocities: np.ndarray
    stresslets: np.ndarray
    midpoint_overlaps: int = 0


class SolverEvaluation(Protocol):
    """What a drift scheme needs of a resistance model at one configuration of N spheres.

    Attributes:
        solver: the backend's solver (`sdmpi.hydro.backend.SolverBackend`) at the configuration.
        positions: (N, 3) the configuration.
        n_particles: N.
        pairs: the pairs within the interparticle-force cut-off, with true gaps.
        radii: (N,) sphere radii (a).
        min_gap: hydrodynamics.min_gap, the lubrication's floor of the gap (mean radii).
    """

    solver: Any
    positions: np.ndarray
    n_particles: int
    pairs: PairList
    radii: np.ndarray
    min_gap: float

    def displaced(self, positions: np.ndarray) -> tuple[Any, int]:
        """The solver at ``positions`` (N, 3), overlaps first separated, with this
        evaluation's pair sets and strain, and the number of overlaps separated."""
        raise NotImplementedError

    def mobility_change(self, positions: np.ndarray, velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(du, ds) to first order in Delta R = R(positions) - R, for velocities m = R_FU^-1 F
        (N, 6) of a solve: du = [R_FU^-1(positions) - R_FU^-1] F (N, 6) and
        ds = -[(R_SU R_FU^-1)(positions) - R_SU R_FU^-1] F (N, 5)."""
        raise NotImplementedError

    def forces_drawn(self) -> None:
        """The scheme has drawn the Brownian forces of its sample (its later solves need
        none): where this is the evaluation's last draw, its solver frees what only they
        need, before the scheme builds more (`displaced`)."""
        raise NotImplementedError


class DriftScheme(Protocol):
    """A drift scheme (``brownian.scheme``), registered in `sdmpi.registry.DRIFT_SCHEMES`
    (docs/extending.md)."""

    def brownian(self, evaluation: SolverEvaluation, z: np.ndarray, kT: float, dt: float,
                 near: Callable[[np.ndarray], Any], z_stress: np.ndarray | None = None) -> BrownianTerms:
        """The step's `BrownianTerms` for the standard normal noise z (the solver's
        noise_shape) at temperature kT and time step dt; near(m): the velocities (N, 6), or
        0, that the near-contact correction adds for the step's displacement direction
        m = R_FU^-1 C z (N, 6); z_stress: the stresslets' own standard normal draw (same
        shape), drawn after the step's other noise for a scheme registered with
        `sdmpi.registry.DriftSpec.stress_draw`, else None."""
        raise NotImplementedError


def rfd_length(min_gap: float) -> float:
    """The random finite difference's length along m = R_FU^-1 C z (~1/(6 pi a) per unit of
    z): 6 pi RFD_STEP min_gap, a displacement of ~RFD_STEP min_gap per sphere."""
    return RFD_STEP * min_gap * 6 * math.pi


def _rfd_difference(evaluation: SolverEvaluation, m: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(eps, the velocity change dm = [R_FU^-1(x + eps m) - R_FU^-1(x)] F (N, 6), the
    stresslet change -[(R_SU R_FU^-1)(x + eps m) - (R_SU R_FU^-1)(x)] F (N, 5)) of a random
    finite difference of length eps = `rfd_length` along m = R_FU^-1 F, to first order in
    Delta R = R(x + eps m) - R (`SolverEvaluation.mobility_change`)."""
    step = rfd_length(evaluation.min_gap)
    dm, ds = evaluation.mobility_change(evaluation.positions + step * m[:, :3], m)
    return step, dm, ds


def rfd_drift(evaluation: SolverEvaluation, m: np.ndarray, kT: float) -> np.ndarray:
    """The drift (N, 6) of one random finite difference along m = R_FU^-1 F:
    (kT/eps) [R_FU^-1(x + eps m) - R_FU^-1(x)] F, whose mean over F = C z is kT div R_FU^-1
    (`_rfd_difference`; docs/numerics.md)."""
    step, dm, _ = _rfd_difference(evaluation, m)
    return (kT / step) * dm


def rfd_terms(evaluation: SolverEvaluation, m: np.ndarray, kT: float) -> tuple[np.ndarray, np.ndarray]:
    """(drift (N, 6), Brownian stresslets (N, 5)) of one random finite difference along the
    direction m = R_FU^-1 F: the drift of `rfd_drift` and
    -(kT/eps) [(R_SU R_FU^-1)(x + eps m) - (R_SU R_FU^-1)(x)] F, whose mean over F = C z is
    -kT div(R_SU R_FU^-1) (docs/numerics.md)."""
    step, dm, ds = _rfd_difference(evaluation, m)
    return (kT / step) * dm, (kT / step) * ds


class RandomFiniteDifference:
    """``rfd``: kT div R_FU^-1 and -kT div(R_SU R_FU^-1) by one random finite difference
    (`rfd_terms`) along the step's own displacement direction m = R_FU^-1 C z (Delong,
    Balboa Usabiaga & Donev 2014; Sprinkle et al. 2017)."""

    def brownian(self, evaluation: SolverEvaluation, z: np.ndarray, kT: float, dt: float,
                 near: Callable[[np.ndarray], Any], z_stress: np.ndarray | None = None) -> BrownianTerms:
        m = evaluation.solver.brownian_velocities(z)
        noise = math.sqrt(2 * kT / dt) * m
        drift, stress = rfd_terms(evaluation, m, kT)
        return BrownianTerms(noise + drift + near(m), stress)


class SplitRandomFiniteDifference:
    """``rfd-split``: the drift by a random finite difference along the step's displacement
    direction m = R_FU^-1 C z, as ``rfd``, and the Brownian stresslets by a second one along
    m' = R_FU^-1 C z_stress of an independent draw (`rfd_drift`, `rfd_terms`). The estimator noise of the
    stresslets is then independent of the step's displacement and of every later
    configuration (with ``rfd`` both are functions of z), a control for the stress
    autocorrelation at rest (docs/numerics.md). One more resistance change and solve per
    step than ``rfd``."""

    def brownian(self, evaluation: SolverEvaluation, z: np.ndarray, kT: float, dt: float,
                 near: Callable[[np.ndarray], Any], z_stress: np.ndarray | None = None) -> BrownianTerms:
        if z_stress is None:
            raise ValueError("rfd-split needs the stresslets' own draw z_stress")
        solver = evaluation.solver
        m = solver.brownian_velocities(z)
        noise = math.sqrt(2 * kT / dt) * m
        drift = rfd_drift(evaluation, m, kT)
        _, stress = rfd_terms(evaluation, solver.brownian_velocities(z_stress), kT)
        return BrownianTerms(noise + drift + near(m), stress)


class Midpoint:
    """``midpoint``: x* = x + (dt/2) R_FU^-1(x) F_B, the velocities R_FU^-1(x*) F_B (mean:
    kT div R_FU^-1 to O(dt)), the Brownian stresslets -[(R_SU R_FU^-1)(x*) -
    (R_SU R_FU^-1)(x)] F_B (Banchio & Brady 2003; docs/numerics.md)."""

    def brownian(self, evaluation: SolverEvaluation, z: np.ndarray, kT: float, dt: float,
                 near: Callable[[np.ndarray], Any], z_stress: np.ndarray | None = None) -> BrownianTerms:
        solver = evaluation.solver
        zero = np.zeros((evaluation.n_particles, 5))
        unit_force = solver.brownian_forces(z)
        m = solver.velocities(unit_force, zero)
        # the start's stresslets of the solve just made (an iterative solver reuses it, so
        # the start's and the midpoint's solve errors cancel in the difference), scaled
        start = math.sqrt(2 * kT / dt) * solver.stresslets(m, zero)
        correction = near(m)
        evaluation.forces_drawn()
        step = 0.5 * dt * math.sqrt(2 * kT / dt)
        mid, found = evaluation.displaced(evaluation.positions + step * m[:, :3])
        mid.take_preconditioner(solver)  # petsc-krylov: refactorise the start's factor
        u_mid = mid.velocities(math.sqrt(2 * kT / dt) * unit_force, zero)
        return BrownianTerms(u_mid + correction, mid.stresslets(u_mid, zero) - start, found)


def squeeze_fraction(mobility: np.ndarray, gap: np.ndarray, radius_i: np.ndarray,
                     radius_j: np.ndarray) -> np.ndarray:
    """kappa = G h |d(f.R_2B f)/dh| / |f|^4 (|f|^2 = 2) of pairs with relative mobility
    G = f.R_FU^-1.f (`unit_pair_forces` f) at gap h: the derivative of the pair's relative
    diffusivity along its own mobility response over D_rr/h (docs/numerics.md), from the
    two-sphere squeeze resistance (`hydro.two_sphere.squeeze_slope`). 1 for two spheres
    alone at contact; below 1 by the share of the pair's relative mobility the rest of the
    suspension takes."""
    return mobility * squeeze_slope(gap, radius_i, radius_j) / 4.0


def contact_reach(gap: np.ndarray, radius_i: np.ndarray, radius_j: np.ndarray, kT: float,
                  dt: float) -> np.ndarray:
    """h / (c dt): the gap h of pairs in units of the distance c dt their relative motion
    covers in a step of dt near contact, c = D_rr / h = kT G / h of the isolated pair
    (kappa = 1: G = 4 / s, `squeeze_fraction`): h^2 s / (4 kT dt), s the two-sphere
    squeeze slope (`hydro.two_sphere.squeeze_slope`)."""
    return gap ** 2 * squeeze_slope(gap, radius_i, radius_j) / (4.0 * kT * dt)


def unit_pair_forces(i: np.ndarray, j: np.ndarray, e: np.ndarray, n: int) -> np.ndarray:
    """Force sets (P, N, 6): for each pair p a unit force e_p on j_p and -e_p on i_p (its
    line of centres), no torques."""
    forces = np.zeros((len(i), n, 6))
    rows = np.arange(len(i))
    forces[rows, j, :3] = e  # each (row, particle) once per statement: no np.add.at needed
    forces[rows, i, :3] -= e  # (a self-image pair, i = j, gets zero)
    return forces


def near_contact_velocities(evaluation: SolverEvaluation, m: np.ndarray, z_near: np.ndarray, kT: float,
                            dt: float) -> np.ndarray:
    """Velocities (N, 6) of the near-contact correction for the step's direction m (N, 6)
    and the independent noise z_near (the solver's noise_shape): R_FU^-1 of the pair forces
    w_p f_p of the pairs with gaps below NEAR_CONTACT_GAP,
    w_p = (2 kappa_p - 1)^+ kT (m'_h^2 - m_h^2) / (2 G_p h_p), m' = R_FU^-1 C z_near
    (docs/numerics.md). Mean zero at every gap, whatever G_p's error; G_p (`mobility_forms`)
    is asked to FORM_ACCURACY within FLOOR_REACH c dt of contact and to
    NEAR_CONTACT_FAR_ACCURACY beyond."""
    pairs, solver = evaluation.pairs, evaluation.solver
    mean_radius = 0.5 * pairs.radii_sum
    close = pairs.gap < NEAR_CONTACT_GAP * mean_radius
    n, zero = evaluation.n_particles, np.zeros((evaluation.n_particles, 5))
    if not close.any():
        return np.zeros((n, 6))
    i, j = pairs.i[close], pairs.j[close]
    dx = pairs.dx[close]
    e = dx / np.sqrt(np.einsum("pc,pc->p", dx, dx))[:, None]
    m_indep = solver.brownian_velocities(z_near)
    m_h, m_indep_h = (np.einsum("pc,pc->p", e, u[j, :3] - u[i, :3]) for u in (m, m_indep))
    gap = np.maximum(pairs.gap[close], evaluation.min_gap * mean_radius[close])  # the lubrication's floor
    forces = unit_pair_forces(i, j, e, n)
    far = contact_reach(gap, evaluation.radii[i], evaluation.radii[j], kT, dt) >= FLOOR_REACH
    mobility = solver.mobility_forms(forces, np.where(far, NEAR_CONTACT_FAR_ACCURACY, FORM_ACCURACY))
    kappa = squeeze_fraction(mobility, gap, evaluation.radii[i], evaluation.radii[j])
    weight = np.maximum(2.0 * kappa - 1.0, 0.0) * 0.5 * kT * (m_indep_h ** 2 - m_h ** 2) / (mobility * gap)
    return solver.velocities(np.einsum("p,pkc->kc", weight, forces), zero)
