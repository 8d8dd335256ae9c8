"""Time integrators: a step's update of the positions from the step's velocities.

An integrator (``integration.scheme``, registered in `sdmpi.registry.INTEGRATORS`) is built
from a `Motion` (what it needs of the realisation: box, time step, shear protocol, the
overlap correction, the deterministic velocity field) and moves a realisation by one
`Step`: the start configuration x_k at t_k = k dt, its model evaluation, the deterministic
velocities U'_k (N, 6) relative to the imposed flow (R_FU^-1 (F_P + R_FE e_inf)) and the
Brownian ones. Its own state (a multistep method's history) is part of the realisation's
state, so that a resumed run steps on bit for bit.

* `EulerMaruyama` (``euler-maruyama``): x_{k+1} = x_k + (gamma(t_{k+1}) - gamma(t_k)) y_k e_x
  + dt (U'_k + U_B), with U'_k's imposed-flow part taken at the step's mean rate
  (docs/physics.md, "Dynamics"), then the overlap correction (`collisions`).
* `AdamsBashforth4` (``adams-bashforth-4``): the fourth-order Adams-Bashforth method for
  non-Brownian motion (Dratler & Schowalter, J. Fluid Mech. 325, 53 (1996), who cite Conte &
  de Boor, Elementary Numerical Analysis (1980)), started by three classical Runge-Kutta
  steps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..hydro.geometry import Lattice
from .collisions import Collisions
from .shear import affine_displacement

#: Adams-Bashforth weights (times 24) of f_k, f_{k-1}, f_{k-2}, f_{k-3}
AB4_WEIGHTS = (55.0, -59.0, 37.0, -9.0)
#: steps of the start-up before the Adams-Bashforth history is full
AB4_HISTORY = 3


@dataclass(frozen=True)
class Motion:
    """What an integrator needs of its realisation.

    Attributes:
        n_particles: N.
        box: (3,) the periodic box (a); Lees-Edwards in y.
        dt: the time step.
        protocol: the shear protocol (`shear`): strain(t), rate(t), mean_rate(t0, t1).
        correct: correct(positions, strain, reflect=False, mobility=None) ->
            (positions, Collisions), the overlap correction (`collisions.separate`); None
            where overlaps are kept (monolayers, frictional contacts).
        collision_rule: hydrodynamics.collisions, "separate" or "reflect".
        velocity: velocity(positions, t) -> (N, 6), the deterministic velocities U'
            relative to the imposed flow at (positions, t), at the rate gamma_dot(t) (an
            evaluation of the model and the interparticle forces).
    """

    n_particles: int
    box: np.ndarray
    dt: float
    protocol: Any
    correct: Callable | None
    collision_rule: str
    velocity: Callable[[np.ndarray, float], np.ndarray]


@dataclass(frozen=True)
class Step:
    """One step's input to an integrator.

    Attributes:
        k: the step's index (t_k = k dt).
        positions: (N, 3) the start x_k, wrapped into the box at strain(t_k), corrected.
        velocity: (N, 6) deterministic velocities relative to the imposed flow, at the rate
            `Integrator.disturbance_rate`.
        noise: (N, 6) Brownian velocities, drift included (zero without Brownian motion).
        evaluation: the model at x_k (its mobility serves the collision rule reflect).
    """

    k: int
    positions: np.ndarray
    velocity: np.ndarray
    noise: np.ndarray
    evaluation: Any


class Integrator(Protocol):
    """A time integrator, registered in `sdmpi.registry.INTEGRATORS` (docs/extending.md);
    built as ``cls(motion)``."""

    def disturbance_rate(self, t0: float, t1: float) -> float:
        """The shear rate at which a step from t0 to t1 wants the imposed flow's part
        R_FU^-1 R_FE e_inf of `Step.velocity`."""
        raise NotImplementedError

    def move(self, step: Step) -> tuple[np.ndarray, Collisions]:
        """The positions at t_{k+1} (N, 3), wrapped into the box at strain(t_{k+1}), and the
        Collisions of their overlap correction."""
        raise NotImplementedError

    def state_fields(self) -> dict[str, tuple[tuple[int, ...], str]]:
        """name -> (shape, dtype) of the integrator's state (may be empty)."""
        raise NotImplementedError

    def get_state(self) -> dict[str, np.ndarray]:
        """The state (see state_fields)."""
        raise NotImplementedError

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state from get_state() (state may hold other fields too)."""
        raise NotImplementedError


class EulerMaruyama:
    """Explicit Euler-Maruyama, the model evaluated once per step at its start:

        x_{k+1} = x_k + (gamma(t_{k+1}) - gamma(t_k)) y_k e_x + dt (U'_k + U_B),

    U'_k at the step's mean rate <gamma_dot> = (gamma(t_{k+1}) - gamma(t_k))/dt, of which
    the affine displacement is the exact integral, then the overlap correction: separate,
    or (collision rule reflect) separate after the deterministic part and reflect after
    the Brownian part, both through the step's mobility R_FU^-1 (`collisions`). No state."""

    def __init__(self, motion: Motion):
        self.motion = motion

    def disturbance_rate(self, t0: float, t1: float) -> float:
        return self.motion.protocol.mean_rate(t0, t1)

    def move(self, step: Step) -> tuple[np.ndarray, Collisions]:
        motion = self.motion
        pos, drift, noise, dt = step.positions, step.velocity, step.noise, motion.dt
        strain, strain1 = motion.protocol.strain(step.k * dt), motion.protocol.strain((step.k + 1) * dt)
        affine = affine_displacement(pos, strain, strain1)
        lattice = Lattice(motion.box, strain1)
        if motion.correct is None:
            return lattice.wrap(pos + dt * (drift + noise)[:, :3] + affine), Collisions.none()
        if motion.collision_rule == "separate":
            return motion.correct(lattice.wrap(pos + dt * (drift + noise)[:, :3] + affine), strain1)
        zero = np.zeros((len(pos), 5))

        def mobility(forces):
            return step.evaluation.velocities(forces, zero)

        moved, first = motion.correct(lattice.wrap(pos + dt * drift[:, :3] + affine), strain1, mobility=mobility)
        moved, second = motion.correct(lattice.wrap(moved + dt * noise[:, :3]), strain1, reflect=True,
                                       mobility=mobility)
        return moved, Collisions.joined(first, second)

    def state_fields(self) -> dict[str, tuple[tuple[int, ...], str]]:
        return {}

    def get_state(self) -> dict[str, np.ndarray]:
        return {}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        pass


class AdamsBashforth4:
    """Fourth-order Adams-Bashforth for deterministic motion dx/dt = gamma_dot(t) y e_x + U'(x, t).

    The imposed flow's displacement of the start's heights is integrated exactly, the rest
    by AB4: with y_k the heights at t_k,

        x_{k+1} = x_k + (gamma(t_{k+1}) - gamma(t_k)) y_k e_x
                  + (dt/24) (55 g_k - 59 g_{k-1} + 37 g_{k-2} - 9 g_{k-3}),
        g_j = U'_j + gamma_dot(t_j) (y_j - y_k) e_x,

    where U'_j (the disturbance velocities plus those of the interparticle forces, at the
    rate gamma_dot(t_j)) is periodic under Lees-Edwards images and y_j - y_k is a height
    difference of the same sphere taken to its nearest image in y. Splitting the velocity
    this way is exact (gamma_dot(t) y(t) = gamma_dot(t) y_k + gamma_dot(t) (y(t) - y_k)),
    and neither part sees the wrapping: the total velocity of a sphere jumps by
    gamma_dot L_y when it is wrapped through the Lees-Edwards boundary, and AB4 applied to
    it would need unwrapped trajectories; the disturbance alone with the affine part
    integrated exactly at fixed y_k would drop the shear advection of the step's own
    motion in y (an O(dt^2) error per step). g is smooth wherever U' is, so the step's
    local error is O(dt^5) and the global error O(dt^4).

    The first AB4_HISTORY steps (k < 3) are classical Runge-Kutta steps of the same split,

        x_{k+1} = x_k + (gamma(t_{k+1}) - gamma(t_k)) y_k e_x + (dt/6)(g1 + 2 g2 + 2 g3 + g4),

    with the stages at t_k, t_k + dt/2 (twice) and t_k + dt at positions
    x_k + (gamma(t_s) - gamma(t_k)) y_k e_x + c dt g_{s-1} (three more evaluations of the
    model per step; local error O(dt^5) too). Then the overlap correction, as
    `EulerMaruyama`'s rule separate. State: g's ingredients of the last three steps, U'_j
    (3, N, 3) and y_j (3, N), newest first; gamma_dot(t_j) follows from j.
    """

    def __init__(self, motion: Motion):
        self.motion = motion
        self.history_velocities = np.zeros((AB4_HISTORY, motion.n_particles, 3))
        self.history_heights = np.zeros((AB4_HISTORY, motion.n_particles))

    def disturbance_rate(self, t0: float, t1: float) -> float:
        return self.motion.protocol.rate(t0)

    def state_fields(self) -> dict[str, tuple[tuple[int, ...], str]]:
        return {"ab4_velocities": (self.history_velocities.shape, "f8"),
                "ab4_heights": (self.history_heights.shape, "f8")}

    def get_state(self) -> dict[str, np.ndarray]:
        return {"ab4_velocities": self.history_velocities.copy(), "ab4_heights": self.history_heights.copy()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        self.history_velocities = np.array(state["ab4_velocities"], dtype=float)
        self.history_heights = np.array(state["ab4_heights"], dtype=float)

    def _relative_heights(self, heights, y0):
        """heights - y0, each to its nearest image in y (box side L_y)."""
        side = self.motion.box[1]
        d = heights - y0
        return d - side * np.round(d / side)

    def _g(self, velocity, t, dy):
        """g = U' + gamma_dot(t) dy e_x (N, 3) for velocities U' (N, 6) and heights dy
        relative to the step's start."""
        g = velocity[:, :3].copy()
        g[:, 0] += self.motion.protocol.rate(t) * dy
        return g

    def _runge_kutta(self, step):
        """(dt/6)(g1 + 2 g2 + 2 g3 + g4) of the start-up."""
        motion, pos = self.motion, step.positions
        dt, t0 = motion.dt, step.k * motion.dt
        protocol, y0 = motion.protocol, pos[:, 1]
        g = self._g(step.velocity, t0, 0.0)
        total = g.copy()
        for c, weight in ((0.5, 2.0), (0.5, 2.0), (1.0, 1.0)):
            t = t0 + c * dt
            x = pos + affine_displacement(pos, protocol.strain(t0), protocol.strain(t)) + c * dt * g
            g = self._g(motion.velocity(x, t), t, x[:, 1] - y0)
            total += weight * g
        return (dt / 6.0) * total

    def _adams_bashforth(self, step):
        """(dt/24)(55 g_k - 59 g_{k-1} + 37 g_{k-2} - 9 g_{k-3})."""
        dt, y0 = self.motion.dt, step.positions[:, 1]
        total = AB4_WEIGHTS[0] * self._g(step.velocity, step.k * dt, 0.0)
        for back, weight in enumerate(AB4_WEIGHTS[1:]):
            t = (step.k - 1 - back) * dt
            dy = self._relative_heights(self.history_heights[back], y0)
            total += weight * self._g(self.history_velocities[back], t, dy)
        return (dt / 24.0) * total

    def move(self, step: Step) -> tuple[np.ndarray, Collisions]:
        motion, pos = self.motion, step.positions
        dt = motion.dt
        strain, strain1 = motion.protocol.strain(step.k * dt), motion.protocol.strain((step.k + 1) * dt)
        increment = self._runge_kutta(step) if step.k < AB4_HISTORY else self._adams_bashforth(step)
        self._remember(step)
        moved = Lattice(motion.box, strain1).wrap(pos + affine_displacement(pos, strain, strain1) + increment)
        if motion.correct is None:
            return moved, Collisions.none()
        return motion.correct(moved, strain1)

    def _remember(self, step):
        """Push U'_k and y_k onto the history (newest first)."""
        self.history_velocities = np.roll(self.history_velocities, 1, axis=0)
        self.history_heights = np.roll(self.history_heights, 1, axis=0)
        self.history_velocities[0] = step.velocity[:, :3]
        self.history_heights[0] = step.positions[:, 1]
