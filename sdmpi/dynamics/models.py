"""Hydrodynamic models: what the integrator asks of the hydrodynamics at one configuration.

A model (`HydrodynamicModel`, built by `hydrodynamic_model(job, ...)` from the entry of
hydrodynamics.model in `sdmpi.registry.HYDRODYNAMIC_MODELS`) is evaluated at a
configuration, ``model.at(positions, strain)``, which assembles and factorises whatever the
model needs and returns an *evaluation* (`HydrodynamicEvaluation`) with

* ``velocities(forces, einf)``: rigid-body velocities relative to the imposed flow, (N, 6)
  U', Omega' = R_FU^-1 (F + R_FE e_inf) for forces/torques (N, 6) and E_inf (N, 5);
* ``stresslets(velocities, einf)``: S = R_SE e_inf - R_SU U' (N, 5);
* ``brownian(rng, kT, dt)``: a `BrownianTerms` of the step, the Brownian velocities
  R_FU^-1 F_B + kT div R_FU^-1 (drift included; F_B of covariance 2 kT R_FU / dt) and an
  estimate of the Brownian stresslets -kT div(R_SU R_FU^-1) (Schaink et al. 2000, eq. 16);
* ``pairs``: the pairs within the interparticle-force cut-off (`lubrication.PairList`,
  true gaps), ``relative_mobility(pairs, mask)``: each pair's mobility of relative motion
  along its line of centres (for the collision forces of `collisions`), ``stats()``: solver
  statistics of the evaluation.

Models (``hydrodynamics.model``, registered in `sdmpi.registry.HYDRODYNAMIC_MODELS`):

* ``stokesian``: full Stokesian dynamics, R = M_inf^-1 + lubrication (Durlofsky, Brady &
  Bossis 1987; Brady et al. 1988), on any solver backend (`sdmpi.registry.SOLVER_BACKENDS`);
* ``far-field``: the periodic far-field (Rotne-Prager-level, FTS) mobility alone, R = M_inf^-1,
  no lubrication: Brownian dynamics with hydrodynamic interactions;
* ``free-draining``: no hydrodynamic interactions, R_FU = diag(6 pi a, 8 pi a^3),
  R_SE e = (20/3) pi a^3 E, R_SU = 0: zero drift, no factorisation.

Drift schemes (``brownian.scheme``) of the resistance models, for the Ito equation
dx = [... + kT div R_FU^-1] dt + sqrt(2 kT dt) R_FU^-1/2 dW:

* ``rfd`` (default on the direct backends): Euler-Maruyama for the noise, R_FU^-1(x) F_B, and
  a random finite difference for the divergences (Delong, Balboa Usabiaga & Donev, J. Chem.
  Phys. 140, 134110 (2014); Sprinkle, Balboa Usabiaga, Patankar & Donev, J. Chem. Phys. 147,
  244103 (2017)) taken along the noise's own directions: with F = C z (covariance R_FU), the
  displacement direction m = R_FU^-1 F (covariance R_FU^-1, so <m_k F_j> = delta_kj) and a
  small length epsilon,

      kT div R_FU^-1        ~ (kT/epsilon) [R_FU^-1(x + epsilon m) - R_FU^-1(x)] F,
      -kT div(R_SU R_FU^-1) ~ -(kT/epsilon) [(R_SU R_FU^-1)(x + epsilon m) - (R_SU R_FU^-1)(x)] F,

  whose means over z are the divergences to O(epsilon^2) (the odd moments of z vanish) at
  every gap. This is Fixman's midpoint below with the half step (dt/2) sqrt(2 kT/dt)
  replaced by epsilon = 6 pi RFD_STEP hydrodynamics.min_gap (a displacement of ~RFD_STEP
  min_gap per sphere): the same directions, so the same variance as the midpoint, which
  weights the stiff lubrication directions by the noise itself (an isotropic random
  difference has a ~100x larger variance of the Brownian stress at phi = 0.1), but a
  displacement far below the gaps the overlap correction leaves, so a pair just separated
  sees the true gradient of its lubrication where a finite half step would cross the floor
  and see none. The difference of two direct solves loses log10(cond R_FU) + log10(1/
  RFD_STEP min_gap) of the 16 digits: ~6 remain relative to the drift at min_gap = 1e-4.
  The displaced configuration is not assembled, inverted and factorised again: with
  R(x + epsilon m) = R + Delta R and Delta R (m, 0) from `hydro.resistance.resistance_change`
  (the far-field change as M_inf(x + epsilon m) applied to one vector by the Ewald sums of
  x's own plan, the lubrication pair by pair), both
  differences are taken to first order in Delta R,

      R_FU^-1(x + epsilon m) F - m                ~ dm = -R_FU^-1 (Delta R_FU m),
      -(R_SU R_FU^-1)(x + epsilon m) F + R_SU m   ~ -(Delta R_SU m) - R_SU dm.

  The terms dropped are quadratic in Delta R, so cubic in z: zero mean, and the mean is
  still the divergence to O(epsilon^2); per sample they are ~2e-4 of the drift at N = 27,
  phi = 0.45 (bench/rfd_accuracy.py, docs/performance.md).
* ``midpoint``: Fixman's midpoint scheme as used for SD by Banchio & Brady, J. Chem. Phys.
  118, 10323 (2003): x* = x + (dt/2) R_FU^-1(x) F_B, then R_FU^-1(x*) F_B, whose mean is
  kT div R_FU^-1 to O(dt); the Brownian stresslet -[(R_SU R_FU^-1)(x*) - (R_SU R_FU^-1)(x)] F_B.
  Its displacement is O(sqrt(dt)), so it suits iterative solvers (petsc-krylov, whose
  tolerance would swamp a difference over epsilon), but near contact the half step crosses
  the minimum-gap floor and its overlap correction: its drift is too small at gaps below
  ~4 dt (59% of the exact drift at a gap of 2e-4 with dt = 5e-4).

Both schemes evaluate the displaced configuration with the pair sets of x and at the same
strain, so the difference is smooth.

Near contact (lubrication on), one explicit step misrepresents a pair's gap h however exact
its mean drift: the relative radial diffusivity falls like the gap, D_rr = kT G ~ c h (c = 4
D0 for equal spheres, G = e.(M_ii + M_jj - M_ij - M_ji).e), so the gap follows

    dh = c dt + sqrt(2 c h) dW,

a squared Bessel process of dimension 2 (h = (c/2) |B|^2 for a planar Brownian motion B;
Revuz & Yor, Continuous Martingales and Brownian Motion, ch. XI; the Feller / Cox-Ingersoll-
Ross diffusion with a vanishing level), whose exact transition over dt is

    h1 = (sqrt(h0) + sqrt(c dt/2) z1)^2 + (c dt/2) z2^2,      z1, z2 ~ N(0, 1) independent,

a scaled non-central chi-square with two degrees of freedom. Both schemes draw the drift
along the noise's own direction. Its singular part near contact is the lubrication term.
Write the pair's squeeze resistance along its unit pair force f_p (e on j, -e on i,
|f_p|^2 = 2) as the rank-one part sigma(h) f_p f_p^T/|f_p|^4 of R_FU, sigma = f_p.R_2B.f_p
(two-sphere squeeze, ~ A/h), and let m_h = f_p.m be the pair's part of the step's direction
m = R_FU^-1 C z, z1 = m_h/sqrt(G) its standard normal radial noise (<m_h^2> = G). The drift
along m changes G by dG = -(sigma'/|f_p|^4) G^2 (f_p.dx) (Sherman-Morrison), so its radial
part is

    f_p.(kT div R_FU^-1) ~ kT |sigma'| G m_h^2 / |f_p|^4 = kappa c z1^2,
    kappa = G h |sigma'| / |f_p|^4   (`squeeze_fraction`),

the derivative of D_rr = kT G along the pair's own response over c = D_rr/h. Two spheres
alone at contact have kappa = 1 (G -> |f_p|^4 h/A); below 1 by the share of the pair's
relative mobility that the rest of the suspension takes, and falling with the gap (N = 27,
phi = 0.45: 0.99 at h = 8e-4, 0.95 at 4e-3, 0.9 at 1e-2, 0.8 at 2e-2; two spheres alone:
0.99 at 1e-3, 0.98 at 3e-3, 0.94 at 1e-2, 0.90 at 2e-2). With kappa = 1 the radial step is
h0 + sqrt(2 c h0 dt) z1 + c dt z1^2: the right mean, but z2 = z1, so that h1 >= h0/2; a
pair can never close more than half its gap in one step, and the layer h < ~c dt is
under-sampled (two spheres at dt = 5e-4: 0.2-0.4 of the equilibrium time below a gap of
1e-3). The near-contact correction gives every pair with a gap below NEAR_CONTACT_GAP (the
separation and gap h of the model's pair list) the step

    h1 = (sqrt(h0) + sqrt(c dt/2) z1)^2 + (kappa - 1/2) c dt z2^2,

the exact transition when kappa = 1 and, for every kappa >= 1/2, a gap that cannot pass
contact with the scheme's mean h0 + kappa c dt: it replaces kappa m_h^2 by m_h^2/2 +
(kappa - 1/2) m'_h^2, with m'_h = f_p.m' from one independent direction m' = R_FU^-1 C z'
(z2 = m'_h/sqrt(G)), i.e. it adds the velocities

    R_FU^-1 sum_p w_p f_p,      w_p = (2 kappa_p - 1) kT (m'_h^2 - m_h^2) / (2 G_p h_p),

which change the pair's own gap by (kappa - 1/2) c dt (z2^2 - z1^2) and move its neighbours
as the hydrodynamics couples them (w_p = 0 where kappa_p < 1/2, at gaps where c dt << h).
Both squares have mean G_p, so the correction has mean zero at every gap and the mean drift
stays exactly the scheme's. Taking kappa = 1 where it is smaller would leave the quadratic
term (kappa - 1/2) c dt z1^2 and a gap that can pass contact, down to
h0 (1 - 1/(2 kappa - 1)): at N = 27, phi = 0.45, dt = 5e-4 the step then leaves pairs below
the floor 2.3-2.5 times as often as the squared-Bessel transition of the same pairs says,
0.99-1.12 times with kappa (`bench/floor_hits.py`). Far from contact (h >> c dt) the
correction is a negligible O(dt^2) change of the step's variance. Cost: two solves, and the
G_p (`relative_mobility`) by one triangular solve for all pairs on the dense backend. It is
applied on the direct backends only: an iterative solve's relative error, small against
the whole of m, is large against the small radial parts m_h of close pairs, and divided by
G_p h_p it would dominate the correction (petsc-krylov keeps the scheme's own step).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..hydro.farfield import NDOF
from ..hydro.geometry import Lattice
from ..hydro.lubrication import PairList, close_pairs
from ..hydro.resistance import resistance_change
from ..hydro.solvers import assemble, make_solver, resolve_backend
from ..hydro.two_sphere import squeeze_slope
from ..registry import HYDRODYNAMIC_MODELS, SOLVER_BACKENDS, backend_for

#: brownian.scheme choices (resistance models)
SCHEMES = ("rfd", "midpoint")
#: the random finite difference's length in units of hydrodynamics.min_gap (mean radii)
RFD_STEP = 1e-2
#: pairs with surface gaps below this (mean radii) get the near-contact correction (module
#: docstring); there lubrication dominates: D_rr/h = 4.0 (h -> 0) to 3.1 (h = 5e-2) D0/a for
#: an isolated pair of equal spheres
NEAR_CONTACT_GAP = 5e-2


@dataclass
class BrownianTerms:
    """One step's Brownian velocities (N, 6), drift included, and Brownian stresslets (N, 5),
    and how many overlapping pairs its displaced evaluation had to separate (midpoint)."""

    velocities: np.ndarray
    stresslets: np.ndarray
    midpoint_overlaps: int = 0


class HydrodynamicEvaluation(Protocol):
    """A hydrodynamic model at one configuration of N spheres (module docstring), all in
    the reduced units of the job (radius a, viscosity eta_m).

    Attributes:
        positions: (N, 3) the configuration, wrapped into the box.
        n_particles: N.
        pairs: the pairs within the interparticle-force cut-off, with true gaps.
    """

    positions: np.ndarray
    n_particles: int
    pairs: PairList

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """U', Omega' (N, 6) relative to the imposed flow = R_FU^-1 (F + R_FE e_inf), for
        forces/torques (N, 6) and E_inf (N, 5)."""
        raise NotImplementedError

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """S (N, 5) = R_SE e_inf - R_SU U' for rigid-body velocities (N, 6) and E_inf (N, 5)."""
        raise NotImplementedError

    def relative_mobility(self, i: np.ndarray, j: np.ndarray, e: np.ndarray) -> np.ndarray:
        """(P,) mobility of relative motion e.(M_jj + M_ii - M_ij - M_ji).e of the pairs
        (i, j) along their unit lines of centres e (P, 3), M = R_FU^-1."""
        raise NotImplementedError

    def brownian(self, rng: np.random.Generator, kT: float, dt: float) -> BrownianTerms:
        """The step's Brownian velocities (drift included) and stresslets, drawn from rng."""
        raise NotImplementedError

    def stats(self) -> dict[str, float]:
        """Solver statistics of the evaluation: solver_iterations, solver_residual,
        lanczos_iterations (zero for the direct backends)."""
        raise NotImplementedError


