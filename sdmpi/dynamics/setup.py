"""The factory from (job, task) to a realisation's components, with explicit parameters:
the only reader of the `sdmpi.config.Job` in `sdmpi.dynamics`.

A realisation (`realisation.Realisation`) is built from a `Setup`: its shear protocol,
geometry (`systems.Bulk` or `monolayer.Monolayer`), the list of its interparticle forces
(`forces.Force`, by interparticle.kind from `sdmpi.registry.FORCES`), the list of its
hydrodynamic-stress recorders (`recorders.StressRecorder`: a Maxwell medium's modes,
`media.MaxwellStress`; output.per_particle's stresslets), its integrator class
(`sdmpi.registry.INTEGRATORS`) and the setting of its hydrodynamic model
(`models.HydrodynamicSetting`, `sdmpi.registry.HYDRODYNAMIC_MODELS`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..config.stresses import CONTRIBUTIONS
from ..registry import FORCES, HYDRODYNAMIC_MODELS, INTEGRATORS, NO_FORCE, backend_for
from .collisions import default_rule
from .component import SampleFields
from .forces import Force, ForceSetting
from .media import MaxwellStress
from .models import HydrodynamicModel, HydrodynamicSetting
from .monolayer import Monolayer
from .recorders import PerParticleStresslets, StressRecorder
from .shear import NoShear, Oscillatory, Steady
from .systems import Bulk, Geometry

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..config.schema import Job
    from ..config.tasks import Task

#: kT in sdmpi's reduced units (a = 1, eta_m = 1, D0 = 1)
KT_REDUCED = 6 * math.pi


@dataclass
class Setup:
    """A realisation's components and parameters (`build`).

    Attributes:
        seed: the job's seed (its random stream: SeedSequence(seed, spawn_key=(task_id,))).
        task_id: the task's id.
        radii: (N,) sphere radii, in a (the largest radius).
        protocol: the shear protocol (strain(t), rate(t)).
        geometry: bulk or monolayer (box, start, volume, overlap rule).
        forces: the interparticle forces, summed in this order.
        recorders: the components that sample the hydrodynamic stresslets, in this order.
        kT: thermal energy (KT_REDUCED, or 0 without Brownian motion).
        dt: the time step (time unit).
        n_steps: the task's steps.
        min_gap: hydrodynamics.min_gap, the hard-sphere surface of the overlap correction.
        collision_rule: "separate" or "reflect" (hydrodynamics.collisions or the model's default).
        far_field_every: steps a far field is held (hydrodynamics.far_field_refresh; 0: never).
        hydrodynamics: the model's class (`HydrodynamicModel`) and its setting.
        integrator: the integrator's class (`sdmpi.dynamics.integrators.Integrator`).
        sample_fields: the sample stream's fields (`sample_fields`).
    """

    seed: int
    task_id: int
    radii: np.ndarray
    protocol: Oscillatory | Steady | NoShear
    geometry: Geometry
    forces: list[Force]
    recorders: list[StressRecorder]
    kT: float
    dt: float
    n_steps: int
    min_gap: float
    collision_rule: str
    far_field_every: int
    hydrodynamics: tuple[type[HydrodynamicModel], HydrodynamicSetting]
    integrator: type
    sample_fields: SampleFields


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


def forces_of(job: Job) -> list[Force]:
    """The interparticle forces of interparticle.kind (its `sdmpi.registry.FORCES` entry's
    builder, given the [interparticle] keys the entry names), fresh for one realisation;
    empty for "none".

    Args:
        job: the validated job.

    Returns:
        The forces, in the order they are summed.
    """
    inter = job.interparticle
    if inter.kind == NO_FORCE:
        return []
    spec = FORCES[inter.kind]
    setting = ForceSetting(np.array(job.system.radii, dtype=float), job.hydrodynamics.lubrication_cutoff)
    return list(spec.load()(setting, **{key: getattr(inter, key) for key in spec.keys}))


def recorders_of(job: Job, dt: float) -> list[StressRecorder]:
    """The hydrodynamic-stress recorders: a Maxwell medium's modes, then output.per_particle's
    stresslets.

    Args:
        job: the validated job.
        dt: the task's time step.

    Returns:
        The recorders, in sample-stream order.
    """
    n, out = job.system.n_particles, []
    if job.medium.kind == "maxwell":
        modes = job.medium.modes
        out.append(MaxwellStress(tuple(m.eta for m in modes), tuple(m.lam for m in modes), dt, n))
    if job.output.per_particle:
        out.append(PerParticleStresslets(n))
    return out


def geometry_of(job: Job, phi: float) -> Geometry:
    """The task's geometry: a `Monolayer` (system.geometry = "monolayer"), or the `Bulk` box
    whose overlaps are corrected unless the force keeps them as contacts
    (`sdmpi.registry.ForceSpec.contacts`).

    Args:
        job: the validated job.
        phi: the task's volume (or areal) fraction.

    Returns:
        The geometry, not yet started.
    """
    system = job.system
    if system.geometry == "monolayer":
        return Monolayer(system.n_particles, phi, system.layer_spacing, job.integration.overlap_stop)
    contacts = job.interparticle.kind != NO_FORCE and FORCES[job.interparticle.kind].contacts
    return Bulk(np.array(system.radii, dtype=float), phi, system.start_sweeps or 0, corrects_overlaps=not contacts)


def hydrodynamic_setting(job: Job) -> HydrodynamicSetting:
    """The hydrodynamic keys of a job, for its model: lubrication where the model has it
    (`sdmpi.registry.ModelSpec`) and hydrodynamics.lubrication is on.

    Args:
        job: the validated job.

    Returns:
        The `HydrodynamicSetting`.
    """
    hyd = job.hydrodynamics
    return HydrodynamicSetting(
        lubrication=HYDRODYNAMIC_MODELS[hyd.model].lubrication and hyd.lubrication,
        ewald_tolerance=job.ewald_tolerance, cutoff=hyd.lubrication_cutoff, min_gap=hyd.min_gap,
        backend=job.solver.backend, far_field=job.solver.far_field, tolerance=job.solver.tolerance,
        lanczos_tolerance=job.solver.lanczos_tolerance, scheme=job.brownian.scheme)


def hydrodynamic_model(job: Job, radii: np.ndarray, box: np.ndarray, comm: Any = None,
                       separate: Callable | None = None, on_error: Callable | None = None) -> HydrodynamicModel:
    """The model of job.hydrodynamics.model (its `sdmpi.registry.HYDRODYNAMIC_MODELS` entry)
    for spheres of these radii in this box.

    Args:
        job: the validated job.
        radii: sphere radii, shape (N,), in a.
        box: box sides (3,), in a.
        comm: the MPI communicator of the ranks that solve together, or None.
        separate: separate(positions, strain) -> (positions, overlaps), the overlap
            correction the midpoint scheme applies at its half step, or None.
        on_error: on_error(LinAlgError) -> the exception raised when M_inf or R_FU is not
            positive definite, or None.

    Returns:
        The model.
    """
    model = HYDRODYNAMIC_MODELS[job.hydrodynamics.model].load()
    return model.build(hydrodynamic_setting(job), radii, box, comm=comm, separate=separate, on_error=on_error)


def job_backend(job: Job) -> str:
    """The backend a job's tasks solve on: job.solver.backend, or what "auto" stands for at
    its N on ensemble.ranks_per_task ranks (`sdmpi.registry.backend_for`).

    Args:
        job: the validated job.

    Returns:
        A registered solver backend name (`sdmpi.registry.SOLVER_BACKENDS`).
    """
    return backend_for(job.solver.backend, job.system.n_particles, job.ensemble.ranks_per_task)


def sample_fields(job: Job) -> SampleFields:
    """name -> (shape per sample, dtype, unit, description) of a task's sample stream:
    the datasets under samples/ in docs/store.md (the same for every task of a job): the
    step's own fields, then the forces' and the recorders' (`forces_of`, `recorders_of`).

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
    for part in (*forces_of(job), *recorders_of(job, 1.0)):  # their fields do not depend on dt
        fields.update(part.sample_fields(su))
    return fields


def build(job: Job, task: Task) -> Setup:
    """The components and parameters of one task's realisation.

    Args:
        job: the validated job.
        task: the task (its phi, omega, dt, n_steps).

    Returns:
        The `Setup`.
    """
    hyd = job.hydrodynamics
    refresh = hyd.far_field_refresh
    return Setup(
        seed=job.job.seed, task_id=task.task_id, radii=np.array(job.system.radii, dtype=float),
        protocol=protocol_of(job, task), geometry=geometry_of(job, task.phi), forces=forces_of(job),
        recorders=recorders_of(job, task.dt), kT=KT_REDUCED if job.brownian.enabled else 0.0, dt=task.dt,
        n_steps=task.n_steps, min_gap=hyd.min_gap, collision_rule=hyd.collisions or default_rule(hyd.model),
        far_field_every=max(1, round(refresh / task.dt)) if refresh > 0 else 0,
        hydrodynamics=(HYDRODYNAMIC_MODELS[hyd.model].load(), hydrodynamic_setting(job)),
        integrator=INTEGRATORS[job.integration.scheme].load(), sample_fields=sample_fields(job))
