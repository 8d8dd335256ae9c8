"""The ``sdmpi`` command line.

Each command is one ``_add_<command>(subparsers)`` function that builds its sub-parser
and sets ``handler`` (called with the parsed arguments, returns the exit code); adding a
command means writing one such function and listing it in ``COMMANDS``. Commands that
read a job file call :func:`add_job_arguments` and :func:`job_from_args`, so ``--set``
behaves the same everywhere. Heavy imports (numpy, MPI, HDF5) belong inside handlers so
that ``sdmpi validate`` and ``--help`` stay fast.

Exit codes (docs/cli.md): 0 success (``run``: every task complete); 1 ``run`` did not
finish: a rank failed (its message on stderr, e.g. a full file system), or mpirun was
itself terminated (SIGTERM to mpirun: mpirun exits 1); committed data are intact and the
same command resumes; 2 bad input (job file, ``--set``, command line, output path,
resources, or a run file that is foreign, damaged or holds another job; nothing is
written); 3 ``run`` stopped by SIGTERM/SIGINT/SIGUSR1 after a clean checkpoint
(SIGUSR1 when sent to mpirun): resumable by running the same command again.

One BLAS/OpenMP thread per process (one rank per core): the thread-count variables are set
to 1 here, before numpy is imported, unless the user set them (OpenBLAS's kernels were
chosen by the package's import: `sdmpi._blas_kernel`).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402

from . import __version__
from .config import JobError, enumerate_tasks, job_hash
from .config.stresses import CONTRIBUTIONS
from .dynamics.checks import load_job
from .registry import HYDRODYNAMIC_MODELS

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2
EXIT_RESUMABLE = 3


def add_job_arguments(parser: argparse.ArgumentParser) -> None:
    """The job file and the repeatable ``--set SECTION.KEY=VALUE`` override."""
    parser.add_argument("job", metavar="JOB.toml", help="job file (TOML)")
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
        help="override one key of the job file; VALUE is a TOML literal (strings in "
             "double quotes, e.g. --set 'medium.kind=\"maxwell\"'); may be repeated")


def job_from_args(args):
    """The validated job named by ``args`` (raises :class:`sdmpi.config.JobError`)."""
    return load_job(args.job, overrides=args.overrides)


# --------------------------------------------------------------------------- validate


def _add_validate(subparsers) -> None:
    parser = subparsers.add_parser(
        "validate", help="check a job file and summarise it",
        description="Check a job file (with any --set overrides) against the schema and "
                    "print a summary: task groups, time steps, tasks and their steps in all, "
                    "the run file's size and the memory per rank (estimates), with a "
                    "WARNING where they do not fit here (sdmpi run would refuse the job), "
                    "and with --time-steps the measured cost. Every problem is listed at "
                    "once, each with the key, the offending value, why, and what is "
                    "allowed. Writes nothing.",
        epilog="exit status: 0 if the job is valid (resource warnings included: the job may "
               "run elsewhere), 2 if not (or the file is unreadable), 1 if --time-steps "
               "could not step the first task (the message says why)")
    add_job_arguments(parser)
    parser.add_argument("--ranks", type=int, default=None, metavar="P",
                        help="MPI ranks the job will run on, all on this machine (for the "
                             "memory check and the wall-time estimate; default: the fewest "
                             "the job can run on, ensemble.ranks_per_task)")
    parser.add_argument("-o", "--output", default="run.h5", metavar="RUN.h5",
                        help="where the run file will go (for the disk-space check; "
                             "default ./run.h5; nothing is written)")
    parser.add_argument("--time-steps", type=int, default=0, metavar="K",
                        help="time K steps of the first task (after one untimed step that "
                             "compiles or loads the kernels) and estimate the run's "
                             "core-hours and wall time from their mean (steps vary; give 10 "
                             "or more for a long job); default 0: no timing. A "
                             "job of R > 1 ranks per task is timed on its R ranks under "
                             "mpirun -n R, on one rank without mpirun")
    parser.set_defaults(handler=_validate)


def _launched_rank() -> int | None:
    """This process's rank when an MPI launcher started it (mpirun, srun), else None; read
    from the launcher's environment, without initialising MPI."""
    from ._kernel_cache import RANK_VARS

    return next((int(os.environ[v]) for v in RANK_VARS if os.environ.get(v, "").isdigit()), None)


