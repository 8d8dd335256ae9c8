"""`petsc-krylov`: the FTS resistance problem solved matrix-free, in mixed (saddle-point) form.

No inverse of the far-field mobility M = M_inf is formed. With the resistance
R = M^-1 + L (L the sparse lubrication correction, `lubrication.lubrication_sparse`), the
generalized velocity V = P_u^T U' + P_e^T (-e_inf) (11 per particle: U', Omega', -E_inf)
and the auxiliary unknown lambda = M^-1 V, the problem (F, L, -S) = R V becomes
(Sierou & Brady, J. Fluid Mech. 448, 115 (2001); Fiore & Swan, J. Fluid Mech. 878, 544
(2019), "fast SD"):

    M lambda - P_u^T U' = P_e^T (-e_inf)
    P_u lambda + L_uu U' = F - L_ue (-e_inf)            (viscosity 1)

solved for (lambda, U') by left-preconditioned GMRES in PETSc (a shell matrix: the far
field as a product `matvec`, L_uu a PETSc BAIJ matrix); -S = P_e (lambda + L V). The
first-order change of a solve at nearby positions (a random finite difference,
`KrylovSolver.mobility_change`) is the same system with the right-hand side
(-Delta M lambda, -Delta L_uu U').

Preconditioner: the same system with M replaced by the block-diagonal D (isolated-sphere
self blocks divided by `self_resistance_scale(phi)`, weighted by
`self_resistance_weights`), solved by block elimination,

    y = G^-1 (g - P_u D^-1 f),   x = D^-1 (f + P_u^T y),   G = L_uu + P_u D^-1 P_u^T,

G applied through a block incomplete factor with FILL_LEVELS levels of fill, keeping the
lubrication coupling of pairs closer than PRECONDITIONER_MAX_GAP, held and applied by
rank 0 of the communicator (g gathered there, G^-1 g scattered back: the factor of the
whole G, so the iteration counts do not depend on the rank count); the Brownian midpoint's
solver takes over the start's factor (`take_preconditioner`).

Brownian forces with covariance R_FU = P_u M^-1 P_u^T + L_uu, without a dense root:

    F_B = P_u P (P^T M P)^-1/2 z_1 + sum_pairs Q_p^T C_p z_p,
    C_p C_p^T = (R_2B - R_2B,inf)_FU,p,

the first term by the Lanczos method for matrix functions (Saad 1992; Ando, Chow, Saad &
Skolnick, J. Chem. Phys. 137, 064106 (2012)) preconditioned by P with P^T C P = I,
C = D + M_long the self mobilities plus the far field's longest waves (`LongWaveFactor`;
any invertible P gives the covariance P (P^T M P)^-1 P^T = M^-1: Chow & Saad, SIAM J.
Sci. Comput. 36, A588 (2014)), the near field exactly pair by pair (Q_p places each
pair's 12x12 factor on its particles). The noise is z_1 (11N) followed by z_p (12 per
pair): `noise_shape`.

Parallel layout over the communicator: particles split in contiguous ranges; every PETSc
vector holds this rank's particles, (lambda, U') laid out [11 per particle, then 6 per
particle]. The far-field product takes and returns whole (11N,) vectors (gathered); the
sparse products and the preconditioner are local or PETSc-distributed. Each rank holds
its particles' block rows of L alone (`particle_ranges`) and the factors C_p of the pairs
that touch its particles (for its rows of F_B); G's kept blocks are gathered from all
ranks when a rank builds its factor. Inputs and outputs
of the interface are replicated numpy arrays; every method is collective.

Far field: an object with matvec((11N,)) -> M (11N,) from `far_field_operator`:
"spectral" (`spectral.SpectralFarField`, particle-mesh Ewald, O(N log N); the default in
a periodic box from DENSE_FAR_FIELD_MAX_N particles on) or "dense" (the Ewald matrix of
`farfield`: small N, unbounded fluid).

The choices of D, G and P and their measured effect on the iteration counts:
docs/numerics.md, "Krylov backend".
"""

from __future__ import annotations

import atexit
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from .backend import FORM_ACCURACY, SolverBackend
from .farfield import (NDOF, FarFieldIndefinite, far_field_mobility, far_field_product, plan_far_field,
                       self_mobility)
from .geometry import find_pairs
from .lubrication import close_pairs, lubrication_rows
from .two_sphere import squeeze_slope
from . import workspace

if TYPE_CHECKING:
    from .farfield import FarFieldPlan
    from .geometry import Lattice

#: default relative residual of the saddle-point solves and the Lanczos square roots
DEFAULT_TOL = 1e-8
#: iteration limits (a solve that does not converge within them raises)
MAX_ITERATIONS = 2000
LANCZOS_MAX_ITERATIONS = 500
#: GMRES restart length
GMRES_RESTART = 200
#: the preconditioner's solve with G: an incomplete factor with FILL_LEVELS levels of fill
#: of the whole G, on rank 0 of the communicator alone (sequential PETSc: the iteration
#: counts do not depend on the split; the other ranks, which would compute the same
#: numbers, keep its memory, 0.13 GiB at N = 10 000, for their real-space blocks), on the
#: pattern of G's full 6x6
#: blocks (zeros inside the blocks kept: ICC(0) on the pattern of the nonzero entries alone
#: stalls). Block ILU on BAIJ (block size 6) gives the factor of ICC on the AIJ matrix
#: with full blocks, in PETSc's block kernels, storing L and U. Equal while no pivot needs
#: a shift: PETSc's ICC shifts the whole diagonal when a pivot is not positive
#: (Manteuffel), ILU here shifts a singular pivot block ("inblocks"), so a near-singular
#: G degrades the preconditioner instead of stopping the solve (GMRES does not need it
#: definite). Level 1 needs about as few iterations as the exact sparse Cholesky factor at
#: a fraction of its cost; level 0 needs more, level 2 no fewer; block Jacobi per rank
#: would drop the lubrication of the pairs across the split (measurements:
#: docs/numerics.md, "Parameter choices")
FILL_LEVELS = 1
OPTIONS_PREFIX = "sdmpi_krylov_schur_"
INNER_OPTIONS = {"ksp_type": "preonly", "pc_type": "ilu", "pc_factor_levels": str(FILL_LEVELS),
                 "pc_factor_shift_type": "inblocks"}
#: G keeps the lubrication coupling (off-diagonal blocks) of pairs closer than this surface
#: gap, in mean radii (2 h / (a_i + a_j)); farther pairs keep their diagonal parts only (G
#: stays positive definite): a factor several times cheaper for about one more iteration
#: per solve; below a gap of 1 the iterations grow, near contact most (measurements:
#: docs/numerics.md, "Parameter choices")
PRECONDITIONER_MAX_GAP = 1.0
#: mobility forms (`KrylovSolver.mobility_forms`): force sets on two lubricated pairs share
#: a solve when every centre distance between their spheres is at least
#: FORMS_SEPARATION * (max(h, FORMS_MAX_GAP) / FORMS_MAX_GAP * FORM_ACCURACY / accuracy)^(1/3)
#: times the sum of the two spheres' radii, h the other pair's surface gap (mean radii) and
#: accuracy the relative accuracy asked of this pair's form (both ways; pairs sharing a
#: sphere never share a solve): the cross term
#: f_p.R_FU^-1.f_q is ~ (1 - kappa_q) ~ h_q times a coupling falling like the distance
#: cubed, and two pairs below a gap of FORMS_MAX_GAP at FORMS_SEPARATION (2: one sphere
#: diameter of space between unit spheres) leave each other's form within ~FORM_ACCURACY
#: (`sdmpi.hydro.backend`, 1e-3)
FORMS_MAX_GAP = 0.005
FORMS_SEPARATION = 2.0
#: forms of sets on lubricated pairs asked to this relative accuracy or less are estimated
#: from the preconditioner's forms, calibrated on the forms solved in the same call
#: (`KrylovSolver._estimated_forms`), where at least CALIBRATION_PAIRS of those are of
#: lubricated pairs (else solved as the others)
ESTIMATE_ACCURACY = 2e-2
CALIBRATION_PAIRS = 5
#: forces (no imposed strain) within this relative distance of a combination of the force
#: sums the last `mobility_forms` solved take the combination of their solutions instead
#: of a solve (`KrylovSolver._combined`): rounding only (weights times unit pair forces)
COMBINED_TOL = 1e-12
#: the preconditioner's far-field self resistance grows with the volume fraction like
#: (1 - phi)^-SELF_RESISTANCE_EXPONENT (self_resistance_scale)
SELF_RESISTANCE_EXPONENT = 2.5
#: ... times these weights on its (translation, rotation, stresslet) parts: translation is
#: hindered more than rotation, the stresslet less (self_resistance_weights)
SELF_RESISTANCE_WEIGHTS = (1.5, 1.0, 0.6)
#: the Lanczos preconditioner's long waves: the lattice's Fourier modes k = 2 pi n.b with
#: 0 < |n|^2 <= LONG_WAVES (92 wave vectors, 46 pairs +-k, 184 columns; `LongWaveFactor`):
#: more modes take fewer Lanczos iterations, with diminishing returns beyond 8, while the
#: cost of building P grows with the square of the columns (measurements:
#: docs/numerics.md, "Parameter choices")
LONG_WAVES = 8
#: far-field operators by name (see far_field_operator)
FAR_FIELDS = ("dense", "spectral")
#: the default far field is dense below this many particles (its matrix is 11N x 11N),
#: spectral from there on (the crossover of bench/bench_krylov.py --far-field lies below
#: this at the fast tolerances; at the tight defaults the dense matrix is also the exact
#: reference; measurements: docs/numerics.md, "Parameter choices")
DENSE_FAR_FIELD_MAX_N = 200


