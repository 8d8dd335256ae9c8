"""Time stepping of one SD realisation: shear protocol, interparticle forces, Brownian
terms, media. Knows nothing of MPI or files."""

from .realisation import Realisation

__all__ = ["Realisation"]