class HydrodynamicModel(Protocol):
    """A hydrodynamic model of spheres of given radii in a box, registered in
    `sdmpi.registry.HYDRODYNAMIC_MODELS` (docs/extending.md)."""

    @classmethod
    def from_job(cls, job: Any, radii: np.ndarray, box: np.ndarray, comm: Any = None,
                 separate: Callable | None = None, on_error: Callable | None = None) -> HydrodynamicModel:
        """The model of ``job`` (`hydrodynamic_model`)."""
        raise NotImplementedError

    def at(self, positions: np.ndarray, strain: float) -> HydrodynamicEvaluation:
        """The model evaluated at ``positions`` (N, 3) with the box at Lees-Edwards ``strain``."""
        raise NotImplementedError


def default_scheme(backend):
    """The drift scheme a backend gets when brownian.scheme is absent: rfd on the direct
    backends, midpoint on the matrix-free (iterative) ones (module docstring)."""
    return "midpoint" if SOLVER_BACKENDS[backend].matrix_free else "rfd"


def squeeze_fraction(mobility, gap, radius_i, radius_j):
    """kappa = G h |d(f.R_2B f)/dh| / |f|^4 (|f|^2 = 2) of pairs with relative mobility
    G = f.R_FU^-1.f (`unit_pair_forces` f) at gap h: the derivative of the pair's relative
    diffusivity along its own mobility response over D_rr/h (module docstring), from the
    two-sphere squeeze resistance (`hydro.two_sphere.squeeze_slope`). 1 for two spheres
    alone at contact; below 1 by the share of the pair's relative mobility the rest of the
    suspension takes."""
    return mobility * squeeze_slope(gap, radius_i, radius_j) / 4.0


