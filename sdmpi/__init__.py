"""sdmpi: MPI-parallel ensemble runner for Stokesian dynamics of colloidal suspensions.

Packages (data flows one way): ``config`` -> ``hydro`` -> ``dynamics`` -> ``ensemble``
-> ``analysis``; ``cli`` ties them together. See the README for units and conventions.

The Python API (docs/api.md, module :mod:`sdmpi.api`): ``sdmpi.load_job``,
``sdmpi.tasks``, ``sdmpi.Realisation``, ``sdmpi.Samples`` and
``sdmpi.hydro.solve_mobility``. They are imported on first use, so that ``import sdmpi``
does not load numpy (the command line sets the thread counts first); it chooses OpenBLAS's
kernels for the CPU when numpy is not loaded yet (`sdmpi._blas_kernel`).
"""

import importlib

__version__ = "0.1.0"

from ._blas_kernel import choose_openblas_kernel  # noqa: E402
from ._kernel_cache import ensure_kernels_can_load  # noqa: E402

choose_openblas_kernel()  # before anything loads numpy: the kernels `sdmpi run` uses
ensure_kernels_can_load()

_API = ("Realisation", "Samples", "load_job", "tasks")
_SUBPACKAGES = ("analysis", "config", "dynamics", "ensemble", "hydro")
__all__ = [*_API, *_SUBPACKAGES]


def __getattr__(name):
    if name in _API:
        return getattr(importlib.import_module(".api", __name__), name)
    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *__all__])
