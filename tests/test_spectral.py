"""The spectral (particle-mesh) Ewald far field against the dense Ewald sum.

Reference: `far_field_mobility(..., tol=1e-10) @ x`, converged far below every tol tested,
so the measured difference is the spectral error itself; SpectralFarField promises
|y - M x| / |M x| <= tol. Also run as a script under ``mpirun -n 2`` (see
test_independent_of_ranks): prints one JSON line per rank.
"""

import functools
import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from sdmpi.dynamics.initial import compress, hard_sphere_fluid
from sdmpi.hydro.farfield import far_field_mobility
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.spectral import SpectralFarField

MPIRUN = shutil.which("mpirun")
N = 27


@functools.lru_cache(maxsize=None)
def configuration(phi, strain, unequal, seed=7):
    """N hard spheres at volume fraction phi in a cube at the given Lees-Edwards strain,
    radii 1 or drawn from [0.6, 1.4]; positions, radii, box and the dense M_inf."""
    rng = np.random.default_rng(seed)
    radii = rng.uniform(0.6, 1.4, N) if unequal else np.ones(N)
    start = min(phi, 0.2)
    pos, side = hard_sphere_fluid(N, start, rng, strain=strain, radii=radii)
    if phi > start:
        pos, side = compress(pos, side, phi, rng, strain=strain, radii=radii)
    box = np.full(3, side)
    return pos, radii, box, far_field_mobility(pos, radii, box, strain, tol=1e-10)


CASES = [  # (phi, strain, unequal radii, tol): every strain, both densities and radii kinds
    (0.05, 0.0, False, 1e-3),
    (0.5, 0.0, True, 1e-4),
    (0.5, -0.45, False, 1e-4),
    (0.05, -0.45, True, 1e-5),
    (0.5, 0.3, True, 1e-6),
    (0.05, 0.3, False, 1e-6),
    (0.5, 0.9, False, 1e-3),
    (0.05, 0.9, True, 1e-4),
]


@pytest.mark.parametrize("phi, strain, unequal, tol", CASES)
def test_matches_dense_ewald_sum(phi, strain, unequal, tol):
    pos, radii, box, dense = configuration(phi, strain, unequal)
    x = np.random.default_rng(1).standard_normal(11 * N)
    op = SpectralFarField(pos, radii, Lattice(box, strain), tol=tol)
    ref = dense @ x
    err = np.linalg.norm(op.matvec(x) - ref) / np.linalg.norm(ref)
    assert err <= tol, (err, op.params)


def test_error_follows_tol():
    """The error is not accidentally tiny: a loose tol gives a visibly larger error, so
    the comparison above can fail (the parameters really are set by tol)."""
    pos, radii, box, dense = configuration(0.5, 0.3, False)
    x = np.random.default_rng(2).standard_normal(11 * N)
    ref = dense @ x
    errs = [np.linalg.norm(SpectralFarField(pos, radii, Lattice(box, 0.3), tol=t).matvec(x) - ref)
            / np.linalg.norm(ref) for t in (1e-2, 1e-6)]
    assert errs[0] > 1e-4 > 1e-6 > errs[1], errs


@pytest.mark.parametrize("tol, rounding", [(1e-6, 1e-12), (1e-4, 1e-6)])  # double, single precision
def test_linear_and_symmetric(tol, rounding):
    """Every stage (sparse real-space blocks with M_ji = M_ij^T, spreading and its exact
    adjoint the interpolation, a real even k-space filter, diagonal self terms) is linear
    and symmetric by construction, so both hold to rounding: 1e-12 relative in double
    precision, 1e-6 with the grids in single precision (from SINGLE_PRECISION_TOL; float32
    rounding 6e-8 per operation, and the sums over a grid point's ~10 particles)."""
    pos, radii, box, _ = configuration(0.5, -0.45, True)
    op = SpectralFarField(pos, radii, Lattice(box, -0.45), tol=tol)
    rng = np.random.default_rng(3)
    x1, x2 = rng.standard_normal((2, 11 * N))
    y1, y2 = op.matvec(x1), op.matvec(x2)
    scale = np.linalg.norm(y1) * np.linalg.norm(x2)
    assert abs(y1 @ x2 - x1 @ y2) <= rounding * scale
    combo = op.matvec(2.5 * x1 - 0.7 * x2)
    assert np.linalg.norm(combo - (2.5 * y1 - 0.7 * y2)) <= rounding * np.linalg.norm(combo)