def _validate(args) -> int:
    """``sdmpi validate``; under mpirun every rank checks the job and rank 0 alone prints
    (the others' output is dropped), and ``--time-steps`` times the first task on the
    job's ensemble.ranks_per_task ranks, as many as mpirun must start."""
    if _launched_rank() in (None, 0):
        return _validate_job(args)
    import contextlib

    with open(os.devnull, "w") as sink, contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        return _validate_job(args)


def _validate_job(args) -> int:
    from .config import resources
    from .config.checks import scheme_problems
    from .dynamics.setup import job_backend

    try:
        job = job_from_args(args)
        used = job_backend(job)
        problems = resources.start_problems(job) + scheme_problems(job, used)
        if problems:
            raise JobError(problems, args.job)
    except JobError as err:
        print(err, file=sys.stderr)
        return EXIT_BAD_INPUT
    rpt = job.ensemble.ranks_per_task
    if args.ranks is None:
        args.ranks = rpt
        if rpt > 1:
            print(f"checking for {rpt} ranks, the fewest this job runs on "
                  f"(ensemble.ranks_per_task = {rpt}); --ranks P checks another count")
    bad = [f"--ranks {args.ranks}: must be at least 1"] if args.ranks < 1 else []
    bad += [f"--time-steps {args.time_steps}: must be 0 or more"] if args.time_steps < 0 else []
    if args.ranks % rpt:
        bad.append(f"--ranks {args.ranks}: must be a multiple of ensemble.ranks_per_task "
                   f"= {rpt} (sdmpi run would refuse it)")
    if bad:
        print("sdmpi validate: " + "\n".join(bad), file=sys.stderr)
        return EXIT_BAD_INPUT
    if job.system.start == "file":
        from .ensemble.start_file import StartError, load

        try:
            load(job)
        except StartError as err:
            print(f"{args.job}: 1 problem\n  - {err}", file=sys.stderr)
            return EXIT_BAD_INPUT
    print(summary(job))
    print(resource_text(job, args.ranks, args.output))
    if args.time_steps and _launched_rank() is not None:
        from mpi4py import MPI

        if MPI.COMM_WORLD.size not in (1, rpt):
            print(f"sdmpi validate: --time-steps under mpirun times one task on its "
                  f"ensemble.ranks_per_task = {rpt} rank(s): start it with mpirun -n {rpt} (here "
                  f"{MPI.COMM_WORLD.size}), or without mpirun to time one rank", file=sys.stderr)
            return EXIT_BAD_INPUT
    if args.time_steps:
        try:
            print(cost_text(job, args.ranks, args.time_steps))
        except Exception as err:  # the realisation cannot step: its message says why
            print(f"sdmpi validate: timing task 0 failed: {type(err).__name__}: {err}", file=sys.stderr)
            return EXIT_FAILED
    else:
        print("  cost: give --time-steps K (e.g. 10) to time K steps here and estimate the "
              "core-hours and wall time")
    return EXIT_OK


def resource_text(job, ranks: int, output) -> str:
    """The resource estimates of a job and, as WARNING lines, what will not fit here."""
    from pathlib import Path

    from .config import resources
    from .dynamics.setup import job_backend
    from .ensemble.store import run_file_bytes

    gib = resources.gib
    backend = job_backend(job)
    size, memory = run_file_bytes(job), resources.memory_per_rank(job, backend)
    available = resources.available_memory()
    where = Path(output).resolve().parent
    lines = [f"  run file: about {gib(size)}; memory: about {gib(memory)} per rank"
             + ("" if available is None else f" ({gib(available)} available here)")]
    problems = resources.problems(job, backend, ranks, where if where.is_dir() else None,
                                  size)
    lines += [f"WARNING: {p}\n  (sdmpi run would refuse this job here)" for p in problems]
    return "\n".join(lines)


