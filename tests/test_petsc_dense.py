"""The petsc-dense backend (ScaLAPACK Cholesky of R_FU through PETSc) against dense: on
one rank in process, on two ranks under mpirun, through solve_mobility, and a Brownian
realisation with ranks_per_task = 2 against one rank."""

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from sdmpi.hydro import solve_mobility
from sdmpi.hydro.petsc_dense import PetscUnavailable, load_petsc, petsc_info

try:
    load_petsc()
except PetscUnavailable as err:
    pytest.skip(f"petsc4py not available: {err}", allow_module_level=True)

from .petsc_check import compare  # noqa: E402
from .runs import child_env  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MPIRUN = shutil.which("mpirun")
needs_mpi = pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
TOL = 1e-10  # relative to the largest entry


def test_scalapack_is_available():
    info = petsc_info()
    assert info["packages"]["scalapack"], info


@pytest.mark.parametrize("phi", [0.1, 0.5])
def test_agrees_with_dense_one_rank(phi):
    out = compare(phi)
    assert out["min_gap"] < 0.01  # near-contact pairs present
    for key in ("velocities", "stresslets", "brownian"):
        assert out[key] < TOL, (key, out)


def rows_on_two_ranks(module, *args):
    """The rows a check module of tests/ (petsc_check.print_per_rank), run as
    ``python -m tests.MODULE ARGS``, prints under mpirun -n 2, all ranks' together, each
    checked to come from 2 ranks that agree bit for bit."""
    cmd = [MPIRUN, "--oversubscribe", "-n", "2", sys.executable, "-m", f"tests.{module}", *args]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=120, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    # a library may write a terminal escape (seen: "\x1b[0m") before a line: strip those
    text = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", res.stdout)
    lines = [json.loads(line) for line in text.splitlines() if line.startswith("[")]
    assert len(lines) == 2  # one per rank
    for out in (out for rows in lines for out in rows):
        assert out["ranks"] == 2 and out["same_on_all_ranks"], out
    return [out for rows in lines for out in rows]


@needs_mpi
@pytest.mark.mpi
def test_agrees_with_dense_two_ranks():
    for out in rows_on_two_ranks("petsc_check", "0.1", "0.5"):
        for key in ("velocities", "stresslets", "brownian"):
            assert out[key] < TOL, (key, out)


@needs_mpi
@pytest.mark.mpi
def test_dropped_solvers_leave_no_petsc_objects_two_ranks():
    """On two ranks petsc4py defers the destroy of a collected object to
    PETSc.garbage_cleanup: a new solver must free what the dropped ones held (three solvers
    with their solves dropped leave 21 objects on petsc-dense and 31 on petsc-krylov
    otherwise; a run would grow by ~1.2 MB a step at N = 64 on petsc-dense, ~0.3 MB at N = 1000
    on petsc-krylov)."""
    for out in rows_on_two_ranks("garbage_check", "petsc-dense", "petsc-krylov"):
        assert out["entries"] == [0, 0], out


def mobility_problem(distance):
    """Four random spheres, two of them at centre distance `distance`, and the keyword
    arguments (strain, forces, torques, shear rate of strain) of a solve_mobility call."""
    rng = np.random.default_rng(5)
    pos = rng.uniform(0, 6, (4, 3))
    pos[1] = pos[0] + [0.0, distance, 0.0]
    kw = dict(strain=0.2, forces=rng.standard_normal((4, 3)), torques=rng.standard_normal((4, 3)),
              rate_of_strain=np.array([[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]]))
    return pos, kw


def test_solve_mobility_one_rank():
    pos, kw = mobility_problem(2.01)
    box = [9.0, 8.0, 10.0]
    for a, b in zip(solve_mobility(pos, box, solver="dense", **kw),
                    solve_mobility(pos, box, solver="petsc-dense", **kw)):
        assert np.abs(a - b).max() < TOL * np.abs(a).max()
    assert_isolated_sphere("petsc-dense", kw["rate_of_strain"])


