"""Checks that involve several keys of a job, run after every key passed its own checks.

Each check takes the provisional :class:`~sdmpi.config.schema.Job` and returns a list of
:class:`~sdmpi.config.problems.Problem`; :data:`CROSS_CHECKS` names the keys each one
reads, so that the loader skips a check when one of those keys already failed. Checks
that need the physics of the dynamics (its force laws, its contact mobilities) are
declared the same way next to it (`sdmpi.dynamics.checks`) and run in the same pass.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

from ..registry import (DRIFT_SCHEMES, FORCES, HYDRODYNAMIC_MODELS, INTEGRATORS, NO_FORCE, SOLVER_BACKENDS,
                        backend_for, drift_schemes_for, force_kinds, several_rank_choices)
from .problems import Problem
from .schema import START_PHI_LIMIT, TWO_PI, Job, quoted


def _discard_periods(job):
    i = job.integration
    if job.shear.protocol != "oscillatory":
        return []
    if i.duration is None:
        if i.discard_periods >= i.periods:
            return [Problem("integration.discard_periods",
                            f"must be smaller than integration.periods (= {i.periods})",
                            i.discard_periods, allowed=f"0 <= discard_periods < {i.periods}")]
        return []
    if i.discard_duration >= i.duration:
        return [Problem("integration.discard_duration", f"must be smaller than "
                        f"integration.duration (= {i.duration:g})", i.discard_duration,
                        allowed=f"0 <= discard_duration < {i.duration:g}")]
    for omega in job.frequencies:  # both are rounded up to whole periods
        kept, dropped = job.periods(omega), job.discarded_periods(omega)
        if dropped >= kept:
            return [Problem("integration.discard_duration", f"leaves no whole period at "
                            f"omega = {omega:g}: both it and integration.duration round up "
                            f"to {kept} period(s) of {TWO_PI / omega:.4g}", i.discard_duration,
                            allowed=f"discard_duration <= {(kept - 1) * TWO_PI / omega:.4g}, "
                            "or a longer duration")]
    return []


def _discard_steps(job):
    i = job.integration
    if job.shear.protocol != "oscillatory" and i.discard_steps >= i.n_steps:
        return [Problem("integration.discard_steps",
                        f"must be smaller than integration.n_steps (= {i.n_steps})",
                        i.discard_steps, allowed=f"0 <= discard_steps < {i.n_steps}")]
    return []


def _trajectory(job):
    """Trajectory extras need frames, and stresslets come from the per-particle samples."""
    out, problems = job.output, []
    for name in ("trajectory_velocities", "trajectory_stresslets"):
        if getattr(out, name) and out.trajectory_every == 0:
            problems.append(Problem(f"output.{name}", "needs a trajectory", True,
                                    allowed="output.trajectory_every >= 1, or false"))
    if out.trajectory_stresslets and not out.per_particle:
        problems.append(Problem("output.trajectory_stresslets", "needs the per-particle "
                                "stresslets", True, allowed="output.per_particle = true, or false"))
    return problems


def _maxwell_sum(job):
    if job.medium.kind != "maxwell":
        return []
    total = math.fsum(m.eta for m in job.medium.modes)
    if abs(total - 1.0) > 1e-9:
        return [Problem("medium.modes", f"the mode viscosities eta sum to {total:g}, but "
                        "their sum is the medium's zero-shear viscosity eta_m, the unit of "
                        "viscosity", job.medium.modes, allowed="modes whose eta sum to 1")]
    return []


def _gaps(job):
    h = job.hydrodynamics
    if h.min_gap >= h.lubrication_cutoff:
        return [Problem("hydrodynamics.min_gap", "must be smaller than "
                        f"hydrodynamics.lubrication_cutoff (= {h.lubrication_cutoff:g})",
                        h.min_gap, allowed=f"0 < min_gap < {h.lubrication_cutoff:g}")]
    return []


def _ranks(job):
    """A task on several ranks needs a backend that solves on several (`sdmpi.registry`)."""
    backend = job.solver.backend
    if job.ensemble.ranks_per_task > 1 and backend not in several_rank_choices():
        return [Problem("ensemble.ranks_per_task", f'the "{backend}" backend runs a task on '
                        "one rank", job.ensemble.ranks_per_task,
                        allowed=f"1, or solver.backend = {quoted(several_rank_choices())}")]
    return []


def _protocol_units(job):
    shear, brownian = job.shear, job.brownian.enabled
    if shear.protocol == "steady" and not brownian and shear.rate != 1.0:
        return [Problem("shear.rate", "non-Brownian steady shear measures time in "
                        "1/gamma_dot, so the rate is 1 by definition", shear.rate,
                        allowed="1.0, or brownian.enabled = true (rate = Peclet number)")]
    if shear.protocol == "none" and not brownian:
        return [Problem("shear.protocol", "without shear and without Brownian motion "
                        "nothing moves", "none",
                        allowed='"oscillatory" or "steady", or brownian.enabled = true')]
    return []


def _time_step(job):
    """Seed eq. 14a (dt < t_D = 1, Brownian jobs) and dt < lambda (Maxwell media)."""
    limits = []
    if job.brownian.enabled:
        smallest = min(job.system.class_radii)
        if smallest == 1.0:
            limits.append((1.0, "the diffusion time t_D = 1 (Schaink et al. eq. 14a)"))
        else:  # size classes: t_D is the largest spheres' diffusion time
            limits.append((smallest ** 3, "the diffusion time a^2/D0(a) = a^3 t_D = "
                           f"{smallest ** 3:.4g} of the smallest spheres (radius {smallest:g})"))
    if job.medium.kind == "maxwell":
        lam = min(m.lam for m in job.medium.modes)
        limits.append((lam, f"the shortest Maxwell relaxation time ({lam:g})"))
    problems = []
    for limit, what in limits:
        omega = max(job.frequencies, key=lambda w: job.time_step(w), default=None)
        dt = job.time_step(omega)
        if dt < limit:
            continue
        if omega is None:
            problems.append(Problem("integration.dt", f"must be smaller than {what}", dt,
                                    allowed=f"0 < dt < {limit:g}"))
        else:
            problems.append(Problem(
                "integration.steps_per_period", f"gives dt = {dt:.3g} at omega = {omega:g}, "
                f"not smaller than {what}", job.integration.steps_per_period,
                allowed=f"more steps per period, or integration.dt_max < {limit:g}"))
    return problems


def _bulk_start(job):
    """The hard-sphere generator (sdmpi.dynamics.initial) starts from a simple cubic
    lattice spaced for the largest diameter, compressed when phi is above the lattice's
    limit: phi < START_PHI_LIMIT for any N and size classes."""
    if job.system.geometry != "bulk":
        return []
    return [Problem(f"system.phi[{k}]", "the initial configuration is a compressed hard-sphere "
                    f"fluid, made up to phi = {START_PHI_LIMIT} (denser ones jam)", phi,
                    allowed=f"0 < phi < {START_PHI_LIMIT}")
            for k, phi in enumerate(job.system.phi) if phi >= START_PHI_LIMIT]


def _monolayer_start(job):
    """Monolayers: the start (sdmpi.dynamics.initial.hard_disk_monolayer): m x m square
    lattice sites, m = ceil(sqrt N), spaced L/m > 2, so phi < pi N / (4 m^2)."""
    system = job.system
    if system.geometry != "monolayer":
        return []
    m = math.isqrt(system.n_particles - 1) + 1
    limit = math.pi * system.n_particles / (4 * m * m)
    return [Problem(f"system.phi[{k}]", f"the monolayer start fills {m} x {m} square-lattice "
                    f"sites spaced for the diameter, which holds N = {system.n_particles} disks "
                    f"up to the areal fraction pi N / (4 m^2) = {limit:.4f}", phi,
                    allowed=f"0 < phi < {math.floor(limit * 1e4) / 1e4:.4f}, or N = {m * m}")
            for k, phi in enumerate(system.phi) if phi >= limit]


def _monolayer(job):
    """Monolayers are Dratler & Schowalter's (1996) case: non-Brownian steady shear of equal
    spheres in a Newtonian medium, hard (with the minimum-gap rule) or with the short-range
    repulsion; the layer's z-images stay outside the lubrication cut-off."""
    system = job.system
    if system.geometry != "monolayer":
        return []
    why = "monolayers are non-Brownian steady shear of equal spheres (Dratler & Schowalter 1996)"
    problems = []
    for path, value, ok, allowed in (
            ("shear.protocol", job.shear.protocol, job.shear.protocol == "steady", '"steady"'),
            ("brownian.enabled", job.brownian.enabled, not job.brownian.enabled, "false"),
            ("medium.kind", job.medium.kind, job.medium.kind == "newtonian", '"newtonian"'),
            ("system.size_classes", system.size_classes, system.size_classes is None,
             "absent (equal spheres)"),
            ("interparticle.kind", job.interparticle.kind,
             job.interparticle.kind in force_kinds(lambda f: f.monolayer),
             quoted(force_kinds(lambda f: f.monolayer)))):
        if not ok:
            problems.append(Problem(path, why, value, allowed=f'{allowed}, or system.geometry = "bulk"'))
    cutoff = job.hydrodynamics.lubrication_cutoff
    side = math.sqrt(system.n_particles * math.pi / max(system.phi))
    need = (2.0 + cutoff) / side
    if system.layer_spacing * side < 2.0 + cutoff:
        problems.append(Problem("system.layer_spacing", f"the layer's z-images ({system.layer_spacing:g} "
                                f"x L = {system.layer_spacing * side:.3g} a away at phi = "
                                f"{max(system.phi):g}) must lie beyond the lubrication cut-off "
                                f"(centre distance 2 + {cutoff:g})", system.layer_spacing,
                                allowed=f"layer_spacing >= {need:.4g}"))
    return problems


