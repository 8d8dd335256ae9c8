"""Run files without parallel HDF5: with an h5py built without MPI, one rank runs (the
file opened directly instead of through MPI-IO) and gives the same data; several ranks
are refused before anything is written, with a message naming what is missing."""

import subprocess
import sys

import pytest

from test_ensemble import HERE, JOB, MPIRUN, _env, needs_mpi, sdmpi, task_data

#: tests/ensemble_run.py with h5py's MPI support reported missing
SERIAL = ("import sys; sys.path.insert(0, sys.argv.pop(1)); from sdmpi import cli; "
          "from sdmpi.ensemble import store; store.parallel_hdf5 = lambda: False; "
          "from ensemble_double import DoubleRealisation; "
          "sys.exit(cli.main(sys.argv[1:], realisation_factory=DoubleRealisation))")


def serial_sdmpi(*args, ranks=None):
    cmd = [sys.executable, "-c", SERIAL, str(HERE), *map(str, args)]
    if ranks:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=_env(), timeout=120)


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
def test_several_ranks_without_parallel_hdf5_are_refused(job_file, tmp_path):
    out = tmp_path / "run.h5"
    res = serial_sdmpi("run", job_file, "-o", out, ranks=2)
    assert res.returncode == 2, res.stderr
    assert "sdmpi run on 2 ranks needs h5py built with MPI (parallel HDF5)" in res.stderr
    assert "h5py.get_config().mpi is False" in res.stderr and "one rank runs" in res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()
