"""The ``sdmpi`` command line.

Each command is one ``_add_<command>(subparsers)`` function that builds its sub-parser
and sets ``handler`` (called with the parsed arguments, returns the exit code); adding a
command means writing one such function and listing it in ``COMMANDS``. Commands that
read a job file call :func:`add_job_arguments` and :func:`job_from_args`, so ``--set``
behaves the same everywhere. Heavy imports (numpy, MPI, HDF5) belong inside handlers so
that ``sdmpi validate`` and ``--help`` stay fast.

Exit codes: 0 success, 2 bad input (job file, ``--set`` or command line).
"""

from __future__ import annotations

import argparse
import sys

from . import __version__
from .config import JobError, enumerate_tasks, job_hash, load_job

EXIT_OK = 0
EXIT_BAD_INPUT = 2


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
                    "print a summary: task groups, time steps, tasks and total cost. Every "
                    "problem is listed at once, each with the key, the offending value, "
                    "why, and what is allowed. Writes nothing.",
        epilog="exit status: 0 if the job is valid, 2 if not (or the file is unreadable)")
    add_job_arguments(parser)
    parser.set_defaults(handler=_validate)


def _validate(args) -> int:
    try:
        job = job_from_args(args)
    except JobError as err:
        print(err, file=sys.stderr)
        return EXIT_BAD_INPUT
    print(summary(job))
    return EXIT_OK


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
        shear = f"steady, rate = {s.rate:g} [1/{unit}]"
    else:
        shear = "none (quiescent)"
    lines = [
        f"job {job.job.name!r}: valid (hash {job_hash(job)[:16]})",
        f"  N = {job.system.n_particles}, phi = "
        + ", ".join(f"{p:g}" for p in job.system.phi) + f", medium {medium}",
        f"  shear {shear}; Brownian {'on' if job.brownian.enabled else 'off'}; "
        f"time unit {unit}",
    ]
    for omega in job.frequencies:
        head = "  every task      " if omega is None else f"  omega = {omega:<9.5g}"
        lines.append(f"{head}  dt = {job.time_step(omega):<9.3g} "
                     f"{job.n_steps(omega)} steps ({job.discard_steps(omega)} discarded)")
    cost = sum(t.cost for t in tasks)
    omegas = f"{len(s.omega)} omega x " if s.omega else ""
    lines.append(f"  tasks: {len(tasks)} = {len(job.system.phi)} phi x {omegas}"
                 f"{job.ensemble.realisations} realisations; "
                 f"total cost {cost:.3g} (steps x N^3); backend {job.solver.backend}, "
                 f"{job.ensemble.ranks_per_task} rank(s) per task")
    return "\n".join(lines)


# --------------------------------------------------------------------------- main

COMMANDS = (_add_validate,)


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


def main(argv=None) -> int:
    """Entry point of the ``sdmpi`` console script; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help, --version (0) and usage errors (2)
        return stop.code if isinstance(stop.code, int) else EXIT_BAD_INPUT
    if not hasattr(args, "handler"):
        parser.print_usage(sys.stderr)
        print("sdmpi: error: a command is required (see sdmpi --help)", file=sys.stderr)
        return EXIT_BAD_INPUT
    return args.handler(args)


if __name__ == "__main__":
    sys.exit(main())