def _size_classes(job):
    """Volume shares summing to 1, the largest radius 1 (the length unit), distinct radii,
    and at least one sphere per class after rounding the counts."""
    system = job.system
    classes = system.size_classes
    if classes is None:
        return []
    problems = []
    total = math.fsum(c.fraction for c in classes)
    if abs(total - 1.0) > 1e-9:
        problems.append(Problem("system.size_classes", f"the volume shares (fraction) sum to "
                                f"{total:g}; they divide the particle volume, so they sum to 1",
                                classes, allowed="fractions > 0 whose sum is 1"))
    largest = max(c.radius for c in classes)
    if largest != 1.0:
        problems.append(Problem("system.size_classes", f"the largest radius is {largest:g}, "
                                "but the largest radius is the length unit a, so it is 1",
                                classes, allowed="radii divided by the largest, e.g. "
                                "[{radius = 1.0, ...}, {radius = 0.5, ...}]"))
    for k, c in enumerate(classes):
        if any(c.radius == d.radius for d in classes[:k]):
            problems.append(Problem(f"system.size_classes[{k}].radius", "appears twice; "
                                    "merge the two classes", c.radius,
                                    allowed="distinct radii"))
    if problems:
        return problems
    for k, (c, m) in enumerate(zip(classes, system.class_counts)):
        if m == 0:
            problems.append(Problem(f"system.size_classes[{k}]", f"gets no sphere among N = "
                                    f"{system.n_particles} (volume share {c.fraction:g} of "
                                    f"radius {c.radius:g} spheres)", c,
                                    allowed="a larger system.n_particles, or a larger fraction"))
    return problems


