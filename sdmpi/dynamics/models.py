"""Hydrodynamic models: what the integrator asks of the hydrodynamics at one configuration.

A model (`HydrodynamicModel`, built from the job's keys in a `HydrodynamicSetting` by
`sdmpi.dynamics.setup` from the entry of hydrodynamics.model in
`sdmpi.registry.HYDRODYNAMIC_MODELS`) is evaluated at a
configuration, ``model.at(positions, strain)``, which assembles and factorises whatever the
model needs and returns an *evaluation* (`HydrodynamicEvaluation`) with

* ``velocities(forces, einf)``: rigid-body velocities relative to the imposed flow, (N, 6)
  U', Omega' = R_FU^-1 (F + R_FE e_inf) for forces/torques (N, 6) and E_inf (N, 5);
* ``stresslets(velocities, einf)``: S = R_SE e_inf - R_SU U' (N, 5);
* ``brownian(rng, kT, dt)``: a `BrownianTerms` of the step, the Brownian velocities
  R_FU^-1 F_B + kT div R_FU^-1 (drift included; F_B of covariance 2 kT R_FU / dt) and an
  estimate of the Brownian stresslets -kT div(R_SU R_FU^-1) (Schaink et al. 2000, eq. 16);
* ``pairs``: the pairs within the interparticle-force cut-off (`lubrication.PairList`,
  true gaps), ``relative_mobility(i, j, e)``: each pair's mobility of relative motion
  along its line of centres (for the collision forces of `collisions`), ``stats()``: solver
  statistics of the evaluation.

Models (``hydrodynamics.model``, registered in `sdmpi.registry.HYDRODYNAMIC_MODELS`):

* ``stokesian``: full Stokesian dynamics, R = M_inf^-1 + lubrication (Durlofsky, Brady &
  Bossis 1987; Brady et al. 1988), on any solver backend (`sdmpi.registry.SOLVER_BACKENDS`);
* ``far-field``: the periodic far-field (Rotne-Prager-level, FTS) mobility alone, R = M_inf^-1,
  no lubrication: Brownian dynamics with hydrodynamic interactions;
* ``free-draining``: no hydrodynamic interactions, R_FU = diag(6 pi a, 8 pi a^3),
  R_SE e = (20/3) pi a^3 E, R_SU = 0: zero drift, no factorisation.

The Brownian terms of the resistance models come from their drift scheme
(``brownian.scheme``, `sdmpi.dynamics.drift`, registered in `sdmpi.registry.DRIFT_SCHEMES`)
and, with lubrication and a scheme derived for it (`sdmpi.registry.DriftSpec.near_contact`:
the random finite differences), the near-contact correction beside them
(`sdmpi.dynamics.drift.near_contact_velocities`); derivations in docs/numerics.md, "Drift
schemes and the near-contact correction".
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..hydro.geometry import Lattice
from ..hydro.lubrication import PairList, close_pairs
from ..hydro.resistance import mobility_change
from ..hydro.solvers import assemble, make_solver, resolve_backend
from ..registry import DRIFT_SCHEMES, SOLVER_BACKENDS, default_drift_scheme
from .drift import BrownianTerms, near_contact_velocities, unit_pair_forces


@dataclass(frozen=True)
class HydrodynamicSetting:
    """The job's keys a hydrodynamic model may read (built by `sdmpi.dynamics.setup`).

    Attributes:
        lubrication: pairwise lubrication on (the model has it and
            hydrodynamics.lubrication is true).
        ewald_tolerance: the Ewald sums' tolerance (hydrodynamics.ewald_tolerance or its
            default).
        cutoff: the lubrication and force cut-off (hydrodynamics.lubrication_cutoff, mean radii).
        min_gap: the lubrication's floor (hydrodynamics.min_gap, mean radii).
        backend: solver.backend (a name, or "auto").
        far_field: solver.far_field (the matrix-free backends' far field).
        tolerance: solver.tolerance, or None.
        lanczos_tolerance: solver.lanczos_tolerance, or None.
        scheme: brownian.scheme, or None for the backend's default.
    """

    lubrication: bool
    ewald_tolerance: float
    cutoff: float
    min_gap: float
    backend: str = "dense"
    far_field: str | None = None
    tolerance: float | None = None
    lanczos_tolerance: float | None = None
    scheme: str | None = None


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
        forces/torques (N, 6) and E_inf (N, 5).

        Args:
            forces: forces and torques (N, 6), in eta_m a^2/t_D and eta_m a^3/t_D.
            einf: E_inf per sphere (N, 5) in the 5-basis, in 1/t_D.

        Returns:
            (U', Omega') (N, 6), in a/t_D and 1/t_D.
        """
        raise NotImplementedError

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """S (N, 5) = R_SE e_inf - R_SU U' for rigid-body velocities (N, 6) and E_inf (N, 5).

        Args:
            velocities: (U', Omega') (N, 6), in a/t_D and 1/t_D.
            einf: E_inf per sphere (N, 5) in the 5-basis, in 1/t_D.

        Returns:
            S (N, 5) in the 5-basis, in eta_m a^3/t_D.
        """
        raise NotImplementedError

    def relative_mobility(self, i: np.ndarray, j: np.ndarray, e: np.ndarray) -> np.ndarray:
        """(P,) mobility of relative motion e.(M_jj + M_ii - M_ij - M_ji).e of the pairs
        (i, j) along their unit lines of centres e (P, 3), M = R_FU^-1.

        Args:
            i: first particles of the pairs, shape (P,).
            j: second particles, shape (P,).
            e: unit lines of centres from i to j, shape (P, 3).

        Returns:
            Relative mobilities, shape (P,), in 1/(eta_m a).
        """
        raise NotImplementedError

    def brownian(self, rng: np.random.Generator, kT: float, dt: float) -> BrownianTerms:
        """The step's Brownian velocities (drift included) and stresslets, drawn from rng.

        Args:
            rng: the realisation's random stream.
            kT: thermal energy (6 pi in reduced units; 0 without Brownian motion).
            dt: the step's duration (t_D).

        Returns:
            The step's `BrownianTerms`: velocities (N, 6) in a/t_D and 1/t_D, stresslets
            (N, 5) in eta_m a^3/t_D.
        """
        raise NotImplementedError

    def stats(self) -> dict[str, float]:
        """Solver statistics of the evaluation: solver_iterations, solver_residual,
        lanczos_iterations (zero for the direct backends).

        Returns:
            solver_iterations, solver_residual (relative), lanczos_iterations.
        """
        raise NotImplementedError


class HydrodynamicModel(Protocol):
    """A hydrodynamic model of spheres of given radii in a box, registered in
    `sdmpi.registry.HYDRODYNAMIC_MODELS` (docs/extending.md)."""

    @classmethod
    def build(cls, setting: HydrodynamicSetting, radii: np.ndarray, box: np.ndarray, comm: Any = None,
              separate: Callable | None = None, on_error: Callable | None = None) -> HydrodynamicModel:
        """The model for these spheres (built by `sdmpi.dynamics.setup.hydrodynamic_model`).

        Args:
            setting: the job's hydrodynamic keys (`HydrodynamicSetting`).
            radii: sphere radii, shape (N,), in a.
            box: box sides (3,), in a.
            comm: the MPI communicator of the ranks that solve together, or None.
            separate: separate(positions, strain) -> (positions, overlaps), the midpoint
                overlap correction, or None.
            on_error: on_error(LinAlgError) -> the exception to raise, or None.

        Returns:
            The model.
        """
        raise NotImplementedError

    def at(self, positions: np.ndarray, strain: float) -> HydrodynamicEvaluation:
        """The model evaluated at ``positions`` (N, 3) with the box at Lees-Edwards ``strain``.

        Args:
            positions: centres, shape (N, 3), in a.
            strain: Lees-Edwards strain of the box, dimensionless.

        Returns:
            The evaluation at that configuration.
        """
        raise NotImplementedError


class ResistanceEvaluation(HydrodynamicEvaluation):
    """A resistance model (stokesian, far-field) at one configuration: its resistance
    (`hydro.resistance`), the backend's solver of it, and the force pair list."""

    def __init__(self, model, resistance, solver, pairs, strain):
        self.model, self.resistance, self.solver, self.pairs = model, resistance, solver, pairs
        self.strain = strain
        self.positions = resistance.positions
        self.n_particles = resistance.n_particles
        self._stats = [solver.stats]  # of its solver and the displaced ones (not the solvers:
        # a displaced solver is freed as soon as its caller is done with it)
        self._last_draw = False  # brownian() is drawing: the evaluation's last draw

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """U', Omega' = R_FU^-1 (F + R_FE e_inf) by the backend's solver."""
        return self.solver.velocities(forces, einf)

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """S = R_SE e_inf - R_SU U' by the backend's solver."""
        return self.solver.stresslets(velocities, einf)

    def relative_mobility(self, i: np.ndarray, j: np.ndarray, e: np.ndarray) -> np.ndarray:
        """e.(M_jj + M_ii - M_ij - M_ji).e of the pairs (i, j) with unit lines of centres
        e (M = R_FU^-1): f.M.f for unit and opposite forces f on j and i (`unit_pair_forces`)."""
        return self.solver.mobility_forms(unit_pair_forces(i, j, e, self.n_particles))

    @property
    def radii(self) -> np.ndarray:
        """(N,) sphere radii.

        Returns:
            The radii, in a.
        """
        return self.model.radii

    @property
    def min_gap(self) -> float:
        """hydrodynamics.min_gap (mean radii).

        Returns:
            The minimum gap, in mean radii.
        """
        return self.model.min_gap

    def brownian(self, rng: np.random.Generator, kT: float, dt: float) -> BrownianTerms:
        """The step's Brownian terms (`brownian_terms`) for noise drawn from rng: z, then z'
        of the near-contact correction where the model has one, then the stresslets' own
        draw where the drift scheme takes one (`sdmpi.registry.DriftSpec.stress_draw`).
        The evaluation's last draw (the step's): once the scheme has drawn its forces, the
        solver frees what only they need and what it can compute again (`forces_drawn`;
        on petsc-krylov the pairs' factors, after which further draws are refused, and
        the spectral far field's real-space blocks), so that a Brownian midpoint is built
        without them (`brownian_terms` draws any number of samples)."""
        self._last_draw = True
        shape = self.solver.noise_shape
        z = rng.standard_normal(shape)
        z_near = rng.standard_normal(shape) if self.model.near_contact else None
        z_stress = rng.standard_normal(shape) if self.model.stress_draw else None
        # the iterative backend's Brownian forces (Lanczos) need a positive definite M_inf
        return self.model._guarded(self.brownian_terms, z, kT, dt, z_near, z_stress)

    def brownian_terms(self, z: np.ndarray, kT: float, dt: float, z_near: np.ndarray | None = None,
                       z_stress: np.ndarray | None = None) -> BrownianTerms:
        """The step's `BrownianTerms` by the model's drift scheme (`drift`) for the standard
        normal noise z (the solver's noise_shape); z_near: the independent noise z' of the
        near-contact correction (`drift.near_contact_velocities`; None: no correction).

        Args:
            z: standard normal noise, shape solver.noise_shape.
            kT: thermal energy (6 pi in reduced units).
            dt: the step's duration (t_D).
            z_near: standard normal noise of the near-contact correction, same shape, or None.
            z_stress: the stresslets' own standard normal draw (same shape) of a scheme
                that takes one, or None.

        Returns:
            The step's `BrownianTerms`: velocities (N, 6) in a/t_D and 1/t_D, stresslets
            (N, 5) in eta_m a^3/t_D.
        """
        def near(m):
            return 0.0 if z_near is None else near_contact_velocities(self, m, z_near, kT, dt)

        return self.model.drift.brownian(self, z, kT, dt, near, z_stress)

    def forces_drawn(self) -> None:
        """The drift scheme has drawn its sample's Brownian forces: in the evaluation's last
        draw (`brownian`) the solver frees what only they need
        (`sdmpi.hydro.backend.SolverBackend.forces_drawn`), else nothing."""
        if self._last_draw:
            self.solver.forces_drawn()

    def displaced(self, positions: np.ndarray) -> tuple[Any, int]:
        """The solver at ``positions`` with this evaluation's pair sets and strain, for solves
        (it draws no Brownian forces), overlaps first separated (counted); its solves join
        `stats`. Returns (solver, overlaps).

        Args:
            positions: displaced centres, shape (N, 3), in a.

        Returns:
            (the backend's solver there, number of overlapping pairs separated first).
        """
        solver, found = self.model.displaced(self, positions, separate=True)
        self._stats.append(solver.stats)
        return solver, found

    def mobility_change(self, positions: np.ndarray, velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(du, ds) of the velocities m = R_FU^-1 F at nearby positions, to first order in
        Delta R = R(positions) - R: du = -R_FU^-1 Delta R_FU m, ds = -(Delta R_SU m +
        R_SU du). On the direct backends from Delta R (m, 0) and the solver
        (`hydro.resistance.mobility_change`); on the matrix-free ones from one solve of the
        change (`hydro.krylov.KrylovSolver.mobility_change`).

        Args:
            positions: nearby centres, shape (N, 3), in a.
            velocities: m, shape (N, 6), in a/t_D and 1/t_D: a solve's velocities for
                forces without imposed strain.

        Returns:
            (du (N, 6) in a/t_D and 1/t_D, ds (N, 5) in eta_m a^3/t_D).
        """
        if SOLVER_BACKENDS[self.model.backend].matrix_free:
            return self.solver.mobility_change(positions, velocities, self.min_gap)
        return mobility_change(self.resistance, self.solver, positions, velocities, self.min_gap)

    def stats(self) -> dict[str, float]:
        """Iterations (Krylov, Lanczos) and the largest residual of the evaluation's solves."""
        stats = self._stats
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
        self.scheme = default_drift_scheme(self.backend) if scheme is None else scheme
        self.drift = DRIFT_SCHEMES[self.scheme].load()()
        self.stress_draw = DRIFT_SCHEMES[self.scheme].stress_draw
        self.lubrication, self.cutoff, self.min_gap = lubrication, cutoff, min_gap
        # the near-contact correction (`drift`): with lubrication, for the schemes derived for it
        self.near_contact = lubrication and DRIFT_SCHEMES[self.scheme].near_contact
        self._hydro = dict(lubrication=lubrication, ewald_tol=ewald_tol, cutoff=cutoff, min_gap=min_gap)
        if SOLVER_BACKENDS[self.backend].matrix_free:
            self._hydro["far_field"] = far_field
        self._solver_args = {} if tolerance is None else dict(tolerance=tolerance,
                                                               lanczos_tolerance=lanczos_tolerance)
        self._separate = separate  # positions, strain -> (positions, overlaps found)
        self._on_error = on_error  # LinAlgError -> exception to raise
        self._held = None  # (positions, strain) of the far field held (`hold_far_field`)
        self._held_blocks = None  # its far-field blocks, computed on first use

    @classmethod
    def build(cls, setting: HydrodynamicSetting, radii: np.ndarray, box: np.ndarray, comm: Any = None,
              separate: Callable | None = None, on_error: Callable | None = None) -> ResistanceModel:
        """The model with the setting's lubrication, Ewald sums, solver backend and drift scheme."""
        return cls(radii, box, lubrication=setting.lubrication, ewald_tol=setting.ewald_tolerance,
                   cutoff=setting.cutoff, min_gap=setting.min_gap, backend=setting.backend,
                   far_field=setting.far_field, comm=comm, tolerance=setting.tolerance,
                   lanczos_tolerance=setting.lanczos_tolerance, scheme=setting.scheme, separate=separate,
                   on_error=on_error)

    def _guarded(self, build, *args, **kwargs):
        """build(*args, **kwargs), its LinAlgError (a matrix not positive definite) turned
        into the exception on_error makes of it (assembly, factorisation, Brownian forces)."""
        try:
            return build(*args, **kwargs)
        except np.linalg.LinAlgError as err:
            if self._on_error is None:
                raise
            raise self._on_error(err) from err

    def _assemble(self, positions, strain, plan=None, brownian=True, lubrication=None, **far):
        hydro = self._hydro if lubrication is None else {**self._hydro, "lubrication": lubrication}
        return self._guarded(assemble, self.backend, positions, self.radii, self.box, strain, plan=plan,
                             comm=self.comm, brownian=brownian, **hydro, **far)

    def hold_far_field(self, positions: np.ndarray, strain: float) -> None:
        """From now on, evaluate with the far-field mobility of (positions, strain) and the
        lubrication of each evaluation's own configuration (hydrodynamics.far_field_refresh;
        the direct backends, whose resistance holds the far field's blocks). The blocks are
        computed at the next evaluation, so that a state restored with the positions of the
        last refresh evaluates as the run it was saved from.

        Args:
            positions: centres of the refresh, shape (N, 3), in a (copied).
            strain: Lees-Edwards strain at the refresh, dimensionless.
        """
        self._held, self._held_blocks = (np.array(positions, dtype=float), strain), None

    def _far(self):
        """{"far": the held far-field blocks (S^-1, X, U_b)}, or {} when none is held."""
        if self._held is None:
            return {}
        if self._held_blocks is None:  # the far field alone (its blocks do not depend on the lubrication)
            res = self._assemble(*self._held, lubrication=False)
            self._held_blocks = (res.s_inverse, res.x_ab, res.chol_bb)
        return {"far": self._held_blocks}

    def _solver(self, resistance):
        return self._guarded(make_solver, self.backend, resistance, self.comm, **self._solver_args)

    def at(self, positions: np.ndarray, strain: float) -> ResistanceEvaluation:
        """The resistance assembled and factorised at ``positions`` (N, 3), box at ``strain``."""
        res = self._assemble(positions, strain, **self._far())
        if self.lubrication:
            pairs = res.pairs  # the lubrication pairs are the force pairs (same cut-off)
        else:
            pairs = close_pairs(res.positions, self.radii, Lattice(self.box, strain), self.cutoff, self.min_gap)
        return ResistanceEvaluation(self, res, self._solver(res), pairs, strain)

    def displaced(self, evaluation: ResistanceEvaluation, positions: np.ndarray,
                  separate: bool) -> tuple[Any, int]:
        """The solver at displaced positions with the pair sets of `evaluation` (and its
        strain), for solves (it draws no Brownian forces); separate: remove overlaps first
        (counted). Returns (solver, overlaps).

        Args:
            evaluation: the evaluation whose pair sets and strain are kept.
            positions: displaced centres, shape (N, 3), in a.
            separate: whether to separate overlapping pairs first.

        Returns:
            (the backend's solver there, number of overlapping pairs separated).
        """
        found = 0
        if separate and self._separate is not None:
            positions, found = self._separate(positions, evaluation.strain)
        res = self._assemble(positions, evaluation.strain, plan=evaluation.resistance.plan, brownian=False)
        return self._solver(res), found


class FreeDrainingEvaluation(HydrodynamicEvaluation):
    """No hydrodynamic interactions at one configuration (module docstring)."""

    def __init__(self, radii, positions, pairs):
        self.positions, self.pairs = positions, pairs
        self.n_particles = len(radii)
        self._mobility = np.hstack([np.repeat(1 / (6 * np.pi * radii)[:, None], 3, axis=1),
                                    np.repeat(1 / (8 * np.pi * radii ** 3)[:, None], 3, axis=1)])
        self._stresslet = (20 / 3) * np.pi * radii ** 3  # R_SE per sphere

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """Stokes' laws: U = F/(6 pi a), Omega = T/(8 pi a^3); E_inf moves no sphere."""
        return self._mobility * forces

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """S = (20/3) pi a^3 E_inf per sphere, independent of the velocities."""
        return self._stresslet[:, None] * np.asarray(einf)

    def relative_mobility(self, i: np.ndarray, j: np.ndarray, e: np.ndarray) -> np.ndarray:
        """1/(6 pi a_i) + 1/(6 pi a_j) of the pairs (i, j)."""
        inv = self._mobility[:, 0]
        return inv[i] + inv[j]

    def brownian(self, rng: np.random.Generator, kT: float, dt: float) -> BrownianTerms:
        """Independent Brownian velocities (2 kT M / dt)^1/2 z per sphere, no drift, zero
        Brownian stresslets."""
        z = rng.standard_normal((self.n_particles, 6))
        return BrownianTerms(math.sqrt(2 * kT / dt) * np.sqrt(self._mobility) * z,
                             np.zeros((self.n_particles, 5)))

    def stats(self) -> dict[str, float]:
        """Nothing is solved: all zero."""
        return {"solver_iterations": 0, "solver_residual": 0.0, "lanczos_iterations": 0}


class FreeDrainingModel(HydrodynamicModel):
    """Isolated-sphere mobilities (Stokes' laws) for every sphere; the force pairs within
    the cut-off are searched here."""

    def __init__(self, radii, box, *, cutoff, min_gap):
        self.radii, self.box, self.cutoff, self.min_gap = radii, box, cutoff, min_gap

    @classmethod
    def build(cls, setting: HydrodynamicSetting, radii: np.ndarray, box: np.ndarray, comm: Any = None,
              separate: Callable | None = None, on_error: Callable | None = None) -> FreeDrainingModel:
        """The model for the setting's cut-off and minimum gap (it solves nothing: comm,
        separate and on_error do not apply)."""
        return cls(radii, box, cutoff=setting.cutoff, min_gap=setting.min_gap)

    def at(self, positions: np.ndarray, strain: float) -> FreeDrainingEvaluation:
        """The spheres at ``positions`` (N, 3), wrapped, with their force pairs, box at ``strain``."""
        lattice = Lattice(self.box, strain)
        pos = lattice.wrap(positions)
        return FreeDrainingEvaluation(self.radii, pos, close_pairs(pos, self.radii, lattice, self.cutoff,
                                                                   self.min_gap))
