"""The grand resistance of Stokesian dynamics, R = (M_inf)^-1 + sum (R_2B - R_2B,inf).

Durlofsky, Brady & Bossis (1987) unbounded; Brady, Phillips, Lester & Bossis (1988)
periodic. Generalized vectors per particle (11 components, see `farfield`):
F = (F, L, -S) = R (U - U_inf, Omega - Omega_inf, -E_inf), viscosity 1. M_inf is
inverted through its Cholesky factorisation (LAPACK potrf/potri): R needs the inverse
itself, not only its action.
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from .farfield import NDOF, far_field_mobility
from .geometry import Lattice
from .lubrication import DEFAULT_CUTOFF, DEFAULT_MIN_GAP, PairList, close_pairs, lubrication_matrix

#: default relative accuracy of the Ewald sums
DEFAULT_EWALD_TOL = 1e-8


@dataclass
class GrandResistance:
    """R (11N x 11N, dofs ordered per particle: 3 U, 3 Omega, 5 E) and its pair list."""

    matrix: np.ndarray
    pairs: PairList

    @property
    def n_particles(self):
        return self.matrix.shape[0] // NDOF

    def blocks(self):
        """(R_FU, R_FE, R_SU, R_SE): the 6N rigid-body and 5N strain partitions."""
        n = self.n_particles
        idx = np.arange(NDOF * n).reshape(n, NDOF)
        rigid = idx[:, :6].ravel()
        strain = idx[:, 6:].ravel()
        m = self.matrix
        return (m[np.ix_(rigid, rigid)], m[np.ix_(rigid, strain)],
                m[np.ix_(strain, rigid)], m[np.ix_(strain, strain)])


def spd_inverse(matrix):
    """Inverse of a symmetric positive definite matrix by Cholesky (potrf + potri)."""
    chol, info = lapack.dpotrf(matrix, lower=False, clean=False, overwrite_a=False)
    if info != 0:
        raise np.linalg.LinAlgError(f"matrix not positive definite (potrf info {info})")
    inv, info = lapack.dpotri(chol, lower=False, overwrite_c=True)
    if info != 0:
        raise np.linalg.LinAlgError(f"potri failed (info {info})")
    upper = np.triu(inv)
    return upper + np.triu(inv, 1).T


def grand_resistance(positions, radii, box=None, strain=0.0, lubrication=True,
                     ewald_tol=DEFAULT_EWALD_TOL, cutoff=DEFAULT_CUTOFF, min_gap=DEFAULT_MIN_GAP):
    """Assemble R for validated inputs (see `solve.solve_mobility` for the checks)."""
    lattice = None if box is None else Lattice(box, strain)
    pos = positions if lattice is None else lattice.wrap(positions)
    matrix = spd_inverse(far_field_mobility(pos, radii, box, strain, tol=ewald_tol))
    if lubrication:
        near, pairs = lubrication_matrix(pos, radii, lattice, cutoff, min_gap)
        matrix += near
    else:
        pairs = close_pairs(pos, radii, lattice, 0.0, min_gap)
    return GrandResistance(matrix, pairs)