def _repulsion_range(job):
    """interparticle.tau (of whichever force reads it): the repulsion of range 1/tau decays
    to 1e-12 within the lubrication cut-off."""
    inter, cutoff = job.interparticle, job.hydrodynamics.lubrication_cutoff
    if inter.tau is not None and 12 * math.log(10) / inter.tau > cutoff:
        need = 12 * math.log(10) / cutoff
        return [Problem("interparticle.tau", "the repulsion must decay (to 1e-12) within the "
                        f"lubrication cut-off (= {cutoff:g}), whose pairs it acts on", inter.tau,
                        allowed=f"tau >= {need:.4g}, or a larger hydrodynamics.lubrication_cutoff")]
    return []


def _force_range(job):
    """interparticle.cap_gap (vdw, dlvo): the van der Waals cap inside the cut-off gap of the
    smallest pair (the force laws' truncation at the cut-off is checked with them,
    `sdmpi.dynamics.checks`)."""
    inter, cutoff = job.interparticle, job.hydrodynamics.lubrication_cutoff
    if inter.cap_gap is None:
        return []
    smallest = min(job.system.class_radii)  # the cut-off gap is cut-off x mean radius
    if inter.cap_gap >= cutoff * smallest:
        of = "" if smallest == 1.0 else f" x the smallest radius {smallest:g}"
        return [Problem("interparticle.cap_gap", "must be smaller than the cut-off gap "
                        f"hydrodynamics.lubrication_cutoff (= {cutoff:g}){of}", inter.cap_gap,
                        allowed=f"0 < cap_gap < {cutoff * smallest:g}")]
    return []


