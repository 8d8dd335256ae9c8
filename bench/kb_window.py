"""Benchmark: a Kaiser-Bessel window for the spectral far field, against its Gaussian.

`sdmpi.hydro.spectral` spreads the generalized forces with a Gaussian window truncated to a
sphere (14 points per axis, ~1 270 points a particle at Ewald tolerance 1e-4) whose
derivatives up to third order (torques, stresslets, Faxen Laplacians) are polynomials
times the Gaussian. This script measures the alternative of a compact window separable in
the lattice's grid coordinates s_l (grid steps from the particle), the Kaiser-Bessel window

    phi(s) = I0(beta sqrt(1 - (2 s/P)^2)) / I0(beta),   |s| < P/2  (P points per axis),

whose Fourier transform is analytic (Lewitt, J. Opt. Soc. Am. A 7, 1834 (1990)),

    phi^(theta) = P sinh(sqrt(beta^2 - (P theta/2)^2)) / (sqrt(beta^2 - (P theta/2)^2) I0(beta)),

and whose derivatives are those of f(u) = I0(beta sqrt(u)), an entire function of
u = 1 - (2 s/P)^2, so that they stay bounded up to the edge of the support (the
exponential-of-semicircle kernel of non-uniform FFTs has phi' ~ 1/sqrt(u) there). Used in
gridding and non-uniform FFTs (Jackson, Meyer, Nishimura & Macovski, IEEE Trans. Med.
Imaging 10, 473 (1991); Potts & Tasche, Adv. Comput. Math. 47, 53 (2021)).

The window W(r) = phi(s_1) phi(s_2) phi(s_3) is deconvolved mode by mode, W^(k) =
(V/M1M2M3) prod_l phi^(2 pi n_l/M_l), in place of the Gaussian's g^(k) (the k-space kernel
J^(k)/W^(k)^2). Cartesian derivatives are d/dr_c = sum_l D_cl d/ds_l, D_cl = M_l b_l,c (b_l
the reciprocal rows), so every source and receiver operator (1, grad, lap, grad lap) is a
polynomial in the three lattice derivatives of total order <= 3 (20 monomials), applied to
the separable tables phi^(d)(s_l), d = 0..3, by sum factorisation: axis 1 per particle, axis
2 per grid row, then four z-terms per grid point as in the Gaussian's code (the z-loops
here are written as `spectral._spread` and `_interpolate` write theirs, so that the
timings compare the windows, not the loops).

Measured (bench/kb_window.json):
  accuracy - the whole product (sdmpi's real-space and self parts, this wave-space part)
             against the dense Ewald sum (`far_field_mobility`, tol 1e-10) at the cases of
             tests/test_spectral.py (27 spheres), on the Gaussian's own grid, for P and
             beta/P; beside it the Gaussian's error.
  timing   - spreading and interpolation at N = 1000, phi = 0.45, strain 0.3, tolerance
             1e-4 (single-precision grids, as `SpectralFarField` uses them there), one
             rank, the two windows alternated in one process (median of `--repeat`), with
             a 297 x 297 Cholesky timed before and after.

    python bench/kb_window.py --out bench/kb_window.json
"""

import argparse
import datetime
import json
import math
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numba
import numpy as np
import scipy.fft
import scipy.special

from bench_step import cholesky_matrix, cholesky_ms  # bench/ is on sys.path when run as a script

from sdmpi.hydro.basis import BASIS
from sdmpi.hydro.spectral import SpectralFarField, _apply_kernel, _fold, _interpolate, _pad, _spread

NDOF = 11
#: lattice-derivative orders (a, b, d) along axes 1, 2, 3 with a + b + d <= 3
MONOMIALS = [(a, b, d) for d in range(4) for a in range(4) for b in range(4) if a + b + d <= 3]
#: (b, d) slots after contracting axis 1, ordered d = 0: b = 0..3, d = 1: b = 0..2, d = 2: b = 0..1, d = 3: b = 0
SLOTS = [(b, d) for d in range(4) for b in range(4) if b + d <= 3]
SLOT_OF = np.array([SLOTS.index((b, d)) for (a, b, d) in MONOMIALS], dtype=np.int64)
AXIS1_ORDER = np.array([a for (a, b, d) in MONOMIALS], dtype=np.int64)


