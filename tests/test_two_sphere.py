"""Tests of sdmpi.hydro.two_sphere (exact two-sphere resistance functions).

Independent references used here (none of them is the code under test):
* Stimson & Jeffery, Proc. R. Soc. A 111, 110 (1926): bispherical series for two equal
  spheres translating together along their line of centres (= XA11 + XA12 at lam = 1).
* Jeffery, Proc. Lond. Math. Soc. 14, 327 (1915) contact limit zeta(3, lam/(1+lam)) of XC
  (Townsend 2018 eq. 26), and the JO84 f_k of XC tabulated in K. Ichiki's libstokes
  (src/XC.c) -- the code evaluates XC from the bispherical sum, not from these f_k.
* Low-order f_k(lam) printed in JO84 / J92 and tabulated in libstokes (src/XA.c, YB.c,
  XG.c, YH.c), which the recurrences must reproduce exactly (they are rational).
* Method of reflections (Stokeslet, rotlet, Faxen laws) for the leading far-field
  couplings: fixes every sign and prefactor convention independently of the papers.
"""

import math

import numpy as np
import pytest
from scipy.special import zeta

from sdmpi.hydro import two_sphere as ts
from sdmpi.hydro.basis import BASIS

F = {name: i for i, name in enumerate(ts.FUNCTIONS)}
B11, B12, B21, B22 = range(4)
LAMS = (0.25, 1.0, 4.0)


def r_of(s, lam, a1=1.0):
    return s * a1 * (1.0 + lam) / 2.0


def scal(s, lam):
    return ts.resistance_scalars(r_of(np.atleast_1d(s), lam), 1.0, lam)


# ---------------------------------------------------------------------------- far field

@pytest.mark.parametrize("lam", LAMS)
def test_isolated_sphere_limit(lam):
    v = scal(1e6, lam)[0]
    # self functions -> 1 (JO normalisation); first correction is O(s^-3 .. s^-4) ~ 1e-18
    for name in ("XA", "YA", "XC", "YC", "XM", "YM", "ZM"):
        assert v[B11, F[name]] == pytest.approx(1.0, abs=1e-9)
        assert v[B22, F[name]] == pytest.approx(1.0, abs=1e-9)
    for name in ("YB", "XG", "YG", "YH"):
        assert abs(v[B11, F[name]]) < 1e-9 and abs(v[B22, F[name]]) < 1e-9
    # couplings decay at least like 1/s (XA12 ~ 3 lam/(...) / s)
    assert np.all(np.abs(v[[B12, B21]]) < 10.0 / 1e6)
    # dimensional: 6 pi a, 8 pi a^3, (20/3) pi a^3 on the diagonal blocks, nothing else
    a1, a2 = 1.3, 1.3 * lam
    R = ts.pair_resistance(np.array([[0.0, 0.0, 1e6]]), a1, a2)[0]
    expect = np.zeros((22, 22))
    for k, a in enumerate((a1, a2)):
        o = 11 * k
        expect[o:o + 3, o:o + 3] = 6 * np.pi * a * np.eye(3)
        expect[o + 3:o + 6, o + 3:o + 6] = 8 * np.pi * a**3 * np.eye(3)
        expect[o + 6:o + 11, o + 6:o + 11] = 20 / 3 * np.pi * a**3 * np.eye(5)
    np.testing.assert_allclose(R, expect, atol=1e-4 * np.abs(expect).max())


