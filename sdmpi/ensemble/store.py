"""The run file: one HDF5 file per job (layout and crash protocol in docs/store.md).

Three ways in:

* :func:`create` (collective, ``mpio``; see :func:`parallel_hdf5`): the whole layout, every dataset preallocated
  (contiguous, allocated at creation), before any rank steps;
* :class:`RunFile` (collective open, ``mpio``): while stepping, each task's owner writes
  raw data only (:meth:`RunFile.commit`), never metadata, so a process killed at any
  instant leaves the HDF5 structure as it was when the file was created;
* :func:`read_summary` (one process, read-only): validate a file and summarise it, or raise
  :class:`StoreError` saying what is wrong. Used before resuming and by ``sdmpi info``.

A checkpoint commits ``[samples -> state slot and checksums -> slot step -> fsync ->
/progress]`` in that order, into the slot that is *not* current, so ``/progress`` only ever
points at data that are completely on disk.

Checksums: CRC-32 (``zlib.crc32``, ISO 3309) of every sample dataset over fixed blocks of
rows (``checksum_block`` rows, fixed when the file is created) and of every state dataset
of a slot. Each slot holds the sample checksums of all rows before its step, so a slot is
a self-contained, verifiable picture of the task up to its step. :func:`read_summary` verifies
them and says, per task, from where a resume may safely continue.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import h5py
import numpy as np

from ..config import JobError, Task, enumerate_tasks, job_hash, parse_job, resume_hash
from ..config import stresses, units
from . import trajectory
from .faults import fault
from .h5 import new_dataset, open_read, parallel_hdf5
from .progress import lock_holder

if TYPE_CHECKING:
    from mpi4py import MPI

    from ..config.schema import Job
    from ..dynamics.realisation import Realisation

FORMAT = "sdmpi-run"
FORMAT_VERSION = 1
COMPONENT_ORDER = "xx yy zz xy xz yz"
#: stress unit of each time unit (eta_m / time unit)
STRESS_UNITS = {"t_D": "eta_m/t_D", "1/gamma_dot": "eta_m gamma_dot"}


#: at most this many checksum blocks per task (larger blocks for longer tasks)
MAX_CHECKSUM_BLOCKS = 4096
#: rows of /sessions, one per session that wrote the file (creation, resume, extension;
#: when full, the last row holds the latest), and the bytes of each (a JSON text)
MAX_SESSIONS, SESSION_BYTES = 64, 1024


class StoreError(Exception):
    """A file that is not a usable run file; the message says why."""


def task_key(task_id: int) -> str:
    """The group name of a task under /tasks and /checkpoints.

    Args:
        task_id: the task's id.

    Returns:
        The six-digit name, e.g. "000007".
    """
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
    def of(cls, realisation: Realisation) -> "TaskLayout":
        """The layout of a realisation (see sdmpi.dynamics.Realisation).

        Args:
            realisation: the task's realisation (sample_fields, state_fields,
                n_particles, box and optionally radii).

        Returns:
            Its layout, dtypes as numpy dtype strings, box and radii in a.
        """
        samples = {k: (tuple(s), np.dtype(d).str, u, t)
                   for k, (s, d, u, t) in realisation.sample_fields().items()}
        state = {k: (tuple(s), np.dtype(d).str) for k, (s, d) in realisation.state_fields().items()}
        n = int(realisation.n_particles)
        radii = getattr(realisation, "radii", None)
        radii = (1.0,) * n if radii is None else tuple(float(a) for a in radii)
        return cls(samples, state, tuple(float(x) for x in realisation.box), n, radii)


def crc32(values: np.ndarray, dtype: np.dtype | str | None = None, running: int = 0) -> int:
    """CRC-32 of an array's bytes (C order, as ``dtype``, default its own), continuing
    ``running`` (the CRC of what precedes it).

    Args:
        values: the array (any shape; array-likes are converted).
        dtype: the dtype whose bytes are checksummed, or None for the array's own.
        running: the CRC-32 of the preceding bytes (0: none).

    Returns:
        The CRC-32, an unsigned 32-bit value.
    """
    return zlib.crc32(np.ascontiguousarray(values, dtype=dtype).view(np.uint8), running)


def checksum_block(job: Job, task: Task) -> int:
    """Rows of a task's sample stream covered by one checksum: ``output.checkpoint_every``
    at creation, larger for tasks of more than MAX_CHECKSUM_BLOCKS such blocks.

    Args:
        job: the validated job.
        task: the task.

    Returns:
        Rows per checksum block.
    """
    return max(job.output.checkpoint_every, -(-task.n_steps // MAX_CHECKSUM_BLOCKS))


def session_row(mode: str, when: str, versions: str) -> bytes:
    """One row of /sessions: ``mode`` ("new", "resume", "extend"), ``when`` (UTC ISO 8601)
    and ``versions`` (the JSON text of sdmpi.ensemble.runner.versions()).

    Args:
        mode: "new", "resume" or "extend".
        when: UTC ISO 8601 time.
        versions: JSON text of the versions.

    Returns:
        The row, a JSON text of at most SESSION_BYTES bytes.

    Raises:
        ValueError: the row is longer than SESSION_BYTES.
    """
    row = json.dumps({"mode": mode, "time": when, "versions": json.loads(versions)}).encode()
    if len(row) > SESSION_BYTES:
        raise ValueError(f"a /sessions row holds {SESSION_BYTES} bytes, this one {len(row)}")
    return row


def read_sessions(f: h5py.File) -> list[dict]:
    """The sessions that wrote the open run file ``f``, oldest first (a file without
    /sessions: its creation, from its root attributes).

    Args:
        f: the open run file.

    Returns:
        One dict (mode, time, versions) per session.
    """
    if "sessions" not in f:
        return [{"mode": "new", "time": f.attrs["created"],
                 "versions": json.loads(f.attrs["versions"])}]
    return [json.loads(row) for row in f["sessions"][()] if row]


def record_session(path: str | os.PathLike, mode: str, when: str, versions: str) -> None:
    """Append a session to /sessions of the run file at ``path`` (one process, under the
    run's lock, no other writer: raw data only, synced). Files without /sessions are left
    as they are.

    Args:
        path: the run file.
        mode: "new", "resume" or "extend".
        when: UTC ISO 8601 time.
        versions: JSON text of the versions.
    """
    with h5py.File(path, "r+") as f:
        if "sessions" not in f:
            return
        rows = f["sessions"]
        used = sum(1 for row in rows[()] if row)
        rows[min(used, len(rows) - 1)] = session_row(mode, when, versions)
        f.flush()
    _fsync(path)


def stack_differences(old: dict, new: dict) -> list[str]:
    """``"name old -> new"`` for every version that differs between two versions dicts.

    Args:
        old: name -> version recorded in the file.
        new: name -> version of this session.

    Returns:
        One line per differing name, old's names first ("(absent)" where missing).
    """
    return [f"{k} {old.get(k, '(absent)')} -> {new.get(k, '(absent)')}"
            for k in list(old) + [k for k in new if k not in old] if old.get(k) != new.get(k)]


def _nan_if_none(x):
    return math.nan if x is None else x


# --------------------------------------------------------------------------- create


#: MPI tag of the commits sent to the writer rank (RemoteRunFile), and the writer's
#: least interval between applying batches of them [s]
COMMIT_TAG, SERVE_EVERY = 7301, 1.0
#: the point of a commit's operation list where what precedes is flushed and synced
SYNC = ("sync",)


def _open_collective(path, mode: str, comm, **kwargs) -> h5py.File:
    """``h5py.File`` opened collectively over ``comm`` through MPI-IO; on one rank
    without parallel HDF5, opened directly (the same file: the layout does not depend
    on the driver)."""
    if parallel_hdf5():
        return h5py.File(path, mode, driver="mpio", comm=comm, **kwargs)
    if comm.Get_size() == 1:
        return h5py.File(path, mode, **kwargs)
    raise StoreError(f"{comm.Get_size()} ranks share the run file, which needs h5py built "
                     "with MPI (parallel HDF5)")


def create(path: str | os.PathLike, job: Job, job_text: str, layouts: dict[int, TaskLayout],
           comm: MPI.Intracomm, versions: str, created: str, backend: str | None = None) -> None:
    """Create the complete run file at ``path`` (collective over ``comm``; every rank
    passes the same arguments). ``versions`` is a JSON text, ``created`` UTC ISO 8601,
    ``backend`` the solver backend the tasks solve on (solver.backend with "auto"
    resolved), recorded as the ``solver_backend`` attribute (None: not recorded).

    Args:
        path: the run file to create (overwritten).
        job: the validated job.
        job_text: the job's canonical text, stored in the file.
        layouts: task id -> TaskLayout, for every task of the job.
        comm: the ranks that create it together.
        versions: JSON text of the versions.
        created: UTC ISO 8601 creation time.
        backend: the resolved solver backend, or None.

    Raises:
        StoreError: several ranks without parallel HDF5.
    """
    tasks = enumerate_tasks(job)
    with _open_collective(path, "w", comm, libver="earliest") as f:
        f.attrs.update({
            "format": FORMAT, "format_version": FORMAT_VERSION, "job_text": job_text,
            "job_hash": job_hash(job), "resume_hash": resume_hash(job),
            "time_unit": job.time_unit, "stress_unit": STRESS_UNITS[job.time_unit],
            "component_order": COMPONENT_ORDER, "versions": versions, "created": created,
            "n_tasks": len(tasks)})
        if backend is not None:
            f.attrs["solver_backend"] = backend
        scales = units.scales(job)
        if scales is not None:  # [physical]: SI value of each reduced unit
            f.attrs["physical_units"] = json.dumps(scales.as_dict())
        progress = new_dataset(f, "progress", (len(tasks),), "i8", fillvalue=0)
        progress.attrs["description"] = "samples committed per task (valid up to)"
        sessions = new_dataset(f, "sessions", (MAX_SESSIONS,), f"S{SESSION_BYTES}")
        sessions[0] = session_row("new", created, versions)
        sessions.attrs["description"] = (
            "one JSON text per session that wrote the file: mode (new, resume, extend), "
            "time (UTC), versions (sdmpi and its library stack); empty rows unused")
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
    radii = new_dataset(group, "radii", data=np.array(layout.radii or
                                                      (1.0,) * layout.n_particles, dtype="f8"))
    radii.attrs.update({"unit": "a", "description": "sphere radius of each particle"})
    samples = group.create_group("samples")
    for name, (shape, dtype, unit, description) in layout.sample_fields.items():
        ds = new_dataset(samples, name, (task.n_steps, *shape), dtype)
        ds.attrs.update({"unit": unit, "description": description})
        offset = stresses.sample_offset(name)
        if offset is not None:  # the time sample k represents, t_k + offset dt
            ds.attrs["sample_offset"] = offset
    ckpt = f.create_group(f"checkpoints/{key}")
    new_dataset(ckpt, "slot_step", (2,), "i8", fillvalue=-1)
    block = checksum_block(job, task)
    fields = sorted(layout.sample_fields)
    table = new_dataset(ckpt, "sample_crc", (2, -(-task.n_steps // block), len(fields)), "u4",
                        fillvalue=0)
    table.attrs.update({"block": block, "fields": " ".join(fields), "description":
                        "per slot: CRC-32 of each sample dataset's rows [b*block, "
                        "min((b+1)*block, slot step)) for block b"})
    names = sorted(layout.state_fields)
    slot_crc = new_dataset(ckpt, "state_crc", (2, len(names) + 1), "u4", fillvalue=0)
    slot_crc.attrs.update({"fields": " ".join(names + ["sample_crc"]), "description":
                           "per slot: CRC-32 of each state dataset, then of the slot's row "
                           "of sample_crc"})
    for slot in (0, 1):
        sg = ckpt.create_group(f"slot{slot}")
        for name, (shape, dtype) in layout.state_fields.items():
            new_dataset(sg, name, shape, dtype)


#: bytes per task for groups, attributes and dataset headers (measured: about 12 KiB)
TASK_OVERHEAD = 16 * 2 ** 10
#: state bytes per particle and slot assumed by the estimate (positions, Maxwell modes,
#: contact history: a generous bound)
STATE_PER_PARTICLE = 16 * 8


def run_file_bytes(job: Job) -> float:
    """Estimated size of a job's run file: every sample dataset and trajectory frame
    (exact: they are all allocated at creation), two state slots per task, the per-task
    overhead and /sessions.

    Args:
        job: the validated job.

    Returns:
        The estimate, in bytes.
    """
    from ..dynamics.setup import sample_fields

    row = sum(np.dtype(d).itemsize * math.prod(s) for s, d, _, _ in sample_fields(job).values())
    per_task = TASK_OVERHEAD + 2 * STATE_PER_PARTICLE * job.system.n_particles
    return float(sum(t.n_steps * row + per_task for t in enumerate_tasks(job))
                 + trajectory.file_bytes(job) + MAX_SESSIONS * SESSION_BYTES)


# --------------------------------------------------------------------------- write


class RunFile:
    """An existing run file opened for stepping: :meth:`open` gives each rank its handle.

    Between open and close only raw data are written, each task's by its owner alone.
    A commit is an ordered list of writes, syncs and fault points (:meth:`commit`); this
    class applies it to the file at once. With parallel HDF5 every rank holds a
    :class:`RunFile` (collective MPI-IO open); with a serial h5py on several ranks world
    rank 0 holds the one writable handle and applies, between its own steps
    (:meth:`serve`), the commits the other ranks send it (:class:`RemoteRunFile`), in the
    order each rank sent them: the same writes as with parallel HDF5, so the same file.
    """

    def __init__(self, path, comm, *, writable: bool = True, senders: int = 0):
        self.comm = comm
        if writable:
            self.file = _open_collective(path, "r+", comm) if senders == 0 \
                else h5py.File(path, "r+")
            self._fd = os.open(path, os.O_RDONLY)  # for fsync, independent of MPI-IO
        else:
            self.file, self._fd = open_read(path), None
        # serial HDF5 keeps raw data in its own buffers until the file is flushed; MPI-IO
        # writes them through at once (and a flush there would be collective)
        self._buffered = not parallel_hdf5()
        self._senders = senders  # ranks whose commits this one applies, until they close
        self._checksums = {}  # task id -> (sample checksum table, block) being extended
        self._pending = []    # operations of the next commit (trajectory frames first)
        self.t_checksum = 0.0  # s spent computing checksums
        self.t_served, self.n_served = 0.0, 0  # s spent applying other ranks' commits, and how many
        self._last_served = 0.0

    @classmethod
    def open(cls, path: str | os.PathLike, comm: MPI.Intracomm) -> "RunFile":
        """Collective over ``comm``: this rank's handle of the run file at ``path``.

        Args:
            path: the existing run file.
            comm: the ranks that step together (all open it).

        Returns:
            A RunFile, or a RemoteRunFile on ranks other than 0 without parallel HDF5.
        """
        if parallel_hdf5() or comm.size == 1:
            return cls(path, comm)
        if comm.rank == 0:
            return cls(path, comm, senders=comm.size - 1)
        return RemoteRunFile(path, comm)

    def close(self) -> None:
        """Collective: apply what the other ranks still send, then close the file."""
        while self._senders:
            self.serve(wait=True)
        if self._fd is not None:
            os.close(self._fd)
        self.file.close()

    def serve(self, wait: bool = False) -> None:
        """The writer: apply the commits the other ranks have sent, at most every
        SERVE_EVERY seconds, all that have arrived as one batch (``wait``: now, after at
        least one message, blocking). Other handles: nothing to do.

        Args:
            wait: block until at least one message has arrived, and apply at once.
        """
        if not self._senders:
            return
        if not wait and time.monotonic() - self._last_served < SERVE_EVERY:
            return
        from mpi4py import MPI  # initialised by the driver (sdmpi.ensemble.runner)

        batch, status = [], MPI.Status()
        while wait or self.comm.iprobe(source=MPI.ANY_SOURCE, tag=COMMIT_TAG, status=status):
            ops = self.comm.recv(source=MPI.ANY_SOURCE, tag=COMMIT_TAG)
            if ops is None:  # that rank has closed
                self._senders -= 1
            else:
                batch.append(ops)
            wait = False
        if batch:
            t0 = time.perf_counter()
            self._apply(batch)
            self.t_served += time.perf_counter() - t0
            self.n_served += len(batch)
        self._last_served = time.monotonic()

    def layout_problems(self, task_id: int, layout: TaskLayout) -> list[str]:
        """How the file's datasets for a task differ from ``layout`` (empty: they match).

        Args:
            task_id: the task.
            layout: the layout its realisation needs.

        Returns:
            One line per differing group.
        """
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
        """The state committed in checkpoint slot ``slot`` of a task.

        Args:
            task_id: the task.
            slot: the checkpoint slot, 0 or 1.

        Returns:
            name -> array, as the realisation's get_state gave it.
        """
        group = self.file[f"checkpoints/{task_key(task_id)}/slot{slot}"]
        return {name: ds[()] for name, ds in group.items()}

    def begin(self, task_id: int, slot: int) -> None:
        """Prepare a task's commits from checkpoint ``slot`` (-1: from scratch): take the
        slot's sample checksums as the running ones.

        Args:
            task_id: the task.
            slot: its current checkpoint slot, 0 or 1, or -1.
        """
        ckpt = self.file[f"checkpoints/{task_key(task_id)}"]
        if "sample_crc" in ckpt:  # a file without checksums is read and resumed unverified
            table = ckpt["sample_crc"]
            rows = table[slot] if slot >= 0 else np.zeros(table.shape[1:], "u4")
            self._checksums[task_id] = (rows, int(table.attrs["block"]))

    def samples(self, task_id: int) -> dict[str, h5py.Dataset]:
        """name -> dataset of a task's sample stream.

        Args:
            task_id: the task.

        Returns:
            The datasets, each of shape (n_steps, *shape per sample).
        """
        group = self.file[f"tasks/{task_key(task_id)}/samples"]
        return {name: group[name] for name in group}

    def write(self, path: str, rows: slice, values: np.ndarray) -> None:
        """Write ``values`` into ``rows`` of the dataset at ``path`` with the next commit,
        ahead of its samples (trajectory frames, sdmpi.ensemble.trajectory.Recorder).

        Args:
            path: the dataset's path in the file.
            rows: the rows (first axis) to write.
            values: the values, shaped as those rows.
        """
        self._pending.append(("write", path, rows, values))

    def commit(self, task_id: int, datasets: dict[str, h5py.Dataset], start: int, stop: int,
               buffers: dict[str, np.ndarray], state: dict[str, np.ndarray], slot: int) -> None:
        """Commit samples ``start:stop`` (rows ``0:stop-start`` of ``buffers``) and the
        realisation's ``state`` at step ``stop`` into checkpoint ``slot`` (not the current
        one), then move ``/progress`` to ``stop``. A kill anywhere in between leaves the
        previous checkpoint current and intact.

        Args:
            task_id: the task.
            datasets: name -> sample dataset (`samples`).
            start: first step of the samples committed.
            stop: the step after them, the checkpoint's step.
            buffers: name -> sample values, at least stop - start rows.
            state: the realisation's state at step stop (get_state).
            slot: the checkpoint slot written, 0 or 1.
        """
        n, ops = stop - start, self._pending
        self._pending = []
        for i, (name, ds) in enumerate(datasets.items()):
            ops.append(("write", ds.name, slice(start, stop), buffers[name][:n].copy()))
            if i == 0:
                ops.append(("fault", "samples"))
        key = f"checkpoints/{task_key(task_id)}"
        # the operations own copies of the buffers and the running checksums, which change
        # after the call (a commit may be applied later, by another rank)
        ops.append(("write", f"{key}/slot_step", slot, -1))  # invalid while rewritten
        group = self.file[f"{key}/slot{slot}"]
        for name, value in state.items():
            ops.append(("write", f"{key}/slot{slot}/{name}", (), np.array(value)))
        if task_id in self._checksums:
            t0 = time.perf_counter()
            table, block = self._checksums[task_id]
            for j, name in enumerate(sorted(datasets)):
                _extend_checksums(table[:, j], block, start, buffers[name][:n],
                                  datasets[name].dtype)
            crcs = [crc32(state[k], group[k].dtype) for k in sorted(state)] + [crc32(table)]
            self.t_checksum += time.perf_counter() - t0
            ops += [("write", f"{key}/sample_crc", slot, table.copy()),
                    ("write", f"{key}/state_crc", slot, crcs)]
        ops += [("fault", "state"), ("write", f"{key}/slot_step", slot, stop),
                SYNC,                                   # all of the above on disk first
                ("fault", "commit"), ("write", "progress", task_id, stop)]
        self._submit(ops)

    def _submit(self, ops: list) -> None:
        self._apply([ops])

    def _apply(self, commits: list) -> None:
        """Apply commits (operation lists, :meth:`commit`, in the order each task made
        them) in rounds that hold at most one commit per task: per round, what each does
        before its ``sync``, one flush and fsync, then what each does after it (its
        ``/progress``). Two commits of one task never share a round: the second rewrites
        the slot that ``/progress`` points to until the first one's ``/progress`` is
        written."""
        rounds, seen = [], {}
        for ops in commits:
            task_id = ops[-1][2]  # the last operation moves /progress[task_id]
            k = seen[task_id] = seen.get(task_id, -1) + 1
            if k == len(rounds):
                rounds.append([])
            rounds[k].append(ops)
        for round_ in rounds:
            after = []
            for ops in round_:
                cut = ops.index(SYNC)
                self._run(ops[:cut])
                after.append(ops[cut + 1:])
            self._flush()
            os.fsync(self._fd)  # everything before the syncs is on disk first
            for ops in after:
                self._run(ops)
            self._flush()       # readers of a live file see the new /progress

    def _run(self, ops: list) -> None:
        for op in ops:
            if op[0] == "write":
                _, path, rows, values = op
                self.file[path][rows] = values
            else:
                fault(op[1])

    def _flush(self) -> None:
        """Hand HDF5's buffered writes to the operating system (serial HDF5 only)."""
        if self._buffered:
            self.file.flush()