def _block_csr(indptr, cols, blocks):
    """PETSc's blocked CSR input of a block-sparse matrix (block row pointers, block columns,
    blocks (nb, 6, 6)): the indices as 32-bit ints, the blocks row-major and flat."""
    return indptr.astype(np.int32), cols.astype(np.int32), np.ascontiguousarray(blocks).reshape(-1)


def _near_blocks(pairs, rows, cols, n):
    """Which blocks (rows, cols) of an N x N block pattern belong to a pair of `pairs` (a
    `lubrication.PairList`) closer than PRECONDITIONER_MAX_GAP mean radii."""
    near = 2 * pairs.gap / pairs.radii_sum < PRECONDITIONER_MAX_GAP
    i, j = np.asarray(pairs.i)[near], np.asarray(pairs.j)[near]
    return np.isin(rows * n + cols, np.concatenate([i * n + j, j * n + i]))


def self_resistance_scale(phi: float) -> float:
    """Factor on the isolated-sphere far-field resistance D^-1 in the preconditioner,
    (1 - phi)^-SELF_RESISTANCE_EXPONENT at volume fraction phi: the far-field resistance
    of a sphere among others exceeds the isolated one (hindered mobility), and a larger
    D^-1 approximates M^-1 better. Empirical (N = 1000, solver tolerance 1e-6, GMRES
    iterations of a shear-flow / a random-force solve, D^-1 scale 1 -> best): phi = 0.1
    17/17 -> 17/17 (scale 1-2); 0.3 27/27 -> 23/24 (3); 0.45 42/42 -> 31/33 (5-6);
    0.55 59/57 -> 38/40 (8); the rule gives 1.3, 2.4, 4.5 and 7.4.

    Args:
        phi: volume fraction of the spheres (capped at 0.7).

    Returns:
        The dimensionless factor (1 - phi)^-SELF_RESISTANCE_EXPONENT.
    """
    return (1.0 - min(phi, 0.7)) ** -SELF_RESISTANCE_EXPONENT


def self_resistance_weights() -> np.ndarray:
    """(11,) weights w on the scaled self resistance, applied as W^1/2 D^-1 W^1/2: the
    SELF_RESISTANCE_WEIGHTS of translation, rotation and stresslet. Empirical (N = 1000,
    solver tolerance 1e-5, flow / force solve iterations, weights (1, 1, 1) -> (1.5, 1,
    0.6)): phi = 0.1 14/14 -> 13/12; 0.3 20/21 -> 17/18; 0.45 27/29 -> 24/25; 0.55 34/37
    -> 31/33 (at phi = 0.45: (2, 1, 0.5) 26/26, (1, 1, 0.5) 24/24 at N = 343, the
    rotational weight 0.5-2 makes no difference).

    Returns:
        (11,) dimensionless weights, 3 translational, 3 rotational, 5 stresslet.
    """
    return np.repeat(SELF_RESISTANCE_WEIGHTS, [3, 3, 5])


def particle_ranges(n: int, size: int) -> np.ndarray:
    """The contiguous particle ranges of size ranks, as even as rounding allows: rank r
    holds particles bounds[r] .. bounds[r + 1] - 1 (its rows of every distributed vector and
    of the lubrication matrix).

    Args:
        n: the number of spheres N.
        size: the number of ranks.

    Returns:
        (size + 1,) int bounds, from 0 to n.
    """
    return np.linspace(0, n, size + 1).round().astype(int)


def gather_rows(comm: Any, local: np.ndarray, root: int = 0) -> np.ndarray | None:
    """The arrays local of the ranks of comm stacked along their first axis in rank order
    on rank root, None on the others (None or one rank: local itself); the other axes and
    the dtype as local's, equal on every rank. Collective.

    Args:
        comm: the MPI communicator, or None.
        local: this rank's array (m, ...).
        root: the rank that receives them.

    Returns:
        On root (sum of m, ...) every rank's rows; None elsewhere.
    """
    local = np.ascontiguousarray(local)
    if comm is None or comm.size == 1:
        return local
    counts = comm.gather(local.shape[0], root=root)
    width = int(np.prod(local.shape[1:], dtype=np.int64))
    out = None
    if comm.rank == root:
        out = np.empty((sum(counts), *local.shape[1:]), dtype=local.dtype)
    comm.Gatherv(local.reshape(-1), None if out is None else [out.reshape(-1), np.array(counts) * width], root=root)
    return out


def _rank_sum(comm, local):
    """The array local summed over the ranks of comm (None or one rank: local itself)."""
    if comm is None or comm.size == 1:
        return local
    total = np.empty_like(local)
    comm.Allreduce(local, total)
    return total