def test_single_precision_grids_round_the_product_only(monkeypatch):
    """From SINGLE_PRECISION_TOL on the blocks and the work grids (spreading, FFTs, the
    grid sent between ranks) are single precision: the product differs from the same
    operator's in double precision by rounding, 1e-6 relative at most (measured 1.2e-7),
    1% of the smallest tolerance that uses it."""
    from sdmpi.hydro import spectral

    pos, radii, box, _ = configuration(0.5, 0.3, True)
    x = np.random.default_rng(9).standard_normal(11 * N)
    single = SpectralFarField(pos, radii, Lattice(box, 0.3), tol=1e-5)
    assert all(g is None or g.dtype in (np.float32, np.complex64) for g in single.work_grids())
    y = single.matvec(x)
    monkeypatch.setattr(spectral, "SINGLE_PRECISION_TOL", 1.0)
    double = SpectralFarField(pos, radii, Lattice(box, 0.3), tol=1e-5)
    assert all(g is None or g.dtype in (np.float64, np.complex128) for g in double.work_grids())
    ref = double.matvec(x)
    assert 0 < np.linalg.norm(y - ref) <= 1e-6 * np.linalg.norm(ref)


def test_operators_sharing_the_work_grids_give_their_own_products():
    """Operators of one process share their grids (`SpectralFarField.work_grids`, one
    product at a time): products of two operators on different grids, taken in turn,
    equal each operator's products taken alone, bit for bit (every product overwrites
    the grids), and the grids are the same arrays for operators of one grid."""
    (pos, radii, box, _), (pos2, radii2, box2, _) = configuration(0.5, 0.3, True), configuration(0.05, 0.0, False)
    x = np.random.default_rng(4).standard_normal(11 * N)
    alone = [SpectralFarField(p, r, Lattice(b, s), tol=t).matvec(x)
             for p, r, b, s, t in ((pos, radii, box, 0.3, 1e-4), (pos2, radii2, box2, 0.0, 1e-3))]
    first, second = (SpectralFarField(p, r, Lattice(b, s), tol=t)
                     for p, r, b, s, t in ((pos, radii, box, 0.3, 1e-4), (pos2, radii2, box2, 0.0, 1e-3)))
    assert first.params.grid != second.params.grid
    for _ in range(2):
        assert np.array_equal(first.matvec(x), alone[0]) and np.array_equal(second.matvec(x), alone[1])
    twin = SpectralFarField(pos, radii, Lattice(box, 0.3), tol=1e-4)
    assert all(np.shares_memory(a, b) for a, b in zip(first.work_grids(), twin.work_grids()) if a is not None)


@pytest.mark.parametrize("tol, rounding", [(1e-6, 1e-13), (1e-5, 1e-6)])  # double, single precision
def test_public_fft_fallback_gives_the_same_product(monkeypatch, tol, rounding):
    """Without scipy's private pocketfft module (transforms into given arrays, pruned to
    the lines of the kept modes) the public scipy.fft functions (full 3-D transforms) give
    the same product to rounding (1e-13 in double precision, 1e-6 in single)."""
    from sdmpi.hydro import spectral

    pos, radii, box, _ = configuration(0.5, 0.3, True)
    op = SpectralFarField(pos, radii, Lattice(box, 0.3), tol=tol)
    x = np.random.default_rng(8).standard_normal(11 * N)
    y = op.matvec(x)
    monkeypatch.setattr(spectral, "pypocketfft", None)
    assert np.linalg.norm(op.matvec(x) - y) <= rounding * np.linalg.norm(y)


