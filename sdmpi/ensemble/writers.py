"""Writers: the outputs of a run, each a set of datasets in the run file (docs/store.md).

A writer (:class:`Writer`) creates its datasets with the rest of the run file, preallocated
(:func:`sdmpi.ensemble.store.create`); gives the leader of each task a
:class:`TaskRecorder`, which sees every step and hands the data collected since the last
checkpoint to the run file (:meth:`sdmpi.ensemble.store.RunFile.write`, or
:meth:`~sdmpi.ensemble.store.RunFile.write_samples` for the checksummed sample stream) just
before the checkpoint commit that makes them valid; copies a task's committed data into a
longer file on ``sdmpi run --extend`` (:mod:`sdmpi.ensemble.extension`); and estimates its
bytes in the run file (``sdmpi validate``, the free-space check of ``sdmpi run``).

A writer writes raw data only, into datasets it created: the commit protocol (one flush
and fsync before ``/progress`` moves, the writer rank of a serial h5py) stays the run
file's (:mod:`sdmpi.ensemble.store`), so a writer cannot break it.

The writers are listed in `sdmpi.registry.WRITERS`; adding one: docs/extending.md.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..registry import WRITERS

if TYPE_CHECKING:
    import h5py

    from ..config.schema import Job
    from ..config.tasks import Task
    from ..dynamics.realisation import Realisation


class TaskRecorder(Protocol):
    """One task's share of a writer while its leader steps it."""

    def before(self, step: int, realisation: Realisation) -> None:
        """Called ahead of step ``step``.

        Args:
            step: the step about to be taken.
            realisation: the task's realisation, at the start of that step.
        """
        raise NotImplementedError

    def after(self, step: int, sample: dict[str, np.ndarray], realisation: Realisation) -> None:
        """Called after step ``step``.

        Args:
            step: the step just taken.
            sample: its sample, name -> array with a leading axis of length 1.
            realisation: the task's realisation, after the step.
        """
        raise NotImplementedError

    def flush(self, stop: int) -> None:
        """Hand what was recorded since the last flush (the steps below ``stop``) to the run
        file, whose next checkpoint commit, at step ``stop``, makes it valid.

        Args:
            stop: the step of that checkpoint.
        """
        raise NotImplementedError


class Writer(Protocol):
    """An output of a run: datasets of the run file, created preallocated, written while
    the tasks step, committed by the checkpoints. Built without arguments."""

    def enabled(self, job: Job) -> bool:
        """Whether the job asks for this output.

        Args:
            job: the validated job.

        Returns:
            False: the writer creates, records and estimates nothing for this job.
        """
        raise NotImplementedError

    def create(self, f: h5py.File, job: Job, tasks: Iterable[Task], layouts: dict[int, Any]) -> None:
        """Create the datasets of every task in the run file being created (collectively,
        with the rest of the layout; preallocated with `sdmpi.ensemble.h5.new_dataset`).

        Args:
            f: the run file, open for writing.
            job: the validated job.
            tasks: the job's tasks.
            layouts: task id -> `sdmpi.ensemble.store.TaskLayout` (sample fields, box,
                n_particles, radii).
        """
        raise NotImplementedError

    def recorder(self, job: Job, task: Task, realisation: Realisation, run_file: Any,
                 start: int) -> TaskRecorder:
        """The recorder of one task, on its leader.

        Args:
            job: the validated job.
            task: the task.
            realisation: its realisation, at step ``start``.
            run_file: the leader's `sdmpi.ensemble.store.RunFile`.
            start: the task's committed step, where it starts or resumes.

        Returns:
            The task's recorder.
        """
        raise NotImplementedError

    def carry_over(self, old: h5py.File, new: h5py.File, job: Job, task_id: int, done: int) -> None:
        """Copy a task's committed data into a longer layout of the same job
        (``sdmpi run --extend``; one process, the new file open for writing).

        Args:
            old: the run file read from.
            new: the longer run file.
            job: the longer job.
            task_id: the task.
            done: its committed steps.
        """
        raise NotImplementedError

    def file_bytes(self, job: Job) -> float:
        """The bytes of this output in the job's run file (preallocated, so exact up to
        the headers).

        Args:
            job: the validated job.

        Returns:
            The estimate, in bytes.
        """
        raise NotImplementedError

    def describe(self, job: Job, done: list[int]) -> str | None:
        """One line of ``sdmpi info`` on this output of a run file (optional: a writer
        without it adds no line).

        Args:
            job: the run file's job.
            done: the committed steps of each task, in task order.

        Returns:
            What the output holds at that progress, or None (nothing beyond the report's
            steps per task).
        """
        raise NotImplementedError


def active(job: Job) -> list[Writer]:
    """The registered writers the job asks for, in registration order.

    Args:
        job: the validated job.

    Returns:
        One instance of each writer whose ``enabled(job)`` holds.
    """
    writers = [spec.load()() for spec in WRITERS]
    return [w for w in writers if w.enabled(job)]
