"""The MPI driver of ``sdmpi run``: check, create or resume, farm out, step, checkpoint.

Phases, in order (collective over MPI_COMM_WORLD unless said otherwise):

1. Rank 0 alone checks everything (job, output path, an existing run file and whether
   it holds the same job) and takes the run's lock; nothing is written if any check
   fails (:class:`BadInput` on every rank; rank 0's carries the message).
2. Groups of ``ensemble.ranks_per_task`` ranks; tasks still to run are assigned to
   groups by :func:`sdmpi.ensemble.farm.assign`; each rank builds the realisations of
   its group's tasks (on the group's sub-communicator when the group has several ranks:
   all of them step each task redundantly and solve collectively).
3. A new run: the leaders' task layouts are gathered and the whole file is created into
   ``RUN.h5.part`` and renamed to ``RUN.h5`` when complete (no half-created run files).
4. The file is opened by all ranks; group leaders step their tasks and commit samples and
   state every ``output.checkpoint_every`` steps (absolute step multiples) and when a
   stop is requested (SIGTERM, SIGINT, SIGUSR1: finish the step, commit, stop).
5. Rank 0 collects progress until every leader is done; the file is closed; the run is
   complete or resumable.

Any other exception on any rank aborts the whole MPI job (exit 1): committed data stay
valid, and running the same command resumes.
"""

from __future__ import annotations

import dataclasses
import datetime
import errno
import hashlib
import importlib.metadata
import json
import os
import platform
import signal
import socket
import sys
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import h5py
import numpy as np
from mpi4py import MPI

from .. import __version__
from .._blas_kernel import openblas_kernel
from .._kernel_cache import kernels_cached
from ..config import (LAYOUT_KEYS, LENGTH_KEYS, JobError, canonical_text, enumerate_tasks,
                      extension_hash, parse_job, resources, resume_hash)
from ..config.checks import scheme_problems
from ..dynamics.checks import load_job
from ..dynamics.setup import job_backend
from ..dynamics.realisation import RealisationFailed
from ..registry import SOLVER_BACKENDS
from . import extension, start_file, store, writers
from .farm import assign, remaining_costs, split_groups
from .faults import fault
from .progress import (PipeSafe, Progress, RunLocked, lock_holder, logs_dir, rank_logger,
                       take_lock)

STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1)


class BadInput(Exception):
    """The run was refused before any work. On world rank 0 the message says why; on the
    other ranks it is None (rank 0 alone prints)."""


@dataclass(frozen=True)
class Plan:
    """What rank 0 decided, broadcast to all ranks."""

    job_text: str      # canonical text of the job to run (this command's layout keys)
    mode: str          # "new", "resume" or "complete"
    progress: tuple    # committed steps per task
    slots: tuple       # current checkpoint slot per task (-1: none)
    versions: str      # JSON
    created: str       # UTC ISO 8601
    notes: tuple = ()  # damage found by the checksums, and where tasks resume instead
    rewind: tuple = ()    # (task id, step): /progress to move back before running
    damaged: tuple = ()   # (task id, slot): checkpoint slots that fail their checksums
    extension: str = ""  # what --extend did (said before the run starts)
    backend: str = ""    # the solver backend the tasks solve on ("auto" resolved)