def _product(p, q):
    """Product of two polynomials in the lattice derivatives (dicts monomial -> coefficient)."""
    out = {}
    for m1, c1 in p.items():
        for m2, c2 in q.items():
            m = tuple(x + y for x, y in zip(m1, m2))
            out[m] = out.get(m, 0.0) + c1 * c2
    return out


def operators(d):
    """(8, 20) coefficients over MONOMIALS of 1, d_x, d_y, d_z, lap, d_x lap, d_y lap,
    d_z lap, for d[c, l] = ds_l/dr_c."""
    grads = [{m: d[c, l] for l, m in enumerate([(1, 0, 0), (0, 1, 0), (0, 0, 1)]) if d[c, l] != 0.0}
             for c in range(3)]
    lap = {}
    for g in grads:
        for m, v in _product(g, g).items():
            lap[m] = lap.get(m, 0.0) + v
    out = np.zeros((8, len(MONOMIALS)))
    for k, poly in enumerate([{(0, 0, 0): 1.0}, *grads, lap, *[_product(g, lap) for g in grads]]):
        for m, v in poly.items():
            out[k, MONOMIALS.index(m)] += v
    return out


@numba.njit(cache=True)
def _window_derivatives(s, half, beta, out):
    """out[d] = phi^(d)(s), d = 0..3, of the Kaiser-Bessel window of half-width `half` (grid
    steps): the series f(u) = sum_m (beta^2 u/4)^m/(m!)^2 = I0(beta sqrt(u)) and its u-derivatives,
    chained through u = 1 - (s/half)^2."""
    u = 1.0 - (s / half) ** 2
    if u <= 0.0:
        out[:] = 0.0
        return
    z = beta * beta / 4.0
    f0 = f1 = f2 = f3 = 0.0
    term, norm = 1.0, 0.0  # z^m/(m!)^2; norm = I0(beta)
    for m in range(200):
        if m > 0:
            term *= z / (m * m)
        norm += term
        f0 += term * u ** m
        if m >= 1:
            f1 += term * m * u ** (m - 1)
        if m >= 2:
            f2 += term * m * (m - 1) * u ** (m - 2)
        if m >= 3:
            f3 += term * m * (m - 1) * (m - 2) * u ** (m - 3)
        if m > z and term < 1e-17 * norm:
            break
    du, d2u = -2.0 * s / (half * half), -2.0 / (half * half)
    out[0] = f0 / norm
    out[1] = f1 * du / norm
    out[2] = (f2 * du * du + f1 * d2u) / norm
    out[3] = (f3 * du ** 3 + 3.0 * f2 * du * d2u) / norm


def window_transform(theta, half, beta):
    """phi^(theta) = int phi(s) exp(-i theta s) ds (Lewitt 1990)."""
    arg = beta ** 2 - (half * theta) ** 2
    root = np.sqrt(np.abs(arg))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(arg > 0, np.sinh(root) / root, np.sinc(root / np.pi))
    out = np.where(arg == 0, 1.0, out)
    return 2 * half * out / scipy.special.i0(beta)


@numba.njit(cache=True)
def _tables(frac, m, points, beta, first, phi):
    """first[i, l]: the first grid index (unwrapped) of particle i along axis l; phi[i, l, d, q]."""
    half = points / 2.0
    tmp = np.empty(4)
    for i in range(frac.shape[0]):
        for l in range(3):
            s = frac[i, l] * m[l]
            start = math.floor(s - half) + 1
            first[i, l] = start
            for q in range(points):
                _window_derivatives(start + q - s, half, beta, tmp)
                for d in range(4):
                    phi[i, l, d, q] = tmp[d]