def unit_pair_forces(i, j, e, n):
    """Force sets (P, N, 6): for each pair p a unit force e_p on j_p and -e_p on i_p (its
    line of centres), no torques."""
    forces = np.zeros((len(i), n, 6))
    rows = np.arange(len(i))
    forces[rows, j, :3] = e  # each (row, particle) once per statement: no np.add.at needed
    forces[rows, i, :3] -= e  # (a self-image pair, i = j, gets zero)
    return forces


class ResistanceEvaluation(HydrodynamicEvaluation):
    """A resistance model (stokesian, far-field) at one configuration: its resistance
    (`hydro.resistance`), the backend's solver of it, and the force pair list."""

    def __init__(self, model, resistance, solver, pairs, strain):
        self.model, self.resistance, self.solver, self.pairs = model, resistance, solver, pairs
        self.strain = strain
        self.positions = resistance.positions
        self.n_particles = resistance.n_particles
        self._solvers = [solver]

    def velocities(self, forces, einf):
        return self.solver.velocities(forces, einf)

    def stresslets(self, velocities, einf):
        return self.solver.stresslets(velocities, einf)

    def relative_mobility(self, i, j, e):
        """e.(M_jj + M_ii - M_ij - M_ji).e of the pairs (i, j) with unit lines of centres
        e (M = R_FU^-1): f.M.f for unit and opposite forces f on j and i (`unit_pair_forces`)."""
        return self.solver.mobility_forms(unit_pair_forces(i, j, e, self.n_particles))

    def brownian(self, rng, kT, dt):
        shape = self.solver.noise_shape
        z = rng.standard_normal(shape)
        z_near = rng.standard_normal(shape) if self.model.near_contact else None
        # the iterative backend's Brownian forces (Lanczos) need a positive definite M_inf
        return self.model._guarded(self.brownian_terms, z, kT, dt, z_near)

    def brownian_terms(self, z, kT, dt, z_near=None):
        """The step's `BrownianTerms` for the standard normal noise z (the solver's noise_shape):
        F_B = sqrt(2 kT/dt) C z (C C^T = R_FU, or any F_B of that covariance), the
        displacement direction m = R_FU^-1 C z (module docstring); z_near: the independent
        noise z' of the near-contact correction (None: no correction)."""
        zero = np.zeros((self.n_particles, 5))
        if self.model.scheme == "midpoint":
            unit_force = self.solver.brownian_forces(z)
            m = self.solver.velocities(unit_force, zero)
        else:
            m = self.solver.brownian_velocities(z)
        noise = math.sqrt(2 * kT / dt) * m
        near = 0.0 if z_near is None else self._near_contact(m, z_near, kT, dt)
        if self.model.scheme == "midpoint":
            step = 0.5 * dt * math.sqrt(2 * kT / dt)
            mid, found = self.model.displaced(self, self.positions + step * m[:, :3], separate=True)
            self._solvers.append(mid)
            mid.take_preconditioner(self.solver)  # petsc-krylov: refactorise the start's factor
            u_mid = mid.velocities(math.sqrt(2 * kT / dt) * unit_force, zero)
            return BrownianTerms(u_mid + near, mid.stresslets(u_mid, zero) - self.solver.stresslets(noise, zero),
                                 found)
        step = self.model.rfd_step * 6 * math.pi  # m is ~ 1/(6 pi a) per unit of z
        direction = np.zeros((self.n_particles, NDOF))
        direction[:, :6] = m
        change = self.model.resistance_change(self, self.positions + step * m[:, :3], direction)
        dm = -self.solver.velocities(change[:, :6], zero)  # (R + Delta R)_FU^-1 F - m, first order
        drift = (kT / step) * dm
        stress = (kT / step) * (self.solver.stresslets(dm, zero) - change[:, 6:])
        return BrownianTerms(noise + drift + near, stress)

    def _near_contact(self, m, z_near, kT, dt):
        """Velocities (N, 6) of the near-contact correction (module docstring) for the step's
        direction m and the independent noise z_near: R_FU^-1 of the pair forces
        w_p f_p, w_p = kT (m'_h^2 - m_h^2) / (2 G_p h_p)."""
        pairs = self.pairs
        mean_radius = 0.5 * pairs.radii_sum
        close = pairs.gap < NEAR_CONTACT_GAP * mean_radius
        n, zero = self.n_particles, np.zeros((self.n_particles, 5))
        if not close.any():
            return np.zeros((n, 6))
        i, j = pairs.i[close], pairs.j[close]
        dx = pairs.dx[close]
        e = dx / np.sqrt(np.einsum("pc,pc->p", dx, dx))[:, None]
        m_indep = self.solver.brownian_velocities(z_near)
        m_h, m_indep_h = (np.einsum("pc,pc->p", e, u[j, :3] - u[i, :3]) for u in (m, m_indep))
        gap = np.maximum(pairs.gap[close], self.model.min_gap * mean_radius[close])  # the lubrication's floor
        forces = unit_pair_forces(i, j, e, n)
        mobility = self.solver.mobility_forms(forces)
        kappa = squeeze_fraction(mobility, gap, self.model.radii[i], self.model.radii[j])
        weight = np.maximum(2.0 * kappa - 1.0, 0.0) * 0.5 * kT * (m_indep_h ** 2 - m_h ** 2) / (mobility * gap)
        return self.solver.velocities(np.einsum("p,pkc->kc", weight, forces), zero)

    def stats(self):
        """Iterations (Krylov, Lanczos) and the largest residual of the evaluation's solves."""
        stats = [s.stats for s in self._solvers]
        return {"solver_iterations": sum(s["iterations"] for s in stats),
                "solver_residual": max(s["residual"] for s in stats),
                "lanczos_iterations": sum(s["lanczos"] for s in stats)}


