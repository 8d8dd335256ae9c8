"""Far-field grand mobility M_inf at the force-torque-stresslet (FTS) level.

Unbounded fluid: Durlofsky, Brady & Bossis, J. Fluid Mech. 180, 21 (1987) (DBB), with the
Faxen laws of unequal spheres. Periodic, Lees-Edwards-sheared box: Beenakker's Ewald
splitting, J. Chem. Phys. 85, 1581 (1986), as used for SD by Brady, Phillips, Lester &
Bossis, J. Fluid Mech. 195, 257 (1988), on the deformed lattice of `geometry.Lattice`.

Construction (viscosity 1). Every coupling is a pair of differential operators applied
to the biharmonic scalar chi(r) = r/(8 pi), whose Oseen tensor is
J = (I lap - grad grad) chi. The source operators of sphere j (radius a_j) are the
force F: (1 + a_j^2/6 lap) J F; the torque L: force density curl(L delta)/2; the
stresslet: force density -S.grad(delta) with (1 + a_j^2/10 lap). The receiver operators
of sphere i are their adjoints: U = (1 + a_i^2/6 lap) u, Omega = curl(u)/2,
E = (1 + a_i^2/10 lap) sym grad u. This reproduces DBB's far-field (Rotne-Prager-level)
mobility, and, being a Gram form, is symmetric positive semi-definite by construction.

Generalized vectors (the sdmpi sign convention, shared with `two_sphere`): the mobility
maps (F, L, -S) -> (U - U_inf, Omega - Omega_inf, -E_inf), with F, L the force and
torque a particle exerts on the fluid, S its stresslet, and strain-type 3x3 tensors
stored as 5-vectors in `basis.BASIS`. Per particle 11 rows: 3 U, 3 Omega, 5 E.

Ewald sum (Hasimoto 1959 / Beenakker 1986): chi = chi_r + chi_k with
chi_k^(k) = -h(k)/k^4, h = (1 + k^2/4xi^2 + k^4/8xi^4) exp(-k^2/4xi^2); in real space
this gives exactly chi_r = r erfc(xi r)/(8 pi). The real-space part is summed over pairs
and lattice images within r_c, the reciprocal part over k != 0 within k_c (k = 0
omitted: zero-volume-flux frame), and the self terms are the isolated-sphere values
minus the k-space field at r = 0. Truncation errors fall like exp(-(xi r_c)^2) and
exp(-(k_c/2xi)^2); `EwaldParameters.choose` picks xi, r_c, k_c for a requested accuracy.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy.special import gamma as gamma_function

from .basis import BASIS
from .geometry import Lattice, find_pairs, pairs_in_reach
from .workspace import work_array

NDOF = 11  # generalized velocity components per particle: 3 U, 3 Omega, 5 E
#: default relative accuracy of the Ewald sums (every entry point)
DEFAULT_EWALD_TOL = 1e-6


# ---------------------------------------------------------------------------------
# radial functions  f(r) = erfc(xi r) sum_n c_n r^n + exp(-xi^2 r^2) sum_n d_n r^n
# ---------------------------------------------------------------------------------

_P0 = 12  # array index of the power r^0
_NPOW = 28  # powers r^-12 .. r^15


class RadialFunction:
    """f(r) = erfc(xi r) sum c_n r^n + exp(-xi^2 r^2) sum d_n r^n, closed under d/dr.

    xi = 0 gives plain Laurent polynomials (the unbounded-fluid kernels)."""

    def __init__(self, xi: float, erfc_coeffs: np.ndarray, exp_coeffs: np.ndarray) -> None:
        self.xi = xi
        self.c = np.asarray(erfc_coeffs, dtype=float)
        self.d = np.asarray(exp_coeffs, dtype=float)

    def derivative(self) -> RadialFunction:
        """f'(r), of the same form.

        Returns:
            The derivative d f/dr.

        Raises:
            ArithmeticError: a power leaves the range r^-12 .. r^15.
        """
        xi = self.xi
        n = np.arange(_NPOW) - _P0
        c, d = np.zeros(_NPOW), np.zeros(_NPOW)
        c[:-1] += (n * self.c)[1:]  # n c_n r^(n-1) erfc
        d += -2 * xi / math.sqrt(math.pi) * self.c  # c_n r^n d/dr erfc(xi r)
        d[:-1] += (n * self.d)[1:]  # n d_n r^(n-1) exp
        d[1:] += (-2 * xi * xi * self.d)[:-1]  # -2 xi^2 d_n r^(n+1) exp
        if abs(c[0]) + abs(d[0]) + abs(c[-1]) + abs(d[-1]) > 0:
            raise ArithmeticError("radial function powers out of range")
        return RadialFunction(xi, c, d)

    def laplacian(self) -> RadialFunction:
        """f'' + 2 f'/r (the Laplacian of a radial function, r > 0).

        Returns:
            The Laplacian, of the same form.
        """
        first = self.derivative()
        second = first.derivative()
        c, d = second.c.copy(), second.d.copy()
        c[:-1] += 2 * first.c[1:]
        d[:-1] += 2 * first.d[1:]
        return RadialFunction(self.xi, c, d)

    def __call__(self, r: np.ndarray | float) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        powers = r[..., None] ** (np.arange(_NPOW) - _P0)
        erfc = np.vectorize(math.erfc)(self.xi * r)
        return erfc * (powers @ self.c) + np.exp(-((self.xi * r) ** 2)) * (powers @ self.d)


def radial_table(xi: float) -> np.ndarray:
    """T[p, m] = coefficients (2, NPOW) of d^m/dr^m of phi_p = lap^p chi_r,
    p = 0..3, m = 0..5, with chi_r = r erfc(xi r)/(8 pi). The kernels use m <= 4;
    m = 5 is the slope of m = 4 for the interpolation grid.

    Args:
        xi: Ewald splitting parameter (1/length; 0: unbounded fluid).

    Returns:
        (4, 6, 2, NPOW) coefficients of the erfc and exp parts, powers r^-12 .. r^15.
    """
    c = np.zeros(_NPOW)
    c[_P0 + 1] = 1.0 / (8 * math.pi)
    phi = RadialFunction(xi, c, np.zeros(_NPOW))
    table = np.zeros((4, 6, 2, _NPOW))
    for p in range(4):
        f = phi
        for m in range(6):
            table[p, m, 0], table[p, m, 1] = f.c, f.d
            f = f.derivative()
        phi = phi.laplacian()
    return table


# ---------------------------------------------------------------------------------
# real-space pair kernel (numba)
# ---------------------------------------------------------------------------------



@numba.njit(cache=True)
def _power_bounds(table):
    """[lo, hi) index range of the non-zero powers of each (p, m) entry of the table."""
    bounds = np.zeros((4, table.shape[1], 2), dtype=np.int64)
    for p in range(4):
        for m in range(table.shape[1]):
            lo, hi = table.shape[3], 0
            for n in range(table.shape[3]):
                if table[p, m, 0, n] != 0.0 or table[p, m, 1, n] != 0.0:
                    lo = min(lo, n)
                    hi = n + 1
            bounds[p, m, 0], bounds[p, m, 1] = lo, max(hi, lo)
    return bounds


@numba.njit(cache=True)
def _radial_values(table, bounds, xi, r, pw, out):
    """out[p, m] = d^m phi_p / dr^m at r for m < out.shape[1] (bounds from
    _power_bounds(table); pw is a work array of length NPOW)."""
    erfc = math.erfc(xi * r)
    gauss = math.exp(-xi * xi * r * r)
    npow = table.shape[3]
    pw[_P0] = 1.0
    for n in range(_P0 + 1, npow):
        pw[n] = pw[n - 1] * r
    inv = 1.0 / r
    for n in range(_P0 - 1, -1, -1):
        pw[n] = pw[n + 1] * inv
    for p in range(4):
        for m in range(out.shape[1]):
            sc = 0.0
            sd = 0.0
            for n in range(bounds[p, m, 0], bounds[p, m, 1]):
                sc += table[p, m, 0, n] * pw[n]
                sd += table[p, m, 1, n] * pw[n]
            out[p, m] = erfc * sc + gauss * sd


@numba.njit(cache=True)
def _fill_radial_grid(table, xi, r0, h, grid):
    """grid[g, p, m] = d^m phi_p/dr^m at r = r0 + g h, m = 0..5."""
    bounds = _power_bounds(table)
    pw = np.empty(_NPOW)
    for g in range(grid.shape[0]):
        _radial_values(table, bounds, xi, r0 + g * h, pw, grid[g])


@numba.njit(cache=True)
def _radial_lookup(grid, r0, h, table, bounds, xi, r, pw, out):
    """out[p, m] (m <= 4) as _radial_values, by cubic Hermite interpolation on the grid
    (values and their r-derivatives, the next m); exact evaluation off the grid."""
    s = (r - r0) / h
    g = int(math.floor(s))
    if g < 0 or g + 1 >= grid.shape[0]:
        _radial_values(table, bounds, xi, r, pw, out)
        return
    t = s - g
    t2 = t * t
    c00 = (2 * t - 3) * t2 + 1
    c10 = ((t - 2) * t + 1) * t * h
    c01 = (3 - 2 * t) * t2
    c11 = (t - 1) * t2 * h
    for p in range(4):
        for m in range(5):
            out[p, m] = (c00 * grid[g, p, m] + c10 * grid[g, p, m + 1]
                         + c01 * grid[g + 1, p, m] + c11 * grid[g + 1, p, m + 1])


@numba.njit(cache=True)
def _pair_block(rvec, ai, aj, table, bounds, xi, basis, work, out):
    """11x11 real-space block coupling receiver sphere i to source sphere j at
    rvec = x_i - x_j (plus a lattice translation); adds into out. work: (80,) scratch."""
    r = math.sqrt(rvec[0] ** 2 + rvec[1] ** 2 + rvec[2] ** 2)
    v = work[3:23].reshape((4, 5))
    _radial_values(table, bounds, xi, r, work[23:23 + _NPOW], v)
    _block_from_radial(rvec, r, v, ai, aj, basis, work[0:3], work[51:66].reshape((5, 3)), work[66:71], out)


#: 1/sqrt(2), 1/sqrt(6): the non-zero entries of the strain basis `basis.BASIS`
_ISQ2 = 1.0 / math.sqrt(2.0)
_ISQ6 = 1.0 / math.sqrt(6.0)


@numba.njit(cache=True)
def _stresslet_coefficients(v, ir, alpha, beta):
    """(c1, c2, h): the U-S and Omega-S couplings of a receiver sphere (Faxen coefficient
    alpha = a^2/6) to a source sphere's stresslet column W = sum_n w_n B^n (beta = a^2/10)
    at r = x_receiver - x_source, e = r/|r|, from the radial values
    v[p, m] = d^m/dr^m lap^p chi_r at r (ir = 1/r):
      U     = (grad^3 Gamma - I.grad lap Gamma) : W = c2 W e + c1 (e.W.e) e,
              Gamma = (1 + alpha lap)(1 + beta lap) chi_r,
              c1 = G3 - 3 G2/r + 3 G1/r^2,  c2 = 2 (G2/r - G1/r^2) - (lap Gamma)_1,
      Omega = -h e x (W e),  h = (1/2) (P2 - P1/r),  Phi = (1 + beta lap) lap chi_r,
    with G_m, P_m, (.)_m the m-th r-derivatives of Gamma, Phi, (.). The E-F and E-L
    couplings are these transposed with the spheres exchanged (M_ji = M_ij^T, DBB 1987)."""
    ir2 = ir * ir
    t1, t2 = alpha + beta, alpha * beta
    g1 = v[1, 1] + t1 * v[2, 1] + t2 * v[3, 1]
    f1 = v[0, 1] + t1 * v[1, 1] + t2 * v[2, 1]
    f2 = v[0, 2] + t1 * v[1, 2] + t2 * v[2, 2]
    f3 = v[0, 3] + t1 * v[1, 3] + t2 * v[2, 3]
    c1 = f3 - 3 * f2 * ir + 3 * f1 * ir2
    c2 = 2 * (f2 * ir - f1 * ir2) - g1
    h = 0.5 * (v[1, 2] + beta * v[2, 2] - (v[1, 1] + beta * v[2, 1]) * ir)
    return c1, c2, h


@numba.njit(cache=True)
def _strain_coefficients(v, ir, u1, u2):
    """(d, c_w, c_i): the E-S coupling of two spheres (beta sums u1 = b_i + b_j,
    u2 = b_i b_j, b = a^2/10) from the radial values v[p, m] = d^m/dr^m lap^p chi_r at r
    (ir = 1/r), DBB 1987:
      -A2[L1] w - B2[L1] I + D1[L0] q q + 4 D2[L0] w + 2 D3[L0] I
        = c_w (B^m e).(B^n e) + d q_m q_n + c_i delta_mn,   q_m = e.B^m.e,
    with F = (1 + b_i lap)(1 + b_j lap) chi_r, H = lap F and F_m, H_m their r-derivatives:
      d = F4 - 6 F3/r + 15 F2/r^2 - 15 F1/r^3,
      c_w = 4 (F3/r - 3 F2/r^2 + 3 F1/r^3) - (H2 - H1/r),
      c_i = 2 (F2/r^2 - F1/r^3) - H1/r."""
    ir2 = ir * ir
    ir3 = ir2 * ir
    h1 = v[1, 1] + u1 * v[2, 1] + u2 * v[3, 1]
    h2 = v[1, 2] + u1 * v[2, 2] + u2 * v[3, 2]
    f1 = v[0, 1] + u1 * v[1, 1] + u2 * v[2, 1]
    f2 = v[0, 2] + u1 * v[1, 2] + u2 * v[2, 2]
    f3 = v[0, 3] + u1 * v[1, 3] + u2 * v[2, 3]
    f4 = v[0, 4] + u1 * v[1, 4] + u2 * v[2, 4]
    d = f4 - 6 * f3 * ir + 15 * f2 * ir2 - 15 * f1 * ir3
    c_w = 4 * (f3 * ir - 3 * f2 * ir2 + 3 * f1 * ir3) - (h2 - h1 * ir)
    c_i = 2 * (f2 * ir2 - f1 * ir3) - h1 * ir
    return d, c_w, c_i


@numba.njit(cache=True)
def _block_from_radial(rvec, r, v, ai, aj, basis, e, be, q, out):
    """The 11x11 block of `_pair_block` from the radial values v[p, m] at r = |rvec|
    (e (3,), be (5, 3), q (5,): scratch, passed in so that a loop over images makes no
    array views per image); adds into out. The strain basis is `basis.BASIS` (its sparse
    entries are used explicitly: B^m e and e.B^m.e below)."""
    ir = 1.0 / r
    e0, e1, e2 = rvec[0] / r, rvec[1] / r, rvec[2] / r
    al_i, al_j = ai * ai / 6.0, aj * aj / 6.0
    be_i, be_j = ai * ai / 10.0, aj * aj / 10.0
    v01, v02, v10, v11, v12 = v[0, 1], v[0, 2], v[1, 0], v[1, 1], v[1, 2]
    v20, v21, v22, v30 = v[2, 0], v[2, 1], v[2, 2], v[3, 0]

    # UF: I lap Psi0 - grad grad Psi0,  Psi0 = (1 + al_i lap)(1 + al_j lap) chi_r
    s1, s2 = al_i + al_j, al_i * al_j
    psi1 = v10 + s1 * v20 + s2 * v30
    d1 = v01 + s1 * v11 + s2 * v21
    d2 = v02 + s1 * v12 + s2 * v22
    a2 = d2 - d1 * ir
    diag = psi1 - d1 * ir
    e00, e01, e02, e11, e12, e22 = e0 * e0, e0 * e1, e0 * e2, e1 * e1, e1 * e2, e2 * e2
    out[0, 0] += diag - a2 * e00
    out[1, 1] += diag - a2 * e11
    out[2, 2] += diag - a2 * e22
    t = a2 * e01
    out[0, 1] -= t
    out[1, 0] -= t
    t = a2 * e02
    out[0, 2] -= t
    out[2, 0] -= t
    t = a2 * e12
    out[1, 2] -= t
    out[2, 1] -= t

    # UL and Omega-F: (1/2) eps grad (lap chi_r + al lap^2 chi_r) = (1/2) f' [e]x
    f_ul = 0.5 * (v11 + al_i * v21)
    f_of = 0.5 * (v11 + al_j * v21)
    for side in range(2):
        f = f_ul if side == 0 else f_of
        r0, c0 = (0, 3) if side == 0 else (3, 0)
        out[r0 + 0, c0 + 1] -= f * e2
        out[r0 + 0, c0 + 2] += f * e1
        out[r0 + 1, c0 + 0] += f * e2
        out[r0 + 1, c0 + 2] -= f * e0
        out[r0 + 2, c0 + 0] -= f * e1
        out[r0 + 2, c0 + 1] += f * e0

    # Omega-L: (1/4)(grad grad lap chi_r - I lap^2 chi_r)
    a2 = 0.25 * (v12 - v11 * ir)
    diag = 0.25 * (v11 * ir - v20)
    out[3, 3] += diag + a2 * e00
    out[4, 4] += diag + a2 * e11
    out[5, 5] += diag + a2 * e22
    t = a2 * e01
    out[3, 4] += t
    out[4, 3] += t
    t = a2 * e02
    out[3, 5] += t
    out[5, 3] += t
    t = a2 * e12
    out[4, 5] += t
    out[5, 4] += t

    # B^n . e and e . B^n . e (basis.BASIS: B^1 = (xx - yy)/sqrt2, B^2 = (2zz - xx - yy)/sqrt6,
    # B^3, B^4, B^5 = (xy + yx, xz + zx, yz + zy)/sqrt2)
    be[0, 0], be[0, 1], be[0, 2] = _ISQ2 * e0, -_ISQ2 * e1, 0.0
    be[1, 0], be[1, 1], be[1, 2] = -_ISQ6 * e0, -_ISQ6 * e1, 2.0 * _ISQ6 * e2
    be[2, 0], be[2, 1], be[2, 2] = _ISQ2 * e1, _ISQ2 * e0, 0.0
    be[3, 0], be[3, 1], be[3, 2] = _ISQ2 * e2, 0.0, _ISQ2 * e0
    be[4, 0], be[4, 1], be[4, 2] = 0.0, _ISQ2 * e2, _ISQ2 * e1
    for n in range(5):
        q[n] = e0 * be[n, 0] + e1 * be[n, 1] + e2 * be[n, 2]

    # U-S and Omega-S: `_stresslet_coefficients` of (alpha, beta) = (al_i, be_j); E-F and E-L:
    # theirs with the spheres exchanged, (al_j, be_i), transposed (the same when a_i = a_j)
    equal = ai == aj
    c1a, c2a, ha = _stresslet_coefficients(v, ir, al_i, be_j)
    if equal:
        c1b, c2b, hb = c1a, c2a, ha
    else:
        c1b, c2b, hb = _stresslet_coefficients(v, ir, al_j, be_i)
    # U-S and E-F:  c2 B e + c1 (e.B.e) e
    for side in range(1 if equal else 2):
        c1, c2 = (c1a, c2a) if side == 0 else (c1b, c2b)
        for n in range(5):
            cq = c1 * q[n]
            x0 = c2 * be[n, 0] + cq * e0
            x1 = c2 * be[n, 1] + cq * e1
            x2 = c2 * be[n, 2] + cq * e2
            if side == 0:
                out[0, 6 + n] += x0
                out[1, 6 + n] += x1
                out[2, 6 + n] += x2
            if side == 1 or equal:
                out[6 + n, 0] -= x0
                out[6 + n, 1] -= x1
                out[6 + n, 2] -= x2

    # Omega-S and E-L:  -h (e x B e)
    for side in range(1 if equal else 2):
        h = ha if side == 0 else hb
        for n in range(5):
            x0 = h * (e1 * be[n, 2] - e2 * be[n, 1])  # h (e x B e)
            x1 = h * (e2 * be[n, 0] - e0 * be[n, 2])
            x2 = h * (e0 * be[n, 1] - e1 * be[n, 0])
            if side == 0:
                out[3, 6 + n] -= x0
                out[4, 6 + n] -= x1
                out[5, 6 + n] -= x2
            if side == 1 or equal:
                out[6 + n, 3] -= x0
                out[6 + n, 4] -= x1
                out[6 + n, 5] -= x2

    # E-S: -A2[L1] w - B2[L1] I + D1[L0] q q + 4 D2[L0] w + 2 D3[L0] I, w = (B^m e).(B^n e)
    dd1, cw, cd = _strain_coefficients(v, ir, be_i + be_j, be_i * be_j)
    for m in range(5):
        bm0, bm1, bm2, dq = be[m, 0], be[m, 1], be[m, 2], dd1 * q[m]
        out[6 + m, 6 + m] += cw * (bm0 * bm0 + bm1 * bm1 + bm2 * bm2) + dq * q[m] + cd
        for n in range(m + 1, 5):
            x = cw * (bm0 * be[n, 0] + bm1 * be[n, 1] + bm2 * be[n, 2]) + dq * q[n]
            out[6 + m, 6 + n] += x
            out[6 + n, 6 + m] += x


@numba.njit(cache=True)
def _real_space_sum(pos, radii, pi, pj, shift, table, grid, grid_r0, grid_h, xi, basis, mob, both=True):
    """Adds the real-space Ewald sum over the pair images (pi, pj, shift) (or, with
    xi = 0 and zero shifts, the unbounded pair couplings) into the (11N, 11N) matrix mob.
    Radial values come from the interpolation grid (see RadialGrid) where it covers r.
    Each image pair is stored once: M_ji = M_ij^T (reciprocity) fills the other
    triangle, and for a self-image (i == j) adds the -n image; with both False the blocks
    M_ji of pairs i < j are left out (`_mirror_lower_blocks` fills them afterwards).
    Consecutive images of the same pair (find_pairs lists them together) are summed before
    being added to mob."""
    bounds = _power_bounds(table)
    pw, e, be, q = np.empty(_NPOW), np.empty(3), np.empty((5, 3)), np.empty(5)
    v = np.empty((4, 5))
    block = np.zeros((NDOF, NDOF))
    rvec = np.empty(3)
    n_img = pi.shape[0]
    for p in range(n_img):
        i, j = pi[p], pj[p]
        for c in range(3):
            rvec[c] = pos[i, c] - pos[j, c] - shift[p, c]
        r = math.sqrt(rvec[0] ** 2 + rvec[1] ** 2 + rvec[2] ** 2)
        _radial_lookup(grid, grid_r0, grid_h, table, bounds, xi, r, pw, v)
        _block_from_radial(rvec, r, v, radii[i], radii[j], basis, e, be, q, block)
        if p + 1 < n_img and pi[p + 1] == i and pj[p + 1] == j:
            continue
        for a in range(NDOF):
            for b in range(NDOF):
                mob[NDOF * i + a, NDOF * j + b] += block[a, b]
        if both or i == j:
            for a in range(NDOF):
                for b in range(NDOF):
                    mob[NDOF * j + b, NDOF * i + a] += block[a, b]
        block[:, :] = 0.0


@numba.njit(cache=True)
def _source_moments(w, wt, k, e0, e1, e2):
    """(g, s, e.F, e.L, e x L) of the source particle k along the unit vector e: g = W e and
    s = e.W.e with W = wt[k] its strain tensor (xx, yy, zz, xy, xz, yz), F = w[k, 0:3] its
    force and L = w[k, 3:6] its torque; g and e x L as components."""
    lx, ly, lz = w[k, 3], w[k, 4], w[k, 5]
    gx = wt[k, 0] * e0 + wt[k, 3] * e1 + wt[k, 4] * e2
    gy = wt[k, 3] * e0 + wt[k, 1] * e1 + wt[k, 5] * e2
    gz = wt[k, 4] * e0 + wt[k, 5] * e1 + wt[k, 2] * e2
    s = e0 * gx + e1 * gy + e2 * gz
    ef = e0 * w[k, 0] + e1 * w[k, 1] + e2 * w[k, 2]
    el = e0 * lx + e1 * ly + e2 * lz
    cx, cy, cz = e1 * lz - e2 * ly, e2 * lx - e0 * lz, e0 * ly - e1 * lx
    return gx, gy, gz, s, ef, el, cx, cy, cz


#: a zero symmetric tensor in the layout of `_add_symmetric_outer`
_ZERO_SYMMETRIC = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@numba.njit(cache=True)
def _add_symmetric_outer(acc, e0, e1, e2, p0, p1, p2):
    """acc + (e P^T + P e^T) for acc a 6-tuple (xx, yy, zz, xy, xz, yz), the diagonal
    halved (e_a P_a)."""
    return (acc[0] + e0 * p0, acc[1] + e1 * p1, acc[2] + e2 * p2,
            acc[3] + (e0 * p1 + e1 * p0), acc[4] + (e0 * p2 + e2 * p0), acc[5] + (e1 * p2 + e2 * p1))


@numba.njit(cache=True)
def _real_space_product(pos, radii, pi, pj, shift, table, grid, grid_r0, grid_h, xi, basis, w, out):
    """Adds M_r w into out (N, 11) for w (N, 11): the real-space sum of `_real_space_sum`
    (same images, radial values and coefficients as `_block_from_radial`, DBB 1987) applied
    to the vectors in tensor form, without forming the 11x11 blocks.

    For an image at r = x_i - x_j - shift, e = r/|r|, and the source's force F, torque L
    and strain tensor W = sum_n S_n B^n (formed once per particle), g = W e, s = e.W.e,
    the block M_ij adds to the receiver i
      U     += d_F F + f_ul e x L + c2 g + (c1 s - a_F e.F) e          (UF, UL, US),
      Omega += d_L L + a_L (e.L) e + e x (f_of F - h g)               (Omega-L, -F, -S),
      E_m   += c_d S_m + B^m : (e P^T),
               P = -c2' F + h' e x L + c_w g + (d_1 s - c1' e.F) e     (EF, EL, ES),
    since sum_n S_n B^n e = g, sum_n S_n q_n = s (q_n = e.B^n.e), (B^m e).P = B^m : (e P^T)
    and B^m : W = S_m. (c1, c2) are the U-S coefficients of (a_i^2/6, a_j^2/10), (c1', c2')
    the E-F ones of (a_i^2/10, a_j^2/6), h (a_j^2/10) and h' (a_i^2/10) those of Omega-S and
    E-L (`_stresslet_coefficients`); for equal radii each primed coefficient equals the
    unprimed one. M_ji = M_ij^T adds the same to particle j with e -> -e and the radii
    exchanged (the odd terms change sign); a self-image (i = j) adds both, its +-n pair.
    Both directions take their source's g, s, e.F, e.L, e x L from `_source_moments`.
    sym(e P^T) is gathered per particle (`_add_symmetric_outer`) and projected on the basis
    at the end; the e-independent d_F, d_L, c_d of a pair's consecutive images are summed
    before being applied."""
    bounds = _power_bounds(table)
    pw = np.empty(_NPOW)
    v = np.empty((4, 5))
    n = w.shape[0]
    # W = sum_n S_n B^n as (xx, yy, zz, xy, xz, yz); tacc: e P^T + P e^T, same order
    ta = (0, 1, 2, 0, 0, 1)
    tb = (0, 1, 2, 1, 2, 2)
    wt = np.zeros((n, 6))
    for k in range(n):
        for c in range(6):
            for m in range(5):
                wt[k, c] += w[k, 6 + m] * basis[m, ta[c], tb[c]]
    tacc = np.zeros((n, 6))
    alpha, beta = radii * radii / 6.0, radii * radii / 10.0  # Faxen coefficients a^2/6, a^2/10
    n_img = pi.shape[0]
    ui0 = ui1 = ui2 = oi0 = oi1 = oi2 = 0.0
    uj0 = uj1 = uj2 = oj0 = oj1 = oj2 = 0.0
    t_i = t_j = _ZERO_SYMMETRIC  # a pair's e P^T + P e^T over its images, receivers i and j
    sum_df = sum_dl = sum_cd = 0.0
    for p in range(n_img):
        i, j = pi[p], pj[p]
        r0 = pos[i, 0] - pos[j, 0] - shift[p, 0]
        r1 = pos[i, 1] - pos[j, 1] - shift[p, 1]
        r2 = pos[i, 2] - pos[j, 2] - shift[p, 2]
        r = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        _radial_lookup(grid, grid_r0, grid_h, table, bounds, xi, r, pw, v)
        ir = 1.0 / r
        e0, e1, e2 = r0 * ir, r1 * ir, r2 * ir
        ai, aj = radii[i], radii[j]
        al_i, al_j = alpha[i], alpha[j]
        be_i, be_j = beta[i], beta[j]
        v01, v02, v10, v11, v12 = v[0, 1], v[0, 2], v[1, 0], v[1, 1], v[1, 2]
        v20, v21, v22, v30 = v[2, 0], v[2, 1], v[2, 2], v[3, 0]

        # scalar coefficients, as in _block_from_radial
        s1, s2 = al_i + al_j, al_i * al_j
        d1 = v01 + s1 * v11 + s2 * v21
        a_f = v02 + s1 * v12 + s2 * v22 - d1 * ir
        d_f = v10 + s1 * v20 + s2 * v30 - d1 * ir
        f_ul = 0.5 * (v11 + al_i * v21)
        f_of = 0.5 * (v11 + al_j * v21)
        a_l = 0.25 * (v12 - v11 * ir)
        d_l = 0.25 * (v11 * ir - v20)
        c1a, c2a, h_j = _stresslet_coefficients(v, ir, al_i, be_j)  # U_i-S_j, Omega_i-S_j; E_j-F_i, E_j-L_i
        if ai == aj:
            c1b, c2b, h_i = c1a, c2a, h_j
        else:
            c1b, c2b, h_i = _stresslet_coefficients(v, ir, al_j, be_i)  # U_j-S_i, Omega_j-S_i; E_i-F_j, E_i-L_j
        dd1, cw, cd = _strain_coefficients(v, ir, be_i + be_j, be_i * be_j)
        sum_cd += cd
        sum_df += d_f
        sum_dl += d_l

        # receiver i, source j
        gx, gy, gz, s, ef, el, cx, cy, cz = _source_moments(w, wt, j, e0, e1, e2)
        fx, fy, fz = w[j, 0], w[j, 1], w[j, 2]
        k = c1a * s - a_f * ef
        ui0 += f_ul * cx + c2a * gx + k * e0
        ui1 += f_ul * cy + c2a * gy + k * e1
        ui2 += f_ul * cz + c2a * gz + k * e2
        mx, my, mz = f_of * fx - h_j * gx, f_of * fy - h_j * gy, f_of * fz - h_j * gz
        k = a_l * el
        oi0 += e1 * mz - e2 * my + k * e0
        oi1 += e2 * mx - e0 * mz + k * e1
        oi2 += e0 * my - e1 * mx + k * e2
        k = dd1 * s - c1b * ef
        px = h_i * cx + cw * gx - c2b * fx + k * e0
        py = h_i * cy + cw * gy - c2b * fy + k * e1
        pz = h_i * cz + cw * gz - c2b * fz + k * e2
        t_i = _add_symmetric_outer(t_i, e0, e1, e2, px, py, pz)

        # receiver j, source i (e -> -e, radii exchanged)
        gx, gy, gz, s, ef, el, cx, cy, cz = _source_moments(w, wt, i, e0, e1, e2)
        fx, fy, fz = w[i, 0], w[i, 1], w[i, 2]
        k = -c1b * s - a_f * ef
        uj0 += k * e0 - f_of * cx - c2b * gx
        uj1 += k * e1 - f_of * cy - c2b * gy
        uj2 += k * e2 - f_of * cz - c2b * gz
        mx, my, mz = f_ul * fx + h_i * gx, f_ul * fy + h_i * gy, f_ul * fz + h_i * gz
        k = a_l * el
        oj0 += k * e0 - (e1 * mz - e2 * my)
        oj1 += k * e1 - (e2 * mx - e0 * mz)
        oj2 += k * e2 - (e0 * my - e1 * mx)
        k = dd1 * s + c1a * ef
        px = h_j * cx + cw * gx + c2a * fx + k * e0
        py = h_j * cy + cw * gy + c2a * fy + k * e1
        pz = h_j * cz + cw * gz + c2a * fz + k * e2
        t_j = _add_symmetric_outer(t_j, e0, e1, e2, px, py, pz)

        if p + 1 < n_img and pi[p + 1] == i and pj[p + 1] == j:
            continue
        out[i, 0] += ui0 + sum_df * w[j, 0]
        out[i, 1] += ui1 + sum_df * w[j, 1]
        out[i, 2] += ui2 + sum_df * w[j, 2]
        out[i, 3] += oi0 + sum_dl * w[j, 3]
        out[i, 4] += oi1 + sum_dl * w[j, 4]
        out[i, 5] += oi2 + sum_dl * w[j, 5]
        out[j, 0] += uj0 + sum_df * w[i, 0]
        out[j, 1] += uj1 + sum_df * w[i, 1]
        out[j, 2] += uj2 + sum_df * w[i, 2]
        out[j, 3] += oj0 + sum_dl * w[i, 3]
        out[j, 4] += oj1 + sum_dl * w[i, 4]
        out[j, 5] += oj2 + sum_dl * w[i, 5]
        for m in range(5):
            out[i, 6 + m] += sum_cd * w[j, 6 + m]
            out[j, 6 + m] += sum_cd * w[i, 6 + m]
        for c in range(6):
            tacc[i, c] += t_i[c]
            tacc[j, c] += t_j[c]
        t_i = t_j = _ZERO_SYMMETRIC
        ui0 = ui1 = ui2 = oi0 = oi1 = oi2 = 0.0
        uj0 = uj1 = uj2 = oj0 = oj1 = oj2 = 0.0
        sum_df = sum_dl = sum_cd = 0.0
    # E_m += B^m : sym(T): tacc holds the diagonal and T_ab + T_ba (a < b)
    for k in range(n):
        for m in range(5):
            acc = 0.0
            for c in range(6):
                acc += basis[m, ta[c], tb[c]] * tacc[k, c]
            out[k, 6 + m] += acc


def far_field_product(positions: np.ndarray, radii: np.ndarray, plan: FarFieldPlan, w: np.ndarray) -> np.ndarray:
    """M_inf w (N, 11) for w (N, 11) at the positions (used as given), with the pair images
    and wave vectors of the plan (`plan_far_field`, made at these or nearby positions),
    without forming M_inf: the real-space images in tensor form (`_real_space_product`),
    the reciprocal sum in O(N n_k) (`_reciprocal_product`) and the self blocks. Equal to
    `far_field_mobility(positions, radii, plan=plan) @ w` up to rounding; at positions
    displaced from the plan's by a small step it carries the same truncation, so that its
    difference to M_inf w at the plan's positions is the change of M_inf to ~tol of the
    change (the random finite difference of `resistance.resistance_change`).

    Args:
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii a.
        plan: the far-field plan.
        w: (N, 11) generalized forces (F, L, S per sphere).

    Returns:
        (N, 11) generalized velocities (U, Omega, E), Stokes units (viscosity 1).
    """
    pos = np.ascontiguousarray(positions, dtype=float)
    radii = np.ascontiguousarray(radii, dtype=float)
    w = np.ascontiguousarray(w, dtype=float)
    out = np.zeros_like(w)
    xi = 0.0 if plan.params is None else plan.params.xi
    grid = plan.grid
    _real_space_product(pos, radii, *plan.images, plan.table, grid.values, grid.r0, grid.h, xi, BASIS, w, out)
    if plan.params is not None:
        out += _reciprocal_product(np.hstack(wave_phases(pos, plan)), radii, *plan.amplitudes, 2.0 / plan.volume, w)
    for a, block in plan.self_blocks.items():  # diagonal 11x11 blocks
        rows = radii == a
        out[rows] += w[rows] * np.diagonal(block)
    return out


# ---------------------------------------------------------------------------------
# reciprocal space and self terms (numpy + BLAS)
# ---------------------------------------------------------------------------------


# Pair form of the reciprocal sum. With b_i(k) the real 11x2 matrix of R_i(k) q_t
# sqrt(h)/k (U rows (1 - a_i^2 k^2/6) q, Omega rows (1/2) k x q, E rows
# (1 - a_i^2 k^2/10) k.B^m.q; the Omega and E rows carry a factor i), the block is
#   M_ij = (2/V) sum_k [cos(k.r_ij) A_k + sin(k.r_ij) B_k],  r_ij = x_i - x_j,
# A_k = (b_i b_j^T) on the U-U and (Omega,E)-(Omega,E) entries, B_k = +-(b_i b_j^T) on
# the U-(Omega,E) (+) and (Omega,E)-U (-) entries (the sum over +-k of the Gram form
# Re[Z Z^H], Z_i = b_i exp(i k.x_i)). Unscaled by radii, A_k is symmetric and B_k
# antisymmetric, so 42 + 24 of the 121 entries are independent. Over all pairs i <= j the
# sum is two matrix products (pairs x k) @ (k x independent entries), N^2 n_k 66 flops:
# an eighth of those of the Gram form as a rank-4 n_k update of the 11N x 11N matrix.
# The radius factors f_a(a_i) f_b(a_j), f = 1 - c a^2 k^2 (c = 1/6 U, 0 Omega,
# 1/10 E), are folded into A_k, B_k when all radii are equal, and otherwise expanded in
# powers of k^2 (three products per part).

_ROW_C = np.array([1 / 6] * 3 + [0.0] * 3 + [1 / 10] * 5)  # Faxen coefficient per row
_EVEN = np.arange(NDOF) < 3  # U rows (real); Omega and E rows carry a factor i
#: independent (row, column) entries: cosine part a <= b of equal parity, sine part
#: U row a, Omega/E column b (B_ba = -B_ab)
_COS_ENTRIES = np.array([(a, b) for a in range(NDOF) for b in range(a, NDOF) if _EVEN[a] == _EVEN[b]])
_SIN_ENTRIES = np.array([(a, b) for a in range(3) for b in range(3, NDOF)])
#: the Faxen coefficients of the rows and columns of the independent entries
_ENTRY_ROW_C = {"cos": _ROW_C[_COS_ENTRIES[:, 0]], "sin": _ROW_C[_SIN_ENTRIES[:, 0]]}
_ENTRY_COL_C = {"cos": _ROW_C[_COS_ENTRIES[:, 1]], "sin": _ROW_C[_SIN_ENTRIES[:, 1]]}
_PAIR_CHUNK = 64  # pairs per matrix product: the phases of a chunk stay in cache (measured optimum at N = 27)


@numba.njit(cache=True)
def _wave_amplitudes(kvec, xi, basis, b):
    """b[k] = the real 11x2 matrix b(k) of the pair form above for unit radius factors:
    R(k) q_t sqrt(h)/k for the two unit vectors q_t normal to k (the factor i of the Omega
    and E rows left out)."""
    q = np.empty(3)
    for kk in range(kvec.shape[0]):
        k0, k1, k2 = kvec[kk, 0], kvec[kk, 1], kvec[kk, 2]
        ksq = k0 * k0 + k1 * k1 + k2 * k2
        kmag = math.sqrt(ksq)
        u = ksq / (4 * xi * xi)
        scale = math.sqrt((1 + u + 2 * u * u) * math.exp(-u)) / kmag
        # q1 = k x t / |k x t| for a trial axis t not parallel to k, q2 = khat x q1
        if abs(k2) < 0.9 * kmag:
            a0, a1, a2 = k1, -k0, 0.0  # k x e_z
        else:
            a0, a1, a2 = 0.0, k2, -k1  # k x e_x
        norm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        p0, p1, p2 = a0 / norm, a1 / norm, a2 / norm
        for t in range(2):
            if t == 0:
                q[0], q[1], q[2] = p0, p1, p2
            else:
                q[0] = (k1 * p2 - k2 * p1) / kmag
                q[1] = (k2 * p0 - k0 * p2) / kmag
                q[2] = (k0 * p1 - k1 * p0) / kmag
            for c in range(3):
                b[kk, c, t] = scale * q[c]
            b[kk, 3, t] = 0.5 * scale * (k1 * q[2] - k2 * q[1])
            b[kk, 4, t] = 0.5 * scale * (k2 * q[0] - k0 * q[2])
            b[kk, 5, t] = 0.5 * scale * (k0 * q[1] - k1 * q[0])
            # k.B^m.q with the sparse basis.BASIS (B^1 = (xx - yy)/sqrt2, B^2 = (2zz - xx -
            # yy)/sqrt6, B^3, B^4, B^5 = (xy + yx, xz + zx, yz + zy)/sqrt2)
            b[kk, 6, t] = scale * _ISQ2 * (k0 * q[0] - k1 * q[1])
            b[kk, 7, t] = scale * _ISQ6 * (2.0 * k2 * q[2] - k0 * q[0] - k1 * q[1])
            b[kk, 8, t] = scale * _ISQ2 * (k0 * q[1] + k1 * q[0])
            b[kk, 9, t] = scale * _ISQ2 * (k0 * q[2] + k2 * q[0])
            b[kk, 10, t] = scale * _ISQ2 * (k1 * q[2] + k2 * q[1])


@numba.njit(cache=True)
def _wave_tensors(b, cos_entries, sin_entries, ksq, scale, a2, row_c, tcos, tsin):
    """tcos[k, e], tsin[k, e] = scale (b b^T)[entry e] of the cosine and sine entries, for
    the wave vectors' b (`_wave_amplitudes`); with a2 >= 0 (all radii equal, a^2) times the
    radius factors f_r(a) f_c(a), f = 1 - row_c a^2 |k|^2 (ksq), of the entry's row and
    column (folded into the rows of b first: one product per entry)."""
    rows = row_c.shape[0]
    bf = np.empty((rows, 2))
    for kk in range(b.shape[0]):
        for a in range(rows):
            factor = 1.0 - row_c[a] * a2 * ksq[kk] if a2 >= 0.0 else 1.0
            bf[a, 0], bf[a, 1] = b[kk, a, 0] * factor, b[kk, a, 1] * factor
        for e in range(cos_entries.shape[0]):
            r, c = cos_entries[e, 0], cos_entries[e, 1]
            tcos[kk, e] = (bf[r, 0] * bf[c, 0] + bf[r, 1] * bf[c, 1]) * scale
        for e in range(sin_entries.shape[0]):
            r, c = sin_entries[e, 0], sin_entries[e, 1]
            tsin[kk, e] = (bf[r, 0] * bf[c, 0] + bf[r, 1] * bf[c, 1]) * scale


@numba.njit(cache=True, inline="never")
def _bracket_row(c, g, s, h, out):
    """out = c g + s h elementwise (one loop: LLVM vectorises it when its runtime check
    that the arrays do not overlap stays small, as for at most four inputs)."""
    for m in range(out.shape[0]):
        out[m] = c[m] * g[m] + s[m] * h[m]


@numba.njit(cache=True)
def _reciprocal_weights(proj, b, ksq, row_c, a2, out):
    """The wave-vector side of `_reciprocal_product`. proj (2 n_k, W): rows k of
    sum_j cos(k.x_j) w_j and then rows k of sum_j sin(k.x_j) w_j, columns the 11 dofs a of
    w (W = 11) or of w and a_j^2 w (W = 22, unequal radii); b (n_k, 11, 2) the unit-radius
    amplitudes b_a(k, t) (`_wave_amplitudes`), ksq (n_k,) |k|^2, row_c (11,) the Faxen
    coefficients c_a, a2 the common radius squared (all radii equal) or -1. With
    f_a(a) = 1 - c_a a^2 |k|^2, per (k, t):

        P_c,s = sum_{a in U} b_a (c, s)-projection of f_a w_a,
        Q_c,s = sum_{a in Omega, E} b_a (c, s)-projection of f_a w_a,
        g0 = P_c - Q_s,  g1 = P_s + Q_c,

    and out (2 n_k, W) rows k: Y_c[k, a] = sum_t b_a(k, t) h_c, then Y_s[k, a] likewise with
    h_s, where (h_c, h_s) = (g0, g1) on the U rows and (g1, -g0) on the Omega and E rows; with
    W = 22 the columns 11..21 hold |k|^2 Y (for the receivers' Faxen factors); with equal
    radii f_a(a) is folded into Y."""
    nk = ksq.shape[0]
    nw = proj.shape[1]
    fw = np.empty(NDOF)
    cw, sw = np.empty(NDOF), np.empty(NDOF)
    for k in range(nk):
        for a in range(NDOF):
            fw[a] = 1.0 - row_c[a] * a2 * ksq[k] if a2 >= 0.0 else 1.0
            if nw == NDOF:
                cw[a], sw[a] = fw[a] * proj[k, a], fw[a] * proj[nk + k, a]
            else:
                cw[a] = proj[k, a] - row_c[a] * ksq[k] * proj[k, NDOF + a]
                sw[a] = proj[nk + k, a] - row_c[a] * ksq[k] * proj[nk + k, NDOF + a]
        for a in range(nw):
            out[k, a] = 0.0
            out[nk + k, a] = 0.0
        for t in range(2):
            pc = ps = qc = qs = 0.0
            for a in range(3):
                pc += b[k, a, t] * cw[a]
                ps += b[k, a, t] * sw[a]
            for a in range(3, NDOF):
                qc += b[k, a, t] * cw[a]
                qs += b[k, a, t] * sw[a]
            g0, g1 = pc - qs, ps + qc
            for a in range(NDOF):
                bat = b[k, a, t] * fw[a]
                if a < 3:
                    out[k, a] += bat * g0
                    out[nk + k, a] += bat * g1
                else:
                    out[k, a] += bat * g1
                    out[nk + k, a] -= bat * g0
        if nw > NDOF:
            for a in range(NDOF):
                out[k, NDOF + a] = ksq[k] * out[k, a]
                out[nk + k, NDOF + a] = ksq[k] * out[nk + k, a]


def _reciprocal_product(phases, radii, b, ksq, scale, w):
    """The reciprocal part of M_k w (N, 11) for w (N, 11), in O(N n_k), no pair loop.
    phases (N, 2 n_k): cos(k.x_j) and then sin(k.x_j); b (n_k, 11, 2), ksq: the plan's
    amplitudes and |k|^2 (`FarFieldPlan.amplitudes`); scale = 2/V. The pair form of
    `_reciprocal_sum` summed over the sources j first: with the projections
    sum_j (cos, sin)(k.x_j) f_a(a_j) w_ja (one BLAS product (2 n_k x N) @ (N x W)), the
    per-wave-vector weights Y of `_reciprocal_weights`, and the receivers

        (M_k w)_ia = scale f_a(a_i) sum_k [cos(k.x_i) Y_c[k, a] + sin(k.x_i) Y_s[k, a]]

    (a second product (N x 2 n_k) @ (2 n_k x W)); f_a(a) = 1 - c_a a^2 |k|^2 is folded into Y
    when all radii are equal (W = 11), else expanded (W = 22: the columns of a_j^2 w and of
    |k|^2 Y)."""
    equal = bool(np.all(radii == radii[0]))
    a2 = radii * radii
    src = w if equal else np.hstack([w, a2[:, None] * w])
    proj = phases.T @ src
    weights = np.empty_like(proj)
    _reciprocal_weights(proj, b, ksq, _ROW_C, float(a2[0]) if equal else -1.0, weights)
    got = phases @ weights
    if equal:
        return scale * got
    return scale * (got[:, :NDOF] - (a2[:, None] * _ROW_C) * got[:, NDOF:])


@numba.njit(cache=True, inline="never")
def _sin_difference_row(re_i, im_i, re_j, im_j, out):
    """out = sin(a_i - a_j) = im_i re_j - re_i im_j from exp(i a) (one pair, all k)."""
    for k in range(out.shape[0]):
        out[k] = im_i[k] * re_j[k] - re_i[k] * im_j[k]


@numba.njit(cache=True)
def _pair_phases(phase_re, phase_im, pi, pj, cos_out, sin_out):
    """cos and sin of k.(x_i - x_j) for the pairs (pi, pj), from exp(i k.x) per particle
    (rows over the wave vectors, vectorised)."""
    for p in range(pi.shape[0]):
        i, j = pi[p], pj[p]
        # cos(a_i - a_j) = re_i re_j + im_i im_j from exp(i a) (one pair, all k)
        _bracket_row(phase_re[i], phase_re[j], phase_im[i], phase_im[j], cos_out[p])
        _sin_difference_row(phase_re[i], phase_im[i], phase_re[j], phase_im[j], sin_out[p])


@numba.njit(cache=True)
def _scatter_pairs(pi, pj, cos_ab, cos_ba, sin_ab, sin_ba, cos_entries, sin_entries, mob, both=True):
    """Adds the pair blocks as M_ij and M_ji = M_ij^T (both False: M_ij alone, for
    `_mirror_lower_blocks`), from the values of each independent entry (a, b) at (a, b) and
    at (b, a) of M_ij."""
    for p in range(pi.shape[0]):
        ri, rj = NDOF * pi[p], NDOF * pj[p]
        for half in range(2):
            v_ab = cos_ab if half == 0 else sin_ab
            v_ba = cos_ba if half == 0 else sin_ba
            entries = cos_entries if half == 0 else sin_entries
            for e in range(entries.shape[0]):
                a, b = entries[e, 0], entries[e, 1]
                mob[ri + a, rj + b] += v_ab[p, e]
                if a != b:
                    mob[ri + b, rj + a] += v_ba[p, e]
                if both and pi[p] != pj[p]:
                    mob[rj + b, ri + a] += v_ab[p, e]
                    if a != b:
                        mob[rj + a, ri + b] += v_ba[p, e]


def wave_amplitudes(kvec: np.ndarray, xi: float) -> np.ndarray:
    """b(k) (nk, 11, 2) of every wave vector (`_wave_amplitudes`).

    Args:
        kvec: (nk, 3) wave vectors (1/length).
        xi: Ewald splitting parameter (1/length).

    Returns:
        (nk, 11, 2) amplitudes b(k) for unit radius factors.
    """
    b = np.empty((len(kvec), NDOF, 2))
    _wave_amplitudes(kvec, xi, BASIS, b)
    return b


@numba.njit(cache=True)
def _phases(pos, index, basis, cos_out, sin_out):
    """cos_out, sin_out (N, nk) = cos and sin of k.x_j for k = index[k] . basis (integer
    coordinates on the reciprocal lattice with rows basis), as the products
    exp(i k.x) = prod_c exp(i n_c theta_c), theta_c = basis_c . x: per particle one
    trigonometric pair per distinct n_c (a few dozen) instead of one per wave vector."""
    lo, hi = np.empty(3, np.int64), np.empty(3, np.int64)
    for c in range(3):
        lo[c], hi[c] = index[:, c].min(), index[:, c].max()
    width = int((hi - lo).max()) + 1
    re, im = np.empty((3, width)), np.empty((3, width))
    for j in range(pos.shape[0]):
        for c in range(3):
            theta = basis[c, 0] * pos[j, 0] + basis[c, 1] * pos[j, 1] + basis[c, 2] * pos[j, 2]
            for m in range(hi[c] - lo[c] + 1):
                re[c, m], im[c, m] = math.cos((lo[c] + m) * theta), math.sin((lo[c] + m) * theta)
        for k in range(index.shape[0]):
            a, b, c = index[k, 0] - lo[0], index[k, 1] - lo[1], index[k, 2] - lo[2]
            xr = re[0, a] * re[1, b] - im[0, a] * im[1, b]
            xim = re[0, a] * im[1, b] + im[0, a] * re[1, b]
            cos_out[j, k] = xr * re[2, c] - xim * im[2, c]
            sin_out[j, k] = xr * im[2, c] + xim * re[2, c]


def wave_phases(positions: np.ndarray, plan: FarFieldPlan) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of k.x (N, nk each) for the positions (N, 3) and the plan's wave vectors.

    Args:
        positions: (N, 3) sphere centres.
        plan: the far-field plan (its wave vectors).

    Returns:
        cos (N, nk) and sin (N, nk) of k.x.
    """
    shape = (len(positions), len(plan.kvec))
    cos, sin = np.empty(shape), np.empty(shape)
    if shape[1]:
        _phases(np.ascontiguousarray(positions, dtype=float), plan.wave_index, plan.wave_basis, cos, sin)
    return cos, sin


def _wave_terms(radii, plan):
    """What the reciprocal sum needs besides the positions: the cosine and sine tensors
    of the plan's wave vectors (scaled by 2/V, with the radius factors folded in when all
    radii are equal), |k|^2 (nk, 1), the Faxen coefficients of their rows and columns, and
    whether the radii are equal."""
    b, ksq = plan.amplitudes
    nk = len(ksq)
    tcos, tsin = np.empty((nk, len(_COS_ENTRIES))), np.empty((nk, len(_SIN_ENTRIES)))
    equal = bool(np.all(radii == radii[0]))
    # all radii equal: f_a(a) f_b(a) folded into the tensors (one product per part)
    a2 = float(radii[0]) ** 2 if equal else -1.0
    _wave_tensors(b, _COS_ENTRIES, _SIN_ENTRIES, ksq, 2.0 / plan.volume, a2, _ROW_C, tcos, tsin)
    return {"cos": tcos, "sin": tsin}, ksq[:, None], _ENTRY_ROW_C, _ENTRY_COL_C, equal


def _reciprocal_sum(pos, radii, plan, mob, both=True):
    """Adds the reciprocal-space Ewald sum (the pair form above) of the plan's wave vectors
    into mob (11N x 11N); both False: the blocks M_ji of pairs i < j left out
    (`_scatter_pairs`). The wave vectors' tensors are kept in the plan for its radii."""
    n, nk = len(pos), len(plan.kvec)
    if plan.wave_terms is None or not np.array_equal(plan.wave_terms[0], radii):
        plan.wave_terms = (radii.copy(), _wave_terms(radii, plan))
    tensors, ksq, c_row, c_col, equal = plan.wave_terms[1]
    phase_re, phase_im = wave_phases(pos, plan)
    if equal:
        pi, pj = _upper_pairs(n, 1)
        _reciprocal_equal(phase_re, phase_im, pi, pj, tensors["cos"], tensors["sin"], _COS_ENTRIES, _SIN_ENTRIES,
                          _PAIR_CHUNK, mob, both)
        # the self pairs (r = 0: cos 1, sin 0), one block for every particle
        _add_diagonal_blocks(mob, _symmetric_block(tensors["cos"].sum(axis=0), _COS_ENTRIES))
        return
    pi, pj = _upper_pairs(n, 0)
    for start in range(0, len(pi), _PAIR_CHUNK):
        ci, cj = pi[start:start + _PAIR_CHUNK], pj[start:start + _PAIR_CHUNK]
        cos_k, sin_k = work_array("cos_k", (len(ci), nk)), work_array("sin_k", (len(ci), nk))
        _pair_phases(phase_re, phase_im, ci, cj, cos_k, sin_k)
        vals = []  # (entry values at (a, b), at (b, a)) of the cosine and sine parts
        for part, trig, sign in (("cos", cos_k, 1.0), ("sin", sin_k, -1.0)):
            t = tensors[part]
            g0 = np.matmul(trig, t, out=work_array(part, (len(ci), t.shape[1])))
            # f_a(a_i) f_b(a_j) = 1 - (c_a a_i^2 + c_b a_j^2) k^2 + c_a c_b a_i^2 a_j^2 k^4
            g1, g2 = trig @ (ksq * t), trig @ (ksq * ksq * t)
            ai2, aj2 = radii[ci, None] ** 2, radii[cj, None] ** 2
            ca, cb = c_row[part], c_col[part]
            g0 += ca * cb * ai2 * aj2 * g2
            vals += [g0 - (ca * ai2 + cb * aj2) * g1, sign * (g0 - (cb * ai2 + ca * aj2) * g1)]
        _scatter_pairs(ci, cj, *vals, _COS_ENTRIES, _SIN_ENTRIES, mob, both)


@numba.njit(cache=True)
def _reciprocal_equal(phase_re, phase_im, pi, pj, tcos, tsin, cos_entries, sin_entries, chunk, mob, both):
    """`_reciprocal_sum` for equal radii (the radius factors folded into tcos, tsin), chunk
    pairs at a time: the pair phases, the two matrix products (BLAS) and the scatter."""
    nk = phase_re.shape[1]
    cos_k, sin_k = np.empty((chunk, nk)), np.empty((chunk, nk))
    g_cos, g_sin = np.empty((chunk, tcos.shape[1])), np.empty((chunk, tsin.shape[1]))
    g_neg = np.empty((chunk, tsin.shape[1]))
    for start in range(0, pi.shape[0], chunk):
        stop = min(start + chunk, pi.shape[0])
        m = stop - start
        ci, cj = pi[start:stop], pj[start:stop]
        _pair_phases(phase_re, phase_im, ci, cj, cos_k[:m], sin_k[:m])
        np.dot(cos_k[:m], tcos, g_cos[:m])
        np.dot(sin_k[:m], tsin, g_sin[:m])
        for p in range(m):
            for e in range(tsin.shape[1]):
                g_neg[p, e] = -g_sin[p, e]
        _scatter_pairs(ci, cj, g_cos[:m], g_cos[:m], g_sin[:m], g_neg[:m], cos_entries, sin_entries, mob, both)


@functools.lru_cache(maxsize=8)
def _upper_pairs(n, offset):
    """np.triu_indices(n, offset) (the pairs i <= j for offset 0, i < j for 1), cached
    read-only."""
    pi, pj = np.triu_indices(n, offset)
    pi.flags.writeable = False
    pj.flags.writeable = False
    return pi, pj


def _symmetric_block(values, entries):
    """The symmetric 11x11 block with values[e] at (a, b) and (b, a) for entries[e] = (a, b)."""
    block = np.zeros((NDOF, NDOF))
    block[entries[:, 0], entries[:, 1]] = values
    block[entries[:, 1], entries[:, 0]] = values
    return block


def _gauss_moment(p, xi):
    """int_0^inf k^(2p) exp(-k^2/4xi^2) dk = Gamma(p + 1/2) (2 xi)^(2p+1) / 2."""
    return 0.5 * gamma_function(p + 0.5) * (2 * xi) ** (2 * p + 1)


def _h_integral(poly, xi):
    """int_0^inf P(k^2) h(k) dk for P given by coefficients in powers of k^2."""
    hpoly = np.array([1.0, 1 / (4 * xi * xi), 1 / (8 * xi ** 4)])
    total = np.convolve(poly, hpoly)
    return sum(c * _gauss_moment(p, xi) for p, c in enumerate(total))


def self_mobility(radius: float, xi: float | None = None) -> np.ndarray:
    """Diagonal 11x11 self block: the isolated sphere, U = F/(6 pi a),
    Omega = L/(8 pi a^3), -E = -S 3/(20 pi a^3), minus (for xi given) the k-space
    Ewald field at r = 0, obtained from int d^3k/(2pi)^3 R(k) J^(k) R(k)^H with the
    angular averages <I - kk> = 2/3, and 1/5 for the strain block (a fresh array).

    Args:
        radius: sphere radius a.
        xi: Ewald splitting parameter (1/length), or None (isolated sphere alone).

    Returns:
        (11, 11) diagonal self block (Stokes units, viscosity 1).
    """
    return np.diag(_self_diagonal(float(radius), None if xi is None else float(xi)))


@functools.lru_cache(maxsize=256)
def _self_diagonal(a, xi):
    """The diagonal of `self_mobility` (read-only, cached: a plan per step asks again)."""
    diag = np.empty(NDOF)
    diag[0:3] = 1 / (6 * math.pi * a)
    diag[3:6] = 1 / (8 * math.pi * a ** 3)
    diag[6:11] = 3 / (20 * math.pi * a ** 3)
    if xi is not None and xi > 0:
        c = 1 / (2 * math.pi ** 2)
        al, be = a * a / 6, a * a / 10
        diag[0:3] -= c * (2 / 3) * _h_integral([1.0, -2 * al, al * al], xi)
        diag[3:6] -= c * (1 / 6) * _h_integral([0.0, 1.0], xi)
        diag[6:11] -= c * (1 / 5) * _h_integral([0.0, 1.0, -2 * be, be * be], xi)
    diag.flags.writeable = False
    return diag


# ---------------------------------------------------------------------------------
# parameters and the public entry point
# ---------------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def _truncation_parameter(tol, power=6):
    """s with exp(-s^2) s^power = tol. With power 6: the reach, in units of 1/xi (real
    space) and 2 xi (reciprocal space), at which the slowest-decaying kernel (the 4th
    derivative of r erfc(xi r) times Faxen Laplacians) has fallen to tol relative to its
    scale."""
    s = math.sqrt(-math.log(tol))
    for _ in range(50):
        s = math.sqrt(-math.log(tol) + power * math.log(s))
    return s


@dataclass(frozen=True)
class EwaldParameters:
    """Splitting parameter xi, real-space cut-off r_c and reciprocal cut-off k_c."""

    xi: float
    rcut: float
    kcut: float

    @classmethod
    def choose(cls, lattice: Lattice, tol: float = DEFAULT_EWALD_TOL, xi: float | None = None,
               cost_ratio: float = 45.0) -> EwaldParameters:
        """Parameters for relative accuracy tol. Unless given, xi balances the
        real-space cost (pairs within r_c ~ N^2 r_c^3 / V, each a numba kernel) against
        the reciprocal cost (N^2 k_c^3 V, each a BLAS rank update); cost_ratio is the
        ratio of the two per term, measured on a Brownian step, where the real-space
        images serve the assembly and a matrix-free product (`far_field_product`): at
        N = 27 and 64 a step is ~7% faster at 45 than at 25 (the optimum of the assembly
        alone, which is flat over 25-45).

        Args:
            lattice: the periodic lattice.
            tol: relative accuracy of the Ewald sums.
            xi: splitting parameter (1/length), or None (chosen by cost).
            cost_ratio: real-space over reciprocal cost per term.

        Returns:
            The parameters (xi, kcut in 1/length; rcut in length).
        """
        s = _truncation_parameter(tol)
        if xi is None:
            xi = (2 * math.pi ** 3 * cost_ratio) ** (1 / 6) / lattice.volume ** (1 / 3)
        return cls(xi=float(xi), rcut=s / xi, kcut=2 * xi * s)


@dataclass
class FarFieldPlan:
    """What the far-field sums need besides the positions, fixed for a configuration and
    its small displacements (random finite differences must not see pairs cross the
    cut-off): Ewald parameters (None: unbounded), real-space pair images (i, j, shift),
    wave vectors (and their integer coordinates on the reciprocal lattice), radial
    coefficient table, the self blocks per radius and the volume;
    the wave vectors' tensors are kept once computed (a step's midpoint reuses them)."""

    params: EwaldParameters | None
    images: tuple
    kvec: np.ndarray
    wave_index: np.ndarray  # (nk, 3) int: k = wave_index . wave_basis
    wave_basis: np.ndarray  # (3, 3): the rows 2 pi b_c of the reciprocal lattice
    table: np.ndarray
    grid: "RadialGrid"
    self_blocks: dict
    volume: float
    wave_terms: tuple | None = None  # (radii, their `_wave_terms`), built on first use

    @functools.cached_property
    def amplitudes(self) -> tuple[np.ndarray, np.ndarray]:
        """(b (nk, 11, 2), |k|^2 (nk,)): the wave vectors' unit-radius amplitudes
        (`_wave_amplitudes`) and squared lengths, computed once per plan (the assembly and
        the products of a step share them)."""
        return wave_amplitudes(self.kvec, self.params.xi), np.einsum("ij,ij->i", self.kvec, self.kvec)

    @property
    def real_space_reach(self) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], float] | None:
        """(images, r_c) of a periodic plan, for `geometry.pairs_in_reach` (None: unbounded)."""
        return None if self.params is None else (self.images, self.params.rcut)


