"""Stress samples of a step beyond the four contributions: the components that record the
step's hydrodynamic stresslets S_H (a Maxwell medium's filtered stress, `media`; the
per-particle stresslets, `PerParticleStresslets`), and the bulk-stress arithmetic they
share with the step.

Stresses are 6-vectors xx yy zz xy xz yz, per volume V (a^3), in eta_m/t_D (or eta_m
gamma_dot for non-Brownian steady shear); stresslets (N, 5) in the 5-basis
(`sdmpi.hydro.basis`), in eta_m a^3/t_D.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from ..hydro.basis import BASIS
from .component import NoState, SampleFields, Stateful

#: stress component order of the 6-vectors
SIX_VECTOR_INDICES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
#: the 6-vector components (SIX_VECTOR_INDICES) of the basis tensors: (6, 5), BASIS[m][a, b]
_SIX_OF_FIVE = np.array([[BASIS[m, a, b] for m in range(5)] for a, b in SIX_VECTOR_INDICES])


def bulk_stress(tensors: np.ndarray, volume: float) -> np.ndarray:
    """(1/V) sum of (N, 5) 5-basis tensors, as a 6-vector xx yy zz xy xz yz.

    Args:
        tensors: per-particle tensors in the 5-basis, shape (N, 5) (e.g. eta_m a^3/t_D).
        volume: the normalising volume V, in a^3.

    Returns:
        The 6-vector, shape (6,), in the tensors' unit per a^3 (e.g. eta_m/t_D).
    """
    return _SIX_OF_FIVE @ tensors.sum(axis=0) / volume


def symmetric_six(matrix: np.ndarray) -> np.ndarray:
    """The symmetric part of a 3x3 matrix as a 6-vector xx yy zz xy xz yz.

    Args:
        matrix: shape (3, 3).

    Returns:
        Shape (6,), in the matrix's unit.
    """
    sym = 0.5 * (matrix + matrix.T)
    return np.array([sym[a, b] for a, b in SIX_VECTOR_INDICES])


class StressRecorder(Stateful, Protocol):
    """A component that samples each step's hydrodynamic stresslets, with its own sample
    fields and state."""

    def sample_fields(self, stress_unit: str) -> SampleFields:
        """Its fields of the sample stream.

        Args:
            stress_unit: the job's stress unit.

        Returns:
            name -> (shape per sample, dtype, unit, description).
        """
        raise NotImplementedError

    def sample(self, step: int, stresslets: np.ndarray, volume: float) -> dict[str, Any]:
        """Its sample of step ``step``.

        Args:
            step: the step k (t_k = k dt); steps come in order.
            stresslets: S_H of the configuration x_k, (N, 5), eta_m a^3/t_D.
            volume: the volume that normalises stresses (a^3).

        Returns:
            name -> value, the fields of sample_fields.
        """
        raise NotImplementedError


class PerParticleStresslets(NoState, StressRecorder):
    """output.per_particle: each step's S_H of the N spheres, in the 5-basis."""

    def __init__(self, n_particles: int):
        self.n_particles = n_particles

    def sample_fields(self, stress_unit: str) -> SampleFields:
        return {"stresslets": ((self.n_particles, 5), "f8", "eta_m a^3/t_D", "S_H in the 5-basis")}

    def sample(self, step: int, stresslets: np.ndarray, volume: float) -> dict[str, Any]:
        return {"stresslets": stresslets}
