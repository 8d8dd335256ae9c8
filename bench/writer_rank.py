"""Benchmark: the cost of writing the run file through rank 0 (serial h5py) against
parallel HDF5 (every rank writes its own tasks), on 2 ranks, and rank 0's share of a
checkpoint interval when P ranks send it their commits.

The realisation is the test double (tests/ensemble_double.py: the real sample datasets,
no physics) slowed to ``--step-ms`` per step, so that stepping takes the time of a real
step (about 5 ms at N = 27 on one core) and only the writing differs between the runs.
Both runs' `sdmpi run` summary lines give the HDF5 writes + checkpoints time and, on the
serial path, the time rank 0 spent applying the other rank's commits. Then, in this
process, rank 0's work alone: applying batches of K = 1, 10, 100 commits (one checkpoint
interval of one task each) to a serial run file, t(K) = fixed + K x per commit (the fixed
part: the flushes and the fsync of a batch). The estimate for P ranks: each of the P - 1
other ranks commits once per interval of ``checkpoint_every`` steps, and rank 0 applies what
has arrived at most every SERVE_EVERY seconds, so per interval it spends
min(P - 1, interval / SERVE_EVERY) x fixed + (P - 1) x per commit; its share is that over
the interval.

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
import time
from pathlib import Path

from sdmpi.ensemble.store import SERVE_EVERY, RunFile, TaskLayout, create

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


class _Collecting(RunFile):
    """A writable run file whose commits are collected instead of applied."""

    def __init__(self, path):
        from mpi4py import MPI
        super().__init__(path, MPI.COMM_SELF)
        self.collected = []

    def _submit(self, ops):
        self.collected.append(ops)


def batch_seconds(job_path: Path, where: Path, sizes=(1, 10, 100)) -> dict:
    """Median time for rank 0 to apply a batch of K commits (one checkpoint interval of
    one task each, K different tasks), on a serial run file of the job in ``where``."""
    sys.path.insert(0, str(TESTS))
    from ensemble_double import DoubleRealisation
    from mpi4py import MPI

    from sdmpi.config import enumerate_tasks, load_job

    job = load_job(str(job_path))
    tasks = enumerate_tasks(job)[:max(sizes)]
    reals = {t.task_id: DoubleRealisation(job, t) for t in tasks}
    layouts = {t.task_id: TaskLayout.of(r) for t, r in zip(tasks, reals.values())}
    path = where / "batches.h5"
    create(path, job, "", layouts, MPI.COMM_SELF, json.dumps({}), "now")
    handle = _Collecting(path)
    every = job.output.checkpoint_every
    for t in tasks:
        handle.begin(t.task_id, -1)
        samples = reals[t.task_id].advance(every)
        handle.commit(t.task_id, handle.samples(t.task_id), 0, every, samples,
                      reals[t.task_id].get_state(), 0)
    out = {}
    for k in sizes:
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            handle._apply(handle.collected[:k])
            times.append(time.perf_counter() - t0)
        out[k] = sorted(times)[2]
    handle.close()
    return out


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
        many = Path(tmp) / "many.toml"  # a task per commit of the largest batch
        many.write_text(JOB.format(n=args.n, tasks=100, periods=args.periods, every=args.every))
        batches = batch_seconds(many, Path(tmp))
    # t(K) = fixed + K x per_commit, from the smallest and largest batch
    (k0, t0), (k1, t1) = min(batches.items()), max(batches.items())
    per_commit = (t1 - t0) / (k1 - k0)
    fixed = max(t0 - k0 * per_commit, 0.0)
    interval = args.every * args.step_ms / 1000
    result.update(serve_every_s=SERVE_EVERY, batch_ms={str(k): 1000 * t for k, t in batches.items()},
                  batch_fixed_ms=1000 * fixed, batch_ms_per_commit=1000 * per_commit)
    # per checkpoint interval: P - 1 commits in at most interval / SERVE_EVERY batches
    share = {}
    for p in (2, 10, 100, 1000):
        n_batches = min(p - 1, interval / SERVE_EVERY)
        share[str(p)] = (n_batches * fixed + (p - 1) * per_commit) / interval
    result["rank0_share_at_P"] = share
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