class ResistanceModel(HydrodynamicModel):
    """Stokesian dynamics (lubrication on) or its far field alone (lubrication off) on a
    solver backend (`sdmpi.registry.SOLVER_BACKENDS`); `at` evaluates it at a configuration."""

    def __init__(self, radii, box, *, lubrication, ewald_tol, cutoff, min_gap, backend="dense",
                 far_field=None, comm=None, tolerance=None, lanczos_tolerance=None, scheme=None,
                 separate=None, on_error=None):
        self.radii, self.box, self.comm = radii, box, comm
        self.backend = resolve_backend(backend, len(radii), comm)
        self.scheme = default_scheme(self.backend) if scheme is None else scheme
        self.lubrication, self.cutoff, self.min_gap = lubrication, cutoff, min_gap
        self.rfd_step = RFD_STEP * min_gap
        # the near-contact correction (module docstring): with lubrication, on the direct
        # backends (an iterative solve's error is amplified in the small radial parts m_h)
        matrix_free = SOLVER_BACKENDS[self.backend].matrix_free
        self.near_contact = lubrication and not matrix_free
        self._hydro = dict(lubrication=lubrication, ewald_tol=ewald_tol, cutoff=cutoff, min_gap=min_gap)
        if matrix_free:
            self._hydro["far_field"] = far_field
        self._solver_args = {} if tolerance is None else dict(tolerance=tolerance,
                                                               lanczos_tolerance=lanczos_tolerance)
        self._separate = separate  # positions, strain -> (positions, overlaps found)
        self._on_error = on_error  # LinAlgError -> exception to raise

    @classmethod
    def from_job(cls, job, radii, box, comm=None, separate=None, on_error=None):
        """The model of job.hydrodynamics.model, with lubrication when the model has it
        (`sdmpi.registry.ModelSpec`) and hydrodynamics.lubrication is on."""
        hyd = job.hydrodynamics
        return cls(radii, box, lubrication=HYDRODYNAMIC_MODELS[hyd.model].lubrication and hyd.lubrication,
                   ewald_tol=job.ewald_tolerance, cutoff=hyd.lubrication_cutoff, min_gap=hyd.min_gap,
                   backend=job.solver.backend, far_field=job.solver.far_field, comm=comm,
                   tolerance=job.solver.tolerance, lanczos_tolerance=job.solver.lanczos_tolerance,
                   scheme=job.brownian.scheme, separate=separate, on_error=on_error)

    def _guarded(self, build, *args, **kwargs):
        """build(*args, **kwargs), its LinAlgError (a matrix not positive definite) turned
        into the exception on_error makes of it (assembly, factorisation, Brownian forces)."""
        try:
            return build(*args, **kwargs)
        except np.linalg.LinAlgError as err:
            if self._on_error is None:
                raise
            raise self._on_error(err) from err

    def _assemble(self, positions, strain, plan=None):
        return self._guarded(assemble, self.backend, positions, self.radii, self.box, strain, plan=plan,
                             comm=self.comm, **self._hydro)

    def _solver(self, resistance):
        return self._guarded(make_solver, self.backend, resistance, self.comm, **self._solver_args)

    def at(self, positions, strain):
        res = self._assemble(positions, strain)
        if self.lubrication:
            pairs = res.pairs  # the lubrication pairs are the force pairs (same cut-off)
        else:
            pairs = close_pairs(res.positions, self.radii, Lattice(self.box, strain), self.cutoff, self.min_gap)
        return ResistanceEvaluation(self, res, self._solver(res), pairs, strain)

    def resistance_change(self, evaluation, positions, vector):
        """[R(positions) - R] v (N, 11) about the configuration of `evaluation`, to first
        order (`hydro.resistance.resistance_change`)."""
        return resistance_change(evaluation.resistance, positions, vector, self.min_gap)

    def displaced(self, evaluation, positions, separate):
        """The solver at displaced positions with the pair sets of `evaluation` (and its
        strain); separate: remove overlaps first (counted). Returns (solver, overlaps)."""
        found = 0
        if separate and self._separate is not None:
            positions, found = self._separate(positions, evaluation.strain)
        res = self._assemble(positions, evaluation.strain, plan=evaluation.resistance.plan)
        return self._solver(res), found


