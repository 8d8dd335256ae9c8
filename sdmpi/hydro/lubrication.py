"""Near-field (lubrication) correction R_2B - R_2B,inf of Stokesian dynamics.

Durlofsky, Brady & Bossis (1987); Brady & Bossis, Annu. Rev. Fluid Mech. 20 (1988):
for every close pair the exact two-sphere resistance R_2B (`two_sphere`, Jeffrey &
Onishi 1984, Jeffrey 1992) is added and the part already present in the inverted far
field, the inverse of the two-sphere far-field mobility R_2B,inf = (M_2B,inf)^-1
(`farfield`, unbounded form), is removed, so that two isolated spheres are exact.

Pairs: all (i, j, image) with centre distance r < a_i + a_j + cutoff (a_i + a_j)/2,
including a particle and its own periodic images; the correction decays like r^-4..r^-7
beyond it. Gap regularisation: a pair closer than a_i + a_j + min_gap (a_i + a_j)/2
(touching or overlapping) is evaluated at that minimum gap (default epsilon = 1e-4 of
the mean radius, as in Dratler & Schowalter's (1996) minimum-separation rule), so R stays finite and
positive definite; such pairs are counted.

Evaluation (tabulated, `lubrication_matrix`). R_2B and R_2B,inf are both invariant
under rotations about, and reflections in planes containing, the line of centres d, and
so is their difference: R_2B - R_2B,inf has exactly the tensor form of `two_sphere` (11
scalar functions of the scaled separation s for each of the 4 particle blocks, times the
tensors of d), with 44 scalars D(s; lam) in the Jeffrey-Onishi normalisation (scale
invariant). Per distinct size ratio lam = a_small/a_big (<= 1; a pair is ordered small
sphere second, i.e. its particles swapped and dx negated when a1 > a2) they are computed
once by the exact path (pair_resistance minus the inverted 22x22 far-field pair mobility)
at d = e_z and projected onto the 44 tensor patterns of `two_sphere._fill_pair_columns`,
on the uniform grid u_k = k h, h = 1/64, of u = log(xi), xi = s - 2, as
xi/(1 + xi) D (the factor removes the 1/xi lubrication singularity; the log terms become
smooth in u). Lookup: 8-point Lagrange interpolation in u. The table covers
xi in [5e-5, 12] when built (gap cut-off up to 10 mean radii) and is extended on the same
grid when a pair needs more (old rows unchanged, results deterministic); interpolation
error: docs/numerics.md, "Lubrication tables". The exact path
(`lubrication_matrix_exact`, `pair_corrections_exact`) serves pairs whose lam has no
table: a table is built for a lam only when a call has >= _MIN_PAIRS_FOR_TABLE pairs with
it, and at most _MAX_TABLES tables are kept (continuous polydispersity then stays on the
exact path); also for gaps outside [_XI_TABLE_MIN, _XI_TABLE_MAX]. The choice depends only
on the pair set and on tables already built (never evicted), so displaced configurations
with the same plan (random finite differences) use the same path.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse

from .basis import BASIS
from .farfield import NDOF, _pair_block, _power_bounds, radial_table, self_mobility
from .geometry import Lattice, find_pairs
from .two_sphere import FILL_SCRATCH, _fill_pair_columns, pair_resistance
from .workspace import work_array

#: default lubrication cut-off: gap in units of the pair's mean radius
DEFAULT_CUTOFF = 2.0
#: default minimum gap (regularisation), in units of the pair's mean radius
DEFAULT_MIN_GAP = 1e-4


@dataclass
class PairList:
    """Close pairs: particle indices i, j, separation vectors x_j + shift - x_i (after
    regularisation), the shifts, true surface gaps (negative for overlaps), and the number of pairs
    closer than the minimum gap (touching or overlapping)."""

    i: np.ndarray
    j: np.ndarray
    dx: np.ndarray
    shift: np.ndarray  # lattice translation of j's image
    gap: np.ndarray
    n_regularised: int
    radii_sum: np.ndarray

    @property
    def distance(self) -> np.ndarray:
        """True centre distances (before regularisation), (npairs,), length unit of the radii."""
        return self.gap + self.radii_sum

    @property
    def min_gap(self) -> float:
        """Smallest surface gap (negative for an overlap), inf without pairs (length unit of
        the radii)."""
        return float(self.gap.min()) if len(self.gap) else np.inf


def lubrication_reach(cutoff: float) -> float:
    """The pair search's relative reach for a gap cut-off (mean radii): centres closer than
    (1 + cutoff/2) (a_i + a_j).

    Args:
        cutoff: gap cut-off, in mean radii of the pair.

    Returns:
        The reach per sum of radii a_i + a_j (dimensionless).
    """
    return 1.0 + 0.5 * cutoff


def close_pairs(positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None = None,
                cutoff: float = DEFAULT_CUTOFF, min_gap: float = DEFAULT_MIN_GAP,
                images: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> PairList:
    """All pairs (with periodic images when a lattice is given) within the cut-off, or
    the given images (i, j, shift) re-evaluated at these positions (so that a slightly
    displaced configuration keeps the same pair set). Separations are regularised to the
    minimum gap and counted.

    Args:
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii a.
        lattice: the periodic lattice, or None (unbounded fluid).
        cutoff: gap cut-off, in mean radii of the pair.
        min_gap: smallest gap the separations are regularised to, in mean radii.
        images: (i (P,), j (P,), shift (P, 3)) pair images to re-evaluate, or None (search).

    Returns:
        The close pairs.
    """
    if images is None:
        images = find_pairs(positions, radii, lattice, 0.0, lubrication_reach(cutoff))
    i, j, shift = images
    if len(i) == 0:
        return PairList(i, j, np.zeros((0, 3)), shift, np.zeros(0), 0, np.zeros(0))
    dx, gap, asum = np.empty((len(i), 3)), np.empty(len(i)), np.empty(len(i))
    short = _separations(np.ascontiguousarray(positions, dtype=float), np.ascontiguousarray(radii, dtype=float),
                         np.ascontiguousarray(i, dtype=np.int64), np.ascontiguousarray(j, dtype=np.int64),
                         np.ascontiguousarray(shift, dtype=float), float(min_gap), dx, gap, asum)
    return PairList(i, j, dx, shift, gap, short, asum)


@numba.njit(cache=True)
def _separations(pos, radii, pi, pj, shift, min_gap, dx, gap, asum):
    """dx[p] = x_j + shift - x_i, gap[p] = |dx| - (a_i + a_j), asum[p] = a_i + a_j for the
    pairs p = (pi[p], pj[p]); separations with a gap below the floor (min_gap/2) asum are
    stretched to it (`close_pairs`); returns how many were."""
    short = 0
    for p in range(pi.shape[0]):
        i, j = pi[p], pj[p]
        d0 = pos[j, 0] + shift[p, 0] - pos[i, 0]
        d1 = pos[j, 1] + shift[p, 1] - pos[i, 1]
        d2 = pos[j, 2] + shift[p, 2] - pos[i, 2]
        r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        s = radii[i] + radii[j]
        g = r - s
        floor = 0.5 * min_gap * s
        if g < floor:
            f = (s + floor) / r
            d0, d1, d2 = d0 * f, d1 * f, d2 * f
            short += 1
        dx[p, 0], dx[p, 1], dx[p, 2] = d0, d1, d2
        gap[p], asum[p] = g, s
    return short


@numba.njit(cache=True)
def _subtract_far_field(dx, a1, a2, self1, self2, table, basis, res):
    """res[p] -= inverse of the 22x22 unbounded two-sphere far-field mobility."""
    mob = np.zeros((2 * NDOF, 2 * NDOF))
    bounds = _power_bounds(table)
    work = np.empty(80)
    block = np.zeros((NDOF, NDOF))
    rvec = np.empty(3)
    for p in range(dx.shape[0]):
        mob[:, :] = 0.0
        block[:, :] = 0.0
        for c in range(3):
            rvec[c] = -dx[p, c]  # receiver 1 minus source 2
        _pair_block(rvec, a1[p], a2[p], table, bounds, 0.0, basis, work, block)
        mob[:NDOF, :NDOF] = self1[p]
        mob[NDOF:, NDOF:] = self2[p]
        mob[:NDOF, NDOF:] = block
        mob[NDOF:, :NDOF] = block.T
        res[p] -= np.linalg.inv(mob)


def pair_corrections_exact(dx: np.ndarray, a1: np.ndarray | float, a2: np.ndarray | float) -> np.ndarray:
    """R_2B - R_2B,inf per pair, shape (npairs, 22, 22), by the exact path:
    `two_sphere.pair_resistance` minus the inverse of the 22x22 unbounded far-field pair
    mobility. dx = x2 - x1 (npairs, 3), radii a1, a2 (npairs,).

    Args:
        dx: (npairs, 3) separations x2 - x1 (length unit of the radii).
        a1: (npairs,) radii of the first spheres (or a scalar).
        a2: (npairs,) radii of the second spheres (or a scalar).

    Returns:
        (npairs, 22, 22) corrections (Stokes units, viscosity 1), dofs (U, Omega, E) of
        sphere 1 then sphere 2.
    """
    dx = np.ascontiguousarray(dx, dtype=float).reshape(-1, 3)
    a1 = np.broadcast_to(np.asarray(a1, dtype=float), (dx.shape[0],)).copy()
    a2 = np.broadcast_to(np.asarray(a2, dtype=float), (dx.shape[0],)).copy()
    if dx.shape[0] == 0:
        return np.zeros((0, 2 * NDOF, 2 * NDOF))
    res = pair_resistance(dx, a1, a2)
    selfs = {a: self_mobility(a) for a in np.unique(np.concatenate([a1, a2]))}
    self1 = np.stack([selfs[a] for a in a1])
    self2 = np.stack([selfs[a] for a in a2])
    _subtract_far_field(dx, a1, a2, self1, self2, _RADIAL_TABLE, BASIS, res)
    return res


def lubrication_matrix_exact(positions: np.ndarray, radii: np.ndarray, pairs: PairList) -> np.ndarray:
    """`lubrication_matrix` by the exact path for every pair (reference; ~14 us/pair).

    Args:
        positions: (N, 3) sphere centres.
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).

    Returns:
        (11N, 11N) near-field correction (Stokes units, viscosity 1).
    """
    n = positions.shape[0]
    out = np.zeros((NDOF * n, NDOF * n))
    if len(pairs.i) == 0:
        return out
    res = pair_corrections_exact(pairs.dx, radii[pairs.i], radii[pairs.j])
    scatter_pair_blocks(pairs.i, pairs.j, res, out)
    return out


def lubrication_matrix(positions: np.ndarray, radii: np.ndarray, pairs: PairList,
                       out: np.ndarray | None = None) -> np.ndarray:
    """The (11N, 11N) near-field correction: the sum over the close pairs (a PairList
    from `close_pairs`) of R_2B - R_2B,inf (tabulated, module docstring). With out (an
    (11N, 11N) float64 C-contiguous array, e.g. the inverted far field), the correction
    is added into it in place and out is returned (no (11N)^2 temporary).

    Args:
        positions: (N, 3) sphere centres.
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).
        out: (11N, 11N) C-contiguous float64 array to add into, or None.

    Returns:
        (11N, 11N) near-field correction (Stokes units, viscosity 1), or out plus it.
    """
    n = positions.shape[0]
    if out is None:
        out = np.zeros((NDOF * n, NDOF * n))
    elif out.shape != (NDOF * n, NDOF * n) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError("lubrication_matrix: out must be a C-contiguous float64 (11N, 11N) array")
    for pi, pj, res, _ in pair_blocks(radii, pairs):
        scatter_pair_blocks(pi, pj, res, out)
    return out


def lubrication_product(radii: np.ndarray, pairs: PairList, vector: np.ndarray,
                        setup: tuple | None = None) -> np.ndarray:
    """L v (N, 11) for v (N, 11): the near-field correction of `lubrication_matrix` applied
    to one vector pair by pair, each tabulated pair's block formed in scratch memory
    (`_tabulated_product`; only its rigid-body columns when v is zero on the strain dofs),
    without forming the matrix. setup: the one of `lubrication_partitions` for the same
    images (e.g. at a nearby configuration), which spares the pairs' ordering and table
    look-up when the tables cover these separations (the same values).

    Args:
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).
        vector: (N, 11) generalized velocities v (U, Omega, E per sphere).
        setup: the setup of `lubrication_partitions` for the same images, or None.

    Returns:
        (N, 11) L v (generalized forces, Stokes units).
    """
    vector = np.ascontiguousarray(vector, dtype=float)
    out = np.zeros_like(vector)
    if len(pairs.i) == 0:
        return out
    rigid = not vector[:, 6:].any()
    if setup is not None:
        swap, a1, a2, tab, tables = setup
        if len(a1) == len(pairs.i):
            pi, pj = np.asarray(pairs.i, dtype=np.int64), np.asarray(pairs.j, dtype=np.int64)
            dx = np.ascontiguousarray(pairs.dx, dtype=float)
            if swap is not None:
                pi, pj = np.where(swap, pj, pi), np.where(swap, pi, pj)
                dx = np.ascontiguousarray(np.where(swap[:, None], -dx, dx))
            if _tables_cover(dx, a1, a2, tab, tables[2], tables[3]):
                _tabulated_product(dx, a1, a2, tab, *tables, pi, pj, vector, rigid, out)
                return out
    (pi, pj, a1, a2, dx, tab, tables, sel, slow), (pi0, pj0, a10, a20, dx0) = _pair_setup(radii, pairs)
    if len(slow) == 0:
        _tabulated_product(dx, a1, a2, tab, *tables, pi, pj, vector, rigid, out)
        return out
    if len(sel):
        _tabulated_product(dx[sel], a1[sel], a2[sel], tab[sel], *tables, pi[sel], pj[sel], vector, rigid, out)
    pair_products(pi0[slow], pj0[slow], pair_corrections_exact(dx0[slow], a10[slow], a20[slow]), vector, out)
    return out


@numba.njit(cache=True)
def pair_products(pi, pj, res, v, out):
    """out[(i, j)] += res[p] (v_i, v_j) for every pair p = (i, j) (22x22 blocks res)."""
    for p in range(pi.shape[0]):
        idx = (pi[p], pj[p])
        for u in range(2):
            for a in range(NDOF):
                acc = 0.0
                for s in range(2):
                    for b in range(NDOF):
                        acc += res[p, NDOF * u + a, NDOF * s + b] * v[idx[s], b]
                out[idx[u], a] += acc


def lubrication_sparse(positions: np.ndarray, radii: np.ndarray, pairs: PairList, factors: bool = False
                       ) -> scipy.sparse.bsr_matrix | tuple[scipy.sparse.bsr_matrix, np.ndarray, np.ndarray,
                                                             np.ndarray]:
    """The near-field correction of `lubrication_matrix` as a scipy BSR matrix
    (11 x 11 blocks): the same pair blocks, summed into the blocks (i, i), (i, j),
    (j, i), (j, j) that the pairs touch. With factors, also the lower Cholesky factors
    C_p (npairs, 12, 12) of each pair's rigid-body (FU) part, C_p C_p^T = (R_2B - R_2B,inf)_FU,
    in the pair order of `pair_blocks` with its (i, j), for Brownian forces.

    Args:
        positions: (N, 3) sphere centres.
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).
        factors: also return the pairs' rigid-body Cholesky factors.

    Returns:
        The (11N, 11N) BSR matrix (Stokes units, viscosity 1); with factors also pair_i
        (npairs,), pair_j (npairs,) and C_p (npairs, 12, 12).

    Raises:
        numpy.linalg.LinAlgError: a pair's rigid-body block is not positive definite.
    """
    matrix, found = lubrication_rows(positions, radii, pairs, (0, positions.shape[0]), factors)
    return matrix if not factors else (matrix, *found[1:])


def lubrication_rows(positions: np.ndarray, radii: np.ndarray, pairs: PairList, rows: tuple[int, int],
                     factors: bool = False) -> tuple[scipy.sparse.bsr_matrix, tuple | None]:
    """Block rows r0:r1 (rows = (r0, r1), spheres r0 .. r1 - 1) of `lubrication_sparse`'s
    matrix, formed from the pairs that touch those spheres alone: every block sums the same
    pair blocks in the same order as the whole matrix's (`pair_blocks` with only), so the
    entries are the same bits. With factors, also the rigid-body Cholesky factors C_p of
    those pairs, the same bits as `lubrication_sparse`'s.

    Args:
        positions: (N, 3) sphere centres.
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).
        rows: (r0, r1), the block rows (spheres) 0 <= r0 <= r1 <= N.
        factors: also return the factors of the pairs that touch the rows.

    Returns:
        The (11 (r1 - r0), 11N) BSR matrix of the rows (Stokes units, viscosity 1), and with
        factors (at, pair_i, pair_j, C_p) of the pairs touching the rows, in the order of
        `lubrication_sparse`'s factors: their places (m,) in that order of all pairs, their
        spheres (m,), (m,) and factors (m, 12, 12); without factors None.

    Raises:
        numpy.linalg.LinAlgError: a pair's rigid-body block is not positive definite.
    """
    n = positions.shape[0]
    r0, r1 = rows
    nl = r1 - r0
    pi, pj = np.asarray(pairs.i, dtype=np.int64), np.asarray(pairs.j, dtype=np.int64)
    touch = ((pi >= r0) & (pi < r1)) | ((pj >= r0) & (pj < r1))
    # block slots: diagonal blocks first (one per sphere of the rows), then the distinct
    # (i, j), i != j, i in the rows
    off = touch & (pi != pj)
    keys = np.unique(np.concatenate([pi[off] * n + pj[off], pj[off] * n + pi[off]]))
    keys = keys[(keys >= r0 * n) & (keys < r1 * n)]
    block_rows = np.concatenate([np.arange(r0, r1), keys // n]) - r0
    cols = np.concatenate([np.arange(r0, r1), keys % n])
    order = np.lexsort((cols, block_rows))
    slot_of = np.empty(len(order), dtype=np.int64)
    slot_of[order] = np.arange(len(order))

    def slots(r, c):  # the slots of the blocks (r, c), -1 for rows outside r0:r1
        inside = (r >= r0) & (r < r1)
        raw = np.where(r == c, r - r0, nl + np.searchsorted(keys, r * n + c))
        return np.where(inside, slot_of[np.where(inside, raw, 0)], -1)

    data = np.zeros((len(order), NDOF, NDOF))
    n_touch = int(touch.sum()) if factors else 0
    at, all_pi, all_pj = (np.empty(n_touch, dtype=np.int64) for _ in range(3))
    chol = np.empty((n_touch, 12, 12))
    done = 0  # pairs so far, in the order of pair_blocks
    for ci, cj, res, places in pair_blocks(radii, pairs, touch):
        _scatter_slots(slots(ci, ci), slots(ci, cj), slots(cj, ci), slots(cj, cj), res, data)
        if factors:
            part = slice(done, done + len(res))
            at[part], all_pi[part], all_pj[part] = places, ci, cj
            bad = _rigid_cholesky(res, chol[part])
            if bad >= 0:
                raise np.linalg.LinAlgError(f"the rigid-body lubrication block of the pair ({ci[bad]}, "
                                            f"{cj[bad]}) is not positive definite")
            done = part.stop
    indptr = np.searchsorted(block_rows[order], np.arange(nl + 1))
    matrix = scipy.sparse.bsr_matrix((data, cols[order], indptr), shape=(NDOF * nl, NDOF * n))
    return matrix, ((at, all_pi, all_pj, chol) if factors else None)


@numba.njit(cache=True)
def _rigid_cholesky(res, out):
    """out[p] = the lower Cholesky factor of the 12 rigid-body rows and columns (U, Omega
    of either sphere: 0-5 and NDOF..NDOF+5) of each pair's 22x22 block res[p], from its
    lower triangle (as LAPACK's potrf; faster than numpy's batched cholesky on 12x12
    blocks). Returns the first pair that is not positive definite, else -1."""
    for p in range(res.shape[0]):
        for a in range(12):
            ra = a if a < 6 else a + NDOF - 6
            for b in range(a + 1):
                rb = b if b < 6 else b + NDOF - 6
                acc = res[p, ra, rb]
                for c in range(b):
                    acc -= out[p, a, c] * out[p, b, c]
                if a > b:
                    out[p, a, b] = acc / out[p, b, b]
                elif acc > 0.0:
                    out[p, a, a] = math.sqrt(acc)
                else:
                    return p
            for b in range(a + 1, 12):
                out[p, a, b] = 0.0
    return -1

#: pairs per chunk of `pair_blocks` (22x22 floats each: ~8 MB per chunk)
_CHUNK = 2048


def _pair_setup(radii, pairs):
    """What `pair_blocks`, `lubrication_partitions` and `lubrication_product` share: the
    pairs ordered big sphere first (pi, pj, a1, a2, dx), each pair's table (-1: exact path)
    and the tables' snapshot (`_TableStore.lookup`), the tabulated pairs' indices (fast)
    and the exact ones (slow), and the pairs as given (pi0, pj0, a10, a20, dx0)."""
    radii = np.asarray(radii, dtype=float)
    pi0, pj0 = np.asarray(pairs.i, dtype=np.int64), np.asarray(pairs.j, dtype=np.int64)
    dx0 = np.ascontiguousarray(pairs.dx, dtype=float)
    a10, a20 = radii[pi0], radii[pj0]
    # order every pair big sphere first (lam = a2/a1 <= 1): one table per unordered lam
    swap = a10 < a20
    if swap.any():
        pi, pj = np.where(swap, pj0, pi0), np.where(swap, pi0, pj0)
        a1, a2 = np.where(swap, a20, a10), np.where(swap, a10, a20)
        dx = np.ascontiguousarray(np.where(swap[:, None], -dx0, dx0))
    else:
        pi, pj, a1, a2, dx = pi0, pj0, a10, a20, dx0
    asum = a1 + a2
    xi = 2.0 * (np.sqrt(np.einsum("ij,ij->i", dx, dx)) - asum) / asum
    lam = a2 / a1
    tab, tables = _STORE.lookup(lam, xi)
    fast = tab >= 0
    if fast.all():
        sel, slow = np.arange(len(fast)), np.zeros(0, dtype=np.int64)
    else:
        sel, slow = np.flatnonzero(fast), np.flatnonzero(~fast)
    return (pi, pj, a1, a2, dx, tab, tables, sel, slow), (pi0, pj0, a10, a20, dx0)


def pair_blocks(radii: np.ndarray, pairs: PairList, only: np.ndarray | None = None
                ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """R_2B - R_2B,inf of every pair, in chunks (pi, pj, res (npairs, 22, 22), places),
    rows and columns ordered (pi's 11 dofs, pj's 11 dofs): the tabulated pairs first, then
    the exact ones (module docstring); together all pairs once, places their positions
    (m,) in that order. only (npairs,) bool: the pairs marked alone, in the same order and
    by the same path (tabulated or exact) as among all pairs (places still count all). A
    tabulated chunk's res is a `workspace.work_array`, valid until the next chunk is asked
    for.

    Args:
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).
        only: which pairs to form, or None (all).

    Returns:
        An iterator of chunks (pi (m,), pj (m,), res (m, 22, 22), Stokes units; places (m,)).
    """
    if len(pairs.i) == 0:
        return
    (pi, pj, a1, a2, dx, tab, tables, sel, slow), (pi0, pj0, a10, a20, dx0) = _pair_setup(radii, pairs)
    places, slow_places = np.arange(len(sel)), len(sel) + np.arange(len(slow))
    if only is not None:
        places, sel = places[only[sel]], sel[only[sel]]
        slow_places, slow = slow_places[only[slow]], slow[only[slow]]
    for c in range(0, len(sel), _CHUNK):
        part = sel[c:c + _CHUNK]
        res = work_array("pair_blocks", (len(part), 2 * NDOF, 2 * NDOF))
        _tabulated_kernel(dx[part], a1[part], a2[part], tab[part], *tables, res)
        yield pi[part], pj[part], res, places[c:c + _CHUNK]
    if len(slow):  # as given (not reordered): same as lubrication_matrix_exact
        yield pi0[slow], pj0[slow], pair_corrections_exact(dx0[slow], a10[slow], a20[slow]), slow_places


def lubrication_partitions(radii: np.ndarray, pairs: PairList, n: int
                           ) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], tuple | None] | None:
    """The near-field correction of `lubrication_matrix` for n particles as dense partitions
    (L_FU (6N x 6N), L_FE (6N x 5N), L_SE (5N x 5N), dofs particle by particle within each:
    rows and columns of the rigid-body dofs U, Omega (6 per particle) and of the strain dofs
    E (5 per particle); L_SU = L_FE^T is not stored), and the pairs' setup: their
    orientation, radii and tables for `lubrication_product` at displaced separations (None
    when some pair takes the exact path). The tabulated pairs' 22x22 blocks are formed one
    at a time in scratch memory and added into the partitions (`_tabulated_partitions`).
    None without pairs.

    Args:
        radii: (N,) sphere radii a.
        pairs: the close pairs (`close_pairs`).
        n: the number of spheres N.

    Returns:
        ((L_FU, L_FE, L_SE), setup) (Stokes units, viscosity 1), or None without pairs.
    """
    if len(pairs.i) == 0:
        return None
    (pi, pj, a1, a2, dx, tab, tables, sel, slow), (pi0, pj0, a10, a20, dx0) = _pair_setup(radii, pairs)
    dense = np.zeros((6 * n, 6 * n)), np.zeros((6 * n, 5 * n)), np.zeros((5 * n, 5 * n))
    if len(slow) == 0:
        _tabulated_partitions(dx, a1, a2, tab, *tables, pi, pj, *dense)
        swap = None if pi is pi0 else pi != pi0
        return dense, (swap, a1, a2, tab, tables)
    if len(sel):
        _tabulated_partitions(dx[sel], a1[sel], a2[sel], tab[sel], *tables, pi[sel], pj[sel], *dense)
    _scatter_partitions(pi0[slow], pj0[slow], pair_corrections_exact(dx0[slow], a10[slow], a20[slow]), *dense)
    return dense, None


@numba.njit(cache=True)
def _tables_cover(dx, a1, a2, tab, k_lo, n_rows):
    """Whether every pair's interpolation (`_interpolate`) at separations dx reads
    rows inside its table (no clamp; one row of margin) and has a gap in the tables'
    range."""
    half = _TAB_NPT // 2
    for p in range(dx.shape[0]):
        r = math.sqrt(dx[p, 0] ** 2 + dx[p, 1] ** 2 + dx[p, 2] ** 2)
        asum = a1[p] + a2[p]
        xi = 2.0 * (r - asum) / asum
        if not (xi >= _XI_TABLE_MIN and xi <= _XI_TABLE_MAX):
            return False
        k = int(math.floor(math.log(xi) * (1.0 / _TAB_H)))
        t = tab[p]
        if k - 1 < k_lo[t] + half - 1 or k + 1 > k_lo[t] + n_rows[t] - half - 1:
            return False
    return True


def pair_corrections(dx: np.ndarray, a1: np.ndarray | float, a2: np.ndarray | float) -> np.ndarray:
    """R_2B - R_2B,inf per pair, (npairs, 22, 22), by the tabulated path where
    `lubrication_matrix` would use it (else exact): for tests and diagnostics.

    Args:
        dx: (npairs, 3) separations x2 - x1 (length unit of the radii).
        a1: (npairs,) radii of the first spheres (or a scalar).
        a2: (npairs,) radii of the second spheres (or a scalar).

    Returns:
        (npairs, 22, 22) corrections (Stokes units, viscosity 1).
    """
    dx = np.ascontiguousarray(dx, dtype=float).reshape(-1, 3)
    npairs = dx.shape[0]
    a1 = np.broadcast_to(np.asarray(a1, dtype=float), (npairs,))
    a2 = np.broadcast_to(np.asarray(a2, dtype=float), (npairs,))
    radii = np.concatenate([a1, a2])
    idx = np.arange(npairs)
    pairs = PairList(idx, idx + npairs, dx.copy(), np.zeros((npairs, 3)), np.zeros(npairs), 0, a1 + a2)
    # each pair on its own two particles: read the four 11x11 blocks back
    big = lubrication_matrix(np.zeros((2 * npairs, 3)), radii, pairs)
    out = np.empty((npairs, 2 * NDOF, 2 * NDOF))
    for u, pu in enumerate((idx, idx + npairs)):
        for v, pv in enumerate((idx, idx + npairs)):
            rows = (NDOF * pu)[:, None] + np.arange(NDOF)[None, :]
            cols = (NDOF * pv)[:, None] + np.arange(NDOF)[None, :]
            out[:, NDOF * u:NDOF * (u + 1), NDOF * v:NDOF * (v + 1)] = big[rows[:, :, None], cols[:, None, :]]
    return out


# ---------------------------------------------------------------------------------------
# tabulated R_2B - R_2B,inf

_RADIAL_TABLE = radial_table(0.0)
#: grid step in u = log(xi) and number of Lagrange points (even)
_TAB_H = 1.0 / 64.0
_TAB_NPT = 8
#: xi range built at first (covers min_gap 1e-4 .. cut-off 10 with margin)
_XI_TABLE_INIT = (5e-5, 12.0)
#: gaps outside this range always take the exact path
_XI_TABLE_MIN, _XI_TABLE_MAX = 1e-9, 1e4
#: a lam gets a table when a call has at least this many pairs with it ...
_MIN_PAIRS_FOR_TABLE = 16
#: ... and fewer than this many tables exist (never evicted)
_MAX_TABLES = 64


def _lagrange_denominators(npt):
    nodes = np.arange(npt) - (npt // 2 - 1)
    return np.array([np.prod([m - l for l in nodes if l != m]) for m in nodes], dtype=float)


#: 1 / the denominators of the Lagrange weights
_TAB_INV_DENOM = 1.0 / _lagrange_denominators(_TAB_NPT)


def _tensor_patterns(lam):
    """(44, 484): the 22x22 matrix of `two_sphere._fill_pair_columns` at d = e_z, a1 = 1,
    a2 = lam for each unit scalar (block b, function f) -> row 11 b + f."""
    d = np.array([0.0, 0.0, 1.0])
    pat = np.zeros((4 * NDOF, 2 * NDOF, 2 * NDOF))
    work = np.empty(FILL_SCRATCH)
    for k in range(4 * NDOF):
        sc = np.zeros((4, NDOF))
        sc.flat[k] = 1.0
        _fill_pair_columns(d, 1.0, lam, sc, pat[k], work, False)
    return pat.reshape(4 * NDOF, -1)


def canonical_scalars(xi: np.ndarray | float, lam: float) -> tuple[np.ndarray, float]:
    """The 44 scalars (npts, 4, 11) of R_2B - R_2B,inf (JO normalisation, `two_sphere`
    layout) at scaled gaps xi and size ratio lam, from the exact path at d = e_z, and the
    largest deviation of that matrix from the tensor form relative to its largest entry
    (round-off: the projection is exact for an invariant matrix).

    Args:
        xi: (npts,) scaled gaps 2 (r - a1 - a2)/(a1 + a2) (or a scalar).
        lam: size ratio a2/a1.

    Returns:
        (npts, 4, 11) scalars (dimensionless, JO normalisation) and the relative
        deviation from the tensor form.
    """
    xi = np.atleast_1d(np.asarray(xi, dtype=float))
    n = xi.shape[0]
    dx = np.zeros((n, 3))
    dx[:, 2] = 0.5 * (1.0 + lam) * (2.0 + xi)
    res = pair_corrections_exact(dx, np.ones(n), np.full(n, float(lam))).reshape(n, -1)
    pat = _tensor_patterns(float(lam))
    # the patterns have disjoint supports: the projection is a weighted sum
    coef = (res @ pat.T) / np.einsum("kq,kq->k", pat, pat)[None, :]
    dev = np.abs(res - coef @ pat).max(axis=1) / np.maximum(np.abs(res).max(axis=1), 1e-300)
    return coef.reshape(n, 4, NDOF), float(dev.max())


class _Tables:
    """All tables in one array (numba-friendly): rows offset[t] .. offset[t] + n_rows[t]
    of data (rows, 44) hold xi/(1 + xi) D at u = (k_lo[t] + row) h for table t."""

    def __init__(self):
        self.lams = []
        self.blocks = []  # (k_lo, rows (nk, 44))
        self._pack()

    def _pack(self):
        nt = len(self.blocks)
        self.k_lo = np.array([b[0] for b in self.blocks], dtype=np.int64)
        self.n_rows = np.array([b[1].shape[0] for b in self.blocks], dtype=np.int64)
        self.offset = np.concatenate([[0], np.cumsum(self.n_rows)])[:nt].astype(np.int64)
        self.data = (np.ascontiguousarray(np.concatenate([b[1] for b in self.blocks]))
                     if nt else np.zeros((1, 4 * NDOF)))

    @staticmethod
    def _rows(lam, k0, k1):
        u = np.arange(k0, k1) * _TAB_H
        xi = np.exp(u)
        coef, _ = canonical_scalars(xi, lam)
        return coef.reshape(len(u), 4 * NDOF) * (xi / (1.0 + xi))[:, None]

    def ensure(self, lam, k0, k1):
        """Table for lam covering grid rows k0 .. k1 - 1 (built or extended)."""
        if lam in self.lams:
            t = self.lams.index(lam)
            k_lo, rows = self.blocks[t]
            k_hi = k_lo + rows.shape[0]
            if k0 >= k_lo and k1 <= k_hi:
                return False
            parts = []
            if k0 < k_lo:
                parts.append(self._rows(lam, k0, k_lo))
            parts.append(rows)
            if k1 > k_hi:
                parts.append(self._rows(lam, k_hi, k1))
            self.blocks[t] = (min(k0, k_lo), np.concatenate(parts))
        else:
            lo, hi = _XI_TABLE_INIT
            k0 = min(k0, int(math.floor(math.log(lo) / _TAB_H)))
            k1 = max(k1, int(math.ceil(math.log(hi) / _TAB_H)) + 1)
            self.lams.append(lam)
            self.blocks.append((k0, self._rows(lam, k0, k1)))
        self._pack()
        return True


class _TableStore:
    def __init__(self):
        self._lock = threading.Lock()
        self._tables = _Tables()

    def lookup(self, lam, xi):
        """Per pair the table index (-1: exact path), building/extending tables as
        needed, and a consistent snapshot (data, offset, k_lo, n_rows) of the tables."""
        half = _TAB_NPT // 2
        n_in, k_min, k_max = _grid_range(xi)
        if n_in == len(xi) and lam.min() == lam.max():
            # every gap in range, one size ratio (monodisperse): no masks, no sort
            lv = float(lam[0])
            with self._lock:
                tables = self._tables
                if lv in tables.lams or (len(xi) >= _MIN_PAIRS_FOR_TABLE and len(tables.lams) < _MAX_TABLES):
                    tables.ensure(lv, k_min - half, k_max + half + 2)
                    tab = np.full(len(xi), tables.lams.index(lv), dtype=np.int64)
                else:
                    tab = np.full(len(xi), -1, dtype=np.int64)
                snapshot = (tables.data, tables.offset, tables.k_lo, tables.n_rows)
            return tab, snapshot
        tab = np.full(lam.shape[0], -1, dtype=np.int64)
        ok = (xi >= _XI_TABLE_MIN) & (xi <= _XI_TABLE_MAX)
        if not ok.any():
            return tab, None
        lam_ok = lam[ok]
        if lam_ok.min() == lam_ok.max():  # one size ratio: no sort
            ulam, inv, counts = lam_ok[:1], np.zeros(len(lam_ok), dtype=np.int64), np.array([len(lam_ok)])
        else:
            ulam, inv, counts = np.unique(lam_ok, return_inverse=True, return_counts=True)
        kk = np.floor(np.log(xi[ok]) / _TAB_H).astype(np.int64)
        with self._lock:
            tables = self._tables
            for il, lv in enumerate(ulam):
                lv = float(lv)
                if lv not in tables.lams and (counts[il] < _MIN_PAIRS_FOR_TABLE
                                              or len(tables.lams) >= _MAX_TABLES):
                    continue
                ks = kk[inv == il] if len(ulam) > 1 else kk
                # one spare row each side: the kernel recomputes k from r
                tables.ensure(lv, int(ks.min()) - half, int(ks.max()) + half + 2)
            index = {lv: t for t, lv in enumerate(tables.lams)}
            per = np.array([index.get(float(lv), -1) for lv in ulam], dtype=np.int64)
            tab[ok] = per[inv]
            snapshot = (tables.data, tables.offset, tables.k_lo, tables.n_rows)
        return tab, snapshot


_STORE = _TableStore()


@numba.njit(cache=True)
def _grid_range(xi):
    """(how many xi lie in [_XI_TABLE_MIN, _XI_TABLE_MAX], the smallest and the largest
    grid row floor(log(xi)/h) among them)."""
    count, k_min, k_max = 0, 0, 0
    for p in range(xi.shape[0]):
        if xi[p] >= _XI_TABLE_MIN and xi[p] <= _XI_TABLE_MAX:
            k = int(math.floor(math.log(xi[p]) / _TAB_H))
            if count == 0 or k < k_min:
                k_min = k
            if count == 0 or k > k_max:
                k_max = k
            count += 1
    return count, k_min, k_max


@numba.njit(cache=True)
def _tabulated_kernel(dx, a1, a2, tab, data, offset, k_lo, n_rows, res):
    """res[p] = R_2B - R_2B,inf of every pair (`_interpolate`, `two_sphere._fill_pair_columns`)."""
    sc = np.empty((4, NDOF))
    w = np.empty(_TAB_NPT)
    d = np.empty(3)
    work = np.empty(FILL_SCRATCH)
    for p in range(dx.shape[0]):
        _interpolate(p, dx, a1, a2, tab, data, offset, k_lo, n_rows, sc, w, d)
        _fill_pair_columns(d, a1[p], a2[p], sc, res[p], work, False)


@numba.njit(cache=True, inline="always")
def _interpolate(p, dx, a1, a2, tab, data, offset, k_lo, n_rows, sc, w, d):
    """The scalars sc (4, 11) of R_2B - R_2B,inf of pair p, by Lagrange interpolation in its
    table, and the unit vector d (3,) of its separation; w (npt,): scratch for the weights
    (times the factor (1 + xi)/xi that undoes the table's scaling)."""
    npt = _TAB_NPT
    half = npt // 2
    r = math.sqrt(dx[p, 0] ** 2 + dx[p, 1] ** 2 + dx[p, 2] ** 2)
    for c in range(3):
        d[c] = dx[p, c] / r
    asum = a1[p] + a2[p]
    xi = 2.0 * (r - asum) / asum
    x = math.log(xi) * (1.0 / _TAB_H)
    k = int(math.floor(x))
    t = tab[p]
    # clamp (never active when the table covers the pair, see _TableStore.lookup)
    k = min(max(k, k_lo[t] + half - 1), k_lo[t] + n_rows[t] - half - 1)
    frac = x - k
    unscale = (1.0 + xi) / xi
    for m in range(npt):
        acc = _TAB_INV_DENOM[m] * unscale
        for l in range(npt):
            if l != m:
                acc *= frac - (l - half + 1)
        w[m] = acc
    row = offset[t] + k - k_lo[t] - half + 1
    # the _TAB_NPT = 8 weights as scalars, each scalar one sum over the points (kept in registers)
    w0, w1, w2, w3, w4, w5, w6, w7 = w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]
    for b in range(4):
        for f in range(NDOF):
            col = NDOF * b + f
            sc[b, f] = (w0 * data[row, col] + w1 * data[row + 1, col] + w2 * data[row + 2, col]
                        + w3 * data[row + 3, col] + w4 * data[row + 4, col] + w5 * data[row + 5, col]
                        + w6 * data[row + 6, col] + w7 * data[row + 7, col])


