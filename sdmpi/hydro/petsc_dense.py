"""`petsc-dense`: R_FU distributed over an MPI communicator, ScaLAPACK Cholesky through PETSc.

Same interface (`backend.SolverBackend`) and equations as `solvers.DenseSolver`:

    U' = R_FU^-1 (F + R_FE e_inf),   S = R_SE e_inf - R_SU U',   F_B = C z with R_FU = C C^T.

What is distributed, and what is not:

- R_FU (6N x 6N) is a PETSc MATMPIDENSE over the communicator (each rank copies only
  its own block of rows out of the replicated numpy R_FU), converted to MATSCALAPACK (2-D
  block-cyclic) and factorised in place by ScaLAPACK's pdpotrf (R_FU = L L^T). Each solve
  is pdpotrs on a distributed vector; the solution is gathered to every rank.
- The Brownian factor is the Cholesky factor itself: after the factorisation, L is
  copied back into a MATMPIDENSE (lower triangle, the strict upper part zeroed) and
  C z = L z is a distributed product, gathered to every rank. The Cholesky factor is
  unique, so F_B equals the `dense` backend's up to rounding (not necessarily bit for
  bit: ScaLAPACK and LAPACK may block the factorisation differently).
  PETSc refuses to convert a factored matrix, so the copy marks the factor unfactored,
  converts it and marks it factored again (MatSetFactorType through ctypes, as petsc4py
  3.18 does not wrap it; if that fails, R_FU is factorised a second time for the copy).
- R_FE, R_SU, R_SE products stay replicated numpy on every rank, and so does the
  assembly of R (`grand_resistance`, including the O((11N)^3) block inverse of M_inf):
  every rank of the communicator holds the whole of it.

Inputs and outputs are replicated numpy arrays; every method is collective over the
communicator (all its ranks must build the same solver and call the same methods in the
same order, with the same arguments), and every rank gets the same result.

PETSc needs ScaLAPACK (the parallel dense Cholesky; docs/numerics.md, "PETSc dense"):
without petsc4py or without ScaLAPACK, building the backend raises `PetscUnavailable`
saying what is missing.

petsc4py is found through PETSC_DIR (Debian's .pth file reads it when Python starts); if
PETSC_DIR is unset, `load_petsc` sets it to the Debian default and adds its site
directory itself. PETSc is initialised with -no_signal_handler so that the ensemble
runner keeps its own SIGTERM/SIGINT/SIGUSR1 handlers.
"""

from __future__ import annotations

import glob
import os
import sys
from types import ModuleType
from typing import Any

import numpy as np

from .backend import SolverBackend


#: options PETSc is initialised with (when sdmpi is the first to import it)
PETSC_OPTIONS = ["-no_signal_handler"]

_PETSC = None
_KEEPALIVE = {}  # communicator handle -> a PETSc object, keeps PETSc's inner comm (and BLACS grid)


class PetscUnavailable(RuntimeError):
    """petsc4py cannot be imported, or this PETSc lacks the solver a backend needs."""


def _petsc_dir_candidates():
    return ["/usr/lib/petsc", *sorted(glob.glob("/usr/lib/petscdir/petsc*/x86_64-linux-gnu-real"),
                                      reverse=True)]


def import_petsc4py() -> ModuleType:
    """The petsc4py package, imported without initialising PETSc (setting PETSC_DIR if
    unset); PetscUnavailable if it cannot be imported. Safe on one rank alone.

    Returns:
        The petsc4py package.

    Raises:
        PetscUnavailable: petsc4py cannot be imported.
    """
    if not os.environ.get("PETSC_DIR"):
        for cand in _petsc_dir_candidates():
            if os.path.isdir(os.path.join(cand, "lib", "python3", "dist-packages", "petsc4py")):
                os.environ["PETSC_DIR"] = cand
                break
    if os.environ.get("PETSC_DIR"):
        site = os.path.join(os.environ["PETSC_DIR"], "lib", "python3", "dist-packages")
        if os.path.isdir(site) and site not in sys.path:
            sys.path.append(site)
    try:
        import petsc4py
    except ImportError as err:
        raise PetscUnavailable(
            f"the PETSc backends need petsc4py, which cannot be imported ({err}); on Debian "
            "install python3-petsc4py and set PETSC_DIR=/usr/lib/petscdir/petsc3.18/"
            "x86_64-linux-gnu-real (or install petsc-dev); otherwise use "
            'solver.backend = "dense"') from err
    return petsc4py