class RemoteRunFile(RunFile):
    """A rank's handle when a serial h5py gives world rank 0 the only writable one: the
    file is read directly (states, checksum tables, layouts), and each commit is sent to
    rank 0, which applies it (:meth:`RunFile.serve`)."""

    #: commits in flight at most; the next one waits for the oldest to be received
    IN_FLIGHT = 4

    def __init__(self, path, comm):
        super().__init__(path, comm, writable=False)
        self._requests = []

    def _submit(self, ops: list) -> None:
        if len(self._requests) >= self.IN_FLIGHT:
            self._requests.pop(0).wait()
        self._requests.append(self.comm.isend(ops, dest=0, tag=COMMIT_TAG))

    def close(self) -> None:
        """Collective: everything sent, then tell rank 0 this rank is done."""
        for request in self._requests:
            request.wait()
        self.comm.send(None, dest=0, tag=COMMIT_TAG)
        self.file.close()


def checksum_slot(f: h5py.File, task_id: int, slot: int, step: int) -> None:
    """Write the checksums of checkpoint ``slot`` (its state at ``step``) of a task from
    the data in the open file ``f``: the sample checksums of rows below ``step``, then the
    state's (as :meth:`RunFile.commit` does; used when data are copied into a new layout,
    sdmpi.ensemble.extension).

    Args:
        f: the run file, open for writing.
        task_id: the task.
        slot: the checkpoint slot, 0 or 1.
        step: the slot's step.
    """
    key = task_key(task_id)
    ckpt, samples = f[f"checkpoints/{key}"], f[f"tasks/{key}/samples"]
    if "sample_crc" not in ckpt:
        return
    table = np.zeros(ckpt["sample_crc"].shape[1:], "u4")
    block = int(ckpt["sample_crc"].attrs["block"])
    for j, name in enumerate(sorted(samples)):
        _extend_checksums(table[:, j], block, 0, samples[name][:step], samples[name].dtype)
    group = ckpt[f"slot{slot}"]
    ckpt["sample_crc"][slot] = table
    ckpt["state_crc"][slot] = [crc32(group[name][()]) for name in sorted(group)] + [crc32(table)]


