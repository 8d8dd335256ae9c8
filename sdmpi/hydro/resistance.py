"""The grand resistance of Stokesian dynamics, R = (M_inf)^-1 + sum (R_2B - R_2B,inf).

Durlofsky, Brady & Bossis (1987) unbounded; Brady, Phillips, Lester & Bossis (1988)
periodic. Generalized vectors per particle (11 components, see `farfield`):
F = (F, L, -S) = R (U - U_inf, Omega - Omega_inf, -E_inf), viscosity 1.

M_inf^-1 is kept in block form (`GrandResistance`): with the rigid-body dofs a (U, Omega: 6
per particle) and the strain dofs b (E: 5 per particle), M_bb = U_b^T U_b (Cholesky) and
X = M_ab U_b^-1, the Schur complement S = M_aa - X X^T gives (block inversion; e.g. Golub &
Van Loan, Matrix Computations, sec. 3.2)

    [M^-1]_aa = S^-1,   [M^-1]_ab = -S^-1 M_ab M_bb^-1,
    [M^-1]_bb = M_bb^-1 + M_bb^-1 M_ba S^-1 M_ab M_bb^-1.

Only S^-1 (6N x 6N) is formed, by Cholesky (LAPACK potrf/potri): R_FU = S^-1 + L_FU must be
a matrix (it is factorised), while the far-field parts of R_FE, R_SU and R_SE only act on
vectors, through X and triangular solves with U_b. This costs about half the flops of
inverting the whole (11N)^2 M_inf. The lubrication L is added pair by pair into dense
partitions L_FU, L_FE, L_SE (its products are then BLAS matrix-vector products: a pair
list within the lubrication cut-off of 2 radii holds about as many entries as the dense
partitions up to N ~ 50, and the dense products stream them several times faster).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from scipy.linalg import blas, lapack

from .farfield import (DEFAULT_EWALD_TOL, NDOF, FarFieldIndefinite, FarFieldPlan, far_field_mobility,
                       far_field_product, plan_far_field)
from .geometry import Lattice, pairs_in_reach
from .krylov import DenseFarField, far_field_operator, particle_ranges
from .lubrication import (DEFAULT_CUTOFF, DEFAULT_MIN_GAP, PairList, close_pairs, lubrication_partitions,
                          lubrication_product, lubrication_reach, lubrication_rows)
from .workspace import release_free_memory

#: M_inf's block inversion runs in single precision for Ewald sums from this tolerance on
#: (its rounding, ~1e-6 of S^-1 at N = 27-343, stays below a tenth of the tolerance; LAPACK's
#: single-precision kernels take ~0.6 of the time) and from SINGLE_PRECISION_MIN_N spheres
#: on (`single_precision_inverse`; docs/numerics.md)
SINGLE_PRECISION_TOL = 1e-5
SINGLE_PRECISION_MIN_N = 64


@dataclass
class HydroPlan:
    """Pair sets of one configuration, reused for its small displacements."""

    far: FarFieldPlan | None  # built on first use
    near_images: tuple | None  # (i, j, shift) of the lubrication pairs, None: no lubrication


@dataclass
class GrandResistance:
    """R = M_inf^-1 + L at one configuration, in the block form of the module docstring:
    S^-1 = [M^-1]_aa (6N x 6N, dofs particle by particle; R_FU = S^-1 + L_FU is formed when
    asked for, `r_fu_rows`), the upper
    Cholesky factor U_b of M_bb (5N x 5N, M_bb = U_b^T U_b) and X = M_ab U_b^-1 (6N x 5N,
    Fortran-ordered); the lubrication as dense partitions (L_FU, L_FE, L_SE)
    (`lubrication.lubrication_partitions`); its close pairs, the plan it was built with,
    the (wrapped) positions it was built at and the radii."""

    s_inverse: np.ndarray
    x_ab: np.ndarray
    chol_bb: np.ndarray
    lubrication_dense: tuple | None
    pairs: PairList
    plan: HydroPlan
    positions: np.ndarray
    radii: np.ndarray
    #: the lubrication pairs' orientation and tables (`lubrication.lubrication_partitions`),
    #: for `lubrication.lubrication_product` at displaced positions; None: looked up again
    lubrication_setup: tuple | None = None
    #: S^-1, X, U_b are the double-precision block inverse of M_inf at these positions, so
    #: that M_inf (M^-1 v) = v to round-off (`resistance_change` relies on it); False for
    #: an inversion in single precision or blocks of another configuration
    exact_inverse: bool = False

    @property
    def n_particles(self) -> int:
        """The number of spheres N."""
        return self.positions.shape[0]

    def r_fu_rows(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Rows start:stop of R_FU = S^-1 + L_FU (a fresh C-ordered array; all 6N rows by
        default).

        Args:
            start: first row (of 6N).
            stop: end of the rows (exclusive), None: 6N.

        Returns:
            (stop - start, 6N) rows of R_FU (Stokes units, viscosity 1).
        """
        rows = slice(start, stop)
        if self.lubrication_dense is None:
            return self.s_inverse[rows].copy()
        return self.s_inverse[rows] + self.lubrication_dense[0][rows]

    @property
    def r_fu(self) -> np.ndarray:
        """R_FU = S^-1 + L_FU (6N x 6N, a fresh array)."""
        return self.r_fu_rows()

    def far_inverse_product(self, v: np.ndarray, rows: str | None = None) -> np.ndarray:
        """M_inf^-1 v (N, 11) for v (N, 11): with z = U_b^-T v_b, y_a = S^-1 (v_a - X z)
        and y_b = U_b^-1 (z - X^T y_a) (= M_bb^-1 v_b - M_bb^-1 M_ba y_a). rows "rigid":
        y_a alone (N, 6); "strain": y_b alone (N, 5); None: both (N, 11).

        Args:
            v: (N, 11) generalized velocities (U, Omega, E) per sphere.
            rows: "rigid", "strain" or None (which rows of the product).

        Returns:
            (N, 6), (N, 5) or (N, 11): M_inf^-1 v (generalized forces, Stokes units).
        """
        n = self.n_particles
        v_a, v_b = np.ascontiguousarray(v[:, :6]).ravel(), np.ascontiguousarray(v[:, 6:]).ravel()
        z = _triangular_solve(self.chol_bb, v_b, 1) if v_b.any() else None  # none for rigid-body v
        y_a = self.s_inverse @ (v_a if z is None else v_a - self.x_ab @ z)
        if rows == "rigid":
            return y_a.reshape(n, 6)
        rhs = -(self.x_ab.T @ y_a)
        if z is not None:
            rhs += z
        y_b = _triangular_solve(self.chol_bb, rhs, 0)
        if rows == "strain":
            return y_b.reshape(n, 5)
        out = np.empty((n, NDOF))
        out[:, :6] = y_a.reshape(n, 6)
        out[:, 6:] = y_b.reshape(n, 5)
        return out

    def lubrication_product(self, v: np.ndarray, rows: str | None = None, strain_only: bool = False) -> np.ndarray:
        """L v (N, 11) for v (N, 11) by the dense partitions; rows "rigid" (N, 6) or "strain"
        (N, 5): those rows alone; strain_only: v is zero on the rigid-body dofs (skipped).

        Args:
            v: (N, 11) generalized velocities (U, Omega, E) per sphere.
            rows: "rigid", "strain" or None (all 11).
            strain_only: v vanishes on the rigid-body dofs.

        Returns:
            (N, 6), (N, 5) or (N, 11): L v (generalized forces, Stokes units).
        """
        n = self.n_particles
        if self.lubrication_dense is None:
            return np.zeros((n, {None: NDOF, "rigid": 6, "strain": 5}[rows]))
        l_fu, l_fe, l_se = self.lubrication_dense
        v_a, v_b = v[:, :6].ravel(), v[:, 6:].ravel()
        parts = []
        if rows != "strain":
            rigid = l_fe @ v_b
            if not strain_only:
                rigid += l_fu @ v_a
            parts.append(rigid.reshape(n, 6))
        if rows != "rigid":
            strain = l_se @ v_b
            if not strain_only:
                strain += l_fe.T @ v_a
            parts.append(strain.reshape(n, 5))
        return parts[0] if len(parts) == 1 else np.hstack(parts)

    def product(self, v: np.ndarray, rows: str | None = None, strain_only: bool = False) -> np.ndarray:
        """R v (N, 11) for v (N, 11); rows "rigid" (N, 6) or "strain" (N, 5): those rows alone;
        strain_only: v is zero on the rigid-body dofs.

        Args:
            v: (N, 11) generalized velocities (U, Omega, E) per sphere.
            rows: "rigid", "strain" or None (all 11).
            strain_only: v vanishes on the rigid-body dofs.

        Returns:
            (N, 6), (N, 5) or (N, 11): R v (generalized forces (F, L, S), Stokes units).
        """
        return self.far_inverse_product(v, rows) + self.lubrication_product(v, rows, strain_only)

    def apply(self, rigid: np.ndarray, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rigid (N, 6) and strain (N, 5) rows of R (rigid, strain): R_FU u + R_FE e and
        R_SU u + R_SE e for u = rigid, e = strain.

        Args:
            rigid: (N, 6) velocities and angular velocities u.
            strain: (N, 5) rates of strain e (`basis` components).

        Returns:
            (N, 6) forces/torques and (N, 5) stresslets (Stokes units).
        """
        out = self.product(np.hstack([rigid, strain]))
        return out[:, :6], out[:, 6:]

    def strain_forces(self, einf: np.ndarray) -> np.ndarray:
        """R_FE e_inf (6N,) for einf (N, 5) (zero without a strain).

        Args:
            einf: (N, 5) imposed rate of strain at each sphere (`basis` components).

        Returns:
            (6N,) forces and torques, sphere by sphere (Stokes units).
        """
        if not np.any(einf):
            return np.zeros(6 * self.n_particles)
        v = np.zeros((self.n_particles, NDOF))
        v[:, 6:] = einf
        return self.product(v, "rigid", strain_only=True).ravel()

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """S = R_SE e_inf - R_SU U' (N, 5) at this resistance: arguments, units and result
        as `sdmpi.hydro.backend.SolverBackend.stresslets`, which the direct solvers answer
        with it."""
        v = np.empty((self.n_particles, NDOF))
        np.negative(velocities, out=v[:, :6])
        v[:, 6:] = einf
        return self.product(v, "strain")

    def blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(R_FU, R_FE, R_SU, R_SE) as fresh dense matrices (dofs particle by particle within
        each; R_SU = R_FE^T): formed explicitly from the block form, for reference and
        tests (a step uses `apply`).

        Returns:
            R_FU (6N, 6N), R_FE (6N, 5N), R_SU (5N, 6N), R_SE (5N, 5N).
        """
        n = self.n_particles
        x = _triangular_solve(self.chol_bb, np.asfortranarray(self.x_ab.T), 0)  # M_bb^-1 M_ba (5N x 6N)
        inv_ab = -self.s_inverse @ x.T
        inv_bb = _chol_solve(self.chol_bb, np.eye(5 * n)) + x @ self.s_inverse @ x.T
        if self.lubrication_dense is None:
            return self.r_fu, inv_ab, inv_ab.T, inv_bb
        _, l_fe, l_se = self.lubrication_dense
        r_fe = inv_ab + l_fe
        return self.r_fu, r_fe, r_fe.T, inv_bb + l_se

    @property
    def matrix(self) -> np.ndarray:
        """The whole R (11N x 11N, dofs particle by particle), formed from `blocks` (for
        reference and tests)."""
        n = self.n_particles
        r_fu, r_fe, r_su, r_se = self.blocks()
        idx = np.arange(NDOF * n).reshape(n, NDOF)
        rigid, strain = idx[:, :6].ravel(), idx[:, 6:].ravel()
        out = np.empty((NDOF * n, NDOF * n))
        out[np.ix_(rigid, rigid)], out[np.ix_(rigid, strain)] = r_fu, r_fe
        out[np.ix_(strain, rigid)], out[np.ix_(strain, strain)] = r_su, r_se
        return out


def _triangular_solve(upper, rhs, trans):
    """U^-1 rhs (trans 0) or U^-T rhs (trans 1) for the upper triangular U (LAPACK trtrs)."""
    sol, info = lapack.dtrtrs(upper, rhs, lower=0, trans=trans)
    if info != 0:
        raise ValueError(f"trtrs: illegal argument {-info}")
    return sol


def _chol_solve(upper, rhs):
    """A^-1 rhs for A = U^T U (upper factor U, LAPACK potrs)."""
    sol, info = lapack.dpotrs(upper, rhs, lower=False)
    if info != 0:
        raise ValueError(f"potrs: illegal argument {-info}")
    return sol


@numba.njit(cache=True)
def _partition(matrix, r_fu, r_fe, r_se):
    """Copies the rigid-body (6 per particle) and strain (5 per particle) rows and
    columns of an (11N, 11N) matrix into its FU, FE and SE partitions."""
    n = r_fu.shape[0] // 6
    for i in range(n):
        for a in range(NDOF):
            row = matrix[NDOF * i + a]
            for j in range(n):
                for b in range(NDOF):
                    v = row[NDOF * j + b]
                    if a < 6:
                        if b < 6:
                            r_fu[6 * i + a, 6 * j + b] = v
                        else:
                            r_fe[6 * i + a, 5 * j + b - 6] = v
                    elif b >= 6:
                        r_se[5 * i + a - 6, 5 * j + b - 6] = v


def _spd_inverse_of_upper(upper):
    """The inverse (Fortran-ordered, both triangles) of the symmetric positive definite
    matrix held in the upper triangle of the Fortran-ordered array upper, in its memory
    and precision (FarFieldIndefinite if it is not: the Schur complement of M_inf)."""
    potrf, potri = lapack.get_lapack_funcs(("potrf", "potri"), (upper,))
    chol, info = potrf(upper, lower=False, clean=False, overwrite_a=True)
    if info != 0:
        raise FarFieldIndefinite(f"the far-field mobility M_inf is not positive definite "
                                 f"(potrf info {info}, Schur complement)")
    inv, info = potri(chol, lower=False, overwrite_c=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"potri failed (info {info})")
    _mirror_upper(inv)
    return inv


@numba.njit(cache=True)
def _mirror_upper(a):
    """Copies the upper triangle of a square matrix onto its lower triangle, in place."""
    for i in range(a.shape[0]):
        for j in range(i):
            a[i, j] = a[j, i]


def check_overlaps(pairs: PairList, radii: np.ndarray, max_overlap: float) -> None:
    """ValueError if a pair overlaps by more than max_overlap of its mean radius.

    Args:
        pairs: the close pairs (`lubrication.close_pairs`).
        radii: (N,) sphere radii.
        max_overlap: largest allowed overlap depth, in mean radii of the pair.

    Raises:
        ValueError: a deeper overlap, naming the pair.
    """
    if len(pairs.gap) == 0:
        return
    depth = -pairs.gap / (0.5 * (radii[pairs.i] + radii[pairs.j]))
    p = int(np.argmax(depth))
    if depth[p] > max_overlap:
        raise ValueError(f"positions: spheres {pairs.i[p]} and {pairs.j[p]} overlap by "
                         f"{depth[p]:.3g} mean radii (allowed: up to {max_overlap})")


def _pairs_and_plan(positions, radii, box, strain, lubrication, cutoff, min_gap, max_overlap, plan,
                    far_field=False, ewald_tol=DEFAULT_EWALD_TOL):
    """(lattice, positions, close pairs, plan) of `grand_resistance` and `split_resistance`;
    far_field: a new plan gets its far-field plan too (tolerance ewald_tol), whose
    real-space images then serve the lubrication pairs where they reach far enough (one
    pair search)."""
    lattice = None if box is None else Lattice(box, strain)
    if plan is None:
        pos = positions if lattice is None else lattice.wrap(positions)
        far = plan_far_field(pos, radii, lattice, ewald_tol) if far_field else None
        near = None
        if lubrication:
            near = pairs_in_reach(pos, radii, lattice, 0.0, lubrication_reach(cutoff),
                                  None if far is None else far.real_space_reach)
        plan = HydroPlan(far, near)
    else:
        pos = positions
    if plan.near_images is None:  # without lubrication: overlapping pairs only
        pairs = close_pairs(pos, radii, lattice, 0.0, min_gap)
    else:
        pairs = close_pairs(pos, radii, None, cutoff, min_gap, images=plan.near_images)
    if max_overlap is not None:
        check_overlaps(pairs, radii, max_overlap)
    return lattice, pos, pairs, plan


def grand_resistance(positions: np.ndarray, radii: np.ndarray, box: np.ndarray | None = None, strain: float = 0.0,
                     lubrication: bool = True, ewald_tol: float = DEFAULT_EWALD_TOL, cutoff: float = DEFAULT_CUTOFF,
                     min_gap: float = DEFAULT_MIN_GAP, max_overlap: float | None = None, plan: HydroPlan | None = None,
                     far: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> GrandResistance:
    """Assemble R (`GrandResistance`). Positions are wrapped into the sheared cell, unless a
    plan from an earlier call is given: then they are used as given with the plan's pair
    sets (for displaced configurations about that one). max_overlap (mean radii): raise
    ValueError for deeper overlaps before the expensive work. far: the far-field blocks
    (S^-1, X, U_b) of another configuration to use instead of those at these positions
    (the far field held fixed between refreshes; None: computed here).

    Args:
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii a.
        box: (3,) sides of the periodic Lees-Edwards box, or None (unbounded fluid).
        strain: Lees-Edwards strain of the box.
        lubrication: add the pairwise lubrication.
        ewald_tol: relative accuracy of the Ewald sums.
        cutoff: lubrication cut-off (`lubrication.DEFAULT_CUTOFF`).
        min_gap: smallest gap of a close pair (`lubrication.close_pairs`).
        max_overlap: largest allowed overlap (mean radii), None: not checked.
        plan: the pair sets of an earlier call, or None.
        far: far-field blocks (S^-1, X, U_b) from `far_field_blocks`, or None.

    Returns:
        The resistance R in block form (Stokes units, viscosity 1).
    """
    radii = np.asarray(radii, dtype=float)
    lattice, pos, pairs, plan = _pairs_and_plan(positions, radii, box, strain, lubrication, cutoff,
                                                min_gap, max_overlap, plan, far_field=True, ewald_tol=ewald_tol)
    if plan.far is None:
        plan.far = plan_far_field(pos, radii, lattice, ewald_tol)
    if far is None:
        single = lattice is not None and single_precision_inverse(len(pos), ewald_tol)
        far, exact = _far_field_inverse(far_field_mobility(pos, radii, plan=plan.far), single)
    else:
        exact = False  # blocks of another configuration
    lub = lubrication_partitions(radii, pairs, len(pos)) if plan.near_images is not None else None
    return from_blocks(far, lub, pairs, plan, pos, radii, exact)


def from_blocks(far: tuple[np.ndarray, np.ndarray, np.ndarray], lub: tuple | None, pairs: PairList,
                plan: HydroPlan, positions: np.ndarray, radii: np.ndarray,
                exact_inverse: bool = False) -> GrandResistance:
    """The GrandResistance of the far-field blocks far (`far_field_blocks`) and the
    lubrication lub: (dense partitions, setup) from `lubrication.lubrication_partitions`
    (None: none).

    Args:
        far: (S^-1 (6N, 6N), X (6N, 5N), U_b (5N, 5N)).
        lub: (dense partitions, setup), or None.
        pairs: the close pairs.
        plan: the pair sets of the configuration.
        positions: (N, 3) sphere centres (wrapped).
        radii: (N,) sphere radii.
        exact_inverse: far is the double-precision inverse of M_inf at these positions
            (`GrandResistance.exact_inverse`).

    Returns:
        The resistance R in block form.
    """
    s_inverse, x_ab, chol_bb = far
    dense, setup = (None, None) if lub is None else lub
    return GrandResistance(s_inverse, x_ab, chol_bb, dense, pairs, plan, positions, radii, setup, exact_inverse)


def single_precision_inverse(n_particles: int, ewald_tol: float) -> bool:
    """Whether `grand_resistance` inverts M_inf of n_particles spheres summed to ewald_tol in
    single precision: from `SINGLE_PRECISION_TOL` and `SINGLE_PRECISION_MIN_N` spheres on
    (below, the inversion is too small a part of a step to pay for the second far-field
    product it costs `resistance_change`)."""
    return ewald_tol >= SINGLE_PRECISION_TOL and n_particles >= SINGLE_PRECISION_MIN_N


def _far_field_inverse(mob: np.ndarray, single: bool) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], bool]:
    """(`far_field_blocks` of mob, whether they are its double-precision inverse): in single
    precision if asked, and in double precision where single precision finds a pivot that
    is not positive (eigenvalues of M_inf within its rounding, ~1e-7 of the largest, of
    zero, which double precision may still resolve)."""
    if single:
        try:
            return far_field_blocks(mob, single=True), False
        except FarFieldIndefinite:
            pass
    return far_field_blocks(mob), True