@pytest.mark.parametrize("lam", LAMS)
def test_reflections_leading_couplings(lam):
    """Leading far-field couplings from Stokeslet / rotlet + Faxen (sign + prefactor)."""
    a1, a2 = 1.0, lam
    r = 1e3 * (a1 + a2)
    s = 2 * r / (a1 + a2)
    v = ts.resistance_scalars(r, a1, a2)[0]
    # relative size of the next reflection is O((a/r)^2) ~ 1e-6
    tol = dict(rel=1e-4)
    # XA12: force on fixed sphere 1 from sphere 2 moving along d: -A12 U2, Stokeslet 6 pi a2 U2
    # felt through Faxen: F1 = 6 pi a1 (6 pi a2 U2 / (8 pi r)) 2  -> A12 = -9 pi a1 a2 / r
    assert 3 * np.pi * (a1 + a2) * v[B12, F["XA"]] == pytest.approx(-9 * np.pi * a1 * a2 / r, **tol)
    assert 3 * np.pi * (a1 + a2) * v[B12, F["YA"]] == pytest.approx(-4.5 * np.pi * a1 * a2 / r, **tol)
    # rotlet of sphere 2 (u = Omega2 x rho a2^3/rho^3) drags fixed sphere 1:
    # F1 = +YB21 pi (a1+a2)^2 (Omega2 x d) = -6 pi a1 a2^3 (Omega2 x d)/r^2
    assert np.pi * (a1 + a2) ** 2 * v[B21, F["YB"]] == pytest.approx(-6 * np.pi * a1 * a2**3 / r**2, **tol)
    # sphere 1 rotating, fixed sphere 2 reflects a Stokeslet: F1 = YB11 P (Omega1 x d)
    # = -(9/2) pi a1^4 a2 / r^3 (Omega1 x d)
    assert np.pi * (2 * a1) ** 2 * v[B11, F["YB"]] == pytest.approx(-4.5 * np.pi * a1**4 * a2 / r**3, **tol)
    # torque on fixed sphere 1 from rotating sphere 2: axial 8 pi a1^3 a2^3/r^3, transverse -1/2 of it
    pc = np.pi * (a1 + a2) ** 3
    assert pc * v[B12, F["XC"]] == pytest.approx(-8 * np.pi * a1**3 * a2**3 / r**3, **tol)
    assert pc * v[B12, F["YC"]] == pytest.approx(4 * np.pi * a1**3 * a2**3 / r**3, **tol)
    # stresslet of fixed sphere 1 in the Stokeslet of sphere 2: S1 = -XG12 pi(a1+a2)^2 (dd-I/3) U
    # = 15 pi a1^3 a2 U / r^2 (dd - I/3)
    assert np.pi * (a1 + a2) ** 2 * v[B12, F["XG"]] == pytest.approx(-15 * np.pi * a1**3 * a2 / r**2, **tol)
    # stresslet in the rotlet strain of sphere 2: YH12 pi (a1+a2)^3 = 10 pi a1^3 a2^3 / r^3
    assert pc * v[B12, F["YH"]] == pytest.approx(10 * np.pi * a1**3 * a2**3 / r**3, **tol)
    del s


# published rational low-order f_k (JO84 / J92; libstokes XA.c, YB.c, XG.c, YH.c)
PUBLISHED_F = {
    "XA": {2: [0, 9], 3: [0, -4, 27, -4], 4: [0, -24, 81, 36], 6: [0, 16, 108, 281, 648, 144],
           7: [0, 0, 288, 1620, 1515, 1620, 288]},
    "YA": {3: [0, 2, 3.375, 2], 6: [0, 4, 54, 19.390625, 81, 72]},
    "YB": {2: [0, -6], 5: [0, -12, -20.25, -36], 7: [0, 0, -189, -525.5625, -243, -144]},
    "XG": {2: [0, 15], 4: [0, -36, 135, -60], 7: [0, 144, 108, -1251, 4860, 2160]},
    "YH": {3: [0, 0, 0, 10], 6: [0, 24, 0, -120], 8: [0, 0, 54, 1280, 270, -1280]},
}


@pytest.mark.parametrize("name", sorted(PUBLISHED_F))
def test_recurrence_reproduces_published_f(name):
    for lam in (0.3, 1.0, 2.5):
        f = ts.f_coefficients(name, lam, ts.SERIES_ORDER)
        for k, poly in PUBLISHED_F[name].items():
            expect = sum(c * lam**j for j, c in enumerate(poly))
            assert f[k] == pytest.approx(expect, rel=1e-13, abs=1e-13)


