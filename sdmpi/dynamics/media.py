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
from typing import Any

import numpy as np

from .component import SampleFields, StateFields
from .recorders import StressRecorder, bulk_stress


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


class MaxwellStress(StressRecorder):
    """The hydrodynamic stress of a multi-mode Maxwell medium (module docstring): the mode
    stresslets S_k (n_modes, N, 5) of N spheres, advanced by a `MaxwellFilter` from each
    step's viscous-medium stresslets S_0; sampled as stress_hydrodynamic_maxwell, (1/V)
    sum_k sum_i S_k. Its state: the modes and the previous step's S_0.

    Args:
        eta: eta_k/eta_m of each mode.
        lam: relaxation time lambda_k of each mode (time unit).
        dt: the time step (time unit).
        n_particles: N.
    """

    def __init__(self, eta: tuple[float, ...], lam: tuple[float, ...], dt: float, n_particles: int):
        self.filter = MaxwellFilter(tuple(eta), tuple(lam), dt)
        self.modes = np.zeros((len(eta), n_particles, 5))
        self.source_prev = np.zeros((n_particles, 5))

    def sample_fields(self, stress_unit: str) -> SampleFields:
        return {"stress_hydrodynamic_maxwell": ((6,), "f8", stress_unit,
                                                "hydrodynamic stress filtered by the Maxwell modes")}

    def sample(self, step: int, stresslets: np.ndarray, volume: float) -> dict[str, Any]:
        """S_k updated from the previous step's S_0 to this one's (from step 1 on)."""
        if step > 0:
            self.filter.update(self.modes, self.source_prev, stresslets)
        self.source_prev = stresslets.copy()
        return {"stress_hydrodynamic_maxwell": bulk_stress(self.modes.sum(axis=0), volume)}

    def state_fields(self) -> StateFields:
        return {"modes": (self.modes.shape, "f8"), "source_prev": (self.source_prev.shape, "f8")}

    def get_state(self) -> dict[str, np.ndarray]:
        return {"modes": self.modes.copy(), "source_prev": self.source_prev.copy()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.modes = np.array(state["modes"], dtype=float)
        self.source_prev = np.array(state["source_prev"], dtype=float)
