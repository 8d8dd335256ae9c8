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
(Bcast); ranks 1.. share the real-space pairs; the 11N result is summed (Allreduce).
"""

import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.fft

from .basis import BASIS
from .farfield import (NDOF, _cached_radial_table, _pair_block, _power_bounds, _truncation_parameter,
                       self_mobility)
from .geometry import Lattice, find_pairs


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
    def choose(cls, lattice, radii, tol=1e-4, xi=None):
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
        work; the window support in grid points does not depend on it."""
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


@numba.njit(cache=True)
def _pair_blocks(pos, radii, pi, pj, shift, table, xi, basis, blocks):
    """blocks[p] = 11x11 real-space block of pair image p (receiver pi, source pj at
    separation x_pj + shift - x_pi), as in `farfield._real_space_sum`."""
    bounds = _power_bounds(table)
    work = np.empty(80)
    rvec = np.empty(3)
    for p in range(pi.shape[0]):
        i, j = pi[p], pj[p]
        for c in range(3):
            rvec[c] = pos[i, c] - pos[j, c] - shift[p, c]
        blocks[p] = 0.0
        _pair_block(rvec, radii[i], radii[j], table, bounds, xi, basis, work, blocks[p])


@numba.njit(cache=True)
def _pairs_product(pi, pj, blocks, x, y):
    """y += sum over pair images of M_ij x_j + M_ij^T x_i (blocks[p] = M_ij)."""
    for p in range(pi.shape[0]):
        i0, j0 = NDOF * pi[p], NDOF * pj[p]
        b = blocks[p]
        for a in range(NDOF):
            acc = 0.0
            for c in range(NDOF):
                acc += b[a, c] * x[j0 + c]
                y[j0 + c] += b[a, c] * x[i0 + a]
            y[i0 + a] += acc


# ---------------------------------------------------------------------------------
# wave space: windows, spreading, interpolation
# ---------------------------------------------------------------------------------


@numba.njit(cache=True)
def _stencil(t, m, steps, half, alpha, reach, idx, d12, e12, zr, z3, e3):
    """Separable parts of the window stencil of a particle at grid coordinates t (3,),
    the grid points within distance reach: wrapped grid indices idx[c, q]; in-plane
    (x, y) offsets d12[q1, q2] from the particle to the grid points, their Gaussians
    e12 = exp(-alpha (dx^2 + dy^2)) and the range zr[q1, q2] = [lo, hi) of q3 within
    reach; z offsets z3[q3] and e3 = exp(-alpha dz^2). steps: rows e_i = L_i/M_i, with
    e_3 along z and e_1, e_2 in the x-y plane (the Lees-Edwards lattice). Returns the
    number of points per axis."""
    npt = np.empty(3, dtype=np.int64)
    s0 = np.empty(3)
    for c in range(3):
        start = math.ceil(t[c] - half[c])
        s0[c] = start - t[c]
        npt[c] = int(2 * half[c]) + 1
        for q in range(npt[c]):
            idx[c, q] = (start + q) % m[c]
    hz = steps[2, 2]
    for q in range(npt[2]):
        z3[q] = (s0[2] + q) * hz
        e3[q] = math.exp(-alpha * z3[q] * z3[q])
    for q1 in range(npt[0]):
        for q2 in range(npt[1]):
            dx = (s0[0] + q1) * steps[0, 0] + (s0[1] + q2) * steps[1, 0]
            dy = (s0[0] + q1) * steps[0, 1] + (s0[1] + q2) * steps[1, 1]
            d12[q1, q2, 0], d12[q1, q2, 1] = dx, dy
            e12[q1, q2] = math.exp(-alpha * (dx * dx + dy * dy))
            rem = reach * reach - dx * dx - dy * dy
            if rem <= 0.0:
                zr[q1, q2, 0], zr[q1, q2, 1] = 0, 0
            else:
                dz = math.sqrt(rem) / hz
                zr[q1, q2, 0] = max(0, math.ceil(-dz - s0[2]))
                zr[q1, q2, 1] = min(npt[2], math.floor(dz - s0[2]) + 1)
    return npt


def _stencil_work(half):
    """Work arrays for _stencil."""
    p = int(2 * half.max()) + 1
    return (np.empty((3, p), dtype=np.int64), np.empty((p, p, 2)), np.empty((p, p)),
            np.empty((p, p, 2), dtype=np.int64), np.empty(p), np.empty(p))


# The window weights of a sphere of radius a at offset d = (d0, d1, z), r2 = |d|^2, with
# g = (alpha/pi)^(3/2) exp(-alpha r2):
#   (1 + a^2/6 lap) g = g (A + B r2),  A = 1 - alpha a^2,  B = (2/3) alpha^2 a^2,
#   (1/2) grad g = -alpha g d,
#   grad (1 + a^2/10 lap) g = g (C + D r2) d,  C = -2 alpha + 2 alpha^2 a^2,  D = -(4/5) alpha^3 a^2.
# Along a grid row (fixed d0, d1) every weight is g times a cubic in z, so the sums below
# work with the z-moments of each row.


