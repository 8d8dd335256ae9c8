"""The solver backends of the resistance problem F = R U, chosen by name.

The interface is `backend.SolverBackend`; the backends are registered, with what the job
checks know of them, in `sdmpi.registry.SOLVER_BACKENDS`. `dense` (`DenseSolver`, here)
factorises R_FU by LAPACK Cholesky on one rank. `petsc-dense`
(`petsc_dense.PetscDenseSolver`) distributes R_FU over an MPI communicator and factorises
it by ScaLAPACK through PETSc. `petsc-krylov` (`krylov.KrylovSolver`) solves iteratively
without forming R: it is built from a `resistance.SplitResistance` (`assemble` picks the
form a backend needs) with a tolerance, draws other noise than z (N, 6) and counts its
iterations. A backend is imported only when asked for. `auto` is not a backend but a rule
(`resolve_backend`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import lapack

from ..registry import SOLVER_BACKENDS, backend_for
from .backend import SolverBackend
from .krylov import DEFAULT_TOL
from .resistance import GrandResistance, SplitResistance, grand_resistance, split_resistance


class DenseSolver(SolverBackend):
    """Cholesky factorisation of R_FU (LAPACK potrf/potrs via scipy, in the memory of the
    resistance's freshly formed R_FU, finite by construction); R_FE, R_SU, R_SE act through the
    resistance's block form (`resistance.GrandResistance`)."""

    def __init__(self, resistance: GrandResistance, comm: Any = None) -> None:  # comm: ignored (one rank)
        self.resistance = resistance
        self.n = resistance.n_particles
        self.noise_shape = (self.n, 6)
        # R_FU is symmetric: the transpose of the (fresh, C-ordered) r_fu is it in Fortran
        # order; its upper factor U (R_FU = U^T U) overwrites it, and U.T is the lower factor C
        upper, info = lapack.dpotrf(resistance.r_fu.T, lower=False, clean=True, overwrite_a=True)
        if info != 0:
            raise np.linalg.LinAlgError(f"R_FU is not positive definite (potrf info {info})")
        self._upper = upper

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """forces (N, 6) = (F, L); einf (N, 5) -> (N, 6) velocities U', Omega'."""
        rhs = forces.ravel()
        if einf.any():
            rhs = rhs + self.resistance.strain_forces(einf)
        sol, info = lapack.dpotrs(self._upper, rhs, lower=False)
        if info != 0:
            raise ValueError(f"potrs: illegal argument {-info}")
        return sol.reshape(self.n, 6)

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """(N, 5) stresslets for rigid-body velocities U' (N, 6) and einf (N, 5)."""
        return self.resistance.stresslets(velocities, einf)

    def brownian_forces(self, noise: np.ndarray) -> np.ndarray:
        """C z for z (N, 6): a force sample with covariance R_FU (times z's variance)."""
        return (self._upper.T @ noise.ravel()).reshape(self.n, 6)

    def brownian_velocities(self, noise: np.ndarray) -> np.ndarray:
        """R_FU^-1 C z (N, 6) for z (N, 6) (C = U^T): U^-1 z, one triangular solve."""
        sol, info = lapack.dtrtrs(self._upper, noise.ravel(), lower=0)
        if info != 0:
            raise ValueError(f"trtrs: illegal argument {-info}")
        return sol.reshape(self.n, 6)

    def mobility_forms(self, forces: np.ndarray, accuracy: np.ndarray | None = None) -> np.ndarray:
        """f.R_FU^-1.f for each of the force sets forces (P, N, 6): |U^-T f|^2 with R_FU =
        U^T U, one triangular solve for all P (exact to rounding whatever the accuracy)."""
        y, info = lapack.dtrtrs(self._upper, forces.reshape(len(forces), -1).T, lower=0, trans=1)
        if info != 0:
            raise ValueError(f"trtrs: illegal argument {-info}")
        return np.einsum("kp,kp->p", y, y)


def resolve_backend(name: str, n_particles: int, comm: Any = None) -> str:
    """The backend `name` (a choice of solver.backend) stands for on the communicator comm
    (None: one rank): itself, or what "auto" picks (`sdmpi.registry.backend_for`).

    Args:
        name: a choice of solver.backend (a registered backend or "auto").
        n_particles: the number of spheres N.
        comm: the MPI communicator, or None (one rank).

    Returns:
        The name of a registered backend.

    Raises:
        ValueError: name is not a choice of solver.backend.
    """
    if name not in SOLVER_BACKENDS.choices():
        raise ValueError(f"solver must be one of {list(SOLVER_BACKENDS.choices())}, got {name!r}")
    return backend_for(name, n_particles, 1 if comm is None else comm.size)


def assemble(name: str, *args: Any, comm: Any = None, brownian: bool = True,
             **kwargs: Any) -> GrandResistance | SplitResistance:
    """The resistance backend `name` needs: `grand_resistance(*args, **kwargs)`, or for
    the matrix-free backends `split_resistance(*args, comm=comm, brownian=brownian,
    **kwargs)`.

    Args:
        name: a registered backend.
        *args: positional arguments of `grand_resistance` / `split_resistance`.
        comm: the MPI communicator of a matrix-free backend, or None (one rank).
        brownian: its solver will draw Brownian forces (False: solves only; a
            matrix-free resistance then leaves out the pair factors they need).
        **kwargs: keyword arguments of `grand_resistance` / `split_resistance`.

    Returns:
        The resistance of the configuration in the form the backend takes.
    """
    if SOLVER_BACKENDS[name].matrix_free:
        return split_resistance(*args, comm=comm, brownian=brownian, **kwargs)
    return grand_resistance(*args, **kwargs)


def make_solver(name: str, resistance: GrandResistance | SplitResistance, comm: Any = None,
                tolerance: float = DEFAULT_TOL, lanczos_tolerance: float | None = None) -> SolverBackend:
    """The backend `name` for a resistance from `assemble(name, ...)`, solving on the MPI
    communicator `comm` (None: this rank alone; collective over comm for the PETSc
    backends); tolerance: relative residual of the iterative backends, lanczos_tolerance:
    accuracy of their Brownian square roots (None: tolerance).

    Args:
        name: a registered backend.
        resistance: the resistance from `assemble(name, ...)`.
        comm: the MPI communicator, or None (this rank alone).
        tolerance: relative residual of iterative solves (dimensionless).
        lanczos_tolerance: relative accuracy of the Brownian square roots, or None.

    Returns:
        The backend, factorised or ready to iterate.
    """
    return SOLVER_BACKENDS[name].load().build(resistance, comm, tolerance, lanczos_tolerance)
