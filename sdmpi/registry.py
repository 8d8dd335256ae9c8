"""The registries of sdmpi's extension points: solver backends, hydrodynamic models, drift
schemes, integrators, interparticle forces and the writers of the run file.

A registry maps a name, as a job file spells it (``solver.backend``,
``hydrodynamics.model``, ``brownian.scheme``, ``integration.scheme``,
``interparticle.kind``; a writer's own name), to an entry: a frozen spec that declares what the job loader,
the checks, the resource estimates, the command line and the key reference need to know
of an implementation, and where the implementation is (the class itself, or
``"module:Class"``, imported on first use). Every list of choices users see is read from
here. This module uses only the standard library, so that `sdmpi.config` derives its
choices and checks from it without importing the numerical packages; `sdmpi.hydro.solvers`,
`sdmpi.dynamics.setup` and `sdmpi.ensemble.writers` build the implementations it names.

Adding an implementation: docs/extending.md. In short, one module with the class
(`sdmpi.hydro.backend.SolverBackend`, `sdmpi.dynamics.models.HydrodynamicModel`,
`sdmpi.dynamics.drift.DriftScheme`, `sdmpi.dynamics.integrators.Integrator`,
`sdmpi.ensemble.writers.Writer`, or a builder of `sdmpi.dynamics.forces.Force` objects) and one
``register``: an entry below for those shipped with sdmpi, or a call of
``SOLVER_BACKENDS.register(BackendSpec(...))`` in the user's own module before the job is
loaded.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

#: bytes of one entry of a dense matrix (double precision)
DOUBLE = 8.0


def _load(implementation: Any) -> Any:
    """The object ``implementation`` stands for: itself, or the attribute named by a
    ``"module:attribute"`` string, imported now."""
    if not isinstance(implementation, str):
        return implementation
    module, _, attribute = implementation.partition(":")
    return getattr(importlib.import_module(module), attribute)


@dataclass(frozen=True)
class Spec:
    """An implementation of an extension point, as sdmpi's job checks know it: its
    ``name`` (the job key's value), ``summary`` (one phrase for the key reference and
    ``sdmpi validate``) and ``implementation`` (the class, or "module:Class")."""

    name: str
    summary: str
    implementation: Any

    def load(self) -> Any:
        """The implementation class (imported on first use)."""
        return _load(self.implementation)


@dataclass(frozen=True)
class BackendSpec(Spec):
    """A solver backend of the resistance problem, as sdmpi's job checks know it.

    Attributes:
        name: its solver.backend value.
        summary: what it is, one phrase (the key reference, ``sdmpi validate``).
        implementation: a `sdmpi.hydro.backend.SolverBackend` class, or "module:Class".
        matrix_free: solves without forming R, iteratively, from a
            `sdmpi.hydro.resistance.SplitResistance` (solver.far_field applies); such a
            backend gets the drift schemes that suit it (`DriftSpec.matrix_free`).
        mobility_change: a matrix-free backend whose solver implements
            ``mobility_change`` (the first-order change of a solve at nearby positions,
            `sdmpi.hydro.krylov.KrylovSolver.mobility_change`): it runs the random finite
            differences too (the direct backends always do).
        several_ranks: a task may solve on several ranks (ensemble.ranks_per_task > 1).
        needs_petsc: needs petsc4py (``sdmpi run`` refuses the job where it is missing).
        dense_matrices: how many (11 N)^2 matrices of doubles a task holds at once (the
            memory estimate), spread over the task's ranks.
        bytes_per_particle: bytes per sphere that every rank of a task holds besides the
            dense matrices (the memory estimate of an O(N) backend, measured).
        spread_bytes_per_particle: bytes per sphere spread over the task's ranks (the
            same, for the part each rank holds a share of).
        drift_scheme: the brownian.scheme it runs where the key is absent ("": the first
            registered that suits it).
    """

    matrix_free: bool = False
    several_ranks: bool = False
    needs_petsc: bool = False
    dense_matrices: int = 0
    bytes_per_particle: float = 0.0
    spread_bytes_per_particle: float = 0.0
    mobility_change: bool = False
    drift_scheme: str = ""

    def memory_per_rank(self, n_particles: int, ranks: int) -> float:
        """Bytes per rank of the solver's data for N spheres solved on ``ranks`` ranks."""
        spread = self.dense_matrices * (11 * n_particles) ** 2 * DOUBLE + self.spread_bytes_per_particle * n_particles
        return spread / ranks + self.bytes_per_particle * n_particles

    def memory_text(self) -> str:
        """What memory_per_rank counts, for people."""
        if self.dense_matrices:
            return f"{self.dense_matrices} matrices of (11 N)^2 doubles"
        if self.bytes_per_particle or self.spread_bytes_per_particle:
            return (f"~{self.bytes_per_particle / 1024:.0f} KiB per sphere on every rank of a task "
                    f"and {self.spread_bytes_per_particle / 1024:.0f} KiB shared by them")
        return "no solver matrices"