class FreeDrainingEvaluation(HydrodynamicEvaluation):
    """No hydrodynamic interactions at one configuration (module docstring)."""

    def __init__(self, radii, positions, pairs):
        self.positions, self.pairs = positions, pairs
        self.n_particles = len(radii)
        self._mobility = np.hstack([np.repeat(1 / (6 * np.pi * radii)[:, None], 3, axis=1),
                                    np.repeat(1 / (8 * np.pi * radii ** 3)[:, None], 3, axis=1)])
        self._stresslet = (20 / 3) * np.pi * radii ** 3  # R_SE per sphere

    def velocities(self, forces, einf):
        return self._mobility * forces

    def stresslets(self, velocities, einf):
        return self._stresslet[:, None] * np.asarray(einf)

    def relative_mobility(self, i, j, e):
        """1/(6 pi a_i) + 1/(6 pi a_j) of the pairs (i, j)."""
        inv = self._mobility[:, 0]
        return inv[i] + inv[j]

    def brownian(self, rng, kT, dt):
        z = rng.standard_normal((self.n_particles, 6))
        return BrownianTerms(math.sqrt(2 * kT / dt) * np.sqrt(self._mobility) * z,
                             np.zeros((self.n_particles, 5)))

    def stats(self):
        return {"solver_iterations": 0, "solver_residual": 0.0, "lanczos_iterations": 0}


