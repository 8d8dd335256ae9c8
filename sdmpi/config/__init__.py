"""Job files: TOML -> a frozen, validated :class:`Job` (every problem reported up front).

Usage::

    from sdmpi.config import load_job, enumerate_tasks, canonical_text, JobError
    job = load_job("jobs/demo.toml", overrides=["shear.gamma0=0.05"])  # raises JobError
    for task in enumerate_tasks(job): ...

The schema (sections, keys, defaults, allowed values, units) lives in :mod:`.schema`;
``schema_text()`` (:mod:`.reference`) prints it. Units: sphere radius 1, medium zero-shear
viscosity 1, time in t_D = a^2/D0 (1/gamma_dot for non-Brownian steady shear);
``Job.time_unit`` says which.
This package uses only the standard library, so validating a job is fast. The checks that
need the physics (force laws, contact mobilities) live with it, in `sdmpi.dynamics.checks`,
whose ``load_job`` runs them in the same pass (``sdmpi.load_job``, the command line).
"""

from .canonical import (LAYOUT_KEYS, LENGTH_KEYS, canonical_text, extension_hash, job_hash,
                        resume_hash, toml_literal)
from .loader import load_job, parse_job
from .problems import JobError, Problem
from .reference import schema_text
from .schema import (Brownian, Ensemble, Hydrodynamics, Integration, Job, JobSection,
                     Medium, Mode, Output, Shear, SizeClass, Solver, System)
from .tasks import Task, enumerate_tasks

__all__ = [
    "Brownian", "Ensemble", "Hydrodynamics", "Integration", "Job", "JobError", "JobSection",
    "LAYOUT_KEYS", "LENGTH_KEYS", "Medium", "Mode", "Output", "Problem", "Shear", "SizeClass", "Solver", "System", "Task",
    "canonical_text", "enumerate_tasks", "extension_hash", "job_hash", "load_job", "parse_job", "resume_hash",
    "schema_text", "toml_literal",
]
