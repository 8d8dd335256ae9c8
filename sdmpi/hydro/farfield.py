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

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy.special import gamma as gamma_function

from .basis import BASIS
from .geometry import Lattice, find_pairs

NDOF = 11  # generalized velocity components per particle: 3 U, 3 Omega, 5 E


# ---------------------------------------------------------------------------------
# radial functions  f(r) = erfc(xi r) sum_n c_n r^n + exp(-xi^2 r^2) sum_n d_n r^n
# ---------------------------------------------------------------------------------

_P0 = 12  # array index of the power r^0
_NPOW = 28  # powers r^-12 .. r^15


class RadialFunction:
    """f(r) = erfc(xi r) sum c_n r^n + exp(-xi^2 r^2) sum d_n r^n, closed under d/dr.

    xi = 0 gives plain Laurent polynomials (the unbounded-fluid kernels)."""

    def __init__(self, xi, erfc_coeffs, exp_coeffs):
        self.xi = xi
        self.c = np.asarray(erfc_coeffs, dtype=float)
        self.d = np.asarray(exp_coeffs, dtype=float)

    def derivative(self):
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

    def laplacian(self):
        """f'' + 2 f'/r (the Laplacian of a radial function, r > 0)."""
        first = self.derivative()
        second = first.derivative()
        c, d = second.c.copy(), second.d.copy()
        c[:-1] += 2 * first.c[1:]
        d[:-1] += 2 * first.d[1:]
        return RadialFunction(self.xi, c, d)

    def __call__(self, r):
        r = np.asarray(r, dtype=float)
        powers = r[..., None] ** (np.arange(_NPOW) - _P0)
        erfc = np.vectorize(math.erfc)(self.xi * r)
        return erfc * (powers @ self.c) + np.exp(-((self.xi * r) ** 2)) * (powers @ self.d)


def radial_table(xi):
    """T[p, m] = coefficients (2, NPOW) of d^m/dr^m of phi_p = lap^p chi_r,
    p = 0..3, m = 0..4, with chi_r = r erfc(xi r)/(8 pi)."""
    c = np.zeros(_NPOW)
    c[_P0 + 1] = 1.0 / (8 * math.pi)
    phi = RadialFunction(xi, c, np.zeros(_NPOW))
    table = np.zeros((4, 5, 2, _NPOW))
    for p in range(4):
        f = phi
        for m in range(5):
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
    bounds = np.zeros((4, 5, 2), dtype=np.int64)
    for p in range(4):
        for m in range(5):
            lo, hi = table.shape[3], 0
            for n in range(table.shape[3]):
                if table[p, m, 0, n] != 0.0 or table[p, m, 1, n] != 0.0:
                    lo = min(lo, n)
                    hi = n + 1
            bounds[p, m, 0], bounds[p, m, 1] = lo, max(hi, lo)
    return bounds


@numba.njit(cache=True)
def _radial_values(table, bounds, xi, r, pw, out):
    """out[p, m] = d^m phi_p / dr^m at r (bounds from _power_bounds(table); pw is a
    work array of length NPOW)."""
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
        for m in range(5):
            sc = 0.0
            sd = 0.0
            for n in range(bounds[p, m, 0], bounds[p, m, 1]):
                sc += table[p, m, 0, n] * pw[n]
                sd += table[p, m, 1, n] * pw[n]
            out[p, m] = erfc * sc + gauss * sd


