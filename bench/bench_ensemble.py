"""Benchmark: parallel efficiency of `sdmpi run` on P ranks against 1 rank, and the share
of the run spent in HDF5 writes + checkpoints, on a job of equal tasks at the default
output settings (checkpoint_every = 1000). Real SD (sdmpi.dynamics.Realisation).

Efficiency = T_1 / (P T_P) with T the wall time of the whole command (start-up, file
creation and numba cache loading included). A warm-up run fills the numba cache first.
Writes a JSON file and prints a summary. Needs P free cores for a fair number.
"""

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

JOB = """\
[job]
name = "bench-ensemble"
seed = 1
[system]
n_particles = {n}
phi = [0.3]
[shear]
omega = [6.283185307179586]
[integration]
steps_per_period = 250
periods = {periods}
discard_periods = 1
[ensemble]
realisations = {tasks}
"""

IO = re.compile(r"HDF5 writes \+ checkpoints ([\d.e+-]+) s = ([\d.]+)% of ([\d.e+-]+) s rank time")


def run(cmd, env):
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{res.stderr}")
    io = IO.search(res.stdout)
    return {"wall_s": wall, "io_s": float(io.group(1)), "io_percent": float(io.group(2)),
            "rank_time_s": float(io.group(3))}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--tasks", type=int, default=8, help="equal tasks (realisations)")
    ap.add_argument("--periods", type=int, default=8, help="periods of 250 steps per task")
    ap.add_argument("--n", type=int, default=8, help="particles per realisation")
    ap.add_argument("--out", default="bench/ensemble_results.json")
    args = ap.parse_args()

    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    sdmpi = [sys.executable, "-m", "sdmpi.cli"]
    mpirun = [shutil.which("mpirun"), "--oversubscribe", "-n", str(args.ranks)]
    with tempfile.TemporaryDirectory() as tmp:
        job = Path(tmp) / "job.toml"
        job.write_text(JOB.format(n=args.n, periods=args.periods, tasks=args.tasks))
        warm = ["--set", "integration.periods=1", "--set", "integration.discard_periods=0"]
        run(mpirun + sdmpi + ["run", str(job), "-o", f"{tmp}/warm.h5", *warm], env)
        one = run(sdmpi + ["run", str(job), "-o", f"{tmp}/one.h5"], env)
        many = run(mpirun + sdmpi + ["run", str(job), "-o", f"{tmp}/many.h5"], env)
    result = {
        "machine": platform.node(), "cpus": os.cpu_count(), "ranks": args.ranks,
        "tasks": args.tasks, "steps_per_task": 250 * args.periods, "n_particles": args.n,
        "one_rank": one, "p_ranks": many,
        "parallel_efficiency": one["wall_s"] / (args.ranks * many["wall_s"]),
    }
    Path(args.out).write_text(json.dumps(result, indent=2) + "\n")
    print(f"{args.tasks} tasks x {250 * args.periods} steps, N = {args.n}")
    print(f"1 rank: {one['wall_s']:.2f} s; {args.ranks} ranks: {many['wall_s']:.2f} s; "
          f"parallel efficiency {result['parallel_efficiency']:.3f}")
    print(f"HDF5 writes + checkpoints: {one['io_percent']:.3f}% (1 rank), "
          f"{many['io_percent']:.3f}% ({args.ranks} ranks) of rank time")


if __name__ == "__main__":
    main()