def _force_brownian(job):
    """A force that may not act in Brownian jobs (`sdmpi.registry.ForceSpec.brownian`: the
    frictional contacts, whose springs the Brownian midpoint would cross)."""
    kind = job.interparticle.kind
    if kind == NO_FORCE or FORCES[kind].brownian or not job.brownian.enabled:
        return []
    return [Problem("brownian.enabled", f"the {kind} force is a non-Brownian model", True,
                    allowed=f'false with interparticle.kind = "{kind}"')]


def _repulsion_length(job):
    """interparticle.repulsion_length (frictional contacts, sdmpi.dynamics.contacts): the
    critical-load repulsion decayed to 1e-12 within the lubrication cut-off (the contact
    springs' stability at the time step is checked with them, `sdmpi.dynamics.checks`)."""
    inter, hyd = job.interparticle, job.hydrodynamics
    if inter.repulsion_length is None:
        return []
    problems = []
    reach = 12 * math.log(10) * inter.repulsion_length
    if reach > hyd.lubrication_cutoff:
        problems.append(Problem("interparticle.repulsion_length", "the repulsion must decay "
                                "(to 1e-12) within the lubrication cut-off (= "
                                f"{hyd.lubrication_cutoff:g}), whose pairs it acts on",
                                inter.repulsion_length, allowed="repulsion_length <= "
                                f"{hyd.lubrication_cutoff / (12 * math.log(10)):.4g}, or a "
                                "larger hydrodynamics.lubrication_cutoff"))
    return problems


