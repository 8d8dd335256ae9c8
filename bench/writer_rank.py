"""Benchmark: the cost of writing the run file through rank 0 (serial h5py) against
parallel HDF5 (every rank writes its own tasks), on 2 ranks, and rank 0's share of a
checkpoint interval when P ranks send it their commits.

The realisation is the test double (tests/ensemble_double.py: the real sample datasets,
no physics) slowed to ``--step-ms`` per step, so that stepping takes the time of a real
step (about 5 ms at N = 27 on one core) and only the writing differs between the runs.
Both runs' `sdmpi run` summary lines give the HDF5 writes + checkpoints time and, on the
serial path, the time rank 0 spent applying the other rank's commits. The estimate for P
ranks: each of the P - 1 other ranks commits once per interval of ``checkpoint_every``
steps, so rank 0 spends (P - 1) x (time per applied commit) per interval; its share is that
over the interval's stepping time.

    python bench/writer_rank.py --out bench/writer_rank.json
"""

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent / "tests"
JOB = """\
[job]
name = "bench-writer"
seed = 3
[system]
n_particles = {n}
phi = [0.45]
[shear]
omega = [25.132741228718345]
[integration]
steps_per_period = 500
periods = {periods}
discard_periods = 1
[ensemble]
realisations = {tasks}
[output]
checkpoint_every = {every}
"""
IO = re.compile(r"HDF5 writes \+ checkpoints ([\d.e+-]+) s = ([\d.]+)% of ([\d.e+-]+) s rank time")
SERVED = re.compile(r"rank 0 applied (\d+) commits of the other ranks in ([\d.e+-]+) s")


def run(serial: bool, job: Path, out: Path, step_ms: float) -> str:
    head = [sys.executable, str(TESTS / "ensemble_run.py"), *(["--serial-h5py"] if serial else [])]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               SDMPI_DOUBLE_SLEEP=str(step_ms / 1000))
    res = subprocess.run(["mpirun", "--oversubscribe", "-n", "2", *head, "run", str(job),
                          "-o", str(out)], capture_output=True, text=True, env=env, check=True)
    return res.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=27)
    parser.add_argument("--tasks", type=int, default=4)
    parser.add_argument("--periods", type=int, default=12)
    parser.add_argument("--every", type=int, default=1000)
    parser.add_argument("--step-ms", type=float, default=5.0)
    parser.add_argument("--out", type=Path, default=HERE / "writer_rank.json")
    args = parser.parse_args()
    result = {"command": "python bench/writer_rank.py " + " ".join(sys.argv[1:]),
              "machine": platform.platform(), "n_particles": args.n, "tasks": args.tasks,
              "steps_per_task": args.periods * 500, "checkpoint_every": args.every,
              "step_ms": args.step_ms}
    with tempfile.TemporaryDirectory() as tmp:
        job = Path(tmp) / "job.toml"
        job.write_text(JOB.format(n=args.n, tasks=args.tasks, periods=args.periods,
                                  every=args.every))
        for name, serial in (("parallel_hdf5", False), ("serial_h5py", True)):
            text = run(serial, job, Path(tmp) / f"{name}.h5", args.step_ms)
            io, share, rank_time = IO.search(text).groups()
            entry = {"io_s": float(io), "io_percent": float(share), "rank_time_s": float(rank_time)}
            served = SERVED.search(text)
            if served:
                entry["commits_applied"], entry["apply_s"] = int(served[1]), float(served[2])
            result[name] = entry
    serial = result["serial_h5py"]
    per_commit = serial["apply_s"] / serial["commits_applied"]
    interval = args.every * args.step_ms / 1000
    result["apply_ms_per_commit"] = 1000 * per_commit
    result["rank0_share_at_P"] = {str(p): (p - 1) * per_commit / interval for p in (2, 10, 100, 1000)}
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
