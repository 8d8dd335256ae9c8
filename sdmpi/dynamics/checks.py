"""Checks of a job against the physics of the dynamics, and the loaders that run them.

The job loader of `sdmpi.config` checks every key and the combinations of keys it can
judge alone; the checks here need the force laws (`forces`) and the contact mobilities
(`contacts`). They are cross-key checks of the same form (keys read, check), run in the
loader's single pass (skipped when a key they read failed), so that every problem of a
job is reported at once. :func:`load_job` and :func:`parse_job` are the loaders with them:
the command line, `sdmpi run` and the Python API (`sdmpi.load_job`) load jobs with these.

This module imports the force laws and contacts only when a job uses them, so that
validating a job stays fast.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping

from ..config import Job, Problem
from ..config import load_job as _load_job
from ..config import parse_job as _parse_job
from ..config.checks import INTEGRATION_KEYS


def _force_tails(job: Job) -> list[Problem]:
    """vdw / dlvo: the shift that truncates the force at the lubrication cut-off is
    negligible, |F(cut-off)| <= `forces.TAIL` |F(contact)| for the worst pair of size
    classes (`forces.tail_ratios`)."""
    inter, cutoff = job.interparticle, job.hydrodynamics.lubrication_cutoff
    # a cap beyond the smallest pair's cut-off gap is reported by sdmpi.config.checks
    if inter.cap_gap is None or inter.cap_gap >= cutoff * min(job.system.class_radii):
        return []
    from .forces import TAIL, tail_ratios
    problems = []
    for path, (ratio, (a_i, a_j)) in tail_ratios(inter.cap_gap, inter.debye_length, cutoff,
                                                  job.system.class_radii).items():
        if ratio > TAIL:
            what = ("the van der Waals force at the cut-off" if path.endswith("cap_gap")
                    else "the double-layer force at the cut-off")
            if job.system.size_classes is not None:
                what += f" (worst pair: radii {a_i:g} and {a_j:g})"
            fix = ("a smaller cap_gap" if path.endswith("cap_gap") else "a shorter debye_length")
            problems.append(Problem(path, f"{what} is {ratio:.2g} of its contact value; "
                                    f"the force is shifted to vanish at the lubrication cut-off "
                                    f"(= {cutoff:g}), which needs <= {TAIL:g}",
                                    getattr(inter, path.split(".")[1]),
                                    allowed=f"{fix}, or a larger hydrodynamics.lubrication_cutoff"))
    return problems


def _contact_springs(job: Job) -> list[Problem]:
    """Frictional contacts: a time step the explicit contact springs allow, dt k m <= 1
    with m the touching pair's mobility at hydrodynamics.min_gap (`contacts` docstring)."""
    inter, hyd = job.interparticle, job.hydrodynamics
    if inter.k_n is None or inter.k_t is None:
        return []
    from .contacts import SQUEEZE, sliding_mobility
    problems = []
    dt = max(job.time_step(w) for w in job.frequencies)
    for path, limit, why in (
            ("interparticle.k_t", 1 / (sliding_mobility(hyd.min_gap) * dt),
             f"sliding mobility {sliding_mobility(hyd.min_gap):.3g} at hydrodynamics.min_gap"),
            ("interparticle.k_n", 1 / (SQUEEZE * hyd.min_gap * dt),
             f"normal mobility {SQUEEZE:g} x hydrodynamics.min_gap at contact")):
        value = getattr(inter, path.split(".")[1])
        if value > limit:
            problems.append(Problem(path, f"is too stiff for the time step dt = {dt:.3g}: the "
                                    f"explicit step needs dt x stiffness x mobility <= 1 ({why})",
                                    value, allowed=f"{path.split('.')[1]} <= {limit:.4g}, or a "
                                    "smaller integration.dt"))
    return problems


#: (keys a check reads, check), as `sdmpi.config.checks.CROSS_CHECKS`
CHECKS = (
    (("interparticle.kind", "interparticle.cap_gap", "interparticle.debye_length",
      "hydrodynamics.lubrication_cutoff", "system.size_classes"), _force_tails),
    (("interparticle.kind", "interparticle.k_n", "interparticle.k_t", "hydrodynamics.min_gap",
      "shear.protocol", "shear.omega") + INTEGRATION_KEYS, _contact_springs),
)


def load_job(source: str | os.PathLike | Mapping, overrides: Iterable[str] = ()) -> Job:
    """Read, override and validate a job: every key, every combination of keys, and the
    physics checks of this module (`sdmpi.config.load_job` with :data:`CHECKS`).

    Args:
        source: the path of a job file (TOML, UTF-8), or a job as a mapping of section
            name -> table, the form ``tomllib.load`` returns (tables as dicts, arrays as
            lists); the mapping is not modified.
        overrides: ``"SECTION.KEY=LITERAL"`` strings (``--set``; LITERAL is a TOML value),
            applied over the source in order.

    Returns:
        The validated, frozen :class:`sdmpi.config.Job`, in sdmpi's reduced units
        (docs/job_keys.md).

    Raises:
        sdmpi.config.JobError: every problem found (key, value, why, what is allowed) at
            once.
    """
    return _load_job(source, overrides, checks=CHECKS)


def parse_job(text: str, overrides: Iterable[str] = (), *, source: str = "job") -> Job:
    """`sdmpi.config.parse_job` (a job's TOML text) with the physics checks of this module."""
    return _parse_job(text, overrides, source=source, checks=CHECKS)