@numba.njit(cache=True)
def _pair_block(rvec, ai, aj, table, bounds, xi, basis, work, out):
    """11x11 real-space block coupling receiver sphere i to source sphere j at
    rvec = x_i - x_j (plus a lattice translation); adds into out. work: (80,) scratch."""
    r = math.sqrt(rvec[0] ** 2 + rvec[1] ** 2 + rvec[2] ** 2)
    e = work[0:3]
    for c in range(3):
        e[c] = rvec[c] / r
    v = work[3:23].reshape((4, 5))
    _radial_values(table, bounds, xi, r, work[23:23 + _NPOW], v)
    al_i, al_j = ai * ai / 6.0, aj * aj / 6.0
    be_i, be_j = ai * ai / 10.0, aj * aj / 10.0
    ir = 1.0 / r

    # UF: I lap Psi0 - grad grad Psi0,  Psi0 = (1 + al_i lap)(1 + al_j lap) chi_r
    s1, s2 = al_i + al_j, al_i * al_j
    psi1 = v[1, 0] + s1 * v[2, 0] + s2 * v[3, 0]
    d1 = v[0, 1] + s1 * v[1, 1] + s2 * v[2, 1]
    d2 = v[0, 2] + s1 * v[1, 2] + s2 * v[2, 2]
    a2 = d2 - d1 * ir
    b2 = d1 * ir
    for a in range(3):
        for b in range(3):
            out[a, b] += -a2 * e[a] * e[b]
        out[a, a] += psi1 - b2

    # UL and Omega-F: (1/2) eps grad (lap chi_r + al lap^2 chi_r) = (1/2) f' [e]x
    f_ul = 0.5 * (v[1, 1] + al_i * v[2, 1])
    f_of = 0.5 * (v[1, 1] + al_j * v[2, 1])
    for side in range(2):
        f = f_ul if side == 0 else f_of
        r0, c0 = (0, 3) if side == 0 else (3, 0)
        out[r0 + 0, c0 + 1] -= f * e[2]
        out[r0 + 0, c0 + 2] += f * e[1]
        out[r0 + 1, c0 + 0] += f * e[2]
        out[r0 + 1, c0 + 2] -= f * e[0]
        out[r0 + 2, c0 + 0] -= f * e[1]
        out[r0 + 2, c0 + 1] += f * e[0]

    # Omega-L: (1/4)(grad grad lap chi_r - I lap^2 chi_r)
    a2 = v[1, 2] - v[1, 1] * ir
    b2 = v[1, 1] * ir
    for m in range(3):
        for n in range(3):
            out[3 + m, 3 + n] += 0.25 * a2 * e[m] * e[n]
        out[3 + m, 3 + m] += 0.25 * (b2 - v[2, 0])

    # B^n . e and e . B^n . e
    be = work[51:66].reshape((5, 3))
    q = work[66:71]
    be[:, :] = 0.0
    q[:] = 0.0
    for n in range(5):
        for k in range(3):
            for l in range(3):
                be[n, k] += basis[n, k, l] * e[l]
        for k in range(3):
            q[n] += e[k] * be[n, k]

    # U-S:  -I.grad lap Gamma + grad^3 Gamma, Gamma = (1 + al_i lap)(1 + be_j lap) chi_r
    # E-F:  same with (be_i, al_j), transposed
    for side in range(2):
        if side == 0:
            t1, t2 = al_i + be_j, al_i * be_j
        else:
            t1, t2 = be_i + al_j, be_i * al_j
        g1 = v[1, 1] + t1 * v[2, 1] + t2 * v[3, 1]
        f1 = v[0, 1] + t1 * v[1, 1] + t2 * v[2, 1]
        f2 = v[0, 2] + t1 * v[1, 2] + t2 * v[2, 2]
        f3 = v[0, 3] + t1 * v[1, 3] + t2 * v[2, 3]
        c1 = f3 - 3 * f2 * ir + 3 * f1 * ir * ir
        c2 = f2 * ir - f1 * ir * ir
        for n in range(5):
            for a in range(3):
                val = (2 * c2 - g1) * be[n, a] + c1 * e[a] * q[n]
                if side == 0:
                    out[a, 6 + n] += val
                else:
                    out[6 + n, a] -= val

    # Omega-S and E-L:  -(1/2) A2 (e x B e)  and  (1/2) A2 (B e x e)
    for side in range(2):
        bb = be_j if side == 0 else be_i
        f1 = v[1, 1] + bb * v[2, 1]
        f2 = v[1, 2] + bb * v[2, 2]
        a2 = f2 - f1 * ir
        for n in range(5):
            for m in range(3):
                m1, m2 = (m + 1) % 3, (m + 2) % 3
                cross = e[m1] * be[n, m2] - e[m2] * be[n, m1]  # (e x B e)_m
                if side == 0:
                    out[3 + m, 6 + n] -= 0.5 * a2 * cross
                else:
                    out[6 + n, 3 + m] -= 0.5 * a2 * cross

    # E-S: -A2[L1] w - B2[L1] I + D1[L0] q q + 4 D2[L0] w + 2 D3[L0] I
    u1, u2 = be_i + be_j, be_i * be_j
    h1 = v[1, 1] + u1 * v[2, 1] + u2 * v[3, 1]
    h2 = v[1, 2] + u1 * v[2, 2] + u2 * v[3, 2]
    f1 = v[0, 1] + u1 * v[1, 1] + u2 * v[2, 1]
    f2 = v[0, 2] + u1 * v[1, 2] + u2 * v[2, 2]
    f3 = v[0, 3] + u1 * v[1, 3] + u2 * v[2, 3]
    f4 = v[0, 4] + u1 * v[1, 4] + u2 * v[2, 4]
    a2 = h2 - h1 * ir
    b2 = h1 * ir
    dd1 = f4 - 6 * f3 * ir + 15 * f2 * ir * ir - 15 * f1 * ir ** 3
    dd2 = f3 * ir - 3 * f2 * ir * ir + 3 * f1 * ir ** 3
    dd3 = f2 * ir * ir - f1 * ir ** 3
    for m in range(5):
        for n in range(5):
            w = be[m, 0] * be[n, 0] + be[m, 1] * be[n, 1] + be[m, 2] * be[n, 2]
            out[6 + m, 6 + n] += (4 * dd2 - a2) * w + dd1 * q[m] * q[n]
        out[6 + m, 6 + m] += 2 * dd3 - b2


