"""Solvers for the resistance problem F = R U, behind one interface.

A backend is built from a `GrandResistance` and answers, for imposed forces/torques
and strain rates, the rigid-body velocities and the stresslets:

    U' = R_FU^-1 (F + R_FE e_inf),      S = R_SE e_inf - R_SU U'

(from (F, L, -S) = R (U', -e_inf), U' = velocities relative to the imposed flow,
e_inf the 5-vector of E_inf at every particle), plus the Brownian factor:
R_FU = C C^T, so C z (z standard normal) has covariance R_FU, and the velocities it
drives, R_FU^-1 C z = C^-T z, have covariance R_FU^-1 (fluctuation-dissipation).

`dense` factorises R_FU by LAPACK Cholesky on one rank. `petsc-dense`
(`petsc_dense.PetscDenseSolver`) distributes R_FU over an MPI communicator and factorises
it by ScaLAPACK through PETSc; it is imported only when asked for. Every backend is
built as backend(resistance, comm): the communicator of the ranks that solve together
(None: one rank; `dense` ignores it). `petsc-krylov` (`krylov.KrylovSolver`) solves
iteratively without forming R: it is built from a `resistance.SplitResistance`
(`assemble` picks the form a backend needs) with a tolerance, draws other noise than
z (N, 6) (`noise_shape`) and counts its iterations (`solver_stats`). `auto` is not a
backend but a rule (`resolve_backend`): dense below AUTO_KRYLOV_MIN_N particles
(petsc-dense on several ranks), petsc-krylov from there on.
"""

import numpy as np
from scipy.linalg import lapack

from .krylov import DEFAULT_TOL
from .resistance import grand_resistance, split_resistance

#: `auto` picks petsc-krylov from this many particles on, for its memory (it forms no
#: dense 11N x 11N matrix); on one rank at the default tolerances dense stays the faster up to
#: N ~ 1000 (bench/bench_krylov.py: docs/numerics.md, "Parameter choices")
AUTO_KRYLOV_MIN_N = 300


class DenseSolver:
    """Cholesky factorisation of R_FU (LAPACK potrf/potrs via scipy, in the memory of the
    resistance's freshly formed R_FU, finite by construction); R_FE, R_SU, R_SE act through the
    resistance's block form (`resistance.GrandResistance`)."""

    name = "dense"

    def __init__(self, resistance, comm=None):  # comm: ignored (one rank)
        self.resistance = resistance
        self.n = resistance.n_particles
        # R_FU is symmetric: the transpose of the (fresh, C-ordered) r_fu is it in Fortran
        # order; its upper factor U (R_FU = U^T U) overwrites it, and U.T is the lower factor C
        upper, info = lapack.dpotrf(resistance.r_fu.T, lower=False, clean=True, overwrite_a=True)
        if info != 0:
            raise np.linalg.LinAlgError(f"R_FU is not positive definite (potrf info {info})")
        self._upper = upper

    def velocities(self, forces, einf):
        """forces (N, 6) = (F, L); einf (N, 5) -> (N, 6) velocities U', Omega'."""
        rhs = forces.ravel()
        if einf.any():
            rhs = rhs + self.resistance.strain_forces(einf)
        sol, info = lapack.dpotrs(self._upper, rhs, lower=False)
        if info != 0:
            raise ValueError(f"potrs: illegal argument {-info}")
        return sol.reshape(self.n, 6)

    def stresslets(self, velocities, einf):
        """(N, 5) stresslets for rigid-body velocities U' (N, 6) and einf (N, 5)."""
        return self.resistance.stresslets(velocities, einf)

    def brownian_forces(self, noise):
        """C z for z (N, 6): a force sample with covariance R_FU (times z's variance)."""
        return (self._upper.T @ noise.ravel()).reshape(self.n, 6)

    def brownian_velocities(self, noise):
        """R_FU^-1 C z (N, 6) for z (N, 6) (C = U^T): U^-1 z, one triangular solve."""
        sol, info = lapack.dtrtrs(self._upper, noise.ravel(), lower=0)
        if info != 0:
            raise ValueError(f"trtrs: illegal argument {-info}")
        return sol.reshape(self.n, 6)

    def mobility_forms(self, forces):
        """f.R_FU^-1.f for each of the force sets forces (P, N, 6): |U^-T f|^2 with R_FU =
        U^T U, one triangular solve for all P."""
        y, info = lapack.dtrtrs(self._upper, forces.reshape(len(forces), -1).T, lower=0, trans=1)
        if info != 0:
            raise ValueError(f"trtrs: illegal argument {-info}")
        return np.einsum("kp,kp->p", y, y)


