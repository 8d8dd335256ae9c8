r"""Exact two-sphere resistance functions and the pair resistance matrix (lubrication).

Two rigid spheres of radii ``a1``, ``a2`` (size ratio ``lam = a2/a1``), centres ``x1``,
``x2``, ``d = (x2 - x1)/r`` the unit vector from sphere 1 to sphere 2, centre distance
``r``, scaled distance ``s = 2 r / (a1 + a2)`` and scaled gap ``xi = s - 2``.  Viscosity 1.

Scalar functions (Jeffrey & Onishi 1984 normalisation)
------------------------------------------------------
``resistance_scalars`` returns, per pair, the 4 blocks ``(alpha, beta) = 11, 12, 21, 22``
of the 11 functions ``XA, YA, YB, XC, YC, XG, YG, YH, XM, YM, ZM``, non-dimensional as
in Jeffrey & Onishi, J. Fluid Mech. 139, 261 (1984) [JO84] and Jeffrey, Phys. Fluids A 4,
16 (1992) [J92]: the dimensional block (alpha, beta) is the function times

    A: 3 pi (a_alpha + a_beta)      B: pi (a_alpha + a_beta)^2     C: pi (a_alpha + a_beta)^3
    G: pi (a_alpha + a_beta)^2      H: pi (a_alpha + a_beta)^3     M: (5/6) pi (a_alpha + a_beta)^3

so that an isolated sphere has ``XA11 = YA11 = XC11 = YC11 = XM11 = YM11 = ZM11 = 1``
for every ``lam``; the couplings and the odd functions vanish as ``s -> inf``. Block
relations (JO84 eq. 1.8): ``X_22(lam) = X_11(1/lam)``, ``X_21(lam) = X_12(1/lam)``, with
an extra minus sign for the functions odd in ``d`` (YB, XG, YG).

Tensor forms (Kim & Karrila, *Microhydrodynamics* (1991) ch. 11; J92), same ``d`` for all
four blocks::

    A_ij   = XA d_i d_j + YA (delta_ij - d_i d_j)        B_ij = YB eps_ijk d_k
    C_ij   = XC d_i d_j + YC (delta_ij - d_i d_j)
    G_ijk  = XG (d_i d_j - delta_ij/3) d_k + YG (d_i delta_jk + d_j delta_ik - 2 d_i d_j d_k)
    H_ijk  = YH (eps_ikl d_l d_j + eps_jkl d_l d_i)
    M_ijkl = XM d0_ijkl + YM d1_ijkl + ZM d2_ijkl      (the standard d^(0), d^(1), d^(2))

with the Kim-Karrila grand resistance (F, L on the particle, S its stresslet)
``(F, L, S) = [[A, Bt, Gt], [B, C, Ht], [G, H, M]] (U_inf - U, Omega_inf - Omega, E_inf)``
and ``Bt^{ab}_ij = B^{ba}_ji``, ``Gt^{ab}_ijk = G^{ba}_jki``, ``Ht^{ab}_ijk = H^{ba}_jki``.

Pair matrix (the sdmpi contract)
--------------------------------
``pair_resistance`` returns the dimensional 22 x 22 matrix ``R`` with ``F = R U`` for the
generalised velocity ``U_a = (U_a - U_inf(x_a), Omega_a - Omega_inf, -E_inf)`` and the
generalised force ``F_a = (F_a, L_a, -S_a)`` where ``F, L`` are exerted by the particle
ON the fluid and ``S`` is the particle stresslet (isolated sphere: ``S = (20/3) pi a^3 E``).
That is the Kim-Karrila matrix above, unchanged.  Per particle 11 rows: 3 U, 3 Omega and
5 strain components in the orthonormal basis of `sdmpi.hydro.basis`; particle 1's 11 rows
first.  ``R`` is symmetric positive definite.

Method
------
Every function but XC is a power series in ``t = 2/s`` whose coefficients come from the
multipole-reflection recurrences of JO84 and J92 as corrected by A. K. Townsend,
arXiv:1802.08226 (2018) (run once per process to order 200, numba; coefficients cached
per ``lam``), with the lubrication singularities ``g1/xi + g2 log(1/xi) + g3 xi log(1/xi)``
written exactly in ``s`` and subtracted from the series: one formula for all ``s > 2``,
no switch point. XC is Jeffery's exact bispherical sum (Proc. Lond. Math. Soc. 14, 327
(1915)). The derivation, the table of initial conditions and the accuracy (all functions
to ~1e-9 relative for ``xi >= 0.1``, the O(1) part near contact to ~1e-5, ``lam`` in
[1/8, 8]) are in docs/numerics.md, "Two-sphere resistance functions".
"""

from __future__ import annotations

import hashlib
import math
import os
import threading
from pathlib import Path

import numba as nb
import numpy as np

__all__ = ["resistance_scalars", "pair_resistance", "squeeze_slope", "FUNCTIONS", "BLOCKS", "SERIES_ORDER"]

#: order of the far-field series (number of terms in t = 2/s)
SERIES_ORDER = 200
#: names of the 11 scalar functions, in the order of the last axis of resistance_scalars
FUNCTIONS = ("XA", "YA", "YB", "XC", "YC", "XG", "YG", "YH", "XM", "YM", "ZM")
#: the pair blocks, in the order of axis 1 of resistance_scalars
BLOCKS = ("11", "12", "21", "22")

_SQ2 = math.sqrt(2.0)
_SQ6 = math.sqrt(6.0)

# ---------------------------------------------------------------------------------------
# recurrences (lam independent), numba