@numba.njit(cache=True)
def _real_space_sum(pos, radii, pi, pj, shift, table, xi, basis, mob):
    """Adds the real-space Ewald sum over the pair images (pi, pj, shift) (or, with
    xi = 0 and zero shifts, the unbounded pair couplings) into the (11N, 11N) matrix mob.
    Each image pair is stored once: M_ji = M_ij^T (reciprocity) fills the other
    triangle, and for a self-image (i == j) adds the -n image. Consecutive images of the
    same pair (find_pairs lists them together) are summed before being added to mob."""
    bounds = _power_bounds(table)
    work = np.empty(80)
    block = np.zeros((NDOF, NDOF))
    rvec = np.empty(3)
    n_img = pi.shape[0]
    for p in range(n_img):
        i, j = pi[p], pj[p]
        for c in range(3):
            rvec[c] = pos[i, c] - pos[j, c] - shift[p, c]
        _pair_block(rvec, radii[i], radii[j], table, bounds, xi, basis, work, block)
        if p + 1 < n_img and pi[p + 1] == i and pj[p + 1] == j:
            continue
        for a in range(NDOF):
            for b in range(NDOF):
                mob[NDOF * i + a, NDOF * j + b] += block[a, b]
                mob[NDOF * j + b, NDOF * i + a] += block[a, b]
        block[:, :] = 0.0


# ---------------------------------------------------------------------------------
# reciprocal space and self terms (numpy + BLAS)
# ---------------------------------------------------------------------------------


