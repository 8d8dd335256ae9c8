"""Bulk stress from particle stresslets (Batchelor 1970): Sigma = -p I + 2 E + n <S>
(viscosity 1, n = N/V), and the hydrodynamic viscosity it implies."""

from __future__ import annotations

from typing import Any

import numpy as np

from .solve import solve_mobility

#: simple shear at unit rate: E_xy = E_yx = 1/2
UNIT_SHEAR = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])


def hydrodynamic_viscosity(positions: np.ndarray, box: np.ndarray, *, radii: np.ndarray | None = None,
                           strain: float = 0.0, **solve_kwargs: Any) -> float:
    """eta_H = n <S_xy> / gamma_dot for force- and torque-free spheres in a periodic box
    sheared at unit rate: the particle part of the high-frequency (instantaneous)
    viscosity, relative to the medium viscosity (eta'_inf = 1 + eta_H).

    Args:
        positions: (N, 3) sphere centres (length unit of the radii).
        box: (3,) sides of the periodic Lees-Edwards box (same unit).
        radii: (N,) sphere radii (default: all 1).
        strain: Lees-Edwards strain of the box.
        **solve_kwargs: further keyword arguments of `solve.solve_mobility` (lubrication,
            solver, ewald_tol, comm, tolerance).

    Returns:
        eta_H, dimensionless (in units of the medium viscosity).
    """
    _, _, s = solve_mobility(positions, box, radii=radii, strain=strain, rate_of_strain=UNIT_SHEAR,
                             **solve_kwargs)
    return len(positions) / float(np.prod(box)) * s[:, 0, 1].mean()
