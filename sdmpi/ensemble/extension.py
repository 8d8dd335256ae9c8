"""Lengthening a run (``sdmpi run --extend``): the same job with longer tasks.

Every dataset of a run file is preallocated at its final length (docs/store.md), so a run
is extended by writing a new file: rank 0 alone creates the longer job's complete layout
into ``RUN.h5.part`` (:func:`sdmpi.ensemble.store.create` on MPI_COMM_SELF), copies every
committed value into it (what each writer committed below each task's ``/progress``:
`sdmpi.ensemble.writers.Writer.carry_over`, the samples and trajectory frames; both
checkpoint slots and their steps; ``/progress``) and the recorded solver
backend (``solver_backend``: the extended run solves on it), syncs it, and renames
it to ``RUN.h5``. A kill before the rename leaves ``RUN.h5`` as it was (the leftover
``.part`` is overwritten by the next attempt); after it, the file is an ordinary
resumable run of the longer job. The run then resumes from each task's last checkpoint:
a realisation is a pure function of (job, task) that does not depend on the number of
steps, so the extended run ends with the data of a run created at the longer length.
"""

from __future__ import annotations

import datetime
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import h5py
from mpi4py import MPI

from ..config import enumerate_tasks
from . import store, writers
from .faults import fault

if TYPE_CHECKING:
    from ..config.schema import Job


def problems(summary: store.RunSummary, job: Job) -> list[str]:
    """Why ``job`` cannot extend the run of ``summary`` (same job up to the length keys,
    checked by the caller): damaged data, tasks that would be shorter, or a changed time
    step; one line per frequency.

    Args:
        summary: the existing run file's summary.
        job: the longer job.

    Returns:
        The problems, one line each; empty when the run can be extended.
    """
    if summary.damage:
        return [f"it holds damaged data ({summary.damage[0]}); run it once without "
                "--extend (it recomputes from the last intact checkpoint), then extend"]
    out = {}
    for old, new in zip(summary.tasks, enumerate_tasks(job)):
        where = "every task" if new.omega is None else f"omega = {new.omega:g}"
        if new.dt != old.dt:
            out[where] = f"{where}: time step {new.dt!r} differs from the run's {old.dt!r}"
        elif new.n_steps < old.n_steps:
            out[where] = (f"{where}: {new.n_steps} steps per task, shorter than the run's "
                          f"{old.n_steps}; a run can only be lengthened")
    return list(out.values())


def extend(path: Path, job: Job, job_text: str, versions: str) -> store.RunSummary:
    """Replace the run file ``path`` by the same run lengthened to ``job`` (one process;
    see the module docstring). Returns the summary of the extended file.

    Args:
        path: the run file RUN.h5.
        job: the longer job (checked by `problems`).
        job_text: the job file's text, stored in the new file.
        versions: the software versions of this session (JSON).

    Returns:
        The summary of the extended file.
    """
    summary = store.read_summary(path)
    part = path.with_name(path.name + ".part")
    with h5py.File(path, "r") as old:
        layouts = {t.task_id: _layout(old, t.task_id) for t in summary.tasks}
        history = json.loads(old.attrs.get("extended", "[]"))
        history.append({"time": _now(), "job_hash": old.attrs["job_hash"]})
        store.create(part, job, job_text, layouts, MPI.COMM_SELF, versions,
                     old.attrs["created"], old.attrs.get("solver_backend"))
        with h5py.File(part, "r+") as new:
            new.attrs["extended"] = json.dumps(history)
            sessions = new["sessions"]
            rows = [json.dumps(s).encode() for s in store.read_sessions(old)]
            rows.append(store.session_row("extend", _now(), versions))
            sessions[:min(len(rows), len(sessions))] = rows[-len(sessions):]
            for task, done in zip(summary.tasks, summary.progress):
                for writer in writers.active(job):
                    writer.carry_over(old, new, job, task.task_id, int(done))
                _copy_checkpoints(old, new, task.task_id, int(done))
            new["progress"][:] = old["progress"][()]
            new.flush()
    with open(part, "rb+") as f:
        os.fsync(f.fileno())
    fault("extend")
    os.replace(part, path)
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)
    return store.read_summary(path)


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _layout(f, task_id: int) -> store.TaskLayout:
    """A task's layout as the run file holds it (every task, run or not)."""
    key = store.task_key(task_id)
    samples = {name: (ds.shape[1:], ds.dtype.str, ds.attrs["unit"], ds.attrs["description"])
               for name, ds in f[f"tasks/{key}/samples"].items()}
    state = {name: (ds.shape, ds.dtype.str)
             for name, ds in f[f"checkpoints/{key}/slot0"].items()}
    task = f[f"tasks/{key}"]
    radii = tuple(float(a) for a in task["radii"][()])
    return store.TaskLayout(samples, state, tuple(float(x) for x in task.attrs["box"]),
                            int(task.attrs["n_particles"]), radii)


def _copy_checkpoints(old, new, task_id: int, done: int) -> None:
    """Copy a task's checkpoint slots and their steps; the slots' checksums are computed
    afresh from the samples already carried over (the longer layout's checksum blocks may
    differ)."""
    key = store.task_key(task_id)
    old_ckpt, new_ckpt = old[f"checkpoints/{key}"], new[f"checkpoints/{key}"]
    new_ckpt["slot_step"][:] = old_ckpt["slot_step"][()]
    for slot in (0, 1):
        for name, ds in old_ckpt[f"slot{slot}"].items():
            new_ckpt[f"slot{slot}/{name}"][()] = ds[()]
        step = int(old_ckpt["slot_step"][slot])
        if 0 < step <= done:
            store.checksum_slot(new, task_id, slot, step)
