"""The tabulated near-field correction of `sdmpi.hydro.lubrication` against the exact path.

Exact path: `two_sphere.pair_resistance` minus the explicit inverse of the 22x22 unbounded
far-field pair mobility (`pair_corrections_exact`, `lubrication_matrix_exact`).  Errors are
measured relative to the largest entry of each pair's 22x22 correction D = R_2B - R_2B,inf.

Beyond gaps of a few radii D is a small difference of two large matrices, so the exact path
itself only holds D to its round-off floor  eps max|R_2B| / max|D|  (~1e-10 of D at xi = 6,
lam = 1; up to ~1e-8 at xi = 10 for lam = 4 and radii ~ 1..8).  The tolerance is therefore
1e-9 (interpolation, the table's own target) plus 16 times that floor; measured errors are
<= 4 floors at xi >= 1 and < 4e-12 of D near contact.  For the default cut-off (xi <= 2)
and radii ~ 1 the errors are below 1e-10.
"""

import numpy as np
import pytest

from sdmpi.hydro import lubrication as lub
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.two_sphere import pair_resistance

EPS = np.finfo(float).eps


def _random_pairs(rng, lam, n, xi_lo=1e-4, xi_hi=10.0):
    xi = np.exp(rng.uniform(np.log(xi_lo), np.log(xi_hi), n))
    # near contact at the regularisation floor, the default and the largest cut-off
    xi[:6] = [1e-4, 1e-4 * (1 + 1e-10), 2.0, 10.0, 0.5, 1.0]
    a1 = rng.uniform(0.6, 1.6, n)
    a2 = lam * a1
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    v[6] = [0.0, 0.0, 1.0]  # along the table's canonical axis, and against it
    v[7] = [0.0, 0.0, -1.0]
    dx = v * (0.5 * (a1 + a2) * (2.0 + xi))[:, None]
    return dx, a1, a2, xi


def _errors(dx, a1, a2):
    fast = lub.pair_corrections(dx, a1, a2)
    exact = lub.pair_corrections_exact(dx, a1, a2)
    scale = np.abs(exact).max(axis=(1, 2))
    err = np.abs(fast - exact).max(axis=(1, 2)) / scale
    floor = EPS * np.abs(pair_resistance(dx, a1, a2)).max(axis=(1, 2)) / scale
    return err, floor


@pytest.mark.parametrize("lam", [0.25, 1.0, 4.0])
def test_tabulated_pairs_match_exact(lam):
    rng = np.random.default_rng(int(lam * 16))
    dx, a1, a2, xi = _random_pairs(rng, lam, 400)
    err, floor = _errors(dx, a1, a2)
    assert np.all(err <= 1e-9 + 16 * floor), (err.max(), xi[np.argmax(err / (1e-9 + 16 * floor))])
    near = xi < 1e-2
    assert err[near].max() < 1e-10
    default = xi <= 2.0
    assert err[default].max() < 1e-9


def test_tabulated_extreme_size_ratios():
    rng = np.random.default_rng(8)
    for lam in (0.125, 8.0):
        dx, a1, a2, xi = _random_pairs(rng, lam, 200)
        err, floor = _errors(dx, a1, a2)
        assert np.all(err <= 1e-9 + 16 * floor), (lam, err.max())


def test_difference_has_two_sphere_tensor_form():
    """The premise of the table: R_2B - R_2B,inf at d = e_z is exactly a combination of the
    44 tensor patterns of two_sphere (deviation = round-off relative to R_2B)."""
    for lam in (0.25, 1.0, 3.0):
        xi = np.array([1e-4, 1e-2, 0.3, 2.0])
        coef, dev = lub.canonical_scalars(xi, lam)
        assert coef.shape == (4, 4, 11)
        assert dev < 1e-11, (lam, dev)


