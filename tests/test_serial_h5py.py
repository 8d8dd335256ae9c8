"""Run files without parallel HDF5: with an h5py built without MPI, one rank runs (the
file opened directly instead of through MPI-IO) and gives the same data; several ranks
are refused before anything is written, with a message naming what is missing."""

import pytest

from .runs import needs_mpi, sdmpi, task_data


def serial_sdmpi(*args, ranks=None):
    """``sdmpi ARGS`` with the double and h5py's MPI support reported missing."""
    return sdmpi("--serial-h5py", *args, ranks=ranks)


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
def test_several_ranks_without_parallel_hdf5_are_refused(ensemble_job, tmp_path):
    out = tmp_path / "run.h5"
    res = serial_sdmpi("run", ensemble_job, "-o", out, ranks=2)
    assert res.returncode == 2, res.stderr
    assert "sdmpi run on 2 ranks needs h5py built with MPI (parallel HDF5)" in res.stderr
    assert "h5py.get_config().mpi is False" in res.stderr and "one rank runs" in res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()