def _model(job):
    """What the hydrodynamic models support (`sdmpi.registry.ModelSpec`): lubrication is
    the models' that have it; monolayers and frictional contacts are built on lubrication;
    a model that solves nothing has nothing to share over several ranks; the drift scheme
    must suit the backend (`scheme_problems`)."""
    hyd, problems = job.hydrodynamics, []
    model = HYDRODYNAMIC_MODELS[hyd.model]
    with_lubrication = HYDRODYNAMIC_MODELS.names(lambda m: m.lubrication)
    if not model.lubrication and not hyd.lubrication:
        problems.append(Problem("hydrodynamics.lubrication", f"applies to the {' and '.join(with_lubrication)} "
                                "model only (lubrication = false there is the far-field model)", False,
                                allowed=f'true (the default) with hydrodynamics.model = "{hyd.model}"'))
    for needed, why in ((job.system.geometry == "monolayer", "monolayers are simulated with full "
                         "Stokesian dynamics only"),
                        (_has_contacts(job), f"{job.interparticle.kind} contacts need the lubrication "
                         "of a model with it")):
        if needed and not model.lubrication:
            problems.append(Problem("hydrodynamics.model", why, hyd.model, allowed=quoted(with_lubrication)))
        elif needed and not hyd.lubrication:  # the stokesian model without it is the far field
            problems.append(Problem("hydrodynamics.lubrication", why, False, allowed="true (the default)"))
    if not model.solves and job.ensemble.ranks_per_task > 1:
        problems.append(Problem("ensemble.ranks_per_task", f"a {hyd.model} realisation has "
                                "nothing to solve on several ranks", job.ensemble.ranks_per_task,
                                allowed=f'1 with hydrodynamics.model = "{hyd.model}"'))
    return problems + scheme_problems(job, job.solver.backend)


def scheme_problems(job, backend: str) -> list[Problem]:
    """brownian.scheme must suit the backend (`sdmpi.registry.drift_schemes_for`): the
    random finite differences need a direct backend or one with
    `sdmpi.registry.BackendSpec.mobility_change`.
    backend: the one the job runs on (the loader passes solver.backend, whose rule "auto" is
    judged once resolved; `sdmpi run` and `sdmpi validate` pass what it stands for,
    `sdmpi.registry.backend_for`)."""
    scheme = job.brownian.scheme
    if scheme is None or not HYDRODYNAMIC_MODELS[job.hydrodynamics.model].solves or \
            backend not in SOLVER_BACKENDS or scheme in drift_schemes_for(backend):
        return []
    named = job.solver.backend
    where = "" if named == backend else (f' (what "{named}" stands for with {job.system.n_particles} particles '
                                         f'on {job.ensemble.ranks_per_task} rank(s) per task)')
    return [Problem("brownian.scheme", DRIFT_SCHEMES[scheme].why_not, scheme,
                    allowed=f'{quoted(drift_schemes_for(backend))} (or absent) with solver.backend = "{backend}"{where}')]


def _far_field_refresh(job):
    """A far field held between refreshes needs a model with one on a backend that forms
    it (solver.backend, or what "auto" resolves to), and no Brownian motion (whose drift is the divergence of the configuration's own
    mobility)."""
    hyd = job.hydrodynamics
    if hyd.far_field_refresh == 0.0:
        return []
    direct = SOLVER_BACKENDS.names(lambda b: not b.matrix_free)
    for broken, why, allowed in (
            (job.brownian.enabled, "the Brownian drift needs the mobility of the step's own configuration",
             "0, or brownian.enabled = false"),
            (not HYDRODYNAMIC_MODELS[hyd.model].solves, f"the {hyd.model} model has no far field",
             f"0 with hydrodynamics.model = \"{hyd.model}\""),
            (backend_for(job.solver.backend, job.system.n_particles, job.ensemble.ranks_per_task) not in direct,
             "the far field is held only by the backends that form it",
             f"0, or solver.backend = {quoted(direct)} (or \"auto\" where it resolves to one)")):
        if broken:
            return [Problem("hydrodynamics.far_field_refresh", why, hyd.far_field_refresh, allowed=allowed)]
    return []


def _integrator(job):
    """What the integrator supports (`sdmpi.registry.IntegratorSpec`): Brownian motion,
    forces with contacts (`sdmpi.registry.ForceSpec.contacts`)."""
    spec, problems = INTEGRATORS[job.integration.scheme], []
    able = INTEGRATORS.names(lambda i: i.brownian)
    if job.brownian.enabled and not spec.brownian:
        problems.append(Problem("integration.scheme", "integrates deterministic motion only (a smooth "
                                "velocity), not Brownian motion", spec.name,
                                allowed=f"{quoted(able)}, or brownian.enabled = false"))
    if _has_contacts(job) and not spec.contacts:
        problems.append(Problem("integration.scheme", f"does not integrate the history of the "
                                f"{job.interparticle.kind} contacts (non-smooth in time)", spec.name,
                                allowed=quoted(INTEGRATORS.names(lambda i: i.contacts))))
    return problems


