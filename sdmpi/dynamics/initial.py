"""Initial configurations: equilibrium hard-sphere fluids in a cubic periodic box, and
hard-disk monolayers (`hard_disk_monolayer`).

Any number N of spheres of equal or unequal radii a_i start on N of the m^3 >= N sites
of a simple cubic lattice spaced for the largest diameter (dense enough up to phi =
(pi/6) sum_i a_i^3 / (m^3 a_max^3), pi/6 = 0.524 for N = m^3 equal spheres; unequal
spheres, or N < m^3, take randomly drawn sites) and are randomised by hard-sphere
Metropolis Monte Carlo (trial displacements uniform in a cube, rejected on overlap,
|x_i - x_j| < a_i + a_j; Metropolis et al. 1953), which samples the equilibrium
hard-sphere distribution for the given volume fraction; the overlap checks use a cell
list, O(N) per sweep, and give the same moves as checking every pair. The lattice's
memory decays slowly: at N = 27 its Bragg peak S(k_L), k_L = 2 pi m / L along each axis,
is still 5 (phi = 0.45) and 24 (phi = 0.5) after 200 sweeps, against the fluid's ~2 after
3000, and the high-frequency viscosity of such starts is 13% (phi = 0.45) and 45% (0.5)
below that of equilibrated ones; the default, START_SWEEPS, melts it. Denser random
packings (up to phi ~ 0.62) come from `compress`: alternating MC sweeps with affine box
shrinks limited by the closest pair, a slow Lubachevsky-Stillinger-like compression
(Lubachevsky & Stillinger 1990). `hard_sphere_fluid` uses it for volume fractions the
lattice cannot hold: lattice + MC at LATTICE_FILL of the lattice limit, compression to
phi, then MC at phi (phi < ``START_PHI_LIMIT``). Equal radii given as an array take
exactly the arithmetic and random stream of a common radius, so a job's positions depend
only on its seed, N and phi. Lengths are in particle radii a.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..config.schema import START_PHI_LIMIT, START_SWEEPS, lattice_sites_per_axis
from ..hydro.geometry import Lattice, find_pairs

#: dense starts: the lattice is filled to this share of its limit before compressing
LATTICE_FILL = 0.9
#: dense starts: compressions tried (each with new random draws) before giving up
COMPRESS_ATTEMPTS = 5


class Jammed(RuntimeError):
    """A compression (:func:`compress`) that stopped below its target volume fraction."""


def cubic_box(n_particles: int, phi: float, radius: float = 1.0) -> float:
    """Side L of the cube holding n spheres of the given radius at volume fraction phi.

    Args:
        n_particles: number of spheres N.
        phi: volume fraction, > 0.
        radius: sphere radius, in a.

    Returns:
        L, in a.
    """
    return (n_particles * 4.0 / 3.0 * math.pi * radius ** 3 / phi) ** (1.0 / 3.0)


def box_side(radii: np.ndarray, phi: float) -> float:
    """Side L of the cube holding spheres of these radii (N,) at volume fraction phi
    (equal radii: exactly :func:`cubic_box`).

    Args:
        radii: sphere radii, shape (N,), in a (any array-like).
        phi: volume fraction, > 0.

    Returns:
        L, in a.
    """
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
    """MC sweeps moving the first ``dims`` coordinates (2: in the plane z = const).

    Overlap checks see only the spheres in the 27 cells around the trial position (cell
    list in the lattice coordinates of the sheared box, `_cells`), when every cell's
    plane spacing is >= the largest contact distance and there are >= 3 cells per axis;
    otherwise all spheres. Either way a sphere closer than contact is always checked,
    by the same `_min_image` arithmetic, so both give the same moves bit for bit."""
    np.random.seed(seed)
    n = pos.shape[0]
    cells = _cell_counts(side, strain, 2.0 * radii.max())
    head, nxt, cell_of = _cells(pos, side, strain, cells)
    accepted = 0
    trial = np.empty(3)
    dx = np.empty(3)
    near = np.empty(n, dtype=np.int64)
    for _ in range(sweeps):
        for i in range(n):
            for c in range(3):
                trial[c] = pos[i, c] + (step * (2.0 * np.random.random() - 1.0) if c < dims else 0.0)
            new_cell = _cell_index(trial, side, strain, cells)
            count = _neighbours(new_cell, cells, head, nxt, near)
            ok = True
            for k in range(count):
                j = near[k]
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
                if new_cell != cell_of[i]:
                    _move(i, cell_of[i], new_cell, head, nxt)
                    cell_of[i] = new_cell
    return accepted / (sweeps * n)


@numba.njit(cache=True)
def _cell_counts(side, strain, reach):
    """Cells per lattice axis (3,): the box's plane spacings (L/sqrt(1 + strain^2), L, L
    for the lattice vectors (L, 0, 0), (strain L, L, 0), (0, 0, L)) over reach, floored;
    all 1 (one cell: every sphere checked) unless each is >= 3."""
    spacing = np.array([side / math.sqrt(1.0 + strain * strain), side, side])
    counts = np.empty(3, dtype=np.int64)
    for c in range(3):
        counts[c] = int(spacing[c] // reach)
    if counts.min() < 3:
        counts[:] = 1
    return counts


@numba.njit(cache=True)
def _cell_index(x, side, strain, cells):
    """Flat index of the cell holding position x (any image): lattice coordinates
    ((x - strain y)/L, y/L, z/L) wrapped into [0, 1)."""
    frac = np.array([(x[0] - strain * x[1]) / side, x[1] / side, x[2] / side])
    index = 0
    for c in range(3):
        f = frac[c] - math.floor(frac[c])
        k = min(int(f * cells[c]), cells[c] - 1)
        index = index * cells[c] + k
    return index


@numba.njit(cache=True)
def _cells(pos, side, strain, cells):
    """Linked-list cell list: head[cell] (first sphere, -1: empty), nxt[i] (next sphere
    in i's cell), cell_of[i]."""
    head = np.full(cells[0] * cells[1] * cells[2], -1, dtype=np.int64)
    nxt = np.full(pos.shape[0], -1, dtype=np.int64)
    cell_of = np.empty(pos.shape[0], dtype=np.int64)
    for i in range(pos.shape[0]):
        cell = _cell_index(pos[i], side, strain, cells)
        cell_of[i] = cell
        nxt[i] = head[cell]
        head[cell] = i
    return head, nxt, cell_of


@numba.njit(cache=True)
def _move(i, old, new, head, nxt):
    """Moves sphere i from cell old to cell new."""
    if head[old] == i:
        head[old] = nxt[i]
    else:
        k = head[old]
        while nxt[k] != i:
            k = nxt[k]
        nxt[k] = nxt[i]
    nxt[i] = head[new]
    head[new] = i


@numba.njit(cache=True)
def _neighbours(cell, cells, head, nxt, out):
    """The spheres in the cell and its 26 neighbours (periodic in lattice coordinates;
    just the one cell when there is only one) into out; returns how many."""
    m0, m1, m2 = cells[0], cells[1], cells[2]
    c0, rest = divmod(cell, m1 * m2)
    c1, c2 = divmod(rest, m2)
    reach = 0 if m0 == 1 else 1
    count = 0
    for d0 in range(-reach, reach + 1):
        for d1 in range(-reach, reach + 1):
            for d2 in range(-reach, reach + 1):
                k = head[(((c0 + d0) % m0) * m1 + (c1 + d1) % m1) * m2 + (c2 + d2) % m2]
                while k >= 0:
                    out[count] = k
                    count += 1
                    k = nxt[k]
    return count


def hard_sphere_fluid(
    n_particles: int,
    phi: float,
    rng: np.random.Generator,
    sweeps: int = START_SWEEPS,
    radius: float = 1.0,
    strain: float = 0.0,
    radii: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Equilibrium hard-sphere configuration in a cube of side L with Lees-Edwards
    images at the given strain: positions (N, 3) (not wrapped) and L.

    Spheres have the common ``radius``, or the per-particle ``radii`` (N,) when given
    (then L comes from their total volume, :func:`box_side`). The start is a simple cubic
    lattice of m^3 >= N sites, m = ceil(N^(1/3)) (layers L/m > 2 a_max apart in y, so no
    overlap at any strain), which holds phi < (pi/6) sum_i a_i^3 / (m^3 a_max^3) (pi/6 for
    N = m^3 equal spheres). When N < m^3, or the spheres are unequal, they take N of the
    sites in an order drawn from ``rng`` (rng.permutation(m^3)[:N]); N = m^3 equal spheres
    fill the lattice in raster order, drawing nothing. ``sweeps`` MC sweeps (N trial
    moves each) follow, the step tuned to ~40% acceptance. At or above the
    lattice limit (phi < START_PHI_LIMIT) the lattice is filled to LATTICE_FILL x the
    limit, equilibrated, compressed (:func:`compress`) and equilibrated again at phi by
    ``sweeps`` more sweeps; :class:`Jammed` if the compression jams COMPRESS_ATTEMPTS times.

    Args:
        n_particles: number of spheres N.
        phi: volume fraction, in (0, START_PHI_LIMIT).
        rng: the random stream of the start.
        sweeps: MC sweeps at each equilibration.
        radius: common sphere radius, in a (used when radii is None).
        strain: Lees-Edwards strain of the images, dimensionless.
        radii: per-particle radii, shape (N,), in a, or None.

    Returns:
        (positions (N, 3) in a, not wrapped; side L in a).

    Raises:
        ValueError: phi outside (0, START_PHI_LIMIT).
        Jammed: the compression jammed COMPRESS_ATTEMPTS times.
    """
    m = lattice_sites_per_axis(n_particles)
    radii = _radii(n_particles, radius, radii)
    a_max = float(radii.max())
    limit = math.pi / 6 * float(np.mean((radii / a_max) ** 3)) * (n_particles / m ** 3)
    if not 0 < phi < START_PHI_LIMIT:
        raise ValueError(f"phi must be in (0, {START_PHI_LIMIT}) (a lattice start below the "
                         f"lattice limit (pi/6) sum_i (a_i/a_max)^3 / m^3 = {limit:.4f} for a "
                         f"spacing of the largest diameter, a compressed one above it), got {phi}")
    start = phi if phi < limit else LATTICE_FILL * limit
    side = box_side(radii, start)
    grid = (np.arange(m) + 0.5) * side / m
    pos = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    if n_particles < m ** 3 or np.any(radii != radii[0]):
        pos = pos[rng.permutation(m ** 3)[:n_particles]]
    _equilibrate(pos, side, radii, 0.5 * (side / m - 2 * a_max) + 0.01, sweeps, rng, strain)
    if start < phi:
        pos, side = _compress_retrying(pos, side, phi, rng, strain, radii)
        _equilibrate(pos, side, radii, 0.05 * a_max, sweeps, rng, strain)
    return pos, side


def _compress_retrying(pos, side, phi, rng, strain, radii):
    """:func:`compress` from the same lattice start with the next random draws, up to
    COMPRESS_ATTEMPTS times: small periodic boxes (N of order 10) can jam below phi."""
    for _ in range(COMPRESS_ATTEMPTS):
        try:
            return compress(pos, side, phi, rng, strain=strain, radii=radii)
        except Jammed as err:
            jam = err
    raise Jammed(f"{jam}, {COMPRESS_ATTEMPTS} times from a lattice of N = {len(pos)} spheres; "
                 "small boxes jam: use more particles or a smaller phi")


def _equilibrate(pos, side, radii, step, sweeps, rng, strain, dims=3):
    """MC sweeps in 10 blocks, the step tuned to ~40% acceptance after each block."""
    seed = int(rng.integers(2 ** 31))
    for block in range(10):
        rate = _mc_sweeps(pos, side, radii, step, max(sweeps // 10, 1), seed + block, strain, dims)
        step *= min(max(rate / 0.4, 0.5), 2.0)


def square_side(n_particles: int, phi_a: float) -> float:
    """Side L of the square cell holding n unit disks at areal fraction phi_a.

    Args:
        n_particles: number of disks N.
        phi_a: areal fraction, > 0.

    Returns:
        L, in a.
    """
    return math.sqrt(n_particles * math.pi / phi_a)


def hard_disk_monolayer(
    n_particles: int,
    phi_a: float,
    rng: np.random.Generator,
    z: float = 0.0,
    sweeps: int = 200,
    strain: float = 0.0,
) -> tuple[np.ndarray, float]:
    """Random non-overlapping monolayer of unit spheres, centres in the plane z, in a square
    cell of side L = :func:`square_side` (periodic in x and y): positions (N, 3) and L.

    Start: N of the m x m sites of a square lattice, m = ceil(sqrt N), spaced L/m > 2 (so
    phi_a < pi N / (4 m^2), = pi/4 when N = m^2; a random choice of sites when N < m^2),
    then hard-disk Metropolis MC in the plane (as :func:`hard_sphere_fluid`, 2D moves),
    which samples the equilibrium hard-disk fluid at phi_a (Dratler & Schowalter 1996: random
    starts), with Lees-Edwards images at the given strain (rows L/m > 2 apart in y: no overlap
    at any strain at the start).

    Args:
        n_particles: number of spheres N.
        phi_a: areal fraction, below pi N / (4 m^2).
        rng: the random stream of the start.
        z: height of the plane of centres, in a.
        sweeps: MC sweeps.
        strain: Lees-Edwards strain of the images, dimensionless.

    Returns:
        (positions (N, 3) in a, side L in a).

    Raises:
        ValueError: phi_a too large for the lattice start.
    """
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
def _ratio_squared(pos, i, j, side, strain, radii, dx):
    """(|x_i - x_j| / (a_i + a_j))^2, Lees-Edwards minimum image in a cube (dx: work)."""
    for c in range(3):
        dx[c] = pos[i, c] - pos[j, c]
    _min_image(dx, side, strain)
    contact = radii[i] + radii[j]
    return (dx[0] ** 2 + dx[1] ** 2 + dx[2] ** 2) / (contact * contact)


@numba.njit(cache=True)
def _contact_ratio(pos, side, strain, radii):
    """Smallest |x_i - x_j| / (a_i + a_j) (Lees-Edwards minimum image) in a cube."""
    n = pos.shape[0]
    best = np.inf
    dx = np.empty(3)
    for i in range(n):
        for j in range(i + 1, n):
            best = min(best, _ratio_squared(pos, i, j, side, strain, radii, dx))
    return math.sqrt(best)


#: `_closest_ratio` looks for the closest pair among those closer than this many contact
#: distances first (cell list), and scans all pairs only when there are none
_NEAR_RATIO = 1.5


@numba.njit(cache=True)
def _pairs_ratio(pos, side, strain, radii, pi, pj):
    """Smallest |x_i - x_j| / (a_i + a_j) over the given pairs, by the arithmetic of
    _contact_ratio."""
    best = np.inf
    dx = np.empty(3)
    for p in range(pi.shape[0]):
        best = min(best, _ratio_squared(pos, pi[p], pj[p], side, strain, radii, dx))
    return math.sqrt(best)


def _closest_ratio(pos, side, strain, radii):
    """_contact_ratio (the same number, bit for bit), from the pairs closer than
    _NEAR_RATIO contact distances when there are any (`geometry.find_pairs`: a cell list
    in large boxes), else from all pairs."""
    i, j, _ = find_pairs(pos, radii, Lattice(np.full(3, side), strain), 0.0, _NEAR_RATIO)
    off = i != j
    if not off.any():
        return _contact_ratio(pos, side, strain, radii)
    return _pairs_ratio(pos, side, strain, radii, i[off], j[off])


def min_gap_ratio(pos: np.ndarray, side: float, radii: np.ndarray, strain: float = 0.0) -> float:
    """Smallest |x_i - x_j| / (a_i + a_j) over pairs (>= 1: no overlap).

    Args:
        pos: positions, shape (N, 3), in a.
        side: side of the cubic box, in a.
        radii: radii, shape (N,), in a.
        strain: Lees-Edwards strain, dimensionless.

    Returns:
        The ratio, dimensionless.
    """
    return _contact_ratio(pos, side, strain, np.ascontiguousarray(radii, dtype=float))


def compress(
    pos: np.ndarray,
    side: float,
    phi_target: float,
    rng: np.random.Generator,
    sweeps_per_shrink: int = 5,
    radius: float = 1.0,
    max_shrinks: int = 20000,
    strain: float = 0.0,
    radii: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Compress a hard-sphere configuration (N, 3) in a cube of the given side (Lees-Edwards
    strain fixed) to volume fraction phi_target; spheres of the common ``radius`` or of the
    per-particle ``radii``. Returns (positions, side). Raises :class:`Jammed` if it jams.

    Args:
        pos: positions, shape (N, 3), in a (not modified).
        side: side of the cubic box, in a.
        phi_target: the volume fraction to reach.
        rng: the random stream of the MC sweeps.
        sweeps_per_shrink: MC sweeps after each shrink.
        radius: common sphere radius, in a (used when radii is None).
        max_shrinks: most shrinks tried.
        strain: Lees-Edwards strain, dimensionless.
        radii: per-particle radii, shape (N,), in a, or None.

    Returns:
        (positions (N, 3) in a, side L in a).

    Raises:
        Jammed: max_shrinks were not enough.
    """
    pos = pos.copy()
    n = len(pos)
    radii = _radii(n, radius, radii)
    target = box_side(radii, phi_target)
    step = 0.05
    for _ in range(max_shrinks):
        if side <= target:
            return pos, side
        ratio = _closest_ratio(pos, side, strain, radii)
        factor = max(1.0 / ratio * (1 + 1e-9), target / side)
        pos *= factor
        side *= factor
        rate = _mc_sweeps(pos, side, radii, step, sweeps_per_shrink, int(rng.integers(2 ** 31)), strain)
        step = min(max(step * (0.5 + rate / 0.4 * 0.5), 1e-4), 0.5)
    volume = 4.0 / 3.0 * math.pi * float(np.sum(radii ** 3))
    raise Jammed(f"compression to phi = {phi_target} jammed at phi = {volume / side ** 3:.3f}")
