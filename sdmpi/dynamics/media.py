"""Suspending media: Newtonian, and multi-mode Maxwell via the correspondence principle.

Schaink et al. (2000) sec. II C: in a Maxwell medium the particle trajectories
are those of the viscous medium of the same zero-shear viscosity eta_m (eq. 32), while
each mode k filters the hydrodynamic stresslets (eqs. 33-34, 42):

    lambda_k dS_k/dt + S_k = (eta_k / eta_m) S_0(t),    S_H = sum_k S_k,

with S_0 the stresslet computed in the viscous medium. Over a step [t0, t0 + dt] with S_0
linear in time, the update is exact (h = dt / lambda_k):

    S_k(t0 + dt) = exp(-h) S_k(t0) + (eta_k/eta_m) [S_0(t0) (1 - exp(-h))
                   + (S_0(t0 + dt) - S_0(t0)) (1 - (1 - exp(-h)) / h)].

The medium's own stress obeys the same law with 2 eta_m E_inf as source; its moduli are
analytic (Schaink et al. eq. 36) and are added by the reducer, not computed here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MaxwellFilter:
    """The modes (eta_k/eta_m, lambda_k) and a fixed step dt: exact linear-source update."""

    eta: tuple
    lam: tuple
    dt: float

    def coefficients(self) -> np.ndarray:
        """Per mode (decay, weight_old, weight_new) so that
        S_k <- decay S_k + weight_old S_0(t0) + weight_new S_0(t0 + dt).

        Returns:
            Array of shape (n_modes, 3), dimensionless (weights carry eta_k/eta_m).
        """
        out = []
        for eta, lam in zip(self.eta, self.lam):
            h = self.dt / lam
            decay = math.exp(-h)
            ramp = 1.0 - (-math.expm1(-h)) / h  # 1 - (1 - e^-h)/h, accurate for small h
            out.append((decay, eta * (-math.expm1(-h) - ramp), eta * ramp))
        return np.array(out)

    def update(
        self, modes: np.ndarray, source_old: np.ndarray, source_new: np.ndarray
    ) -> np.ndarray:
        """Advance the mode stresslets (n_modes, ...) over one step, in place.

        Args:
            modes: mode stresslets S_k, shape (n_modes, ...), modified in place.
            source_old: viscous-medium stresslets S_0(t0), shape of one mode (...).
            source_new: viscous-medium stresslets S_0(t0 + dt), same shape.

        Returns:
            `modes`, the same array, advanced by dt (stresslet units of the sources).
        """
        for k, (decay, w_old, w_new) in enumerate(self.coefficients()):
            modes[k] *= decay
            modes[k] += w_old * source_old + w_new * source_new
        return modes
