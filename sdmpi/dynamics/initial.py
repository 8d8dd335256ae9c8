"""Initial configurations: equilibrium hard-sphere fluids in a cubic periodic box.

Spheres start on a simple cubic lattice (dense enough up to phi = pi/6 = 0.524) and are
randomised by hard-sphere Metropolis Monte Carlo (trial displacements uniform in a cube,
rejected on overlap; Metropolis et al. 1953), which samples the equilibrium hard-sphere
distribution for the given volume fraction. Above pi/6 the lattice start is impossible;
such systems are out of this generator's range.
"""

import math

import numba
import numpy as np


def cubic_box(n_particles, phi, radius=1.0):
    """Side L of the cube holding n spheres of the given radius at volume fraction phi."""
    return (n_particles * 4.0 / 3.0 * math.pi * radius ** 3 / phi) ** (1.0 / 3.0)


@numba.njit(cache=True)
def _mc_sweeps(pos, side, diameter, step, sweeps, seed):
    np.random.seed(seed)
    n = pos.shape[0]
    d2 = diameter * diameter
    accepted = 0
    trial = np.empty(3)
    for _ in range(sweeps):
        for i in range(n):
            for c in range(3):
                trial[c] = pos[i, c] + step * (2.0 * np.random.random() - 1.0)
                trial[c] -= side * math.floor(trial[c] / side)
            ok = True
            for j in range(n):
                if j == i:
                    continue
                r2 = 0.0
                for c in range(3):
                    dx = trial[c] - pos[j, c]
                    dx -= side * round(dx / side)
                    r2 += dx * dx
                if r2 < d2:
                    ok = False
                    break
            if ok:
                pos[i, :] = trial
                accepted += 1
    return accepted / (sweeps * n)


def hard_sphere_fluid(n_particles, phi, rng, sweeps=200, radius=1.0):
    """Equilibrium hard-sphere configuration: positions (N, 3) in [0, L)^3 and L.

    n_particles must be a perfect cube (lattice start) and phi < pi/6. The MC step is
    tuned during the first sweeps to ~40% acceptance."""
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
        rate = _mc_sweeps(pos, side, 2 * radius, step, max(sweeps // 10, 1), seed + block)
        step *= min(max(rate / 0.4, 0.5), 2.0)
    return pos, side
