"""One SD realisation: Brownian spheres in a sheared periodic box, stepped in time.

Overdamped Stokesian dynamics in configuration space (Schaink et al., J. Rheol. 44 (2000),
eqs. 13, 32; Ito):

    dx = [U_inf(x) + R_FU^-1 (F_P + R_FE e_inf) + kT div R_FU^-1] dt
         + sqrt(2 kT dt) R_FU^-1/2 dW.

A realisation is built from the components of `setup.build` (the only reader of the job):
a geometry (`systems.Bulk`, `monolayer.Monolayer`), a list of interparticle forces
(`forces.Force`), a list of hydrodynamic-stress recorders (`recorders.StressRecorder`:
Maxwell modes, per-particle stresslets), a hydrodynamic model (`models`) and an integrator
(`integrators`). Each step, at the start x_k of t_k = k dt:

1. the model is evaluated at x_k; the imposed flow's velocities R_FU^-1 R_FE e_inf, at the
   integrator's rate (the step's mean rate for Euler-Maruyama, `shear`), and its
   stresslets S_H = (R_SE - R_SU R_FU^-1 R_FE) e_inf at gamma_dot(t_k);
2. the forces' terms on the model's pairs are summed in order, F_P, and their velocities
   R_FU^-1 F_P added; each force samples its own fields;
3. with kT > 0 the model's Brownian velocities (drift included) and stresslets
   (`drift`; Banchio & Brady, J. Chem. Phys. 118, 10323 (2003));
4. the forces advance their state (the contacts' springs), the integrator moves the
   spheres (in the geometry's plane) and corrects overlaps (`collisions`) unless the
   geometry keeps them;
5. the sample: stresses (bulk, per volume V, 6-vectors xx yy zz xy xz yz; the registry
   `sdmpi.config.stresses`): hydrodynamic (1/V) sum S_H, Brownian (1/V) sum S_B,
   interparticle -(1/V) sum (x F_P + R_SU R_FU^-1 F_P), collision (`collisions`), then the
   forces' and the recorders' own fields.

Why the step's mean rate, and each stream's sample time: docs/physics.md, "Dynamics".

Units: a = 1 (the largest radius), eta_m = 1, D0 = kT/(6 pi eta_m a) = 1, so kT = 6 pi and
time is in t_D = a^2/D0; stresses in eta_m/t_D = kT/(6 pi a^3); non-Brownian runs use the
same code with kT = 0 (time unit 1/gamma_dot under steady shear).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..hydro.basis import to_five
from ..hydro.farfield import FarFieldIndefinite
from ..hydro.geometry import Lattice
from .collisions import Collisions, separate
from .forces import ForceTerms
from .integrators import Motion, Step
from .recorders import bulk_stress, symmetric_six
from .setup import KT_REDUCED, build
from .shear import rate_of_strain

if TYPE_CHECKING:
    from ..config.schema import Job
    from ..config.tasks import Task

__all__ = ["KT_REDUCED", "Realisation", "RealisationFailed"]


class RealisationFailed(RuntimeError):
    """A realisation cannot go on (e.g. a hydrodynamic matrix not positive definite): the
    message names the task, the step, the cause and the job key to change."""


class Realisation:
    """One task's SD realisation, a deterministic function of (job, task): its random
    stream is SeedSequence(job seed, spawn_key=(task_id,)). Produces one sample per step
    at the start of the step, t_k = k dt: the stresses of the configuration x_k at the
    rate gamma_dot(t_k), and the collision stress of the overlap correction that ends the
    step, which represents t_k + dt/2 (`config.stresses`, sample_offset); exposes its
    full state. Its positions are those of the step's start, corrected. Its components
    (geometry, forces, stress recorders, model, integrator) come from `setup.build`.

    Args:
        job: the validated job.
        task: the task.
        comm: the MPI communicator of the ranks that step this realisation together
            (ensemble.ranks_per_task > 1, PETSc backends; every rank builds and steps the
            same realisation, the solves are collective); None: this rank alone.
    """

    def __init__(self, job: Job, task: Task, comm: Any = None):
        self.job, self.task, self.comm = job, task, comm
        setup = build(job, task)
        self.fields = setup.sample_fields
        self.rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(setup.seed,
                                                                              spawn_key=(setup.task_id,))))
        self.protocol, self.radii, self.n_particles = setup.protocol, setup.radii, len(setup.radii)
        self.geometry, self.forces, self.recorders = setup.geometry, setup.forces, setup.recorders
        pos = self.geometry.start(self.rng, self.protocol.strain(0.0))
        self.box, self.volume = self.geometry.box, self.geometry.volume
        self.positions = Lattice(self.box, self.protocol.strain(0.0)).wrap(pos)
        self.kT, self.dt, self.n_steps, self.step = setup.kT, setup.dt, setup.n_steps, 0
        self.min_gap, self.collision_rule = setup.min_gap, setup.collision_rule
        self._unchecked = True  # a start or a restored state: its overlaps not yet corrected
        model, self.hydrodynamics = setup.hydrodynamics
        self.model = model.build(self.hydrodynamics, self.radii, self.box, comm, separate=self._separate_midpoint,
                                 on_error=self._lost_definiteness)
        # hydrodynamics.far_field_refresh: the far field held for this many steps (0: never held)
        self.far_field_every = setup.far_field_every
        self.far_field_positions = np.zeros((self.n_particles, 3))  # the start of the last refresh
        correct = self._separate if self.geometry.corrects_overlaps else None
        motion = Motion(self.n_particles, self.box, self.dt, self.protocol, correct, self.collision_rule,
                        self._velocity_at)
        self.integrator = setup.integrator(motion)

    # ------------------------------------------------------------------ interface

    def sample_fields(self) -> dict[str, tuple[tuple[int, ...], str, str, str]]:
        """name -> (shape per sample, dtype, unit, description) of the sample stream.

        Returns:
            `setup.sample_fields` of this realisation's job (a copy).
        """
        return dict(self.fields)

    def _components(self):
        """The components with state of their own, in state order."""
        return (*self.recorders, *self.forces, self.geometry)

    def state_fields(self) -> dict[str, tuple[tuple[int, ...], str]]:
        """name -> (shape, dtype) of the state (fixed for the realisation).

        Returns:
            The state's fields, the components' and the integrator's included.
        """
        n = self.n_particles
        fields = {"positions": ((n, 3), "f8"), "step": ((1,), "i8"), "rng": ((6,), "u8")}
        for part in self._components():
            fields.update(part.state_fields())
        if self.far_field_every:
            fields["far_field_positions"] = ((n, 3), "f8")
        return {**fields, **self.integrator.state_fields()}

    def get_state(self) -> dict[str, np.ndarray]:
        """The full state as arrays (see state_fields).

        Returns:
            name -> array (copies), shapes and dtypes of state_fields; positions in a.
        """
        state = {"positions": self.positions.copy(), "step": np.array([self.step], dtype=np.int64),
                 "rng": _encode_rng(self.rng)}
        for part in self._components():
            state.update(part.get_state())
        if self.far_field_every:
            state["far_field_positions"] = self.far_field_positions.copy()
        return {**state, **self.integrator.get_state()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state from get_state().

        Args:
            state: name -> array, as returned by get_state (or read back from the store).
        """
        self.positions = np.array(state["positions"], dtype=float)
        self.step = int(state["step"][0])
        self._unchecked = True
        _decode_rng(self.rng, state["rng"])
        for part in self._components():
            part.set_state(state)
        self.integrator.set_state(state)
        if self.far_field_every and self.step % self.far_field_every:
            self._hold_far_field(np.array(state["far_field_positions"], dtype=float),
                                 self.step - self.step % self.far_field_every)

    def advance(self, n: int) -> dict[str, np.ndarray]:
        """The next n samples (dict of arrays with leading axis n); steps n times.

        Args:
            n: samples wanted; fewer are produced when fewer steps are left.

        Returns:
            name -> array of shape (n', *shape) for each of sample_fields, n' = min(n,
            steps left), in the units of sample_fields.
        """
        n = min(n, self.n_steps - self.step)
        out = {k: np.empty((n, *shape), dtype=dt) for k, (shape, dt, _, _) in self.fields.items()}
        for s in range(n):
            for key, value in self._one_step().items():
                out[key][s] = value
        return out

    # ------------------------------------------------------------------ physics

    def _lost_definiteness(self, err):
        """The RealisationFailed of a hydrodynamic matrix that is not positive definite
        (LinAlgError err): the far-field mobility (Ewald sums too coarse for the box or the
        radii) or R_FU (a configuration the time step drove too far)."""
        where = f"task {self.task.task_id}, step {self.step}: "
        if isinstance(err, FarFieldIndefinite):
            lo, hi = float(np.min(self.radii)), float(np.max(self.radii))
            radii = "" if lo == hi else f" and radii from {lo:.3g} to {hi:.3g}"
            return RealisationFailed(
                f"{where}{err}: its Ewald sums at hydrodynamics.ewald_tolerance = "
                f"{self.hydrodynamics.ewald_tolerance:g} are too coarse for a box of side "
                f"{float(np.min(self.box)):.3g}{radii} - set a smaller hydrodynamics.ewald_tolerance "
                "(1e-6 is the deterministic jobs' default)")
        if self.kT > 0:
            advice = (f"a time step of {self.dt:.3g} moves spheres by ~{math.sqrt(2 * self.dt):.2g} "
                      "radii per step (Brownian) - use a smaller time step (Schaink et al. 2000 "
                      "used 5e-5 <= dt <= 5e-4 t_D)")
        else:
            advice = f"the time step of {self.dt:.3g} moved the spheres too far - use a smaller one"
        return RealisationFailed(f"{where}the hydrodynamic matrices lost positive definiteness "
                                 f"({err}); {advice}")

    def _separate(self, positions, strain, reflect=False, mobility=None):
        """Pairs in contact separated, or reflected, symmetrically or through the mobility
        (`collisions.separate`): (positions, Collisions)."""
        return separate(positions, self.radii, Lattice(self.box, strain), self.min_gap, reflect, mobility=mobility)

    def _separate_midpoint(self, positions, strain):
        positions, collisions = self._separate(positions, strain)
        return positions, collisions.n_overlaps

    def _start(self, strain, lattice):
        """The step's start configuration and the Collisions of a start or restored state
        that needed a correction (steps leave theirs corrected), or of the overlaps the
        geometry keeps (monolayers: counted, Dratler & Schowalter 1996)."""
        pos = lattice.wrap(self.positions)
        if not self.geometry.corrects_overlaps or not self._unchecked:
            return pos, self.geometry.kept_overlaps(pos, self.radii, lattice)
        self._unchecked = False
        return self._separate(pos, strain)

    def _one_step(self):
        k = self.step
        t0, t1 = k * self.dt, (k + 1) * self.dt
        strain, rate = self.protocol.strain(t0), self.protocol.rate(t0)
        step_rate = self.integrator.disturbance_rate(t0, t1)
        pos, started = self._start(strain, Lattice(self.box, strain))
        if self.geometry.stops(k, started.deepest, self.task.task_id):
            self.step += 1
            return self.geometry.stopped_sample(self.fields, t0, strain, rate)
        if self.far_field_every and k % self.far_field_every == 0:
            self._hold_far_field(pos, k)
        at = self.model.at(pos, strain)
        n = self.n_particles
        e5 = _imposed_rate(n, rate)
        u_flow = at.velocities(np.zeros((n, 6)), e5)
        s_h = at.stresslets(u_flow, e5)
        terms, force_sample = self._forces(at)
        velocity, stress_p = self._with_forces(at, _at_step_rate(at, u_flow, rate, step_rate), terms)
        stress_b, midpoint_overlaps, noise = np.zeros(6), 0, np.zeros((n, 6))
        if self.kT > 0:
            brownian = at.brownian(self.rng, self.kT, self.dt)
            noise = brownian.velocities
            stress_b = bulk_stress(brownian.stresslets, self.volume)
            midpoint_overlaps = brownian.midpoint_overlaps
        for force in self.forces:
            force.advance(velocity + noise, step_rate, self.dt)
        in_plane = self.geometry.in_plane
        self.positions, moved = self.integrator.move(Step(k, pos, in_plane(velocity), in_plane(noise), at))
        collisions = Collisions.joined(started, moved)
        sample = {"time": t0, "strain": strain, "rate": rate,
                  "stress_hydrodynamic": bulk_stress(s_h, self.volume),
                  "stress_brownian": stress_b, "stress_interparticle": stress_p,
                  "stress_collision": self._collision_stress(at, collisions),
                  "n_overlaps": collisions.n_overlaps, "n_overlaps_midpoint": midpoint_overlaps,
                  "min_gap": min(collisions.deepest, at.pairs.min_gap), **force_sample, **at.stats()}
        for recorder in self.recorders:
            sample.update(recorder.sample(k, s_h, self.volume))
        self.step += 1
        return sample

    def _hold_far_field(self, positions, k):
        """Evaluate the model with the far field of the start ``positions`` of step k until
        the next refresh (hydrodynamics.far_field_refresh, Dratler & Schowalter 1996)."""
        self.far_field_positions = positions.copy()
        self.model.hold_far_field(positions, self.protocol.strain(k * self.dt))

    def _forces(self, at):
        """Each force's `ForceTerms` on the evaluation's pairs, in order, and the forces' own
        samples (a force's own stress costs one solve: `Force.sample`)."""
        terms, sample = [], {}
        for force in self.forces:
            terms.append(force.terms(at.pairs))
            sample.update(force.sample(terms[-1], lambda t: self._terms_stress(at, t)))
        return terms, sample

    def _terms_stress(self, at, terms):
        """The stress of one force's terms, through their own velocities."""
        u = at.velocities(terms.forces, np.zeros((self.n_particles, 5)))
        return self._force_stress(at, u, terms.virial)

    def _with_forces(self, at, velocity, terms):
        """The velocities (N, 6) plus those of the summed forces' terms (in order), and the
        interparticle stress of their sum (zero without forces)."""
        if not terms:
            return velocity, np.zeros(6)
        forces, virial = _summed(terms)
        u_force = at.velocities(forces, np.zeros((self.n_particles, 5)))
        return velocity + u_force, self._force_stress(at, u_force, virial)

    def _collision_stress(self, at, collisions):
        """The stress of the contact impulses of the step's overlap corrections (`collisions`)."""
        if not len(collisions.i):
            return np.zeros(6)
        f_c, virial_c = collisions.forces(at.relative_mobility, self.dt, self.n_particles)
        return self._force_stress(at, at.velocities(f_c, np.zeros((self.n_particles, 5))), virial_c)

    def _velocity_at(self, positions, t):
        """The deterministic velocities (N, 6) relative to the imposed flow at (positions, t):
        the model at strain(t), the disturbance of the rate gamma_dot(t) plus the velocities
        of the forces, in the geometry's plane (the velocity field of a multistep
        integrator's start-up, `integrators.AdamsBashforth4`, which the job checks refuse
        forces with contacts, whose history is state)."""
        at = self.model.at(positions, self.protocol.strain(t))
        n = self.n_particles
        e5 = _imposed_rate(n, self.protocol.rate(t))
        velocity = at.velocities(np.zeros((n, 6)), e5)
        if self.forces:
            forces, _ = _summed([force.terms(at.pairs) for force in self.forces])
            velocity = velocity + at.velocities(forces, np.zeros((n, 5)))
        return self.geometry.in_plane(velocity)

    def _force_stress(self, at, velocities, virial):
        """Stress of forces that drive these velocities with this virial sum x F:
        -(1/V) (sum R_SU R_FU^-1 F + sum x F)."""
        n = self.n_particles
        return bulk_stress(at.stresslets(velocities, np.zeros((n, 5))), self.volume) \
            - symmetric_six(virial) / self.volume


