"""Five-component basis for symmetric traceless 3x3 tensors (stresslets, strain rates).

The basis is orthonormal under the double contraction, B^m : B^n = delta_mn, so that
S : E = s . e for the 5-vectors s_m = S : B^m, e_m = E : B^m, and blocks of the grand
mobility/resistance that couple two such tensors are symmetric 5x5 matrices:

    B^1 = (xx - yy)/sqrt2,  B^2 = (2zz - xx - yy)/sqrt6,
    B^3 = (xy + yx)/sqrt2,  B^4 = (xz + zx)/sqrt2,  B^5 = (yz + zy)/sqrt2.
"""

from __future__ import annotations

import numpy as np

_S2 = np.sqrt(2.0)
_S6 = np.sqrt(6.0)

#: BASIS[m] is the 3x3 matrix B^(m+1).
BASIS = np.zeros((5, 3, 3))
BASIS[0, 0, 0], BASIS[0, 1, 1] = 1 / _S2, -1 / _S2
BASIS[1, 0, 0], BASIS[1, 1, 1], BASIS[1, 2, 2] = -1 / _S6, -1 / _S6, 2 / _S6
BASIS[2, 0, 1] = BASIS[2, 1, 0] = 1 / _S2
BASIS[3, 0, 2] = BASIS[3, 2, 0] = 1 / _S2
BASIS[4, 1, 2] = BASIS[4, 2, 1] = 1 / _S2


def to_five(tensor: np.ndarray) -> np.ndarray:
    """(..., 3, 3) symmetric traceless tensors -> (..., 5) components in BASIS.

    Args:
        tensor: (..., 3, 3) symmetric traceless tensors (any unit).

    Returns:
        (..., 5) components t_m = T : B^m, in the unit of tensor.
    """
    return np.einsum("...ij,mij->...m", tensor, BASIS)


def from_five(vector: np.ndarray) -> np.ndarray:
    """(..., 5) components -> (..., 3, 3) symmetric traceless tensors.

    Args:
        vector: (..., 5) components in BASIS (any unit).

    Returns:
        (..., 3, 3) symmetric traceless tensors sum_m v_m B^m, in the unit of vector.
    """
    return np.einsum("...m,mij->...ij", vector, BASIS)