def long_waves(lattice: Lattice) -> np.ndarray:
    """Wave vectors k = 2 pi n.b (m, 3) of the lattice with 0 < |n|^2 <= LONG_WAVES, one of
    each pair +-k (the first nonzero component of n positive). By |n|, not |k|: in a tall
    monolayer cell the waves along z are uniform over the layer and do not help; choosing
    the same number of modes by |k| V^(1/3) instead took 19-24 Lanczos iterations against
    17-21 (N = 400 and 1024, areal fraction 0.4, Lz = 2 L and 5 L; 27-31 without any).

    Args:
        lattice: the periodic lattice.

    Returns:
        (m, 3) wave vectors (1/length).
    """
    reach = int(np.sqrt(LONG_WAVES))
    n = np.stack(np.meshgrid(*[np.arange(-reach, reach + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    norm2 = np.einsum("ij,ij->i", n, n)
    first = n[np.arange(len(n)), np.argmax(n != 0, axis=1)]  # the first nonzero component
    n = n[(norm2 > 0) & (norm2 <= LONG_WAVES) & (first > 0)]
    return 2 * np.pi * n @ lattice.reciprocal


class LongWaveFactor:
    """The Lanczos square root's preconditioner (module docstring): a factor P with
    P^T C P = I for C = D + M_long ~ M, D the isolated-sphere self mobilities
    (`farfield.self_mobility`, diagonal), M_long the periodic Oseen-RPY mobility of the
    translational velocities through the lattice's longest waves (`long_waves`, K+),

        M_long,ij = (2/V) sum_{k in K+} j0(k a_i) j0(k a_j) / k^2 cos(k.(x_i - x_j)) (I - k k/k^2),

    j0(x) = sin(x)/x (the Faxen factor), which carry M's largest eigenvalues (the box's
    collective flows: ~n/k^2 against 1/(6 pi a) for a sphere alone; N = 4096, phi = 0.45,
    |k| = 2 pi/L: 3.1 against 0.053). With M_long = A S A^T (A: 3N x 4|K+|, cos and sin
    times two polarisations), V = D^-1/2 A, its Gram matrix V^T V = E s E^T (the
    directions with s > GRAM_CUTOFF max s: V = Q R, Q = V E s^-1/2, R = s^1/2 E^T) and
    R S R^T = W L W^T,

        P = D^-1/2 X^-1/2,   X^-1/2 = (I + V S V^T)^-1/2 = I + U diag((1 + L)^-1/2 - 1) U^T,

    U = Q W = V B, B = E s^-1/2 W (translational rows). Then F = P (P^T M P)^-1/2 z has
    covariance M^-1 (for any invertible P: P^T C P = I only makes it converge fast).
    Each rank forms its particles' rows of V (by blocks of particles, twice, never all at
    once); the Gram matrix is summed over comm, and rank 0's B and L are broadcast, so
    that all ranks use one basis. right (P x) and left (P^T x) act on this rank's
    particles p0..p1 (11 per particle) and sum over the ranks of comm. In unbounded
    fluid (lattice None), or with LONG_WAVES = 0, P = D^-1/2."""

    #: Gram eigenvalues below this fraction of the largest are dropped (V is rank-deficient
    #: with fewer rows than columns; P^T C P = I to 2e-15 measured also then, N = 5-90)
    GRAM_CUTOFF = 1e-13
    #: particles per block of V's rows (~2 MB of V at a time)
    CHUNK = 512

    def __init__(self, positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None, p0: int, p1: int,
                 comm: Any = None) -> None:
        self.comm = comm
        unique, which = np.unique(radii[p0:p1], return_inverse=True)
        self.d_root = (1.0 / np.sqrt([np.diag(self_mobility(a)) for a in unique]))[which].ravel()
        self.u = None
        k = np.zeros((0, 3)) if lattice is None else long_waves(lattice)
        if len(k) == 0:
            return
        k_norm = np.linalg.norm(k, axis=1)
        axis = np.eye(3)[np.argmin(np.abs(k), axis=1)]  # polarisations e1, e2 orthogonal to k
        e1 = np.cross(k, axis)
        e1 /= np.linalg.norm(e1, axis=1)[:, None]
        e2 = np.cross(k / k_norm[:, None], e1)
        root = self.d_root.reshape(-1, NDOF)[:, 0]

        def rows(chunk):  # V's translational rows (3 n, 4m) of this rank's particles p0 + chunk
            phase = positions[p0:p1][chunk] @ k.T  # (n, m)
            # j0(k a) times D^-1/2 on the translational rows (sqrt(6 pi a), as in d_root)
            amplitude = np.sinc(np.outer(radii[p0:p1][chunk], k_norm) / np.pi) * root[chunk, None]
            return np.stack([amplitude[:, None, :] * trig(phase)[:, None, :] * e.T[None]
                             for trig in (np.cos, np.sin) for e in (e1, e2)], -1).reshape(-1, 4 * len(k))

        # V by blocks of particles, formed twice (for its Gram matrix, then for U = V B)
        # rather than held: U's rows alone stay (N = 10 000, 2 ranks: 22 MB a rank)
        chunks = [slice(c, c + self.CHUNK) for c in range(0, p1 - p0, self.CHUNK)]
        gram = np.zeros((4 * len(k), 4 * len(k)))  # columns (wave, 4)
        for chunk in chunks:
            block = rows(chunk)
            gram += block.T @ block
        gram = _rank_sum(comm, gram)
        weights = np.repeat(2.0 / (lattice.volume * k_norm ** 2), 4)
        shared = None
        if comm is None or comm.rank == 0:
            s, e = np.linalg.eigh(gram)
            keep = s > self.GRAM_CUTOFF * s.max()
            e, s = e[:, keep], s[keep]
            r = np.sqrt(s)[:, None] * e.T
            lam, w = np.linalg.eigh((r * weights) @ r.T)
            shared = (e / np.sqrt(s)) @ w, lam  # B, L
        if comm is not None and comm.size > 1:
            shared = comm.bcast(shared, root=0)
        basis, lam = shared
        self.u = np.empty((3 * (p1 - p0), basis.shape[1]))
        for chunk in chunks:
            self.u[3 * chunk.start:3 * min(chunk.stop, p1 - p0)] = rows(chunk) @ basis
        self.c = (1.0 + np.maximum(lam, 0.0)) ** -0.5 - 1.0

    def _x_root(self, x):
        """X^-1/2 x (this rank's rows)."""
        if self.u is None:
            return x
        y = x.copy()
        trans = y.reshape(-1, NDOF)[:, :3]
        t = _rank_sum(self.comm, self.u.T @ trans.ravel())
        trans += (self.u @ (self.c * t)).reshape(-1, 3)
        return y

    def right(self, x: np.ndarray) -> np.ndarray:
        """P x for this rank's rows x; collective over comm.

        Args:
            x: (11 (p1 - p0),) this rank's rows.

        Returns:
            (11 (p1 - p0),) this rank's rows of P x.
        """
        return self.d_root * self._x_root(x)

    def left(self, x: np.ndarray) -> np.ndarray:
        """P^T x for this rank's rows x; collective over comm.

        Args:
            x: (11 (p1 - p0),) this rank's rows.

        Returns:
            (11 (p1 - p0),) this rank's rows of P^T x.
        """
        return self._x_root(self.d_root * x)


class KrylovError(RuntimeError):
    """An iterative solve did not reach its tolerance."""


#: solvers alive, destroyed before PETSc finalizes at exit: PETSc would otherwise reset
#: their python contexts after the interpreter is gone (segmentation fault at exit)
_LIVE = weakref.WeakSet()


@atexit.register  # Python exit handlers run before petsc4py's C-level PetscFinalize
def _destroy_live():
    for solver in list(_LIVE):
        solver.destroy()


class DenseFarField:
    """M_inf as a dense Ewald matrix (`farfield.far_field_mobility`) applied by products;
    every rank holds all of it (tests and small N)."""

    def __init__(self, positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None, tol: float,
                 plan: FarFieldPlan | None = None) -> None:
        # plan: a `farfield.FarFieldPlan` to reuse (small displacements), else made here
        self.plan = plan_far_field(positions, radii, lattice, tol) if plan is None else plan
        self.matrix = far_field_mobility(positions, radii, plan=self.plan)
        self.positions, self.radii = np.array(positions, dtype=float), np.asarray(radii, dtype=float)

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """M_inf x.

        Args:
            x: (11N,) generalized forces (F, L, S), sphere by sphere.

        Returns:
            (11N,) generalized velocities (U, Omega, E) (Stokes units, viscosity 1).
        """
        return self.matrix @ x

    def change(self, displacement: np.ndarray, x: np.ndarray) -> np.ndarray:
        """[M_inf(positions + displacement) - M_inf] x for a small displacement (N, 3), by
        two products (`farfield.far_field_product`) with this operator's plan (the same
        images and wave vectors: the Ewald truncation of the change, not of M_inf;
        `spectral.SpectralFarField.change`).

        Args:
            displacement: (N, 3) displacement of the sphere centres (length unit of the radii).
            x: (11N,) generalized forces (F, L, S), sphere by sphere.

        Returns:
            (11N,) the change of the generalized velocities.
        """
        w = np.ascontiguousarray(np.reshape(x, (-1, NDOF)), dtype=float)
        moved = far_field_product(self.positions + displacement, self.radii, self.plan, w)
        return (moved - far_field_product(self.positions, self.radii, self.plan, w)).ravel()

    def release_real_space(self) -> None:
        """Nothing: the dense matrix (small N) is kept (`spectral.SpectralFarField.release_real_space`)."""


def far_field_kind(kind: str | None, n_particles: int, periodic: bool = True) -> str:
    """The far field `far_field_operator` builds for `kind` (None: spectral in a periodic
    box from DENSE_FAR_FIELD_MAX_N particles on, else dense).

    Args:
        kind: "dense", "spectral" or None.
        n_particles: the number of spheres N.
        periodic: the box is periodic.

    Returns:
        kind, or the one chosen for None.
    """
    if kind is not None:
        return kind
    return "spectral" if periodic and n_particles >= DENSE_FAR_FIELD_MAX_N else "dense"


def far_field_operator(kind: str | None, positions: np.ndarray, radii: np.ndarray, lattice: Lattice | None,
                       tol: float, comm: Any = None, plan: FarFieldPlan | None = None) -> Any:
    """The far-field mobility operator `kind` ("dense" or "spectral"; FAR_FIELDS; None:
    by `far_field_kind`) at the given positions; "spectral" needs a periodic lattice.
    plan: a `farfield.FarFieldPlan` for "dense".

    Args:
        kind: "dense", "spectral" or None.
        positions: (N, 3) sphere centres (length unit of the radii).
        radii: (N,) sphere radii a.
        lattice: the periodic lattice, or None (unbounded fluid).
        tol: relative accuracy of the Ewald sums.
        comm: the MPI communicator of "spectral", or None (this rank alone).
        plan: a far-field plan to reuse ("dense"), or None.

    Returns:
        A `DenseFarField` or `spectral.SpectralFarField` (matvec: (11N,) -> (11N,)).

    Raises:
        ValueError: an unknown kind, or "spectral" without a periodic lattice.
    """
    kind = far_field_kind(kind, len(positions), lattice is not None)
    if kind == "dense":
        return DenseFarField(positions, radii, lattice, tol, plan)
    if kind == "spectral":
        if lattice is None:
            raise ValueError("far_field: \"spectral\" needs a periodic box (got box=None); use \"dense\"")
        from .spectral import SpectralFarField

        return SpectralFarField(positions, radii, lattice, tol=tol, comm=comm)
    raise ValueError(f"far_field must be one of {FAR_FIELDS}, got {kind!r}")


def lanczos_inverse_sqrt(apply: Callable[[np.ndarray], np.ndarray], z: np.ndarray,
                         dot: Callable[[np.ndarray, np.ndarray], Any], tol: float = DEFAULT_TOL,
                         max_iterations: int = LANCZOS_MAX_ITERATIONS) -> tuple[np.ndarray, int]:
    """A^-1/2 z for a symmetric positive definite A by the Lanczos method (with full
    reorthogonalisation): after k steps, A^-1/2 z ~ |z| V_k T_k^-1/2 e_1 (V_k the
    orthonormal Krylov basis, T_k the tridiagonal Lanczos matrix). Stops when the
    estimate changes by less than tol (relative) between steps. apply and dot act on
    this rank's part of distributed vectors (dot sums over ranks).
    Returns (A^-1/2 z, iterations); FarFieldIndefinite when T_k shows that A (the far-field
    mobility) is not positive definite.

    Args:
        apply: x -> A x on this rank's part of a vector.
        z: (m,) this rank's part of the vector z.
        dot: (a, b) -> a @ b summed over the ranks (a a vector or rows of vectors).
        tol: relative change of the estimate at which to stop.
        max_iterations: largest number of Lanczos steps.

    Returns:
        (m,) this rank's part of A^-1/2 z, and the number of iterations.

    Raises:
        FarFieldIndefinite: A is not positive definite.
        KrylovError: not converged within max_iterations.
    """
    beta0 = np.sqrt(dot(z, z))
    if beta0 == 0.0:
        return np.zeros_like(z), 0
    basis = np.zeros((32, len(z)))  # rows: the Krylov basis (grown as needed)
    basis[0] = z / beta0
    alphas, betas = [], []
    coef_prev = np.zeros(0)
    for k in range(1, max_iterations + 1):
        w = apply(basis[k - 1])
        alphas.append(dot(w, basis[k - 1]))
        for _ in range(2):  # full reorthogonalisation (classical Gram-Schmidt twice)
            w = w - dot(basis[:k], w) @ basis[:k]
        t = np.diag(alphas) + np.diag(betas, 1) + np.diag(betas, -1)
        evals, evecs = np.linalg.eigh(t)
        if evals.min() <= 0.0:
            raise FarFieldIndefinite("the far-field mobility M_inf is not positive definite (Lanczos)")
        coef = evecs @ (evecs[0] / np.sqrt(evals))
        change = np.linalg.norm(coef - np.concatenate([coef_prev, [0.0]]))
        if change <= tol * np.linalg.norm(coef):
            break
        coef_prev = coef
        beta = np.sqrt(dot(w, w))
        if beta <= 1e-14 * abs(alphas[-1]):  # invariant subspace: exact
            break
        betas.append(beta)
        if k == len(basis):
            basis = np.concatenate([basis, np.zeros_like(basis)])
        basis[k] = w / beta
    else:
        raise KrylovError(f"Lanczos: A^-1/2 z not converged to {tol:g} in {max_iterations} iterations")
    return beta0 * (coef @ basis[:k]), k


class _Context:
    """A PETSc python context of a KrylovSolver, holding it by a weak reference (no
    cycle solver -> PETSc object -> context -> solver: the solver and its far field are
    freed as soon as the caller drops them)."""

    def __init__(self, solver):
        self.s = weakref.proxy(solver)


class _Saddle(_Context):
    """PETSc shell matrix of the mixed system (module docstring)."""

    def mult(self, mat, x, y):
        s = self.s
        xa = x.getArray(readonly=True)
        lam, u = xa[:s.nl11], xa[s.nl11:]
        out = y.getArray()
        m_lam = s.far_rows(lam)
        m_lam.reshape(-1, NDOF)[:, :6] -= u.reshape(-1, 6)
        out[:s.nl11] = m_lam
        s.u_in.setArray(u)
        s.l_uu.mult(s.u_in, s.u_out)
        out[s.nl11:] = lam.reshape(-1, NDOF)[:, :6].ravel() + s.u_out.getArray(readonly=True)


class _NearFieldPreconditioner(_Context):
    """PETSc shell preconditioner: the block elimination with M -> D (module docstring)."""

    def apply(self, pc, r, z):
        s = self.s
        ra = r.getArray(readonly=True)
        f, g = ra[:s.nl11].reshape(-1, NDOF), ra[s.nl11:]
        d_f = np.einsum("pij,pj->pi", s.d_inv, f)
        y = s.schur_solve(g - d_f[:, :6].ravel())
        rhs = f.copy()
        rhs[:, :6] += y.reshape(-1, 6)
        out = z.getArray()
        out[:s.nl11] = np.einsum("pij,pj->pi", s.d_inv, rhs).ravel()
        out[s.nl11:] = y


class _FarField(_Context):
    """PETSc shell matrix of M alone (stresslets for velocities not from a solve)."""

    def mult(self, mat, x, y):
        y.getArray()[:] = self.s.far_rows(x.getArray(readonly=True))


class _SelfPreconditioner(_Context):
    """PETSc shell preconditioner D^-1 (block diagonal) for M."""

    def apply(self, pc, r, z):
        s = self.s
        z.getArray()[:] = np.einsum("pij,pj->pi", s.d_inv, r.getArray(readonly=True).reshape(-1, NDOF)).ravel()


class KrylovSolver(SolverBackend):
    """The `petsc-krylov` backend (`backend.SolverBackend`) for a
    `resistance.SplitResistance` on the MPI communicator comm (None: this rank alone); tol:
    relative residual of every solve, lanczos_tol: relative accuracy of the Lanczos square
    roots (None: tol). Its noise is longer than N x 6 (`noise_shape`), it takes over the
    preconditioner of a solver at a nearby configuration (`take_preconditioner`), and
    counts its iterations (`stats`)."""

    @classmethod
    def build(cls, resistance: Any, comm: Any, tolerance: float,
              lanczos_tolerance: float | None) -> KrylovSolver:
        """The solver of ``resistance`` on ``comm`` with the relative residual
        ``tolerance`` and Lanczos accuracy ``lanczos_tolerance`` (None: tolerance);
        collective over comm."""
        return cls(resistance, comm, tolerance, lanczos_tolerance)

    def __init__(self, resistance: Any, comm: Any = None, tol: float = DEFAULT_TOL,
                 lanczos_tol: float | None = None) -> None:
        from .petsc_dense import _keepalive, _mpi_comm, collect_garbage, load_petsc

        PETSc = load_petsc()
        _LIVE.add(self)
        self._PETSc = PETSc
        self.comm = _mpi_comm(comm)
        _keepalive(PETSc, self.comm)
        collect_garbage(PETSc, self.comm)
        self.tol = float(tol)
        self.lanczos_tol = self.tol if lanczos_tol is None else float(lanczos_tol)
        self.far = resistance.far
        self.n = n = resistance.n_particles
        self.positions, self.radii, self.lattice = resistance.positions, resistance.radii, resistance.lattice
        size, rank = self.comm.size, self.comm.rank
        splits = particle_ranges(n, size)
        self.p0, self.p1 = p0, p1 = splits[rank], splits[rank + 1]
        self.counts11 = NDOF * np.diff(splits)
        self.counts6 = 6 * np.diff(splits)
        nl = p1 - p0
        self.nl11 = NDOF * nl
        # the lubricated pairs (none without lubrication: then resistance.pairs are overlaps)
        self.lubricated = resistance.lubricated
        self.noise_shape = (NDOF * n + 12 * (0 if self.lubricated is None else len(self.lubricated.i)),)
        self.pair_factors = resistance.pair_factors
        self._resistance = resistance  # (forces_drawn frees its pair factors too)
        self.stats = {"iterations": 0, "residual": 0.0, "lanczos": 0}

        # this rank's block rows of the lubrication matrix L (11 x 11 blocks: the
        # resistance holds these alone), and of its rigid-body part L_uu (6 x 6 blocks)
        self._lub = lub = resistance.lubrication
        if lub.shape != (NDOF * nl, NDOF * n):
            raise ValueError(f"petsc-krylov: the resistance holds lubrication rows {lub.shape[0] // NDOF} "
                             f"spheres long, this rank's are {nl} (a resistance of another communicator)")
        self.l_uu = self.u_in = self.u_out = None
        self._rigid_lubrication()
        # far-field self blocks of the preconditioner (isolated spheres, scaled by
        # self_resistance_scale, weighted by self_resistance_weights; this rank's
        # particles), and this rank's block rows of the Schur complement G: L_uu with
        # D_uu^-1 added to its diagonal blocks (lubrication_sparse stores one for every
        # particle), of which G keeps the diagonal ones and those of pairs closer than
        # PRECONDITIONER_MAX_GAP (_g_keep, over the blocks of self.lub; G's blocks formed
        # and gathered from all ranks when needed: schur_blocks)
        root_w = np.sqrt(self_resistance_weights())
        scale = self_resistance_scale(resistance.volume_fraction) * np.outer(root_w, root_w)
        inv = {a: scale * np.linalg.inv(self_mobility(a)) for a in np.unique(resistance.radii)}
        self.d_inv = np.array([inv[a] for a in resistance.radii[p0:p1]]).reshape(nl, NDOF, NDOF)
        block_rows = p0 + np.repeat(np.arange(nl), np.diff(lub.indptr))
        self._g_pattern = (lub.indptr, lub.indices, block_rows)
        self._g_keep = (lub.indices == block_rows) | _near_blocks(resistance.pairs, block_rows, lub.indices, n)
        # G as a sequential PETSc matrix, its incomplete factor (the KSP `inner`) and work
        # vectors, on rank 0 (None on the others): built at the first preconditioner
        # application, or taken over from a solver of the same pattern
        # (take_preconditioner); _g_ready: whether they are there (on every rank)
        self.schur = self.inner = self._g_in = self._g_out = None
        self._g_ready = False

        m = NDOF * n + 6 * n
        ml = self.nl11 + 6 * nl
        self.saddle = PETSc.Mat().createPython([(ml, m), (ml, m)], context=_Saddle(self), comm=self.comm)
        self.saddle.setUp()
        self.ksp = self._ksp(self.saddle, "gmres", _NearFieldPreconditioner(self))
        self.ksp.setGMRESRestart(GMRES_RESTART)
        self._mobility_ksp = None
        self._last = None  # (velocities, einf, lambda rows) of the last solve
        self._forms = None  # (force sums (G, N, 6), velocities, lambda rows) of mobility_forms' solves
        workspace.release_free_memory()  # the set-up's temporaries, before the solves allocate theirs

    def destroy(self) -> None:
        """Frees the PETSc objects now (otherwise when the solver is garbage collected:
        `__del__`). Idempotent."""
        for name in ("ksp", "_mobility_ksp", "inner", "saddle", "l_uu", "schur", "u_in", "u_out", "_g_in", "_g_out"):
            obj = getattr(self, name, None)  # (None also for a solver whose __init__ failed)
            if obj is not None:
                obj.destroy()
        _LIVE.discard(self)

    def __del__(self) -> None:
        """The PETSc objects destroyed with the solver: the shell matrices and
        preconditioners hold their python contexts from PETSc's side, and PETSc keeps the
        objects alive with them unless they are destroyed (a solver's matrices, factor and
        Krylov vectors, every step's start and midpoint, would otherwise stay allocated
        until the process ends)."""
        self.destroy()

    # ------------------------------------------------------------------ helpers

    @property
    def lub(self) -> Any:
        """This rank's block rows of the lubrication matrix L (scipy BSR, 11 x 11 blocks),
        computed again from the resistance's pairs after `forces_drawn` freed them
        (`lubrication.lubrication_rows`: the same bits)."""
        if self._lub is None:
            workspace.release_free_memory()  # what solvers that have gone held (the midpoint's)
            r = self._resistance
            self._lub = r.lubrication = lubrication_rows(r.positions, r.radii, self.lubricated, (self.p0, self.p1))[0]
        return self._lub

    def _rigid_lubrication(self) -> None:
        """L_uu, the rigid-body part of this rank's rows of L, as a PETSc BAIJ matrix with
        its work vectors (for the mixed system's product), built unless it is there.
        Collective."""
        if self.l_uu is None:
            lub = self.lub
            self.l_uu = self._baij(_block_csr(lub.indptr, lub.indices, lub.data[:, :6, :6]), self.comm)
            self.u_in, self.u_out = self.l_uu.createVecs()

    def schur_blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """G (6N x 6N) in blocked CSR (`_block_csr`) on rank 0: its kept blocks (_g_keep) of
        L_uu + D_uu^-1, every rank's block rows gathered in order, columns sorted within
        each (as lubrication_sparse stores them). Collective.

        Returns:
            On rank 0 block row pointers (N + 1,) int32, block columns (nb,) int32, and
            the blocks (36 nb,) row-major; None on the other ranks.
        """
        _, cols, rows = self._g_pattern
        keep = self._g_keep
        cols, rows = cols[keep], rows[keep]
        blocks = self.lub.data[keep, :6, :6]  # a copy
        diagonal = cols == rows
        blocks[diagonal] += self.d_inv[rows[diagonal] - self.p0, :6, :6]
        per_row, cols, blocks = (gather_rows(self.comm, a) for a in
                                 (np.bincount(rows - self.p0, minlength=self.p1 - self.p0), cols, blocks))
        if per_row is None:
            return None
        return _block_csr(np.concatenate([[0], np.cumsum(per_row)]), cols, blocks)

    def schur_solver(self) -> Any:
        """The KSP applying the incomplete factor of the whole G (INNER_OPTIONS) on rank 0
        alone, built on first use. Collective.

        Returns:
            On rank 0 the PETSc KSP (sequential) of G; None on the other ranks.
        """
        if not self._g_ready:
            csr = self.schur_blocks()
            if csr is not None:
                PETSc = self._PETSc
                self.schur = self._baij(csr, PETSc.COMM_SELF)
                self.inner = PETSc.KSP().create(comm=PETSc.COMM_SELF)
                self.inner.setOperators(self.schur)
                self.inner.setOptionsPrefix(OPTIONS_PREFIX)
                options = PETSc.Options(OPTIONS_PREFIX)
                for key, value in INNER_OPTIONS.items():
                    options.setValue(key, value)
                self.inner.setFromOptions()
            self._g_ready = True
        if self.inner is not None and self._g_in is None:
            self._g_in, self._g_out = self.schur.createVecs()
        return self.inner

    def schur_solve(self, local: np.ndarray) -> np.ndarray:
        """This rank's rows of G^-1 g (incomplete factor) from this rank's rows of g.

        Args:
            local: (6 (p1 - p0),) this rank's rows of g.

        Returns:
            (6 (p1 - p0),) this rank's rows of G^-1 g.

        Raises:
            KrylovError: the incomplete factorisation failed.
        """
        inner = self.schur_solver()
        g = self._gather_root(local, self.counts6)
        reason, out = np.zeros(1, dtype=np.int64), None
        if inner is not None:
            self._g_in.setArray(g)
            inner.solve(self._g_in, self._g_out)
            reason[0], out = inner.getConvergedReason(), self._g_out.getArray(readonly=True)
        if self.comm.size > 1:
            self.comm.Bcast(reason, root=0)
        if reason[0] < 0:  # e.g. a zero pivot in the incomplete factor
            raise KrylovError(f"petsc-krylov: the preconditioner's incomplete factor "
                              f"failed (PETSc reason {reason[0]})")
        return self._scatter_root(out, self.counts6)

    def take_preconditioner(self, other: KrylovSolver) -> None:
        """Take over other's G matrix and factor when the lubrication has the same block
        pattern here (the Brownian midpoint: the pair sets of the step's start): G keeps
        other's blocks, with this configuration's values, so the factorisation keeps its
        symbolic part and redoes only the numeric one. other builds a new one if it needs
        it. (The solve itself starts from zero, as other's did: the two GMRES runs then
        take nearly the same path, so their errors nearly cancel in the difference of the
        two solutions, the Brownian stresslets S_mid - S_start; started from other's
        solution instead, the midpoint needs ~20% fewer iterations, but its error is
        independent of other's and the difference is ~100 x less accurate:
        tests/test_krylov.py::test_midpoint_difference_is_accurate.) Collective.

        Args:
            other: a solver of this backend at a nearby configuration.
        """
        mine, theirs = self._g_pattern, other._g_pattern
        same = all(self.comm.allgather(all(np.array_equal(a, b) for a, b in zip(mine, theirs))))
        if self._g_ready or not other._g_ready or not same:
            return
        self._g_keep = other._g_keep
        self.schur, self.inner = other.schur, other.inner  # (None but on rank 0)
        other.schur = other.inner = None
        other._g_ready, self._g_ready = False, True
        csr = self.schur_blocks()
        if csr is not None:
            self.schur.zeroEntries()
            self.schur.setValuesBlockedCSR(*csr)
            self.schur.assemble()

    def forces_drawn(self) -> None:
        """Frees the lubrication pairs' factors C_p (12 x 12 doubles per pair touching this
        rank's spheres), here and in the resistance the solver was built from, which the
        Brownian forces alone use (`brownian_forces` then refuses); and what the next solve
        computes again, the same bits: the spectral far field's real-space blocks
        (`spectral.SpectralFarField.release_real_space`), this rank's rows of the
        lubrication matrix L and its PETSc copy L_uu (`lub`, `_rigid_lubrication`; where
        they exceed `workspace.RELEASE_MIN_BYTES`: smaller ones cost more time, ~1% of a
        step at N = 1000, than they hold). The step's start would otherwise hold them
        through the Brownian midpoint's set-up and solve (at N = 10 000 on 2 ranks ~0.45 GiB
        per rank), and the allocator hands what they held back to the system
        (`workspace.release_free_memory`)."""
        self.pair_factors = self._resistance.pair_factors = None
        self.far.release_real_space()
        # (without lubrication L is its diagonal: kept)
        if self.lubricated is not None and self._lub.data.nbytes > workspace.RELEASE_MIN_BYTES:
            self._lub = self._resistance.lubrication = None
            for name in ("l_uu", "u_in", "u_out"):
                getattr(self, name).destroy()
                setattr(self, name, None)
        workspace.release_free_memory()

    def _baij(self, csr, comm):
        """A PETSc BAIJ matrix (6x6 blocks, PETSc's block kernels) of 6N columns from this
        rank's block rows csr (`_block_csr`) on comm."""
        rows = 6 * (len(csr[0]) - 1)
        mat = self._PETSc.Mat().createBAIJ([(rows, 6 * self.n), (rows, 6 * self.n)], 6, csr=csr, comm=comm)
        mat.assemble()
        return mat

    def _ksp(self, mat, kind, precond):
        PETSc = self._PETSc
        ksp = PETSc.KSP().create(comm=self.comm)
        ksp.setOperators(mat)
        ksp.setType(kind)
        # left preconditioning, preconditioned residual |P^-1 r| ~ the error of the
        # solution: its relative decrease bounds the error (measured: 1-4 x tol)
        ksp.setPCSide(PETSc.PC.Side.LEFT)
        ksp.setNormType(PETSc.KSP.NormType.PRECONDITIONED)
        ksp.setTolerances(rtol=self.tol, atol=0.0, max_it=MAX_ITERATIONS)
        pc = ksp.getPC()
        pc.setType("python")
        pc.setPythonContext(precond)
        return ksp

    def _gather(self, local, counts):
        if self.comm.size == 1:
            return np.array(local, dtype=float)
        full = np.empty(counts.sum())
        self.comm.Allgatherv(np.ascontiguousarray(local, dtype=float), [full, counts])
        return full

    def _gather_root(self, local, counts):
        """Every rank's part local (counts[r] values on rank r) joined in rank order on
        rank 0; None on the others."""
        if self.comm.size == 1:
            return np.array(local, dtype=float)
        full = np.empty(counts.sum()) if self.comm.rank == 0 else None
        self.comm.Gatherv(np.ascontiguousarray(local, dtype=float), None if full is None else [full, counts],
                          root=0)
        return full

    def _scatter_root(self, full, counts):
        """This rank's part (counts[rank] values, in rank order) of rank 0's array full."""
        if self.comm.size == 1:
            return np.array(full, dtype=float)
        part = np.empty(counts[self.comm.rank])
        self.comm.Scatterv(None if full is None else [np.ascontiguousarray(full), counts], part, root=0)
        return part

    def far_rows(self, lam_local: np.ndarray) -> np.ndarray:
        """This rank's rows of M lambda, from this rank's rows of lambda.

        Args:
            lam_local: (11 (p1 - p0),) this rank's rows of lambda.

        Returns:
            (11 (p1 - p0),) this rank's rows of M lambda.
        """
        full = self.far.matvec(self._gather(lam_local, self.counts11))
        return full[NDOF * self.p0:NDOF * self.p1].copy()

    def _run(self, ksp, rhs):
        """Solve with ksp for this rank's part of rhs, from zero; returns this rank's
        solution. Records the iterations and the relative preconditioned residual
        |P^-1 r|/|P^-1 b|."""
        b, x = ksp.getOperators()[0].createVecs()
        b.setArray(rhs)
        ksp.solve(b, x)
        reason = ksp.getConvergedReason()
        pb = b.duplicate()
        ksp.getPC().apply(b, pb)
        bnorm = pb.norm()
        residual = ksp.getResidualNorm() / bnorm if bnorm > 0 else 0.0
        if reason < 0:
            raise KrylovError(f"petsc-krylov: the solve did not converge (PETSc reason {reason}, "
                              f"relative residual {residual:.3g} after {ksp.getIterationNumber()} "
                              f"iterations, tolerance {self.tol:g})")
        self.stats["iterations"] += ksp.getIterationNumber()
        self.stats["residual"] = max(self.stats["residual"], residual)
        solution = x.getArray().copy()
        for vec in (b, x, pb):  # (collective: destroyed now rather than left to collect_garbage)
            vec.destroy()
        return solution

    @staticmethod
    def _generalized(velocities, einf):
        v = np.empty((len(einf), NDOF))
        v[:, :6] = velocities
        v[:, 6:] = -einf
        return v.ravel()

    # ------------------------------------------------------------------ interface

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """forces (N, 6) = (F, L); einf (N, 5) -> (N, 6) velocities U', Omega'. Forces
        without imposed strain that are a combination of the force sums the last
        `mobility_forms` solved take that combination of their solutions (`_combined`),
        other forces a GMRES solve.

        Raises:
            KrylovError: GMRES did not converge.
        """
        if not np.any(einf):
            combined = self._combined(forces)
            if combined is not None:
                return combined
        p0, p1 = self.p0, self.p1
        self._rigid_lubrication()
        v_e = self._generalized(np.zeros((self.n, 6)), einf)
        l_v = (self.lub @ v_e).reshape(-1, NDOF)[:, :6]
        rhs = np.concatenate([v_e[NDOF * p0:NDOF * p1], (forces[p0:p1] - l_v).ravel()])
        sol = self._run(self.ksp, rhs)
        u = self._gather(sol[self.nl11:], self.counts6).reshape(self.n, 6)
        self._last = (u.copy(), np.array(einf, dtype=float), sol[:self.nl11])
        return u

    def _lambda(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """This rank's rows of lambda = M^-1 V for V of (velocities, einf): the last
        solve's where it solved for them, else by preconditioned CG."""
        last = self._last
        if last is not None and np.array_equal(last[0], velocities) and np.array_equal(last[1], einf):
            return last[2]
        if self._mobility_ksp is None:
            ml = self.nl11
            mat = self._PETSc.Mat().createPython([(ml, NDOF * self.n), (ml, NDOF * self.n)],
                                                 context=_FarField(self), comm=self.comm)
            mat.setUp()
            self._mobility_ksp = self._ksp(mat, "cg", _SelfPreconditioner(self))
        v = self._generalized(velocities, einf)
        return self._run(self._mobility_ksp, v[NDOF * self.p0:NDOF * self.p1])

    def _stresslets_of(self, lam: np.ndarray, l_v: np.ndarray) -> np.ndarray:
        """-P_e (lambda + L V) (N, 5) from this rank's rows of lambda and of L V."""
        minus_s = (lam.reshape(-1, NDOF) + l_v.reshape(-1, NDOF))[:, 6:].ravel()
        return -self._gather(minus_s, 5 * (self.counts11 // NDOF)).reshape(self.n, 5)

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """(N, 5) stresslets for rigid-body velocities U' (N, 6) and einf (N, 5)."""
        return self._stresslets_of(self._lambda(velocities, einf), self.lub @ self._generalized(velocities, einf))

    def mobility_change(self, moved: np.ndarray, velocities: np.ndarray, min_gap: float) -> tuple[np.ndarray, np.ndarray]:
        """(du (N, 6), ds (N, 5)) of the velocities m = R_FU^-1 F (N, 6), no imposed
        strain, at the nearby positions moved (N, 3), to first order in Delta R =
        R(moved) - R with this configuration's pair sets:
        du = [R_FU^-1(moved) - R_FU^-1] F = -R_FU^-1 Delta R_FU m and
        ds = -[(R_SU R_FU^-1)(moved) - R_SU R_FU^-1] F = -(Delta R_SU m + R_SU du).
        With lambda_m = M^-1 (m, 0) and Delta(M^-1) = -M^-1 Delta M M^-1, both come from one
        solve of the mixed system with the right-hand side (-Delta M lambda_m,
        -Delta L_uu m): its U' is du, its lambda = M^-1 ((du, 0) - Delta M lambda_m), and
        ds = -P_e (lambda + L (du, 0) + Delta L (m, 0)). The far-field change by
        `far.change` (the same pair images and window points, double precision), the
        lubrication's by this rank's rows of L at moved (min_gap: the floor of the gaps,
        as in `lubrication.close_pairs`) less those here. The solve's error is relative to
        the change itself (a difference of two solves at the tolerance would lose it).
        Collective.

        Args:
            moved: (N, 3) nearby sphere centres (length unit of the radii).
            velocities: (N, 6) m, the solution of a solve for forces without strain.
            min_gap: the lubrication's floor of the gaps (mean radii).

        Returns:
            (du, ds): (N, 6) velocities and (N, 5) stresslets, Stokes units.
        """
        zero = np.zeros((self.n, 5))
        lam = self._gather(self._lambda(velocities, zero), self.counts11)
        far = self.far.change(moved - self.positions, lam)
        v = self._generalized(velocities, zero)
        lub_change = np.zeros((self.p1 - self.p0, NDOF))
        r = self._resistance
        if self.lubricated is not None:
            pairs = close_pairs(moved, self.radii, None, min_gap=min_gap, images=r.plan.near_images)
            rows = lubrication_rows(moved, self.radii, pairs, (self.p0, self.p1))[0]
            lub_change = (rows @ v - self.lub @ v).reshape(-1, NDOF)
        self._rigid_lubrication()
        rhs = np.concatenate([-far[NDOF * self.p0:NDOF * self.p1], -lub_change[:, :6].ravel()])
        sol = self._run(self.ksp, rhs)
        du = self._gather(sol[self.nl11:], self.counts6).reshape(self.n, 6)
        l_v = self.lub @ self._generalized(du, zero) + lub_change.ravel()
        return du, self._stresslets_of(sol[:self.nl11], l_v)

    def mobility_forms(self, forces: np.ndarray, accuracy: np.ndarray | None = None) -> np.ndarray:
        """f.R_FU^-1.f (P,) for each of the force sets ``forces`` (P, N, 6), the sets on
        lubricated pairs several to a solve (`form_groups`): for the sets f_p of one solve,
        u = R_FU^-1 sum_q f_q gives f_p.u = f_p.R_FU^-1.f_p + sum_{q != p} f_p.R_FU^-1.f_q.
        The cross terms are small for pair forces on lubricated pairs near contact: such a
        pair moves apart only against its squeeze resistance, so its relative mobility
        G_p = f_p.R_FU^-1.f_p ~ h_p, and it barely deforms in the flow of a distant pair's
        forces, which themselves move the fluid only through that pair's small relative
        motion: f_p.R_FU^-1.f_q ~ G_p G_q (measured, N = 343, phi = 0.45, 40 pairs with
        gaps below 0.02: |f_p.R_FU^-1.f_q| / G_p <= 2 G_q eta_m a (centres >= 4 a apart),
        <= 8 G_q eta_m a (sharing a sphere); pairs at gaps of the collisions, G_p ~ 1e-4
        1/(eta_m a): each form within 1e-3 of one solve per set, N = 1000; docs/numerics.md,
        "Krylov backend"). The separations of pairs sharing a solve grow with their gaps
        and with the accuracy asked (FORMS_SEPARATION). Forms of lubricated pairs asked to
        ESTIMATE_ACCURACY or less take no solve where enough others are solved
        (`_estimated_forms`). Other sets (other supports, no lubrication) are solved one by
        one.

        Args:
            forces: (P, N, 6) force/torque sets.
            accuracy: (P,) relative accuracy each form needs (None: FORM_ACCURACY for all).

        Returns:
            (P,) the quadratic forms f.R_FU^-1.f.
        """
        accuracy = np.full(len(forces), FORM_ACCURACY) if accuracy is None else np.asarray(accuracy, float)
        supports, gaps = self._set_pairs(forces)
        on_pairs = ~np.isnan(gaps)
        estimated = on_pairs & (accuracy >= ESTIMATE_ACCURACY)
        if np.count_nonzero(on_pairs & ~estimated) < CALIBRATION_PAIRS:
            estimated[:] = False
        solved = np.flatnonzero(~estimated)
        zero = np.zeros((self.n, 5))
        forms = np.zeros(len(forces))
        sums, velocities, lams = [], [], []
        self._forms = None  # (each group solved afresh)
        for group in self._groups([supports[k] for k in solved], gaps[solved], accuracy[solved]):
            group = solved[group]
            sums.append(forces[group].sum(axis=0))
            u = self.velocities(sums[-1], zero)
            forms[group] = [np.vdot(forces[p], u) for p in group]
            velocities.append(u)
            lams.append(self._last[2])
        self._forms = (np.array(sums), np.array(velocities), np.array(lams)) if sums else None
        if estimated.any():
            forms[estimated] = self._estimated_forms(forces, supports, gaps, estimated, on_pairs & ~estimated, forms)
        return forms

    def _estimated_forms(self, forces, supports, gaps, estimated, calibrating, forms):
        """The forms of the sets ``estimated`` (lubricated pairs' unit pair forces f_p) from
        the preconditioner's, f_p.G^-1.f_p (`schur_solve`; several sets to an application,
        grouped as `form_groups` does for ESTIMATE_ACCURACY), through their deficit against
        a pair whose own squeeze holds all its relative mobility,
        D_p = 4/s_p - G_p = (4/s_p)(1 - kappa_p) (s_p = h |d(f.R_2B.f)/dh| of the isolated
        pair at the pair's gap, `two_sphere.squeeze_slope`; kappa: docs/numerics.md, "Drift
        schemes and the near-contact correction"). G holds the lubrication exactly and the
        far field only through a scaled self resistance, so its deficit is too large by a
        factor nearly common to the pairs near contact (~1.35 at phi = 0.45, 125 spheres,
        gaps up to 0.05, quartiles 1.32-1.40): G_p = 4/s_p - c D_pre,p with c the median of
        D_q/D_pre,q over the sets ``calibrating`` whose ``forms`` were solved, at most 1 (so
        that G_p >= f_p.G^-1.f_p > 0). Measured against one solve per pair on four
        equilibrated configurations (125 spheres, phi = 0.45, calibrated on the pairs below
        a gap of 0.012, estimating those from 0.012 to 0.05): kappa within 3-5% (medians
        0.8-2.3%) in 10-11 applications of G^-1 for ~70 pairs.

        Returns:
            The estimated forms of the sets ``estimated``, in their order.
        """
        both = np.flatnonzero(estimated | calibrating)
        pre = np.zeros(len(forces))
        rows = slice(self.p0, self.p1)
        for group in self._groups([supports[k] for k in both], gaps[both], np.full(len(both), ESTIMATE_ACCURACY)):
            group = both[group]
            g = self.schur_solve(forces[group].sum(axis=0)[rows].ravel())
            pre[group] = _rank_sum(self.comm, np.array([np.vdot(forces[k][rows].ravel(), g) for k in group]))
        i, j = np.array([supports[k] for k in both]).T
        isolated = np.zeros(len(forces))
        isolated[both] = 4.0 / squeeze_slope(gaps[both], self.radii[i], self.radii[j])
        scale = min(1.0, float(np.median((isolated - forms)[calibrating] / (isolated - pre)[calibrating])))
        return (isolated - scale * (isolated - pre))[estimated]

    def _combined(self, forces: np.ndarray) -> np.ndarray | None:
        """The velocities (N, 6) of ``forces`` (no imposed strain) as the combination
        sum_g c_g u_g of the solutions u_g of the force sums b_g that the last
        `mobility_forms` solved, where forces = sum_g c_g b_g to rounding (least squares
        over the N x 6 entries, residual below COMBINED_TOL of |forces|); None otherwise.
        The collision forces sum_p w_p f_p of pairs each solved alone (one corrected
        pair, or each pair a group of `form_groups` of its own) are such a combination, so
        that their velocities and stresslets (the combined lambda is kept for
        `stresslets`) need no solve of their own. The combination's residual is at most
        tol sum_g |c_g| |b_g|, within sqrt(G) tol |forces| for sums on disjoint spheres."""
        if self._forms is None:
            return None
        sums, velocities, lams = self._forms
        basis = sums.reshape(len(sums), -1).T
        target = np.asarray(forces, dtype=float).ravel()
        coefficients = np.linalg.lstsq(basis, target, rcond=None)[0]
        if np.linalg.norm(basis @ coefficients - target) > COMBINED_TOL * np.linalg.norm(target):
            return None
        u = np.tensordot(coefficients, velocities, axes=1)
        self._last = (u.copy(), np.zeros((self.n, 5)), np.tensordot(coefficients, lams, axes=1))
        return u

    def form_groups(self, forces: np.ndarray, accuracy: np.ndarray | None = None) -> list[list[int]]:
        """The force sets (P, N, 6) that `mobility_forms` solves together: the sets acting
        on the two spheres of a lubricated pair in groups whose sets all lie far enough
        apart (every centre distance between their spheres, any lattice images, at least
        the separation of FORMS_SEPARATION's rule times the sum of the two radii, for the
        pairs' gaps and the accuracies asked of their forms), as few groups as `_groups`
        finds; every other set is a group of its own, and sets without force none.

        Args:
            forces: (P, N, 6) force/torque sets.
            accuracy: (P,) relative accuracy each form needs (None: FORM_ACCURACY for all).

        Returns:
            Lists of set indices, in order of their first set.
        """
        accuracy = np.full(len(forces), FORM_ACCURACY) if accuracy is None else np.asarray(accuracy, float)
        return self._groups(*self._set_pairs(forces), accuracy)

    def _set_pairs(self, forces):
        """The spheres each force set acts on (its support) and the surface gap of the
        lubricated pair it acts on (NaN: the set acts on no lubricated pair; none: empty)."""
        supports = [np.flatnonzero(np.any(f != 0.0, axis=1)) for f in forces]
        lubricated = {}
        pairs = self.lubricated
        if pairs is not None:
            lubricated = {(min(a, b), max(a, b)): g for a, b, g in zip(pairs.i, pairs.j, pairs.gap)}
        gaps = np.array([lubricated.get(tuple(k), np.nan) if len(k) == 2 else np.nan for k in supports])
        return supports, gaps

    def _groups(self, supports, gaps, accuracy):
        """`form_groups` of sets with these supports, lubricated pairs' gaps (NaN: none) and
        accuracies: the sets on lubricated pairs coloured so that no two of a colour lie
        too close (`_too_close`), by DSatur (Brelaz, Commun. ACM 22, 251 (1979): the set
        whose neighbours already take the most colours first, ties to the most neighbours,
        then the lowest index; each set the lowest colour its neighbours leave), which needs
        fewer colours, so fewer solves, than taking the sets in order (N = 1000, phi = 0.45,
        the near-contact correction: 4-5 against 5-6)."""
        shared = [p for p, support in enumerate(supports) if len(support) == 2 and not np.isnan(gaps[p])]
        alone = set(range(len(supports))) - set(shared)
        groups = [[p] for p in sorted(alone) if len(supports[p])]
        if shared:
            colour = _dsatur(self._too_close(np.array([supports[p] for p in shared]), np.asarray(gaps)[shared],
                                             np.asarray(accuracy, float)[shared]))
            groups += [[shared[k] for k in np.flatnonzero(colour == c)] for c in range(colour.max() + 1)]
        return sorted(groups)

    def _too_close(self, spheres, gaps, accuracy):
        """(S, S) whether two lubricated pairs (their spheres (S, 2), surface gaps and the
        accuracies asked of their forms) lie too close to share a solve: some centre
        distance between their spheres (any lattice images) below FORMS_SEPARATION's rule
        times the sum of the two radii; a pair is too close to itself. The candidates are
        the pairs whose middles lie within the largest such reach (`geometry.find_pairs`),
        so the cost grows with S, not S^2."""
        gap = 2 * gaps / self.radii[spheres].sum(axis=1)  # in mean radii
        term = np.maximum(gap, FORMS_MAX_GAP) * (FORM_ACCURACY / FORMS_MAX_GAP)
        x0, x1 = self.positions[spheres[:, 0]], self.positions[spheres[:, 1]]
        half = 0.5 * (x1 - x0 if self.lattice is None else self.lattice.nearest_image(x1 - x0))
        middle = x0 + half if self.lattice is None else self.lattice.wrap(x0 + half)
        offsets = np.stack([-half, half], axis=1)  # (S, 2, 3): each pair's spheres from its middle
        radii = self.radii[spheres]
        largest = (FORMS_SEPARATION * np.cbrt(term.max() / accuracy.min()) * 2 * radii.max()
                   + 2 * np.linalg.norm(half, axis=1).max())
        p, q, shift = find_pairs(middle, np.zeros(len(middle)), self.lattice, largest, 0.0)
        separation = FORMS_SEPARATION * np.cbrt(np.maximum(term[q] / accuracy[p], term[p] / accuracy[q]))
        d = ((middle[q] + shift - middle[p])[:, None, None, :] + offsets[q][:, None, :, :]
             - offsets[p][:, :, None, :])  # (C, 2, 2, 3): p's sphere, q's sphere
        reach = separation[:, None, None] * (radii[p][:, :, None] + radii[q][:, None, :])
        hit = np.any(np.einsum("cabx,cabx->cab", d, d) < reach ** 2, axis=(1, 2))
        close = np.eye(len(spheres), dtype=bool)
        close[p[hit], q[hit]] = close[q[hit], p[hit]] = True
        return close

    def brownian_forces(self, noise: np.ndarray) -> np.ndarray:
        """F (N, 6) with covariance R_FU over the noise (flat, noise_shape, standard
        normal): P_u P (P^T M P)^-1/2 z_1 + sum_p Q_p^T C_p z_p (module docstring; P:
        `LongWaveFactor`).

        Raises:
            ValueError: the resistance is one for solves only (no pair factors).
        """
        if self.pair_factors is None:
            raise ValueError("petsc-krylov: Brownian forces need the lubrication pairs' factors "
                             "(a resistance of split_resistance(..., brownian=True), before forces_drawn)")
        n = self.n
        z1 = noise[:NDOF * n]
        z2 = noise[NDOF * n:].reshape(-1, 12)

        def dot(a, b):  # a @ b summed over the ranks (a: vector or rows of vectors)
            total = _rank_sum(self.comm, np.atleast_1d(a @ b))
            return total if np.ndim(a) > 1 else float(total[0])

        pre = LongWaveFactor(self.positions, self.radii, self.lattice, self.p0, self.p1, self.comm)
        y, its = lanczos_inverse_sqrt(lambda v: pre.left(self.far_rows(pre.right(v))),
                                      z1[NDOF * self.p0:NDOF * self.p1], dot, self.lanczos_tol)
        self.stats["lanczos"] += its
        force = pre.right(y).reshape(-1, NDOF)[:, :6].copy()  # this rank's rows
        # the pairs touching this rank's spheres, each with its rows of the noise
        at, pair_i, pair_j, chol = self.pair_factors
        near = np.einsum("pij,pj->pi", chol, z2[at])
        for spheres, part in ((pair_i, near[:, :6]), (pair_j, near[:, 6:])):
            mine = (spheres >= self.p0) & (spheres < self.p1)
            np.add.at(force, spheres[mine] - self.p0, part[mine])
        return self._gather(force.ravel(), self.counts6).reshape(n, 6)


def _dsatur(adjacent: np.ndarray) -> np.ndarray:
    """Colours (S,) of the vertices of the graph with boolean adjacency (S, S) (the diagonal
    ignored), no two adjacent vertices alike, by DSatur (Brelaz 1979); deterministic."""
    n = len(adjacent)
    adjacent = adjacent & ~np.eye(n, dtype=bool)
    colour = np.full(n, -1)
    taken = np.zeros((n, n + 1), dtype=bool)  # taken[v, c]: a neighbour of v has colour c
    saturation, degree = np.zeros(n, dtype=np.int64), adjacent.sum(axis=1)
    for _ in range(n):
        v = int(np.argmax(np.where(colour < 0, saturation * (n + 1) + degree, -1)))
        c = int(np.argmin(taken[v]))
        colour[v] = c
        fresh = adjacent[v] & ~taken[:, c]
        saturation[fresh] += 1
        taken[fresh, c] = True
    return colour