@numba.njit(cache=True)
def _source(x, o, radius, ops, basis, t):
    """t (3, 20): the particle's force density over the monomials,
    f = F (1 + a^2/6 lap) W + (1/2) grad W x L - S.grad (1 + a^2/10 lap) W."""
    w = np.zeros((3, 8))
    s = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            for n in range(5):
                s[a, b] += x[o + 6 + n] * basis[n, a, b]
    a2 = radius * radius
    for c in range(3):
        w[c, 0] = x[o + c]
        w[c, 4] = x[o + c] * a2 / 6.0
        for e in range(3):
            w[c, 1 + e] = -s[c, e]
            w[c, 5 + e] = -s[c, e] * a2 / 10.0
    lx, ly, lz = x[o + 3], x[o + 4], x[o + 5]
    w[0, 2] += 0.5 * lz
    w[0, 3] -= 0.5 * ly
    w[1, 3] += 0.5 * lx
    w[1, 1] -= 0.5 * lz
    w[2, 1] += 0.5 * ly
    w[2, 2] -= 0.5 * lx
    for c in range(3):
        for k in range(ops.shape[1]):
            acc = 0.0
            for j in range(8):
                acc += w[c, j] * ops[j, k]
            t[c, k] = acc


@numba.njit(cache=True, fastmath=True)
def spread(x, radii, ops, basis, first, phi, m, slot, axis1, grid):
    """grid (M1, M2, M3 + P, 3) += the force density of x (11N), particle i's tables the i-th."""
    points = phi.shape[3]
    t = np.empty((3, ops.shape[1]))
    u = np.empty((points, 10, 3))
    for i in range(first.shape[0]):
        _source(x, NDOF * i, radii[i], ops, basis, t)
        p1, p2, p3 = phi[i, 0], phi[i, 1], phi[i, 2]
        u[:, :, :] = 0.0
        for q1 in range(points):
            for k in range(ops.shape[1]):
                f = p1[axis1[k], q1]
                for c in range(3):
                    u[q1, slot[k], c] += t[c, k] * f
        z0 = first[i, 2] % m[2]
        for q1 in range(points):
            i1 = (first[i, 0] + q1) % m[0]
            v = u[q1]
            for q2 in range(points):
                i2 = (first[i, 1] + q2) % m[1]
                b0, b1, b2, b3 = p2[0, q2], p2[1, q2], p2[2, q2], p2[3, q2]
                x0 = v[0, 0] * b0 + v[1, 0] * b1 + v[2, 0] * b2 + v[3, 0] * b3
                y0 = v[0, 1] * b0 + v[1, 1] * b1 + v[2, 1] * b2 + v[3, 1] * b3
                w0 = v[0, 2] * b0 + v[1, 2] * b1 + v[2, 2] * b2 + v[3, 2] * b3
                x1 = v[4, 0] * b0 + v[5, 0] * b1 + v[6, 0] * b2
                y1 = v[4, 1] * b0 + v[5, 1] * b1 + v[6, 1] * b2
                w1 = v[4, 2] * b0 + v[5, 2] * b1 + v[6, 2] * b2
                x2, y2, w2 = v[7, 0] * b0 + v[8, 0] * b1, v[7, 1] * b0 + v[8, 1] * b1, v[7, 2] * b0 + v[8, 2] * b1
                x3, y3, w3 = v[9, 0] * b0, v[9, 1] * b0, v[9, 2] * b0
                row = grid[i1, i2, z0:]
                for q3 in range(points):
                    a0, a1, a2, a3 = p3[0, q3], p3[1, q3], p3[2, q3], p3[3, q3]
                    row[q3, 0] += x0 * a0 + x1 * a1 + x2 * a2 + x3 * a3
                    row[q3, 1] += y0 * a0 + y1 * a1 + y2 * a2 + y3 * a3
                    row[q3, 2] += w0 * a0 + w1 * a1 + w2 * a2 + w3 * a3