def run(job_path: str | os.PathLike, overrides: Iterable[str], output: str | os.PathLike, *,
        new: bool = False, extend: bool = False,
        realisation_factory: Callable[..., Any] | None = None,
        comm: MPI.Intracomm | None = None, stream: TextIO | None = None) -> bool:
    """Run or resume the job in ``job_path`` (with ``--set`` ``overrides``) into the run
    file ``output``; ``new`` replaces an existing file; ``extend`` lengthens the existing
    run to the job's longer tasks first (:mod:`.extension`). Collective over ``comm``
    (default MPI_COMM_WORLD). Returns True when every task is complete, False when
    stopped by a signal (resumable). Raises :class:`BadInput` (nothing written).

    ``realisation_factory(job, task)`` defaults to :class:`sdmpi.dynamics.Realisation`;
    with ``ensemble.ranks_per_task > 1`` it is called as ``(job, task, comm=group)``, the
    sub-communicator of the ranks that step the task together.

    Args:
        job_path: the job file (TOML).
        overrides: ``--set`` strings "section.key=LITERAL".
        output: the run file RUN.h5.
        new: replace an existing run file.
        extend: lengthen the existing run to the job's longer tasks first.
        realisation_factory: builds a task's realisation, or None for the default.
        comm: the communicator of all ranks, or None for MPI_COMM_WORLD.
        stream: where rank 0 prints progress, or None for stdout.

    Returns:
        True when every task is complete, False when stopped by a signal.

    Raises:
        BadInput: the run was refused (nothing written).
    """
    comm = comm or MPI.COMM_WORLD
    lock = None
    try:
        plan, lock = _agree(comm, job_path, overrides, Path(output), new, extend)
        return _execute(comm, plan, Path(output), realisation_factory,
                        PipeSafe(stream or sys.stdout))
    except BadInput:
        raise
    except Exception as err:  # a bug or a failing realisation: stop every rank, keep the file
        if _file_system_full(err):
            sys.stderr.write(f"sdmpi run: rank {comm.rank}: cannot write {output}: the file "
                             f"system is full ({err}). Everything up to the last checkpoint "
                             "is committed: free some space, then run the same command "
                             "again to resume.\n")
        elif isinstance(err, RealisationFailed):  # its message says why and what to change
            sys.stderr.write(f"sdmpi run: rank {comm.rank}: {err}. Everything up to the last "
                             "checkpoint is committed.\n")
        else:
            sys.stderr.write(f"sdmpi run: rank {comm.rank} failed:\n{traceback.format_exc()}")
        sys.stderr.flush()
        comm.Abort(1)
    finally:
        if lock is not None:
            os.close(lock)


def _file_system_full(err: BaseException) -> bool:
    """Whether an error is a full file system or an exceeded quota (h5py reports HDF5's
    write failures as OSError with the C errno in the message)."""
    text = str(err)
    return isinstance(err, OSError) and (
        err.errno in (errno.ENOSPC, errno.EDQUOT) or "No space left" in text
        or "quota exceeded" in text.lower())


def _agree(comm, job_path, overrides, out: Path, new: bool, extend: bool):
    """Rank 0 checks everything, takes the lock and extends the run file if asked; all
    ranks get its plan or raise :class:`BadInput`. Returns (plan, lock descriptor or
    None)."""
    plan = lock = None
    if comm.rank == 0:
        try:
            plan = _plan(job_path, overrides, out, new, extend, comm.size)
            if plan.mode != "complete" or plan.damaged:
                lock = take_lock(out)
            if plan.rewind or plan.damaged:
                store.fall_back(out, dict(plan.rewind), list(plan.damaged))
            if plan.mode == "resume":
                store.record_session(out, "resume", plan.created, plan.versions)
            if plan.mode == "extend":
                plan = _extended(plan, out)
        except RunLocked as err:
            plan = BadInput(_in_use(out, str(err)))
        except BadInput as err:
            plan = err
        except OSError as err:  # e.g. the log directory cannot be created
            plan = BadInput(f"{out}: {err}")
    plan = comm.bcast(plan, root=0)
    if isinstance(plan, BadInput):
        raise plan if comm.rank == 0 else BadInput(None)
    return plan, lock


def _execute(comm, plan: Plan, out: Path, factory, stream) -> bool:
    """Everything after the checks (see the module docstring)."""
    if comm.rank == 0:
        for note in plan.notes:
            print(f"WARNING: {note}", file=stream, flush=True)
    if plan.mode == "complete":
        if comm.rank == 0:
            print(f"{out}: already complete ({len(plan.progress)} tasks); nothing to do",
                  file=stream)
        return True
    if factory is None:
        from ..dynamics import Realisation as factory
    return _Driver(comm, parse_job(plan.job_text), plan, out, factory, stream).run()


# --------------------------------------------------------------------------- checks (rank 0)


def _in_use(out: Path, holder: str) -> str:
    return f"{out}: in use by another sdmpi run ({holder}); wait for it to finish or stop it"


