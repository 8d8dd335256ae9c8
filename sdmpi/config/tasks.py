"""Tasks: one realisation at one (phi, omega), the unit of work farmed out to ranks."""

from __future__ import annotations

from dataclasses import dataclass

from .schema import Job


@dataclass(frozen=True)
class Task:
    """One task. ``omega`` is None unless the shear is oscillatory; ``dt`` is in the job's
    time unit; ``cost`` = n_steps x N^3 (the dense solve's scaling), in arbitrary units."""

    task_id: int
    phi: float
    omega: float | None
    realisation: int
    dt: float
    n_steps: int
    discard_steps: int
    cost: int


def enumerate_tasks(job: Job) -> tuple[Task, ...]:
    """All tasks of ``job`` in task-id order.

    Ids are phi-major, then omega, then realisation, in the order the job file lists
    them: task_id = (i_phi * n_omega + i_omega) * realisations + realisation. They depend
    only on the job, never on ranks, so they key the random streams and the HDF5 groups.
    """
    tasks = []
    n_cubed = job.system.n_particles ** 3
    for phi in job.system.phi:
        for omega in job.frequencies:
            dt, steps, discard = job.time_step(omega), job.n_steps(omega), job.discard_steps(omega)
            for r in range(job.ensemble.realisations):
                tasks.append(Task(len(tasks), phi, omega, r, dt, steps, discard, steps * n_cubed))
    return tuple(tasks)