@numba.njit(cache=True, fastmath=True)
def interpolate(grid, radii, ops, basis, first, phi, m, slot, axis1, y):
    """y (11N) += (U, Omega, E) from the velocity field on the grid (the adjoint of spread)."""
    points = phi.shape[3]
    r = np.empty((3, ops.shape[1]))
    u = np.empty((points, 10, 3))
    for i in range(first.shape[0]):
        p1, p2, p3 = phi[i, 0], phi[i, 1], phi[i, 2]
        z0 = first[i, 2] % m[2]
        u[:, :, :] = 0.0
        for q1 in range(points):
            i1 = (first[i, 0] + q1) % m[0]
            v = u[q1]
            for q2 in range(points):
                i2 = (first[i, 1] + q2) % m[1]
                row = grid[i1, i2, z0:]
                m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = m30 = m31 = m32 = 0.0
                for q3 in range(points):
                    a0, a1, a2, a3 = p3[0, q3], p3[1, q3], p3[2, q3], p3[3, q3]
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
                b0, b1, b2, b3 = p2[0, q2], p2[1, q2], p2[2, q2], p2[3, q2]
                # the slots in SLOTS order (b, d): row moment of z-derivative d times phi2^(b)
                v[0, 0] += m00 * b0
                v[0, 1] += m01 * b0
                v[0, 2] += m02 * b0
                v[1, 0] += m00 * b1
                v[1, 1] += m01 * b1
                v[1, 2] += m02 * b1
                v[2, 0] += m00 * b2
                v[2, 1] += m01 * b2
                v[2, 2] += m02 * b2
                v[3, 0] += m00 * b3
                v[3, 1] += m01 * b3
                v[3, 2] += m02 * b3
                v[4, 0] += m10 * b0
                v[4, 1] += m11 * b0
                v[4, 2] += m12 * b0
                v[5, 0] += m10 * b1
                v[5, 1] += m11 * b1
                v[5, 2] += m12 * b1
                v[6, 0] += m10 * b2
                v[6, 1] += m11 * b2
                v[6, 2] += m12 * b2
                v[7, 0] += m20 * b0
                v[7, 1] += m21 * b0
                v[7, 2] += m22 * b0
                v[8, 0] += m20 * b1
                v[8, 1] += m21 * b1
                v[8, 2] += m22 * b1
                v[9, 0] += m30 * b0
                v[9, 1] += m31 * b0
                v[9, 2] += m32 * b0
        for k in range(ops.shape[1]):
            for c in range(3):
                acc = 0.0
                for q1 in range(points):
                    acc += u[q1, slot[k], c] * p1[axis1[k], q1]
                r[c, k] = acc
        w = np.zeros((3, 8))  # 1, grad (3), lap, grad lap (3) applied to each velocity component
        for c in range(3):
            for j in range(8):
                for k in range(ops.shape[1]):
                    w[c, j] += r[c, k] * ops[j, k]
        a2 = radii[i] * radii[i]
        o = NDOF * i
        for c in range(3):
            y[o + c] += w[c, 0] + a2 / 6.0 * w[c, 4]
        y[o + 3] += 0.5 * (w[1, 3] - w[2, 2])
        y[o + 4] += 0.5 * (w[2, 1] - w[0, 3])
        y[o + 5] += 0.5 * (w[0, 2] - w[1, 1])
        for n in range(5):
            acc = 0.0
            for c in range(3):
                for e in range(3):
                    acc += basis[n, c, e] * (w[c, 1 + e] + a2 / 10.0 * w[c, 5 + e])
            y[o + 6 + n] -= acc


