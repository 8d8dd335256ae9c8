"""Time stepping of one SD realisation: shear protocol, interparticle forces, Brownian
terms, media. Knows nothing of MPI or files.

``Realisation`` (`realisation`) is imported on first use, so that the job checks of
`checks` load without the hydrodynamics.
"""

import importlib

__all__ = ["Realisation"]


def __getattr__(name):
    if name == "Realisation":
        return importlib.import_module(".realisation", __name__).Realisation
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
