"""The run file: one HDF5 file per job (layout and crash protocol in docs/store.md).

Three ways in:

* :func:`create` (collective, ``mpio``): the whole layout, every dataset preallocated
  (contiguous, allocated at creation), before any rank steps;
* :class:`RunFile` (collective open, ``mpio``): while stepping, each task's owner writes
  raw data only (:meth:`RunFile.commit`), never metadata, so a process killed at any
  instant leaves the HDF5 structure as it was when the file was created;
* :func:`inspect` (one process, read-only): validate a file and summarise it, or raise
  :class:`StoreError` saying what is wrong. Used before resuming and by ``sdmpi info``.

A checkpoint commits ``[samples -> state slot -> slot step -> fsync -> /progress]`` in that
order, into the slot that is *not* current, so ``/progress`` only ever points at data that
are completely on disk.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass

import h5py
import numpy as np

from ..config import JobError, Task, enumerate_tasks, job_hash, parse_job, resume_hash
from ..config import units
from . import trajectory
from .faults import fault

FORMAT = "sdmpi-run"
FORMAT_VERSION = 1
COMPONENT_ORDER = "xx yy zz xy xz yz"
#: stress unit of each time unit (eta_m / time unit)
STRESS_UNITS = {"t_D": "eta_m/t_D", "1/gamma_dot": "eta_m gamma_dot"}


class StoreError(Exception):
    """A file that is not a usable run file; the message says why."""


def task_key(task_id: int) -> str:
    """The group name of a task under /tasks and /checkpoints."""
    return f"{task_id:06d}"


@dataclass(frozen=True)
class TaskLayout:
    """What the store needs of one task's realisation (picklable, for allgather).

    sample_fields  name -> (shape per sample, dtype, unit, description);
    state_fields   name -> (shape, dtype); box (3,) in radii; n_particles;
    radii          (N,) sphere radii in a (all 1 unless the job has size classes).
    """

    sample_fields: dict
    state_fields: dict
    box: tuple
    n_particles: int
    radii: tuple = ()

    @classmethod
    def of(cls, realisation) -> "TaskLayout":
        """The layout of a realisation (see sdmpi.dynamics.Realisation)."""
        samples = {k: (tuple(s), np.dtype(d).str, u, t)
                   for k, (s, d, u, t) in realisation.sample_fields().items()}
        state = {k: (tuple(s), np.dtype(d).str) for k, (s, d) in realisation.state_fields().items()}
        n = int(realisation.n_particles)
        radii = getattr(realisation, "radii", None)
        radii = (1.0,) * n if radii is None else tuple(float(a) for a in radii)
        return cls(samples, state, tuple(float(x) for x in realisation.box), n, radii)


def _nan_if_none(x):
    return math.nan if x is None else x


# --------------------------------------------------------------------------- create


def create(path, job, job_text: str, layouts: dict[int, TaskLayout], comm, versions: str,
           created: str) -> None:
    """Create the complete run file at ``path`` (collective over ``comm``; every rank
    passes the same arguments). ``versions`` is a JSON text, ``created`` UTC ISO 8601."""
    tasks = enumerate_tasks(job)
    with h5py.File(path, "w", driver="mpio", comm=comm, libver="earliest") as f:
        f.attrs.update({
            "format": FORMAT, "format_version": FORMAT_VERSION, "job_text": job_text,
            "job_hash": job_hash(job), "resume_hash": resume_hash(job),
            "time_unit": job.time_unit, "stress_unit": STRESS_UNITS[job.time_unit],
            "component_order": COMPONENT_ORDER, "versions": versions, "created": created,
            "n_tasks": len(tasks)})
        scales = units.scales(job)
        if scales is not None:  # [physical]: SI value of each reduced unit
            f.attrs["physical_units"] = json.dumps(scales.as_dict())
        progress = f.create_dataset("progress", (len(tasks),), "i8", fillvalue=0,
                                    track_times=False)
        progress.attrs["description"] = "samples committed per task (valid up to)"
        for task in tasks:
            _create_task(f, job, task, layouts[task.task_id])
        trajectory.create(f, job, tasks, layouts)


def _create_task(f, job, task: Task, layout: TaskLayout) -> None:
    key = task_key(task.task_id)
    group = f.create_group(f"tasks/{key}")
    group.attrs.update({
        "task_id": task.task_id, "phi": task.phi, "omega": _nan_if_none(task.omega),
        "realisation": task.realisation, "dt": task.dt, "n_steps": task.n_steps,
        "discard_steps": task.discard_steps, "n_particles": layout.n_particles,
        "box": np.array(layout.box), "gamma0": _nan_if_none(job.shear.gamma0)})
    radii = group.create_dataset("radii", data=np.array(layout.radii or
                                                        (1.0,) * layout.n_particles, dtype="f8"),
                                 track_times=False)
    radii.attrs.update({"unit": "a", "description": "sphere radius of each particle"})
    samples = group.create_group("samples")
    for name, (shape, dtype, unit, description) in layout.sample_fields.items():
        ds = samples.create_dataset(name, (task.n_steps, *shape), dtype, track_times=False)
        ds.attrs.update({"unit": unit, "description": description})
    ckpt = f.create_group(f"checkpoints/{key}")
    ckpt.create_dataset("slot_step", (2,), "i8", fillvalue=-1, track_times=False)
    for slot in (0, 1):
        sg = ckpt.create_group(f"slot{slot}")
        for name, (shape, dtype) in layout.state_fields.items():
            sg.create_dataset(name, shape, dtype, track_times=False)


# --------------------------------------------------------------------------- write


class RunFile:
    """An existing run file opened for stepping (collective open and close over ``comm``).

    Between open and close only raw data are written, each task by its owner alone.
    """

    def __init__(self, path, comm):
        self.file = h5py.File(path, "r+", driver="mpio", comm=comm)
        self._fd = os.open(path, os.O_RDONLY)  # for fsync, independent of MPI-IO
        self._progress = self.file["progress"]

    def close(self) -> None:
        """Collective: close the file."""
        os.close(self._fd)
        self._progress = None
        self.file.close()

    def layout_problems(self, task_id: int, layout: TaskLayout) -> list[str]:
        """How the file's datasets for a task differ from ``layout`` (empty: they match)."""
        key, problems = task_key(task_id), []
        expected = {f"tasks/{key}/samples": {k: (s, d) for k, (s, d, _, _) in
                                             layout.sample_fields.items()},
                    f"checkpoints/{key}/slot0": layout.state_fields}
        for where, fields in expected.items():
            group = self.file[where]
            found = {k: (group[k].shape[1:] if where.endswith("samples") else group[k].shape,
                         group[k].dtype.str) for k in group}
            if found != fields:
                problems.append(f"task {task_id}: {where} holds {sorted(found.items())}, "
                                f"the realisation needs {sorted(fields.items())}")
        return problems

    def read_state(self, task_id: int, slot: int) -> dict[str, np.ndarray]:
        """The state committed in checkpoint slot ``slot`` of a task."""
        group = self.file[f"checkpoints/{task_key(task_id)}/slot{slot}"]
        return {name: ds[()] for name, ds in group.items()}

    def samples(self, task_id: int) -> dict:
        """name -> dataset of a task's sample stream."""
        group = self.file[f"tasks/{task_key(task_id)}/samples"]
        return {name: group[name] for name in group}

    def commit(self, task_id: int, datasets: dict, start: int, stop: int, buffers: dict,
               state: dict, slot: int) -> None:
        """Commit samples ``start:stop`` (rows ``0:stop-start`` of ``buffers``) and the
        realisation's ``state`` at step ``stop`` into checkpoint ``slot`` (not the current
        one), then move ``/progress`` to ``stop``. A kill anywhere in between leaves the
        previous checkpoint current and intact."""
        n = stop - start
        for i, (name, ds) in enumerate(datasets.items()):
            ds[start:stop] = buffers[name][:n]
            if i == 0:
                fault("samples")
        ckpt = self.file[f"checkpoints/{task_key(task_id)}"]
        slot_step = ckpt["slot_step"]
        slot_step[slot] = -1                      # invalid while its state is rewritten
        group = ckpt[f"slot{slot}"]
        for name, value in state.items():
            group[name][()] = value
        fault("state")
        slot_step[slot] = stop
        os.fsync(self._fd)                        # all of the above on disk first
        fault("commit")
        self._progress[task_id] = stop


