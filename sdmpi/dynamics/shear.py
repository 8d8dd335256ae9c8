"""Imposed shear protocols: strain gamma(t) and rate gamma_dot(t) of simple shear
u_inf = gamma_dot(t) y e_x (flow x, gradient y, vorticity z). The box strain follows
gamma(t) exactly (Lees-Edwards), so positions are advected affinely and wrapped with the
lattice of the current strain.

A step from t0 to t1 moves the particles with the step's mean rate

    <gamma_dot>_[t0, t1] = (gamma(t1) - gamma(t0)) / (t1 - t0),

the rate of which the exact affine displacement (gamma(t1) - gamma(t0)) y is the
integral, so that the affine and the disturbance parts of a velocity belong to the same
imposed flow (`mean_rate`)."""

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Oscillatory:
    """gamma(t) = gamma0 sin(omega t), gamma_dot(t) = gamma0 omega cos(omega t)."""

    gamma0: float
    omega: float

    def strain(self, t):
        return self.gamma0 * math.sin(self.omega * t)

    def rate(self, t):
        return self.gamma0 * self.omega * math.cos(self.omega * t)

    def mean_rate(self, t0, t1):
        """(gamma(t1) - gamma(t0)) / (t1 - t0) = gamma0 omega cos(omega t_m) sinc(omega dt/2)
        with t_m = (t0 + t1)/2, dt = t1 - t0, sinc x = sin x / x."""
        return (self.strain(t1) - self.strain(t0)) / (t1 - t0)


@dataclass(frozen=True)
class Steady:
    """gamma(t) = rate t."""

    shear_rate: float

    def strain(self, t):
        return self.shear_rate * t

    def rate(self, t):
        return self.shear_rate

    def mean_rate(self, t0, t1):
        """The rate itself (exactly: not the rounded difference of two strains)."""
        return self.shear_rate


@dataclass(frozen=True)
class NoShear:
    """Equilibrium: no imposed flow."""

    def strain(self, t):
        return 0.0

    def rate(self, t):
        return 0.0

    def mean_rate(self, t0, t1):
        return 0.0


def rate_of_strain(rate):
    """E_inf (3, 3) of simple shear at the given rate: E_xy = E_yx = rate/2."""
    e = np.zeros((3, 3))
    e[0, 1] = e[1, 0] = 0.5 * rate
    return e


def affine_displacement(positions, strain_old, strain_new):
    """Exact affine displacement of simple shear between two strains: dx = dgamma y."""
    shift = np.zeros_like(positions)
    shift[:, 0] = (strain_new - strain_old) * positions[:, 1]
    return shift
