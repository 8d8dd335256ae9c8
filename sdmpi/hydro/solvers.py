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
(None: one rank; `dense` ignores it).
"""

import numpy as np
from scipy.linalg import cho_factor, cho_solve


class DenseSolver:
    """Cholesky factorisation of R_FU (LAPACK via scipy)."""

    name = "dense"

    def __init__(self, resistance, comm=None):  # comm: ignored (one rank)
        self.r_fu, self.r_fe, self.r_su, self.r_se = resistance.blocks()
        self.n = resistance.n_particles
        try:
            self._chol = cho_factor(self.r_fu, lower=True)
        except np.linalg.LinAlgError as exc:
            raise np.linalg.LinAlgError("R_FU is not positive definite") from exc

    def velocities(self, forces, einf):
        """forces (N, 6) = (F, L); einf (N, 5) -> (N, 6) velocities U', Omega'."""
        rhs = forces.ravel() + self.r_fe @ einf.ravel()
        return cho_solve(self._chol, rhs).reshape(self.n, 6)

    def stresslets(self, velocities, einf):
        """(N, 5) stresslets for rigid-body velocities U' (N, 6) and einf (N, 5)."""
        return (self.r_se @ einf.ravel() - self.r_su @ velocities.ravel()).reshape(self.n, 5)

    def brownian_forces(self, noise):
        """C z for z (N, 6): a force sample with covariance R_FU (times z's variance)."""
        chol = np.tril(self._chol[0])
        return (chol @ noise.ravel()).reshape(self.n, 6)


def _petsc_dense(resistance, comm=None):
    from .petsc_dense import PetscDenseSolver

    return PetscDenseSolver(resistance, comm)


BACKENDS = {"dense": DenseSolver, "petsc-dense": _petsc_dense}


def make_solver(name, resistance, comm=None):
    """The backend `name` for a GrandResistance, solving on the MPI communicator `comm`
    (None: this rank alone; collective over comm for the PETSc backends)."""
    try:
        backend = BACKENDS[name]
    except KeyError:
        raise ValueError(f"solver must be one of {sorted(BACKENDS)}, got {name!r}") from None
    return backend(resistance, comm)
