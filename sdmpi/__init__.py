"""sdmpi: MPI-parallel ensemble runner for Stokesian dynamics of colloidal suspensions.

Packages (data flows one way): ``config`` -> ``hydro`` -> ``dynamics`` -> ``ensemble``
-> ``analysis``; ``cli`` ties them together. See the README for units and conventions.
"""

__version__ = "0.1.0"

from ._kernel_cache import ensure_kernels_can_load  # noqa: E402

ensure_kernels_can_load()
