"""The interface of a solver backend: what the hydrodynamics asks of a solver of F = R U.

A backend is built at one configuration from its resistance (`resistance.GrandResistance`,
or `resistance.SplitResistance` for a matrix-free backend: `sdmpi.registry.BackendSpec`)
and answers, for imposed forces/torques and strain rates, the rigid-body velocities and
the stresslets,

    U' = R_FU^-1 (F + R_FE e_inf),      S = R_SE e_inf - R_SU U'

(from (F, L, -S) = R (U', -e_inf), U' = velocities relative to the imposed flow, e_inf
the 5-vector of E_inf at every particle), and a Brownian factor: forces C z of covariance
R_FU = C C^T for standard normal z, whose velocities R_FU^-1 C z have covariance R_FU^-1
(fluctuation-dissipation).

A backend class subclasses `SolverBackend` and implements its abstract members; the other
members have generic forms a backend may replace by faster ones of its own (the dense
backend's triangular solves). It is registered in `sdmpi.registry.SOLVER_BACKENDS`
(docs/extending.md).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, Protocol

import numpy as np

#: the relative error `SolverBackend.mobility_forms` may leave in a form where its caller
#: asks for no other accuracy (a direct backend's forms are exact to rounding; an iterative
#: one may solve for several sets at once, `sdmpi.hydro.krylov.FORMS_SEPARATION`)
FORM_ACCURACY = 1e-3


class SolverBackend(Protocol):
    """A solver of the resistance problem at one configuration of N spheres.

    Attributes:
        n: the number of spheres N.
        noise_shape: the shape of the standard normal noise z that `brownian_forces` takes
            ((N, 6) for a factor C of R_FU itself; a matrix-free backend may draw more).
        stats: iterations (Krylov "iterations", "lanczos") and the largest relative
            "residual" of the solves so far (zero for a direct backend).
    """

    n: int
    noise_shape: tuple[int, ...]
    stats: Mapping[str, float] = MappingProxyType({"iterations": 0, "residual": 0.0, "lanczos": 0})

    @classmethod
    def build(cls, resistance: Any, comm: Any, tolerance: float, lanczos_tolerance: float | None) -> SolverBackend:
        """The backend of ``resistance`` solving on the MPI communicator ``comm`` (None: this
        rank alone; collective over comm otherwise); ``tolerance``: relative residual of
        iterative solves, ``lanczos_tolerance``: accuracy of their Brownian square roots
        (None: tolerance). Generic form: ``cls(resistance, comm)``, for the direct backends,
        which have no tolerance."""
        return cls(resistance, comm)

    def velocities(self, forces: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """U' (N, 6) = R_FU^-1 (F + R_FE e_inf) for forces/torques (N, 6) and e_inf (N, 5).

        Args:
            forces: (N, 6) forces and torques on the spheres (Stokes units, viscosity 1).
            einf: (N, 5) imposed rate of strain at each sphere (`basis` components).

        Returns:
            (N, 6) velocities and angular velocities relative to the imposed flow.
        """
        raise NotImplementedError

    def stresslets(self, velocities: np.ndarray, einf: np.ndarray) -> np.ndarray:
        """S (N, 5) = R_SE e_inf - R_SU U' for rigid-body velocities U' (N, 6) and e_inf (N, 5).

        Args:
            velocities: (N, 6) velocities and angular velocities relative to the imposed flow.
            einf: (N, 5) imposed rate of strain at each sphere (`basis` components).

        Returns:
            (N, 5) stresslets (`basis` components, Stokes units).
        """
        raise NotImplementedError

    def brownian_forces(self, noise: np.ndarray) -> np.ndarray:
        """C z (N, 6), of covariance R_FU, for the standard normal noise z (`noise_shape`).

        Args:
            noise: standard normal noise z, of shape `noise_shape`.

        Returns:
            (N, 6) forces and torques C z (per unit variance of the noise).
        """
        raise NotImplementedError

    def brownian_velocities(self, noise: np.ndarray) -> np.ndarray:
        """R_FU^-1 C z (N, 6) for the noise z (`noise_shape`): the velocities of the
        Brownian force C z. Generic form: ``velocities(brownian_forces(z), 0)``.

        Args:
            noise: standard normal noise z, of shape `noise_shape`.

        Returns:
            (N, 6) velocities and angular velocities R_FU^-1 C z.
        """
        return self.velocities(self.brownian_forces(noise), np.zeros((self.n, 5)))

    def mobility_forms(self, forces: np.ndarray, accuracy: np.ndarray | None = None) -> np.ndarray:
        """f.R_FU^-1.f (P,) for each of the force sets ``forces`` (P, N, 6), each within its
        relative ``accuracy`` (a backend may spend less work on a form asked for less).
        Generic form: one solve per set, exact to the solver's tolerance.

        Args:
            forces: (P, N, 6) force/torque sets.
            accuracy: (P,) relative error each form may have (None: FORM_ACCURACY for all).

        Returns:
            (P,) the quadratic forms f.R_FU^-1.f.
        """
        zero = np.zeros((self.n, 5))
        return np.array([np.vdot(f, self.velocities(f, zero)) for f in forces])

    def take_preconditioner(self, previous: SolverBackend) -> None:
        """Take over what can be reused of ``previous``, a solver of the same backend at a
        nearby configuration (the Brownian step's start for its midpoint). Generic form:
        nothing (a direct backend factorises afresh)."""

    def forces_drawn(self) -> None:
        """No more Brownian forces will be drawn from this solver (a step's are drawn), and
        a solver at the Brownian midpoint is built next: free what only `brownian_forces`
        needs, and what later solves can compute again; later solves give the same
        results. Generic form: nothing (a direct backend's factor serves its solves too)."""
