"""Initial configurations: equilibrium hard-sphere fluids in a cubic periodic box.

Spheres start on a simple cubic lattice (dense enough up to phi = pi/6 = 0.524) and are
randomised by hard-sphere Metropolis Monte Carlo (trial displacements uniform in a cube,
rejected on overlap; Metropolis et al. 1953), which samples the equilibrium hard-sphere
distribution for the given volume fraction. Denser random packings (up to phi ~ 0.62) come
from `compress`: alternating MC sweeps with affine box shrinks limited by the closest
pair, a slow Lubachevsky-Stillinger-like compression (Lubachevsky & Stillinger 1990).
"""

import math

import numba
import numpy as np


def cubic_box(n_particles, phi, radius=1.0):
    """Side L of the cube holding n spheres of the given radius at volume fraction phi."""
    return (n_particles * 4.0 / 3.0 * math.pi * radius ** 3 / phi) ** (1.0 / 3.0)


@numba.njit(cache=True)
def _min_image(dx, side, strain):
    """Lees-Edwards minimum image of a separation (3,) in a cube at the given strain."""
    ny = round(dx[1] / side)
    dx[0] -= ny * strain * side
    dx[1] -= ny * side
    dx[0] -= side * round(dx[0] / side)
    dx[2] -= side * round(dx[2] / side)


@numba.njit(cache=True)
def _mc_sweeps(pos, side, diameter, step, sweeps, seed, strain):
    np.random.seed(seed)
    n = pos.shape[0]
    d2 = diameter * diameter
    accepted = 0
    trial = np.empty(3)
    dx = np.empty(3)
    for _ in range(sweeps):
        for i in range(n):
            for c in range(3):
                trial[c] = pos[i, c] + step * (2.0 * np.random.random() - 1.0)
            ok = True
            for j in range(n):
                if j == i:
                    continue
                for c in range(3):
                    dx[c] = trial[c] - pos[j, c]
                _min_image(dx, side, strain)
                if dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2 < d2:
                    ok = False
                    break
            if ok:
                pos[i, :] = trial
                accepted += 1
    return accepted / (sweeps * n)


def hard_sphere_fluid(n_particles, phi, rng, sweeps=200, radius=1.0, strain=0.0):
    """Equilibrium hard-sphere configuration in a cube of side L with Lees-Edwards
    images at the given strain: positions (N, 3) (not wrapped) and L.

    n_particles must be a perfect cube (lattice start: layers L/m > 2a apart in y, so
    no overlap at any strain) and phi < pi/6. The MC step is tuned to ~40% acceptance."""
    m = round(n_particles ** (1 / 3))
    if m ** 3 != n_particles:
        raise ValueError(f"n_particles must be a perfect cube for a lattice start, got {n_particles}")
    if not 0 < phi < math.pi / 6:
        raise ValueError(f"phi must be in (0, pi/6 = 0.5236) for a lattice start, got {phi}")
    side = cubic_box(n_particles, phi, radius)
    grid = (np.arange(m) + 0.5) * side / m
    pos = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    step = 0.5 * (side / m - 2 * radius) + 0.01
    seed = int(rng.integers(2 ** 31))
    for block in range(10):
        rate = _mc_sweeps(pos, side, 2 * radius, step, max(sweeps // 10, 1), seed + block, strain)
        step *= min(max(rate / 0.4, 0.5), 2.0)
    return pos, side


@numba.njit(cache=True)
def min_distance(pos, side, strain=0.0):
    """Smallest centre distance (Lees-Edwards minimum image) in a cube."""
    n = pos.shape[0]
    best = np.inf
    dx = np.empty(3)
    for i in range(n):
        for j in range(i + 1, n):
            for c in range(3):
                dx[c] = pos[i, c] - pos[j, c]
            _min_image(dx, side, strain)
            best = min(best, dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2)
    return math.sqrt(best)


def compress(pos, side, phi_target, rng, sweeps_per_shrink=5, radius=1.0, max_shrinks=20000, strain=0.0):
    """Compress a hard-sphere configuration (N, 3) in a cube of the given side (Lees-Edwards
    strain fixed) to volume fraction phi_target. Returns (positions, side). Raises
    RuntimeError if it jams."""
    pos = pos.copy()
    n = len(pos)
    target = cubic_box(n, phi_target, radius)
    step = 0.05
    for _ in range(max_shrinks):
        if side <= target:
            return pos, side
        dmin = min_distance(pos, side, strain)
        factor = max(2 * radius / dmin * (1 + 1e-9), target / side)
        pos *= factor
        side *= factor
        rate = _mc_sweeps(pos, side, 2 * radius, step, sweeps_per_shrink, int(rng.integers(2 ** 31)), strain)
        step = min(max(step * (0.5 + rate / 0.4 * 0.5), 1e-4), 0.5)
    raise RuntimeError(f"compression to phi = {phi_target} jammed at phi = {n * 4 / 3 * math.pi / side ** 3:.3f}")