def test_lubrication_matrix_polydisperse_periodic():
    """Assembled (11N, 11N) matrix, bidisperse spheres with periodic images (including a
    particle's own image) and one touching pair (regularised), fast vs exact."""
    rng = np.random.default_rng(2)
    n = 40
    radii = np.where(np.arange(n) % 3 == 0, 0.5, 1.0)
    side = 7.0
    lattice = Lattice([side] * 3, 0.1)
    pos = rng.uniform(0, side, (n, 3))
    pos[1] = pos[0] + [radii[0] + radii[1], 0, 0]  # touching: regularised to the min gap
    pos = lattice.wrap(pos)
    pairs = lub.close_pairs(pos, radii, lattice, cutoff=4.0)
    assert len(pairs.i) > 50 and pairs.n_regularised >= 1
    fast = lub.lubrication_matrix(pos, radii, pairs)
    exact = lub.lubrication_matrix_exact(pos, radii, pairs)
    assert np.abs(fast - exact).max() <= 1e-9 * np.abs(exact).max()
    np.testing.assert_allclose(fast, fast.T, rtol=0, atol=1e-12 * np.abs(fast).max())
    # out=: added in place into a given matrix
    base = rng.normal(size=fast.shape)
    out = base.copy()
    assert lub.lubrication_matrix(pos, radii, pairs, out=out) is out
    np.testing.assert_allclose(out, base + fast, rtol=0, atol=1e-13 * np.abs(fast).max())


def test_gaps_beyond_the_initial_table():
    """A cut-off larger than the initial table (xi up to 12) and a min gap below it extend
    the table on the same grid; values inside the old range are unchanged (bitwise)."""
    rng = np.random.default_rng(11)
    lam = 0.5
    dx, a1, a2, xi = _random_pairs(rng, lam, 64, 1e-3, 2.0)
    before = lub.pair_corrections(dx, a1, a2)
    dxw, a1w, a2w, xiw = _random_pairs(rng, lam, 64, 1e-6, 60.0)
    err, floor = _errors(dxw, a1w, a2w)
    assert np.all(err <= 1e-9 + 16 * floor), err.max()
    assert np.array_equal(lub.pair_corrections(dx, a1, a2), before)


def test_exact_fallbacks():
    """Size ratios with few pairs and no table, and gaps outside the table range, take the
    exact path (bitwise equal to it)."""
    rng = np.random.default_rng(4)
    lam = 0.3711  # not used elsewhere: no table exists
    n = lub._MIN_PAIRS_FOR_TABLE - 1
    dx, a1, a2, _ = _random_pairs(rng, lam, n)
    assert np.array_equal(lub.pair_corrections(dx, a1, a2), lub.pair_corrections_exact(dx, a1, a2))
    assert lam not in lub._STORE._tables.lams
    for xi in (0.5 * lub._XI_TABLE_MIN, 2 * lub._XI_TABLE_MAX):
        dx = np.array([[0.3, -0.2, 1.0]])
        dx *= (2.0 + xi) / np.linalg.norm(dx)
        assert np.array_equal(lub.pair_corrections(dx, 1.0, 1.0), lub.pair_corrections_exact(dx, 1.0, 1.0))


def test_deterministic_and_smooth():
    """Random finite differences: repeated calls are bitwise identical, and the tabulated
    correction is smooth: its radial finite difference over 1e-3 of the gap matches the
    exact one."""
    rng = np.random.default_rng(6)
    dx, a1, a2, xi = _random_pairs(rng, 1.0, 32, 1e-4, 10.0)
    assert np.array_equal(lub.pair_corrections(dx, a1, a2), lub.pair_corrections(dx, a1, a2))
    r = np.linalg.norm(dx, axis=1)
    step = (1e-3 * 0.5 * (a1 + a2) * xi / r)[:, None] * dx
    fd_fast = lub.pair_corrections(dx + step, a1, a2) - lub.pair_corrections(dx - step, a1, a2)
    fd_exact = lub.pair_corrections_exact(dx + step, a1, a2) - lub.pair_corrections_exact(dx - step, a1, a2)
    scale = np.abs(fd_exact).max(axis=(1, 2))
    err = np.abs(fd_fast - fd_exact).max(axis=(1, 2)) / scale
    assert err[xi <= 2.0].max() < 1e-6, err.max()


