"""The command line on inputs a new user tries: messages and exit codes, never a
traceback, nothing overwritten that is not an sdmpi run file."""

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from sdmpi.hydro import solve_mobility

from . import runs as ens


def python_m(*args, **kwargs):
    return subprocess.run([sys.executable, "-m", "sdmpi", *map(str, args)], capture_output=True,
                          text=True, env=ens.child_env(), **kwargs)


def test_python_m_sdmpi(tmp_path):
    res = python_m("--version")
    assert res.returncode == 0 and res.stdout.startswith("sdmpi ")
    job = tmp_path / "job.toml"
    job.write_text(ens.JOB)
    res = python_m("validate", job)
    assert res.returncode == 0 and "valid" in res.stdout


def test_empty_job_file_refused(tmp_path):
    job = tmp_path / "empty.toml"
    job.write_text("")
    res = python_m("validate", job)
    assert res.returncode == 2 and "the job file is empty" in res.stderr, res.stderr
    res = ens.sdmpi("run", job, "-o", tmp_path / "run.h5")
    assert res.returncode == 2 and "the job file is empty" in res.stderr
    assert sorted(os.listdir(tmp_path)) == ["empty.toml"]


def test_info_into_a_closed_pipe(tmp_path):
    """`sdmpi info RUN.h5 | head`: the reader is gone before sdmpi writes; no
    BrokenPipeError traceback, exit 0."""
    job = tmp_path / "job.toml"
    job.write_text(ens.JOB)
    out = tmp_path / "run.h5"
    assert ens.sdmpi("run", job, "-o", out).returncode == 0
    proc = subprocess.Popen([sys.executable, str(ens.DRIVER), "info", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ens.child_env())
    proc.stdout.close()  # long before the report is written (imports take ~1 s)
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0 and stderr == "", stderr


def test_run_into_a_closed_pipe(tmp_path):
    """`sdmpi run ... | head -1`: the run goes on to the end when its reader is gone."""
    job = tmp_path / "job.toml"
    job.write_text(ens.JOB)
    out = tmp_path / "run.h5"
    proc = subprocess.Popen([sys.executable, str(ens.DRIVER), "run", str(job), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ens.child_env())
    proc.stdout.close()
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0 and stderr == "", stderr
    assert ens.sdmpi("info", out).stdout.count(" done\n") == ens.N_TASKS


def test_new_replaces_only_run_files(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text(ens.JOB)
    before = job.read_bytes()
    res = ens.sdmpi("run", job, "--new", "-o", job)
    assert res.returncode == 2 and "not an sdmpi run file" in res.stderr, res.stderr
    assert "--new replaces only sdmpi run files" in res.stderr
    assert job.read_bytes() == before
    res = ens.sdmpi("run", job, "-o", job)  # without --new: no advice to use it
    assert res.returncode == 2 and "--new" not in res.stderr
    assert job.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["job.toml"]
    run = tmp_path / "run.h5"
    assert ens.sdmpi("run", job, "-o", run).returncode == 0
    res = ens.sdmpi("run", job, "--new", "-o", run, "--set", "job.seed=8")
    assert res.returncode == 0, res.stderr  # an sdmpi run file is replaced


def test_solve_mobility_argument_checks():
    pos, box = np.array([[0.0, 0, 0], [3.0, 0, 0]]), np.full(3, 10.0)
    with pytest.raises(ValueError, match="ewald_tol must be in"):
        solve_mobility(pos, box, ewald_tol=0)
    with pytest.raises(TypeError, match="lubrication must be True or False, got 'no'"):
        solve_mobility(pos, box, lubrication="no")


def _readable_by_others(path):
    """Every directory above path can be entered, and path read, by any user."""
    path = Path(path).resolve()
    if not os.stat(path).st_mode & 0o004:
        return False
    return all(os.stat(p).st_mode & 0o001 for p in path.parents)


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("setpriv") is None,
                    reason="needs root and setpriv to act as another user")
def test_read_only_install():
    """As another user (nobody) with no writable HOME, no NUMBA_CACHE_DIR and a source
    tree it cannot write: every command runs, compiling in memory, and says so once.
    Skipped where the checkout itself is private (e.g. under a 0700 temporary directory):
    the other user could not read the code at all."""
    if not _readable_by_others(ens.DRIVER):
        pytest.skip(f"{ens.DRIVER} is not readable by other users here")
    work = Path(tempfile.mkdtemp(prefix="sdmpi-ro-"))
    try:
        work.chmod(0o777)
        job = work / "job.toml"
        job.write_text(ens.JOB)
        env = {k: v for k, v in ens.child_env().items() if k != "NUMBA_CACHE_DIR"}
        env["HOME"] = "/nonexistent"
        nobody = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
        out = work / "run.h5"
        for args in (["validate", job], ["run", job, "-o", out], ["info", out],
                     ["reduce", out, "-o", work / "red", "--no-plots"]):
            res = subprocess.run([*nobody, sys.executable, str(ens.DRIVER), *map(str, args)],
                                 capture_output=True, text=True, env=env, timeout=300)
            assert res.returncode == 0, (args, res.stderr)
            assert res.stderr.count("compiling them in memory") == 1, res.stderr
            assert "Traceback" not in res.stderr
        assert (work / "red" / "moduli.csv").is_file()
    finally:
        shutil.rmtree(work)


@pytest.mark.skipif(ens.MPIRUN is None, reason="mpirun not found")
@pytest.mark.mpi
def test_sigterm_to_mpirun_exits_1_resumable(tmp_path):
    """The documented outcome of SIGTERM sent to mpirun: exit 1 (mpirun's own status when
    it is terminated), a resumable file, and a resume that ends bit for bit."""
    job = tmp_path / "job.toml"
    job.write_text(ens.JOB)
    reference = tmp_path / "ref.h5"
    assert ens.sdmpi("run", job, "-o", reference).returncode == 0
    out = tmp_path / "run.h5"
    proc = subprocess.Popen([ens.MPIRUN, "--oversubscribe", "-n", "2", sys.executable,
                             str(ens.DRIVER), "run", str(job), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=ens.child_env({"SDMPI_DOUBLE_SLEEP": "0.02"}))
    deadline = time.monotonic() + 30
    while not out.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=60)
    assert proc.returncode == 1
    info = ens.sdmpi("info", out)
    assert info.returncode == 0 and "resumable" in info.stdout
    res = ens.sdmpi("run", job, "-o", out)
    assert res.returncode == 0, res.stderr
    assert ens.task_data(out) == ens.task_data(reference)


def test_lubrication_key_must_be_a_boolean():
    from sdmpi.config import JobError, parse_job

    with pytest.raises(JobError, match='hydrodynamics.lubrication = "no": expected true or '
                                       'false, got a string'):
        parse_job('[hydrodynamics]\nlubrication = "no"\n')


def test_indefinite_far_field_stops_the_run_without_a_traceback(tmp_path):
    """Ewald sums too coarse for a tiny box: `sdmpi run` stops with exit 1 and one message
    that names the task, the step and hydrodynamics.ewald_tolerance; no traceback."""
    job = tmp_path / "job.toml"
    job.write_text('[job]\nname = "tiny-box"\nseed = 1\n[system]\nn_particles = 2\nphi = [0.45]\n'
                   "[shear]\nomega = [6.283185307179586]\n[integration]\nsteps_per_period = 200\n"
                   "periods = 1\ndiscard_periods = 0\n[ensemble]\nrealisations = 1\n"
                   "[hydrodynamics]\newald_tolerance = 1e-3\n")
    res = python_m("run", job, "-o", tmp_path / "run.h5", timeout=600)
    assert res.returncode == 1, res.stderr
    assert "task 0, step 0: the far-field mobility M_inf is not positive definite" in res.stderr
    assert "set a smaller hydrodynamics.ewald_tolerance" in res.stderr
    assert "Traceback" not in res.stderr
