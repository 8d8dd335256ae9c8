"""Benchmark: seconds per Brownian step of `sdmpi run` as users run it, in units of a 297 x
297 LAPACK Cholesky timed in the same processes.

Run under ``mpirun -n P``: every rank times a Cholesky (`bench_step.cholesky_ms`, median
of five timings of 20), then runs ``sdmpi run JOB -o OUT`` in-process (`sdmpi.cli.main`,
the console script's entry) with --set integration.n_steps=S for each S of --steps (the
first the short run, e.g. 2; a fresh run file each), then times the Cholesky again. The
wall time per step is the difference between the runs over the difference of their step
counts (the start, the Monte Carlo, the run file and the first step's compilation
cancel), and its Cholesky-equivalents that time over the Cholesky's wall time (median of
the ranks' timings before and after). Also the peak resident memory of each rank over
the runs (ru_maxrss, GiB). Prints a JSON row; --out FILE merges it into FILE under
--label.

    mpirun -n 2 python bench/run_cost.py jobs/large_n_krylov.toml --steps 2 12 \\
        --set 'shear.protocol="none"' --set integration.dt=5e-4 --set integration.discard_steps=0 \\
        --set ensemble.realisations=1 --label n1000_rest_dt5e-4 --out bench/run_cost.json
"""

import resource
import tempfile
import time
from pathlib import Path

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np
from mpi4py import MPI

from bench_step import cholesky_matrix, cholesky_ms  # bench/ is on sys.path when run as a script
from workers import job_benchmark

from sdmpi.cli import main as sdmpi_main


def cholesky_wall_ms(spd):
    """Median wall ms of one Cholesky of spd over five timings."""
    return float(np.median([cholesky_ms(spd)[0] for _ in range(5)]))


def measure(job, overrides, steps):
    """The row: wall seconds of each run (max over ranks), seconds per step, Cholesky ms."""
    comm = MPI.COMM_WORLD
    spd = cholesky_matrix()
    chol = [cholesky_wall_ms(spd)]
    walls = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in steps:
            out = str(Path(tmp) / f"run{s}.h5") if comm.rank == 0 else None
            out = comm.bcast(out, root=0)
            args = ["run", job, "-o", out, "--set", f"integration.n_steps={s}"]
            for o in overrides:
                args += ["--set", o]
            comm.Barrier()
            t0 = time.perf_counter()
            code = sdmpi_main(args)
            comm.Barrier()
            walls.append(comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
            if code:
                raise SystemExit(f"sdmpi run exited with {code}")
    chol.append(cholesky_wall_ms(spd))
    chol = sorted(c for pair in comm.allgather(chol) for c in pair)
    per_step = (walls[-1] - walls[0]) / (steps[-1] - steps[0])
    chol_ms = float(np.median(chol))
    return {"job": job, "overrides": overrides, "ranks": comm.size, "steps": steps, "wall_s": walls,
            "wall_s_per_step": per_step, "cholesky_wall_ms": chol,
            "cholesky_equivalents_per_step": 1e3 * per_step / chol_ms,
            "peak_rss_gib_per_rank": comm.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20)}


if __name__ == "__main__":
    job_benchmark(__doc__, measure, dict(type=int, nargs=2, default=[2, 12]))