@numba.njit(cache=True)
def _tabulated_partitions(dx, a1, a2, tab, data, offset, k_lo, n_rows, pi, pj, l_fu, l_fe, l_se):
    """Adds every pair's R_2B - R_2B,inf (as `_tabulated_kernel`, formed in scratch memory)
    into the dense partitions L_FU, L_FE, L_SE (`_add_partitions`)."""
    sc = np.empty((4, NDOF))
    w = np.empty(_TAB_NPT)
    d = np.empty(3)
    work = np.empty(FILL_SCRATCH)
    res = np.empty((2 * NDOF, 2 * NDOF))
    flat = res.reshape(-1)
    n = l_fu.shape[0] // 6
    fu, fe, se = l_fu.reshape(-1), l_fe.reshape(-1), l_se.reshape(-1)
    for p in range(dx.shape[0]):
        _interpolate(p, dx, a1, a2, tab, data, offset, k_lo, n_rows, sc, w, d)
        _fill_pair_columns(d, a1[p], a2[p], sc, res, work, False)
        _add_partitions(pi[p], pj[p], flat, fu, fe, se, n)


@numba.njit(cache=True)
def _scatter_partitions(pi, pj, blocks, l_fu, l_fe, l_se):
    """Adds each pair's 22x22 block blocks[p] into the dense partitions (`_add_partitions`)."""
    n = l_fu.shape[0] // 6
    fu, fe, se = l_fu.reshape(-1), l_fe.reshape(-1), l_se.reshape(-1)
    for p in range(pi.shape[0]):
        _add_partitions(pi[p], pj[p], blocks[p].reshape(-1), fu, fe, se, n)