def _has_contacts(job):
    """Whether the job's force keeps overlaps as contacts (`sdmpi.registry.ForceSpec.contacts`)."""
    kind = job.interparticle.kind
    return kind != NO_FORCE and FORCES[kind].contacts


def _maxwell_forces(job):
    """Schaink et al. (2000) cover hard spheres in a Maxwell medium: the viscoelastic response of the
    force-induced stresslets is not modelled, so the combination is refused."""
    if job.medium.kind == "maxwell" and job.interparticle.kind != NO_FORCE:
        return [Problem("interparticle.kind", "interparticle forces in a Maxwell medium are not "
                        "modelled (their stresslets would need the medium's memory too)",
                        job.interparticle.kind, allowed=f'"{NO_FORCE}" with medium.kind = "maxwell"')]
    return []


#: every integration key (each can change the time step)
INTEGRATION_KEYS = tuple(f"integration.{f.name}" for f in dataclasses.fields(Job().integration))

#: (keys a check reads, check): the check is skipped when one of those keys failed its own
#: checks
CrossCheck = tuple[tuple[str, ...], Callable[[Job], list[Problem]]]

CROSS_CHECKS: tuple[CrossCheck, ...] = (
    (("shear.protocol", "shear.omega") + INTEGRATION_KEYS, _discard_periods),
    (("shear.protocol", "integration.n_steps", "integration.discard_steps"), _discard_steps),
    (("medium.kind", "medium.modes"), _maxwell_sum),
    (("output.trajectory_every", "output.trajectory_velocities", "output.trajectory_stresslets",
      "output.per_particle"), _trajectory),
    (("hydrodynamics.min_gap", "hydrodynamics.lubrication_cutoff"), _gaps),
    (("ensemble.ranks_per_task", "solver.backend"), _ranks),
    (("shear.protocol", "shear.rate", "brownian.enabled"), _protocol_units),
    (("shear.protocol", "shear.omega", "brownian.enabled", "medium.kind", "medium.modes",
      "system.size_classes") + INTEGRATION_KEYS, _time_step),
    (("system.n_particles", "system.size_classes"), _size_classes),
    (("system.phi", "system.geometry"), _bulk_start),
    (("system.n_particles", "system.phi", "system.geometry"), _monolayer_start),
    (("system.geometry", "system.n_particles", "system.phi", "system.layer_spacing",
      "system.size_classes", "shear.protocol", "brownian.enabled", "medium.kind",
      "interparticle.kind", "hydrodynamics.lubrication_cutoff"), _monolayer),
    (("interparticle.kind", "interparticle.tau", "hydrodynamics.lubrication_cutoff"), _repulsion_range),
    (("interparticle.kind", "interparticle.cap_gap", "hydrodynamics.lubrication_cutoff",
      "system.size_classes"), _force_range),
    (("hydrodynamics.model", "hydrodynamics.lubrication", "system.geometry", "interparticle.kind",
      "ensemble.ranks_per_task", "brownian.scheme", "solver.backend"), _model),
    (("interparticle.kind", "brownian.enabled"), _force_brownian),
    (("interparticle.kind", "interparticle.repulsion_length", "hydrodynamics.lubrication_cutoff"),
     _repulsion_length),
    (("medium.kind", "interparticle.kind"), _maxwell_forces),
    (("integration.scheme", "brownian.enabled", "interparticle.kind"), _integrator),
    (("hydrodynamics.far_field_refresh", "hydrodynamics.model", "brownian.enabled", "solver.backend"),
     _far_field_refresh),
)
