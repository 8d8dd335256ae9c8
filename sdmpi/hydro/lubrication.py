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
the mean radius, as in seed 001's minimum-separation rule), so R stays finite and
positive definite; such pairs are counted.
"""

from dataclasses import dataclass

import numba
import numpy as np

from .basis import BASIS
from .farfield import _LEVI, NDOF, _pair_block, _power_bounds, radial_table, self_mobility
from .geometry import find_pairs
from .two_sphere import pair_resistance

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
    def distance(self):
        """True centre distances (before regularisation)."""
        return self.gap + self.radii_sum

    @property
    def min_gap(self):
        """Smallest surface gap (negative for an overlap), inf without pairs."""
        return float(self.gap.min()) if len(self.gap) else np.inf


def close_pairs(positions, radii, lattice=None, cutoff=DEFAULT_CUTOFF, min_gap=DEFAULT_MIN_GAP, images=None):
    """All pairs (with periodic images when a lattice is given) within the cut-off, or
    the given images (i, j, shift) re-evaluated at these positions (so that a slightly
    displaced configuration keeps the same pair set). Separations are regularised to the
    minimum gap and counted."""
    if images is None:
        images = find_pairs(positions, radii, lattice, 0.0, 1.0 + 0.5 * cutoff)
    i, j, shift = images
    dx = positions[j] + shift - positions[i]
    if len(i) == 0:
        return PairList(i, j, dx, shift, np.zeros(0), 0, np.zeros(0))
    r = np.linalg.norm(dx, axis=1)
    asum = radii[i] + radii[j]
    gap = r - asum
    floor = 0.5 * min_gap * asum
    short = gap < floor
    dx[short] *= ((asum[short] + floor[short]) / r[short])[:, None]
    return PairList(i, j, dx, shift, gap, int(short.sum()), asum)


@numba.njit(cache=True)
def _subtract_far_field(dx, a1, a2, self1, self2, table, basis, levi, res):
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
        _pair_block(rvec, a1[p], a2[p], table, bounds, 0.0, basis, levi, work, block)
        mob[:NDOF, :NDOF] = self1[p]
        mob[NDOF:, NDOF:] = self2[p]
        mob[:NDOF, NDOF:] = block
        mob[NDOF:, :NDOF] = block.T
        res[p] -= np.linalg.inv(mob)


def lubrication_matrix(positions, radii, pairs):
    """The (11N, 11N) near-field correction: the sum over the close pairs (a PairList
    from `close_pairs`) of R_2B - R_2B,inf."""
    n = positions.shape[0]
    out = np.zeros((NDOF * n, NDOF * n))
    if len(pairs.i) == 0:
        return out
    a1, a2 = radii[pairs.i], radii[pairs.j]
    res = pair_resistance(pairs.dx, a1, a2)
    selfs = {a: self_mobility(a) for a in np.unique(radii)}
    self1 = np.stack([selfs[a] for a in a1])
    self2 = np.stack([selfs[a] for a in a2])
    _subtract_far_field(pairs.dx, a1, a2, self1, self2, radial_table(0.0), BASIS, _LEVI, res)
    _scatter_pairs(pairs.i, pairs.j, res, out)
    return out


@numba.njit(cache=True)
def _scatter_pairs(pi, pj, res, out):
    """Adds each pair's 22x22 matrix into the blocks (i,i), (i,j), (j,i), (j,j)."""
    for p in range(pi.shape[0]):
        idx = (pi[p], pj[p])
        for u in range(2):
            for v in range(2):
                r0, c0 = NDOF * idx[u], NDOF * idx[v]
                for a in range(NDOF):
                    for b in range(NDOF):
                        out[r0 + a, c0 + b] += res[p, NDOF * u + a, NDOF * v + b]