@numba.njit(cache=True)
def _add_partitions(i, j, pair, fu, fe, se, n):
    """Adds a pair's 22x22 matrix (flattened, C order; rows and columns: i's 11 dofs, j's
    11 dofs) into the dense partitions L_FU (6N x 6N), L_FE (6N x 5N) and L_SE (5N x 5N),
    given flattened (C order), n = N. The indices are unsigned, so that numba adds no
    negative-index wraparound to every access."""
    u64 = numba.uint64
    for u in range(2):
        row = i if u == 0 else j
        for v in range(2):
            col = i if v == 0 else j
            r0, c0 = NDOF * u, NDOF * v
            for a in range(6):
                k_fu = u64((6 * row + a) * 6 * n + 6 * col)
                k_fe = u64((6 * row + a) * 5 * n + 5 * col)
                k_p = u64((r0 + a) * 2 * NDOF + c0)
                for b in range(6):
                    fu[k_fu + u64(b)] += pair[k_p + u64(b)]
                for b in range(5):
                    fe[k_fe + u64(b)] += pair[k_p + u64(6 + b)]
            for a in range(5):
                k_se = u64((5 * row + a) * 5 * n + 5 * col)
                k_p = u64((r0 + 6 + a) * 2 * NDOF + c0 + 6)
                for b in range(5):
                    se[k_se + u64(b)] += pair[k_p + u64(b)]


