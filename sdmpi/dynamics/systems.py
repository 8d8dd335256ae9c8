"""The geometry of a realisation's system: its box, its start, the volume that normalises
its stresses, the constraint on its motion and its rule for overlaps.

Two geometries (``system.geometry``): `Bulk`, spheres filling a periodic box (this module),
and `sdmpi.dynamics.monolayer.Monolayer`, a sheared layer of spheres (Dratler &
Schowalter 1996). Units: lengths in a (the largest radius).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from .collisions import Collisions
from .component import NoState, Stateful
from .initial import hard_sphere_fluid

if TYPE_CHECKING:
    from ..hydro.geometry import Lattice

class Geometry(Stateful, Protocol):
    """A realisation's geometry. ``box`` (3,) (a) and ``volume`` (a^3, the volume that
    normalises the bulk stresses) are set by `start`; ``corrects_overlaps``: whether
    overlapping pairs are corrected at the end of each step (`collisions`) or kept."""

    box: np.ndarray
    volume: float
    corrects_overlaps: bool

    def start(self, rng: np.random.Generator, strain: float) -> np.ndarray:
        """A random start (not wrapped); sets ``box`` and ``volume``.

        Args:
            rng: the realisation's random stream.
            strain: the Lees-Edwards strain at t = 0, dimensionless.

        Returns:
            Positions (N, 3), in a.
        """
        raise NotImplementedError

    def kept_overlaps(self, positions: np.ndarray, radii: np.ndarray, lattice: Lattice) -> Collisions:
        """The overlaps at a step's start that are counted, not corrected.

        Args:
            positions: centres (N, 3), wrapped, in a.
            radii: radii (N,), in a.
            lattice: the periodic lattice at the step's strain.

        Returns:
            A `Collisions` without pairs, with the count and the deepest gap.
        """
        raise NotImplementedError

    def stops(self, step: int, min_gap: float, task_id: int) -> bool:
        """Whether the realisation has stopped (at this step or earlier).

        Args:
            step: the step.
            min_gap: the step's smallest surface gap (a).
            task_id: the task, for a warning.

        Returns:
            True once stopped: every later sample is `stopped_sample`.
        """
        raise NotImplementedError

    def stopped_sample(self, fields: dict[str, tuple[tuple[int, ...], str, str, str]], time: float,
                       strain: float, rate: float) -> dict[str, Any]:
        """The sample of a step after the stop (time, strain and rate; every other value
        NaN, -1 for counts)."""
        raise NotImplementedError

    def in_plane(self, velocity: np.ndarray) -> np.ndarray:
        """The velocities (N, 6) the geometry allows (the same array where all are)."""
        raise NotImplementedError


class Bulk(NoState, Geometry):
    """N spheres of radii ``radii`` (a) at volume fraction ``phi`` in a periodic cube with
    Lees-Edwards images, started as an equilibrium hard-sphere fluid of ``sweeps`` Monte
    Carlo sweeps (`initial.hard_sphere_fluid`); overlapping pairs are corrected unless
    ``corrects_overlaps`` is False (forces with contacts); nothing stops it."""

    def __init__(self, radii: np.ndarray, phi: float, sweeps: int, corrects_overlaps: bool = True):
        self.radii, self.phi, self.sweeps = radii, phi, sweeps
        self.corrects_overlaps = corrects_overlaps
        self.box, self.volume = np.full(3, np.nan), np.nan

    def start(self, rng: np.random.Generator, strain: float) -> np.ndarray:
        pos, side = hard_sphere_fluid(len(self.radii), self.phi, rng, strain=strain, radii=self.radii,
                                      sweeps=self.sweeps)
        self.box = np.full(3, side)
        self.volume = float(np.prod(self.box))
        return pos

    def kept_overlaps(self, positions: np.ndarray, radii: np.ndarray, lattice: Lattice) -> Collisions:
        """None counted: overlaps are corrected (or, with contacts, the contacts' own)."""
        return Collisions.none()

    def stops(self, step: int, min_gap: float, task_id: int) -> bool:
        return False

    def stopped_sample(self, fields: dict[str, tuple[tuple[int, ...], str, str, str]], time: float,
                       strain: float, rate: float) -> dict[str, Any]:
        raise RuntimeError("a bulk realisation does not stop")

    def in_plane(self, velocity: np.ndarray) -> np.ndarray:
        return velocity
