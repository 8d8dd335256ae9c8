"""Periodic boxes with Lees-Edwards shear, as a deformed lattice.

Axes: flow x, gradient y, vorticity z. A box (Lx, Ly, Lz) at strain gamma has the
lattice vectors L1 = (Lx, 0, 0), L2 = (gamma Ly, Ly, 0), L3 = (0, 0, Lz): the image
at +Ly is shifted in x by gamma Ly (Lees & Edwards 1972). The lattice is unchanged by
gamma -> gamma + Lx/Ly, so the strain is reduced to |gamma| <= Lx/(2 Ly) before use;
this keeps the lattice vectors short and makes every result periodic in the strain.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np


def check_box(box: np.ndarray | None) -> np.ndarray | None:
    """Validate a box argument: None, or three finite positive lengths.

    Args:
        box: (3,) sides (Lx, Ly, Lz) (length unit of the radii), or None (unbounded fluid).

    Returns:
        The sides as a (3,) float array, or None.

    Raises:
        ValueError: wrong shape, or a side not finite and > 0.
    """
    if box is None:
        return None
    box = np.asarray(box, dtype=float)
    if box.shape != (3,):
        raise ValueError(f"box must have shape (3,) (Lx, Ly, Lz) or be None, got shape {box.shape}")
    if not all(math.isfinite(length) and length > 0 for length in box.tolist()):
        raise ValueError(f"box lengths must be finite and > 0, got {box.tolist()}")
    return box


class Lattice:
    """The periodic lattice of a box (Lx, Ly, Lz) sheared by Lees-Edwards strain."""

    def __init__(self, box: np.ndarray, strain: float = 0.0) -> None:
        box = check_box(box)
        strain = float(strain)
        if not math.isfinite(strain):
            raise ValueError(f"strain must be finite, got {strain}")
        lx, ly, lz = box.tolist()
        period = lx / ly
        self.box = box
        self.strain = strain - round(strain / period) * period  # round half to even
        #: rows are the lattice vectors L1, L2, L3
        self.vectors = np.array([[lx, 0.0, 0.0], [self.strain * ly, ly, 0.0], [0.0, 0.0, lz]])
        #: rows b_i with b_i . L_j = delta_ij (reciprocal vectors without the 2 pi)
        self.reciprocal = np.array([[1 / lx, -self.strain / lx, 0.0], [0.0, 1 / ly, 0.0], [0.0, 0.0, 1 / lz]])
        self.volume = float(lx * ly * lz)

    @functools.cached_property
    def plane_density(self) -> np.ndarray:
        """|b_i| (3,): the inverse spacings of the lattice planes (1/length)."""
        return np.linalg.norm(self.reciprocal, axis=1)

    def wrap(self, positions: np.ndarray) -> np.ndarray:
        """Map positions into the primary (sheared) cell, fractional coords in [0, 1).

        Args:
            positions: (..., 3) positions (length unit of the box).

        Returns:
            (..., 3) the lattice images of the positions in the primary cell.
        """
        frac = positions @ self.reciprocal.T
        frac -= np.floor(frac)
        return frac @ self.vectors

    def nearest_image(self, displacements: np.ndarray) -> np.ndarray:
        """The lattice image of each displacement (..., 3) with fractional coordinates in
        [-1/2, 1/2]: the displacement itself whenever |d . b_i| < 1/2 for every reciprocal
        vector b_i, i.e. when it is shorter than half the distance between each pair of
        opposite cell faces (used to unwrap positions between nearby times).

        Args:
            displacements: (..., 3) displacements (length unit of the box).

        Returns:
            (..., 3) the nearest lattice images of the displacements.
        """
        frac = displacements @ self.reciprocal.T
        frac -= np.round(frac)
        return frac @ self.vectors

    @property
    def wave_basis(self) -> np.ndarray:
        """The rows 2 pi b_i (3, 3) (1/length): the reciprocal lattice is
        k = n . wave_basis, n integer."""
        return 2 * np.pi * self.reciprocal

    def wave_vectors(self, kmax: float) -> tuple[np.ndarray, np.ndarray]:
        """Reciprocal lattice vectors k = 2 pi n . b with 0 < |k| <= kmax, one of each
        +-k pair (the sums below use that the terms at -k are complex conjugates), and
        their integer coordinates n: (k (nk, 3), n (nk, 3) int).

        Args:
            kmax: largest wave number |k| (1/length).

        Returns:
            k: (nk, 3) wave vectors (1/length), in lexicographic order of n.
            n: (nk, 3) int64 integer coordinates of k.
        """
        counts = np.ceil(kmax * np.linalg.norm(self.vectors, axis=1) / (2 * np.pi)).astype(np.int64)
        size = int(np.prod(2 * counts + 1)) // 2
        out, index = np.empty((size, 3)), np.empty((size, 3), dtype=np.int64)
        count = _wave_vectors(counts, self.wave_basis, float(kmax), out, index)
        return out[:count], index[:count]


@numba.njit(cache=True)
def _wave_vectors(counts, recip, kmax, out, index):
    """Fills out with k = n . recip (and index with n) for the integer n, |n_c| <= counts[c],
    in the half space (first non-zero n_c positive) with |k| <= kmax, in lexicographic
    order of n; returns how many."""
    count = 0
    for n0 in range(-counts[0], counts[0] + 1):
        for n1 in range(-counts[1], counts[1] + 1):
            for n2 in range(-counts[2], counts[2] + 1):
                first = n0 if n0 != 0 else (n1 if n1 != 0 else n2)
                if first <= 0:
                    continue
                k0 = n0 * recip[0, 0] + n1 * recip[1, 0] + n2 * recip[2, 0]
                k1 = n0 * recip[0, 1] + n1 * recip[1, 1] + n2 * recip[2, 1]
                k2 = n0 * recip[0, 2] + n1 * recip[1, 2] + n2 * recip[2, 2]
                if k0 * k0 + k1 * k1 + k2 * k2 <= kmax * kmax:
                    out[count, 0], out[count, 1], out[count, 2] = k0, k1, k2
                    index[count, 0], index[count, 1], index[count, 2] = n0, n1, n2
                    count += 1
    return count


@numba.njit(cache=True)
def _image_range(d0, reach, length, periodic):
    """(lo, hi): the integers n with |d0 + n length| < reach lie in [lo, hi] (0 alone if
    not periodic)."""
    if not periodic:
        return 0, 0
    return math.ceil((-reach - d0) / length), math.floor((reach - d0) / length)


@numba.njit(cache=True, inline="always")
def _record(count, i, j, n0, n1, n2, cell, out_i, out_j, out_s):
    """Stores pair `count` (i, j, shift n0 L1 + n1 L2 + n2 L3; cell as in _scan_pairs) if
    the outputs have room; returns count + 1."""
    if count < out_i.shape[0]:
        out_i[count], out_j[count] = i, j
        out_s[count, 0] = n0 * cell[0] + n1 * cell[3]
        out_s[count, 1] = n1 * cell[1]
        out_s[count, 2] = n2 * cell[2]
    return count + 1


@numba.njit(cache=True)
def _scan_pairs(pos, radii, cell, periodic, reach_abs, reach_rel, out_i, out_j, out_s):
    """Fills (up to their length) the pairs (i <= j) and lattice translations
    n0 L1 + n1 L2 + n2 L3 with |x_j + shift - x_i| < reach_abs + reach_rel (a_i + a_j);
    returns how many there are. cell = (Lx, Ly, Lz, gamma Ly): L3 is along z and L2 has
    no z part, so the admissible n2, then n1, then n0 follow from the z, y and x
    separations in turn (no image is tested in vain). Self-images (i == j) keep one of
    each +-n pair (the first non-zero of n2, n1, n0 positive)."""
    lx, ly, lz, tilt = cell[0], cell[1], cell[2], cell[3]
    n = pos.shape[0]
    count = 0
    for i in range(n):
        for j in range(i, n):
            reach = reach_abs + reach_rel * (radii[i] + radii[j])
            r2 = reach * reach
            dx0 = pos[j, 0] - pos[i, 0]
            dy0 = pos[j, 1] - pos[i, 1]
            dz0 = pos[j, 2] - pos[i, 2]
            lo2, hi2 = _image_range(dz0, reach, lz, periodic)
            for n2 in range(lo2, hi2 + 1):
                dz = dz0 + n2 * lz
                rem_z = r2 - dz * dz
                if rem_z <= 0.0:
                    continue
                lo1, hi1 = _image_range(dy0, math.sqrt(rem_z), ly, periodic)
                for n1 in range(lo1, hi1 + 1):
                    dy = dy0 + n1 * ly
                    rem_y = rem_z - dy * dy
                    if rem_y <= 0.0:
                        continue
                    dxy = dx0 + n1 * tilt
                    lo0, hi0 = _image_range(dxy, math.sqrt(rem_y), lx, periodic)
                    for n0 in range(lo0, hi0 + 1):
                        dx = dxy + n0 * lx
                        if dx * dx >= rem_y:
                            continue
                        if i == j and not (n2 > 0 or (n2 == 0 and (n1 > 0 or (n1 == 0 and n0 > 0)))):
                            continue
                        count = _record(count, i, j, n0, n1, n2, cell, out_i, out_j, out_s)
    return count


@numba.njit(cache=True)
def _scan_pairs_cells(pos, radii, cell, counts, reach_abs, reach_rel, out_i, out_j, out_s):
    """_scan_pairs (same arguments, periodic) with a cell list: counts (3,) cells per
    lattice axis, each at least the largest reach wide (plane spacing) and >= 3 of them,
    so that a pair within reach has exactly one image within reach, the nearest one, and
    lies in neighbouring cells. The pairs come in cell order (the caller sorts them);
    each is tested with the arithmetic of _scan_pairs, so both find the same pairs."""
    lx, ly, lz, tilt = cell[0], cell[1], cell[2], cell[3]
    m0, m1, m2 = counts[0], counts[1], counts[2]
    n = pos.shape[0]
    head = np.full(m0 * m1 * m2, -1, dtype=np.int64)
    nxt = np.empty(n, dtype=np.int64)
    home = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        # lattice coordinates ((x - tilt y/Ly)/Lx, y/Ly, z/Lz), wrapped into [0, 1)
        frac = ((pos[i, 0] - tilt * pos[i, 1] / ly) / lx, pos[i, 1] / ly, pos[i, 2] / lz)
        key = 0
        for c in range(3):
            f = frac[c] - math.floor(frac[c])
            home[i, c] = min(int(f * counts[c]), counts[c] - 1)
            key = key * counts[c] + home[i, c]
        nxt[i] = head[key]
        head[key] = i
    count = 0
    for i in range(n):
        for d0 in range(-1, 2):
            for d1 in range(-1, 2):
                for d2 in range(-1, 2):
                    key = (((home[i, 0] + d0) % m0) * m1 + (home[i, 1] + d1) % m1) * m2 + (home[i, 2] + d2) % m2
                    j = head[key]
                    while j >= 0:
                        if j > i:
                            reach = reach_abs + reach_rel * (radii[i] + radii[j])
                            dx0 = pos[j, 0] - pos[i, 0]
                            dy0 = pos[j, 1] - pos[i, 1]
                            dz0 = pos[j, 2] - pos[i, 2]
                            n2 = -round(dz0 / lz)
                            n1 = -round(dy0 / ly)
                            dxy = dx0 + n1 * tilt
                            n0 = -round(dxy / lx)
                            dz = dz0 + n2 * lz
                            rem_z = reach * reach - dz * dz
                            dy = dy0 + n1 * ly
                            rem_y = rem_z - dy * dy
                            dx = dxy + n0 * lx
                            if rem_z > 0.0 and rem_y > 0.0 and dx * dx < rem_y:
                                count = _record(count, i, j, n0, n1, n2, cell, out_i, out_j, out_s)
                        j = nxt[j]
    return count


def _cell_counts(lattice, reach):
    """Cells per lattice axis for _scan_pairs_cells: the plane spacings 1/|b_i| over the
    reach, floored; None when a cell list does not apply (fewer than 3 along an axis)."""
    counts = np.floor(1.0 / (lattice.plane_density * reach)).astype(np.int64)
    return counts if counts.min() >= 3 else None


def _expected_pairs(n, lattice, reach):
    """A room for find_pairs' outputs: in a periodic box ~10% more than the mean count of
    pair images within reach, N(N+1)/2 x (4 pi/3) reach^3/V (images of a pair included),
    so that one scan usually suffices (with 16 N, the pair search for the spectral real
    space at N = 1000 scanned twice); in unbounded fluid every pair (N(N-1)/2) for an
    infinite reach, else 16 N (a second scan finds the count if more)."""
    if lattice is None:
        return max(16, n * (n - 1) // 2) if math.isinf(reach) else 16 * n
    mean = 0.5 * n * (n + 1) * 4.0 * math.pi / 3.0 * reach ** 3 / lattice.volume
    return int(1.1 * mean) + 16 * n


def pairs_in_reach(positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None, reach_abs: float,
                   reach_rel: float, candidates: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], float] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`find_pairs`, or, when candidates = (images, reach) holds a `find_pairs` list of
    these positions and lattice to an absolute reach covering this one, that list filtered
    (`pairs_within`): one search serves several reaches.

    Args:
        positions, radii, lattice, reach_abs, reach_rel: as for `find_pairs`.
        candidates: (images, reach) of an earlier `find_pairs` at absolute reach `reach`
            (length), or None.

    Returns:
        (i, j, shift) as `find_pairs` returns them.
    """
    if candidates is not None and candidates[1] >= reach_abs + 2.0 * reach_rel * float(np.max(radii)):
        return pairs_within(candidates[0], positions, radii, reach_abs, reach_rel)
    return find_pairs(positions, radii, lattice, reach_abs, reach_rel)


