"""Hydrodynamics: positions + box + strain -> grand mobility / resistance, and solves.

Knows nothing of time, MPI or files. Modules: `basis` (5-vector storage of symmetric
traceless tensors), `geometry` (Lees-Edwards lattice), `farfield` (Ewald FTS mobility),
`two_sphere` (exact two-sphere resistance functions), `lubrication` (R_2B - R_2B,inf),
`resistance` (assembly), `backend` (the interface of a solver backend), `solvers` (the
backends by name), `solve` (`solve_mobility`).
"""

from .solve import solve_mobility

__all__ = ["solve_mobility"]
