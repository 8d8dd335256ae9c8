"""Run files without parallel HDF5: with an h5py built without MPI the file is opened
directly instead of through MPI-IO; on several ranks world rank 0 writes what every rank
commits. Either way the data are those of a parallel-HDF5 run."""

import subprocess
import sys

import pytest

from test_ensemble import HERE, JOB, MPIRUN, _env, logs, needs_mpi, sdmpi, task_data

#: tests/ensemble_run.py with h5py's MPI support reported missing
SERIAL = ("import sys; sys.path.insert(0, sys.argv.pop(1)); from sdmpi import cli; "
          "from sdmpi.ensemble import store; store.parallel_hdf5 = lambda: False; "
          "from ensemble_double import DoubleRealisation; "
          "sys.exit(cli.main(sys.argv[1:], realisation_factory=DoubleRealisation))")


def serial_sdmpi(*args, ranks=None, env=None):
    cmd = [sys.executable, "-c", SERIAL, str(HERE), *map(str, args)]
    if ranks:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=_env(env), timeout=120)


@pytest.fixture
def job_file(tmp_path):
    path = tmp_path / "job.toml"
    path.write_text(JOB)
    return path


def test_one_rank_runs_without_parallel_hdf5(job_file, tmp_path):
    serial, parallel = tmp_path / "serial.h5", tmp_path / "parallel.h5"
    res = serial_sdmpi("run", job_file, "-o", serial)
    assert res.returncode == 0, res.stderr
    assert "complete (8 tasks)" in res.stdout
    res = sdmpi("run", job_file, "-o", parallel)
    assert res.returncode == 0, res.stderr
    assert task_data(serial) == task_data(parallel)
    assert sdmpi("info", serial).returncode == 0


@pytest.mark.mpi
@needs_mpi
def test_several_ranks_without_parallel_hdf5_write_through_rank_0(job_file, tmp_path):
    """Two ranks, serial h5py: rank 0 writes every rank's commits; the file's data are
    those of a one-rank run, and a SIGKILL of either rank, then a resume on two ranks,
    ends with the same data."""
    serial, parallel = tmp_path / "serial2.h5", tmp_path / "parallel.h5"
    assert sdmpi("run", job_file, "-o", parallel).returncode == 0
    res = serial_sdmpi("run", job_file, "-o", serial, ranks=2)
    assert res.returncode == 0, res.stderr
    assert "complete (8 tasks)" in res.stdout
    assert task_data(serial) == task_data(parallel)
    assert {p.name for p in logs(serial).glob("rank-*.log")} == {"rank-0.log", "rank-1.log"}
    killed = tmp_path / "killed.h5"
    for kill in ("commit:3", "step:30"):  # rank 1 counts its own points (writer: rank 0)
        res = serial_sdmpi("run", job_file, "-o", killed, ranks=2,
                           env={"SDMPI_TEST_KILL": kill})
        assert res.returncode != 0
        assert sdmpi("info", killed).returncode == 0
    res = serial_sdmpi("run", job_file, "-o", killed, ranks=2)
    assert res.returncode == 0, res.stderr
    assert task_data(killed) == task_data(parallel)