@functools.lru_cache(maxsize=16)
def _cached_radial_table(xi):
    return radial_table(xi)


@dataclass(frozen=True)
class RadialGrid:
    """The real-space radial values d^m lap^p chi_r/dr^m (m = 0..5) at r = r0 + g h,
    for cubic Hermite interpolation by `_radial_lookup` (exact evaluation off the grid).
    The interpolation error is h^4/384 max|f^(4)|; measured relative to each function's
    largest value on [1, r_c], it is 4e-8 (h/0.01)^4, so h is set for 1e-2 tol. Below
    h = 0.002 (tol < 6e-9) the grid would outgrow the caches: exact values instead."""

    r0: float
    h: float
    values: np.ndarray  # (n, 4, 6)

    #: start of the grid (closer pairs, possible only with radii below 1, are exact)
    START = 1.0

    @classmethod
    @functools.lru_cache(maxsize=16)
    def build(cls, xi: float, r_max: float, tol: float) -> RadialGrid:
        """A grid on [START, r_max] for splitting parameter xi and Ewald accuracy tol;
        xi = 0 (unbounded fluid, no cut-off): an empty grid, all values exact.

        Args:
            xi: Ewald splitting parameter (1/length).
            r_max: end of the grid (length).
            tol: relative accuracy of the Ewald sums.

        Returns:
            The grid (cached per arguments).
        """
        h = min(0.02, 0.01 * (2.5e5 * tol) ** 0.25)
        if xi == 0 or h < 0.002:
            return cls(cls.START, 1.0, np.zeros((0, 4, 6)))
        n = int(math.ceil((r_max - cls.START) / h)) + 2
        values = np.empty((n, 4, 6))
        _fill_radial_grid(_cached_radial_table(xi), xi, cls.START, h, values)
        return cls(cls.START, h, values)