@numba.njit(cache=True)
def _reciprocal_rows(pos, radii, kvec, xi, basis, z):
    """Rows of Z for the reciprocal sum: for wave vector k and each of the two unit
    vectors q normal to it, Z_i = R_i(k) q sqrt(h(k))/k exp(i k.x_i), real parts in rows
    [0, 2 nk), imaginary parts in rows [2 nk, 4 nk). R_i(k): U rows (1 - a^2 k^2/6) q,
    Omega rows (i/2) k x q, E rows i (1 - a^2 k^2/10) k.B^m.q."""
    nk = kvec.shape[0]
    n = pos.shape[0]
    q = np.empty((2, 3))
    kq = np.empty((2, 5))
    kxq = np.empty((2, 3))
    for kk in range(nk):
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
        q[0, 0], q[0, 1], q[0, 2] = a0 / norm, a1 / norm, a2 / norm
        q[1, 0] = (k1 * q[0, 2] - k2 * q[0, 1]) / kmag
        q[1, 1] = (k2 * q[0, 0] - k0 * q[0, 2]) / kmag
        q[1, 2] = (k0 * q[0, 1] - k1 * q[0, 0]) / kmag
        for t in range(2):
            for c in range(3):
                q[t, c] *= scale
            kxq[t, 0] = 0.5 * (k1 * q[t, 2] - k2 * q[t, 1])
            kxq[t, 1] = 0.5 * (k2 * q[t, 0] - k0 * q[t, 2])
            kxq[t, 2] = 0.5 * (k0 * q[t, 1] - k1 * q[t, 0])
            for m in range(5):
                acc = 0.0
                for a in range(3):
                    for b in range(3):
                        acc += kvec[kk, a] * basis[m, a, b] * q[t, b]
                kq[t, m] = acc
        for i in range(n):
            ph = k0 * pos[i, 0] + k1 * pos[i, 1] + k2 * pos[i, 2]
            cs, sn = math.cos(ph), math.sin(ph)
            a2i = radii[i] * radii[i] * ksq
            fu, fe = 1 - a2i / 6, 1 - a2i / 10
            col = NDOF * i
            for t in range(2):
                rr, ri = 2 * kk + t, 2 * nk + 2 * kk + t
                for c in range(3):  # U rows: real
                    z[rr, col + c] = fu * q[t, c] * cs
                    z[ri, col + c] = fu * q[t, c] * sn
                for c in range(3):  # Omega rows: imaginary
                    z[rr, col + 3 + c] = -kxq[t, c] * sn
                    z[ri, col + 3 + c] = kxq[t, c] * cs
                for m in range(5):  # E rows: imaginary
                    z[rr, col + 6 + m] = -fe * kq[t, m] * sn
                    z[ri, col + 6 + m] = fe * kq[t, m] * cs


def _reciprocal_matrix(pos, radii, kvec, xi, volume):
    """(2/V) sum over half-space k of Re[Z Z^H] (see _reciprocal_rows)."""
    n = pos.shape[0]
    z = np.empty((4 * kvec.shape[0], NDOF * n))
    _reciprocal_rows(pos, radii, kvec, xi, BASIS, z)
    return (2.0 / volume) * (z.T @ z)


def _gauss_moment(p, xi):
    """int_0^inf k^(2p) exp(-k^2/4xi^2) dk = Gamma(p + 1/2) (2 xi)^(2p+1) / 2."""
    return 0.5 * gamma_function(p + 0.5) * (2 * xi) ** (2 * p + 1)


def _h_integral(poly, xi):
    """int_0^inf P(k^2) h(k) dk for P given by coefficients in powers of k^2."""
    hpoly = np.array([1.0, 1 / (4 * xi * xi), 1 / (8 * xi ** 4)])
    total = np.convolve(poly, hpoly)
    return sum(c * _gauss_moment(p, xi) for p, c in enumerate(total))


def self_mobility(radius, xi=None):
    """Diagonal 11x11 self block: the isolated sphere, U = F/(6 pi a),
    Omega = L/(8 pi a^3), -E = -S 3/(20 pi a^3), minus (for xi given) the k-space
    Ewald field at r = 0, obtained from int d^3k/(2pi)^3 R(k) J^(k) R(k)^H with the
    angular averages <I - kk> = 2/3, and 1/5 for the strain block."""
    a = float(radius)
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
    return np.diag(diag)