def far_field_blocks(mob: np.ndarray, single: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S^-1, X = M_ab U_b^-1, U_b) of the far-field mobility mob (11N x 11N) (module docstring).

    Args:
        mob: (11N, 11N) far-field mobility M_inf (Stokes units, viscosity 1).
        single: factorise and invert in single precision (LAPACK's s-kernels, ~0.6 of the
            time; relative rounding of S^-1 ~1e-6 at N = 27-343, for M_inf summed no more
            accurately than `SINGLE_PRECISION_TOL`); the blocks are returned in
            double precision either way.

    Returns:
        S^-1 (6N, 6N), X (6N, 5N, Fortran-ordered), U_b (5N, 5N) upper Cholesky factor of M_bb.

    Raises:
        FarFieldIndefinite: M_inf is not positive definite.
    """
    n = mob.shape[0] // NDOF
    dtype = np.float32 if single else np.float64
    m_aa, m_ab, m_bb = (np.empty(shape, dtype) for shape in ((6 * n, 6 * n), (6 * n, 5 * n), (5 * n, 5 * n)))
    _partition(mob, m_aa, m_ab, m_bb)
    potrf, = lapack.get_lapack_funcs(("potrf",), (m_bb,))
    trsm, syrk = blas.get_blas_funcs(("trsm", "syrk"), (m_bb,))
    chol_bb, info = potrf(m_bb.T, lower=False, clean=True, overwrite_a=True)
    if info != 0:
        raise FarFieldIndefinite(f"the far-field mobility M_inf is not positive definite "
                                 f"(potrf info {info}, strain block)")
    # X = M_ab U_b^-1 (6N x 5N; the right-side solve is the faster kernel), S = M_aa - X X^T
    x = trsm(1.0, chol_bb, np.asfortranarray(m_ab), side=1, overwrite_b=1)
    del m_ab  # (its Fortran-ordered copy became x)
    schur = syrk(-1.0, x, beta=1.0, c=m_aa.T, trans=0, lower=0, overwrite_c=1)  # upper triangle
    del m_aa, m_bb  # (their memory is schur's and chol_bb's)
    s_inverse = _spd_inverse_of_upper(schur).T
    if not single:
        return s_inverse, x, chol_bb
    del schur
    # to double precision one array at a time, each single-precision one freed before the next
    s_inverse = s_inverse.astype(np.float64)
    x = np.asfortranarray(x, dtype=np.float64)
    chol_bb = np.asfortranarray(chol_bb, dtype=np.float64)
    return s_inverse, x, chol_bb


def resistance_change(base: GrandResistance, moved: np.ndarray, vector: np.ndarray, min_gap: float) -> np.ndarray:
    """[R(moved) - R(base)] v (N, 11) for one vector v (N, 11), to first order in the
    displacement moved - base.positions (small, e.g. a random finite difference), with the
    pair sets of base (its plan) and without assembling or inverting anything at moved:

        Delta R v = -M^-1 [M_inf(moved) - M_inf(base)] w + L(moved) v - L(base) v,   w = M^-1 v,

    M^-1 from base's block form, the far-field products by `farfield.far_field_product`
    with base's far-field plan (the same images and wave vectors as base's M_inf, so that
    the difference carries the Ewald truncation of the change, not of M_inf). Where base's
    blocks are M_inf's double-precision inverse at its positions
    (`GrandResistance.exact_inverse`), M_inf(base) w is v to round-off and one product
    suffices; otherwise (an inverse rounded to ~1e-7 by `far_field_blocks` in single
    precision breaks M_inf w = v by ~1e-7 |v|, as much as the whole change of a random
    finite difference, ~1e-6 of R v) M_inf(base) w is the second product, and the change
    carries M^-1's rounding only relatively. L(moved) v pair by pair with base's pair
    images and tables (`lubrication.lubrication_product`,
    separations floored at min_gap as in `close_pairs`) and L(base) v by base's dense
    partitions. The lubrication difference carries a round-off of ~eps max|L v| (eps =
    2.2e-16), as the entries of L do (tests/test_resistance_change.py). The dropped term,
    M^-1 Delta M M^-1 Delta M M^-1 v, is second order in the displacement.

    Args:
        base: the resistance at the base configuration.
        moved: (N, 3) displaced sphere centres (length unit of the radii).
        vector: (N, 11) generalized velocities v.
        min_gap: smallest gap of a close pair (as in `close_pairs`).

    Returns:
        (N, 11) the change [R(moved) - R(base)] v (generalized forces, Stokes units).
    """
    vector = np.ascontiguousarray(vector, dtype=float)
    far_v = base.far_inverse_product(vector)
    far = base.plan.far
    at_base = vector if base.exact_inverse else far_field_product(base.positions, base.radii, far, far_v)
    out = -base.far_inverse_product(far_field_product(moved, base.radii, far, far_v) - at_base)
    if base.plan.near_images is not None and base.lubrication_dense is not None:
        pairs = close_pairs(moved, base.radii, None, min_gap=min_gap, images=base.plan.near_images)
        out += lubrication_product(base.radii, pairs, vector, base.lubrication_setup)
        out -= base.lubrication_product(vector)
    return out


def mobility_change(base: GrandResistance, solver: Any, moved: np.ndarray, velocities: np.ndarray,
                    min_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """(du, ds) of velocities m = R_FU^-1 F (no imposed strain) at moved positions, to first
    order in Delta R = R(moved) - R(base) (`resistance_change` of (m, 0)):
    du = [R_FU^-1(moved) - R_FU^-1] F = -R_FU^-1 Delta R_FU m (one solve with solver, a
    direct solver of base) and ds = -[(R_SU R_FU^-1)(moved) - R_SU R_FU^-1] F =
    -(Delta R_SU m + R_SU du) (the matrix-free backend's own: `krylov.KrylovSolver.mobility_change`).

    Args:
        base: the resistance at the base configuration.
        solver: a solver of base (`backend.SolverBackend`).
        moved: (N, 3) nearby sphere centres.
        velocities: (N, 6) m.
        min_gap: smallest gap of a close pair (as in `close_pairs`).

    Returns:
        (du (N, 6), ds (N, 5)), Stokes units.
    """
    n = base.n_particles
    zero = np.zeros((n, 5))
    direction = np.zeros((n, NDOF))
    direction[:, :6] = velocities
    change = resistance_change(base, moved, direction, min_gap)
    du = -solver.velocities(change[:, :6], zero)
    return du, solver.stresslets(du, zero) - change[:, 6:]


def mobility_divergence(resistance_at: Callable[[np.ndarray, HydroPlan], GrandResistance], base: GrandResistance,
                        h: float = 1e-5) -> tuple[np.ndarray, np.ndarray]:
    """The divergences (div M (6N,), div A (5N,)), (div X)_i = sum_j dX_ij/dx_j over the
    3N translations, of M = R_FU^-1 and A = R_SU R_FU^-1 at the configuration of the
    GrandResistance base, by centred finite differences of step h with base's pair sets
    (its plan): kT div M is the Brownian drift, -kT div A the mean Brownian stresslets.
    resistance_at(positions, plan) assembles R (as `grand_resistance` with a plan). The
    differences of R_FU^-1 over h need M_inf inverted in double precision (rounding in
    single precision, ~1e-7, over h = 1e-5 would swamp them): base must be an exact
    inverse (`GrandResistance.exact_inverse`: fewer than `SINGLE_PRECISION_MIN_N`
    spheres or Ewald sums below `SINGLE_PRECISION_TOL`).

    Args:
        resistance_at: assembles R at (positions (N, 3), plan).
        base: the resistance at the configuration.
        h: finite-difference step (length unit of the radii).

    Returns:
        div M (6N,) and div A (5N,), in units of M and A per length.

    Raises:
        ValueError: base's far-field inverse is not exact.
    """
    if not base.exact_inverse:
        raise ValueError("mobility_divergence needs M_inf inverted in double precision at the "
                         f"configuration: fewer than {SINGLE_PRECISION_MIN_N} spheres or an Ewald "
                         f"tolerance below {SINGLE_PRECISION_TOL:g} (GrandResistance.exact_inverse)")
    n = base.n_particles
    div_m, div_a = np.zeros(6 * n), np.zeros(5 * n)
    for p in range(n):
        for c in range(3):
            col = 6 * p + c
            columns = []
            for sign in (1, -1):
                moved = base.positions.copy()
                moved[p, c] += sign * h
                r_fu, _, r_su, _ = resistance_at(moved, base.plan).blocks()
                m_col = np.linalg.inv(r_fu)[:, col]
                columns.append((m_col, r_su @ m_col))
            div_m += (columns[0][0] - columns[1][0]) / (2 * h)
            div_a += (columns[0][1] - columns[1][1]) / (2 * h)
    return div_m, div_a


@dataclass
class SplitResistance:
    """R = M_inf^-1 + L without M_inf^-1 (for `krylov.KrylovSolver`): the far-field
    mobility as an operator (`far.matvec`), this rank's block rows of the lubrication L
    (its spheres p0 .. p1 - 1 of `krylov.particle_ranges`: a sparse (11 (p1 - p0) x 11N)
    BSR matrix; all of L on one rank), and pair_factors (at, pair_i, pair_j, C_p) of the
    lubrication pairs that touch this rank's spheres (`lubrication.lubrication_rows`): the
    Cholesky factors C_p (m, 12, 12) of their rigid-body blocks, for Brownian forces, their
    spheres and their places among all pairs (the rows of their noise; None in a
    resistance for solves only, `split_resistance` with brownian=False). lubricated: the
    lubrication pairs (None without lubrication, when pairs are the overlaps)."""

    far: object
    lubrication: object
    pair_factors: tuple | None
    lubricated: PairList | None
    pairs: PairList
    plan: HydroPlan
    positions: np.ndarray
    radii: np.ndarray
    volume_fraction: float  # sum of sphere volumes / box volume (0 in unbounded fluid)
    lattice: Lattice | None  # the periodic box (None: unbounded fluid)

    @property
    def n_particles(self) -> int:
        """The number of spheres N."""
        return self.positions.shape[0]


def _rank_lubrication(positions, radii, pairs, comm, factors):
    """This rank's block rows of `lubrication.lubrication_sparse(positions, radii, pairs)`
    (the spheres of `krylov.particle_ranges` on comm), formed by this rank from the pairs
    that touch them (`lubrication.lubrication_rows`: the same bits as the whole matrix's
    rows), and with factors (at, pair_i, pair_j, C_p) of those pairs (factors False:
    None). A pair whose rigid-body block is not positive definite raises LinAlgError on
    every rank of comm, not only on those whose rows it touches."""
    rank, size = (0, 1) if comm is None else (comm.rank, comm.size)
    bounds = particle_ranges(positions.shape[0], size)
    rows = (bounds[rank], bounds[rank + 1])
    if not factors or size == 1:
        return lubrication_rows(positions, radii, pairs, rows, factors)
    try:
        out, failure = lubrication_rows(positions, radii, pairs, rows, factors), None
    except np.linalg.LinAlgError as err:
        failure = str(err)
    failure = next((f for f in comm.allgather(failure) if f is not None), None)
    if failure is not None:
        raise np.linalg.LinAlgError(failure)
    return out


def split_resistance(positions: np.ndarray, radii: np.ndarray, box: np.ndarray | None = None, strain: float = 0.0,
                     lubrication: bool = True, ewald_tol: float = DEFAULT_EWALD_TOL, cutoff: float = DEFAULT_CUTOFF,
                     min_gap: float = DEFAULT_MIN_GAP, max_overlap: float | None = None,
                     plan: HydroPlan | None = None, far_field: str | None = None, comm: Any = None,
                     brownian: bool = True) -> SplitResistance:
    """The matrix-free form of `grand_resistance` (same arguments and pair sets): the
    far field by the operator `far_field` (`krylov.far_field_operator`: "spectral",
    "dense", None: by N; built on the MPI communicator comm), the
    lubrication sparse, each rank's block rows of `lubrication.lubrication_sparse`'s
    matrix (`krylov.particle_ranges`) computed by that rank.

    Args:
        positions, radii, box, strain, lubrication, ewald_tol, cutoff, min_gap,
            max_overlap, plan: as for `grand_resistance`.
        far_field: "spectral", "dense" or None (chosen by N).
        comm: the MPI communicator (collective over it), or None (this rank alone).
        brownian: with the lubrication pairs' factors of the Brownian forces (False: a
            resistance for solves only, without pair_factors; 12 x 12 doubles per pair
            less).

    Returns:
        The matrix-free resistance (Stokes units, viscosity 1).
    """
    release_free_memory()  # what resistances and solvers that have gone held (the last step's)
    radii = np.asarray(radii, dtype=float)
    lattice, pos, pairs, plan = _pairs_and_plan(positions, radii, box, strain, lubrication, cutoff,
                                                min_gap, max_overlap, plan)
    far = far_field_operator(far_field, pos, radii, lattice, ewald_tol, comm, plan.far)
    if isinstance(far, DenseFarField):
        plan.far = far.plan
    if plan.near_images is None:  # the pairs are overlaps only: no lubrication
        none = np.zeros(0, dtype=np.int64)
        lub_pairs = close_pairs(pos, radii, images=(none, none, np.zeros((0, 3))))
    else:
        lub_pairs = pairs
    lub, factors = _rank_lubrication(pos, radii, lub_pairs, comm, brownian)
    # the box's volume fraction (a monolayer's cell of height layer_spacing x L: ~0.02,
    # so its preconditioner's self-resistance scale is ~1)
    phi = 0.0 if lattice is None else float(np.sum(4 * np.pi / 3 * radii ** 3) / lattice.volume)
    lubricated = lub_pairs if len(lub_pairs.i) else None
    return SplitResistance(far, lub, factors, lubricated, pairs, plan, pos, radii, phi, lattice)