def assert_isolated_sphere(solver, rate_of_strain):
    """solve_mobility with `solver` for one sphere in unbounded fluid gives Stokes' laws:
    U = F/(6 pi), Omega = L/(8 pi), S = (20 pi/3) E (viscosity 1, radius 1), to 1e-12."""
    u, w, s = solve_mobility([[0.0, 0.0, 0.0]], None, forces=[[1.0, 2.0, 3.0]],
                             torques=[[0.0, 0.0, 1.0]], rate_of_strain=rate_of_strain, solver=solver)
    assert np.allclose(u, np.array([1.0, 2.0, 3.0]) / (6 * np.pi), rtol=1e-12)
    assert np.allclose(w, np.array([0.0, 0.0, 1.0]) / (8 * np.pi), rtol=1e-12)
    assert np.allclose(s, 20 / 3 * np.pi * rate_of_strain, rtol=1e-12)


def test_not_positive_definite_is_a_linalg_error():
    from sdmpi.hydro.resistance import grand_resistance
    from sdmpi.hydro.solvers import make_solver

    res = grand_resistance(np.array([[0.0, 0, 0], [3.0, 0, 0]]), np.ones(2))
    res.s_inverse[0, 0] = -10.0  # R_FU = S^-1 + L_FU then has a negative diagonal entry
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        make_solver("petsc-dense", res)


# ---------------------------------------------------------------- ranks_per_task = 2

SHORT = ["--set", "system.n_particles=27", "--set", "system.phi=[0.45]",
         "--set", "integration.periods=1", "--set", "integration.discard_periods=0",
         "--set", "shear.omega=[25.132741228718345]", "--set", "ensemble.realisations=1",
         "--set", "output.checkpoint_every=40"]
PETSC = ["--set", 'solver.backend="petsc-dense"']


def _run(out, *extra, ranks=None):
    cmd = [sys.executable, "-m", "sdmpi.cli", "run", str(ROOT / "jobs" / "demo.toml"),
           "-o", str(out), *SHORT, *extra]
    if ranks:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks), *cmd]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=300, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    with h5py.File(out, "r") as f:
        (task,) = f["tasks"]
        samples = f["tasks"][task]["samples"]
        return {k: samples[k][()] for k in samples}


@needs_mpi
@pytest.mark.mpi
@pytest.mark.parametrize("scheme,rtol", [("midpoint", 1e-9), ("rfd", 1e-6)])
def test_two_ranks_per_task_same_stream(tmp_path, scheme, rtol):
    """A Brownian realisation (N = 27, phi = 0.45, 100 steps) on a 2-rank sub-communicator
    against dense on one rank: the deterministic columns are equal, the stresses agree
    to rounding (the Brownian force uses the same, unique Cholesky factor), so their
    statistics agree too. The rfd drift is a difference of two solves over a step
    delta = 1e-6 a: it carries the solvers' rounding (eps cond(R_FU) ~ 1e-12 at the
    1e-4 floor) amplified by 1/delta, ~1e-6 relative, hence its tolerance."""
    scheme_key = ["--set", f'brownian.scheme="{scheme}"']
    one = _run(tmp_path / "one.h5", *scheme_key)
    two = _run(tmp_path / "two.h5", *PETSC, *scheme_key, "--set", "ensemble.ranks_per_task=2", ranks=2)
    assert_same_stream(one, two, rtol=rtol, mean_tol=1e-6 if scheme == "midpoint" else 1e-3)
    b1, b2 = one["stress_brownian"], two["stress_brownian"]
    assert np.allclose(b1.std(axis=0), b2.std(axis=0), rtol=10 * rtol)


def assert_same_stream(one, two, rtol, mean_tol):
    """Two sample streams of one realisation: deterministic columns equal, stresses and
    gaps within rtol of their scale, Brownian-stress means within mean_tol standard errors."""
    for key in ("time", "strain", "rate", "n_overlaps"):
        assert np.array_equal(one[key], two[key]), key
    for key in ("stress_hydrodynamic", "stress_brownian", "stress_interparticle", "min_gap"):
        scale = np.abs(one[key]).max()
        assert np.abs(one[key] - two[key]).max() <= rtol * scale, key
    b1, b2 = one["stress_brownian"], two["stress_brownian"]
    err = b1.std(axis=0) / np.sqrt(len(b1))
    assert np.all(np.abs(b1.mean(axis=0) - b2.mean(axis=0)) < mean_tol * err)