@pytest.mark.parametrize("n, strain, tol", [(27, 0.0, 1e-4), (27, 0.9, 1e-6), (8, -0.45, 1e-2)])
def test_kept_modes_hold_every_mode_the_kernel_keeps(n, strain, tol):
    """The pruned transforms' index ranges (`_kept_modes`) hold every mode with a nonzero
    kernel and are the tightest such ranges (their last z index and the y bounds carry a
    kept mode), so pruning skips only lines the kernel zeroes."""
    from sdmpi.hydro.spectral import _kept_modes

    rng = np.random.default_rng(n)
    lattice = Lattice(np.full(3, 3.0 * round(n ** (1 / 3))), strain)
    op = SpectralFarField(rng.random((n, 3)) * lattice.vectors.diagonal(), np.ones(n), lattice, tol=tol)
    scale = op._scale
    z_kept, y_kept = _kept_modes(scale)
    inside = np.zeros(scale.shape, dtype=bool)
    for part in y_kept:
        inside[:, part, z_kept] = True
    assert not np.any((scale != 0) & ~inside)
    assert np.any(scale[:, :, z_kept.stop - 1] != 0)
    assert all(np.any(scale[:, part.stop - 1 if k == 0 else part.start] != 0) for k, part in enumerate(y_kept))
    assert inside.sum() < scale.size  # these grids have lines to skip


def test_periodic_images_give_the_same_product():
    """Positions moved by lattice translations (unwrapped, as a dynamics run leaves them)
    describe the same suspension: same product up to the rounding of the wrap (1e-12)."""
    pos, radii, box, _ = configuration(0.5, 0.9, True)
    lattice = Lattice(box, 0.9)
    shifts = np.random.default_rng(5).integers(-3, 4, (N, 3)) @ lattice.vectors
    x = np.random.default_rng(6).standard_normal(11 * N)
    y = SpectralFarField(pos, radii, lattice, tol=1e-5).matvec(x)
    y_images = SpectralFarField(pos + shifts, radii, lattice, tol=1e-5).matvec(x)
    assert np.linalg.norm(y_images - y) <= 1e-12 * np.linalg.norm(y)


def test_grid_translations_give_the_same_product():
    """The grid is uniform in lattice coordinates, so moving every particle by whole grid
    steps along the lattice vectors shifts the spread force density cyclically and leaves
    the discrete operator unchanged (to rounding, 1e-12). The shift carries windows across
    the box edges, where they wrap into the grid padded along z; at tol 1e-9 the windows
    (23 points) are wider than the grid (20), so some reach past twice its length and
    their pads fold back twice."""
    pos, radii, box, _ = configuration(0.05, -0.45, True)
    lattice = Lattice(box, -0.45)
    x = np.random.default_rng(7).standard_normal(11 * N)
    op = SpectralFarField(pos, radii, lattice, tol=1e-9)
    assert op._stencils.pad + op.params.grid[2] > 2 * op.params.grid[2] + 1
    steps = np.array([3, -5, 7]) / np.array(op.params.grid)
    moved = SpectralFarField(pos + steps @ lattice.vectors, radii, lattice, tol=1e-9)
    y = op.matvec(x)
    assert np.linalg.norm(moved.matvec(x) - y) <= 1e-12 * np.linalg.norm(y)