class FreeDrainingModel(HydrodynamicModel):
    """Isolated-sphere mobilities (Stokes' laws) for every sphere; the force pairs within
    the cut-off are searched here."""

    def __init__(self, radii, box, *, cutoff, min_gap):
        self.radii, self.box, self.cutoff, self.min_gap = radii, box, cutoff, min_gap

    @classmethod
    def from_job(cls, job, radii, box, comm=None, separate=None, on_error=None):
        """The model for the job's cut-off and minimum gap (it solves nothing: comm,
        separate and on_error do not apply)."""
        return cls(radii, box, cutoff=job.hydrodynamics.lubrication_cutoff, min_gap=job.hydrodynamics.min_gap)

    def at(self, positions, strain):
        lattice = Lattice(self.box, strain)
        pos = lattice.wrap(positions)
        return FreeDrainingEvaluation(self.radii, pos, close_pairs(pos, self.radii, lattice, self.cutoff,
                                                                   self.min_gap))


def job_backend(job):
    """The backend a job's tasks solve on: job.solver.backend, or what "auto" stands for at
    its N on ensemble.ranks_per_task ranks (`sdmpi.registry.backend_for`)."""
    return backend_for(job.solver.backend, job.system.n_particles, job.ensemble.ranks_per_task)


def hydrodynamic_model(job, radii, box, comm=None, separate=None, on_error=None) -> HydrodynamicModel:
    """The model of job.hydrodynamics.model (its `sdmpi.registry.HYDRODYNAMIC_MODELS` entry)
    for spheres of these radii in this box (comm: the ranks that solve together;
    separate(positions, strain) -> (positions, overlaps): the overlap correction the
    midpoint scheme applies at its half step; on_error(LinAlgError) -> the exception raised
    when M_inf or R_FU is not positive definite)."""
    model = HYDRODYNAMIC_MODELS[job.hydrodynamics.model].load()
    return model.from_job(job, radii, box, comm=comm, separate=separate, on_error=on_error)