@dataclass(frozen=True)
class ModelSpec(Spec):
    """A hydrodynamic model, as sdmpi's job checks know it.

    Attributes:
        name: its hydrodynamics.model value.
        summary: what it is, one phrase (the key reference).
        implementation: a `sdmpi.dynamics.models.HydrodynamicModel` class, or
            "module:Class".
        lubrication: it has the pairwise lubrication (hydrodynamics.lubrication applies;
            monolayers and frictional contacts need it; pairs in contact are separated by
            default, hydrodynamics.collisions).
        solves: it solves a resistance problem on solver.backend (False: nothing to solve,
            no solver memory, one rank per task, no drift scheme).
    """

    lubrication: bool = False
    solves: bool = True


@dataclass(frozen=True)
class DriftSpec(Spec):
    """A drift scheme of the resistance models (brownian.scheme), as sdmpi's job checks know it.

    Attributes:
        name: its brownian.scheme value.
        summary: what it is, one phrase (the key reference).
        implementation: a `sdmpi.dynamics.drift.DriftScheme` class (built without
            arguments), or "module:Class".
        matrix_free: it suits every matrix-free (iterative) backend (`BackendSpec.matrix_free`);
            every scheme suits the direct ones and those with `BackendSpec.mobility_change`.
        why_not: why it does not suit the matrix-free backends (the checks' message).
        stress_draw: it estimates the Brownian stresslets from a standard normal draw of
            their own (the ``z_stress`` of `sdmpi.dynamics.drift.DriftScheme.brownian`),
            drawn after the step's other noise.
        near_contact: with lubrication it takes the near-contact correction
            (`sdmpi.dynamics.drift.near_contact_velocities`, derived for a step whose drift
            is taken along its own direction at its start: the random finite differences).
    """

    matrix_free: bool = True
    why_not: str = ""
    stress_draw: bool = False
    near_contact: bool = True


@dataclass(frozen=True)
class IntegratorSpec(Spec):
    """A time integrator (integration.scheme), as sdmpi's job checks know it.

    Attributes:
        name: its integration.scheme value.
        summary: what it is, one phrase (the key reference).
        implementation: a `sdmpi.dynamics.integrators.Integrator` class, or "module:Class".
        brownian: it integrates Brownian motion (False: brownian.enabled = true is refused).
        contacts: it integrates the forces with contacts (`ForceSpec.contacts`, the frictional
            ones: their tangential springs are state advanced by each step's velocities).
    """

    brownian: bool = True
    contacts: bool = True


@dataclass(frozen=True)
class ForceSpec(Spec):
    """An interparticle force (interparticle.kind), as sdmpi's job checks know it.

    Attributes:
        name: its interparticle.kind value.
        summary: what it is, one phrase (the key reference).
        implementation: a builder, ``build(setting, **keys) -> list of
            sdmpi.dynamics.forces.Force`` (``setting`` a `sdmpi.dynamics.forces.ForceSetting`,
            ``keys`` the values of the [interparticle] keys named in ``keys``, in the job's
            units), or "module:function".
        keys: the [interparticle] keys it reads, passed to the builder by name.
        brownian: it may act in Brownian jobs (False: brownian.enabled = true is refused).
        monolayer: it may act in monolayers (system.geometry = "monolayer").
        contacts: overlapping pairs are its contacts, with a history that each step's
            velocities advance: overlaps are kept (not corrected), the model needs
            lubrication and the integrator must integrate contacts
            (`IntegratorSpec.contacts`).
    """

    keys: tuple[str, ...] = ()
    brownian: bool = True
    monolayer: bool = False
    contacts: bool = False