def _petsc_dense(resistance, comm=None):
    from .petsc_dense import PetscDenseSolver

    return PetscDenseSolver(resistance, comm)


def _petsc_krylov(resistance, comm=None, tolerance=DEFAULT_TOL, lanczos_tolerance=None):
    from .krylov import KrylovSolver

    return KrylovSolver(resistance, comm, tolerance, lanczos_tolerance)


BACKENDS = {"dense": DenseSolver, "petsc-dense": _petsc_dense, "petsc-krylov": _petsc_krylov}
#: backends built from a SplitResistance (the others from a GrandResistance)
MATRIX_FREE = ("petsc-krylov",)
#: what a `solver` argument may name
CHOICES = (*BACKENDS, "auto")


def resolve_backend(name, n_particles, comm=None):
    """The backend `name` stands for on the communicator comm (None: one rank): see
    `backend_for`."""
    return backend_for(name, n_particles, 1 if comm is None else comm.size)


def backend_for(name, n_particles, ranks):
    """The backend `name` stands for with `ranks` ranks per task: itself, or for "auto"
    dense (one rank) or petsc-dense (several) below AUTO_KRYLOV_MIN_N particles, else
    petsc-krylov."""
    if name not in CHOICES:
        raise ValueError(f"solver must be one of {list(CHOICES)}, got {name!r}")
    if name != "auto":
        return name
    if n_particles >= AUTO_KRYLOV_MIN_N:
        return "petsc-krylov"
    return "dense" if ranks == 1 else "petsc-dense"


def assemble(name, *args, comm=None, **kwargs):
    """The resistance backend `name` needs: `grand_resistance(*args, **kwargs)`, or for
    the matrix-free backends `split_resistance(*args, comm=comm, **kwargs)`."""
    if name in MATRIX_FREE:
        return split_resistance(*args, comm=comm, **kwargs)
    return grand_resistance(*args, **kwargs)


def make_solver(name, resistance, comm=None, tolerance=DEFAULT_TOL, lanczos_tolerance=None):
    """The backend `name` for a resistance from `assemble(name, ...)`, solving on the MPI
    communicator `comm` (None: this rank alone; collective over comm for the PETSc
    backends); tolerance: relative residual of the iterative backends, lanczos_tolerance:
    accuracy of their Brownian square roots (None: tolerance)."""
    try:
        backend = BACKENDS[name]
    except KeyError:
        raise ValueError(f"solver must be one of {sorted(BACKENDS)}, got {name!r}") from None
    if name in MATRIX_FREE:
        return backend(resistance, comm, tolerance, lanczos_tolerance)
    return backend(resistance, comm)


def noise_shape(solver):
    """Shape of the standard normal noise `solver.brownian_forces` takes: (N, 6) unless
    the backend declares its own (noise_shape)."""
    return getattr(solver, "noise_shape", (solver.n, 6))


def mobility_forms(solver, forces):
    """f.R_FU^-1.f (P,) for the force sets forces (P, N, 6): the backend's own batched form
    where it has one (dense), else one solve per set."""
    forms = getattr(solver, "mobility_forms", None)
    if forms is not None:
        return forms(forces)
    zero = np.zeros((solver.n, 5))
    return np.array([np.vdot(f, solver.velocities(f, zero)) for f in forces])


def brownian_velocities(solver, noise):
    """R_FU^-1 C z for the noise z (`noise_shape`): the velocities of the Brownian force
    C z (C C^T = R_FU), by the backend's own short cut where it has one (dense: one
    triangular solve), else `velocities(brownian_forces(z))`."""
    direct = getattr(solver, "brownian_velocities", None)
    if direct is not None:
        return direct(noise)
    return solver.velocities(solver.brownian_forces(noise), np.zeros((solver.n, 5)))


def take_preconditioner(solver, previous):
    """Let solver take over the preconditioner factor of previous (a solver of the same
    backend at a nearby configuration, the Brownian step's start for its midpoint), where
    the backend has one (petsc-krylov); the direct backends ignore it."""
    take = getattr(solver, "take_preconditioner", None)
    if take is not None:
        take(previous)


def solver_stats(solver):
    """Iterations (Krylov, Lanczos) and the largest relative residual of the solves so
    far: zero for the direct backends."""
    return getattr(solver, "stats", {"iterations": 0, "residual": 0.0, "lanczos": 0})