def plan_far_field(positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None = None,
                   tol: float = DEFAULT_EWALD_TOL, xi: float | None = None,
                   candidates: FarFieldPlan | None = None) -> FarFieldPlan:
    """A FarFieldPlan for (wrapped) positions in the lattice (None: unbounded fluid).
    candidates: a periodic plan for the same positions and lattice; where its real-space
    cut-off covers this plan's, its images are filtered (`geometry.pairs_in_reach`) instead
    of searched again.

    Args:
        positions: (N, 3) sphere centres, wrapped into the cell (length unit of the radii).
        radii: (N,) sphere radii a.
        lattice: the periodic lattice, or None (unbounded fluid).
        tol: relative accuracy of the Ewald sums.
        xi: Ewald splitting parameter (1/length), or None (chosen).
        candidates: a periodic plan of the same positions and lattice, or None.

    Returns:
        The plan.
    """
    if lattice is None:
        images = find_pairs(positions, radii, None, np.inf, 0.0)
        return FarFieldPlan(None, images, np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros((3, 3)),
                            _cached_radial_table(0.0),
                            RadialGrid.build(0.0, 0.0, tol),
                            {a: self_mobility(a) for a in np.unique(radii)}, np.inf)
    par = EwaldParameters.choose(lattice, tol=tol, xi=xi)
    images = pairs_in_reach(positions, radii, lattice, par.rcut, 0.0,
                            None if candidates is None else candidates.real_space_reach)
    # the grid reaches past r_c for the small displacements a plan is reused for
    grid = RadialGrid.build(par.xi, par.rcut + 1.0, tol)
    return FarFieldPlan(par, images, *lattice.wave_vectors(par.kcut), lattice.wave_basis, _cached_radial_table(par.xi),
                        grid, {a: self_mobility(a, par.xi) for a in np.unique(radii)}, lattice.volume)


