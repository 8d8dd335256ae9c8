"""Shared set-up of the test suite.

One BLAS/OpenMP thread: the tests compare sample streams and run files bit for bit, which
holds with one thread (`sdmpi run` sets the same unless told otherwise). The variables are
set here, before any test module imports numpy, also when pytest runs outside
``make test``.
"""

import os
import sys
import warnings

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"
if "numpy" in sys.modules:  # a plugin imported it first: its BLAS keeps its thread count
    warnings.warn("numpy was imported before tests/conftest.py set one BLAS thread; run "
                  "with OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1")

import pytest  # noqa: E402

from .runs import JOB, sdmpi  # noqa: E402


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
