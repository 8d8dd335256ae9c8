"""Imposed shear protocols: strain gamma(t) and rate gamma_dot(t) of simple shear
u_inf = gamma_dot(t) y e_x (flow x, gradient y, vorticity z). The box strain follows
gamma(t) exactly (Lees-Edwards), so positions are advected affinely and wrapped with the
lattice of the current strain.

A step from t0 to t1 moves the particles with the step's mean rate

    <gamma_dot>_[t0, t1] = (gamma(t1) - gamma(t0)) / (t1 - t0),

the rate of which the exact affine displacement (gamma(t1) - gamma(t0)) y is the
integral, so that the affine and the disturbance parts of a velocity belong to the same
imposed flow (`mean_rate`).

Times are in t_D (1/gamma_dot for non-Brownian steady shear), rates in 1/t_D, strains
dimensionless, lengths in particle radii a."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Oscillatory:
    """gamma(t) = gamma0 sin(omega t), gamma_dot(t) = gamma0 omega cos(omega t)."""

    gamma0: float
    omega: float

    def strain(self, t: float) -> float:
        """Strain at a time.

        Args:
            t: time (t_D).

        Returns:
            gamma(t), dimensionless.
        """
        return self.gamma0 * math.sin(self.omega * t)

    def rate(self, t: float) -> float:
        """Shear rate at a time.

        Args:
            t: time (t_D).

        Returns:
            gamma_dot(t) (1/t_D).
        """
        return self.gamma0 * self.omega * math.cos(self.omega * t)

    def mean_rate(self, t0: float, t1: float) -> float:
        """(gamma(t1) - gamma(t0)) / (t1 - t0) = gamma0 omega cos(omega t_m) sinc(omega dt/2)
        with t_m = (t0 + t1)/2, dt = t1 - t0, sinc x = sin x / x.

        Args:
            t0: start of the step (t_D).
            t1: end of the step (t_D), t1 != t0.

        Returns:
            The step's mean rate (1/t_D).
        """
        return (self.strain(t1) - self.strain(t0)) / (t1 - t0)


@dataclass(frozen=True)
class Steady:
    """gamma(t) = rate t."""

    shear_rate: float

    def strain(self, t: float) -> float:
        """Strain at a time.

        Args:
            t: time (t_D).

        Returns:
            gamma(t) = rate t, dimensionless.
        """
        return self.shear_rate * t

    def rate(self, t: float) -> float:
        """Shear rate, the same at every time.

        Args:
            t: time (t_D).

        Returns:
            The constant rate (1/t_D).
        """
        return self.shear_rate

    def mean_rate(self, t0: float, t1: float) -> float:
        """The rate itself (exactly: not the rounded difference of two strains).

        Args:
            t0: start of the step (t_D).
            t1: end of the step (t_D).

        Returns:
            The constant rate (1/t_D).
        """
        return self.shear_rate


@dataclass(frozen=True)
class NoShear:
    """Equilibrium: no imposed flow."""

    def strain(self, t: float) -> float:
        """Strain at a time.

        Args:
            t: time (t_D).

        Returns:
            0.0.
        """
        return 0.0

    def rate(self, t: float) -> float:
        """Shear rate at a time.

        Args:
            t: time (t_D).

        Returns:
            0.0.
        """
        return 0.0

    def mean_rate(self, t0: float, t1: float) -> float:
        """Mean rate over a step.

        Args:
            t0: start of the step (t_D).
            t1: end of the step (t_D).

        Returns:
            0.0.
        """
        return 0.0


def rate_of_strain(rate: float) -> np.ndarray:
    """E_inf (3, 3) of simple shear at the given rate: E_xy = E_yx = rate/2.

    Args:
        rate: shear rate gamma_dot (1/t_D).

    Returns:
        The symmetric traceless rate-of-strain tensor, shape (3, 3), in 1/t_D.
    """
    e = np.zeros((3, 3))
    e[0, 1] = e[1, 0] = 0.5 * rate
    return e


def affine_displacement(
    positions: np.ndarray, strain_old: float, strain_new: float
) -> np.ndarray:
    """Exact affine displacement of simple shear between two strains: dx = dgamma y.

    Args:
        positions: particle centres, shape (N, 3), in radii a.
        strain_old: strain at the start of the step, dimensionless.
        strain_new: strain at the end of the step, dimensionless.

    Returns:
        Displacements, shape (N, 3), in a; only the x column is non-zero.
    """
    shift = np.zeros_like(positions)
    shift[:, 0] = (strain_new - strain_old) * positions[:, 1]
    return shift