def pairs_within(images: tuple[np.ndarray, np.ndarray, np.ndarray], positions: np.ndarray, radii: np.ndarray,
                 reach_abs: float, reach_rel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The images (i, j, shift) of a `find_pairs` list of a larger reach (same positions and
    lattice) that lie within reach_abs + reach_rel (a_i + a_j), in their order: a second
    pair search at a shorter reach without scanning again.

    Args:
        images: (i (P,), j (P,), shift (P, 3)) of a `find_pairs` list.
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii.
        reach_abs: absolute part of the reach (length).
        reach_rel: part of the reach per sum of radii a_i + a_j (dimensionless).

    Returns:
        (i (Q,), j (Q,), shift (Q, 3)): the images within reach, in their order.
    """
    return _within(np.ascontiguousarray(positions, dtype=float), np.ascontiguousarray(radii, dtype=float),
                   *images, float(reach_abs), float(reach_rel))


@numba.njit(cache=True)
def _within(pos, radii, pi, pj, shift, reach_abs, reach_rel):
    """The images p with |x_j + shift - x_i| < reach_abs + reach_rel (a_i + a_j), in order:
    (i, j, shift) arrays."""
    keep = np.empty(pi.shape[0], dtype=np.bool_)
    count = 0
    for p in range(pi.shape[0]):
        i, j = pi[p], pj[p]
        r2 = 0.0
        for c in range(3):
            d = pos[j, c] + shift[p, c] - pos[i, c]
            r2 += d * d
        reach = reach_abs + reach_rel * (radii[i] + radii[j])
        keep[p] = r2 < reach * reach
        count += keep[p]
    out_i, out_j, out_s = np.empty(count, np.int64), np.empty(count, np.int64), np.empty((count, 3))
    q = 0
    for p in range(pi.shape[0]):
        if keep[p]:
            out_i[q], out_j[q] = pi[p], pj[p]
            out_s[q, 0], out_s[q, 1], out_s[q, 2] = shift[p, 0], shift[p, 1], shift[p, 2]
            q += 1
    return out_i, out_j, out_s


def image_cell(lattice: Lattice) -> np.ndarray:
    """(Lx, Ly, Lz, strain Ly): the numbers from which `find_pairs` forms a pair image's
    shift n0 L1 + n1 L2 + n2 L3 = (n0 Lx + n1 strain Ly, n1 Ly, n2 Lz) (`_record`).

    Args:
        lattice: the periodic lattice.

    Returns:
        (4,) the cell numbers (length).
    """
    lx, ly, lz = lattice.box
    return np.array([lx, ly, lz, lattice.strain * ly])


def image_indices(shift: np.ndarray, lattice: Lattice) -> np.ndarray:
    """The lattice indices (n0, n1, n2) of `find_pairs`'s shifts (P, 3), as int8: the shift
    formed again from them and `image_cell` with `_record`'s arithmetic has the same bits
    (3 bytes a pair image to keep instead of 24).

    Args:
        shift: (P, 3) shifts of pair images (length), from find_pairs on lattice.
        lattice: the periodic lattice.

    Returns:
        (P, 3) int8 lattice indices.

    Raises:
        ValueError: an index outside int8's range (a cut-off of more than ~127 boxes).
    """
    cell = image_cell(lattice)
    n1 = np.rint(shift[:, 1] / cell[1])
    n = np.stack([np.rint((shift[:, 0] - n1 * cell[3]) / cell[0]), n1, np.rint(shift[:, 2] / cell[2])], axis=1)
    if n.size and np.abs(n).max() > np.iinfo(np.int8).max:
        raise ValueError(f"pair images up to {int(np.abs(n).max())} boxes away: more than int8 holds")
    return n.astype(np.int8)


def find_pairs(positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None, reach_abs: float,
               reach_rel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (i <= j) and lattice images within reach_abs + reach_rel (a_i + a_j):
    arrays i, j and shift vectors (so that the separation is x_j + shift - x_i), ordered
    by i, then j. With lattice None (unbounded fluid) only the zero shift is used.
    Self-images appear once per +-n pair. Large periodic boxes (>= 3 cells of the largest
    reach per axis) are scanned with a cell list, O(N), others pair by pair, O(N^2).

    Args:
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii.
        lattice: the periodic lattice, or None (unbounded fluid).
        reach_abs: absolute part of the reach (length).
        reach_rel: part of the reach per sum of radii a_i + a_j (dimensionless).

    Returns:
        i: (P,) int64 first sphere of each pair image.
        j: (P,) int64 second sphere (i <= j).
        shift: (P, 3) lattice translations (length): the separation is x_j + shift - x_i.
    """
    pos = np.ascontiguousarray(positions, dtype=float)
    radii = np.ascontiguousarray(radii, dtype=float)
    reach = float(reach_abs) + 2.0 * float(reach_rel) * (float(radii.max()) if len(radii) else 0.0)
    if lattice is None:
        cell, periodic, counts = np.ones(4), False, None
    else:
        cell, periodic = image_cell(lattice), True
        counts = _cell_counts(lattice, reach) if reach > 0 else None
    size = _expected_pairs(len(pos), lattice, reach)
    while True:  # a second scan only if the estimate was short
        i, j = np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int64)
        s = np.empty((size, 3))
        if counts is None:
            count = _scan_pairs(pos, radii, cell, periodic, float(reach_abs), float(reach_rel), i, j, s)
        else:
            count = _scan_pairs_cells(pos, radii, cell, counts, float(reach_abs), float(reach_rel), i, j, s)
        if count <= size:
            break
        size = count
    i, j, s = i[:count], j[:count], s[:count]
    if counts is not None:
        order = np.lexsort((j, i))
        i, j, s = i[order], j[order], s[order]
    return i, j, s