def _timing_group(ranks_per_task: int):
    """The communicator of the ranks that time a task: MPI_COMM_WORLD when this process was
    launched (mpirun) on the task's ``ranks_per_task`` > 1 ranks (`_validate_job` refuses
    other counts above one), else None: this process times it alone."""
    if _launched_rank() is None or ranks_per_task == 1:
        return None
    from mpi4py import MPI

    return MPI.COMM_WORLD if MPI.COMM_WORLD.size > 1 else None


def _step_seconds(job, task, k: int, comm) -> list[float]:
    """Wall seconds of each of ``k`` steps of a task's realisation (after one untimed
    step), on ``comm``'s ranks (each step's slowest rank) or, for None, on this process."""
    import time

    from .dynamics import Realisation

    try:
        real = Realisation(job, task, comm)
        real.advance(1)
        seconds = []
        for _ in range(k):
            if comm is not None:
                comm.Barrier()
            t0 = time.perf_counter()
            real.advance(1)
            seconds.append(time.perf_counter() - t0)
    except Exception as err:
        if comm is None:
            raise
        # the other ranks may wait in a collective: stop them all (sys.__stderr__: a rank
        # other than 0 prints through it)
        print(f"sdmpi validate: rank {comm.rank}: timing task 0 failed: {type(err).__name__}: "
              f"{err}", file=sys.__stderr__, flush=True)
        comm.Abort(EXIT_FAILED)
    return seconds if comm is None else [max(s) for s in zip(*comm.allgather(seconds))]


