"""The sample stream: one row per time step of each task's realisation, in
``tasks/NNNNNN/samples/<name>`` of the run file (shape (n_steps, *shape per sample); layout
in docs/store.md), written at each checkpoint commit and covered by its checksums
(`sdmpi.ensemble.store.RunFile.write_samples`). A `sdmpi.ensemble.writers.Writer`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from ..config import enumerate_tasks, stresses
from .h5 import new_dataset
from .store import task_key

if TYPE_CHECKING:
    import h5py

    from ..config.schema import Job
    from ..config.tasks import Task
    from ..dynamics.realisation import Realisation


class SampleStream:
    """The writer of every task's sample stream (always enabled)."""

    def enabled(self, job: Job) -> bool:
        """Always: every run keeps its samples."""
        return True

    def describe(self, job: Job, done: list[int]) -> None:
        """Nothing: a task's committed samples are its committed steps, which ``sdmpi
        info`` lists."""
        return None

    def create(self, f: h5py.File, job: Job, tasks: Iterable[Task], layouts: dict[int, Any]) -> None:
        """One dataset (n_steps, *shape) per sample field of each task's layout, with its
        unit, description and, for samples that represent another instant, its
        ``sample_offset`` (`sdmpi.config.stresses.sample_offset`)."""
        for task in tasks:
            samples = f.create_group(f"tasks/{task_key(task.task_id)}/samples")
            for name, (shape, dtype, unit, description) in layouts[task.task_id].sample_fields.items():
                ds = new_dataset(samples, name, (task.n_steps, *shape), dtype)
                ds.attrs.update({"unit": unit, "description": description})
                offset = stresses.sample_offset(name)
                if offset is not None:  # the time sample k represents, t_k + offset dt
                    ds.attrs["sample_offset"] = offset

    def recorder(self, job: Job, task: Task, realisation: Realisation, run_file: Any,
                 start: int) -> "SampleRecorder":
        """A buffer of output.checkpoint_every rows per sample field."""
        return SampleRecorder(task, realisation, run_file, start, job.output.checkpoint_every)

    def carry_over(self, old: h5py.File, new: h5py.File, job: Job, task_id: int, done: int) -> None:
        """Copy the rows below ``done`` of every sample dataset."""
        if not done:
            return
        for name, ds in old[f"tasks/{task_key(task_id)}/samples"].items():
            new[f"tasks/{task_key(task_id)}/samples/{name}"][:done] = ds[:done]

    def file_bytes(self, job: Job) -> float:
        """n_steps rows of every sample field, summed over the tasks."""
        from ..dynamics.setup import sample_fields

        row = sum(np.dtype(d).itemsize * math.prod(s) for s, d, _, _ in sample_fields(job).values())
        return float(sum(t.n_steps * row for t in enumerate_tasks(job)))


class SampleRecorder:
    """One task's samples since its last checkpoint, handed to the run file at the next."""

    def __init__(self, task: Task, realisation: Realisation, run_file: Any, start: int, chunk: int):
        self.task_id, self.run_file, self.start = task.task_id, run_file, start
        self.datasets = run_file.samples(task.task_id)
        self.buffers = {k: np.empty((min(chunk, task.n_steps), *shape), dtype)
                        for k, (shape, dtype, _, _) in realisation.sample_fields().items()}

    def before(self, step: int, realisation: Realisation) -> None:
        """Nothing: a sample is known after its step."""

    def after(self, step: int, sample: dict[str, np.ndarray], realisation: Realisation) -> None:
        """Buffer the step's sample."""
        for k, buf in self.buffers.items():
            buf[step - self.start] = sample[k][0]

    def flush(self, stop: int) -> None:
        """Hand rows start..stop-1 to the run file (`RunFile.write_samples`)."""
        self.run_file.write_samples(self.task_id, self.datasets, self.start, stop, self.buffers)
        self.start = stop
