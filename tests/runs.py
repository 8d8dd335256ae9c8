"""Helpers shared by the tests that run sdmpi: the environment of a child process, the
runner with the cheap test double (``tests/ensemble_run.py``), the 8-task job it runs,
comparisons of run files, and the state of a fresh process for in-process realisations."""

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DRIVER = HERE / "ensemble_run.py"
MPIRUN = shutil.which("mpirun")
needs_mpi = pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")

#: the ensemble tests' job: 8 tasks of 48 steps with the test double
JOB = """\
[job]
name = "ensemble-test"
seed = 7

[system]
n_particles = 8
phi = [0.2, 0.3]

[medium]
kind = "maxwell"
modes = [{eta = 0.6, lambda = 0.5}, {eta = 0.4, lambda = 2.0}]

[shear]
omega = [2.0, 8.0]

[integration]
steps_per_period = 16
periods = 3
discard_periods = 1

[ensemble]
realisations = 2

[output]
per_particle = true
checkpoint_every = 10
"""
N_TASKS, N_STEPS = 8, 48


def child_env(extra=None):
    """The environment of a child sdmpi process: this one's without sdmpi's fault-injection
    variables or an enclosing mpirun's, Open MPI allowed as root and oversubscribed."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SDMPI_", "OMPI_COMM"))}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    env.update(extra or {})
    return env


def sdmpi(*args, ranks=None, env=None, timeout=120):
    """Run ``sdmpi ARGS`` with the double: plain (one rank) or under mpirun -n RANKS."""
    cmd = [sys.executable, str(DRIVER), *map(str, args)]
    if ranks:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=child_env(env), timeout=timeout)


def task_data(path):
    """Every dataset under /tasks, and /progress, as bytes."""
    out = {}
    with h5py.File(path, "r") as f:
        f["tasks"].visititems(
            lambda name, obj: out.__setitem__(name, obj[()].tobytes())
            if isinstance(obj, h5py.Dataset) else None)
        out["progress"] = f["progress"][()].tobytes()
    return out


def digest(path):
    """SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def fresh_lubrication_tables():
    """Empty this process's two-sphere lubrication tables (`sdmpi.hydro.lubrication`), so
    that the next realisation steps as the first one of a fresh process (the first task
    of `sdmpi run` on a rank): the last bits of a sample stream depend on the tables that
    earlier realisations built (docs/api.md)."""
    from sdmpi.hydro import lubrication
    lubrication._STORE = lubrication._TableStore()