def test_rigid_cholesky_matches_lapack_and_reports_the_bad_pair():
    """The pair factors for the Brownian near field (`_rigid_cholesky`, the 12 rigid-body
    rows of each pair's block) equal numpy's (LAPACK) Cholesky factors to rounding on
    real pair blocks (gaps 1e-4 to 2, size ratios 1 and 1/4), and the first pair whose
    block is not positive definite is reported."""
    rng = np.random.default_rng(3)
    rigid = np.r_[0:6, lub.NDOF:lub.NDOF + 6]
    blocks = []
    for lam in (1.0, 0.25):
        dx, a1, a2, _ = _random_pairs(rng, lam, 40, xi_hi=2.0)
        blocks.append(lub.pair_corrections_exact(dx, a1, a2))
    res = np.concatenate(blocks)
    out = np.empty((len(res), 12, 12))
    assert lub._rigid_cholesky(res, out) == -1
    ref = np.linalg.cholesky(res[:, rigid][:, :, rigid])
    assert np.abs(out - ref).max() < 1e-12 * np.abs(ref).max()
    bad = res.copy()
    bad[17, 3, 3] = -1.0  # an inner diagonal entry of the rigid block
    assert lub._rigid_cholesky(bad, out) == 17


def _partitions_of(matrix, n):
    """The FU, FE, SE partitions of an (11N, 11N) matrix (dofs particle by particle)."""
    idx = np.arange(lub.NDOF * n).reshape(n, lub.NDOF)
    rigid, strain = idx[:, :6].ravel(), idx[:, 6:].ravel()
    return matrix[np.ix_(rigid, rigid)], matrix[np.ix_(rigid, strain)], matrix[np.ix_(strain, strain)]


def _bidisperse_periodic(n=40, seed=2, odd_radius=None):
    """n spheres (every third of radius 0.5, else 1; with odd_radius, sphere 5 has that radius: a
    size ratio with too few pairs for a table) in a sheared periodic box, one pair touching."""
    rng = np.random.default_rng(seed)
    radii = np.where(np.arange(n) % 3 == 0, 0.5, 1.0)
    if odd_radius is not None:
        radii[5] = odd_radius
    lattice = Lattice([7.0] * 3, 0.1)
    pos = rng.uniform(0, 7.0, (n, 3))
    pos[1] = pos[0] + [radii[0] + radii[1], 0, 0]
    pos = lattice.wrap(pos)
    return pos, radii, lub.close_pairs(pos, radii, lattice, cutoff=4.0)


@pytest.mark.parametrize("odd_radius", [None, 0.77])
def test_partitions_equal_the_matrix(odd_radius):
    """`lubrication_partitions` (each pair's block added straight into the dense partitions)
    against the partitions of `lubrication_matrix` (the same blocks, summed in the same pair
    order): equal to rounding (1e-14 of the largest entry); with a size ratio on the exact
    path (odd_radius) no setup is returned."""
    pos, radii, pairs = _bidisperse_periodic(odd_radius=odd_radius)
    n = len(pos)
    dense, setup = lub.lubrication_partitions(radii, pairs, n)
    assert (setup is None) == (odd_radius is not None)
    ref = _partitions_of(lub.lubrication_matrix(pos, radii, pairs), n)
    for got, want in zip(dense, ref):
        assert got.shape == want.shape
        assert np.abs(got - want).max() <= 1e-14 * np.abs(want).max()
    none = np.zeros(0, dtype=np.int64)
    assert lub.lubrication_partitions(radii, lub.close_pairs(pos, radii, images=(none, none, np.zeros((0, 3)))),
                                      n) is None


@pytest.mark.parametrize("odd_radius", [None, 0.77])
def test_product_equals_the_matrix(odd_radius):
    """`lubrication_product` pair by pair, with and without the setup of
    `lubrication_partitions`, at the pairs' own and at displaced positions (same images),
    for a general vector and one without strain part (only the rigid-body columns formed),
    against the assembled matrix times the vector: 1e-13 of the largest entry."""
    pos, radii, pairs = _bidisperse_periodic(odd_radius=odd_radius)
    n = len(pos)
    _, setup = lub.lubrication_partitions(radii, pairs, n)
    rng = np.random.default_rng(7)
    images = (pairs.i, pairs.j, pairs.shift)
    moved = lub.close_pairs(pos + 1e-6 * rng.standard_normal(pos.shape), radii, images=images)
    v = rng.standard_normal((n, lub.NDOF))
    rigid = v.copy()
    rigid[:, 6:] = 0.0
    for at, where in ((pairs, pos), (moved, None)):
        matrix = lub.lubrication_matrix(pos, radii, at)
        for vec in (v, rigid):
            ref = (matrix @ vec.ravel()).reshape(n, lub.NDOF)
            for s in (None, setup):
                got = lub.lubrication_product(radii, at, vec, s)
                assert np.abs(got - ref).max() < 1e-13 * np.abs(ref).max()