@numba.njit(cache=True)
def _tabulated_product(dx, a1, a2, tab, data, offset, k_lo, n_rows, pi, pj, v, rigid_columns, out):
    """out[(i, j)] += res_p (v_i, v_j) for every pair p = (pi[p], pj[p]), res_p its block
    R_2B - R_2B,inf at dx[p] (as `_tabulated_kernel`, in scratch memory); rigid_columns: v
    is zero on the strain dofs (their columns are neither formed nor used)."""
    sc = np.empty((4, NDOF))
    w = np.empty(_TAB_NPT)
    d = np.empty(3)
    work = np.empty(FILL_SCRATCH)
    res = np.empty((2 * NDOF, 2 * NDOF))
    acc = np.empty(2 * NDOF)
    ncol = 6 if rigid_columns else NDOF
    for p in range(dx.shape[0]):
        _interpolate(p, dx, a1, a2, tab, data, offset, k_lo, n_rows, sc, w, d)
        _fill_pair_columns(d, a1[p], a2[p], sc, res, work, rigid_columns)
        i, j = pi[p], pj[p]
        acc[:] = 0.0
        for b in range(ncol):
            vi, vj = v[i, b], v[j, b]
            for r in range(2 * NDOF):
                acc[r] += res[r, b] * vi + res[r, NDOF + b] * vj
        for a in range(NDOF):
            out[i, a] += acc[a]
            out[j, a] += acc[NDOF + a]