def _extend_checksums(column, block: int, start: int, rows, dtype) -> None:
    """Extend one dataset's block checksums (``column``, one per block) by ``rows``, the
    samples from row ``start`` on."""
    lo, stop = start, start + len(rows)
    while lo < stop:
        b = lo // block
        hi = min((b + 1) * block, stop)
        running = 0 if lo == b * block else int(column[b])
        column[b] = crc32(rows[lo - start:hi - start], dtype, running)
        lo = hi


def fall_back(path: str | os.PathLike, progress: dict[int, int],
              damaged: list[tuple[int, int]]) -> None:
    """Undo what failed its checksums (one process, under the run's lock, before the
    run opens the file): move ``/progress`` back (task id -> step, the resume point
    :func:`read_summary` found), sync, then mark every damaged ``(task id, slot)`` as never
    written (``slot_step`` -1), sync. Each stage leaves a consistent file.

    Args:
        path: the run file.
        progress: task id -> step to move /progress back to.
        damaged: (task id, slot) of each damaged checkpoint slot.
    """
    with h5py.File(path, "r+") as f:
        for tid, step in progress.items():
            f["progress"][tid] = step
        f.flush()
        _fsync(path)
        for tid, slot in damaged:
            f[f"checkpoints/{task_key(tid)}/slot_step"][slot] = -1
        f.flush()
    _fsync(path)