def _summed(terms: list[ForceTerms]) -> tuple[np.ndarray, np.ndarray]:
    """The forces (N, 6) and virial (3, 3) of a list of force terms, summed in order."""
    forces, virial = terms[0].forces, terms[0].virial
    for more in terms[1:]:
        forces, virial = forces + more.forces, virial + more.virial
    return forces, virial


def _at_step_rate(at, u_flow, rate, step_rate):
    """The disturbance velocities R_FU^-1 R_FE e_inf of the step's mean rate
    <gamma_dot> = (gamma(t1) - gamma(t0))/dt (`shear`) from those of the start's rate
    gamma_dot(t0): they are linear in e_inf, so u(<gamma_dot>) = (<gamma_dot>/gamma_dot(t0))
    u(gamma_dot(t0)); one more solve only where gamma_dot(t0) = 0 exactly. Unchanged (the
    same array) where the two rates are equal (steady shear, no shear)."""
    if step_rate == rate:
        return u_flow
    if rate != 0.0:
        return (step_rate / rate) * u_flow
    n = len(u_flow)
    return at.velocities(np.zeros((n, 6)), _imposed_rate(n, step_rate))


def _imposed_rate(n, rate):
    """E_inf of simple shear at shear rate ``rate`` for each of n spheres, (n, 5) in the
    5-basis (a read-only broadcast)."""
    return np.broadcast_to(to_five(rate_of_strain(rate)), (n, 5))


def _encode_rng(rng):
    """PCG64 state -> 6 uint64: state (hi, lo), inc (hi, lo), has_uint32, uinteger."""
    st = rng.bit_generator.state
    mask = (1 << 64) - 1
    s, inc = st["state"]["state"], st["state"]["inc"]
    return np.array([s >> 64, s & mask, inc >> 64, inc & mask, st["has_uint32"], st["uinteger"]],
                    dtype=np.uint64)


def _decode_rng(rng, arr):
    arr = [int(x) for x in arr]
    rng.bit_generator.state = {"bit_generator": "PCG64",
                               "state": {"state": (arr[0] << 64) | arr[1], "inc": (arr[2] << 64) | arr[3]},
                               "has_uint32": arr[4], "uinteger": arr[5]}
