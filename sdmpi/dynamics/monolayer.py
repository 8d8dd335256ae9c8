"""Sheared monolayers of non-Brownian spheres (Dratler & Schowalter, J. Fluid
Mech. 325, 53 (1996), after Brady & Bossis, J. Fluid Mech. 155, 105 (1985)).

Geometry. N spheres of radius a = 1 with centres in the plane z = Lz/2 of the box
(L, L, Lz): a square cell of side L = (N pi / phi_a)^(1/2) at areal fraction phi_a
(``system.phi``), periodic in x and y with the Lees-Edwards shift of the flow
u = gamma_dot y e_x, and Lz = ``system.layer_spacing`` x L.

Third direction. The layer moves in unbounded 3D fluid; the far field is summed by the
3D Ewald sums of `sdmpi.hydro`, so the layer is replicated every Lz in z (a stack of
layers, as in the seed, which put its z-images 100 L away to keep the mobility positive
definite). With zero net force per layer (force-free spheres, pair forces) the layers
interact only through the in-plane Fourier modes k >= 2 pi/L of their force and stresslet
densities, whose fields decay like exp(-k Lz) between layers. Measured (phi_a = 0.4,
N = 25, Ewald tolerance 1e-10): from Lz = 2 L to 100 L the hydrodynamic viscosity of a
configuration changes by < 2e-9 (relative), and from 2 L to 50 L the relative velocities
under pair forces by 8e-6; the one Lz-dependent motion is a uniform drift of the whole layer (its uniform
translation is resisted only by the pairs' lubrication and a far-field term ~1/Lz), which
moves no sphere relative to another. Default Lz = 2 L; the loader keeps the z-images
beyond the lubrication cut-off.

In-plane motion. The configuration and the flow are symmetric under the reflection
z -> Lz - z, which maps the grand resistance onto itself, so R couples the mirror-even
components (U_x, U_y, Omega_z, and E_xx, E_yy, E_zz, E_xy) only among themselves: the
out-of-plane velocity U_z and the rotations about in-plane axes, Omega_x and Omega_y, of
the full FTS solution vanish (measured ~1e-17, tests/test_monolayer.py), and the in-plane
ones equal the solution of Dratler & Schowalter's reduced 3N x 3N problem (its eq. 2: F_x, F_y,
T_z). sdmpi solves the full problem and sets the mirror-odd velocities to 0 so that rounding
never moves a centre out of the plane. Brownian noise would excite them; Brownian
monolayers are refused by the loader.

Viscosity (Dratler & Schowalter's eq. 6). Dratler & Schowalter's relative viscosity is
eta = 1 + 3 phi_a <S*_xy> + (interparticle terms), S* = S/(6 pi eta_m a^3 gamma_dot):
the particle stress of the layer is its stresslet (and virial) per unit area divided by
the layer thickness 2a, Sigma = (1/(2 a L^2)) sum (S - x F_P). So a monolayer's samples
use the volume 2 a L^2 (not L^2 Lz), and `sdmpi reduce` turns them into Dratler & Schowalter's eta,
eta_h (row ``hydrodynamic``) and eta_p (row ``interparticle``) unchanged, with the column
``phi`` holding phi_a. Dilute limit: S_xy = (10/3) pi a^3 eta_m gamma_dot per sphere gives
eta = 1 + (5/3) phi_a.

Overlaps (Dratler & Schowalter 1996 sec. 3; Bossis & Brady, J. Chem. Phys. 80, 5141 (1984)). Pairs closer
than the gap epsilon = ``hydrodynamics.min_gap``, overlapping ones included, get the
lubrication of that gap (`sdmpi.hydro.lubrication`) but are not moved (unlike the bulk's
potential-free correction); ``n_overlaps`` counts the overlapping pairs (periodic images
count once) and ``min_gap`` the deepest, at each step. When an overlap exceeds
``integration.overlap_stop`` (Dratler & Schowalter sec. 4: 2% of a radius) the realisation stops: it
warns, keeps its last configuration, and every later sample is NaN (counts -1), which
`sdmpi reduce` takes as the end of that realisation's data.

Repulsion (Dratler & Schowalter's eq. 9, `forces.Repulsion`): F(h) = F0 tau e^(-tau h)/(1 +
e^(-tau h)), gamma* = 6 pi eta_m a^2 gamma_dot / (2 F0). In the job's force unit
6 pi eta_m a^2 gamma_dot, ``interparticle.f0`` = 1/(2 gamma*) (Dratler & Schowalter's gamma* = 1 is
f0 = 0.5).

Units: lengths in a, times in the job's time unit (1/gamma_dot under steady shear, as
these jobs are non-Brownian).
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..hydro.lubrication import close_pairs
from .collisions import Collisions
from .initial import hard_disk_monolayer, square_side
from .recorders import StateFields
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