def _fsync(path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


# --------------------------------------------------------------------------- read_summary


@dataclass(frozen=True)
class Damage:
    """Committed data that fail their checksum: ``what`` is "samples" (committed samples,
    which a reduction would read) or "state" (a checkpoint slot); ``where`` names the
    dataset and step range, or the slot and its step."""

    task_id: int
    what: str
    where: str
    slot: int = -1  # the damaged checkpoint slot ("state")

    def __str__(self) -> str:
        return f"task {self.task_id}: {self.where}"


@dataclass(frozen=True)
class RunSummary:
    """A validated run file: its job, per-task progress and current checkpoint slot; the
    checksum verification's findings (``damage``) and, per task, the (step, slot) from
    which a resume continues safely (``resume``: the current checkpoint when intact, else
    the latest intact one before any damage, else (0, -1), the task's start)."""

    path: str
    job: object
    job_text: str
    attrs: dict
    versions: dict
    tasks: tuple
    progress: np.ndarray
    slots: tuple  # current slot per task; -1 when nothing is committed
    checksummed: bool = False  # False: the file has no checksums (not verified)
    damage: tuple = ()
    resume: tuple = ()
    sessions: tuple = ()  # dicts: mode, time, versions (read_sessions)

    @property
    def complete(self) -> bool:
        """Whether every task has committed all its steps.

        Returns:
            True when /progress equals n_steps for every task.
        """
        return all(int(p) == t.n_steps for p, t in zip(self.progress, self.tasks))


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def is_run_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` is (or was, before damage) an sdmpi run file: HDF5 with
    ``format = "sdmpi-run"``, or, if HDF5 cannot open it, an HDF5 signature and that
    attribute's value among its first 64 KiB (where the root attributes are written).

    Args:
        path: any file.

    Returns:
        Whether it is (or was) a run file; False if it cannot be read.
    """
    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("format") == FORMAT
    except Exception:  # not HDF5, or damaged: look at the bytes
        pass
    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError:
        return False
    return head.startswith(HDF5_SIGNATURE) and FORMAT.encode() in head


#: reads of a live file (a run holds its lock) before a finding is reported, and the
#: pause between them [s]: a checkpoint that moves while the file is read is read again
LIVE_READS, LIVE_PAUSE = 5, 0.5


def read_summary(path: str | os.PathLike) -> RunSummary:
    """Open ``path`` read-only, check that it is an intact sdmpi run file, summarise it.

    Raises :class:`StoreError` for a file that is not HDF5, truncated, not a run file, of
    an unknown format version, or inconsistent (damaged). A file that a running job is
    writing (it holds the run's lock, :func:`sdmpi.ensemble.progress.lock_holder`) is
    read without HDF5's file lock, only its current checkpoints are verified (the other
    slot may be being rewritten), and a read that disagrees with itself is repeated
    (LIVE_READS times, LIVE_PAUSE apart) before :class:`StoreError` says the file is being
    written; a live file is never reported damaged.

    Args:
        path: the run file.

    Returns:
        Its summary.

    Raises:
        StoreError: not a usable run file (the message says why).
    """
    path = str(path)
    holder = lock_holder(path)
    if holder is None:
        return _inspect_once(path, live=False)
    for _ in range(LIVE_READS):
        try:
            summary = _inspect_once(path, live=True)
            if not summary.damage:
                return summary
        except StoreError:
            pass
        if lock_holder(path) is None:  # the run ended meanwhile: a plain read decides
            return _inspect_once(path, live=False)
        time.sleep(LIVE_PAUSE)
    raise StoreError(f"{path}: being written by a running job ({holder}), which changed it "
                     f"during each of {LIVE_READS} reads; try again, or wait for it to stop")


def _inspect_once(path: str, live: bool) -> RunSummary:
    try:
        f = open_read(path)
    except OSError as err:
        raise StoreError(f"{path}: not a readable HDF5 file, or truncated/corrupted ({err})")
    with f:
        try:
            return _read_summary(f, path, live)
        except StoreError:
            raise
        except Exception as err:  # h5py raises OSError, KeyError, ValueError, ... on damage
            raise StoreError(f"{path}: damaged run file ({type(err).__name__}: {err})") from None


def _read_summary(f, path, live: bool) -> RunSummary:
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
    checksummed = all("sample_crc" in f[f"checkpoints/{task_key(t.task_id)}"] for t in tasks)
    damage, resume = [], []
    for task, done, slot in zip(tasks, progress, slots):
        if checksummed:
            found, start = _verify_task(f, task, int(done), live)
            damage += found
            resume.append(start)
        else:
            resume.append((int(done), slot))
    return RunSummary(path, job, text, attrs, json.loads(attrs["versions"]), tasks, progress,
                      tuple(slots), checksummed, tuple(damage), tuple(resume),
                      tuple(read_sessions(f)))


def _verify_task(f, task, done: int, live: bool = False):
    """Verify one task's checkpoint slots (state) and committed samples against their
    checksums (``live``: the current slot alone). Returns (list of :class:`Damage`,
    (step, slot) to resume from)."""
    tid, key = task.task_id, task_key(task.task_id)
    ckpt = f[f"checkpoints/{key}"]
    slot_step = ckpt["slot_step"][()]
    damage, intact = [], []
    for slot in sorted((0, 1), key=lambda s: -slot_step[s]):
        step = int(slot_step[slot])
        if not 0 < step <= done or (live and step != done):
            continue  # never written, being written, or ahead of /progress (not committed)
        if _slot_intact(ckpt, slot):
            intact.append((step, slot))
        else:
            damage.append(Damage(tid, "state", f"checkpoint slot {slot} (state at step "
                                               f"{step}) fails its checksum", slot))
    verified = intact[0][0] if intact else 0
    first_bad = done
    if verified < done:
        damage.append(Damage(tid, "samples", f"samples of steps {verified}..{done - 1} "
                                             "cannot be verified (their checkpoint is damaged)"))
        first_bad = verified
    if intact:
        first_bad = min(first_bad, _verify_samples(f[f"tasks/{key}/samples"], ckpt,
                                                   intact[0], tid, damage))
    return damage, next((s for s in intact if s[0] <= first_bad), (0, -1))


def _slot_intact(ckpt, slot: int) -> bool:
    """Whether a slot's state datasets and its sample checksums match its state_crc."""
    group = ckpt[f"slot{slot}"]
    found = [crc32(group[name][()]) for name in sorted(group)]
    found.append(crc32(ckpt["sample_crc"][slot]))
    return found == [int(c) for c in ckpt["state_crc"][slot]]


def _verify_samples(samples, ckpt, trusted, tid: int, damage: list) -> int:
    """Check the sample rows before the intact slot ``trusted`` = (step, slot) against its
    checksums; append a :class:`Damage` per dataset and damaged step range; return the
    first damaged row (``trusted`` step if none)."""
    step, slot = trusted
    table = ckpt["sample_crc"]
    block, fields = int(table.attrs["block"]), table.attrs["fields"].split()
    if fields != sorted(samples):
        raise StoreError(f"{samples.file.filename}: damaged run file (task {tid}: sample checksums name the datasets "
                         f"{fields}, the file has {sorted(samples)})")
    expected = table[slot]
    first_bad = step
    for j, name in enumerate(fields):
        ds, bad = samples[name], []
        for b in range(-(-step // block)):
            lo, hi = b * block, min((b + 1) * block, step)
            if crc32(ds[lo:hi]) != int(expected[b, j]):
                if bad and bad[-1][1] == lo:
                    bad[-1][1] = hi
                else:
                    bad.append([lo, hi])
        for lo, hi in bad:
            damage.append(Damage(tid, "samples", f"samples/{name} of steps {lo}..{hi - 1} "
                                                 "fail their checksum"))
        first_bad = min([first_bad] + [lo for lo, _ in bad])
    return first_bad
