"""Initial configurations: equilibrium hard-sphere fluids in a cubic periodic box, and
hard-disk monolayers (`hard_disk_monolayer`).

Spheres of equal or unequal radii a_i start on a simple cubic lattice spaced for the
largest diameter (dense enough up to phi = (pi/6) sum_i a_i^3 / (N a_max^3), pi/6 = 0.524
for equal spheres; unequal spheres are placed on randomly permuted sites) and are
randomised by hard-sphere Metropolis Monte Carlo (trial displacements uniform in a cube,
rejected on overlap, |x_i - x_j| < a_i + a_j; Metropolis et al. 1953), which samples the equilibrium hard-sphere
distribution for the given volume fraction. Denser random packings (up to phi ~ 0.62) come
from `compress`: alternating MC sweeps with affine box shrinks limited by the closest
pair, a slow Lubachevsky-Stillinger-like compression (Lubachevsky & Stillinger 1990).
`hard_sphere_fluid` uses it for volume fractions the lattice cannot hold (dense
polydisperse suspensions, monodisperse phi >= pi/6): lattice + MC at LATTICE_FILL of the
lattice limit, compression to phi, then MC at phi (phi < ``START_PHI_LIMIT``).
Equal radii take exactly the arithmetic (and random stream) of the monodisperse code
before size classes existed, so old seeds give the same positions bit for bit.
"""

import math

import numba
import numpy as np

from ..config.schema import START_PHI_LIMIT

#: dense starts: the lattice is filled to this share of its limit before compressing
LATTICE_FILL = 0.9


def cubic_box(n_particles, phi, radius=1.0):
    """Side L of the cube holding n spheres of the given radius at volume fraction phi."""
    return (n_particles * 4.0 / 3.0 * math.pi * radius ** 3 / phi) ** (1.0 / 3.0)


def box_side(radii, phi):
    """Side L of the cube holding spheres of these radii (N,) at volume fraction phi
    (equal radii: exactly :func:`cubic_box`)."""
    radii = np.asarray(radii, float)
    if np.all(radii == radii[0]):
        return cubic_box(len(radii), phi, float(radii[0]))
    return (float(np.sum(radii ** 3)) * 4.0 / 3.0 * math.pi / phi) ** (1.0 / 3.0)


def _radii(n, radius, radii):
    """Per-particle radii (N,) from either a common radius or an array."""
    if radii is None:
        return np.full(n, float(radius))
    radii = np.ascontiguousarray(radii, dtype=float)
    if radii.shape != (n,) or not np.all(radii > 0):
        raise ValueError(f"radii must be {n} positive numbers, got shape {radii.shape}")
    return radii


@numba.njit(cache=True)
def _min_image(dx, side, strain):
    """Lees-Edwards minimum image of a separation (3,) in a cube at the given strain."""
    ny = round(dx[1] / side)
    dx[0] -= ny * strain * side
    dx[1] -= ny * side
    dx[0] -= side * round(dx[0] / side)
    dx[2] -= side * round(dx[2] / side)


@numba.njit(cache=True)
def _mc_sweeps(pos, side, radii, step, sweeps, seed, strain, dims=3):
    """MC sweeps moving the first ``dims`` coordinates (2: in the plane z = const)."""
    np.random.seed(seed)
    n = pos.shape[0]
    accepted = 0
    trial = np.empty(3)
    dx = np.empty(3)
    for _ in range(sweeps):
        for i in range(n):
            for c in range(3):
                trial[c] = pos[i, c] + (step * (2.0 * np.random.random() - 1.0) if c < dims else 0.0)
            ok = True
            for j in range(n):
                if j == i:
                    continue
                for c in range(3):
                    dx[c] = trial[c] - pos[j, c]
                _min_image(dx, side, strain)
                contact = radii[i] + radii[j]
                if dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2 < contact * contact:
                    ok = False
                    break
            if ok:
                pos[i, :] = trial
                accepted += 1
    return accepted / (sweeps * n)


def hard_sphere_fluid(n_particles, phi, rng, sweeps=200, radius=1.0, strain=0.0, radii=None):
    """Equilibrium hard-sphere configuration in a cube of side L with Lees-Edwards
    images at the given strain: positions (N, 3) (not wrapped) and L.

    Spheres have the common ``radius``, or the per-particle ``radii`` (N,) when given
    (then L comes from their total volume, :func:`box_side`). n_particles must be a
    perfect cube (lattice start: layers L/m > 2 a_max apart in y, so no overlap at any
    strain), which holds phi < (pi/6) sum_i a_i^3 / (N a_max^3) (pi/6 for equal spheres). Unequal
    spheres take the lattice sites in an order drawn from ``rng`` (equal ones in raster
    order, drawing nothing). The MC step is tuned to ~40% acceptance. At or above the
    lattice limit (phi < START_PHI_LIMIT) the lattice is filled to LATTICE_FILL x the
    limit, equilibrated, compressed (:func:`compress`) and equilibrated again at phi by
    ``sweeps`` more sweeps; RuntimeError if the compression jams."""
    m = round(n_particles ** (1 / 3))
    if m ** 3 != n_particles:
        raise ValueError(f"n_particles must be a perfect cube for a lattice start, got {n_particles}")
    radii = _radii(n_particles, radius, radii)
    a_max = float(radii.max())
    limit = math.pi / 6 * float(np.mean((radii / a_max) ** 3))
    if not 0 < phi < START_PHI_LIMIT:
        raise ValueError(f"phi must be in (0, {START_PHI_LIMIT}) (a lattice start below the "
                         f"lattice limit pi/6 <(a/a_max)^3> = {limit:.4f} for a spacing of the "
                         f"largest diameter, a compressed one above it), got {phi}")
    start = phi if phi < limit else LATTICE_FILL * limit
    side = box_side(radii, start)
    grid = (np.arange(m) + 0.5) * side / m
    pos = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    if np.any(radii != radii[0]):
        pos = pos[rng.permutation(n_particles)]
    _equilibrate(pos, side, radii, 0.5 * (side / m - 2 * a_max) + 0.01, sweeps, rng, strain)
    if start < phi:
        pos, side = compress(pos, side, phi, rng, radius=radius, strain=strain, radii=radii)
        _equilibrate(pos, side, radii, 0.05 * a_max, sweeps, rng, strain)
    return pos, side