def _plan(job_path, overrides, out: Path, new: bool, extend: bool, size: int) -> Plan:
    try:
        job = load_job(job_path, overrides)
    except JobError as err:
        raise BadInput(str(err)) from None
    rpt = job.ensemble.ranks_per_task
    if size % rpt:
        raise BadInput(f"ensemble.ranks_per_task = {rpt} does not divide the {size} MPI "
                       f"ranks; run with a multiple of {rpt} ranks")
    _check_output(out, new)
    holder = lock_holder(out)
    if holder is not None:  # before reading the file: a live file is never "damaged"
        raise BadInput(_in_use(out, holder))
    plan = _mode(job, out, new, extend)
    if plan.mode != "complete":  # a run file with nothing left to do is left alone
        _check_backend(job, plan.backend, job_path)
        _check_resources(job, plan.backend, job_path, out, new, size, extend)
    if 0 in plan.progress and plan.mode != "complete":  # tasks to start: check their start
        try:
            start_file.load(job)
        except start_file.StartError as err:
            raise BadInput(f"{job_path}: 1 problem\n  - {err}") from None
    return plan


def _mode(job, out: Path, new: bool, extend: bool) -> Plan:
    """The plan for this job and output file: new, resume, extend or complete."""
    tasks = enumerate_tasks(job)
    meta = (json.dumps(versions()),
            datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
    if extend and not out.exists():
        raise BadInput(f"{out}: does not exist; --extend lengthens an existing run file")
    if out.exists() and not new:
        try:
            summary = store.read_summary(out)
        except store.StoreError as err:
            advice = ("Use --new to replace it, or choose another output file (-o)."
                      if store.is_run_file(out) else "Choose another output file (-o).")
            raise BadInput(f"{err}\nLeft untouched. {advice}") from None
        if resume_hash(summary.job) != resume_hash(job):
            if not extend or extension_hash(summary.job) != extension_hash(job):
                raise BadInput(_different_job(out, summary.job, job, extend))
            problems = extension.problems(summary, job)
            if problems:
                raise BadInput("\n".join([f"{out}: cannot be extended to this job:",
                                          *(f"  {p}" for p in problems), "Left untouched."]))
            return Plan(canonical_text(job), "extend", tuple(int(p) for p in summary.progress),
                        summary.slots, *meta, backend=_recorded_backend(summary, job))
        progress = tuple(step for step, _ in summary.resume)
        slots = tuple(slot for _, slot in summary.resume)
        mode = "complete" if all(p == t.n_steps for p, t in zip(progress, tasks)) else "resume"
        rewind = tuple((t.task_id, step) for t, step, done in
                       zip(tasks, progress, summary.progress) if step < done)
        notes = tuple(f"damaged: {d}" for d in summary.damage) + tuple(
            f"task {tid}: recomputing from step {step} (committed up to "
            f"{summary.progress[tid]}), bit for bit as before the damage" for tid, step in rewind)
        damaged = tuple((d.task_id, d.slot) for d in summary.damage if d.what == "state")
        if mode == "resume":
            notes += _stack_note(out, summary.sessions[-1], json.loads(meta[0]))
        return Plan(canonical_text(job), mode, progress, slots, *meta, notes, rewind, damaged,
                    backend=_recorded_backend(summary, job))
    return Plan(canonical_text(job), "new", (0,) * len(tasks), (-1,) * len(tasks), *meta,
                backend=job_backend(job))


def _recorded_backend(summary, job) -> str:
    """The backend a run file's tasks solve on: the one recorded at its creation
    (``solver_backend``), so that a resumed "auto" run never switches backend, whatever
    the rank count (`_check_backend` refuses one that cannot run here); for a file
    without the record, what job.solver.backend stands for at the job's N and
    ensemble.ranks_per_task."""
    return summary.attrs.get("solver_backend") or job_backend(job)


def _stack_note(out: Path, last: dict, now: dict) -> tuple[str, ...]:
    """A warning when this session's sdmpi or library stack is not the one that last
    wrote the run file: the numbers differ in their last bits between stacks."""
    changed = store.stack_differences(last["versions"], now)
    if not changed:
        return ()
    return (f"{out} was last written ({last['mode']}, {last['time']}) by another sdmpi or "
            f"library stack ({'; '.join(changed)}): the tasks resumed here are valid "
            "statistically, but not bit for bit what one stack would have computed "
            "(recorded in the file; 'sdmpi info' lists every session)",)


def _extended(plan: Plan, out: Path) -> Plan:
    """Rank 0: lengthen the run file to the plan's job (:func:`.extension.extend`)."""
    try:
        summary = extension.extend(out, parse_job(plan.job_text), plan.job_text, plan.versions)
    except (OSError, store.StoreError) as err:
        out.with_name(out.name + ".part").unlink(missing_ok=True)
        raise BadInput(f"{out}: could not be extended ({err}); left untouched") from None
    steps = sum(t.n_steps for t in summary.tasks)
    said = (f"extended {out} to {steps} steps in all ({sum(plan.progress)} committed steps "
            f"copied)")
    return dataclasses.replace(plan, mode="complete" if summary.complete else "resume",
                               progress=tuple(int(p) for p in summary.progress),
                               slots=summary.slots, extension=said)


def _check_backend(job, used: str, job_path) -> None:
    """The backend the job runs on (``used``: named, recorded in the run file, or what
    "auto" picks for this N and ranks_per_task) must be registered here, run a task on
    ensemble.ranks_per_task ranks, suit the drift scheme (`config.checks.scheme_problems`),
    and have petsc4py if it needs PETSc: refuse the job before anything is written
    otherwise."""
    from ..hydro.petsc_dense import PetscUnavailable, import_petsc4py

    backend, rpt = job.solver.backend, job.ensemble.ranks_per_task
    why = f'the run file\'s tasks solve on the "{used}" backend' + (
        f' (what solver.backend = "{backend}" stood for when the run file was created; a '
        "resumed run keeps its backend)" if backend != used else "")
    if used not in SOLVER_BACKENDS:
        raise BadInput(f"{why}, which this sdmpi does not have (registered: "
                       f"{', '.join(SOLVER_BACKENDS.names())}). Nothing written.")
    if rpt > 1 and not SOLVER_BACKENDS[used].several_ranks:
        raise BadInput(f"{why}, which runs a task on one rank: ensemble.ranks_per_task = "
                       f"{rpt}; allowed: 1 for this run file. Nothing written.")
    problems = scheme_problems(job, used)
    if problems:
        raise BadInput(f"{JobError(problems, str(job_path))}\nNothing written.")
    if not SOLVER_BACKENDS[used].needs_petsc:
        return
    try:
        import_petsc4py()  # not load_petsc: PETSc initialisation is collective
    except PetscUnavailable as err:
        raise BadInput(f"solver.backend = {backend!r} needs PETSc here: {err}") from None


def _check_resources(job, backend: str, job_path, out: Path, new: bool, size: int,
                     extend: bool = False) -> None:
    """Refuse a job that cannot fit on its ``backend``: the memory of the ranks on this
    machine, and (for a run file still to be created, or the longer copy an extension
    writes beside the run file) the room for it in the output's file system."""
    creating = new or extend or not out.exists()
    replaced = out.stat().st_size if out.exists() and creating and not extend else 0
    problems = resources.problems(job, backend, resources.ranks_on_this_node(size),
                                  out.parent if creating else None,
                                  store.run_file_bytes(job) - replaced)
    if problems:
        raise BadInput(f"{JobError(problems, str(job_path))}\nNothing written.")


def _check_output(out: Path, new: bool) -> None:
    parent = out.parent
    if not parent.is_dir():
        raise BadInput(f"{out}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise BadInput(f"{out}: cannot create files in {parent} (permission denied)")
    if out.is_dir():
        raise BadInput(f"{out}: is a directory; -o names the run file (e.g. run.h5)")
    if out.exists() and not new and not os.access(out, os.R_OK | os.W_OK):
        raise BadInput(f"{out}: exists but is not readable and writable")
    if out.exists() and new and not store.is_run_file(out):
        raise BadInput(f"{out}: exists and is not an sdmpi run file; --new replaces only "
                       f"sdmpi run files. Left untouched: choose another output file (-o)")
    logs = logs_dir(out)
    if logs.exists() and not logs.is_dir():
        raise BadInput(f"{logs}: exists and is not a directory (the run's log directory)")


def _key_values(job) -> dict[str, str]:
    """section.key -> TOML value text of a job's canonical text, layout keys left out."""
    values, section = {}, ""
    for line in canonical_text(job, exclude=LAYOUT_KEYS).splitlines():
        if line.startswith("["):
            section = line.strip("[]")
        elif " = " in line:
            key, value = line.split(" = ", 1)
            values[f"{section}.{key}"] = value
    return values


def _different_job(out: Path, stored, job, extend: bool) -> str:
    old, now = _key_values(stored), _key_values(job)
    keys = list(old) + [k for k in now if k not in old]
    differ = [k for k in keys if old.get(k) != now.get(k)]
    diffs = [f"  {k}: file has {old.get(k, '(absent)')}, this job has {now.get(k, '(absent)')}"
             for k in differ]
    hint = []
    if extend:
        hint = [f"--extend allows only the length keys to differ ({', '.join(sorted(LENGTH_KEYS))})"]
    elif all(k in LENGTH_KEYS for k in differ):
        hint = ["Only the length differs: add --extend to lengthen the run (what is "
                "committed is kept)."]
    return "\n".join([f"{out}: holds a different job ({stored.job.name!r}); it differs in:",
                      *diffs, *hint,
                      "Left untouched. Use --new to replace it (its data are lost), or "
                      "choose another output file (-o)."])


def source_digest(root: Path = Path(__file__).resolve().parents[1]) -> str:
    """The first 12 hex digits of the SHA-256 of the Python sources under ``root`` (sdmpi's
    package directory): each file's relative path and bytes, in sorted order. Run files
    written by different code carry different digests, whatever the version number.

    Args:
        root: the directory whose ``*.py`` files are digested (default: sdmpi's package).

    Returns:
        12 lowercase hex digits.
    """
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


def versions() -> dict[str, str]:
    """Versions of sdmpi (its number and its source digest) and of the library stack it
    runs on (Python, numpy, scipy, numba, h5py and its HDF5, mpi4py and its MPI library,
    petsc4py when installed, OpenBLAS's kernels): a run's numbers are bit-for-bit
    reproducible for one such stack.

    Returns:
        name -> version text ("not installed" for a missing petsc4py).
    """
    import mpi4py
    import numba
    import scipy

    try:
        petsc4py = importlib.metadata.version("petsc4py")
    except importlib.metadata.PackageNotFoundError:
        petsc4py = "not installed"
    return {"sdmpi": __version__, "sdmpi source": source_digest(),
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__,
            "h5py": h5py.version.version, "hdf5": h5py.version.hdf5_version,
            "mpi4py": mpi4py.__version__,
            "MPI": MPI.Get_library_version().split(",")[0].splitlines()[0].strip(),
            "petsc4py": petsc4py, "BLAS kernels": openblas_kernel()}


# --------------------------------------------------------------------------- stopping


class _Stop:
    """Stop requests from signals: the first one asks for a clean stop (finish the step,
    commit, exit resumable); a second one of the same kind kills the process at once."""

    def __init__(self):
        self.signal = None
        self._previous = {}

    def install(self) -> None:
        """Handle STOP_SIGNALS with this object, keeping the previous handlers."""
        for sig in STOP_SIGNALS:
            self._previous[sig] = signal.signal(sig, self._handler)

    def restore(self) -> None:
        """Put back the handlers that install replaced."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _handler(self, signum, frame) -> None:
        if self.signal == signum:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
        self.signal = signum

    def requested(self, group: MPI.Intracomm) -> bool:
        """Whether to stop now; agreed by all ranks of ``group`` (they step together).

        Args:
            group: the ranks that step together (collective when it has several).

        Returns:
            True when any rank of the group has received a stop signal.
        """
        flag = self.signal is not None
        return group.allreduce(flag, op=MPI.LOR) if group.size > 1 else flag


# --------------------------------------------------------------------------- the driver


def _pinned(job, backend: str):
    """The job with solver.backend = ``backend`` (the one its tasks solve on), which the
    realisations are built from: "auto" resolved once, by the plan, not again by each
    realisation on its communicator."""
    if job.solver.backend == backend:
        return job
    return dataclasses.replace(job, solver=dataclasses.replace(job.solver, backend=backend))


class _Driver:
    def __init__(self, comm, job, plan: Plan, out: Path, factory, stream):
        self.comm, self.job, self.plan, self.out = comm, job, plan, out
        self.factory, self.stream = factory, stream
        self.rank = comm.rank
        self.log = rank_logger(logs_dir(out), self.rank)
        self.stop = _Stop()
        self.t_step = self.t_io = self.t_checksum = 0.0  # s: stepping, HDF5 writes +
        # checkpoints, the checksums' part of the latter
        self.served = (0, 0.0)  # serial h5py, rank 0: other ranks' commits applied, s

    def say(self, text: str) -> None:
        """Rank 0: print (and log) one line.

        Args:
            text: the line, without a newline.
        """
        if self.rank == 0:
            print(text, file=self.stream, flush=True)

    def run(self) -> bool:
        """Step this rank's share of the tasks, committing checkpoints (module docstring,
        phases 2, 4 and 5).

        Returns:
            True when every task is complete, False when stopped by a signal.
        """
        comm, job, plan = self.comm, self.job, self.plan
        tasks = enumerate_tasks(job)
        rpt = job.ensemble.ranks_per_task
        group, index, n_groups = split_groups(comm, rpt)
        leader = group.rank == 0
        mine = assign(remaining_costs(tasks, plan.progress), n_groups)[index]
        self.log.info(f"=== sdmpi {__version__} run {plan.mode}: {self.out}, rank {self.rank} of "
                      f"{comm.size}, group {index} of {n_groups}, pid {os.getpid()} on "
                      f"{socket.gethostname()}; tasks {mine}")
        todo = [t for t in tasks if plan.progress[t.task_id] < t.n_steps]
        steps_todo = sum(t.n_steps - plan.progress[t.task_id] for t in todo)
        if plan.extension:
            self.say(plan.extension)
        if plan.mode == "resume":
            self.say(f"resuming {self.out}: {len(tasks) - len(todo)}/{len(tasks)} tasks "
                     f"complete, {sum(plan.progress)} steps committed")
        self.say(f"job {job.job.name!r}: {len(todo)} tasks to run ({steps_todo} steps) on "
                 f"{comm.size} rank(s), {rpt} per task, backend {plan.backend} -> {self.out}")

        if not kernels_cached():
            self.say("compiling the numba kernels (the first run of this installation, "
                     "or one without a writable cache: about a minute before the first step)")
        self.stop.install()
        try:
            # with ranks_per_task > 1 every rank of a group builds and steps the same
            # realisations on the group's communicator (collective solves); the leader writes
            extra = {"comm": group} if group.size > 1 else {}
            solving = _pinned(job, plan.backend)
            realisations = {tid: self.factory(solving, tasks[tid], **extra) for tid in mine}
            fresh = [tid for tid in mine if plan.progress[tid] == 0]
            if fresh and job.system.start == "file":
                configurations = start_file.load(job)
                for tid in fresh:
                    start_file.apply(realisations[tid], configurations.positions(tasks[tid]))
            layouts = {tid: store.TaskLayout.of(r) for tid, r in realisations.items()} \
                if leader else {}
            if plan.mode == "new":
                self._create(layouts)
            run_file = store.RunFile.open(self.out, comm)
            try:
                if plan.mode == "resume":
                    self._check_layouts(run_file, layouts)
                leaders = [g * rpt for g in range(n_groups)]
                steps_total = sum(t.n_steps for t in tasks)
                progress = Progress(comm, leaders, (len(tasks) - len(todo), len(tasks)),
                                    (steps_total - steps_todo, steps_total), self.stream)
                t0 = time.perf_counter()
                unfinished = 0
                for tid in mine:
                    if unfinished or self.stop.requested(group):
                        unfinished += 1
                        continue
                    unfinished += not self._run_task(tasks[tid], realisations.pop(tid),
                                                     run_file, group, leader, progress)
                wall = time.perf_counter() - t0
                progress.finish(idle=run_file.serve)
            finally:
                run_file.close()
                self.t_checksum = run_file.t_checksum
                self.served = (run_file.n_served, run_file.t_served)
        finally:
            self.stop.restore()
        unfinished = comm.allreduce(unfinished if leader else 0)
        self._summary(wall, unfinished, len(tasks))
        return unfinished == 0

    def _create(self, layouts) -> None:
        """Create the run file (collective) in RUN.h5.part, then rename it to RUN.h5."""
        merged = {}
        for part in self.comm.allgather(layouts):
            merged.update(part)
        part = self.out.with_name(self.out.name + ".part")
        if store.parallel_hdf5():
            store.create(part, self.job, self.plan.job_text, merged, self.comm,
                         self.plan.versions, self.plan.created, self.plan.backend)
        elif self.rank == 0:  # serial h5py: rank 0 writes the file for all
            store.create(part, self.job, self.plan.job_text, merged, MPI.COMM_SELF,
                         self.plan.versions, self.plan.created, self.plan.backend)
        self.comm.Barrier()
        if self.rank == 0:
            os.replace(part, self.out)
        self.comm.Barrier()
        self.log.info(f"created {self.out}")

    def _check_layouts(self, run_file, layouts) -> None:
        problems = [p for tid, lay in layouts.items() for p in run_file.layout_problems(tid, lay)]
        problems = [p for part in self.comm.allgather(problems) for p in part]
        if problems:
            raise BadInput("\n".join([f"{self.out}: written by a different version of the "
                                      "dynamics; cannot resume:", *problems])
                           if self.rank == 0 else None)

    def _run_task(self, task, real, run_file, group, leader, progress) -> bool:
        """Step one task from its committed step to the end or to a stop request;
        returns True when the task is complete."""
        tid, n = task.task_id, task.n_steps
        start, slot = self.plan.progress[tid], self.plan.slots[tid]
        if start > 0:
            real.set_state(run_file.read_state(tid, slot))
        if leader:
            run_file.begin(tid, slot)
        if real.step != start:
            raise RuntimeError(f"task {tid}: realisation at step {real.step}, expected {start}")
        chunk = self.job.output.checkpoint_every
        recorders = [writer.recorder(self.job, task, real, run_file, start)
                     for writer in writers.active(self.job)] if leader else []
        self.log.info(f"task {tid}: {'resumed at' if start else 'started at'} step {start} of {n}")
        t_task = time.perf_counter()
        io_before = self.t_io
        step = start
        stopped = False
        while step < n and not stopped:
            end = min((step // chunk + 1) * chunk, n)
            t0 = time.perf_counter()
            while step < end:
                for recorder in recorders:
                    recorder.before(step, real)
                sample = real.advance(1)
                fault("step")
                run_file.serve()  # the writer rank of a serial h5py: others' commits
                for recorder in recorders:
                    recorder.after(step, sample, real)
                step += 1
                progress.add(steps=1)
                if self.stop.requested(group):
                    stopped = True
                    break
            t1 = time.perf_counter()
            self.t_step += t1 - t0
            if leader:
                slot = 0 if slot < 0 else 1 - slot
                for recorder in recorders:  # their data first: the checkpoint makes them valid
                    recorder.flush(step)
                run_file.checkpoint(tid, step, real.get_state(), slot)
                self.t_io += time.perf_counter() - t1
        elapsed = time.perf_counter() - t_task
        io = self.t_io - io_before
        rate = (step - start) / elapsed if elapsed > 0 else 0.0
        if step == n:
            progress.add(tasks=1)
            self.log.info(f"task {tid}: complete, {step - start} steps in {elapsed:.3g} s "
                          f"({rate:.3g} steps/s), writes+checkpoints {io:.3g} s")
            return True
        self.log.info(f"task {tid}: stopped by signal {self.stop.signal} at step {step} "
                      f"(committed)")
        return False

    def _summary(self, wall: float, unfinished: int, n_tasks: int) -> None:
        wall_all = self.comm.allreduce(wall)
        io_all = self.comm.allreduce(self.t_io)
        crc_all = self.comm.allreduce(self.t_checksum)
        share = 100.0 * io_all / wall_all if wall_all > 0 else 0.0
        self.log.info(f"done: wall {wall:.3g} s, stepping {self.t_step:.3g} s, HDF5 writes + "
                      f"checkpoints {self.t_io:.3g} s (checksums {self.t_checksum:.3g} s)")
        io_text = (f"HDF5 writes + checkpoints {io_all:.3g} s = {share:.2f}% of "
                   f"{wall_all:.3g} s rank time (checksums {crc_all:.2g} s of it)")
        if self.served[0]:
            self.log.info(f"applied {self.served[0]} commits of other ranks in "
                          f"{self.served[1]:.3g} s (serial h5py: this rank writes for all)")
            io_text += (f"; rank 0 applied {self.served[0]} commits of the other ranks in "
                        f"{self.served[1]:.3g} s")
        if unfinished == 0:
            self.say(f"{self.out}: complete ({n_tasks} tasks); {io_text}")
        else:
            name = signal.Signals(self.stop.signal).name if self.stop.signal else "a signal"
            self.say(f"{self.out}: stopped by {name}, {n_tasks - unfinished}/{n_tasks} tasks "
                     f"complete, all work up to the last checkpoint committed; run the same "
                     f"command again to resume")
