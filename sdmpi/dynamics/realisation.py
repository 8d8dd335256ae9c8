"""One SD realisation: Brownian hard spheres in a sheared periodic box, stepped in time.

Overdamped Stokesian dynamics in configuration space (Schaink et al. 2000, eqs. 13, 32; Ito):

    dx = [U_inf(x) + R_FU^-1 (F_P + R_FE e_inf) + kT div R_FU^-1] dt
         + sqrt(2 kT dt) R_FU^-1/2 dW,

stepped by the integrator of integration.scheme (`integrators`, registered in
`sdmpi.registry.INTEGRATORS`) with the hydrodynamics of a model
(`models.hydrodynamic_model`: stokesian, far-field or free-draining) evaluated at the step's
start x_k; by default explicitly (Euler-Maruyama),

    x_{k+1} = x_k + (gamma(t_{k+1}) - gamma(t_k)) y e_x + dt U(x_k),

with the imposed flow's part of U, R_FU^-1 R_FE e_inf, taken at the step's mean rate
<gamma_dot> = (gamma(t_{k+1}) - gamma(t_k))/dt (`shear`), of which the affine displacement
is the exact integral. Both parts then belong to one flow: a pair whose relative velocity
along its line of centres is (1 - A) times the affine one (A -> 1 near contact) closes with
the step's own strain (with the start's rate gamma_dot(t_k) in the disturbance, it would be
driven like the rate of A/(2(1 - A)) steps later). A Brownian force F_B = sqrt(2 kT/dt) C z
with R_FU = C C^T and z ~ N(0, I), so <F_B F_B> = 2 kT R_FU / dt (fluctuation-dissipation),
and the drift kT div R_FU^-1 and the Brownian stresslet -kT div(R_SU R_FU^-1) (Schaink et
al. eq. 16) estimated by the model's drift scheme (`drift`: a random finite difference
along the noise's directions, or Fixman's midpoint as in Banchio & Brady, J. Chem. Phys.
118, 10323 (2003)).

Stresses (bulk, per volume V, 6-vectors xx yy zz xy xz yz, units eta_m/t_D = kT/(6 pi a^3);
the registry `config.stresses`): hydrodynamic (1/V) sum S_H with S_H = (R_SE - R_SU R_FU^-1
R_FE) e_inf; Brownian (1/V) sum S_B; interparticle -(1/V) sum (x F_P + R_SU R_FU^-1 F_P);
collision (`collisions`), the stress of the overlap correction's impulses. Maxwell media filter
S_H by their modes (`media`). Units: a = 1, eta_m = 1, D0 = kT/(6 pi eta_m a) = 1, so
kT = 6 pi and time is in t_D = a^2/D0; non-Brownian runs use the same code with kT = 0.

Size classes (`job.system.size_classes`): every particle has its own radius a_i (in units
of the largest, a = 1); the hydrodynamics, the overlap correction and the pair forces use
them, and a, kT = 6 pi and t_D keep their meaning (those of the largest spheres).

Hard spheres: lubrication keeps overlaps rare; pairs brought into contact by a finite step
are counted and corrected at the end of the step by the potential-free correction of
`collisions` (Schaink et al. 2000, sec. III, Bossis & Brady 1984): separated, or, with the
rule ``reflect``, separated after the step's deterministic part and reflected after its
Brownian part, both by contact impulses acting through the step's mobility R_FU^-1
(``hydrodynamics.collisions``, `collisions.default_rule`). An optional pair
repulsion (`forces.Repulsion`, Dratler & Schowalter 1996) adds F_P.

Frictional contacts (`contacts`, interparticle.kind = "frictional", non-Brownian): overlaps
are contacts, not corrected; their spring forces and torques join F_P (and its stress),
their stress is also sampled alone, and their tangential stretches are state.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..config.stresses import CONTRIBUTIONS
from ..hydro.basis import BASIS, to_five
from ..hydro.farfield import FarFieldIndefinite
from ..hydro.geometry import Lattice
from ..registry import INTEGRATORS
from .collisions import Collisions, default_rule, separate
from .contacts import contact_model
from .forces import force_law, pair_forces
from .initial import hard_sphere_fluid
from .integrators import Motion, Step
from .media import MaxwellFilter
from .models import hydrodynamic_model
from .monolayer import Monolayer
from .shear import NoShear, Oscillatory, Steady, rate_of_strain

if TYPE_CHECKING:
    from ..config.schema import Job
    from ..config.tasks import Task


class RealisationFailed(RuntimeError):
    """A realisation cannot go on (e.g. a hydrodynamic matrix not positive definite): the
    message names the task, the step, the cause and the job key to change."""


#: kT in sdmpi's reduced units (a = 1, eta_m = 1, D0 = 1)
KT_REDUCED = 6 * math.pi
#: stress component order of the 6-vectors
SIX_VECTOR_INDICES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


#: the 6-vector components (SIX_VECTOR_INDICES) of the basis tensors: (6, 5), BASIS[m][a, b]
_SIX_OF_FIVE = np.array([[BASIS[m, a, b] for m in range(5)] for a, b in SIX_VECTOR_INDICES])


def bulk_stress(tensors: np.ndarray, volume: float) -> np.ndarray:
    """(1/V) sum of (N, 5) 5-basis tensors, as a 6-vector xx yy zz xy xz yz.

    Args:
        tensors: per-particle tensors in the 5-basis, shape (N, 5) (e.g. eta_m a^3/t_D).
        volume: the normalising volume V, in a^3.

    Returns:
        The 6-vector, shape (6,), in the tensors' unit per a^3 (e.g. eta_m/t_D).
    """
    return _SIX_OF_FIVE @ tensors.sum(axis=0) / volume


def symmetric_six(matrix: np.ndarray) -> np.ndarray:
    """The symmetric part of a 3x3 matrix as a 6-vector xx yy zz xy xz yz.

    Args:
        matrix: shape (3, 3).

    Returns:
        Shape (6,), in the matrix's unit.
    """
    sym = 0.5 * (matrix + matrix.T)
    return np.array([sym[a, b] for a, b in SIX_VECTOR_INDICES])


def protocol_of(job: Job, task: Task) -> Oscillatory | Steady | NoShear:
    """The shear protocol of a task.

    Args:
        job: the validated job (shear.protocol and its parameters).
        task: the task (its omega for oscillatory shear, 1/t_D).

    Returns:
        The protocol: strain and rate as functions of time.
    """
    if job.shear.protocol == "oscillatory":
        return Oscillatory(job.shear.gamma0, task.omega)
    if job.shear.protocol == "steady":
        return Steady(job.shear.rate)
    return NoShear()


def sample_fields(job: Job) -> dict[str, tuple[tuple[int, ...], str, str, str]]:
    """name -> (shape per sample, dtype, unit, description) of a task's sample stream:
    the datasets under samples/ in docs/store.md (the same for every task of a job).

    Args:
        job: the validated job.

    Returns:
        The fields in stream order; shapes exclude the leading sample axis.
    """
    su = "eta_m/t_D" if job.time_unit == "t_D" else "eta_m gamma_dot"
    fields = {
        "time": ((), "f8", job.time_unit, "t_k = k dt"),
        "strain": ((), "f8", "1", "gamma(t_k)"),
        "rate": ((), "f8", "1/" + job.time_unit, "gamma_dot(t_k)"),
        **{c.dataset: ((6,), "f8", su, c.description) for c in CONTRIBUTIONS},
        "n_overlaps": ((), "i4", "1", "pairs in contact (gap below hydrodynamics.min_gap) before correction"),
        "n_overlaps_midpoint": ((), "i4", "1", "overlapping pairs corrected at the Brownian midpoint"),
        "min_gap": ((), "f8", "a", "smallest surface gap before correction"),
        "solver_iterations": ((), "i4", "1", "Krylov iterations of the step's solves (0: direct backend)"),
        "solver_residual": ((), "f8", "1", "largest relative residual of the step's iterative solves"),
        "lanczos_iterations": ((), "i4", "1", "Lanczos iterations of the step's Brownian forces"),
    }
    if job.interparticle.kind == "frictional":
        fields["stress_contact"] = ((6,), "f8", su, "contact springs' part of stress_interparticle")
        fields["n_contacts"] = ((), "i4", "1", "touching pairs (gap < 0)")
        fields["n_sliding"] = ((), "i4", "1", "touching pairs at the Coulomb limit")
    if job.medium.kind == "maxwell":
        fields["stress_hydrodynamic_maxwell"] = ((6,), "f8", su, "hydrodynamic stress filtered by the Maxwell modes")
    if job.output.per_particle:
        fields["stresslets"] = ((job.system.n_particles, 5), "f8", "eta_m a^3/t_D", "S_H in the 5-basis")
    return fields


class Realisation:
    """One task's SD realisation, a deterministic function of (job, task): its random
    stream is SeedSequence(job seed, spawn_key=(task_id,)). Produces one sample per step
    at the start of the step, t_k = k dt: the stresses of the configuration x_k at the
    rate gamma_dot(t_k), and the collision stress of the overlap correction that ends the
    step, which represents t_k + dt/2 (`config.stresses`, sample_offset); exposes its
    full state. Its positions are those of the step's start, corrected."""

    def __init__(self, job, task, comm=None):
        # comm: the MPI communicator of the ranks that step this realisation together
        # (ensemble.ranks_per_task > 1, PETSc backends; every rank builds and steps the
        # same realisation, the solves are collective); None: this rank alone
        self.job, self.task, self.comm = job, task, comm
        self.force_law = force_law(job)
        self.contacts = contact_model(job)
        seq = np.random.SeedSequence(job.job.seed, spawn_key=(task.task_id,))
        self.rng = np.random.Generator(np.random.PCG64(seq))
        n = job.system.n_particles
        self.protocol = protocol_of(job, task)
        # radii in a (the largest radius): all 1, or job.system.size_classes class by class
        self.radii = np.array(job.system.radii, dtype=float)
        # Dratler & Schowalter 1996 monolayers (sdmpi.dynamics.monolayer): their own box, start
        # and volume
        self.monolayer = Monolayer(job, task.phi) if job.system.geometry == "monolayer" else None
        if self.monolayer is None:
            pos, side = hard_sphere_fluid(n, task.phi, self.rng, strain=self.protocol.strain(0.0),
                                          radii=self.radii, sweeps=job.system.start_sweeps or 0)
            self.box = np.full(3, side)
        else:
            pos, self.box = self.monolayer.start(self.rng), self.monolayer.box
        self.n_particles = n
        self.volume = float(np.prod(self.box)) if self.monolayer is None else self.monolayer.volume
        self.positions = Lattice(self.box, self.protocol.strain(0.0)).wrap(pos)
        self.kT = KT_REDUCED if job.brownian.enabled else 0.0
        self.dt = task.dt
        self.n_steps = task.n_steps
        self.step = 0
        hyd = job.hydrodynamics
        self.collision_rule = hyd.collisions or default_rule(hyd.model)
        self._unchecked = True  # a start or a restored state: its overlaps not yet corrected
        self.model = hydrodynamic_model(job, self.radii, self.box, comm, separate=self._separate_midpoint,
                                        on_error=self._lost_definiteness)
        self.maxwell = None
        if job.medium.kind == "maxwell":
            modes = job.medium.modes
            self.maxwell = MaxwellFilter(tuple(m.eta for m in modes), tuple(m.lam for m in modes), self.dt)
            self.modes = np.zeros((len(modes), n, 5))
            self.source_prev = np.zeros((n, 5))
        # hydrodynamics.far_field_refresh: the far field held for this many steps (0: never held)
        refresh = hyd.far_field_refresh
        self.far_field_every = max(1, round(refresh / self.dt)) if refresh > 0 else 0
        self.far_field_positions = np.zeros((n, 3))  # the start of the last refresh
        motion = Motion(n, self.box, self.dt, self.protocol, self._separate if self._corrects_overlaps() else None,
                        self.collision_rule, self._velocity_at)
        self.integrator = INTEGRATORS[job.integration.scheme].load()(motion)

    # ------------------------------------------------------------------ interface

    def sample_fields(self) -> dict[str, tuple[tuple[int, ...], str, str, str]]:
        """name -> (shape per sample, dtype, unit, description) of the sample stream.

        Returns:
            The module function `sample_fields` of this realisation's job.
        """
        return sample_fields(self.job)

    def state_fields(self) -> dict[str, tuple[tuple[int, ...], str]]:
        """name -> (shape, dtype) of the state (fixed for the realisation).

        Returns:
            The state's fields, the integrator's included.
        """
        n = self.n_particles
        fields = {"positions": ((n, 3), "f8"), "step": ((1,), "i8"), "rng": ((6,), "u8")}
        if self.maxwell is not None:
            fields["modes"] = (self.modes.shape, "f8")
            fields["source_prev"] = ((n, 5), "f8")
        if self.contacts is not None:
            fields["contact_partners"] = (self.contacts.partners.shape, "i8")
            fields["contact_stretch"] = (self.contacts.stretch.shape, "f8")
        if self.monolayer is not None:
            fields["stopped_at"] = ((1,), "i8")
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
        if self.maxwell is not None:
            state["modes"] = self.modes.copy()
            state["source_prev"] = self.source_prev.copy()
        if self.contacts is not None:
            state["contact_partners"] = self.contacts.partners.copy()
            state["contact_stretch"] = self.contacts.stretch.copy()
        if self.monolayer is not None:
            state["stopped_at"] = np.array([self.monolayer.stopped_at], dtype=np.int64)
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
        if self.maxwell is not None:
            self.modes = np.array(state["modes"], dtype=float)
            self.source_prev = np.array(state["source_prev"], dtype=float)
        if self.contacts is not None:
            self.contacts.partners[:] = state["contact_partners"]
            self.contacts.stretch[:] = state["contact_stretch"]
        if self.monolayer is not None:
            self.monolayer.stopped_at = int(state["stopped_at"][0])
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
        fields = self.sample_fields()
        out = {k: np.empty((n, *shape), dtype=dt) for k, (shape, dt, _, _) in fields.items()}
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
                f"{self.job.ewald_tolerance:g} are too coarse for a box of side "
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
        return separate(positions, self.radii, Lattice(self.box, strain), self.job.hydrodynamics.min_gap,
                        reflect, mobility=mobility)

    def _separate_midpoint(self, positions, strain):
        positions, collisions = self._separate(positions, strain)
        return positions, collisions.n_overlaps

    def _corrects_overlaps(self):
        """Whether overlaps are corrected: not in monolayers (counted and kept, Dratler &
        Schowalter 1996) nor with frictional contacts (the springs' compression)."""
        return self.monolayer is None and self.contacts is None

    def _start(self, k, strain, lattice):
        """The step's start configuration and the Collisions of a start or restored state
        that needed a correction (steps leave theirs corrected)."""
        pos = lattice.wrap(self.positions)
        # Dratler & Schowalter 1996: overlaps counted and kept; a deep one stops the run
        if self.monolayer is not None:
            n_overlaps, overlap_gap = self.monolayer.overlaps(pos, self.radii, lattice)
            return pos, Collisions.none(n_overlaps, overlap_gap)
        if not self._corrects_overlaps() or not self._unchecked:
            return pos, Collisions.none()
        self._unchecked = False
        return self._separate(pos, strain)

    def _one_step(self):
        k = self.step
        t0, t1 = k * self.dt, (k + 1) * self.dt
        strain, rate = self.protocol.strain(t0), self.protocol.rate(t0)
        step_rate = self.integrator.disturbance_rate(t0, t1)
        pos, started = self._start(k, strain, Lattice(self.box, strain))
        if self.monolayer is not None and self.monolayer.stops(k, started.deepest, self.task.task_id):
            self.step += 1
            return self.monolayer.stopped_sample(self.sample_fields(), t0, strain, rate)
        if self.far_field_every and k % self.far_field_every == 0:
            self._hold_far_field(pos, k)
        at = self.model.at(pos, strain)
        n = self.n_particles
        e5 = _imposed_rate(n, rate)
        u_flow = at.velocities(np.zeros((n, 6)), e5)
        s_h = at.stresslets(u_flow, e5)
        contributions, contact_sample = self._forces(at)
        velocity, stress_p = self._with_forces(at, _at_step_rate(at, u_flow, rate, step_rate), contributions)
        stress_b, midpoint_overlaps, noise = np.zeros(6), 0, np.zeros((n, 6))
        if self.kT > 0:
            brownian = at.brownian(self.rng, self.kT, self.dt)
            noise = brownian.velocities
            stress_b = bulk_stress(brownian.stresslets, self.volume)
            midpoint_overlaps = brownian.midpoint_overlaps
        if self.contacts is not None:
            self.contacts.advance(velocity + noise, step_rate, self.dt)
        self.positions, moved = self.integrator.move(Step(k, pos, self._in_plane(velocity), self._in_plane(noise),
                                                          at))
        collisions = Collisions.joined(started, moved)
        sample = {"time": t0, "strain": strain, "rate": rate,
                  "stress_hydrodynamic": bulk_stress(s_h, self.volume),
                  "stress_brownian": stress_b, "stress_interparticle": stress_p,
                  "stress_collision": self._collision_stress(at, collisions),
                  "n_overlaps": collisions.n_overlaps, "n_overlaps_midpoint": midpoint_overlaps,
                  "min_gap": min(collisions.deepest, at.pairs.min_gap), **contact_sample, **at.stats()}
        if self.maxwell is not None:
            if k > 0:
                self.maxwell.update(self.modes, self.source_prev, s_h)
            self.source_prev = s_h.copy()
            sample["stress_hydrodynamic_maxwell"] = bulk_stress(self.modes.sum(axis=0), self.volume)
        if self.job.output.per_particle:
            sample["stresslets"] = s_h
        self.step += 1
        return sample

    def _hold_far_field(self, positions, k):
        """Evaluate the model with the far field of the start ``positions`` of step k until
        the next refresh (hydrodynamics.far_field_refresh, Dratler & Schowalter 1996)."""
        self.far_field_positions = positions.copy()
        self.model.hold_far_field(positions, self.protocol.strain(k * self.dt))

    def _pair_forces(self, at):
        """The pair forces of the force law on the evaluation's pairs: (forces (N, 6), virial
        sum x F (3, 3))."""
        forces, virial = pair_forces(self.force_law, at.pairs, self.n_particles, self.radii)
        return np.hstack([forces, np.zeros((self.n_particles, 3))]), virial

    def _forces(self, at):
        """The interparticle force contributions at the evaluation `at`, in order: a list of
        (forces and torques (N, 6), virial sum x F (3, 3)) (the force law's pair forces, then
        the frictional contacts'), and the contacts' own sample (empty without them)."""
        contributions = [self._pair_forces(at)]
        if self.contacts is None:
            return contributions, {}
        contact = self.contacts.forces(at.pairs, self.radii)
        f6 = np.hstack([contact.forces, contact.torques])
        u_c = at.velocities(f6, np.zeros((self.n_particles, 5)))
        contributions.append((f6, contact.virial))
        return contributions, {"stress_contact": self._force_stress(at, u_c, contact.virial),
                               "n_contacts": contact.n_contacts, "n_sliding": contact.n_sliding}

    def _with_forces(self, at, velocity, contributions):
        """The velocities (N, 6) plus those of the summed force contributions, and the
        interparticle stress of their sum (zero without a force law or contacts)."""
        if self.force_law is None and self.contacts is None:
            return velocity, np.zeros(6)
        forces, virial = contributions[0]
        for more_forces, more_virial in contributions[1:]:
            forces, virial = forces + more_forces, virial + more_virial
        u_force = at.velocities(forces, np.zeros((self.n_particles, 5)))
        return velocity + u_force, self._force_stress(at, u_force, virial)

    def _in_plane(self, velocity):
        """Monolayers: the velocities' in-plane part (`monolayer.Monolayer.in_plane`)."""
        return velocity if self.monolayer is None else self.monolayer.in_plane(velocity)

    def _collision_stress(self, at, collisions):
        """The stress of the contact impulses of the step's overlap corrections (`collisions`)."""
        if not len(collisions.i):
            return np.zeros(6)
        f_c, virial_c = collisions.forces(at.relative_mobility, self.dt, self.n_particles)
        return self._force_stress(at, at.velocities(f_c, np.zeros((self.n_particles, 5))), virial_c)

    def _velocity_at(self, positions, t):
        """The deterministic velocities (N, 6) relative to the imposed flow at (positions, t):
        the model at strain(t), the disturbance of the rate gamma_dot(t) plus the velocities
        of the force law's pair forces, in the plane of a monolayer (the velocity field of a
        multistep integrator's start-up, `integrators.AdamsBashforth4`; frictional contacts,
        whose springs are state, do not enter it)."""
        at = self.model.at(positions, self.protocol.strain(t))
        n = self.n_particles
        e5 = _imposed_rate(n, self.protocol.rate(t))
        velocity = at.velocities(np.zeros((n, 6)), e5)
        if self.force_law is not None:
            velocity = velocity + at.velocities(self._pair_forces(at)[0], np.zeros((n, 5)))
        return self._in_plane(velocity)

    def _force_stress(self, at, velocities, virial):
        """Stress of forces that drive these velocities with this virial sum x F:
        -(1/V) (sum R_SU R_FU^-1 F + sum x F)."""
        n = self.n_particles
        return bulk_stress(at.stresslets(velocities, np.zeros((n, 5))), self.volume) \
            - symmetric_six(virial) / self.volume


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
