"""Shared by the benchmarks that measure under mpirun: each runs its own script again as
a worker (one process group per measurement, so memory and MPI state belong to that
run) and reads the rows the worker prints; or, run under mpirun itself on one job file,
takes the command line of `job_benchmark`."""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

#: one BLAS/OpenMP thread per rank; mpirun allowed as root (containers)
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
TAG = "ROWS "


def emit(rows):
    """Worker side: hand the rows (a list of dicts) to the launcher."""
    print(TAG + json.dumps(rows), flush=True)


def run_worker(script, args, ranks, cwd=None):
    """Run `script --worker *args` on `ranks` ranks (under mpirun when > 1) and return
    the rows it emitted; exit with its error output if it fails."""
    cmd = [sys.executable, str(script), "--worker", *map(str, args)]
    if ranks > 1:
        cmd = [shutil.which("mpirun"), "--oversubscribe", "-n", str(ranks), *cmd]
    res = subprocess.run(cmd, capture_output=True, text=True, env=ENV, cwd=cwd)
    if res.returncode != 0:
        sys.exit(f"{' '.join(cmd)}: failed\n{res.stderr[-3000:]}")
    text = re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", res.stdout)  # stray terminal escapes (seen: ESC[0m)
    return [row for line in text.splitlines() if line.startswith(TAG)
            for row in json.loads(line[len(TAG):])]


def report(row, out=None, label=None):
    """Print the row as JSON; with out (a path), merge it into that JSON file under label."""
    print(json.dumps(row, indent=1), flush=True)
    if out:
        path = Path(out)
        data = json.loads(path.read_text()) if path.exists() else {}
        data[label] = row
        path.write_text(json.dumps(data, indent=1) + "\n")


def job_benchmark(doc, measure, steps):
    """The command line of a benchmark of one job file, run on every rank of mpirun:
    JOB, --set KEY=VALUE (repeatable), --steps (argparse keywords ``steps``), --label,
    --out. Calls measure(job, overrides, steps) on every rank; rank 0 reports the row
    (`report`; the label defaults to the overrides joined by "-")."""
    from mpi4py import MPI

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("job")
    ap.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE")
    ap.add_argument("--steps", **steps)
    ap.add_argument("--label", default=None)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    row = measure(args.job, args.overrides, args.steps)
    if MPI.COMM_WORLD.rank == 0:
        report(row, args.out, args.label or "-".join(args.overrides))
