"""Shared set-up of the test suite (the thread counts and BLAS kernels: `tests/__init__.py`)."""

import pytest

from .runs import JOB, sdmpi


@pytest.fixture(scope="session")
def ensemble_job(tmp_path_factory):
    """The ensemble tests' job file (`runs.JOB`: 8 tasks of 48 steps); read-only."""
    path = tmp_path_factory.mktemp("job") / "job.toml"
    path.write_text(JOB)
    return path


@pytest.fixture(scope="session")
def ensemble_reference(ensemble_job, tmp_path_factory):
    """An uninterrupted one-rank run of `ensemble_job` with the test double; copy it
    before changing it."""
    out = tmp_path_factory.mktemp("ref") / "ref.h5"
    res = sdmpi("run", ensemble_job, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "complete (8 tasks)" in res.stdout
    return out