def test_bad_input():
    pos, radii, box, _ = configuration(0.05, 0.0, False)
    lattice = Lattice(box)
    with pytest.raises(ValueError, match="positions"):
        SpectralFarField(pos[:, :2], radii, lattice)
    with pytest.raises(ValueError, match="radii"):
        SpectralFarField(pos, radii[:-1], lattice)
    with pytest.raises(ValueError, match="radii"):
        SpectralFarField(pos, -radii, lattice)
    with pytest.raises(ValueError, match="lattice"):
        SpectralFarField(pos, radii, None)
    with pytest.raises(ValueError, match=r"tol must be in \[1e-10, 0.1\]"):
        SpectralFarField(pos, radii, lattice, tol=0.5)
    with pytest.raises(ValueError, match=r"x must have shape \(297,\)"):
        SpectralFarField(pos, radii, lattice).matvec(np.zeros(10))


def rank_check():
    """On comm = COMM_WORLD: the largest relative difference to the one-rank product, and
    a digest of the result (to compare across ranks)."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    pos, radii, box, _ = configuration(0.5, 0.3, True)
    lattice = Lattice(box, 0.3)
    x = np.random.default_rng(4).standard_normal(11 * N)
    single = SpectralFarField(pos, radii, lattice, tol=1e-5, comm=comm).matvec(x)
    single1 = SpectralFarField(pos, radii, lattice, tol=1e-5).matvec(x)
    far = SpectralFarField(pos, radii, lattice, tol=1e-6, comm=comm)
    y = far.matvec(x)
    y1 = SpectralFarField(pos, radii, lattice, tol=1e-6).matvec(x)
    far.release_real_space()
    return {"ranks": comm.size, "diff": float(np.abs(y - y1).max() / np.abs(y1).max()),
            "diff_single": float(np.abs(single - single1).max() / np.abs(single1).max()),
            "digest": hashlib.sha256(y.tobytes()).hexdigest(),
            "own_indices": bool(far._pi.base is None and far._pj.base is None and far._images.base is None),
            "released_same": bool(np.array_equal(far.matvec(x), y))}


@pytest.mark.mpi
@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_independent_of_ranks():
    """Two ranks (spreading and interpolation split by particles, FFTs on rank 0, the
    real-space pairs shared by `real_space_shares`) give the one-rank result up to the
    order of floating-point sums (1e-13 in double precision, 1e-6 with single-precision
    grids), the same bits on every rank, and again after each rank released its
    real-space blocks."""
    from .test_petsc_dense import rows_on_two_ranks

    rows = rows_on_two_ranks(Path(__file__).stem)
    assert len(rows) == 2 and all(r["diff"] < 1e-13 and r["diff_single"] < 1e-6 for r in rows), rows
    assert all(r["own_indices"] for r in rows), rows  # its share's indices, not views of all
    assert all(r["released_same"] for r in rows), rows  # blocks released and computed again


def test_real_space_indices_are_32_bit_and_give_the_same_product():
    """The operator keeps its pair images' indices as 32-bit copies (half the bytes the
    product streams besides the blocks); its real-space product equals, bit for bit, the
    one over the pair search's own 64-bit indices."""
    from sdmpi.hydro.geometry import find_pairs
    from sdmpi.hydro.spectral import _pairs_product

    pos, radii, box, _ = configuration(0.5, 0.3, True)
    lattice = Lattice(box, 0.3)
    far = SpectralFarField(pos, radii, lattice, tol=1e-5)
    pi, pj, _ = find_pairs(lattice.wrap(pos), radii, lattice, far.params.rcut, 0.0)
    assert far._pi.dtype == far._pj.dtype == np.int32 and pi.dtype == np.int64
    assert np.array_equal(far._pi, pi) and np.array_equal(far._pj, pj)
    x = np.random.default_rng(5).standard_normal(11 * N)
    wide, narrow = np.zeros(11 * N), np.zeros(11 * N)
    _pairs_product(pi, pj, far._blocks, x, wide)
    far.real_space(x, narrow)
    assert np.abs(wide).max() > 0 and np.array_equal(wide, narrow)