def _equilibrate(pos, side, radii, step, sweeps, rng, strain, dims=3):
    """MC sweeps in 10 blocks, the step tuned to ~40% acceptance after each block."""
    seed = int(rng.integers(2 ** 31))
    for block in range(10):
        rate = _mc_sweeps(pos, side, radii, step, max(sweeps // 10, 1), seed + block, strain, dims)
        step *= min(max(rate / 0.4, 0.5), 2.0)


def square_side(n_particles, phi_a):
    """Side L of the square cell holding n unit disks at areal fraction phi_a."""
    return math.sqrt(n_particles * math.pi / phi_a)


def hard_disk_monolayer(n_particles, phi_a, rng, z=0.0, sweeps=200, strain=0.0):
    """Random non-overlapping monolayer of unit spheres, centres in the plane z, in a square
    cell of side L = :func:`square_side` (periodic in x and y): positions (N, 3) and L.

    Start: N of the m x m sites of a square lattice, m = ceil(sqrt N), spaced L/m > 2 (so
    phi_a < pi N / (4 m^2), = pi/4 when N = m^2; a random choice of sites when N < m^2),
    then hard-disk Metropolis MC in the plane (as :func:`hard_sphere_fluid`, 2D moves),
    which samples the equilibrium hard-disk fluid at phi_a (seed 001: random starts), with
    Lees-Edwards images at the given strain (rows L/m > 2 apart in y: no overlap at any
    strain at the start)."""
    m = math.isqrt(n_particles - 1) + 1
    side = square_side(n_particles, phi_a)
    if side / m <= 2.0:
        raise ValueError(f"phi_a must be below pi N/(4 m^2) = {math.pi * n_particles / (4 * m * m):.4f} "
                         f"for the {m} x {m} lattice start of N = {n_particles}, got {phi_a}")
    sites = np.arange(m * m) if n_particles == m * m else np.sort(rng.permutation(m * m)[:n_particles])
    grid = (np.arange(m) + 0.5) * side / m
    pos = np.column_stack([grid[sites // m], grid[sites % m], np.full(n_particles, float(z))])
    _equilibrate(pos, side, np.ones(n_particles), 0.5 * (side / m - 2.0) + 0.01, sweeps, rng, strain,
                 dims=2)
    return pos, side


@numba.njit(cache=True)
def _contact_ratio(pos, side, strain, radii):
    """Smallest |x_i - x_j| / (a_i + a_j) (Lees-Edwards minimum image) in a cube."""
    n = pos.shape[0]
    best = np.inf
    dx = np.empty(3)
    for i in range(n):
        for j in range(i + 1, n):
            for c in range(3):
                dx[c] = pos[i, c] - pos[j, c]
            _min_image(dx, side, strain)
            contact = radii[i] + radii[j]
            best = min(best, (dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2) / (contact * contact))
    return math.sqrt(best)


def min_distance(pos, side, strain=0.0):
    """Smallest centre distance (Lees-Edwards minimum image) in a cube."""
    return _contact_ratio(pos, side, strain, np.full(len(pos), 0.5))


def min_gap_ratio(pos, side, radii, strain=0.0):
    """Smallest |x_i - x_j| / (a_i + a_j) over pairs (>= 1: no overlap)."""
    return _contact_ratio(pos, side, strain, np.ascontiguousarray(radii, dtype=float))


def compress(pos, side, phi_target, rng, sweeps_per_shrink=5, radius=1.0, max_shrinks=20000, strain=0.0,
             radii=None):
    """Compress a hard-sphere configuration (N, 3) in a cube of the given side (Lees-Edwards
    strain fixed) to volume fraction phi_target; spheres of the common ``radius`` or of the
    per-particle ``radii``. Returns (positions, side). Raises RuntimeError if it jams."""
    pos = pos.copy()
    n = len(pos)
    radii = _radii(n, radius, radii)
    target = box_side(radii, phi_target)
    step = 0.05
    for _ in range(max_shrinks):
        if side <= target:
            return pos, side
        ratio = _contact_ratio(pos, side, strain, radii)
        factor = max(1.0 / ratio * (1 + 1e-9), target / side)
        pos *= factor
        side *= factor
        rate = _mc_sweeps(pos, side, radii, step, sweeps_per_shrink, int(rng.integers(2 ** 31)), strain)
        step = min(max(step * (0.5 + rate / 0.4 * 0.5), 1e-4), 0.5)
    volume = 4.0 / 3.0 * math.pi * float(np.sum(radii ** 3))
    raise RuntimeError(f"compression to phi = {phi_target} jammed at phi = {volume / side ** 3:.3f}")
