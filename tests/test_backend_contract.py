"""Every registered solver backend keeps the `sdmpi.hydro.backend.SolverBackend` contract at
one configuration with near-contact pairs in a sheared periodic box: a symmetric positive
definite mobility, fluctuation-dissipation (the Brownian forces' covariance is R_FU, so
covariance x mobility = identity), its own short cuts equal to the generic forms, the
dense backend's velocities and stresslets."""

import numpy as np
import pytest

from sdmpi.hydro.petsc_dense import PetscUnavailable, load_petsc
from sdmpi.hydro.solvers import assemble, make_solver
from sdmpi.registry import SOLVER_BACKENDS

#: relative tolerance of the iterative backends' solves; the direct ones are exact to
#: rounding (cond M = 30 here: errors ~1e-15)
TOL = 1e-10
#: agreement allowed: 1e3 x TOL covers the preconditioner's factor between residual and
#: error and the Lanczos square root's accuracy (petsc-krylov measured: 1.6e-10 asymmetry,
#: 3e-10 against dense, 1.3e-9 from the identity in covariance x mobility, which is
#: allowed AGREE x cond M); an error in the equations gives O(1e-3..1)
AGREE = 1e3 * TOL
BOX = np.array([6.0, 6.5, 7.0])
STRAIN = 0.1
POSITIONS = np.array([[0.5, 0.5, 0.5], [2.52, 0.5, 0.5], [0.5, 2.6, 0.6], [3.0, 3.1, 3.2],
                      [5.0, 1.0, 5.5], [1.5, 4.8, 2.0]])


def _available(spec):
    if not spec.needs_petsc:
        return True
    try:
        load_petsc()
    except PetscUnavailable:
        return False
    return True


def _solver(name):
    n = len(POSITIONS)
    res = assemble(name, POSITIONS, np.ones(n), BOX, STRAIN, True, 1e-8, comm=None)
    return make_solver(name, res, tolerance=TOL, lanczos_tolerance=TOL)


@pytest.mark.parametrize("name", SOLVER_BACKENDS.names())
def test_backend_keeps_the_contract(name):
    if not _available(SOLVER_BACKENDS[name]):
        pytest.skip(f"{name} needs petsc4py")
    solver, n = _solver(name), len(POSITIONS)
    assert solver.n == n
    zero = np.zeros((n, 5))
    unit = np.eye(6 * n).reshape(6 * n, n, 6)
    mobility = np.array([solver.velocities(f, zero).ravel() for f in unit])  # rows: M e_k
    scale = np.abs(mobility).max()
    assert np.abs(mobility - mobility.T).max() < AGREE * scale
    assert np.linalg.eigvalsh(0.5 * (mobility + mobility.T)).min() > 0
    forms = solver.mobility_forms(unit[:5])
    assert np.abs(forms - np.diag(mobility)[:5]).max() < AGREE * scale
    noise = np.eye(int(np.prod(solver.noise_shape))).reshape(-1, *solver.noise_shape)
    forces = np.array([solver.brownian_forces(z).ravel() for z in noise])
    covariance = forces.T @ forces  # sum over unit noises of F F^T = C C^T = R_FU
    assert np.abs(covariance @ mobility - np.eye(6 * n)).max() < AGREE * np.linalg.cond(mobility)
    z = np.random.default_rng(1).standard_normal(solver.noise_shape)
    direct = solver.brownian_velocities(z)
    generic = solver.velocities(solver.brownian_forces(z), zero)
    assert np.abs(direct - generic).max() < AGREE * np.abs(generic).max()
    dense = _solver("dense")
    einf = np.tile([0.3, -0.2, 0.5, 0.1, -0.4], (n, 1))
    forces = np.random.default_rng(2).standard_normal((n, 6))
    for ours, ref in ((solver.velocities(forces, einf), dense.velocities(forces, einf)),
                      (solver.stresslets(forces, einf), dense.stresslets(forces, einf))):
        assert np.abs(ours - ref).max() < AGREE * np.abs(ref).max()
    solver.take_preconditioner(_solver(name))
    assert set(solver.stats) == {"iterations", "residual", "lanczos"}