@nb.njit(cache=True)
def _binom_table(n):
    b = np.zeros((n + 1, n + 1))
    for i in range(n + 1):
        b[i, 0] = 1.0
        for j in range(1, i + 1):
            b[i, j] = b[i - 1, j - 1] + (b[i - 1, j] if j <= i - 1 else 0.0)
    return b


@nb.njit(cache=True)
def _get(a, n, p, q):
    if n < 0 or p < 0 or q < 0 or n >= a.shape[0] or p >= a.shape[1] or q >= a.shape[2]:
        return 0.0
    return a[n, p, q]


@nb.njit(cache=True)
def _s_upper(q):
    # P_{s,p,q'} (and V, Q) vanish for s > p + 1 unless (p, q') = (0, 0); the initial
    # conditions sit at n0 <= 2, hence the exception for q <= 2.
    if q <= 2:
        return q
    return min(q, (q + 3) // 2)


@nb.njit(cache=True)
def _recurrence_x(m_max, n0):
    """Axisymmetric (X) recurrence: JO84 (3.6)-(3.9); Townsend (2018) eqs. (5)-(8)."""
    nmax = m_max // 2 + 3
    P = np.zeros((nmax, m_max + 1, m_max + 1))
    V = np.zeros((nmax, m_max + 1, m_max + 1))
    b = _binom_table(2 * m_max + 4)
    P[n0, 0, 0] = 1.0
    V[n0, 0, 0] = 1.0
    for k in range(1, m_max + 1):
        for p in range(0, k + 1):
            q = k - p
            shi = _s_upper(q)
            for n in range(1, min(nmax, p + 2)):
                acc = 0.0
                acc2 = 0.0
                for s in range(1, shi + 1):
                    t = (n * (2 * n + 1) * (2 * n * s - n - s + 2)
                         / (2.0 * (n + 1) * (2 * s - 1) * (n + s)) * _get(P, s, q - s, p - n + 1)
                         - n * (2 * n - 1) / (2.0 * (n + 1)) * _get(P, s, q - s, p - n - 1)
                         - n * (4 * n * n - 1) / (2.0 * (n + 1) * (2 * s + 1))
                         * _get(V, s, q - s - 2, p - n + 1))
                    acc += b[n + s, n] * t
                    acc2 += b[n + s, n] * _get(P, s, q - s, p - n - 1)
                P[n, p, q] = acc
                V[n, p, q] = acc - 2.0 * n / ((n + 1) * (2 * n + 3.0)) * acc2
    return P


@nb.njit(cache=True)
def _recurrence_y(m_max, n0, p0, q0):
    """Transverse (Y) recurrence: JO84 (4.6)-(4.11), (7.3)-(7.5); J92 (58); Townsend (18)."""
    nmax = m_max // 2 + 3
    P = np.zeros((nmax, m_max + 1, m_max + 1))
    V = np.zeros((nmax, m_max + 1, m_max + 1))
    Q = np.zeros((nmax, m_max + 1, m_max + 1))
    b = _binom_table(2 * m_max + 4)
    P[n0, 0, 0] = p0
    V[n0, 0, 0] = p0
    Q[n0, 0, 0] = q0
    for k in range(1, m_max + 1):
        for p in range(0, k + 1):
            q = k - p
            shi = _s_upper(q)
            for n in range(1, min(nmax, p + 2)):
                acc_p = 0.0
                acc_q = 0.0
                acc_v = 0.0
                for s in range(1, shi + 1):
                    bb = b[n + s, n + 1]
                    acc_p += bb * ((2 * n + 1) / (2.0 * (n + 1))
                                   * (3.0 * (n + s) - (n * s + 1) * (2 * n * s - s - n + 2))
                                   / (s * (n + s) * (2 * s - 1.0)) * _get(P, s, q - s, p - n + 1)
                                   + n * (2 * n - 1) / (2.0 * (n + 1)) * _get(P, s, q - s, p - n - 1)
                                   + n * (4 * n * n - 1) / (2.0 * (n + 1) * (2 * s + 1))
                                   * _get(V, s, q - s - 2, p - n + 1)
                                   - 2.0 * (4 * n * n - 1) / (3.0 * (n + 1))
                                   * _get(Q, s, q - s - 1, p - n + 1))
                    acc_q += bb * (s / (n + 1.0) * _get(Q, s, q - s - 1, p - n)
                                   - 3.0 / (2.0 * n * s * (n + 1)) * _get(P, s, q - s, p - n))
                    acc_v += bb * _get(P, s, q - s, p - n - 1)
                P[n, p, q] = acc_p
                Q[n, p, q] = acc_q
                V[n, p, q] = acc_p + 2.0 * n / ((n + 1) * (2 * n + 3.0)) * acc_v
    return P, Q


@nb.njit(cache=True)
def _recurrence_z(m_max):
    """ZM recurrence: J92 (73)-(76) as corrected by Townsend (2018)."""
    nmax = m_max // 2 + 3
    P = np.zeros((nmax, m_max + 1, m_max + 1))
    V = np.zeros((nmax, m_max + 1, m_max + 1))
    Q = np.zeros((nmax, m_max + 1, m_max + 1))
    b = _binom_table(2 * m_max + 4)
    P[2, 0, 0] = 1.0
    V[2, 0, 0] = 1.0
    for k in range(1, m_max + 1):
        for p in range(0, k + 1):
            q = k - p
            shi = _s_upper(q)
            for n in range(2, min(nmax, p + 2)):
                acc_p = 0.0
                acc_q = 0.0
                acc_v = 0.0
                for s in range(2, shi + 1):
                    bb = b[n + s, n + 2]
                    acc_p += bb * (-2.0 * (2 * n + 1) * (2 * n - 1) / (n + 1)
                                   * _get(Q, s, q - s - 1, p - n + 1)
                                   + n * (2 * n + 1) * (2 * n - 1) / (2.0 * (n + 1) * (2 * s + 1))
                                   * _get(V, s, q - s - 2, p - n + 1)
                                   + (2 * n + 1) / (n + 1.0)
                                   * (n * s * (n + s - 2 * n * s - 2) - 4.0 * (2 * n * s - 4 * s - 4 * n + 2))
                                   / (2.0 * s * (n + s) * (2 * s - 1)) * _get(P, s, q - s, p - n + 1)
                                   + n * (2 * n - 1) / (2.0 * (n + 1)) * _get(P, s, q - s, p - n - 1))
                    acc_q += bb * (s / (n + 1.0) * _get(Q, s, q - s - 1, p - n)
                                   - 2.0 / (n * s * (n + 1.0)) * _get(P, s, q - s, p - n))
                    acc_v += bb * _get(P, s, q - s, p - n - 1)
                P[n, p, q] = acc_p
                Q[n, p, q] = acc_q
                V[n, p, q] = acc_p + 2.0 * n / ((n + 1) * (2 * n + 3.0)) * acc_v
    return P


# the 10 series functions (XC is exact, separate); index into FUNCTIONS
_SERIES = ("XA", "YA", "YB", "YC", "XG", "YG", "YH", "XM", "YM", "ZM")
_SERIES_IDX = np.array([FUNCTIONS.index(f) for f in _SERIES], dtype=np.int64)
# parity (0 even, 1 odd) of the 11 and 12 series
_PARITY = {"XA": (0, 1), "YA": (0, 1), "YB": (1, 0), "YC": (0, 1), "XG": (1, 0),
           "YG": (1, 0), "YH": (0, 1), "XM": (0, 1), "YM": (0, 1), "ZM": (0, 1)}
# functions odd in d: block 22 / 21 pick up a minus sign under lam -> 1/lam
_ODD_IN_D = {"YB", "XG", "YG"}

_TABLES = None
_TABLES_LOCK = threading.Lock()


def _cache_file(m_max):
    """Where the lambda polynomial tables are kept between processes: $SDMPI_CACHE_DIR or
    ~/.cache/sdmpi, keyed by the series order and a hash of this module's source (any
    edit of the recurrences invalidates it)."""
    digest = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
    root = Path(os.environ.get("SDMPI_CACHE_DIR", Path.home() / ".cache" / "sdmpi"))
    return root / f"two_sphere_m{m_max}_{digest}.npz"


def _lambda_polynomials(m_max=SERIES_ORDER):
    """{name: (T[k, j], shift)}: f_k(lam) / (2 (1 + lam))^k = sum_j T[k, j] x^j y^(k-j),
    x = lam/(1+lam), y = 1/(1+lam) (j may exceed k by one: y^-1 = 1 + lam).
    Computed once (~2 s), then read from a disk cache (`_cache_file`) by later processes."""
    global _TABLES
    with _TABLES_LOCK:
        if _TABLES is not None and _TABLES[0] == m_max:
            return _TABLES[1]
        path = _cache_file(m_max)
        try:
            with np.load(path) as data:
                out = {name: data[name] for name in FUNCTIONS if name != "XC"}
            _TABLES = (m_max, out)
            return out
        except (OSError, KeyError, ValueError):
            pass  # absent or unreadable: compute (and try to store) below
        out = _compute_polynomials(m_max)
        try:  # atomic: ranks starting together never read a half-written file
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
            np.savez(tmp, **out)
            os.replace(tmp, path)
        except OSError:
            pass  # a read-only home only costs the recomputation next time
        _TABLES = (m_max, out)
        return out


def _compute_polynomials(m_max):
    """The lambda polynomial tables of `_lambda_polynomials`, from the recurrences."""
    out = {}

    def take(T, n, scale, shift):
        c = np.zeros((m_max + 1, m_max + 2))
        for k in range(m_max + 1):
            q = np.arange(k + 1)
            c[k, q + (k % 2 if shift else 0)] += scale * T[n, k - q, q]
        return c

    P = _recurrence_x(m_max, 1)
    out["XA"] = take(P, 1, 1.0, False)
    out["XG"] = take(P, 2, 0.75, False)
    del P
    P = _recurrence_x(m_max, 2)
    out["XM"] = take(P, 2, 1.0, True)
    del P
    P, Q = _recurrence_y(m_max, 1, 1.0, 0.0)
    out["YA"] = take(P, 1, 1.0, False)
    out["YB"] = take(Q, 1, 2.0, False)
    out["YG"] = take(P, 2, 0.75, False)
    del P, Q
    P, Q = _recurrence_y(m_max, 1, 0.0, 1.0)
    out["YC"] = take(Q, 1, 1.0, True)
    out["YH"] = take(P, 2, -0.375, True)
    del P, Q
    P, _ = _recurrence_y(m_max, 2, 1.0, 0.0)
    out["YM"] = take(P, 2, 1.0, True)
    del P
    out["ZM"] = take(_recurrence_z(m_max), 2, 1.0, True)
    return out


def f_coefficients(name: str, lam: float, m_max: int = SERIES_ORDER) -> np.ndarray:
    """The JO84/J92 f_k(lam), k = 0..m_max, of a series function (for checks/tables).

    Args:
        name: a function of `FUNCTIONS`.
        lam: size ratio a2/a1.
        m_max: highest order k.

    Returns:
        (m_max + 1,) the dimensionless coefficients f_k(lam).
    """
    c = _lambda_polynomials(m_max)[name]
    k = np.arange(m_max + 1)
    j = np.arange(m_max + 2)
    return np.array([np.sum(c[kk] * lam ** j) * 2.0 ** kk for kk in k])


def _h_coefficients(c, lam):
    """a_k = f_k(lam) / (2 (1 + lam))^k from the polynomial table c (float-safe)."""
    m_max = c.shape[0] - 1
    x = lam / (1.0 + lam)
    y = 1.0 / (1.0 + lam)
    k = np.arange(m_max + 1)[:, None]
    j = np.arange(m_max + 2)[None, :]
    e = k - j
    w = np.where(e >= 0, x ** j * y ** np.maximum(e, 0), x ** j * (1.0 + lam) ** np.maximum(-e, 0))
    return np.sum(c * np.where(c != 0.0, w, 0.0), axis=1)


# ---------------------------------------------------------------------------------------
# near-contact coefficients (Townsend 2018 = corrected JO84 / J92), "h level":
#   h_11 = X_11,  X_12 = P12(lam) h_12;   h ~ G1/xi + G2 log(1/xi) + G3 xi log(1/xi)


def _singular_coefficients(name, lam):
    """((G1, G2, G3) for h_11, (G1, G2, G3) for h_12, P12) at size ratio lam."""
    l = lam
    l1 = 1.0 + l
    if name == "XA":
        g = (2 * l**2 / l1**3, l * (1 + 7 * l + l**2) / (5 * l1**3),
             (1 + 18 * l - 29 * l**2 + 18 * l**3 + l**4) / (42 * l1**3))
        return g, g, -2.0 / l1
    if name == "YA":
        g = (0.0, 4.0 / 15.0 * l * (2 + l + 2 * l**2) / l1**3,
             2.0 / 375.0 * (16 - 45 * l + 58 * l**2 - 45 * l**3 + 16 * l**4) / l1**3)
        return g, g, -2.0 / l1
    if name == "YB":
        g = (0.0, -l * (4 + l) / (5 * l1**2), -(32 - 33 * l + 83 * l**2 + 43 * l**3) / (250 * l1**2))
        return g, g, -4.0 / l1**2
    if name == "YC":
        g11 = (0.0, 2.0 / 5.0 * l / l1, (8 + 6 * l + 33 * l**2) / (125 * l1))
        g12 = (0.0, l**2 / (10 * l1), l * (43 - 24 * l + 43 * l**2) / (500 * l1))
        return g11, g12, 8.0 / l1**3
    if name == "XG":
        g = (3 * l**2 / l1**3, 3.0 / 10.0 * (l + 12 * l**2 - 4 * l**3) / l1**3,
             (5 + 181 * l - 453 * l**2 + 566 * l**3 - 65 * l**4) / (140 * l1**3))
        return g, g, -4.0 / l1**2
    if name == "YG":
        g = (0.0, (4 * l - l**2 + 7 * l**3) / (10 * l1**3),
             (32 - 179 * l + 532 * l**2 - 356 * l**3 + 221 * l**4) / (500 * l1**3))
        return g, g, -4.0 / l1**2
    if name == "YH":
        g11 = (0.0, (2 * l - l**2) / (10 * l1**2), (16 - 61 * l + 180 * l**2 + 2 * l**3) / (500 * l1**2))
        g12 = (0.0, (l**2 + 7 * l**3) / (20 * l1**2),
               (43 * l + 147 * l**2 - 185 * l**3 + 221 * l**4) / (1000 * l1**2))
        return g11, g12, 8.0 / l1**3
    if name == "XM":
        g11 = (6.0 / 5.0 * l**2 / l1**3, 3.0 / 25.0 * (l + 17 * l**2 - 9 * l**3) / l1**3,
               (5 + 272 * l - 831 * l**2 + 1322 * l**3 - 415 * l**4) / (350 * l1**3))
        g12 = (6.0 / 5.0 * l**3 / l1**3, 3.0 / 25.0 * (-4 * l**2 + 17 * l**3 - 4 * l**4) / l1**3,
               (-65 * l + 832 * l**2 - 1041 * l**3 + 832 * l**4 - 65 * l**5) / (350 * l1**3))
        return g11, g12, 8.0 / l1**3
    if name == "YM":
        g11 = (0.0, 6.0 / 25.0 * (l - l**2 + 4 * l**3) / l1**3,
               (24 - 201 * l + 882 * l**2 - 1182 * l**3 + 591 * l**4) / (625 * l1**3))
        g12 = (0.0, 3.0 / 50.0 * (7 * l**2 - 10 * l**3 + 7 * l**4) / l1**3,
               3.0 / 2500.0 * l * (221 - 728 * l + 1902 * l**2 - 728 * l**3 + 221 * l**4) / l1**3)
        return g11, g12, 8.0 / l1**3
    if name == "ZM":
        g = (0.0, 0.0, -3.0 / 10.0 * (l**2 + l**4) / l1**3)
        return g, g, -8.0 / l1**3
    raise KeyError(name)


def squeeze_slope(gap: np.ndarray | float, a1: np.ndarray | float, a2: np.ndarray | float) -> np.ndarray:
    """h |d/dh (f.R f)| of two spheres at surface gap h (dimensional, viscosity 1), where
    f.R f is their resistance to relative motion along the line of centres for the unit
    pair force f (e on sphere 2, -e on sphere 1; |f|^2 = 2):
    f.R f = A11 + A22 - 2 A12 along d, A_ab = 3 pi (a_a + a_b) X^A_ab. With the near-contact
    forms X^A_11 ~ G1/xi + G2 log(1/xi) + G3 xi log(1/xi), X^A_12 = -2/(1 + lam) times the
    same, xi = 2h/(a1 + a2), lam = a2/a1, and X^A_22(lam) = X^A_11(1/lam) with
    lam Gk(1/lam) = Gk(lam) (Jeffrey & Onishi, J. Fluid Mech. 139, 261 (1984); Townsend
    2018), f.R f ~ 24 pi a1 X^A_11, whose -xi d/dxi is G1/xi + G2 + G3 xi (1 - log(1/xi));
    the regular remainder of X^A changes the result by O(h) relative. gap, a1, a2
    broadcast.

    Args:
        gap: surface gaps h (length unit of the radii).
        a1: radii of the first spheres.
        a2: radii of the second spheres.

    Returns:
        h |d/dh (f.R f)| (a resistance, viscosity 1 x length), broadcast shape.
    """
    gap, a1, a2 = (np.asarray(v, dtype=float) for v in (gap, a1, a2))
    xi = 2.0 * gap / (a1 + a2)
    lam = a2 / a1
    if lam.size and lam.min() == lam.max():  # one size ratio: the coefficients once
        lam = float(lam.flat[0])
    (g1, g2, g3), _, _ = _singular_coefficients("XA", lam)
    return 24.0 * math.pi * a1 * (g1 / xi + g2 + g3 * xi * (1.0 + np.log(xi)))


def _basis_taylor(m_max, parity):
    """Taylor coefficients in t of the three exact singular functions (module docstring)."""
    m = np.arange(m_max + 1)
    out = np.zeros((3, m_max + 1))
    if parity == 0:
        ev = m % 2 == 0
        out[0, ev] = 1.0
        sel = ev & (m > 0)
        out[1, sel] = 2.0 / m[sel]
        out[2, 2] = 1.0
        sel = ev & (m >= 4)
        out[2, sel] = -4.0 / (m[sel] * (m[sel] - 2.0))
    else:
        od = m % 2 == 1
        out[0, od] = 1.0
        out[1, od] = 2.0 / m[od]
        out[2, 1] = 2.0
        sel = od & (m >= 3)
        out[2, sel] = -4.0 / (m[sel] * (m[sel] - 2.0))
    return out


_LAM_CACHE: dict = {}
_LAM_LOCK = threading.Lock()


def _per_lambda(lam):
    """(rem (10, 2, M+1), G (10, 2, 3), par (10, 2), pref (10, 2)) for blocks 11, 12."""
    key = float(lam)
    with _LAM_LOCK:
        hit = _LAM_CACHE.get(key)
    if hit is not None:
        return hit
    tabs = _lambda_polynomials()
    m_max = SERIES_ORDER
    basis = (_basis_taylor(m_max, 0), _basis_taylor(m_max, 1))
    nf = len(_SERIES)
    rem = np.zeros((nf, 2, m_max + 1))
    gg = np.zeros((nf, 2, 3))
    par = np.zeros((nf, 2), dtype=np.int64)
    pref = np.ones((nf, 2))
    for i, name in enumerate(_SERIES):
        a = _h_coefficients(tabs[name], key)
        g11, g12, p12 = _singular_coefficients(name, key)
        for b, g in enumerate((g11, g12)):
            p = _PARITY[name][b]
            mask = (np.arange(m_max + 1) % 2) == p
            rem[i, b] = np.where(mask, a - np.asarray(g) @ basis[p], 0.0)
            gg[i, b] = g
            par[i, b] = p
        pref[i, 1] = p12
    out = (rem, gg, par, pref)
    with _LAM_LOCK:
        if len(_LAM_CACHE) > 4096:
            _LAM_CACHE.clear()
        _LAM_CACHE[key] = out
    return out


def _tables_for(lams):
    """Stack per-lambda tables for the 4 blocks (11, 12 at lam; 21, 22 from 1/lam)."""
    nl = len(lams)
    m_max = SERIES_ORDER
    nf = len(_SERIES)
    rem = np.zeros((nl, nf, 4, m_max + 1))
    gg = np.zeros((nl, nf, 4, 3))
    par = np.zeros((nl, nf, 4), dtype=np.int64)
    pref = np.zeros((nl, nf, 4))
    sign = np.array([-1.0 if n in _ODD_IN_D else 1.0 for n in _SERIES])
    for il, lam in enumerate(lams):
        r1, g1, p1, f1 = _per_lambda(lam)
        r2, g2, p2, f2 = _per_lambda(1.0 / lam)
        rem[il, :, 0], rem[il, :, 1] = r1[:, 0], r1[:, 1]
        rem[il, :, 2], rem[il, :, 3] = r2[:, 1], r2[:, 0]
        gg[il, :, 0], gg[il, :, 1] = g1[:, 0], g1[:, 1]
        gg[il, :, 2], gg[il, :, 3] = g2[:, 1], g2[:, 0]
        par[il, :, 0], par[il, :, 1] = p1[:, 0], p1[:, 1]
        par[il, :, 2], par[il, :, 3] = p2[:, 1], p2[:, 0]
        pref[il, :, 0], pref[il, :, 1] = f1[:, 0], f1[:, 1]
        pref[il, :, 2], pref[il, :, 3] = sign * f2[:, 1], sign * f2[:, 0]
    return rem, gg, par, pref


# ---------------------------------------------------------------------------------------
# per-pair kernels


@nb.njit(cache=True)
def _csch3_sum(c0, h, scale_arg):
    """sinh^3(scale_arg) * sum_{n>=0} csch^3(c0 + n h), overflow-safe (c0 >= scale_arg)."""
    total = 0.0
    n = 0
    u = c0
    while u < 3.0:
        r = math.exp(scale_arg - u) * (-math.expm1(-2.0 * scale_arg)) / (-math.expm1(-2.0 * u))
        total += r * r * r
        n += 1
        u = c0 + n * h
    # tail, u >= 3: csch^3 v = 8 sum_j C(j+2,2) exp(-(3+2j) v), geometric in n
    w = 0.5 * math.exp(scale_arg - u) * (-math.expm1(-2.0 * scale_arg))  # sinh(a) e^{-u}
    base = 8.0 * w * w * w
    e2 = math.exp(-2.0 * u)
    j = 0
    ej = 1.0
    while True:
        term = base * 0.5 * (j + 1) * (j + 2) * ej / (-math.expm1(-(3.0 + 2.0 * j) * h))
        total += term
        if term <= 1e-18 * total or j > 200:
            break
        j += 1
        ej *= e2
    return total


@nb.njit(cache=True)
def _xc_exact(r, a1, a2):
    """(XC11, XC12, XC21, XC22), JO normalisation, Jeffery (1915) bispherical series."""
    lam = a2 / a1
    gap = r - a1 - a2
    u1 = gap * (r - a1 + a2) / (2.0 * r * a1)
    u2 = gap * (r - a2 + a1) / (2.0 * r * a2)
    al = math.log1p(u1 + math.sqrt(u1 * (u1 + 2.0)))
    be = math.log1p(u2 + math.sqrt(u2 * (u2 + 2.0)))
    h = al + be
    x11 = _csch3_sum(al, h, al)
    x22 = _csch3_sum(be, h, be)
    x12 = -8.0 / (1.0 + lam) ** 3 * _csch3_sum(h, h, al)
    x21 = -8.0 / (1.0 + 1.0 / lam) ** 3 * _csch3_sum(h, h, be)
    return x11, x12, x21, x22


@nb.njit(cache=True)
def _scalars_one(r, a1, a2, rem, gg, par, pref, out):
    """Fill out (4, 11) with the JO-normalised functions of one pair."""
    s = 2.0 * r / (a1 + a2)
    xi = 2.0 * (r - a1 - a2) / (a1 + a2)
    t = 2.0 / s
    omt2 = xi * (4.0 + xi) / (s * s)          # 1 - t^2
    lev = -math.log(omt2)                     # -log(1 - t^2)
    lod = math.log((s + 2.0) / xi)            # log((1+t)/(1-t))
    ev0 = 1.0 / omt2
    od0 = t / omt2
    m_max = rem.shape[3] - 1
    t2 = t * t
    nf = rem.shape[1]
    for f in range(nf):
        fi = _SERIES_IDX[f]
        for b in range(4):
            p = par[0, f, b]
            if p == 0:
                s0 = ev0
                s1 = lev
                s2 = omt2 * lev
                m = m_max if m_max % 2 == 0 else m_max - 1
            else:
                s0 = od0
                s1 = lod
                s2 = omt2 * lod
                m = m_max if m_max % 2 == 1 else m_max - 1
            acc = 0.0
            while m >= 0:
                acc = acc * t2 + rem[0, f, b, m]
                m -= 2
            if p == 1:
                acc *= t
            h = gg[0, f, b, 0] * s0 + gg[0, f, b, 1] * s1 + gg[0, f, b, 2] * s2 + acc
            out[b, fi] = pref[0, f, b] * h
    x11, x12, x21, x22 = _xc_exact(r, a1, a2)
    out[0, 3] = x11
    out[1, 3] = x12
    out[2, 3] = x21
    out[3, 3] = x22


@nb.njit(cache=True)
def _scalars_kernel(r, a1, a2, lidx, rem, gg, par, pref):
    n = r.shape[0]
    out = np.zeros((n, 4, 11))
    for i in range(n):
        li = lidx[i]
        _scalars_one(r[i], a1[i], a2[i], rem[li:li + 1], gg[li:li + 1], par[li:li + 1],
                     pref[li:li + 1], out[i])
    return out


#: B^m entries of `basis.BASIS`: 1/sqrt2 and 1/sqrt6
_R2 = 1.0 / _SQ2
_R6 = 1.0 / _SQ6
#: length of the scratch array of `_fill_pair_columns`
FILL_SCRATCH = 140


@nb.njit(cache=True)
def _fill_pair_columns(d, a1, a2, sc, R, pat, rigid_columns):
    """The 22x22 pair matrix R from the scalars sc (4, 11) and the unit vector d (tensor
    forms of the module docstring), with caller-provided scratch pat (FILL_SCRATCH,): the
    tensors of d are formed once, each distinct entry of a block is computed once and
    written to its mirror positions as well. Every entry is written (none accumulated),
    so R needs no zeroing between pairs. rigid_columns: only the columns of the
    rigid-body dofs (U, Omega of either sphere: 0-5, 11-16) are written (for products
    with vectors that are zero on the strain dofs), the others are left as they were."""
    d0, d1, d2 = d[0], d[1], d[2]
    # bd[3 m + i] = (B^m d)_i (basis.BASIS), e[m] = d.B^m.d
    bd, e = pat[0:15], pat[15:20]
    bd[0], bd[1], bd[2] = _R2 * d0, -_R2 * d1, 0.0
    bd[3], bd[4], bd[5] = -_R6 * d0, -_R6 * d1, 2.0 * _R6 * d2
    bd[6], bd[7], bd[8] = _R2 * d1, _R2 * d0, 0.0
    bd[9], bd[10], bd[11] = _R2 * d2, 0.0, _R2 * d0
    bd[12], bd[13], bd[14] = 0.0, _R2 * d2, _R2 * d1
    for m in range(5):
        e[m] = d0 * bd[3 * m] + d1 * bd[3 * m + 1] + d2 * bd[3 * m + 2]
    # [3 m + k] of G = XG p1 + YG p2 and H = YH p3: B^m_ij (d_i d_j - delta_ij/3) d_k,
    # B^m_ij (d_i delta_jk + d_j delta_ik - 2 d_i d_j d_k), B^m_ij (v_i d_j + v_j d_i) with
    # v = e_k x d (B^m traceless)
    p1, p2, p3 = pat[20:35], pat[35:50], pat[50:65]
    for m in range(5):
        b0, b1, b2 = bd[3 * m], bd[3 * m + 1], bd[3 * m + 2]
        for k in range(3):
            p1[3 * m + k] = e[m] * d[k]
            p2[3 * m + k] = 2.0 * (bd[3 * m + k] - e[m] * d[k])
        p3[3 * m] = 2.0 * (d1 * b2 - d2 * b1)
        p3[3 * m + 1] = 2.0 * (d2 * b0 - d0 * b2)
        p3[3 * m + 2] = 2.0 * (d0 * b1 - d1 * b0)
    # [5 m + n] (m <= n) of M = XM p4 + YM p5 + ZM p6: B^m : d^(0,1,2) : B^n, with
    # q = (d.B^m.d)(d.B^n.d), c = (B^m d).(B^n d) and B^m : B^n = delta_mn
    p4, p5, p6 = pat[65:90], pat[90:115], pat[115:140]
    if not rigid_columns:
        for m in range(5):
            for n in range(m, 5):
                q = e[m] * e[n]
                c = bd[3 * m] * bd[3 * n] + bd[3 * m + 1] * bd[3 * n + 1] + bd[3 * m + 2] * bd[3 * n + 2]
                p4[5 * m + n] = 1.5 * q
                p5[5 * m + n] = 2.0 * (c - q)
                p6[5 * m + n] = (1.0 if m == n else 0.0) - 2.0 * c + 0.5 * q
    dd00, dd11, dd22 = d0 * d0, d1 * d1, d2 * d2
    dd01, dd02, dd12 = d0 * d1, d0 * d2, d1 * d2
    for ia in range(2):
        for ib in range(2):
            blk = 2 * ia + ib
            asum = (a1 if ia == 0 else a2) + (a1 if ib == 0 else a2)
            pA = 3.0 * math.pi * asum
            pB = math.pi * asum * asum  # B and G
            pC = pB * asum  # C and H
            pM = 5.0 / 6.0 * pC
            r0 = 11 * ia
            c0 = 11 * ib
            # A (offset 0) and C (offset 3): X d_i d_j + Y (delta_ij - d_i d_j)
            for o, X, Y in ((0, pA * sc[blk, 0], pA * sc[blk, 1]), (3, pC * sc[blk, 3], pC * sc[blk, 4])):
                Z = X - Y
                v01, v02, v12 = Z * dd01, Z * dd02, Z * dd12
                R[r0 + o, c0 + o] = Y + Z * dd00
                R[r0 + o, c0 + o + 1] = v01
                R[r0 + o, c0 + o + 2] = v02
                R[r0 + o + 1, c0 + o] = v01
                R[r0 + o + 1, c0 + o + 1] = Y + Z * dd11
                R[r0 + o + 1, c0 + o + 2] = v12
                R[r0 + o + 2, c0 + o] = v02
                R[r0 + o + 2, c0 + o + 1] = v12
                R[r0 + o + 2, c0 + o + 2] = Y + Z * dd22
            # B^{ab}: L_a = B U_b = YB (U x d), (r0 + 3 + i, c0 + k) = YB (e_k x d)_i; Bt^{ba} = (B^{ab})^T
            YB = pB * sc[blk, 2]
            b0, b1, b2 = YB * d0, YB * d1, YB * d2
            R[r0 + 3, c0] = 0.0
            R[r0 + 3, c0 + 1] = b2
            R[r0 + 3, c0 + 2] = -b1
            R[r0 + 4, c0] = -b2
            R[r0 + 4, c0 + 1] = 0.0
            R[r0 + 4, c0 + 2] = b0
            R[r0 + 5, c0] = b1
            R[r0 + 5, c0 + 1] = -b0
            R[r0 + 5, c0 + 2] = 0.0
            R[c0, r0 + 3] = 0.0
            R[c0, r0 + 4] = -b2
            R[c0, r0 + 5] = b1
            R[c0 + 1, r0 + 3] = b2
            R[c0 + 1, r0 + 4] = 0.0
            R[c0 + 1, r0 + 5] = -b0
            R[c0 + 2, r0 + 3] = -b1
            R[c0 + 2, r0 + 4] = b0
            R[c0 + 2, r0 + 5] = 0.0
            # G^{ab}: S_a = G U_b ; H^{ab}: S_a = H Omega_b ; transposes for Gt, Ht
            XG = pB * sc[blk, 5]
            YG = pB * sc[blk, 6]
            YH = pC * sc[blk, 7]
            for m in range(5):
                for k in range(3):
                    g = XG * p1[3 * m + k] + YG * p2[3 * m + k]
                    h = YH * p3[3 * m + k]
                    R[r0 + 6 + m, c0 + k] = g
                    R[r0 + 6 + m, c0 + 3 + k] = h
                    if not rigid_columns:
                        R[c0 + k, r0 + 6 + m] = g
                        R[c0 + 3 + k, r0 + 6 + m] = h
            if rigid_columns:
                continue
            # M^{ab}: S_a = M : E_b, in the 5-basis (symmetric)
            XM = pM * sc[blk, 8]
            YM = pM * sc[blk, 9]
            ZM = pM * sc[blk, 10]
            for m in range(5):
                for n in range(m, 5):
                    val = XM * p4[5 * m + n] + YM * p5[5 * m + n] + ZM * p6[5 * m + n]
                    R[r0 + 6 + m, c0 + 6 + n] = val
                    R[r0 + 6 + n, c0 + 6 + m] = val


@nb.njit(cache=True)
def _pair_kernel(dx, a1, a2, lidx, rem, gg, par, pref):
    n = dx.shape[0]
    out = np.zeros((n, 22, 22))
    sc = np.zeros((4, 11))
    d = np.zeros(3)
    pat = np.empty(FILL_SCRATCH)
    for p in range(n):
        r = math.sqrt(dx[p, 0] ** 2 + dx[p, 1] ** 2 + dx[p, 2] ** 2)
        for i in range(3):
            d[i] = dx[p, i] / r
        li = lidx[p]
        _scalars_one(r, a1[p], a2[p], rem[li:li + 1], gg[li:li + 1], par[li:li + 1],
                     pref[li:li + 1], sc)
        _fill_pair_columns(d, a1[p], a2[p], sc, out[p], pat, False)
    return out


# ---------------------------------------------------------------------------------------
# public API


def _prepare(r, a1, a2):
    r = np.atleast_1d(np.asarray(r, dtype=float))
    n = r.shape[0]
    a1 = np.broadcast_to(np.asarray(a1, dtype=float), (n,)).copy()
    a2 = np.broadcast_to(np.asarray(a2, dtype=float), (n,)).copy()
    if np.any(~np.isfinite(r)) or np.any(a1 <= 0) or np.any(a2 <= 0):
        raise ValueError("two_sphere: need finite r and positive radii")
    if np.any(r <= a1 + a2):
        bad = int(np.argmax(r <= a1 + a2))
        raise ValueError(f"two_sphere: overlapping or touching spheres (pair {bad}: r = {r[bad]!r}, "
                         f"a1 + a2 = {a1[bad] + a2[bad]!r}); need r > a1 + a2")
    lam = a2 / a1
    ulam, lidx = np.unique(lam, return_inverse=True)
    return r, a1, a2, ulam, lidx.astype(np.int64)


def resistance_scalars(r: np.ndarray | float, a1: np.ndarray | float, a2: np.ndarray | float) -> np.ndarray:
    """Non-dimensional two-sphere resistance functions, shape (npairs, 4, 11).

    Axis 1: blocks 11, 12, 21, 22; axis 2: XA, YA, YB, XC, YC, XG, YG, YH, XM, YM, ZM
    (`FUNCTIONS`), in the Jeffrey & Onishi (1984) / Jeffrey (1992) normalisation (module
    docstring).  ``r``, ``a1``, ``a2`` broadcast to (npairs,); requires ``r > a1 + a2``.

    Args:
        r: (npairs,) centre distances (length unit of the radii).
        a1: (npairs,) radii of the first spheres (or a scalar).
        a2: (npairs,) radii of the second spheres (or a scalar).

    Returns:
        (npairs, 4, 11) dimensionless resistance functions.

    Raises:
        ValueError: touching or overlapping spheres (r <= a1 + a2), r not finite or a
            radius not > 0.
    """
    r, a1, a2, ulam, lidx = _prepare(r, a1, a2)
    rem, gg, par, pref = _tables_for(ulam)
    return _scalars_kernel(r, a1, a2, lidx, rem, gg, par, pref)


def pair_resistance(dx: np.ndarray, a1: np.ndarray | float, a2: np.ndarray | float) -> np.ndarray:
    """Dimensional pair resistance matrices, shape (npairs, 22, 22).

    ``dx`` (npairs, 3) = x2 - x1; ``a1``, ``a2`` radii (scalars or (npairs,)).  Viscosity
    1, sdmpi sign convention: ``(F, L, -S) = R (U - U_inf, Omega - Omega_inf, -E_inf)``
    with F, L exerted on the fluid (module docstring).  Symmetric positive definite.

    Args:
        dx: (npairs, 3) or (3,) separations x2 - x1 (length unit of the radii).
        a1: (npairs,) radii of the first spheres (or a scalar).
        a2: (npairs,) radii of the second spheres (or a scalar).

    Returns:
        (npairs, 22, 22) resistance matrices, dofs (U, Omega, E) of sphere 1 then sphere 2.

    Raises:
        ValueError: dx of the wrong shape, touching or overlapping spheres (r <= a1 + a2),
            or a radius not > 0.
    """
    dx = np.asarray(dx, dtype=float)
    if dx.ndim == 1:
        dx = dx[None, :]
    if dx.ndim != 2 or dx.shape[1] != 3:
        raise ValueError("pair_resistance: dx must have shape (npairs, 3)")
    if dx.shape[0] == 0:
        return np.zeros((0, 22, 22))
    r = np.sqrt(np.einsum("ij,ij->i", dx, dx))
    r, a1, a2, ulam, lidx = _prepare(r, a1, a2)
    rem, gg, par, pref = _tables_for(ulam)
    return _pair_kernel(np.ascontiguousarray(dx), a1, a2, lidx, rem, gg, par, pref)