# --------------------------------------------------------------------------- inspect


@dataclass(frozen=True)
class RunSummary:
    """A validated run file: its job, per-task progress and current checkpoint slot."""

    path: str
    job: object
    job_text: str
    attrs: dict
    versions: dict
    tasks: tuple
    progress: np.ndarray
    slots: tuple  # current slot per task; -1 when nothing is committed

    @property
    def complete(self) -> bool:
        return all(int(p) == t.n_steps for p, t in zip(self.progress, self.tasks))


def inspect(path) -> RunSummary:
    """Open ``path`` read-only, check that it is an intact sdmpi run file, summarise it.

    Raises :class:`StoreError` for a file that is not HDF5, truncated, not a run file, of
    an unknown format version, or inconsistent (damaged)."""
    path = str(path)
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise StoreError(f"{path}: not a readable HDF5 file, or truncated/corrupted ({err})")
    with f:
        try:
            return _inspect(f, path)
        except StoreError:
            raise
        except Exception as err:  # h5py raises OSError, KeyError, ValueError, ... on damage
            raise StoreError(f"{path}: damaged run file ({type(err).__name__}: {err})") from None


def _inspect(f, path) -> RunSummary:
    attrs = {k: f.attrs[k] for k in f.attrs}
    if attrs.get("format") != FORMAT:
        raise StoreError(f"{path}: an HDF5 file, but not an sdmpi run file "
                         f"(no format = {FORMAT!r} attribute)")
    if attrs.get("format_version") != FORMAT_VERSION:
        raise StoreError(f"{path}: run-file format version {attrs.get('format_version')} "
                         f"is not supported (this sdmpi reads version {FORMAT_VERSION})")
    text = attrs["job_text"]
    if hashlib.sha256(text.encode()).hexdigest() != attrs.get("job_hash"):
        # job_hash is the SHA-256 of the canonical text as written (by any sdmpi version)
        raise StoreError(f"{path}: damaged run file (job text and job_hash disagree)")
    try:
        job = parse_job(text, source=f"{path} (stored job)")
    except JobError as err:
        raise StoreError(f"{path}: the stored job is not valid for this sdmpi:\n{err}") from None
    tasks = enumerate_tasks(job)
    progress = f["progress"][()]
    if progress.shape != (len(tasks),) or attrs.get("n_tasks") != len(tasks):
        raise StoreError(f"{path}: damaged run file ({len(tasks)} tasks, but /progress "
                         f"has shape {progress.shape})")
    slots = []
    for task, done in zip(tasks, progress):
        key = task_key(task.task_id)
        if not 0 <= done <= task.n_steps:
            raise StoreError(f"{path}: damaged run file (task {task.task_id}: progress "
                             f"{done} outside 0..{task.n_steps})")
        for name, ds in f[f"tasks/{key}/samples"].items():
            if ds.shape[:1] != (task.n_steps,):
                raise StoreError(f"{path}: damaged run file (tasks/{key}/samples/{name} "
                                 f"has shape {ds.shape})")
        slot_step = f[f"checkpoints/{key}/slot_step"][()]
        current = [s for s in (0, 1) if slot_step[s] == done] if done > 0 else []
        if done > 0 and len(current) != 1:
            raise StoreError(f"{path}: damaged run file (task {task.task_id}: no checkpoint "
                             f"for its committed step {done})")
        if current:
            for ds in f[f"checkpoints/{key}/slot{current[0]}"].values():
                ds[()]  # readable
        slots.append(current[0] if current else -1)
    return RunSummary(path, job, text, attrs, json.loads(attrs["versions"]), tasks, progress,
                      tuple(slots))