class KaiserBesselWaveSpace:
    """The wave-space product of `SpectralFarField` (same xi, kmax, grid) with the
    Kaiser-Bessel window of `points` per axis and shape beta = beta_per_point * points."""

    def __init__(self, gaussian: SpectralFarField, lattice, points: int, beta_per_point: float,
                 order: np.ndarray | None = None):
        par = gaussian.params
        self.m = np.array(par.grid)
        self.points, self.beta = points, beta_per_point * points
        self.order = np.arange(gaussian.n_particles) if order is None else order
        self.radii = gaussian._radii[self.order]
        frac = gaussian._frac[self.order]
        self.first = np.empty((len(frac), 3), dtype=np.int64)
        self.phi = np.empty((len(frac), 3, 4, points))
        _tables(frac, self.m, points, self.beta, self.first, self.phi)
        self.ops = operators((self.m[:, None] * lattice.reciprocal).T)
        m1, m2, m3 = par.grid
        n = np.meshgrid(np.fft.fftfreq(m1, 1 / m1), np.fft.fftfreq(m2, 1 / m2), np.arange(m3 // 2 + 1), indexing="ij")
        k = 2 * math.pi * np.einsum("i...,ic->...c", np.array(n), lattice.reciprocal)
        ksq = np.einsum("...c,...c->...", k, k)
        u = ksq / (4 * par.xi ** 2)
        transform = np.prod([window_transform(2 * math.pi * n[l] / self.m[l], points / 2, self.beta)
                             for l in range(3)], axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.scale = (1 + u + 2 * u * u) * np.exp(-u) / (ksq * lattice.volume * transform ** 2)
        self.scale[(ksq == 0) | (ksq > par.kmax ** 2)] = 0.0
        self.recip = lattice.reciprocal

    def grid(self, dtype):
        m1, m2, m3 = self.m
        return np.zeros((m1, m2, m3 + self.points, 3), dtype=dtype)

    def spread(self, x, padded):
        spread(x, self.radii, self.ops, BASIS, self.first, self.phi, self.m, SLOT_OF, AXIS1_ORDER, padded)

    def interpolate(self, padded, y):
        interpolate(padded, self.radii, self.ops, BASIS, self.first, self.phi, self.m, SLOT_OF, AXIS1_ORDER, y)

    def product(self, x):
        """The wave-space part of M_inf x (11N, particles in `order`), double precision."""
        m3 = self.m[2]
        padded = self.grid(np.float64)
        self.spread(x, padded)
        _fold(padded, m3)
        fk = scipy.fft.rfftn(padded[:, :, :m3], axes=(0, 1, 2))
        _apply_kernel(fk, self.scale, self.recip)
        padded[:, :, :m3] = scipy.fft.irfftn(fk, s=tuple(self.m), axes=(0, 1, 2), norm="forward")
        _pad(padded, m3)
        y = np.zeros_like(x)
        self.interpolate(padded, y)
        return y


def accuracy(points_list, betas):
    """Errors of the whole product against the dense Ewald sum at tests/test_spectral.py's cases."""
    from sdmpi.dynamics.initial import compress, hard_sphere_fluid
    from sdmpi.hydro.farfield import far_field_mobility
    from sdmpi.hydro.geometry import Lattice

    rows = []
    cases = [(0.05, 0.0, False, 1e-3), (0.5, 0.0, True, 1e-4), (0.5, -0.45, False, 1e-4), (0.05, -0.45, True, 1e-5),
             (0.5, 0.3, True, 1e-6), (0.05, 0.3, False, 1e-6), (0.5, 0.9, False, 1e-3), (0.05, 0.9, True, 1e-4)]
    n = 27
    for phi, strain, unequal, tol in cases:  # the configurations of tests/test_spectral.py
        rng = np.random.default_rng(7)
        radii = rng.uniform(0.6, 1.4, n) if unequal else np.ones(n)
        pos, side = hard_sphere_fluid(n, min(phi, 0.2), rng, strain=strain, radii=radii)
        if phi > 0.2:
            pos, side = compress(pos, side, phi, rng, strain=strain, radii=radii)
        box = np.full(3, side)
        lattice = Lattice(box, strain)
        x = np.random.default_rng(1).standard_normal(NDOF * n)
        ref = far_field_mobility(pos, radii, box, strain, tol=1e-10) @ x
        gaussian = SpectralFarField(pos, radii, lattice, tol=tol)
        rest = gaussian._self * x
        gaussian.real_space(x, rest)
        row = {"phi": phi, "strain": strain, "unequal_radii": unequal, "tol": tol,
               "grid": list(gaussian.params.grid), "gaussian_points": gaussian._stencils.pad,
               "gaussian_error": float(np.linalg.norm(gaussian.matvec(x) - ref) / np.linalg.norm(ref)),
               "kaiser_bessel_error": {}}
        for beta in betas:
            for points in points_list:
                wave = KaiserBesselWaveSpace(gaussian, lattice, points, beta).product(x)
                err = float(np.linalg.norm(rest + wave - ref) / np.linalg.norm(ref))
                row["kaiser_bessel_error"][f"P={points}, beta/P={beta}"] = err
        rows.append(row)
        best = {p: min(row["kaiser_bessel_error"][f"P={p}, beta/P={b}"] for b in betas) for p in points_list}
        print(f"phi {phi} strain {strain} tol {tol:g}: Gaussian {row['gaussian_error']:.1e} "
              f"({row['gaussian_points']} points/axis); Kaiser-Bessel, best beta: "
              + " ".join(f"P{p} {e:.1e}" for p, e in best.items()), flush=True)
    return rows


def timing(points_list, beta, repeat):
    """Spreading and interpolation at N = 1000 (tolerance 1e-4), the two windows alternated."""
    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro.geometry import Lattice

    n = 1000
    rng = np.random.default_rng(1)
    pos, side = hard_sphere_fluid(n, 0.45, rng, sweeps=100)
    lattice = Lattice(np.full(3, side), 0.3)
    gaussian = SpectralFarField(pos, np.ones(n), lattice, tol=1e-4)
    par, stencils = gaussian.params, gaussian._stencils
    x = rng.standard_normal(NDOF * n)
    padded = gaussian.work_grids()[0]
    spd = cholesky_matrix()
    chol = [cholesky_ms(spd)[0]]
    out = {"n": n, "grid": list(par.grid), "grid_dtype": str(padded.dtype), "gaussian_points": stencils.pad,
           "gaussian_window_points": float(np.sum(np.maximum(np.diff(stencils.zr, axis=-1), 0)) / n),
           "kaiser_bessel": {}}
    for points in points_list:
        kb = KaiserBesselWaveSpace(gaussian, lattice, points, beta, order=gaussian._order)
        xo = x.reshape(n, NDOF)[gaussian._order].ravel()
        grid = kb.grid(padded.dtype)
        times = {"gaussian_spread": [], "gaussian_interpolate": [], "spread": [], "interpolate": []}
        for _ in range(repeat):
            padded.fill(0.0)
            t = time.perf_counter()
            _spread(gaussian._radii, gaussian._order, x, par.alpha, BASIS, *stencils.arrays(), padded)
            times["gaussian_spread"].append(time.perf_counter() - t)
            y = np.zeros_like(x)
            t = time.perf_counter()
            _interpolate(gaussian._radii, gaussian._order, padded, par.alpha, BASIS, *stencils.arrays(), y)
            times["gaussian_interpolate"].append(time.perf_counter() - t)
            grid.fill(0.0)
            t = time.perf_counter()
            kb.spread(xo, grid)
            times["spread"].append(time.perf_counter() - t)
            y = np.zeros_like(x)
            t = time.perf_counter()
            kb.interpolate(grid, y)
            times["interpolate"].append(time.perf_counter() - t)
        ms = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
        ms["ratio"] = (ms["spread"] + ms["interpolate"]) / (ms["gaussian_spread"] + ms["gaussian_interpolate"])
        out["kaiser_bessel"][f"P={points}"] = ms
        print(f"N = {n}, P = {points}: spreading + interpolation {ms['spread']:.2f} + {ms['interpolate']:.2f} ms "
              f"against the Gaussian's {ms['gaussian_spread']:.2f} + {ms['gaussian_interpolate']:.2f} ms "
              f"({ms['ratio']:.2f})", flush=True)
    chol.append(cholesky_ms(spd)[0])
    out["cholesky_ms"] = chol
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, nargs="+", default=[7, 8, 9, 10, 11])
    ap.add_argument("--betas", type=float, nargs="+", default=[2.3, 2.5, 2.7], help="beta / P")
    ap.add_argument("--timing-points", type=int, nargs="+", default=[8, 9, 10])
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--out", default="bench/kb_window.json")
    args = ap.parse_args()
    result = {"date": datetime.date.today().isoformat(), "accuracy": accuracy(args.points, args.betas),
              "timing": timing(args.timing_points, 2.5, args.repeat)}
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