# JO84 f_k of XC (libstokes src/XC.c): coefficient lists {k: {power: coeff}}
XC_F = {0: {0: 1}, 3: {3: 8}, 6: {3: 64}, 8: {5: 768}, 9: {6: 512}, 10: {7: 6144},
        11: {6: 6144, 8: 6144}, 12: {6: 4096, 9: 40960},
        13: {6: 49152, 8: 98304, 10: 49152}, 14: {6: 49152, 8: 98304, 11: 245760},
        15: {6: 327680, 8: 983040, 9: 32768, 10: 983040, 12: 327680},
        16: {6: 393216, 8: 1572864, 10: 1376256, 13: 1376256},
        17: {6: 1966080, 8: 7864320, 9: 786432, 10: 11796480, 11: 786432, 12: 7864320,
             14: 1966080}}


@pytest.mark.parametrize("lam", LAMS)
def test_xc_bispherical_matches_series(lam):
    # s = 10, f_k to k = 17: the first omitted term is < 1e-13 relative
    s = 10.0
    v = scal(s, lam)[0]
    x = s * (1 + lam)
    f = {k: sum(c * lam**p for p, c in d.items()) for k, d in XC_F.items()}
    x11 = sum(fk / x**k for k, fk in f.items() if k % 2 == 0)
    x12 = -8 / (1 + lam) ** 3 * sum(fk / x**k for k, fk in f.items() if k % 2 == 1)
    assert v[B11, F["XC"]] == pytest.approx(x11, rel=1e-12)
    assert v[B12, F["XC"]] == pytest.approx(x12, rel=1e-11)


@pytest.mark.parametrize("lam", LAMS)
def test_xc_contact_limit(lam):
    xi = 1e-9   # correction is -lam^2/(4(1+lam)) xi log(1/xi) ~ 1e-8
    v = scal(2 + xi, lam)[0]
    q = lam / (1 + lam)
    assert v[B11, F["XC"]] == pytest.approx(q**3 * zeta(3, q), abs=5e-8)
    assert v[B12, F["XC"]] * (1 + lam) ** 3 / 8 == pytest.approx(-q**3 * zeta(3, 1), abs=5e-8)


# ---------------------------------------------------------------------------- exact results

