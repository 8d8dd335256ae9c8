"""Run files without parallel HDF5: with an h5py built without MPI the file is opened
directly instead of through MPI-IO; on several ranks world rank 0 writes what every rank
commits. Either way the data are those of a parallel-HDF5 run."""

import pytest

from pathlib import Path

from .runs import needs_mpi, sdmpi, task_data


def serial_sdmpi(*args, ranks=None, env=None):
    """``sdmpi ARGS`` with the double and h5py's MPI support reported missing."""
    return sdmpi("--serial-h5py", *args, ranks=ranks, env=env)


def test_one_rank_runs_without_parallel_hdf5(ensemble_job, tmp_path):
    serial, parallel = tmp_path / "serial.h5", tmp_path / "parallel.h5"
    res = serial_sdmpi("run", ensemble_job, "-o", serial)
    assert res.returncode == 0, res.stderr
    assert "complete (8 tasks)" in res.stdout
    res = sdmpi("run", ensemble_job, "-o", parallel)
    assert res.returncode == 0, res.stderr
    assert task_data(serial) == task_data(parallel)
    assert sdmpi("info", serial).returncode == 0


@pytest.mark.mpi
@needs_mpi
def test_several_ranks_without_parallel_hdf5_write_through_rank_0(ensemble_job,
                                                                   ensemble_reference, tmp_path):
    """Two ranks, serial h5py: rank 0 writes every rank's commits; the file's data are
    those of a one-rank run, and a SIGKILL of either rank, then a resume on two ranks,
    ends with the same data."""
    serial = tmp_path / "serial2.h5"
    res = serial_sdmpi("run", ensemble_job, "-o", serial, ranks=2)
    assert res.returncode == 0, res.stderr
    assert "complete (8 tasks)" in res.stdout and "rank 0 applied" in res.stdout
    assert task_data(serial) == task_data(ensemble_reference)
    logs = Path(str(serial) + ".logs")
    assert {p.name for p in logs.glob("rank-*.log")} == {"rank-0.log", "rank-1.log"}
    killed = tmp_path / "killed.h5"
    for kill in ("commit:3", "step:30"):  # each rank counts its own points (writer: rank 0)
        res = serial_sdmpi("run", ensemble_job, "-o", killed, ranks=2,
                           env={"SDMPI_TEST_KILL": kill})
        assert res.returncode != 0
        assert sdmpi("info", killed).returncode == 0
    res = serial_sdmpi("run", ensemble_job, "-o", killed, ranks=2)
    assert res.returncode == 0, res.stderr
    assert task_data(killed) == task_data(ensemble_reference)
