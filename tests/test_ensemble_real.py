"""End to end with the real SD realisation: jobs/demo.toml, shortened, under mpirun -n 2,
against a one-rank run that was SIGKILLed mid-checkpoint and resumed on two ranks."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from .runs import child_env, task_data

ROOT = Path(__file__).resolve().parents[1]
MPIRUN = shutil.which("mpirun")
SHORT = ["--set", "integration.periods=1", "--set", "integration.discard_periods=0",
         "--set", "shear.omega=[25.132741228718345]", "--set", "output.checkpoint_every=40"]


def sdmpi(*args, ranks=None, env=None):
    """Run the real ``sdmpi`` command, plain or under mpirun -n RANKS."""
    cmd = [sys.executable, "-m", "sdmpi.cli", *map(str, args)]
    if ranks:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=child_env(env), timeout=300)


@pytest.mark.mpi
@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_real_demo_two_ranks_and_resume(tmp_path):
    job = ROOT / "jobs" / "demo.toml"
    ref, killed = tmp_path / "ref.h5", tmp_path / "killed.h5"
    res = sdmpi("run", job, "-o", ref, *SHORT, ranks=2)
    assert res.returncode == 0, res.stderr
    res = sdmpi("run", job, "-o", killed, *SHORT, env={"SDMPI_TEST_KILL": "commit:2"})
    assert res.returncode != 0
    res = sdmpi("run", job, "-o", killed, *SHORT, ranks=2)
    assert res.returncode == 0 and "resuming" in res.stdout, res.stderr
    assert task_data(killed) == task_data(ref)
    info = sdmpi("info", ref)
    assert info.returncode == 0 and "2/2 tasks complete" in info.stdout