@numba.njit(cache=True, inline="always")
def _weight_coefficients(alpha, radius):
    """(A, B, C, D) of the window weights above."""
    a2 = radius * radius
    return (1 - alpha * a2, 2 / 3 * alpha * alpha * a2,
            -2 * alpha + 2 * alpha * alpha * a2, -0.8 * alpha ** 3 * a2)


@numba.njit(cache=True, fastmath=True)
def _spread(frac, radii, order, x, steps, half, alpha, reach, basis, work, grid):
    """grid (M1, M2, M3, 3) += force density f(x) of the generalized forces x (11N):
    f = F (1 + a^2/6 lap) g + (1/2) grad g x L - S.grad (1 + a^2/10 lap) g per particle,
    particles taken in the given order."""
    idx, d12, e12, zr, z3, e3 = work
    m = grid.shape[:3]
    norm = (alpha / math.pi) ** 1.5
    t = np.empty(3)
    s = np.zeros((3, 3))
    cf = np.empty((3, 4))
    for p in order:
        for c in range(3):
            t[c] = frac[p, c] * m[c]
        npt = _stencil(t, m, steps, half, alpha, reach, idx, d12, e12, zr, z3, e3)
        o = NDOF * p
        f0, f1, f2 = x[o], x[o + 1], x[o + 2]
        l0, l1, l2 = x[o + 3], x[o + 4], x[o + 5]
        for a in range(3):
            for b in range(3):
                s[a, b] = 0.0
                for n in range(5):
                    s[a, b] += x[o + 6 + n] * basis[n, a, b]
        wa, wb, wc, wd = _weight_coefficients(alpha, radii[p])
        for q1 in range(npt[0]):
            g1 = idx[0, q1]
            for q2 in range(npt[1]):
                g2 = idx[1, q2]
                d0, d1 = d12[q1, q2, 0], d12[q1, q2, 1]
                r12 = d0 * d0 + d1 * d1
                pu, pe = wa + wb * r12, wc + wd * r12
                # f_c / g = cf[c, 0] + cf[c, 1] z + cf[c, 2] z^2 + cf[c, 3] z^3
                for c in range(3):
                    sd = -(s[c, 0] * d0 + s[c, 1] * d1)
                    cf[c, 1] = -pe * s[c, 2]
                    cf[c, 3] = -wd * s[c, 2]
                    cf[c, 0] = pe * sd
                    cf[c, 2] = wd * sd
                cf[0, 0] += f0 * pu - alpha * d1 * l2
                cf[1, 0] += f1 * pu + alpha * d0 * l2
                cf[2, 0] += f2 * pu - alpha * (d0 * l1 - d1 * l0)
                cf[0, 1] += alpha * l1
                cf[1, 1] -= alpha * l0
                cf[0, 2] += f0 * wb
                cf[1, 2] += f1 * wb
                cf[2, 2] += f2 * wb
                g12 = norm * e12[q1, q2]
                for q3 in range(zr[q1, q2, 0], zr[q1, q2, 1]):
                    g3 = idx[2, q3]
                    z = z3[q3]
                    g = g12 * e3[q3]
                    for c in range(3):
                        grid[g1, g2, g3, c] += g * (cf[c, 0] + z * (cf[c, 1] + z * (cf[c, 2] + z * cf[c, 3])))