E = TypeVar("E", bound=Spec)


class Registry(Generic[E]):
    """Entries by name in registration order, for the job key ``key``; ``rules`` are
    further choices of that key that stand for an entry (solver.backend = "auto"), with
    their summaries."""

    def __init__(self, key: str, rules: dict[str, str] | None = None):
        self.key = key
        self.rules = dict(rules or {})
        self._entries: dict[str, E] = {}

    def register(self, entry: E) -> E:
        """Add ``entry`` under ``entry.name`` (ValueError if the name is taken)."""
        if entry.name in self._entries or entry.name in self.rules:
            raise ValueError(f"{self.key}: {entry.name!r} is registered already")
        self._entries[entry.name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove the entry ``name``."""
        del self._entries[name]

    def __getitem__(self, name: str) -> E:
        try:
            return self._entries[name]
        except KeyError:
            raise ValueError(f"{self.key} must be one of {list(self._entries)}, got {name!r}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[E]:
        return iter(tuple(self._entries.values()))

    def names(self, where: Callable[[E], bool] = lambda entry: True) -> tuple[str, ...]:
        """The names of the entries (those for which ``where(entry)`` holds)."""
        return tuple(entry.name for entry in self if where(entry))

    def choices(self) -> tuple[str, ...]:
        """Every value the job key may take: the names, then the rules."""
        return (*self._entries, *self.rules)

    def summaries(self) -> str:
        """The key's documentation: "name = summary" of every choice, joined by "; "."""
        return "; ".join([f"{e.name} = {e.summary}" for e in self] + [f"{r} = {s}" for r, s in self.rules.items()])


# --------------------------------------------------------------------------- solver backends

AUTO = "auto"
#: `auto` picks petsc-krylov from this many particles on when a task has one rank: below,
#: dense is the faster at the default tolerances (its peak at N = 1000: 2.2 GiB, against
#: 0.5 GiB for petsc-krylov), from here on petsc-krylov, the leaner, is as fast or faster
#: (bench/bench_krylov.py: docs/numerics.md, "Parameter choices")
AUTO_KRYLOV_MIN_N_ONE_RANK = 1000
#: the same for a task of several ranks: petsc-dense assembles the whole R on every rank,
#: so petsc-krylov, which shares its work between the ranks, takes over earlier
AUTO_KRYLOV_MIN_N = 300
#: petsc-krylov's memory per sphere at phi = 0.45, tolerances 1e-4 (bytes): every rank holds
#: about KRYLOV_BYTES, the task's ranks share KRYLOV_SPREAD_BYTES (real-space blocks,
#: lubrication, stencils of the start and the midpoint, work vectors): with the 300 MiB base
#: 1.06-1.28 x the peak resident memory per rank measured at N = 1000 on one rank and at
#: N = 1000, 4096 and 10 000 on two (bench/memory.py, bench/krylov_shares.py; docs/performance.md)
KRYLOV_BYTES, KRYLOV_SPREAD_BYTES = 40e3, 70e3
#: 11N x 11N matrices alive at once in a dense evaluation, rounded up (it holds 218 N^2
#: doubles: S^-1, X, U_b, the lubrication's dense partitions and R_FU's factor; assembling
#: one peaks at 242 N^2; the midpoint scheme holds one evaluation while it assembles
#: another: 460 N^2 = 3.8 (11N)^2)
DENSE_MATRICES = 4

SOLVER_BACKENDS: Registry[BackendSpec] = Registry("solver.backend", {
    AUTO: f"dense below {AUTO_KRYLOV_MIN_N_ONE_RANK} particles on one rank per task, petsc-dense below "
          f"{AUTO_KRYLOV_MIN_N} on several, else petsc-krylov"})
SOLVER_BACKENDS.register(BackendSpec(
    "dense", "LAPACK Cholesky on one rank", "sdmpi.hydro.solvers:DenseSolver",
    dense_matrices=DENSE_MATRICES))
SOLVER_BACKENDS.register(BackendSpec(
    "petsc-dense", "ScaLAPACK Cholesky over the task's ranks", "sdmpi.hydro.petsc_dense:PetscDenseSolver",
    several_ranks=True, needs_petsc=True, dense_matrices=DENSE_MATRICES))
SOLVER_BACKENDS.register(BackendSpec(
    "petsc-krylov", "matrix-free mixed-form GMRES and Lanczos Brownian forces (large N)",
    "sdmpi.hydro.krylov:KrylovSolver", matrix_free=True, several_ranks=True, needs_petsc=True,
    bytes_per_particle=KRYLOV_BYTES, spread_bytes_per_particle=KRYLOV_SPREAD_BYTES, mobility_change=True,
    drift_scheme="midpoint"))


def backend_for(name: str, n_particles: int, ranks: int) -> str:
    """The backend solver.backend = ``name`` stands for with ``ranks`` ranks per task:
    itself, or for "auto" dense below AUTO_KRYLOV_MIN_N_ONE_RANK particles (one rank),
    petsc-dense below AUTO_KRYLOV_MIN_N (several ranks), else petsc-krylov. The choice
    depends on N and the ranks alone, so a job resolves to the same backend on every
    machine. ValueError for an unknown name."""
    if name != AUTO:
        return SOLVER_BACKENDS[name].name
    if ranks == 1:
        return "dense" if n_particles < AUTO_KRYLOV_MIN_N_ONE_RANK else "petsc-krylov"
    return "petsc-dense" if n_particles < AUTO_KRYLOV_MIN_N else "petsc-krylov"


def several_rank_choices() -> tuple[str, ...]:
    """The solver.backend choices that may run a task on several ranks: the backends that
    can, and "auto" (which picks one of them there)."""
    return (*SOLVER_BACKENDS.names(lambda backend: backend.several_ranks), AUTO)


# --------------------------------------------------------------------------- hydrodynamic models

HYDRODYNAMIC_MODELS: Registry[ModelSpec] = Registry("hydrodynamics.model")
HYDRODYNAMIC_MODELS.register(ModelSpec(
    "stokesian", "far field + lubrication (Stokesian dynamics)", "sdmpi.dynamics.models:ResistanceModel",
    lubrication=True))
HYDRODYNAMIC_MODELS.register(ModelSpec(
    "far-field", "the periodic far-field (Rotne-Prager-level FTS) mobility alone",
    "sdmpi.dynamics.models:ResistanceModel"))
HYDRODYNAMIC_MODELS.register(ModelSpec(
    "free-draining", "none (Stokes drag of isolated spheres)", "sdmpi.dynamics.models:FreeDrainingModel",
    solves=False))


# --------------------------------------------------------------------------- drift schemes

#: brownian.scheme absent: the backend's `BackendSpec.drift_scheme`, or the first registered scheme that suits it
DRIFT_SCHEMES: Registry[DriftSpec] = Registry("brownian.scheme")
_RFD_NEEDS = ("the random finite difference needs the change of a solve at nearby positions "
              "(mobility_change), which this matrix-free backend does not provide")
DRIFT_SCHEMES.register(DriftSpec(
    "rfd", "random finite difference at every step (exact in the mean at every gap)",
    "sdmpi.dynamics.drift:RandomFiniteDifference", matrix_free=False, why_not=_RFD_NEEDS))
DRIFT_SCHEMES.register(DriftSpec(
    "rfd-split", "rfd, the Brownian stresslets from a random finite difference along a draw of their "
    "own, independent of the step's displacement (a control for stress correlations at rest; one "
    "more solve per step)",
    "sdmpi.dynamics.drift:SplitRandomFiniteDifference", matrix_free=False, why_not=_RFD_NEEDS,
    stress_draw=True))
DRIFT_SCHEMES.register(DriftSpec(
    "midpoint", "Fixman's midpoint (too small a drift at gaps below ~4 dt; no near-contact correction)", "sdmpi.dynamics.drift:Midpoint",
    near_contact=False))


def drift_schemes_for(backend: str) -> tuple[str, ...]:
    """The brownian.scheme values that suit the solver backend ``backend`` (a registered
    name), the default first."""
    spec = SOLVER_BACKENDS[backend]
    suits = DRIFT_SCHEMES.names(lambda scheme: scheme.matrix_free or not spec.matrix_free or spec.mobility_change)
    first = spec.drift_scheme or suits[0]
    return (first, *(name for name in suits if name != first))


def default_drift_scheme(backend: str) -> str:
    """The drift scheme a backend gets when brownian.scheme is absent: its
    `BackendSpec.drift_scheme`, else the first registered that suits it (rfd on the direct
    backends, midpoint on petsc-krylov)."""
    return drift_schemes_for(backend)[0]


# --------------------------------------------------------------------------- integrators

INTEGRATORS: Registry[IntegratorSpec] = Registry("integration.scheme")
INTEGRATORS.register(IntegratorSpec(
    "euler-maruyama", "explicit Euler-Maruyama, the hydrodynamics evaluated once per step",
    "sdmpi.dynamics.integrators:EulerMaruyama"))
INTEGRATORS.register(IntegratorSpec(
    "adams-bashforth-4", "fourth-order Adams-Bashforth (non-Brownian jobs; Dratler & Schowalter "
    "1996), started by three classical Runge-Kutta steps", "sdmpi.dynamics.integrators:AdamsBashforth4",
    brownian=False, contacts=False))


# --------------------------------------------------------------------------- interparticle forces

NO_FORCE = "none"
#: interparticle.kind = "none": hard spheres, no force of this registry
FORCES: Registry[ForceSpec] = Registry("interparticle.kind", {
    NO_FORCE: "hard spheres (lubrication and the potential-free overlap correction)"})
FORCES.register(ForceSpec(
    "repulsion", "f0 tau exp(-tau h)/(1 + exp(-tau h)) along the line of centres (Dratler & Schowalter 1996)",
    "sdmpi.dynamics.forces:repulsion", keys=("f0", "tau"), monolayer=True))
FORCES.register(ForceSpec(
    "vdw", "Hamaker's van der Waals attraction, constant below cap_gap (Finke et al. 2020)",
    "sdmpi.dynamics.forces:van_der_waals", keys=("hamaker", "cap_gap")))
FORCES.register(ForceSpec(
    "dlvo", "vdw plus the double-layer repulsion psi^2 R ln(1 + exp(-h/debye_length))",
    "sdmpi.dynamics.forces:dlvo", keys=("hamaker", "cap_gap", "surface_potential", "debye_length")))
FORCES.register(ForceSpec(
    "frictional", "contact springs with Coulomb friction and the critical-load repulsion (Mari et al. 2014)",
    "sdmpi.dynamics.contacts:frictional", keys=("mu", "k_n", "k_t", "f_r0", "repulsion_length", "max_contacts"),
    brownian=False, contacts=True))


def force_kinds(where: Callable[[ForceSpec], bool]) -> tuple[str, ...]:
    """The interparticle.kind values for which ``where(spec)`` holds, "none" (hard spheres,
    which every combination allows) first."""
    return (NO_FORCE, *FORCES.names(where))


# --------------------------------------------------------------------------- writers

#: the outputs of a run, each a set of datasets in the run file (docs/store.md), created,
#: recorded, committed and carried over on --extend in this order; a writer whose
#: ``enabled(job)`` is false writes nothing
WRITERS: Registry[Spec] = Registry("writer")
WRITERS.register(Spec(
    "samples", "the sample stream: one row per time step (tasks/NNNNNN/samples)",
    "sdmpi.ensemble.samples:SampleStream"))
WRITERS.register(Spec(
    "trajectory", "H5MD trajectory frames every output.trajectory_every steps (particles/, "
    "observables/)", "sdmpi.ensemble.trajectory:TrajectoryWriter"))