def stimson_jeffery(s):
    """Two equal spheres translating together along their line of centres, F / (6 pi a U)."""
    alpha = math.acosh(s / 2.0)
    n = np.arange(1, int(80 / alpha) + 60, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        num = 4 * np.sinh((n + 0.5) * alpha) ** 2 - (2 * n + 1) ** 2 * math.sinh(alpha) ** 2
        den = 2 * np.sinh((2 * n + 1) * alpha) + (2 * n + 1) * math.sinh(2 * alpha)
        q = np.where(np.isfinite(num) & np.isfinite(den), num / den, 1.0)
    return 4.0 / 3.0 * math.sinh(alpha) * np.sum(n * (n + 1) / ((2 * n - 1) * (2 * n + 3)) * (1 - q))


@pytest.mark.parametrize("xi", [1e-4, 1e-3, 1e-2, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0])
def test_stimson_jeffery(xi):
    v = scal(2 + xi, 1.0)[0]
    got = v[B11, F["XA"]] + v[B12, F["XA"]]
    # measured: 9.3e-6 relative at contact (truncation of the order-200 whole-range
    # series), 9e-8 at xi = 0.05, < 1e-9 for xi >= 0.1, 1e-15 for xi >= 0.3
    tol = 1.5e-5 if xi < 0.05 else (2e-7 if xi < 0.1 else 2e-9)
    assert got == pytest.approx(stimson_jeffery(2 + xi), rel=tol)


# ---------------------------------------------------------------------------- structure

@pytest.mark.parametrize("lam", LAMS)
def test_reciprocal_symmetry_of_scalars(lam):
    # blocks 12 and 21 come from the tables at lam and 1/lam; A, C, M must coincide
    v = scal(np.array([2.0 + 1e-5, 2.01, 2.5, 4.0, 20.0]), lam)
    for name in ("XA", "YA", "XC", "YC", "XM", "YM", "ZM"):
        np.testing.assert_allclose(v[:, B12, F[name]], v[:, B21, F[name]], rtol=1e-11, atol=1e-13)


@pytest.mark.parametrize("lam", LAMS)
def test_block_relations(lam):
    s = np.array([2.001, 2.3, 5.0])
    v = scal(s, lam)
    w = ts.resistance_scalars(r_of(s, 1 / lam, a1=lam), lam, 1.0)   # spheres swapped
    sign = np.array([-1.0 if n in ("YB", "XG", "YG") else 1.0 for n in ts.FUNCTIONS])
    np.testing.assert_allclose(v[:, B22], sign * w[:, B11], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(v[:, B21], sign * w[:, B12], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("lam", LAMS)
def test_near_contact_singular_terms(lam):
    l1 = 1 + lam
    v = scal(np.array([2 + 1e-8, 2 + 1e-7]), lam)
    g1 = 2 * lam**2 / l1**3
    # XA11 = g1/xi + O(log xi): xi * XA11 -> g1
    assert v[0, B11, F["XA"]] * 1e-8 == pytest.approx(g1, rel=1e-6)
    # YA11 slope in log(1/xi) is g2 (the O(xi log xi) remainder is ~1e-6)
    g2 = 4 / 15 * lam * (2 + lam + 2 * lam**2) / l1**3
    slope = (v[0, B11, F["YA"]] - v[1, B11, F["YA"]]) / math.log(10.0)
    assert slope == pytest.approx(g2, abs=1e-5)
    # XM11 ~ (6/5) lam^2/(1+lam)^3 / xi
    assert v[0, B11, F["XM"]] * 1e-8 == pytest.approx(1.2 * lam**2 / l1**3, rel=1e-5)


@pytest.mark.parametrize("lam", LAMS)
def test_remainder_coefficients_decay(lam):
    """The g's of the lubrication terms are consistent with the f_k: the series left after
    subtracting the exact singular functions has coefficients -> 0 (like m^-3), which
    fails at once (|r_m| ~ 1 or ~ 1/m) if a g1 or g2 were wrong."""
    rem = ts._per_lambda(lam)[0]
    tail = np.abs(rem[:, :, 150:]).max(axis=2)
    assert np.all(tail < 1e-3)


def test_smooth_whole_range():
    # one formula for all s (no switch): second differences on a fine log grid in xi stay
    # at the level of the curvature (a jump or a kink would show up as an outlier)
    xi = np.geomspace(1e-5, 30.0, 4001)
    for lam in LAMS:
        v = scal(2 + xi, lam)
        y = v * xi[:, None, None]           # remove the 1/xi growth
        d2 = np.abs(np.diff(y, 2, axis=0))
        d1 = np.abs(np.diff(y, 1, axis=0)).max(axis=0)
        assert np.all(d2.max(axis=0) <= 0.02 * d1 + 1e-12)


# ---------------------------------------------------------------------------- pair matrix

def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _big_rotation(Q):
    T5 = np.einsum("mij,ik,jl,nkl->mn", BASIS, Q, Q, BASIS)
    one = np.zeros((11, 11))
    one[:3, :3] = Q
    one[3:6, 3:6] = Q
    one[6:, 6:] = T5
    out = np.zeros((22, 22))
    out[:11, :11] = one
    out[11:, 11:] = one
    return out


@pytest.mark.parametrize("lam", LAMS)
def test_pair_matrix_spd_and_covariant(lam):
    rng = np.random.default_rng(7)
    gaps = np.array([1e-6, 1e-4, 1e-2, 0.1, 1.0, 10.0])
    a1 = 0.7
    dirs = rng.normal(size=(len(gaps), 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dx = dirs * (r_of(2 + gaps, lam, a1))[:, None]
    R = ts.pair_resistance(dx, a1, a1 * lam)
    for Rp in R:
        np.testing.assert_allclose(Rp, Rp.T, rtol=0, atol=1e-12 * np.abs(Rp).max())
        assert np.linalg.eigvalsh(Rp).min() > 0
    Q = _rotation(3)
    Rq = ts.pair_resistance(dx @ Q.T, a1, a1 * lam)
    T = _big_rotation(Q)
    # rotating dx changes |dx| by rounding (~1e-16 of it), i.e. the gap by ~1e-16 (2 + gap)
    # and R ~ 1/gap by that over the gap: 2e-10 of R at a gap of 1e-6 (measured 2.4e-10)
    for Rp, Rr, gap in zip(R, Rq, gaps):
        tol = 1e-11 + 1e-15 * (2 + gap) / gap
        np.testing.assert_allclose(Rr, T @ Rp @ T.T, rtol=0, atol=tol * np.abs(Rp).max())


def test_pair_matrix_conventions():
    """Entries against the tensor forms along d = z, from the scalars (sign contract)."""
    a1, a2 = 1.0, 2.0
    r = 3.2
    R = ts.pair_resistance(np.array([[0.0, 0.0, r]]), a1, a2)[0]
    v = ts.resistance_scalars(r, a1, a2)[0]
    p12 = a1 + a2
    assert R[2, 11 + 2] == pytest.approx(3 * np.pi * p12 * v[B12, F["XA"]])
    assert R[0, 11 + 0] == pytest.approx(3 * np.pi * p12 * v[B12, F["YA"]])
    # L1 = B12 U2 = YB12 (U2 x d): U2 = x gives L1 = -y
    assert R[4, 11 + 0] == pytest.approx(-np.pi * p12**2 * v[B12, F["YB"]])
    assert R[5, 11 + 5] == pytest.approx(np.pi * p12**3 * v[B12, F["XC"]])
    # -S1 = G11 U1 with U1 = d = z: S = XG (zz - I/3), and B2 : (zz - I/3) = sqrt(6)/3
    assert R[6 + 1, 2] == pytest.approx(np.pi * (2 * a1) ** 2 * v[B11, F["XG"]] * math.sqrt(6) / 3)
    # M: the axisymmetric strain B2 along d is an eigenvector with eigenvalue XM
    assert R[11 + 7, 11 + 7] == pytest.approx(5 / 6 * np.pi * (2 * a2) ** 3 * v[B22, F["XM"]])
    # B1 (xx - yy) is transverse to d = z: d2 part, eigenvalue ZM
    assert R[6, 6] == pytest.approx(5 / 6 * np.pi * (2 * a1) ** 3 * v[B11, F["ZM"]])
    # B4 (xz) couples to d: d1 part, eigenvalue YM
    assert R[9, 11 + 9] == pytest.approx(5 / 6 * np.pi * p12**3 * v[B12, F["YM"]])


def test_polydisperse_batch_matches_single():
    rng = np.random.default_rng(1)
    n = 12
    a1 = rng.choice([0.5, 1.0, 2.0], n)
    a2 = rng.choice([0.5, 1.0, 2.0], n)
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dx = dirs * ((a1 + a2) * (1 + rng.uniform(1e-4, 2.0, n)))[:, None]
    R = ts.pair_resistance(dx, a1, a2)
    for i in range(n):
        np.testing.assert_array_equal(R[i], ts.pair_resistance(dx[i:i + 1], a1[i], a2[i])[0])


def test_overlap_rejected():
    with pytest.raises(ValueError):
        ts.resistance_scalars(2.0, 1.0, 1.0)
    with pytest.raises(ValueError):
        ts.pair_resistance(np.array([[0.0, 0.0, 1.5]]), 1.0, 1.0)


@pytest.mark.parametrize("a1,a2", [(1.0, 1.0), (1.0, 0.5), (0.3, 1.0)])
@pytest.mark.parametrize("gap", [1e-4, 1e-3, 1e-2])
def test_squeeze_slope_is_the_gap_derivative_of_the_squeeze_resistance(a1, a2, gap):
    """h |d(f.R f)/dh| from the near-contact forms against centred differences (relative
    step 1e-5) of the exact pair matrix along the line of centres: the forms leave out the
    regular part of X^A, an O(h) share of the slope's (measured 1e-7 at h = 1e-4, 2e-4 at
    1e-2); limit 1e-6 + 0.03 h."""
    e = np.array([0.0, 0.0, 1.0])
    f = np.zeros(22)
    f[0:3], f[11:14] = -e, e
    values = [f @ ts.pair_resistance((e * (a1 + a2 + gap * (1 + sign * 1e-5)))[None], a1, a2)[0] @ f
              for sign in (1.0, -1.0)]
    finite_difference = -(values[0] - values[1]) / 2e-5
    assert float(ts.squeeze_slope(gap, a1, a2)) == pytest.approx(finite_difference, rel=1e-6 + 0.03 * gap)