@numba.njit(cache=True)
def _add_pair(i, j, pair, out):
    """Adds a pair's 22x22 matrix into the blocks (i,i), (i,j), (j,i), (j,j) of out."""
    idx = (i, j)
    for u in range(2):
        for v in range(2):
            r0, c0 = NDOF * idx[u], NDOF * idx[v]
            for a in range(NDOF):
                for b in range(NDOF):
                    out[r0 + a, c0 + b] += pair[NDOF * u + a, NDOF * v + b]


@numba.njit(cache=True)
def scatter_pair_blocks(pi, pj, res, out):
    """Adds each pair's 22x22 matrix res[p] into out (see _add_pair)."""
    for p in range(pi.shape[0]):
        _add_pair(pi[p], pj[p], res[p], out)


@numba.njit(cache=True)
def _scatter_slots(s_ii, s_ij, s_ji, s_jj, res, data):
    """Adds each pair's four 11x11 blocks res[p] into the block slots data[s_..[p]]
    (slot -1: a block not held, skipped)."""
    for p in range(res.shape[0]):
        slots = ((s_ii[p], s_ij[p]), (s_ji[p], s_jj[p]))
        for u in range(2):
            for v in range(2):
                s = slots[u][v]
                if s < 0:
                    continue
                for a in range(NDOF):
                    for b in range(NDOF):
                        data[s, a, b] += res[p, NDOF * u + a, NDOF * v + b]