def load_petsc() -> ModuleType:
    """Import petsc4py, initialise PETSc (collective over MPI_COMM_WORLD) and return the
    PETSc module.

    Returns:
        The petsc4py.PETSc module.

    Raises:
        PetscUnavailable: petsc4py cannot be imported.
    """
    global _PETSC
    if _PETSC is not None:
        return _PETSC
    petsc4py = import_petsc4py()
    from mpi4py import MPI  # noqa: F401  (MPI initialised by mpi4py, as everywhere in sdmpi)
    if "petsc4py.PETSc" not in sys.modules:
        petsc4py.init(PETSC_OPTIONS)
    from petsc4py import PETSc

    _PETSC = PETSc
    return PETSc


def petsc_info() -> dict[str, Any]:
    """Version and the direct-solver packages this PETSc was built with.

    Returns:
        {"version": "major.minor.patch", "packages": {name: available}}.
    """
    PETSc = load_petsc()
    packages = ("scalapack", "elemental", "mumps", "superlu_dist", "strumpack", "mkl_cpardiso")
    return {"version": ".".join(map(str, PETSc.Sys.getVersion())),
            "packages": {p: bool(PETSc.Sys.hasExternalPackage(p)) for p in packages}}


def _mpi_comm(comm):
    """An mpi4py communicator: None -> COMM_SELF (one rank, as outside mpirun)."""
    from mpi4py import MPI

    if comm is None:
        return MPI.COMM_SELF
    if hasattr(comm, "tompi4py"):  # a PETSc.Comm
        return comm.tompi4py()
    return comm


def collect_garbage(PETSc, comm):
    """Destroy the PETSc objects on ``comm`` that Python has dropped. Collective.

    On a communicator of several ranks petsc4py (3.18 on) does not destroy an object when
    its Python wrapper is garbage collected, as the destroy is collective and Python may
    collect in a different order on each rank: it keeps the object until
    ``PETSc.garbage_cleanup(comm)``. Every solver calls this when it is built (each step
    builds new ones), so that what earlier steps' solvers and solves dropped is freed
    instead of accumulating for the whole run. Without it (older petsc4py) nothing is
    deferred."""
    cleanup = getattr(PETSc, "garbage_cleanup", None)
    if cleanup is not None and comm.Get_size() > 1:
        cleanup(comm)


def _keepalive(PETSc, comm):
    """Hold one PETSc object per communicator so that PETSc's duplicated inner
    communicator and ScaLAPACK's BLACS grid, cached on it, outlive each solver."""
    from mpi4py import MPI

    key = MPI._handleof(comm)
    if key not in _KEEPALIVE:
        _KEEPALIVE[key] = PETSc.Vec().createMPI((0, PETSc.DECIDE), comm=comm)
    return _KEEPALIVE[key]


#: MatFactorType value of MAT_FACTOR_CHOLESKY (petscmat.h, PETSc 3.18)
MAT_FACTOR_CHOLESKY = 2
_SET_FACTOR_TYPE = []


def _set_factor_type():
    """MatSetFactorType(Mat, MatFactorType) from the loaded libpetsc, or None."""
    if not _SET_FACTOR_TYPE:
        func = None
        try:
            import ctypes

            with open("/proc/self/maps") as maps:
                libs = sorted({line.split()[-1] for line in maps
                               if "/libpetsc" in line and ".so" in line})
            for lib in libs:
                handle = ctypes.CDLL(lib)
                if hasattr(handle, "MatSetFactorType"):
                    func = handle.MatSetFactorType
                    func.argtypes = [ctypes.c_void_p, ctypes.c_int]
                    func.restype = ctypes.c_int
                    break
        except OSError:
            func = None
        _SET_FACTOR_TYPE.append(func)
    return _SET_FACTOR_TYPE[0]


