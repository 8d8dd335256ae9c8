"""sdmpi's test suite (a package: its helper modules are imported relative to it).

One BLAS/OpenMP thread and OpenBLAS's kernels chosen as `sdmpi run` chooses them
(`sdmpi._blas_kernel`): the tests compare sample streams and run files bit for bit, which
holds with one thread and one kernel set. Set here, before any test module imports numpy,
for pytest (which imports this package first) and for ``python -m tests.<module>`` alike.
"""

import os
import sys
import warnings

if "numpy" in sys.modules:  # a plugin imported it first: its BLAS keeps its threads and kernels
    warnings.warn("numpy was imported before the test package set one BLAS thread; run "
                  "with OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1")
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import sdmpi  # noqa: E402,F401  (loads no numpy; its import chooses OpenBLAS's kernels)