class FarFieldIndefinite(np.linalg.LinAlgError):
    """The far-field mobility M_inf of a configuration is not positive definite: its Ewald
    sums too coarse for the box or the radii (the truncation error outgrows the smallest
    eigenvalue), or spheres overlapping deeply."""


def far_field_mobility(positions: np.ndarray, radii: np.ndarray, box: np.ndarray | None = None, strain: float = 0.0,
                       tol: float = DEFAULT_EWALD_TOL, xi: float | None = None,
                       plan: FarFieldPlan | None = None) -> np.ndarray:
    """The (11N, 11N) far-field grand mobility M_inf, symmetric positive definite for
    non-overlapping spheres.

    positions (N, 3), radii (N,); box (3,) for a periodic Lees-Edwards box at the given
    strain, or None for unbounded fluid (DBB 1987). Periodic sums are converged to
    relative accuracy ~tol; xi overrides the Ewald splitting parameter. With a plan
    (from `plan_far_field`), positions are used as given (not wrapped) with its pairs.

    Args:
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii a.
        box: (3,) sides of the periodic Lees-Edwards box, or None (unbounded fluid).
        strain: Lees-Edwards strain of the box.
        tol: relative accuracy of the Ewald sums.
        xi: Ewald splitting parameter (1/length), or None (chosen).
        plan: a far-field plan to use, or None (made here).

    Returns:
        (11N, 11N) M_inf, dofs (U, Omega, E) sphere by sphere (Stokes units, viscosity 1).
    """
    pos = np.ascontiguousarray(positions, dtype=float)
    radii = np.ascontiguousarray(radii, dtype=float)
    if plan is None:
        lattice = None if box is None else Lattice(box, strain)
        if lattice is not None:
            pos = lattice.wrap(pos)
        plan = plan_far_field(pos, radii, lattice, tol, xi)
    n = pos.shape[0]
    mob = np.zeros((NDOF * n, NDOF * n))
    xi_used = 0.0 if plan.params is None else plan.params.xi
    grid = plan.grid
    # the pair sums add the blocks M_ij, i <= j, only: M_ji = M_ij^T is copied at the end
    # (every contribution to M_ji is the transpose of one to M_ij, in the same order)
    _real_space_sum(pos, radii, *plan.images, plan.table, grid.values, grid.r0, grid.h, xi_used, BASIS, mob,
                    False)
    if plan.params is not None:
        _reciprocal_sum(pos, radii, plan, mob, both=False)
    _mirror_lower_blocks(mob)
    if len(plan.self_blocks) == 1:  # one radius: its self block on every diagonal block
        _add_diagonal_blocks(mob, next(iter(plan.self_blocks.values())))
    else:
        for i, a in enumerate(radii):
            mob[NDOF * i : NDOF * (i + 1), NDOF * i : NDOF * (i + 1)] += plan.self_blocks[a]
    return mob


@numba.njit(cache=True)
def _mirror_lower_blocks(mob):
    """mob[r, c] = mob[c, r] below the diagonal 11x11 blocks (the blocks M_ji, i > j, from
    M_ij)."""
    for r in range(mob.shape[0]):
        for c in range(NDOF * (r // NDOF)):
            mob[r, c] = mob[c, r]


@numba.njit(cache=True)
def _add_diagonal_blocks(mob, block):
    """Adds the 11x11 block to every diagonal 11x11 block of mob (11N x 11N)."""
    for i in range(mob.shape[0] // NDOF):
        for a in range(NDOF):
            for b in range(NDOF):
                mob[NDOF * i + a, NDOF * i + b] += block[a, b]