class PetscDenseSolver(SolverBackend):
    """ScaLAPACK Cholesky of R_FU over `comm` (an mpi4py communicator; None: COMM_SELF), a
    `backend.SolverBackend`. Collective over comm; see the module docstring."""

    def __init__(self, resistance: Any, comm: Any = None) -> None:
        PETSc = load_petsc()
        if not PETSc.Sys.hasExternalPackage("scalapack"):
            info = petsc_info()
            have = ", ".join(p for p, ok in info["packages"].items() if ok) or "none"
            raise PetscUnavailable(
                f"petsc-dense needs a PETSc built with ScaLAPACK (parallel dense Cholesky); "
                f"this PETSc {info['version']} has: {have}. Use solver.backend = \"dense\"")
        self.comm = _mpi_comm(comm)
        _keepalive(PETSc, self.comm)
        collect_garbage(PETSc, self.comm)
        self.n = n = resistance.n_particles
        self.noise_shape = (n, 6)
        m = 6 * n
        self.resistance = resistance  # R_FE, R_SU, R_SE act through its block form
        dense = PETSc.Mat().createDense([m, m], comm=self.comm)
        dense.setUp()
        r0, r1 = dense.getOwnershipRange()
        rows = resistance.r_fu_rows(r0, r1)  # R_FU in this rank's rows
        dense.getDenseArray()[:] = rows
        dense.assemble()
        factor = dense.convert("scalapack")  # in place (petsc4py: no `out`)
        perm = PETSc.IS().createStride(r1 - r0, first=r0, step=1, comm=self.comm)
        try:
            factor.factorCholesky(perm)
        except PETSc.Error as exc:
            detail = str(exc).strip().splitlines()[-1].strip()
            raise np.linalg.LinAlgError(f"R_FU is not positive definite ({detail})") from exc
        perm.destroy()
        self._factor = factor
        self._chol = self._lower_factor(PETSc, factor, rows)
        self._b, self._x = factor.createVecs()
        self._range = self._b.getOwnershipRange()
        self._chol_vecs = self._chol.createVecs()
        self._chol_range = self._chol_vecs[0].getOwnershipRange()
        self._gather, self._all = PETSc.Scatter.toAll(self._x)
        self._PETSc = PETSc

    def _lower_factor(self, PETSc, factor, rows):
        """L (R_FU = L L^T) as a row-distributed MATMPIDENSE, its strict upper part zero.

        After pdpotrf the ScaLAPACK matrix holds L in its lower triangle. PETSc refuses
        to convert (or duplicate) a factored matrix, so the factor is marked unfactored,
        converted, and marked factored again (MatSetFactorType, not wrapped by petsc4py
        3.18: called through ctypes). If that call is unavailable, R_FU is factorised a
        second time for the copy (twice the factorisation cost, same result)."""
        mark = _set_factor_type()
        if mark is not None:
            factor.setUnfactored()
            lower = factor.convert("dense", PETSc.Mat())  # a new matrix
            mark(factor.handle, MAT_FACTOR_CHOLESKY)
        else:
            dense = PETSc.Mat().createDense([6 * self.n, 6 * self.n], comm=self.comm)
            dense.setUp()
            r0, r1 = dense.getOwnershipRange()
            dense.getDenseArray()[:] = rows
            dense.assemble()
            second = dense.convert("scalapack")  # in place
            perm = PETSc.IS().createStride(r1 - r0, first=r0, step=1, comm=self.comm)
            second.factorCholesky(perm)
            second.setUnfactored()
            lower = second.convert("dense")  # in place
            perm.destroy()
        l0, _ = lower.getOwnershipRange()
        local = lower.getDenseArray()
        local[:] = np.tril(local, k=l0)  # local row i is global row l0 + i
        lower.assemble()
        return lower

    # ------------------------------------------------------------------ interface

    def _gathered(self, vec):
        PETSc = self._PETSc
        self._gather.scatter(vec, self._all, addv=PETSc.InsertMode.INSERT,
                             mode=PETSc.ScatterMode.FORWARD)
        return self._all.getArray().copy()

    def _solve(self, rhs):
        r0, r1 = self._range
        self._b.setArray(rhs[r0:r1])
        self._factor.solve(self._b, self._x)
        return self._gathered(self._x)

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """forces (N, 6) = (F, L); einf (N, 5) -> (N, 6) velocities U', Omega'."""
        rhs = forces.ravel() + self.resistance.strain_forces(einf)
        return self._solve(rhs).reshape(self.n, 6)

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """(N, 5) stresslets for rigid-body velocities U' (N, 6) and einf (N, 5)."""
        return self.resistance.stresslets(velocities, einf)

    def brownian_forces(self, noise: np.ndarray) -> np.ndarray:
        """L z for z (N, 6), R_FU = L L^T: a force sample with covariance R_FU."""
        z, y = self._chol_vecs
        r0, r1 = self._chol_range
        z.setArray(noise.ravel()[r0:r1])
        self._chol.mult(z, y)
        return self._gathered(y).reshape(self.n, 6)