@numba.njit(cache=True, fastmath=True)
def _interpolate(frac, radii, order, grid, steps, half, alpha, reach, basis, work, y):
    """y (11N) += (U, Omega, E) of every particle from the velocity field u on the grid
    (the adjoint of _spread): U = sum u (1 + a^2/6 lap) g, Omega = (1/2) sum u x grad g,
    E^m = -B^m : sum u grad (1 + a^2/10 lap) g."""
    idx, d12, e12, zr, z3, e3 = work
    m = grid.shape[:3]
    norm = (alpha / math.pi) ** 1.5
    t = np.empty(3)
    mom = np.empty((4, 3))  # row moments sum g z^k u_c
    u = np.empty(3)
    om = np.empty(3)
    tens = np.empty((3, 3))
    for p in order:
        for c in range(3):
            t[c] = frac[p, c] * m[c]
        npt = _stencil(t, m, steps, half, alpha, reach, idx, d12, e12, zr, z3, e3)
        wa, wb, wc, wd = _weight_coefficients(alpha, radii[p])
        u[:] = 0.0
        om[:] = 0.0
        tens[:, :] = 0.0
        for q1 in range(npt[0]):
            g1 = idx[0, q1]
            for q2 in range(npt[1]):
                g2 = idx[1, q2]
                mom[:, :] = 0.0
                g12 = norm * e12[q1, q2]
                for q3 in range(zr[q1, q2, 0], zr[q1, q2, 1]):
                    g3 = idx[2, q3]
                    z = z3[q3]
                    g = g12 * e3[q3]
                    for c in range(3):
                        v = g * grid[g1, g2, g3, c]
                        mom[0, c] += v
                        mom[1, c] += v * z
                        mom[2, c] += v * z * z
                        mom[3, c] += v * z * z * z
                d0, d1 = d12[q1, q2, 0], d12[q1, q2, 1]
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
    """h(k)/k^2 / g^(k)^2 / (V/(M1 M2 M3)) on the rfft grid (the last factor: the grid
    cell, quadrature weight of the spreading), zero at k = 0 and |k| > kmax."""
    m1, m2, m3 = par.grid
    n = np.meshgrid(np.fft.fftfreq(m1, 1 / m1), np.fft.fftfreq(m2, 1 / m2),
                    np.arange(m3 // 2 + 1), indexing="ij")
    k = 2 * math.pi * np.einsum("i...,ic->...c", np.array(n), lattice.reciprocal)
    ksq = np.einsum("...c,...c->...", k, k)
    u = ksq / (4 * par.xi ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = ((1 + u + 2 * u * u) * np.exp(-u + ksq / (2 * par.alpha))
                 * lattice.volume / (ksq * m1 * m2 * m3))
    scale[(ksq == 0) | (ksq > par.kmax ** 2)] = 0.0
    return scale


# ---------------------------------------------------------------------------------
# the operator
# ---------------------------------------------------------------------------------


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

    def __init__(self, positions, radii, lattice, tol=1e-4, comm=None, *, xi=None):
        pos, rad = _check_inputs(positions, radii, lattice, tol, xi)
        self.n_particles = pos.shape[0]
        self.tol = float(tol)
        self.comm = comm
        rank, size = (0, 1) if comm is None else (comm.rank, comm.size)
        pos = lattice.wrap(pos)
        self.params = par = SpectralParameters.choose(lattice, rad, tol, xi)
        self._radii = rad
        self._frac = pos @ lattice.reciprocal.T
        unique, which = np.unique(rad, return_inverse=True)
        self._self = np.array([np.diag(self_mobility(a, par.xi)) for a in unique])[which].ravel()
        # wave space: every rank spreads and interpolates a share of the particles (in
        # grid-cell order, contiguous in space), rank 0 does the FFTs
        self._steps = lattice.vectors / np.array(par.grid)[:, None]
        # half-width of the window in grid steps along each axis (plane spacing 1/(M_i |b_i|))
        self._half = par.window * np.array(par.grid) * np.linalg.norm(lattice.reciprocal, axis=1)
        self._work = _stencil_work(self._half)
        cells = np.floor(self._frac * np.array(par.grid) / 4).astype(np.int64)
        self._order = np.array_split(np.lexsort(cells.T[::-1]), size)[rank]
        if rank == 0:
            self._scale = _kernel_scale(lattice, par)
            self._recip = lattice.reciprocal
        # real space: pair images on one rank, else shared by ranks 1..size-1
        pi, pj, shift = find_pairs(pos, rad, lattice, par.rcut, 0.0)
        if size > 1:
            mine = np.array_split(np.arange(len(pi)), size - 1)[rank - 1] if rank > 0 else np.arange(0)
            pi, pj, shift = pi[mine], pj[mine], shift[mine]
        self._pi, self._pj = pi, pj
        self._blocks = np.empty((len(pi), NDOF, NDOF))
        _pair_blocks(pos, rad, pi, pj, np.ascontiguousarray(shift), _cached_radial_table(par.xi),
                     par.xi, BASIS, self._blocks)

    def real_space(self, x, y):
        """y += this rank's share of the real-space product."""
        _pairs_product(self._pi, self._pj, self._blocks, x, y)

    def wave_space(self, x, y):
        """y += the wave-space product at this rank's particles (collective over comm)."""
        par = self.params
        parallel = self.comm is not None and self.comm.size > 1
        stencil = (self._steps, self._half, par.alpha, par.window, BASIS, self._work)
        grid = np.zeros((*par.grid, 3))
        _spread(self._frac, self._radii, self._order, x, *stencil, grid)
        if parallel:
            from mpi4py import MPI

            self.comm.Reduce(MPI.IN_PLACE if self.comm.rank == 0 else grid, grid, op=MPI.SUM, root=0)
        if self.comm is None or self.comm.rank == 0:
            fk = scipy.fft.rfftn(grid, axes=(0, 1, 2))
            _apply_kernel(fk, self._scale, self._recip)
            grid = np.ascontiguousarray(scipy.fft.irfftn(fk, s=par.grid, axes=(0, 1, 2)))
        if parallel:
            self.comm.Bcast(grid, root=0)
        _interpolate(self._frac, self._radii, self._order, grid, *stencil, y)

    def matvec(self, x):
        """M_inf x for x of shape (11N,); collective over comm."""
        x = np.asarray(x, dtype=float)
        if x.shape != (NDOF * self.n_particles,):
            raise ValueError(f"x must have shape ({NDOF * self.n_particles},) (11 per particle), "
                             f"got {x.shape}")
        x = np.ascontiguousarray(x)
        y = np.zeros_like(x)
        self.wave_space(x, y)
        self.real_space(x, y)
        if self.comm is None or self.comm.rank == 0:
            y += self._self * x
        if self.comm is not None and self.comm.size > 1:
            from mpi4py import MPI

            self.comm.Allreduce(MPI.IN_PLACE, y, op=MPI.SUM)
        return y