# ---------------------------------------------------------------------------------
# parameters and the public entry point
# ---------------------------------------------------------------------------------


def _truncation_parameter(tol):
    """s with exp(-s^2) s^6 = tol: the reach, in units of 1/xi (real space) and 2 xi
    (reciprocal space), at which the slowest-decaying kernel (the 4th derivative of
    r erfc(xi r) times Faxen Laplacians) has fallen to tol relative to its scale."""
    s = math.sqrt(-math.log(tol))
    for _ in range(50):
        s = math.sqrt(-math.log(tol) + 6 * math.log(s))
    return s


@dataclass(frozen=True)
class EwaldParameters:
    """Splitting parameter xi, real-space cut-off r_c and reciprocal cut-off k_c."""

    xi: float
    rcut: float
    kcut: float

    @classmethod
    def choose(cls, lattice, n_particles, tol=1e-8, xi=None, cost_ratio=25.0):
        """Parameters for relative accuracy tol. Unless given, xi balances the
        real-space cost (pairs within r_c ~ N^2 r_c^3 / V, each a numba kernel) against
        the reciprocal cost (N^2 k_c^3 V, each a BLAS rank update); cost_ratio is the
        measured ratio of one kernel evaluation to one rank-update element."""
        s = _truncation_parameter(tol)
        if xi is None:
            xi = (2 * math.pi ** 3 * cost_ratio) ** (1 / 6) / lattice.volume ** (1 / 3)
        return cls(xi=float(xi), rcut=s / xi, kcut=2 * xi * s)


@dataclass
class FarFieldPlan:
    """What the far-field sums need besides the positions, fixed for a configuration and
    its small displacements (random finite differences must not see pairs cross the
    cut-off): Ewald parameters (None: unbounded), real-space pair images (i, j, shift),
    wave vectors, radial coefficient table, the self blocks per radius and the volume."""

    params: EwaldParameters | None
    images: tuple
    kvec: np.ndarray
    table: np.ndarray
    self_blocks: dict
    volume: float


@functools.lru_cache(maxsize=16)
def _cached_radial_table(xi):
    return radial_table(xi)


def plan_far_field(positions, radii, lattice=None, tol=1e-8, xi=None):
    """A FarFieldPlan for (wrapped) positions in the lattice (None: unbounded fluid)."""
    if lattice is None:
        images = find_pairs(positions, radii, None, np.inf, 0.0)
        return FarFieldPlan(None, images, np.zeros((0, 3)), _cached_radial_table(0.0),
                            {a: self_mobility(a) for a in np.unique(radii)}, np.inf)
    par = EwaldParameters.choose(lattice, len(positions), tol=tol, xi=xi)
    images = find_pairs(positions, radii, lattice, par.rcut, 0.0)
    return FarFieldPlan(par, images, lattice.wave_vectors(par.kcut), _cached_radial_table(par.xi),
                        {a: self_mobility(a, par.xi) for a in np.unique(radii)}, lattice.volume)


def far_field_mobility(positions, radii, box=None, strain=0.0, tol=1e-8, xi=None, plan=None):
    """The (11N, 11N) far-field grand mobility M_inf, symmetric positive definite for
    non-overlapping spheres.

    positions (N, 3), radii (N,); box (3,) for a periodic Lees-Edwards box at the given
    strain, or None for unbounded fluid (DBB 1987). Periodic sums are converged to
    relative accuracy ~tol; xi overrides the Ewald splitting parameter. With a plan
    (from `plan_far_field`), positions are used as given (not wrapped) with its pairs."""
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
    _real_space_sum(pos, radii, *plan.images, plan.table, xi_used, BASIS, mob)
    if plan.params is not None:
        mob += _reciprocal_matrix(pos, radii, plan.kvec, xi_used, plan.volume)
    for i, a in enumerate(radii):
        mob[NDOF * i : NDOF * (i + 1), NDOF * i : NDOF * (i + 1)] += plan.self_blocks[a]
    return mob
