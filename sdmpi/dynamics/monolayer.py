"""Sheared monolayers of non-Brownian spheres (Dratler & Schowalter, J. Fluid Mech. 325, 53
(1996), after Brady & Bossis, J. Fluid Mech. 155, 105 (1985)): the `Monolayer` geometry
(`systems.Geometry`) of system.geometry = "monolayer". Derivations and measurements:
docs/physics.md, "Monolayers".

Geometry: N spheres of radius a = 1 with centres in the plane z = Lz/2 of the box
(L, L, Lz), a square cell of side L = (N pi / phi_a)^(1/2) at areal fraction phi_a
(``system.phi``), periodic in x and y with the Lees-Edwards shift of u = gamma_dot y e_x,
and Lz = ``system.layer_spacing`` x L: the 3D Ewald sums of `sdmpi.hydro` replicate the
layer every Lz in z.

In-plane motion: the configuration and the flow are symmetric under z -> Lz - z, so the
mirror-odd velocities U_z, Omega_x, Omega_y (``MIRROR_ODD``) of the full FTS solution
vanish and the in-plane ones are the solution of Dratler & Schowalter's reduced problem
(their eq. 2: F_x, F_y, T_z); `Monolayer.in_plane` sets the mirror-odd ones to 0 so that
rounding never moves a centre out of the plane.

Stresses (Dratler & Schowalter's eq. 6): normalised by the layer's volume 2 a L^2,
Sigma = (1/(2 a L^2)) sum (S - x F_P), so that `sdmpi reduce` gives their eta, eta_h and
eta_p.

Overlaps (Dratler & Schowalter sec. 3; Bossis & Brady, J. Chem. Phys. 80, 5141 (1984)):
pairs closer than ``hydrodynamics.min_gap`` get the lubrication of that gap but are not
moved; the overlapping ones are counted (periodic images once) with the deepest gap, and
an overlap deeper than ``integration.overlap_stop`` stops the realisation: it warns, keeps
its last configuration, and every later sample is NaN (counts -1).

Units: lengths in a, times in the job's time unit (1/gamma_dot under steady shear).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..hydro.lubrication import close_pairs
from .collisions import Collisions
from .component import StateFields
from .initial import hard_disk_monolayer, square_side
from .systems import Geometry

if TYPE_CHECKING:
    from ..hydro.geometry import Lattice

#: velocity components (of the 6 per sphere: U, Omega) that are odd under z -> -z
MIRROR_ODD = (2, 3, 4)

log = logging.getLogger(__name__)


class Monolayer(Geometry):
    """The monolayer of one task (a `systems.Geometry`): box, normalising volume, start,
    in-plane constraint, overlaps counted and kept, and the overlap stop (module docstring).

    Args:
        n_particles: N.
        phi_a: areal fraction (system.phi).
        layer_spacing: Lz / L (system.layer_spacing).
        overlap_stop: the deepest overlap (a) before the run stops (integration.overlap_stop).
    """

    corrects_overlaps = False

    def __init__(self, n_particles: int, phi_a: float, layer_spacing: float, overlap_stop: float):
        side = square_side(n_particles, phi_a)
        self.n_particles, self.phi_a = n_particles, phi_a
        self.box = np.array([side, side, layer_spacing * side])
        #: the layer's volume 2 a L^2 that normalises its stresses (Dratler & Schowalter's eq. 6)
        self.volume = 2.0 * side * side
        self.overlap_stop = overlap_stop
        #: the step at which the run stopped on an overlap, -1 while running
        self.stopped_at = -1

    def start(self, rng: np.random.Generator, strain: float = 0.0) -> np.ndarray:
        """Random non-overlapping start in the plane z = Lz/2, (N, 3).

        Args:
            rng: the random stream of the start.
            strain: unused (the start's disks do not overlap at any strain).

        Returns:
            Positions, shape (N, 3), in a.
        """
        return hard_disk_monolayer(self.n_particles, self.phi_a, rng, z=0.5 * self.box[2])[0]

    def kept_overlaps(self, positions: np.ndarray, radii: np.ndarray, lattice: Lattice) -> Collisions:
        """Overlaps counted and kept (Dratler & Schowalter 1996): their number and the deepest."""
        return Collisions.none(*self.overlaps(positions, radii, lattice))

    def state_fields(self) -> StateFields:
        return {"stopped_at": ((1,), "i8")}

    def get_state(self) -> dict[str, np.ndarray]:
        return {"stopped_at": np.array([self.stopped_at], dtype=np.int64)}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.stopped_at = int(state["stopped_at"][0])

    @staticmethod
    def in_plane(velocity: np.ndarray) -> np.ndarray:
        """(N, 6) velocities with the mirror-odd components U_z, Omega_x, Omega_y set to 0.

        Args:
            velocity: (U, Omega), shape (N, 6), not modified.

        Returns:
            A copy, shape (N, 6), same units, columns MIRROR_ODD zero.
        """
        out = velocity.copy()
        out[:, MIRROR_ODD] = 0.0
        return out

    @staticmethod
    def overlaps(positions: np.ndarray, radii: np.ndarray, lattice: Lattice) -> tuple[int, float]:
        """Overlapping pairs (count) and the smallest surface gap among them (inf: none).

        Args:
            positions: centres, shape (N, 3), in a.
            radii: radii, shape (N,), in a.
            lattice: the periodic lattice of the current strain.

        Returns:
            (number of overlapping pairs, smallest gap in a).
        """
        pairs = close_pairs(positions, radii, lattice, cutoff=0.0)
        return len(pairs.i), pairs.min_gap

    def stops(self, step: int, min_gap: float, task_id: int) -> bool:
        """True once the run has stopped: now, if an overlap is deeper than overlap_stop.

        Args:
            step: the current step number.
            min_gap: the step's smallest surface gap, in a (negative: overlap).
            task_id: the task, for the warning.

        Returns:
            Whether the run has stopped (at this or an earlier step).
        """
        if self.stopped_at < 0 and -min_gap > self.overlap_stop:
            self.stopped_at = step
            log.warning(f"task {task_id}: stopped at step {step}: two spheres overlap by "
                        f"{-min_gap:.3g} a > integration.overlap_stop = {self.overlap_stop:g} "
                        f"(Dratler & Schowalter 1996); the remaining samples are NaN")
        return self.stopped_at >= 0

    def stopped_sample(
        self, fields: dict[str, tuple[tuple[int, ...], str, str, str]], time: float, strain: float, rate: float
    ) -> dict[str, Any]:
        """A sample after the stop: time, strain and rate, every other value NaN (-1 for
        counts).

        Args:
            fields: the sample stream's fields (`setup.sample_fields`).
            time: sample time (time unit).
            strain: strain at that time, dimensionless.
            rate: shear rate at that time (1/time unit).

        Returns:
            name -> value, arrays shaped as in fields.
        """
        sample = {k: np.full(shape, -1 if np.dtype(dt).kind == "i" else math.nan, dtype=dt)
                  for k, (shape, dt, _, _) in fields.items()}
        sample.update(time=time, strain=strain, rate=rate)
        return sample