@pytest.mark.parametrize("strain", [0.0, 0.3, -0.45])
def test_blocks_from_image_indices_equal_those_of_the_pair_search_shifts(strain):
    """The operator keeps each pair image's lattice indices (int8, `geometry.image_indices`)
    instead of its shift: the shifts formed from them have the bits of `find_pairs`'s, so
    every real-space block equals, bit for bit, the block at the pair search's own
    separation x_j + shift - x_i (`farfield._pair_block`, one by one)."""
    from sdmpi.hydro.basis import BASIS
    from sdmpi.hydro.farfield import _cached_radial_table, _pair_block, _power_bounds
    from sdmpi.hydro.geometry import find_pairs

    pos, radii, box, _ = configuration(0.5, strain, True)
    lattice = Lattice(box, strain)
    far = SpectralFarField(pos, radii, lattice, tol=1e-6)  # double precision: every bit compared
    wrapped = lattice.wrap(pos)
    pi, pj, shift = find_pairs(wrapped, radii, lattice, far.params.rcut, 0.0)
    assert far._images.dtype == np.int8 and len(np.unique(far._images, axis=0)) > 5
    xi = far.params.xi
    table = _cached_radial_table(xi)
    bounds = _power_bounds(table)
    for p in range(len(pi)):
        block = np.zeros((11, 11))
        rvec = wrapped[pi[p]] - wrapped[pj[p]] - shift[p]
        _pair_block(rvec, radii[pi[p]], radii[pj[p]], table, bounds, xi, BASIS, np.empty(80), block)
        assert np.array_equal(block, far._blocks[p]), p


@pytest.mark.parametrize("tol", [1e-4, 1e-6])   # blocks in single, double precision
def test_released_real_space_blocks_are_computed_again_bit_for_bit(tol):
    """`release_real_space` frees the real-space blocks (the step's start does while its
    Brownian midpoint is built and solved); the next product computes them again from the
    operator's own copies of the positions and pair images: the same blocks and products,
    bit for bit, even when the caller's positions array has changed meanwhile."""
    pos, radii, box, _ = configuration(0.5, 0.3, True)
    pos, radii = pos.copy(), radii.copy()
    far = SpectralFarField(pos, radii, Lattice(box, 0.3), tol=tol)
    x = np.random.default_rng(8).standard_normal(11 * N)
    blocks, y = far._blocks.copy(), far.matvec(x)
    far.release_real_space()
    assert far._blocks is None
    pos += 0.1   # the caller's arrays change; the operator keeps its configuration
    radii *= 1.01
    assert np.array_equal(far.matvec(x), y) and np.array_equal(far._blocks, blocks)


def test_real_space_shares_balance_rank_zeros_ffts():
    """Pair images per rank: all of them, once; rank 0's share plus its FFTs (in pair
    units) equals each other rank's share to one pair; none for rank 0 when its FFTs
    alone outweigh the others' shares."""
    from sdmpi.hydro.spectral import _FFT_COST_PER_GRID_POINT, real_space_shares

    grid = (48, 50, 50)
    for precision, cost in _FFT_COST_PER_GRID_POINT.items():
        fft = cost * np.prod(grid)
        for pairs, size in ((59692, 2), (243000, 2), (243000, 4), (7, 2)):
            shares = real_space_shares(pairs, grid, size, precision)
            assert len(shares) == size and shares.sum() == pairs and np.all(shares >= 0)
            if shares[0] > 0:
                assert np.all(np.abs(shares[0] + fft - shares[1:]) <= 1)
            else:
                assert np.all(shares[1:] <= fft + 1)
    # cheaper single-precision FFTs: rank 0 takes more pairs
    assert real_space_shares(59692, grid, 2, np.float32)[0] > real_space_shares(59692, grid, 2)[0]
    assert real_space_shares(1000, grid, 2)[0] == 0  # FFTs outweigh: all pairs on rank 1
    assert np.array_equal(real_space_shares(10, grid, 1), [10])


if __name__ == "__main__":
    from mpi4py import MPI

    from .petsc_check import print_per_rank

    print_per_rank([rank_check()], MPI.COMM_WORLD)
