"""sdmpi's Python API: a job, its tasks, and one task's realisation stepped in time.

::

    import sdmpi
    job = sdmpi.load_job("jobs/demo.toml", ["system.n_particles=8"])
    tasks = sdmpi.tasks(job)                 # one per (phi, omega, realisation)
    r = sdmpi.Realisation(job, tasks[0])
    samples = r.advance(100)                 # 100 steps: one sample per step
    samples.stress["hydrodynamic"]           # (100, 6): xx yy zz xy xz yz

A realisation is a pure function of (job, task): it gives the numbers that ``sdmpi run``
stores for the same task, bit for bit, with one BLAS thread, on one process
(docs/api.md). Units are sdmpi's reduced units (README, docs/physics.md).
"""

from __future__ import annotations

import numpy as np

from .config import Job, Task, enumerate_tasks
from .config.stresses import CONTRIBUTIONS, contribution_datasets
from .dynamics import realisation as _dynamics
from .dynamics.checks import load_job
from .ensemble import start_file

__all__ = ["Realisation", "Samples", "load_job", "tasks"]


def tasks(job: Job) -> tuple[Task, ...]:
    """The tasks of a job, in task-id order.

    Args:
        job: a validated job (:func:`load_job`).

    Returns:
        One :class:`sdmpi.config.Task` per (phi, omega, realisation): phi-major, then
        omega, then realisation, in the order the job lists them, so that
        ``tasks(job)[k].task_id == k``. Each holds ``phi``, ``omega`` (rad per time unit;
        None unless the shear is oscillatory), ``realisation``, the time step ``dt`` and
        ``n_steps``, ``discard_steps`` (the start-up the reducer leaves out).
    """
    return enumerate_tasks(job)


class Samples(dict):
    """The samples of consecutive steps: sample dataset name -> array with a leading axis
    of one entry per step, the datasets ``samples/*`` of a run file (docs/store.md): e.g.
    ``time`` (n,), ``strain`` (n,), ``rate`` (n,), ``stress_hydrodynamic`` (n, 6),
    ``n_overlaps`` (n,). Stresses are 6-vectors xx yy zz xy xz yz (flow x, gradient y,
    vorticity z) per unit volume, in eta_m/t_D (eta_m gamma_dot for non-Brownian steady
    shear); :attr:`Realisation.fields` gives every dataset's unit and meaning."""

    def __init__(self, arrays: dict[str, np.ndarray], stress_datasets: dict[str, str]):
        super().__init__(arrays)
        self._stress_datasets = stress_datasets

    @property
    def stress(self) -> dict[str, np.ndarray]:
        """Stress contribution -> its (n, 6) samples: ``hydrodynamic``, ``brownian``,
        ``interparticle``, ``collision``, the rows of ``moduli.csv`` between ``medium``
        and ``total`` (`sdmpi.config.stresses`); in a Maxwell medium ``hydrodynamic`` is
        the stress filtered by its modes. Sample k is taken at ``time[k]``, the
        collision stress at ``time[k] + dt/2`` (docs/physics.md)."""
        return {component: self[dataset] for component, dataset in self._stress_datasets.items()}


class Realisation:
    """One task's Stokesian-dynamics realisation, stepped in time.

    Its start (generated, or from ``system.start_file``) and its random stream
    (``numpy.random.SeedSequence(job.job.seed, spawn_key=(task_id,))``) depend on the job
    and the task only. It steps on this process alone (a PETSc backend solves on this
    rank); ``sdmpi run`` gives the same numbers for the same task with
    ``ensemble.ranks_per_task = 1``, bit for bit when this process has stepped the same
    realisations before it (its lubrication tables: docs/api.md).

    Args:
        job: a validated job (:func:`load_job`).
        task: one of ``tasks(job)``, or its task id.
    """

    def __init__(self, job: Job, task: Task | int):
        if not isinstance(task, Task):
            task = tasks(job)[task]
        self._real = _dynamics.Realisation(job, task)
        start = start_file.load(job)
        if start is not None:
            start_file.apply(self._real, start.positions(task))
        self._stress = {c.component: dataset
                        for c, dataset in zip(CONTRIBUTIONS, contribution_datasets(job.medium.kind))}

    def advance(self, n: int) -> Samples:
        """Step ``n`` times (fewer at the task's end: ``n_steps - step`` at most).

        Args:
            n: number of steps, >= 0.

        Returns:
            The steps' samples, one per step (:class:`Samples`): sample k is taken at the
            start of its step, ``time[k] = (step + k) dt`` with ``step`` the value before
            the call.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"n must be an integer >= 0, got {n!r}")
        return Samples(self._real.advance(int(n)), self._stress)

    @property
    def job(self) -> Job:
        """The job."""
        return self._real.job

    @property
    def task(self) -> Task:
        """The task."""
        return self._real.task

    @property
    def step(self) -> int:
        """Steps taken (0 at the start)."""
        return self._real.step

    @property
    def n_steps(self) -> int:
        """Steps of the task."""
        return self._real.n_steps

    @property
    def dt(self) -> float:
        """The time step, in the job's time unit (``job.time_unit``: t_D, or 1/gamma_dot
        for non-Brownian steady shear)."""
        return self._real.dt

    @property
    def time(self) -> float:
        """The time of the current configuration, ``step * dt``."""
        return self._real.step * self._real.dt

    @property
    def strain(self) -> float:
        """The imposed strain gamma at :attr:`time` (the Lees-Edwards shift of the box's
        image at +Ly is ``strain * Ly``)."""
        return float(self._real.protocol.strain(self.time))

    @property
    def rate(self) -> float:
        """The imposed shear rate gamma_dot at :attr:`time`, per time unit."""
        return float(self._real.protocol.rate(self.time))

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) a copy of the sphere centres at :attr:`time`, in units of the largest
        radius a, inside the box. At a start they are as generated (or read); a pair
        overlapping there is separated by the first step."""
        return self._real.positions.copy()

    @property
    def radii(self) -> np.ndarray:
        """(N,) a copy of the sphere radii, in units of the largest radius a."""
        return self._real.radii.copy()

    @property
    def box(self) -> np.ndarray:
        """(3,) a copy of the periodic box's sides (Lx, Ly, Lz), in units of a."""
        return self._real.box.copy()

    @property
    def fields(self) -> dict[str, tuple[tuple[int, ...], str, str, str]]:
        """Sample dataset -> (shape per sample, dtype, unit, description): what
        :meth:`advance` returns."""
        return self._real.sample_fields()
