"""The public hydrodynamics entry point `solve_mobility` (DESIGN.md contract 1)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .basis import from_five, to_five
from .geometry import check_box
from .krylov import DEFAULT_TOL
from .resistance import DEFAULT_EWALD_TOL
from .solvers import assemble, make_solver, resolve_backend

#: overlaps deeper than this fraction of the pair's mean radius are rejected
MAX_OVERLAP = 0.05


def _array(name, value, shape, n):
    arr = np.asarray(value, dtype=float)
    want = tuple(n if s is None else s for s in shape)
    if arr.shape != want:
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def check_inputs(positions: ArrayLike, box: ArrayLike | None, radii: ArrayLike | None, strain: float,
                 forces: ArrayLike | None, torques: ArrayLike | None, rate_of_strain: ArrayLike | None
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
    """Validate and normalise the arguments of `solve_mobility` (ValueError naming the
    argument on any problem).

    Args:
        positions, box, radii, strain, forces, torques, rate_of_strain: as for
            `solve_mobility`.

    Returns:
        positions (N, 3), box (3,) or None, radii (N,), strain, forces (N, 3), torques
        (N, 3), rate of strain (3, 3), as float arrays with the defaults filled in.

    Raises:
        ValueError: an argument of the wrong shape, not finite, radii not > 0, or a rate of
            strain not symmetric and traceless.
    """
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
        raise ValueError(f"positions must have shape (N, 3) with N >= 1, got {pos.shape}")
    n = pos.shape[0]
    pos = _array("positions", pos, (None, 3), n)
    box = check_box(box)
    radii = np.ones(n) if radii is None else _array("radii", radii, (None,), n)
    if np.any(radii <= 0):
        raise ValueError("radii must be > 0")
    if not np.isfinite(strain):
        raise ValueError(f"strain must be finite, got {strain}")
    forces = np.zeros((n, 3)) if forces is None else _array("forces", forces, (None, 3), n)
    torques = np.zeros((n, 3)) if torques is None else _array("torques", torques, (None, 3), n)
    if rate_of_strain is None:
        einf = np.zeros((3, 3))
    else:
        einf = _array("rate_of_strain", rate_of_strain, (3, 3), n)
        scale = max(np.abs(einf).max(), 1e-300)
        if np.abs(einf - einf.T).max() > 1e-12 * scale or abs(np.trace(einf)) > 1e-12 * scale:
            raise ValueError("rate_of_strain must be symmetric and traceless")
    return pos, box, radii, float(strain), forces, torques, einf


def solve_mobility(positions: ArrayLike, box: ArrayLike | None, *, radii: ArrayLike | None = None,
                   strain: float = 0.0, forces: ArrayLike | None = None, torques: ArrayLike | None = None,
                   rate_of_strain: ArrayLike | None = None, lubrication: bool = True,
                   solver: str = "dense", ewald_tol: float = DEFAULT_EWALD_TOL, comm: Any = None,
                   tolerance: float = DEFAULT_TOL) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Velocities and stresslets of N rigid spheres in Stokes flow (the FTS problem of
    Stokesian dynamics: far field by Ewald sums, Durlofsky, Brady & Bossis 1987,
    Beenakker 1986; exact two-sphere lubrication, Jeffrey & Onishi 1984).

    Plain Stokes units: fluid viscosity 1, lengths in any unit (radii in the same unit).
    Zero-volume-flux frame (the k = 0 Ewald term omitted). An isolated sphere gives
    U = F/(6 pi a), Omega = T/(8 pi a^3), S = (20/3) pi a^3 E_inf.

    Args:
        positions: (N, 3) sphere centres.
        box: (3,) sides (Lx, Ly, Lz) of a periodic Lees-Edwards box, or None for an
            unbounded fluid.
        radii: (N,) sphere radii (default: all 1).
        strain: Lees-Edwards strain of the box: the image at +Ly is shifted by strain Ly
            in x.
        forces: (N, 3) forces exerted on the spheres (default 0).
        torques: (N, 3) torques exerted on the spheres (default 0).
        rate_of_strain: (3, 3) symmetric traceless rate of strain E_inf of the imposed
            linear flow (default 0); simple shear u = gamma_dot y e_x has
            E_xy = E_yx = gamma_dot/2.
        lubrication: add the pairwise lubrication (near-field) resistance; False gives
            the far-field (Rotne-Prager level, FTS) mobility alone.
        solver: a solver backend of `sdmpi.registry.SOLVER_BACKENDS` ("dense": LAPACK,
            "petsc-dense", "petsc-krylov", ...) or "auto".
        ewald_tol: relative accuracy of the Ewald sums.
        comm: the MPI communicator a PETSc backend solves on, collective over it
            (default: this process alone).
        tolerance: relative residual of the iterative solves (petsc-krylov).

    Returns:
        U: (N, 3) translational velocities relative to the imposed flow at each centre.
        Omega: (N, 3) angular velocities relative to the imposed vorticity.
        S: (N, 3, 3) stresslets (symmetric, traceless).

    Raises:
        ValueError: an argument of the wrong shape, not finite, or spheres overlapping by
            more than MAX_OVERLAP of their mean radius (shallower overlaps and touching
            pairs are regularised: docs/numerics.md).
    """
    pos, box, radii, strain, forces, torques, einf = check_inputs(
        positions, box, radii, strain, forces, torques, rate_of_strain)
    if not 0.0 < tolerance < 1.0:
        raise ValueError(f"tolerance must be in (0, 1), got {tolerance}")
    if not 0.0 < ewald_tol < 1.0:
        raise ValueError(f"ewald_tol must be in (0, 1), got {ewald_tol}")
    if not isinstance(lubrication, (bool, np.bool_)):
        raise TypeError(f"lubrication must be True or False, got {lubrication!r}")
    name = resolve_backend(solver, pos.shape[0], comm)
    res = assemble(name, pos, radii, box, strain, lubrication, ewald_tol, max_overlap=MAX_OVERLAP, comm=comm)
    backend = make_solver(name, res, comm, tolerance)
    n = pos.shape[0]
    e5 = np.broadcast_to(to_five(einf), (n, 5))
    vel = backend.velocities(np.hstack([forces, torques]), e5)
    stress = backend.stresslets(vel, e5)
    return vel[:, :3], vel[:, 3:], from_five(stress)
