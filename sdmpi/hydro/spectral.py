"""Matrix-free far-field grand mobility M_inf by spectral (particle-mesh) Ewald summation.

The same operator as `farfield.far_field_mobility` (Beenakker's splitting of the FTS
mobility on the Lees-Edwards lattice), applied to a vector in O(N log N):

    M_inf x = M_real x + M_wave x + M_self x.

Real space: the 11x11 pair blocks of `farfield._pair_block` within r_c, computed once per
configuration and applied as a sparse product (each pair image stored once, M_ji = M_ij^T).

Wave space (Lindbo & Tornberg, J. Comput. Phys. 229, 8994 (2010) and 230, 8744 (2011);
Fiore, Balboa Usabiaga, Donev & Swan, J. Chem. Phys. 146, 124116 (2017)): with the
normalised Gaussian window g(r) = (alpha/pi)^(3/2) exp(-alpha r^2), g^(k) = exp(-k^2/4alpha),
the reciprocal sum (1/V) sum_k R_i(k) J^(k) R_j(k)^H exp(i k.(x_i - x_j)) of `farfield`
(J^(k) = h(k)/k^2 (I - k k/k^2), h = (1 + k^2/4xi^2 + k^4/8xi^4) exp(-k^2/4xi^2)) is split as
[R_i g^] [J^/g^^2] [g^ R_j^H]. The source operators act on the window in real space,
giving one smooth force density on the grid,

    f(x) = sum_j F_j (1 + a_j^2/6 lap) g + (1/2) grad g x L_j - S_j.grad (1 + a_j^2/10 lap) g,

(g centred at x_j; S_j = sum_m x_m B^m from the five strain components), which is FFT'd,
multiplied by J^/g^^2 and transformed back to a velocity field u; the receivers are the
adjoint integrals U_i = int u (1 + a_i^2/6 lap) g, Omega_i = (1/2) int u x grad g,
E_i^m = -B^m : int u grad[(1 + a_i^2/10 lap) g] (Faxen laws, any radii). The grid is uniform
in lattice coordinates, so wave vectors are those of the sheared lattice at any strain;
the wave-space product W^T K W is symmetric to rounding (modes with |k| > k_max dropped).

Self terms: `farfield.self_mobility`. Units: viscosity 1, lengths as given.

Parallel (comm given): every rank spreads and interpolates a share of the particles; the
grid is summed on rank 0 (Reduce), which does the FFTs and sends the velocity grid back
(Bcast); the real-space pairs are shared so that rank 0's share plus its FFTs balances
the others' (`real_space_shares`), whose product they compute while rank 0 does the
FFTs; the 11N result is summed (Allreduce).

Speed: the window stencils of a configuration (wrapped grid indices, in-plane Gaussians,
z ranges and moments: `Stencils`) are computed once, not per product; spreading and
interpolation run along grid rows in z, over a grid padded along z by the window width,
so that no index wraps inside the loops (`_fold`, `_pad`); the grids and the FFT outputs
are kept between products (scipy's pocketfft backend, which takes output arrays); the
transforms run one axis at a time, along y and x only on the lines that hold modes with
|k| <= kmax (`_kept_modes`). Parameters, accuracy and measurements: docs/numerics.md,
"Spectral Ewald"; bench/bench_spectral.py times the parts.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
import scipy.fft
try:  # scipy.fft's backend (private): transforms into given arrays, no fresh allocations
    from scipy.fft._pocketfft import pypocketfft
except ImportError:  # a scipy without it: the public functions (same numbers, allocating)
    pypocketfft = None

from .basis import BASIS
from .farfield import (NDOF, _cached_radial_table, _pair_block, _power_bounds, _truncation_parameter,
                       self_mobility)
from .geometry import Lattice, find_pairs, image_cell, image_indices
from .workspace import work_array


@dataclass(frozen=True)
class SpectralParameters:
    """Ewald splitting xi, real-space cut-off rcut, wave-space cut-off kmax, Gaussian
    window exponent alpha (alpha = 2 xi^2/eta) and its truncation radius, grid shape."""

    xi: float
    rcut: float
    kmax: float
    alpha: float
    window: float
    grid: tuple

    @classmethod
    def choose(cls, lattice: Lattice, radii: np.ndarray, tol: float = 1e-4,
               xi: float | None = None) -> SpectralParameters:
        """Parameters for relative accuracy tol (radii: (N,) sphere radii). Each error
        source is kept below tol/(2 kappa), kappa = max(1, largest ratio of the Ewald
        wave-space self field to the isolated-sphere value (`self_mobility`, largest
        sphere)): the Ewald parts, and so their errors, grow like (xi a)^3 relative to
        the result. Estimates, with polynomial prefactors calibrated against the dense
        sum (tests/test_spectral.py): real space exp(-(xi rcut)^2) and wave-space
        truncation exp(-(kmax/2xi)^2), as `farfield.EwaldParameters`; window truncation
        exp(-alpha w^2); aliasing by the grid's shortest reciprocal translation K,
        exp(-eta (2 - eta) (K/4xi)^2) (its worst case, at |k| = eta K/2, weighted by the
        kernel). xi (by default set by the number density) balances real- and wave-space
        work; the window support in grid points does not depend on it.

        Args:
            lattice: the periodic lattice.
            radii: (N,) sphere radii a.
            tol: relative accuracy of M_inf x.
            xi: Ewald splitting parameter (1/length), or None (by the number density).

        Returns:
            The parameters (xi, rcut, kmax, alpha, window in units of length and
            1/length, grid points per lattice axis).
        """
        if xi is None:
            xi = _XI_DENSITY * (len(radii) / lattice.volume) ** (1 / 3)
        isolated = np.diag(self_mobility(radii.max()))
        tol = tol / (2 * max(1.0, np.max(1 - np.diag(self_mobility(radii.max(), xi)) / isolated)))
        rcut = _truncation_parameter(tol, 6) / xi
        kmax = 2 * xi * _truncation_parameter(tol, 6)
        alias = 4 * xi * _truncation_parameter(tol / 4, _POW_ALIAS) / math.sqrt(_ETA * (2 - _ETA))
        alpha = 2 * xi * xi / _ETA
        # grid: K = 2 pi M_i |b_i| >= alias, and every |k| <= kmax inside the index box with
        # the Nyquist planes excluded (|n_i| = |k.L_i|/2pi < M_i/2)
        need = np.maximum(alias / (2 * math.pi * np.linalg.norm(lattice.reciprocal, axis=1)),
                          2 * np.ceil(kmax * np.linalg.norm(lattice.vectors, axis=1) / (2 * math.pi)) + 2)
        grid = tuple(int(scipy.fft.next_fast_len(int(math.ceil(m)), real=True)) for m in need)
        window = _truncation_parameter(tol / 4, _POW_WINDOW) / math.sqrt(alpha)
        return cls(xi=float(xi), rcut=rcut, kmax=kmax, alpha=alpha, window=window, grid=grid)


_ETA = 0.4  # window width: g^(k) = exp(-k^2/4alpha) = exp(-eta k^2/8xi^2)
_XI_DENSITY = 1.45  # xi in units of the inverse mean spacing (N/V)^(1/3)
_POW_ALIAS, _POW_WINDOW = 4, 4  # powers of the polynomial prefactors


# ---------------------------------------------------------------------------------
# real space: sparse pair blocks
# ---------------------------------------------------------------------------------


#: Ewald tolerances from which the real-space blocks are stored, and the wave-space grids
#: spread, transformed and sent, in single precision (the product's rounding ~1e-7
#: relative, <= 1% of the tolerance; the sums over a particle's stencil and pairs run in
#: double): half the bytes to stream, transform and send make the product ~12% faster on
#: 2 ranks (docs/numerics.md)
SINGLE_PRECISION_TOL = 1e-5


@numba.njit(cache=True)
def _pair_blocks(pos, radii, pi, pj, images, cell, table, xi, basis, blocks):
    """blocks[p] = 11x11 real-space block of pair image p (receiver pi, source pj at
    separation x_pj + shift - x_pi), as in `farfield._real_space_sum`, computed in double
    precision and stored in blocks' precision. The shift n0 L1 + n1 L2 + n2 L3 from the
    image's lattice indices images[p] and `geometry.image_cell`'s numbers, formed as
    `geometry.find_pairs` forms it (the same bits)."""
    bounds = _power_bounds(table)
    work = np.empty(80)
    rvec = np.empty(3)
    block = np.empty((NDOF, NDOF))
    for p in range(pi.shape[0]):
        _image_block(pos, radii, pi[p], pj[p], images[p], cell, table, bounds, xi, basis, work, rvec, block)
        for a in range(NDOF):
            for b in range(NDOF):
                blocks[p, a, b] = block[a, b]


@numba.njit(cache=True, inline="always")
def _image_block(pos, radii, i, j, image, cell, table, bounds, xi, basis, work, rvec, block):
    """block = the 11x11 real-space block of the pair image (i, j) with lattice indices
    image at the positions pos: separation x_i - x_j - (n0 L1 + n1 L2 + n2 L3), the shift
    formed as `geometry.find_pairs` forms it (the same bits). rvec, work: scratch."""
    n0, n1, n2 = image[0], image[1], image[2]
    rvec[0] = pos[i, 0] - pos[j, 0] - (n0 * cell[0] + n1 * cell[3])
    rvec[1] = pos[i, 1] - pos[j, 1] - n1 * cell[1]
    rvec[2] = pos[i, 2] - pos[j, 2] - n2 * cell[2]
    block[:, :] = 0.0
    _pair_block(rvec, radii[i], radii[j], table, bounds, xi, basis, work, block)


@numba.njit(cache=True)
def _pairs_change_product(pos, moved, radii, pi, pj, images, cell, table, xi, basis, x, y):
    """y += sum over pair images of D_ij x_j + D_ij^T x_i, D_ij = M_ij(moved) - M_ij(pos):
    the change of the real-space product between two configurations with the same pair
    images, each block formed at both in double precision (not stored)."""
    bounds = _power_bounds(table)
    work = np.empty(80)
    rvec = np.empty(3)
    before = np.empty((NDOF, NDOF))
    after = np.empty((NDOF, NDOF))
    for p in range(pi.shape[0]):
        i, j = pi[p], pj[p]
        _image_block(pos, radii, i, j, images[p], cell, table, bounds, xi, basis, work, rvec, before)
        _image_block(moved, radii, i, j, images[p], cell, table, bounds, xi, basis, work, rvec, after)
        i0, j0 = NDOF * i, NDOF * j
        for a in range(NDOF):
            for c in range(NDOF):
                d = after[a, c] - before[a, c]
                y[i0 + a] += d * x[j0 + c]
                y[j0 + c] += d * x[i0 + a]


@numba.njit(cache=True, fastmath=True)
def _pairs_product(pi, pj, blocks, x, y):
    """y += sum over pair images of M_ij x_j + M_ij^T x_i (blocks[p] = M_ij). The two
    particles' parts of x and y go through local arrays: no aliasing of the slices (a pair
    image of a particle with itself has i = j), so the loops vectorise."""
    xi, xj = np.empty(NDOF), np.empty(NDOF)
    yi, yj = np.empty(NDOF), np.empty(NDOF)
    for p in range(pi.shape[0]):
        i0, j0 = NDOF * pi[p], NDOF * pj[p]
        b = blocks[p]
        for a in range(NDOF):
            xi[a], xj[a], yj[a] = x[i0 + a], x[j0 + a], 0.0
        for a in range(NDOF):
            acc, xa = 0.0, xi[a]
            for c in range(NDOF):
                acc += b[a, c] * xj[c]
                yj[c] += b[a, c] * xa
            yi[a] = acc
        for a in range(NDOF):
            y[i0 + a] += yi[a]
        for a in range(NDOF):
            y[j0 + a] += yj[a]


# ---------------------------------------------------------------------------------
# wave space: windows, spreading, interpolation
# ---------------------------------------------------------------------------------


@dataclass
class Stencils:
    """The separable parts of the window stencils of a set of particles, the grid points
    within the window reach of each (computed once per configuration, used by every
    product). For the i-th particle: grid indices idx[i, c, q] (wrapped into [0, M_c))
    along x and y (c = 0, 1); the first grid index zb[i] in [0, M3) along z, from which
    the window runs unwrapped (the grids are padded along z); offsets s0[i] from the
    particle to the first point, in grid steps; in-plane Gaussians
    e12[i, q1, q2] = exp(-alpha (dx^2 + dy^2)) of the (x, y) offsets; the range
    zr[i, q1, q2] = [lo, hi) of q3 within reach; z moments
    ez[i, k, q3] = z^k exp(-alpha z^2) (k = 0..3) of the z offsets. steps: rows
    e_i = L_i/M_i, with e_3 along z and e_1, e_2 in the x-y plane (the Lees-Edwards
    lattice). Memory: about 16 P^2 bytes per particle for P window points per axis
    (3 kB at tol 1e-4, P = 14)."""

    steps: np.ndarray
    idx: np.ndarray
    zb: np.ndarray
    s0: np.ndarray
    e12: np.ndarray
    zr: np.ndarray
    ez: np.ndarray

    @classmethod
    def build(cls, frac: np.ndarray, grid: tuple[int, int, int], steps: np.ndarray, half: np.ndarray,
              alpha: float, reach: float) -> Stencils:
        """Stencils of the particles at fractional coordinates frac (n, 3) on a grid of
        shape `grid`, window half-width half (grid steps per axis).

        Args:
            frac: (n, 3) fractional coordinates of the particles.
            grid: grid points (M1, M2, M3) per lattice axis.
            steps: (3, 3) rows e_i = L_i/M_i (length).
            half: (3,) window half-width in grid steps per axis.
            alpha: Gaussian window exponent (1/length^2).
            reach: window truncation radius (length).

        Returns:
            The stencils.
        """
        n, p = len(frac), int(2 * half.max()) + 1
        st = cls(steps, np.empty((n, 2, p), dtype=np.int64), np.empty(n, dtype=np.int64), np.empty((n, 3)),
                 np.zeros((n, p, p)), np.zeros((n, p, p, 2), dtype=np.int32), np.empty((n, 4, p)))
        _fill_stencils(frac, frac, np.array(grid), steps, half, alpha, reach, *st.arrays()[1:])
        return st

    def moved(self, frac: np.ndarray, anchor: np.ndarray, grid: tuple[int, int, int], half: np.ndarray,
              alpha: float, reach: float) -> Stencils:
        """The stencils of the same particles moved to frac (n, 3), on the grid points of
        these (built at the fractional coordinates anchor, with the same arguments): the
        window weights at the new offsets, the grid points and each row's range in reach
        kept, so that a product with them is a smooth function of the displacement (a
        particle moving across a grid plane or a point across the reach would change it
        by the window's truncation).

        Returns:
            The stencils at frac.
        """
        st = Stencils(self.steps, np.empty_like(self.idx), np.empty_like(self.zb), np.empty_like(self.s0),
                      np.zeros_like(self.e12), np.zeros_like(self.zr), np.empty_like(self.ez))
        _fill_stencils(frac, anchor, np.array(grid), self.steps, half, alpha, reach, *st.arrays()[1:])
        st.zr = self.zr
        return st

    @property
    def pad(self) -> int:
        """Points per axis of the largest stencil: the z pad of the grids."""
        return self.idx.shape[2]

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The arrays, in the order the kernels take them.

        Returns:
            (steps, idx, zb, s0, e12, zr, ez).
        """
        return self.steps, self.idx, self.zb, self.s0, self.e12, self.zr, self.ez


@numba.njit(cache=True)
def _fill_stencils(frac, anchor, m, steps, half, alpha, reach, idx, zb, s0, e12, zr, ez):
    """Fill the `Stencils` arrays of particles at fractional coordinates frac, their first
    grid points placed by the fractional coordinates anchor (frac itself, or those of
    `Stencils.moved`'s base)."""
    hz = steps[2, 2]
    for i in range(frac.shape[0]):
        for c in range(3):
            t = frac[i, c] * m[c]
            start = math.ceil(anchor[i, c] * m[c] - half[c])
            s0[i, c] = start - t
            if c < 2:
                for q in range(idx.shape[2]):
                    idx[i, c, q] = (start + q) % m[c]
            else:
                zb[i] = start % m[c]
        for q in range(idx.shape[2]):
            z = (s0[i, 2] + q) * hz
            ez[i, 0, q] = math.exp(-alpha * z * z)
            ez[i, 1, q] = ez[i, 0, q] * z
            ez[i, 2, q] = ez[i, 1, q] * z
            ez[i, 3, q] = ez[i, 2, q] * z
        for q1 in range(int(2 * half[0]) + 1):
            for q2 in range(int(2 * half[1]) + 1):
                dx, dy = _offset(s0[i], q1, q2, steps)
                e12[i, q1, q2] = math.exp(-alpha * (dx * dx + dy * dy))
                rem = reach * reach - dx * dx - dy * dy
                if rem > 0.0:
                    dz = math.sqrt(rem) / hz
                    zr[i, q1, q2, 0] = max(0, math.ceil(-dz - s0[i, 2]))
                    zr[i, q1, q2, 1] = min(int(2 * half[2]) + 1, math.floor(dz - s0[i, 2]) + 1)


@numba.njit(cache=True, inline="always")
def _offset(s0, q1, q2, steps):
    """In-plane offset (dx, dy) from a particle to its stencil point (q1, q2)."""
    return ((s0[0] + q1) * steps[0, 0] + (s0[1] + q2) * steps[1, 0],
            (s0[0] + q1) * steps[0, 1] + (s0[1] + q2) * steps[1, 1])


# The window weights of a sphere of radius a at offset d = (d0, d1, z), r2 = |d|^2, with
# g = (alpha/pi)^(3/2) exp(-alpha r2):
#   (1 + a^2/6 lap) g = g (A + B r2),  A = 1 - alpha a^2,  B = (2/3) alpha^2 a^2,
#   (1/2) grad g = -alpha g d,
#   grad (1 + a^2/10 lap) g = g (C + D r2) d,  C = -2 alpha + 2 alpha^2 a^2,  D = -(4/5) alpha^3 a^2.
# Along a grid row (fixed d0, d1) every weight is g times a cubic in z, so the sums below
# work with the z-moments of each row. The grids are (M1, M2, M3 + pad, 3), padded along
# z by the stencil width, so that every row of a window is one unwrapped range; `_fold`
# and `_padded` map between the padded and the periodic grid.


@numba.njit(cache=True, inline="always")
def _weight_coefficients(alpha, radius):
    """(A, B, C, D) of the window weights above."""
    a2 = radius * radius
    return (1 - alpha * a2, 2 / 3 * alpha * alpha * a2,
            -2 * alpha + 2 * alpha * alpha * a2, -0.8 * alpha ** 3 * a2)


@numba.njit(cache=True, fastmath=True)
def _spread(radii, order, x, alpha, basis, steps, idx, zb, s0, e12, zr, ez, grid):
    """grid (M1, M2, M3 + pad, 3) += force density f(x) of the generalized forces x (11N):
    f = F (1 + a^2/6 lap) g + (1/2) grad g x L - S.grad (1 + a^2/10 lap) g per particle
    order[i], whose stencil is the i-th."""
    norm = (alpha / math.pi) ** 1.5
    s = np.zeros((3, 3))
    for i in range(order.shape[0]):
        p = order[i]
        o = NDOF * p
        f0, f1, f2 = x[o], x[o + 1], x[o + 2]
        l0, l1, l2 = x[o + 3], x[o + 4], x[o + 5]
        for a in range(3):
            for b in range(3):
                s[a, b] = 0.0
                for n in range(5):
                    s[a, b] += x[o + 6 + n] * basis[n, a, b]
        wa, wb, wc, wd = _weight_coefficients(alpha, radii[p])
        e0, e1, e2, e3 = ez[i, 0], ez[i, 1], ez[i, 2], ez[i, 3]
        for q1 in range(e12.shape[1]):
            for q2 in range(e12.shape[2]):
                lo, hi = zr[i, q1, q2, 0], zr[i, q1, q2, 1]
                if lo >= hi:
                    continue
                d0, d1 = _offset(s0[i], q1, q2, steps)
                r12 = d0 * d0 + d1 * d1
                pu, pe = wa + wb * r12, wc + wd * r12
                g12 = norm * e12[i, q1, q2]
                # along the row f / exp(-alpha z^2) = c0 + c1 z + c2 z^2 + c3 z^3 per component
                # (x0..x3, y0..y3, z0..z3; scalars, so that the loop keeps them in registers)
                sx = -(s[0, 0] * d0 + s[0, 1] * d1)
                sy = -(s[1, 0] * d0 + s[1, 1] * d1)
                sz = -(s[2, 0] * d0 + s[2, 1] * d1)
                x0 = g12 * (pe * sx + f0 * pu - alpha * d1 * l2)
                y0 = g12 * (pe * sy + f1 * pu + alpha * d0 * l2)
                z0 = g12 * (pe * sz + f2 * pu - alpha * (d0 * l1 - d1 * l0))
                x1, y1, z1 = (g12 * (alpha * l1 - pe * s[0, 2]), -g12 * (alpha * l0 + pe * s[1, 2]),
                              -g12 * pe * s[2, 2])
                x2, y2, z2 = g12 * (wd * sx + f0 * wb), g12 * (wd * sy + f1 * wb), g12 * (wd * sz + f2 * wb)
                x3, y3, z3 = -g12 * wd * s[0, 2], -g12 * wd * s[1, 2], -g12 * wd * s[2, 2]
                row = grid[idx[i, 0, q1], idx[i, 1, q2], zb[i]:]
                for q3 in range(lo, hi):
                    a0, a1, a2, a3 = e0[q3], e1[q3], e2[q3], e3[q3]
                    row[q3, 0] += x0 * a0 + x1 * a1 + x2 * a2 + x3 * a3
                    row[q3, 1] += y0 * a0 + y1 * a1 + y2 * a2 + y3 * a3
                    row[q3, 2] += z0 * a0 + z1 * a1 + z2 * a2 + z3 * a3


@numba.njit(cache=True, fastmath=True)
def _interpolate(radii, order, grid, alpha, basis, steps, idx, zb, s0, e12, zr, ez, y):
    """y (11N) += (U, Omega, E) of particle order[i] (stencil i) from the velocity field u
    on the grid (M1, M2, M3 + pad, 3) (the adjoint of _spread): U = sum u (1 + a^2/6 lap) g,
    Omega = (1/2) sum u x grad g, E^m = -B^m : sum u grad (1 + a^2/10 lap) g."""
    norm = (alpha / math.pi) ** 1.5
    mom = np.empty((4, 3))  # row moments sum g z^k u_c
    u = np.empty(3)
    om = np.empty(3)
    tens = np.empty((3, 3))
    for i in range(order.shape[0]):
        p = order[i]
        wa, wb, wc, wd = _weight_coefficients(alpha, radii[p])
        u[:] = 0.0
        om[:] = 0.0
        tens[:, :] = 0.0
        e0, e1, e2, e3 = ez[i, 0], ez[i, 1], ez[i, 2], ez[i, 3]
        for q1 in range(e12.shape[1]):
            for q2 in range(e12.shape[2]):
                lo, hi = zr[i, q1, q2, 0], zr[i, q1, q2, 1]
                if lo >= hi:
                    continue
                row = grid[idx[i, 0, q1], idx[i, 1, q2], zb[i]:]
                m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = m30 = m31 = m32 = 0.0
                for q3 in range(lo, hi):
                    a0, a1, a2, a3 = e0[q3], e1[q3], e2[q3], e3[q3]
                    v0, v1, v2 = row[q3, 0], row[q3, 1], row[q3, 2]
                    m00 += a0 * v0
                    m01 += a0 * v1
                    m02 += a0 * v2
                    m10 += a1 * v0
                    m11 += a1 * v1
                    m12 += a1 * v2
                    m20 += a2 * v0
                    m21 += a2 * v1
                    m22 += a2 * v2
                    m30 += a3 * v0
                    m31 += a3 * v1
                    m32 += a3 * v2
                g12 = norm * e12[i, q1, q2]
                mom[0, 0], mom[0, 1], mom[0, 2] = g12 * m00, g12 * m01, g12 * m02
                mom[1, 0], mom[1, 1], mom[1, 2] = g12 * m10, g12 * m11, g12 * m12
                mom[2, 0], mom[2, 1], mom[2, 2] = g12 * m20, g12 * m21, g12 * m22
                mom[3, 0], mom[3, 1], mom[3, 2] = g12 * m30, g12 * m31, g12 * m32
                d0, d1 = _offset(s0[i], q1, q2, steps)
                r12 = d0 * d0 + d1 * d1
                pu, pe = wa + wb * r12, wc + wd * r12
                for c in range(3):
                    u[c] += pu * mom[0, c] + wb * mom[2, c]
                    grad = pe * mom[0, c] + wd * mom[2, c]
                    tens[c, 0] += grad * d0
                    tens[c, 1] += grad * d1
                    tens[c, 2] += pe * mom[1, c] + wd * mom[3, c]
                om[0] -= alpha * (mom[1, 1] - d1 * mom[0, 2])
                om[1] -= alpha * (d0 * mom[0, 2] - mom[1, 0])
                om[2] -= alpha * (d1 * mom[0, 0] - d0 * mom[0, 1])
        o = NDOF * p
        for c in range(3):
            y[o + c] += u[c]
            y[o + 3 + c] += om[c]
        for n in range(5):
            acc = 0.0
            for a in range(3):
                for b in range(3):
                    acc += basis[n, a, b] * tens[a, b]
            y[o + 6 + n] -= acc


def _fold(padded, m3):
    """Add the pads of a grid padded along z back into its periodic part [0, M3), in place."""
    for start in range(m3, padded.shape[2], m3):
        width = min(m3, padded.shape[2] - start)
        padded[:, :, :width] += padded[:, :, start:start + width]


def _pad(padded, m3):
    """Fill the pads of a grid padded along z from its periodic part [0, M3), in place."""
    for start in range(m3, padded.shape[2], m3):
        width = min(m3, padded.shape[2] - start)
        padded[:, :, start:start + width] = padded[:, :, :width]


@numba.njit(cache=True)
def _apply_kernel(fk, scale, recip):
    """fk (M1, M2, M3//2+1, 3) <- scale(k) (I - k k/k^2) fk, in place; k = 2 pi n.b."""
    m1, m2, mh = fk.shape[0], fk.shape[1], fk.shape[2]
    k = np.empty(3)
    for i1 in range(m1):
        n1 = i1 if 2 * i1 < m1 else i1 - m1
        for i2 in range(m2):
            n2 = i2 if 2 * i2 < m2 else i2 - m2
            for i3 in range(mh):
                sc = scale[i1, i2, i3]
                if sc == 0.0:
                    fk[i1, i2, i3, :] = 0.0
                    continue
                ksq = 0.0
                for c in range(3):
                    k[c] = 2 * math.pi * (n1 * recip[0, c] + n2 * recip[1, c] + i3 * recip[2, c])
                    ksq += k[c] * k[c]
                kf = (k[0] * fk[i1, i2, i3, 0] + k[1] * fk[i1, i2, i3, 1]
                      + k[2] * fk[i1, i2, i3, 2]) / ksq
                for c in range(3):
                    fk[i1, i2, i3, c] = sc * (fk[i1, i2, i3, c] - kf * k[c])


def _kernel_scale(lattice, par):
    """h(k)/k^2 / g^(k)^2 V/(M1 M2 M3)^2 on the rfft grid, zero at k = 0 and |k| > kmax.
    The last factor: 1/V of the reciprocal sum times the grid cell V/(M1 M2 M3) twice,
    the quadrature weight of the forward transform of the spread density and of the
    interpolation integrals (the inverse transform is unnormalised)."""
    m1, m2, m3 = par.grid
    n = np.meshgrid(np.fft.fftfreq(m1, 1 / m1), np.fft.fftfreq(m2, 1 / m2),
                    np.arange(m3 // 2 + 1), indexing="ij")
    k = 2 * math.pi * np.einsum("i...,ic->...c", np.array(n), lattice.reciprocal)
    ksq = np.einsum("...c,...c->...", k, k)
    u = ksq / (4 * par.xi ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = ((1 + u + 2 * u * u) * np.exp(-u + ksq / (2 * par.alpha))
                 * lattice.volume / (ksq * (m1 * m2 * m3) ** 2))
    scale[(ksq == 0) | (ksq > par.kmax ** 2)] = 0.0
    return scale


def _kept_modes(scale):
    """The index ranges of the rfft grid that hold every mode the kernel keeps (scale != 0,
    |k| <= kmax): (z slice, (y slices)), the non-negative z indices 0..n3 and the y
    indices -n2..n2 (two slices: 0..n2 and M2-n2..M2-1). Transforming along y only the z
    lines 0..n3, and along x only the lines in both ranges, gives the same modes as the
    full 3-D transform (and its inverse, whose input is zero outside) with fewer lines:
    the grid, set by the window's aliasing, reaches a little beyond 2 kmax L/2pi (N =
    1000: 43 of 50 y and 21 of 26 z indices kept; 10-15% less time)."""
    m2 = scale.shape[1]
    _, i2, i3 = np.nonzero(scale)
    if len(i3) == 0:  # no wave-space modes: nothing to transform along y and x
        return slice(0, 0), ()
    n2 = int(np.max(np.minimum(i2, m2 - i2)))
    y_kept = (slice(0, m2),) if 2 * n2 + 1 >= m2 else (slice(0, n2 + 1), slice(m2 - n2, m2))
    return slice(0, int(i3.max()) + 1), y_kept


# ---------------------------------------------------------------------------------
# the operator
# ---------------------------------------------------------------------------------


#: cost of the FFTs + k-space kernel per grid point, in units of the real-space product
#: per pair image, by the precision of blocks and grids (measured with
#: bench/bench_spectral.py and paired products on 2 ranks: docs/numerics.md)
_FFT_COST_PER_GRID_POINT = {np.float64: 0.4, np.float32: 0.3}


def real_space_shares(n_pairs: int, grid: tuple[int, int, int], size: int,
                      precision: type = np.float64) -> np.ndarray:
    """Pair images per rank (size ranks) such that rank 0's share plus its FFTs (cost
    _FFT_COST_PER_GRID_POINT[precision] per grid point) equals every other rank's share:
    with R the pair images and F the FFTs in pair units, r_k = (R + F)/size for k >= 1 and
    r_0 = r_k - F (none if negative). A fixed cost model, not a timing: the split, and so
    the rounding of the result, depends only on the configuration and the rank count.

    Args:
        n_pairs: the number of real-space pair images R.
        grid: grid points (M1, M2, M3).
        size: the number of ranks.
        precision: np.float64 or np.float32, that of the blocks and grids.

    Returns:
        (size,) int64 pair images per rank, summing to n_pairs.
    """
    fft = _FFT_COST_PER_GRID_POINT[precision] * float(np.prod(grid))
    first = int(round(min(n_pairs, max(0.0, (n_pairs + fft) / size - fft))))
    rest = np.diff(np.linspace(0, n_pairs - first, size).round().astype(np.int64))
    return np.concatenate([[first], rest])


def _check_inputs(positions, radii, lattice, tol, xi):
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] < 1:
        raise ValueError(f"positions must have shape (N, 3) with N >= 1, got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("positions must be finite")
    rad = np.asarray(radii, dtype=float)
    if rad.shape != (pos.shape[0],):
        raise ValueError(f"radii must have shape ({pos.shape[0]},) (one per particle), got {rad.shape}")
    if not np.all(np.isfinite(rad)) or np.any(rad <= 0):
        raise ValueError("radii must be finite and > 0")
    if not isinstance(lattice, Lattice):
        raise ValueError(f"lattice must be a geometry.Lattice (periodic box), got {type(lattice).__name__}")
    if not 1e-10 <= tol <= 0.1:
        raise ValueError(f"tol must be in [1e-10, 0.1], got {tol}")
    if xi is not None and not (np.isfinite(xi) and xi > 0):
        raise ValueError(f"xi must be finite and > 0 (or None for the default), got {xi}")
    return pos, rad


class SpectralFarField:
    """Matrix-free periodic M_inf for (wrapped) positions on a Lattice.

    matvec(x) maps the generalized forces x (11N: per particle F, L and the five strain
    components of the stresslet, in the convention of `farfield.far_field_mobility`) to
    M_inf x with relative error <= tol. comm (mpi4py communicator or None): matvec is
    collective and returns the full result on every rank. xi overrides the Ewald
    splitting parameter (by default set by the number density)."""

    def __init__(self, positions: np.ndarray, radii: np.ndarray, lattice: Lattice, tol: float = 1e-4,
                 comm: Any = None, *, xi: float | None = None) -> None:
        pos, rad = _check_inputs(positions, radii, lattice, tol, xi)
        self.n_particles = pos.shape[0]
        self.tol = float(tol)
        self.comm = comm
        rank, size = (0, 1) if comm is None else (comm.rank, comm.size)
        pos = lattice.wrap(pos)
        self.params = par = SpectralParameters.choose(lattice, rad, tol, xi)
        self._radii = rad.copy()  # own copy: the real-space blocks are computed again from it
        self._frac = pos @ lattice.reciprocal.T
        unique, which = np.unique(rad, return_inverse=True)
        self._self = np.array([np.diag(self_mobility(a, par.xi)) for a in unique])[which].ravel()
        # wave space: every rank spreads and interpolates a share of the particles (in
        # grid-cell order, contiguous in space), rank 0 does the FFTs
        # half-width of the window in grid steps along each axis (plane spacing 1/(M_i |b_i|))
        half = par.window * np.array(par.grid) * np.linalg.norm(lattice.reciprocal, axis=1)
        cells = np.floor(self._frac * np.array(par.grid) / 4).astype(np.int64)
        self._order = np.array_split(np.lexsort(cells.T[::-1]), size)[rank]
        steps = lattice.vectors / np.array(par.grid)[:, None]
        self._stencils = Stencils.build(self._frac[self._order], par.grid, steps, half, par.alpha, par.window)
        self._half, self._reciprocal = half, lattice.reciprocal
        if rank == 0:
            self._scale = _kernel_scale(lattice, par)
            self._recip = lattice.reciprocal
            self._kept = _kept_modes(self._scale)
        # real space: pair images on one rank, else shared so that every rank's real-space
        # work plus rank 0's FFTs balance (real_space_shares)
        self._precision = np.float32 if tol >= SINGLE_PRECISION_TOL else np.float64
        pi, pj, shift = find_pairs(pos, rad, lattice, par.rcut, 0.0)
        if size > 1:
            shares = real_space_shares(len(pi), par.grid, size, self._precision)
            bounds = np.cumsum(np.concatenate([[0], shares]))
            pi, pj, shift = (a[bounds[rank]:bounds[rank + 1]] for a in (pi, pj, shift))
        # 32-bit copies (not views of all ranks' images): the product streams them with the blocks
        self._pi, self._pj = pi.astype(np.int32), pj.astype(np.int32)
        # to compute the blocks again: the wrapped positions (a fresh array) and the pair
        # images' lattice indices (int8, 3 bytes an image; geometry.image_indices)
        self._positions, self._images, self._cell = pos, image_indices(shift, lattice), image_cell(lattice)
        self._blocks = self._computed_blocks()

    def _computed_blocks(self) -> np.ndarray:
        """The 11 x 11 real-space blocks of this rank's pair images (P, 11, 11), in single
        precision from `SINGLE_PRECISION_TOL` on."""
        blocks = np.empty((len(self._pi), NDOF, NDOF), dtype=self._precision)
        xi = self.params.xi
        _pair_blocks(self._positions, self._radii, self._pi, self._pj, self._images, self._cell,
                     _cached_radial_table(xi), xi, BASIS, blocks)
        return blocks

    def release_real_space(self) -> None:
        """Frees the real-space blocks (484 bytes a pair image in single precision, the
        largest part of the operator); the next product computes them again, the same
        bits. For an operator that waits while another is built and used (the start of a
        Brownian step during its midpoint)."""
        self._blocks = None

    def work_grids(self, precision: type | None = None) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """The work grids of a product, in the operator's precision (single from
        `SINGLE_PRECISION_TOL` on) unless precision (np.float64) says otherwise: the grid padded along z for spreading and
        interpolation (M1, M2, M3 + pad, 3); with several ranks a contiguous copy of its
        periodic part for MPI (M1, M2, M3, 3), else None; on the rank that does the FFTs
        their output (M1, M2, M3//2 + 1, 3) complex, else None. Views of this thread's
        `workspace.work_array` buffers, shared by all operators of this process (one
        product at a time: the step's start and its midpoint hold one set of grids, not
        two) and kept between products (fresh pages, also of the FFT outputs, cost more
        than the transforms); their contents are overwritten by every product.

        Returns:
            (padded grid, MPI grid or None, FFT output or None).
        """
        m1, m2, m3 = self.params.grid
        real = self._precision if precision is None else precision
        padded = work_array("spectral_padded_grid", (m1, m2, m3 + self._stencils.pad, 3), real)
        parallel = self.comm is not None and self.comm.size > 1
        grid = work_array("spectral_grid", (m1, m2, m3, 3), real) if parallel else None
        fk = None
        if self.comm is None or self.comm.rank == 0:
            fk = work_array("spectral_fft", (*self._scale.shape, 6), real).view(np.result_type(real, 1j))
        return padded, grid, fk

    def real_space(self, x: np.ndarray, y: np.ndarray) -> None:
        """y += this rank's share of the real-space product.

        Args:
            x: (11N,) generalized forces (F, L, S per sphere).
            y: (11N,) generalized velocities (U, Omega, E), added to in place.
        """
        if self._blocks is None:
            self._blocks = self._computed_blocks()
        _pairs_product(self._pi, self._pj, self._blocks, x, y)

    def wave_space(self, x: np.ndarray, y: np.ndarray, meanwhile: Callable[[], Any] | None = None,
                   stencils: Stencils | None = None, precision: type | None = None) -> None:
        """y += the wave-space product at this rank's particles (collective over comm).
        meanwhile: local work (a callable, this rank's real-space share) that ranks 1.. do
        while rank 0 does the FFTs, and rank 0 after them.

        Args:
            x: (11N,) generalized forces (F, L, S per sphere).
            y: (11N,) generalized velocities (U, Omega, E), added to in place.
            meanwhile: local work to overlap with the FFTs, or None.
            stencils: this rank's particles' stencils (None: those of the configuration).
            precision: of the grids (None: the operator's, `work_grids`).
        """
        par = self.params
        st = self._stencils if stencils is None else stencils
        parallel = self.comm is not None and self.comm.size > 1
        (padded, contiguous, fk), m3 = self.work_grids(precision), par.grid[2]
        padded.fill(0.0)
        _spread(self._radii, self._order, x, par.alpha, BASIS, *st.arrays(), padded)
        _fold(padded, m3)
        grid = padded[:, :, :m3]  # the periodic grid, a view
        if parallel:
            from mpi4py import MPI

            contiguous[...] = grid  # contiguous, for MPI
            grid = contiguous
            self.comm.Reduce(MPI.IN_PLACE if self.comm.rank == 0 else grid, grid, op=MPI.SUM, root=0)
        if self.comm is None or self.comm.rank == 0:
            self._velocity_grid(grid, fk)
        if meanwhile is not None:
            meanwhile()
        if parallel:
            self.comm.Bcast(grid, root=0)
            padded[:, :, :m3] = grid
        _pad(padded, m3)
        _interpolate(self._radii, self._order, padded, par.alpha, BASIS, *st.arrays(), y)

    def _velocity_grid(self, grid, fk):
        """Rank 0: grid (M1, M2, M3, 3), the force density <- the velocity field, by FFT,
        k-space kernel and inverse FFT; fk: the FFT output (`work_grids`)."""
        if pypocketfft is None:  # unnormalised both ways, as below
            fk = scipy.fft.rfftn(grid, axes=(0, 1, 2))
            _apply_kernel(fk, self._scale, self._recip)
            grid[...] = scipy.fft.irfftn(fk, s=grid.shape[:3], axes=(0, 1, 2), norm="forward")
            return
        # one axis at a time, each along the lines the kept modes need (`_kept_modes`); the
        # c2c transforms in place on views of the FFT output
        z_kept, y_kept = self._kept
        pypocketfft.r2c(grid, axes=(2,), forward=True, out=fk)
        lines = fk[:, :, z_kept]
        pypocketfft.c2c(lines, axes=(1,), forward=True, out=lines)
        for part in y_kept:
            lines = fk[:, part, z_kept]
            pypocketfft.c2c(lines, axes=(0,), forward=True, out=lines)
        _apply_kernel(fk, self._scale, self._recip)  # zero outside |k| <= kmax, so also the
        for part in y_kept:                         # lines not transformed back
            lines = fk[:, part, z_kept]
            pypocketfft.c2c(lines, axes=(0,), forward=False, out=lines)
        lines = fk[:, :, z_kept]
        pypocketfft.c2c(lines, axes=(1,), forward=False, out=lines)
        pypocketfft.c2r(fk, axes=(2,), lastsize=grid.shape[2], forward=False, out=grid)

    def change(self, displacement: np.ndarray, x: np.ndarray) -> np.ndarray:
        """[M_inf(positions + displacement) - M_inf] x (11N,) for a small displacement
        (N, 3), with this configuration's pair images and window grid points
        (`Stencils.moved`), so that the result is a smooth function of the displacement
        and carries the Ewald truncation of the change, not of M_inf (the random finite
        difference of `krylov.KrylovSolver.mobility_change`). Both products are formed in
        double precision whatever the operator's (a change ~1e-6 of M_inf x would drown in
        single-precision rounding); the real-space blocks of both configurations are formed
        pair by pair and not stored. The self blocks do not change. Collective over comm.

        Args:
            displacement: (N, 3) displacement of the sphere centres (length unit of the radii).
            x: (11N,) generalized forces (F, L, S per sphere).

        Returns:
            (11N,) the change of the generalized velocities, on every rank.
        """
        x = np.ascontiguousarray(x, dtype=float)
        par = self.params
        moved_frac = self._frac + np.asarray(displacement, dtype=float) @ self._reciprocal.T
        moved = self._stencils.moved(moved_frac[self._order], self._frac[self._order], par.grid, self._half,
                                     par.alpha, par.window)
        y, before = np.zeros_like(x), np.zeros_like(x)
        self.wave_space(x, y, stencils=moved, precision=np.float64)
        self.wave_space(x, before, precision=np.float64)
        y -= before
        xi = par.xi
        _pairs_change_product(self._positions, self._positions + displacement, self._radii, self._pi, self._pj,
                              self._images, self._cell, _cached_radial_table(xi), xi, BASIS, x, y)
        if self.comm is not None and self.comm.size > 1:
            from mpi4py import MPI

            self.comm.Allreduce(MPI.IN_PLACE, y, op=MPI.SUM)
        return y

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M_inf x for x of shape (11N,); collective over comm.

        Args:
            x: (11N,) generalized forces (F, L, S per sphere; viscosity 1).

        Returns:
            (11N,) generalized velocities (U, Omega, E), on every rank.

        Raises:
            ValueError: x has the wrong shape.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != (NDOF * self.n_particles,):
            raise ValueError(f"x must have shape ({NDOF * self.n_particles},) (11 per particle), "
                             f"got {x.shape}")
        x = np.ascontiguousarray(x)
        y = np.zeros_like(x)
        self.wave_space(x, y, meanwhile=lambda: self.real_space(x, y))
        if self.comm is None or self.comm.rank == 0:
            y += self._self * x
        if self.comm is not None and self.comm.size > 1:
            from mpi4py import MPI

            self.comm.Allreduce(MPI.IN_PLACE, y, op=MPI.SUM)
        return y