def cost_text(job, ranks: int, k: int) -> str:
    """Core-hours and wall time of a job on ``ranks`` ranks, from timing ``k`` steps of
    its first task (after one untimed step: kernel compilation or loading, first solves)
    on the ranks of one task (ensemble.ranks_per_task) when launched on them
    (``mpirun -n R sdmpi validate``), else on this process alone. Every step of a job
    costs about the same (same N, same solver); the wall time is the largest load of the
    LPT assignment (sdmpi.ensemble.farm)."""
    from .ensemble.farm import assign
    from .ensemble.progress import hms

    tasks = enumerate_tasks(job)
    rpt, groups = job.ensemble.ranks_per_task, max(ranks // job.ensemble.ranks_per_task, 1)
    comm = _timing_group(rpt)
    timing = rpt if comm is not None else 1
    print(f"timing {k} step(s) of task 0 on {timing} rank(s) (after one untimed step that "
          "compiles or loads the kernels)...", file=sys.stderr, flush=True)
    seconds = _step_seconds(job, tasks[0], k, comm)
    per_step = sum(seconds) / k
    steps = {t.task_id: float(t.n_steps) for t in tasks}
    makespan = max(sum(steps[tid] for tid in group) for group in assign(steps, groups))
    core_hours = sum(steps.values()) * per_step * rpt / 3600.0
    note = ("" if timing == rpt else
            f"; a task runs on {rpt} ranks, whose step takes another time: "
            f"mpirun -n {rpt} sdmpi validate ... times it on them")
    timed = "1 step" if k == 1 else f"mean of {k} steps, {min(seconds):.3g}-{max(seconds):.3g} s"
    return (f"  cost (measured: {per_step:.3g} s per step of task 0 ({timed}) on {timing} rank(s) "
            f"of this machine{note}): {core_hours:.3g} core-hours, wall time "
            f"{hms(makespan * per_step)} on {ranks} rank(s)")


def hydrodynamics_line(job) -> str:
    """The hydrodynamic model a job runs, as it runs it: hydrodynamics.model, and, where
    hydrodynamics.lubrication = false turns a model with lubrication into its far field
    alone, that too."""
    hyd = job.hydrodynamics
    if HYDRODYNAMIC_MODELS[hyd.model].lubrication and not hyd.lubrication:
        return (f'{hyd.model} without lubrication (hydrodynamics.lubrication = false): the far-field '
                'mobility alone, as hydrodynamics.model = "far-field" (whose default collision rule, '
                'reflect, differs)')
    return hyd.model


def brownian_line(job) -> str:
    """"off", or "on" with the drift scheme the job runs (brownian.scheme, or the default
    of the backend it runs on, `sdmpi.registry.default_drift_scheme`) and whether its
    near-contact correction applies (lubrication on and `DriftSpec.near_contact`)."""
    from .dynamics.setup import job_backend
    from .registry import DRIFT_SCHEMES, default_drift_scheme

    model = HYDRODYNAMIC_MODELS[job.hydrodynamics.model]
    if not job.brownian.enabled or not model.solves:
        return "on" if job.brownian.enabled else "off"
    scheme = job.brownian.scheme or default_drift_scheme(job_backend(job))
    near = model.lubrication and job.hydrodynamics.lubrication and DRIFT_SCHEMES[scheme].near_contact
    return f"on (drift {scheme}{', near-contact correction' if near else ''})"


def integrator_line(job) -> str:
    """The time integrator (integration.scheme) and, where the far field is held between
    refreshes (hydrodynamics.far_field_refresh > 0), its interval."""
    refresh = job.hydrodynamics.far_field_refresh
    held = f"; far-field mobility held {refresh:g} [{job.time_unit}] between refreshes" if refresh > 0 else ""
    return job.integration.scheme + held


def summary(job) -> str:
    """A few lines describing a resolved job: physics, task groups, tasks and cost."""
    s, unit, tasks = job.shear, job.time_unit, enumerate_tasks(job)
    medium = job.medium.kind
    if job.medium.modes:
        medium += " (" + ", ".join(f"eta={m.eta:g} lambda={m.lam:g}"
                                   for m in job.medium.modes) + f") [{unit}]"
    if s.protocol == "oscillatory":
        shear = f"oscillatory, gamma0 = {s.gamma0:g}"
    elif s.protocol == "steady":
        per_time = "gamma_dot" if unit == "1/gamma_dot" else f"1/{unit}"
        shear = f"steady, rate = {s.rate:g} [{per_time}]"
    else:
        shear = "none (quiescent)"
    phi = "areal fraction" if job.system.geometry == "monolayer" else "phi"
    lines = [
        f"job {job.job.name!r}: valid (hash {job_hash(job)[:16]})",
        f"  N = {job.system.n_particles}, {phi} = "
        + ", ".join(f"{p:g}" for p in job.system.phi) + f", medium {medium}",
        f"  shear {shear}; Brownian {brownian_line(job)}; time unit {unit}",
        f"  hydrodynamics: {hydrodynamics_line(job)}",
        f"  integrator: {integrator_line(job)}",
    ]
    from .config.units import scales

    si = scales(job)
    if si is not None:
        pe = "" if s.protocol != "steady" or si.thermal_energy is None else f"; Pe = {si.peclet(s.rate):.3g}"
        lines.append(f"  physical units: a = {si.length:.4g} m, {unit} = {si.time:.4g} s, "
                     f"stress unit {si.stress:.4g} Pa, force unit {si.force:.4g} N{pe}")
    if job.system.size_classes:
        sysm = job.system
        lines.insert(2, "  size classes: " + ", ".join(
            f"{m} x radius {r:g} ({100 * f:.1f}% of the particle volume)"
            for r, m, f in zip(sysm.class_radii, sysm.class_counts, sysm.realised_fractions)))
    for omega in job.frequencies:
        head = "  every task      " if omega is None else f"  omega = {omega:<9.5g}"
        periods = "" if omega is None else \
            f" = {job.periods(omega)} periods ({job.discarded_periods(omega)} discarded)"
        lines.append(f"{head}  dt = {job.time_step(omega):<9.3g} "
                     f"{job.n_steps(omega)} steps ({job.discard_steps(omega)} discarded){periods}")
    omegas = f"{len(s.omega)} omega x " if s.omega else ""
    lines.append(f"  tasks: {len(tasks)} = {len(job.system.phi)} phi x {omegas}"
                 f"{job.ensemble.realisations} realisations; "
                 f"{sum(t.n_steps for t in tasks)} time steps in all; backend {_backend(job)}, "
                 f"{job.ensemble.ranks_per_task} rank(s) per task")
    return "\n".join(lines)


def _backend(job) -> str:
    """The solver backend as `run` uses it ("auto" resolved), its far field if it is
    matrix-free, and whether PETSc, where the backend needs it, can be imported here
    (`run` refuses the job otherwise)."""
    from .dynamics.setup import job_backend
    from .hydro.krylov import far_field_kind
    from .hydro.petsc_dense import PetscUnavailable, import_petsc4py
    from .registry import SOLVER_BACKENDS

    name = job.solver.backend
    used = job_backend(job)
    spec = SOLVER_BACKENDS[used]
    text = name if used == name else f"{name} (here {used})"
    if spec.matrix_free:
        text += f", {far_field_kind(job.solver.far_field, job.system.n_particles)} far field"
    if not spec.needs_petsc:
        return text
    try:
        import_petsc4py()
    except PetscUnavailable as err:
        return f"{text} - NOT RUNNABLE HERE, sdmpi run would refuse it: {err}"
    return text


# --------------------------------------------------------------------------- run


def _add_run(subparsers) -> None:
    parser = subparsers.add_parser(
        "run", help="run or resume an ensemble (under mpirun for several ranks)",
        description="Run the job's tasks on the MPI ranks ([mpirun -n P] sdmpi run ...) and "
                    "stream their samples into the run file. If RUN.h5 exists and holds the "
                    "same job (layout keys ensemble.ranks_per_task and "
                    "output.checkpoint_every may differ), the run resumes from its last "
                    "checkpoint, with any number of ranks. SIGTERM, SIGINT or SIGUSR1 stop "
                    "the run cleanly after a checkpoint (under mpirun send SIGUSR1 to "
                    "mpirun: it forwards it, exit 3; SIGTERM to mpirun is forwarded too, but mpirun "
                    "exits 1 and kills ranks still running after about 1 s: the file is "
                    "resumable either way). "
                    "Per-rank logs go to RUN.h5.logs/.",
        epilog="exit status: 0 complete; 1 not finished: a rank failed (see its message) or "
               "mpirun itself was terminated (SIGTERM to mpirun), committed data intact, rerun "
               "to resume; 2 bad input or resources (nothing written); 3 stopped cleanly by a "
               "signal (rerun to resume)")
    add_job_arguments(parser)
    parser.add_argument("-o", "--output", required=True, metavar="RUN.h5",
                        help="the run file (HDF5): created, or resumed if it exists")
    again = parser.add_mutually_exclusive_group()
    again.add_argument("--new", action="store_true",
                       help="start afresh, replacing RUN.h5 if it exists (its data are lost)")
    again.add_argument("--extend", action="store_true",
                       help="lengthen the existing RUN.h5 to this job, which may differ from "
                            "the stored one only in the length keys (integration.periods, "
                            "duration, n_steps and their discard keys) and not be shorter "
                            "for any task: what is committed is kept, the run resumes")
    parser.set_defaults(handler=_run, realisation_factory=None)


def _run(args) -> int:
    os.environ.setdefault("H5PY_ALWAYS_USE_MPI", "1")  # parallel h5py even without mpirun
    from .ensemble.runner import BadInput, run

    try:
        complete = run(args.job, args.overrides, args.output, new=args.new,
                       extend=args.extend, realisation_factory=args.realisation_factory)
    except BadInput as err:
        if err.args and err.args[0]:
            print(err, file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK if complete else EXIT_RESUMABLE


# --------------------------------------------------------------------------- info


def _add_info(subparsers) -> None:
    parser = subparsers.add_parser(
        "info", help="summarise a run file: job, progress per task, versions",
        description="Check a run file written by 'sdmpi run' and print its job, the "
                    "progress of every task and the versions that wrote it. Read-only; "
                    "works while the run is going on.",
        epilog="exit status: 0, or 2 if the file is not an intact sdmpi run file (including "
               "committed data failing their checksums: each is listed)")
    parser.add_argument("run", metavar="RUN.h5", help="the run file")
    parser.add_argument("--job", action="store_true",
                        help="print the stored job (canonical TOML) instead")
    parser.set_defaults(handler=_info)


def _info(args) -> int:
    from .ensemble.progress import lock_holder
    from .ensemble.store import StoreError, read_summary

    try:
        run = read_summary(args.run)
    except StoreError as err:
        print(err, file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.job:
        print(run.job_text, end="")
    else:
        print(info_text(run, lock_holder(args.run)))
    if run.damage:
        print(f"{args.run}: DAMAGED: {len(run.damage)} checksum mismatch(es):", file=sys.stderr)
        for damage in run.damage:
            print(f"  {damage}", file=sys.stderr)
        print("'sdmpi run' with the same job recomputes the damaged steps (bit for bit) from "
              "the last intact checkpoint before them; 'sdmpi reduce' refuses damaged "
              "samples", file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK


def session_lines(sessions) -> list[str]:
    """``sdmpi info``'s history of the sessions that wrote a run file, each with how its
    sdmpi and library stack differ from the session before."""
    from .ensemble.store import stack_differences

    lines = [f"sessions: {len(sessions)} (the stack of each, against the one before)"]
    for before, now in zip((None, *sessions), sessions):
        changed = [] if before is None else stack_differences(before["versions"],
                                                              now["versions"])
        said = "as created" if before is None else (
            "; ".join(changed) if changed else "same stack")
        lines.append(f"  {now['time']}  {now['mode']:<6}  {said}")
    return lines


def info_text(run, running=None) -> str:
    """The ``sdmpi info`` report of an inspected run file (:class:`RunSummary`);
    ``running``: who is writing it now (see sdmpi.ensemble.progress.lock_holder)."""
    a, tasks = run.attrs, run.tasks
    done = [int(p) for p in run.progress]
    n_done = sum(p == t.n_steps for p, t in zip(done, tasks))
    steps, total = sum(done), sum(t.n_steps for t in tasks)
    if n_done == len(tasks):
        state = "complete"
    elif running:
        state = f"running ({running}; counts are up to its last checkpoints)"
    else:
        state = "resumable (run the same command again)"
    lines = [f"{run.path}: sdmpi run file, format {a['format_version']}, created {a['created']}",
             f"job {run.job.job.name!r} (job_hash {a['job_hash'][:16]})",
             summary(run.job).split("\n", 1)[1],
             f"progress: {n_done}/{len(tasks)} tasks complete, {steps}/{total} steps "
             f"({100.0 * steps / total:.1f}%); {state}",
             f"  {'task':>6}  {'phi':>6}  {'omega':>10}  {'real.':>5}  {'steps':>17}  state"]
    for task, p in zip(tasks, done):
        omega = "-" if task.omega is None else f"{task.omega:.5g}"
        mark = "done" if p == task.n_steps else ("not started" if p == 0
                                                 else f"{100.0 * p / task.n_steps:.0f}%")
        lines.append(f"  {task.task_id:>6}  {task.phi:>6.4g}  {omega:>10}  "
                     f"{task.realisation:>5}  {f'{p}/{task.n_steps}':>17}  {mark}")
    from .ensemble.writers import active

    for writer in active(run.job):
        describe = getattr(writer, "describe", None)  # optional: without it, no line
        line = describe(run.job, done) if describe is not None else None
        if line:
            lines.append(line)
    if "solver_backend" in a:
        lines.append(f"solver backend: {a['solver_backend']} (recorded at creation; a resume "
                     "keeps it)")
    if "extended" in a:
        lines.append(f"extended {len(json.loads(a['extended']))} time(s) (sdmpi run --extend)")
    if not run.checksummed:
        lines.append("checksums: none in this file; data not verified")
    elif run.damage:
        lines.append(f"checksums: {len(run.damage)} mismatch(es), see below")
    else:
        lines.append("checksums: every committed sample and checkpoint verified")
    lines.append("versions: " + ", ".join(f"{k} {v}" for k, v in run.versions.items()))
    lines += session_lines(run.sessions)
    lines.append(f"units: time {a['time_unit']}, stress {a['stress_unit']}, "
                 f"stress components {a['component_order']}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- reduce


def _add_reduce(subparsers) -> None:
    parser = subparsers.add_parser(
        "reduce", help="ensemble-averaged moduli (or viscosities) with errors, and plots",
        description="Reduce one or several run files of the same system (jobs differing "
                    "only in seed and number of realisations) to G', G'', eta', eta'' per "
                    "(phi, omega) and contribution (medium, "
                    + ", ".join(c.component for c in CONTRIBUTIONS) + ", total), each with one "
                    "standard error: the larger of the spread between realisations and the "
                    "blocking error within them (OUTDIR/errors.csv says which). Writes "
                    "OUTDIR/moduli.csv, OUTDIR/moduli.h5, errors.csv, units.json (the unit of "
                    "every column), trust.csv (the dynamics' trust report: docs/reduce.md) and "
                    "PNG figures, each written whole or not at all; steady-shear jobs give "
                    "viscosity.csv/.h5 instead. Uses the committed samples only, so it works "
                    "on a run that is unfinished or still going (and says so). Units: omega "
                    "in 1/t_D, moduli in eta_m/t_D, viscosities relative to eta_m.",
        epilog="exit status: 0, or 2 if an input is not an intact sdmpi run file, the files "
               "hold different systems, or the job cannot be reduced")
    parser.add_argument("runs", nargs="+", metavar="RUN.h5", help="run file(s)")
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR",
                        help="output directory (created if needed)")
    parser.add_argument("--task", type=int, default=None, metavar="ID",
                        help="task (of the first file) for the Lissajous figure; default: "
                             "the first (phi, omega) task with the most analysed periods")
    parser.add_argument("--no-plots", action="store_true", help="write the tables only")
    parser.add_argument(
        "--medium", action="append", default=[], metavar="SPEC",
        help="also reduce the run as if its medium were SPEC, applied after the fact to "
             "the stored viscous hydrodynamic stress (Schaink et al. 2000 eqs. 33-35: the "
             "trajectories are the same), into OUTDIR/<medium>/ (e.g. maxwell_lambda0.5); "
             "SPEC is 'newtonian', 'maxwell:eta=E,lambda=L[;eta=E,lambda=L...]' (eta "
             "relative to eta_m, summing to 1; lambda in t_D) or a TOML file with a "
             "[medium] table; may be repeated (see docs/reduce.md)")
    parser.add_argument(
        "--gk-window", type=float, default=None, metavar="T",
        help="runs at rest (shear.protocol = \"none\"), reduced by Green-Kubo into "
             "relaxation.csv, moduli_gk.csv and green_kubo.json: the window t_M in t_D over "
             "which G(t) is integrated (default: 1/8 of the longest analysed realisation; "
             "see docs/reduce.md)")
    parser.add_argument(
        "--gk-lag0", default=None, metavar="RULE",
        help="runs at rest: the short-time rule, how the first lags of G(t) are treated "
             "(default: contact without lubrication, validated for free draining; lag1 "
             "with it; the rules and when each "
             "applies: docs/reduce.md)")
    parser.set_defaults(handler=_reduce)


def _reduce(args) -> int:
    import warnings

    from .analysis.medium_view import MediumError, label, parse_medium
    from .analysis.reduce import PartialRunWarning, ReduceError, reduce_runs
    from .analysis.report import check_output_dir, format_table, write_all

    try:
        media = [parse_medium(spec) for spec in args.medium]
        names = [label(m) for m in media]
        if len(set(names)) < len(names):
            raise ReduceError(f"--medium: the same medium is given twice ({', '.join(names)})")
        check_output_dir(args.output)
        from .analysis.at_rest import quiescent
        if quiescent(args.runs[0]):
            return _reduce_at_rest(args, zip(media, names))
        if args.gk_window is not None or args.gk_lag0 is not None:
            raise ReduceError("--gk-window and --gk-lag0 apply only to runs at rest "
                              "(shear.protocol = \"none\"), reduced by Green-Kubo")
        views = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PartialRunWarning)  # the notes say it all
            red = reduce_runs(args.runs)
            for medium, name in zip(media, names):
                views.append((name, reduce_runs(args.runs, medium=medium)))
        paths, notes = write_all(red, args.output, plots=not args.no_plots,
                                 task_id=args.task)
        for name, view in views:
            more, view_notes = write_all(view, os.path.join(args.output, name),
                                         plots=not args.no_plots, task_id=args.task)
            paths += more
            notes += [f"{name}: {n}" for n in view_notes]
    except (ReduceError, MediumError) as err:
        print(f"sdmpi reduce: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(format_table(red))
    for name, view in views:
        print(f"\n{name} (medium applied after the fact):")
        print(format_table(view))
    if not red.complete:
        print(f"PARTIAL RUN: {int((red.committed < red.n_steps).sum())} of "
              f"{red.committed.size} tasks unfinished; reduced what is committed",
              file=sys.stderr)
    for note in red.notes + tuple(notes):
        print(f"note: {note}", file=sys.stderr)
    for path in paths:
        print(f"wrote {path}")
    return EXIT_OK


def _reduce_at_rest(args, media) -> int:
    """`sdmpi reduce` of runs at rest: Green-Kubo (sdmpi.analysis.at_rest)."""
    import warnings

    from .analysis.at_rest import reduce_at_rest, write_at_rest
    from .analysis.reduce import PartialRunWarning
    from .analysis.report import format_table

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)  # the notes say it all
        views = [("", reduce_at_rest(args.runs, window=args.gk_window, lag0=args.gk_lag0))]
        views += [(name, reduce_at_rest(args.runs, window=args.gk_window, lag0=args.gk_lag0,
                                        medium=medium)) for medium, name in media]
    paths = []
    for name, red in views:
        more, _ = write_at_rest(red, os.path.join(args.output, name), plots=not args.no_plots,
                                task_id=args.task)
        paths += more
    red = views[0][1]
    for name, view in views:
        print(("" if not name else f"\n{name} (medium applied after the fact):\n")
              + format_table(view))
    if not red.complete:
        print(f"PARTIAL RUN: {int((red.committed < red.n_steps).sum())} of "
              f"{red.committed.size} tasks unfinished; reduced what is committed",
              file=sys.stderr)
    for note in red.notes:
        print(f"note: {note}", file=sys.stderr)
    for warning in red.warnings:
        print(f"WARNING: {warning}", file=sys.stderr)
    for path in paths:
        print(f"wrote {path}")
    return EXIT_OK


# --------------------------------------------------------------------------- main

COMMANDS = (_add_validate, _add_run, _add_info, _add_reduce)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sdmpi",
        description="Ensembles of Stokesian dynamics simulations of colloidal suspensions "
                    "under oscillatory shear, farmed out over MPI ranks.",
        epilog="Run 'sdmpi COMMAND --help' for the options of one command.")
    parser.add_argument("--version", action="version", version=f"sdmpi {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND")
    for add in COMMANDS:
        add(subparsers)
    return parser


def main(argv=None, *, realisation_factory=None) -> int:
    """Entry point of the ``sdmpi`` console script; returns the exit code.
    ``realisation_factory`` replaces sdmpi.dynamics.Realisation in ``run`` (tests)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help, --version (0) and usage errors (2)
        return stop.code if isinstance(stop.code, int) else EXIT_BAD_INPUT
    if not hasattr(args, "handler"):
        parser.print_usage(sys.stderr)
        print("sdmpi: error: a command is required (see sdmpi --help)", file=sys.stderr)
        return EXIT_BAD_INPUT
    if realisation_factory is not None:
        args.realisation_factory = realisation_factory
    try:
        return args.handler(args)
    except BrokenPipeError:  # the reader went away (e.g. `sdmpi info RUN.h5 | head`)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes stdout
        return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
