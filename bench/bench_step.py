"""Benchmark: ms per Brownian SD step of one realisation, in Cholesky equivalents.

The setting of the Schaink et al. (2000) study (jobs/schaink2000_newtonian.toml: phi = 0.45, dt = 5e-4 t_D,
Brownian, oscillatory shear, dense solver, the rfd drift scheme, ewald_tolerance 1e-3,
and again at 1e-4 and 1e-6 in "single_ewald_1e-4", "single_ewald_1e-6"), one rank, BLAS
on one thread (the Makefile pins it), for N = 8, 27, 64, 125 (N = 8 is mostly the part
of a step that does not grow with N: the interpreter's and numpy's per-call work, which
is what stepping realisations in lockstep could share). A step includes its hydrodynamic
evaluation, the resistance change of the random finite difference, the overlap and
near-contact corrections, the drift and the Brownian stresslets (`Realisation.advance`).
"rank_of_7": the same per realisation-step with seven realisations on the rank, stepped one
after another as a rank of a study steps the tasks it owns (that study's 49 tasks on 7
ranks). Each size is timed in blocks of steps interleaved with blocks of one 297 x 297 LAPACK
Cholesky (dpotrf) in the same process; the medians of their CPU times give
"Cholesky-equivalents per step", a figure that holds up under other load and carries
roughly across machines (wall-clock ms are recorded too; on an idle machine they agree).
Also times the first step of a realisation from an empty numba cache, in a fresh process
("cold_first_step_s": the kernels' compile time, which every new installation and every
cluster node without a shared cache pays once; `--no-cold` skips it). Writes
bench/step.json.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python bench/bench_step.py
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np
from scipy.linalg import lapack

from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation

JOB = "jobs/schaink2000_newtonian.toml"


def cholesky_matrix(n=297):
    """The n x n symmetric positive definite matrix whose Cholesky the benchmarks time
    as their unit of machine speed."""
    a = np.random.default_rng(0).standard_normal((n, n))
    return a @ a.T + n * np.eye(n)


def cholesky_ms(spd, repeat=20):
    """(wall, CPU) ms of one dpotrf of spd."""
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(repeat):
        lapack.dpotrf(spd)
    return 1e3 * (time.perf_counter() - w0) / repeat, 1e3 * (time.process_time() - c0) / repeat


def time_steps(n, blocks, steps_per_block, spd, overrides=(), realisations=1):
    """Median wall and CPU ms per realisation-step and per Cholesky over interleaved blocks;
    the Cholesky-equivalents from the CPU times (robust when other processes share the
    cores). realisations > 1: that many tasks of the job live on the rank and each block
    steps them one after another, steps_per_block in all, as a rank of a study steps the
    tasks it owns."""
    job = load_job(JOB, overrides=[f"system.n_particles={n}", *overrides])
    tasks = enumerate_tasks(job)[:realisations]
    reals = [Realisation(job, task) for task in tasks]
    for real in reals:
        real.advance(3)  # warm-up: numba caches, lubrication tables
    task, real = tasks[0], reals[0]
    share = max(1, steps_per_block // len(reals))
    steps_per_block = share * len(reals)
    step, chol = [], []
    for _ in range(blocks):
        chol.append(cholesky_ms(spd))
        w0, c0 = time.perf_counter(), time.process_time()
        for each in reals:
            each.advance(share)
        step.append((1e3 * (time.perf_counter() - w0) / steps_per_block,
                     1e3 * (time.process_time() - c0) / steps_per_block))
    (step_wall, step_cpu), (chol_wall, chol_cpu) = np.median(step, axis=0), np.median(chol, axis=0)
    return {"ms_per_step": float(step_wall), "cholesky_ms": float(chol_wall),
            "cpu_ms_per_step": float(step_cpu), "cpu_cholesky_ms": float(chol_cpu),
            "cholesky_equivalents": float(step_cpu / chol_cpu),
            "steps": blocks * steps_per_block, "realisations": len(reals), "dt": task.dt, "phi": task.phi,
            "ewald_tolerance": job.ewald_tolerance, "backend": getattr(real.model, "backend", None)}


COLD_SCRIPT = """
import time
t0 = time.perf_counter()
from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation
job = load_job({job!r}, overrides=["system.n_particles=27"])
Realisation(job, enumerate_tasks(job)[0]).advance(1)
print(time.perf_counter() - t0)
"""


def cold_first_step_seconds():
    """Wall seconds of imports, set-up and the first step at N = 27 in a fresh process with an
    empty numba cache (every kernel compiled)."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        out = subprocess.run([sys.executable, "-c", COLD_SCRIPT.format(job=JOB)], env=env, check=True,
                             capture_output=True, text=True)
    return float(out.stdout.split()[-1])


def show(n, r, note=""):
    """Print one timing's line; returns it."""
    print(f"{n:5d} {r['ewald_tolerance']:6.0e} {r['ms_per_step']:9.2f} {r['cholesky_ms']:9.3f} "
          f"{r['cpu_ms_per_step']:9.2f} {r['cpu_cholesky_ms']:9.3f} {r['cholesky_equivalents']:9.1f}{note}",
          flush=True)
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 27, 64, 125])
    ap.add_argument("--blocks", type=int, default=7)
    ap.add_argument("--seconds", type=float, default=3.0, help="rough stepping time per block and size")
    ap.add_argument("--out", default="bench/step.json")
    ap.add_argument("--no-cold", action="store_true", help="skip the first step from an empty numba cache")
    args = ap.parse_args()
    spd = cholesky_matrix()
    guess_ms = {8: 2.5, 27: 7.0, 64: 45.0, 125: 150.0}
    results = {"command": "make bench (python bench/bench_step.py)", "job": JOB,
               "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
               "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
               "date": time.strftime("%Y-%m-%d", time.gmtime()), "single": {}, "single_ewald_1e-4": {},
               "single_ewald_1e-6": {}, "rank_of_7": {}}
    print(f"{'N':>5} {'Ewald':>6} {'ms/step':>9} {'Cholesky':>9} {'cpu ms':>9} {'cpu Chol':>9} {'Ch-equiv':>9}")
    for n in args.sizes:
        per_block = max(2, int(1e3 * args.seconds / args.blocks / guess_ms.get(n, 0.02 * n ** 2)))
        for name, overrides in (("single", ()), *((f"single_ewald_{tol}", (f"hydrodynamics.ewald_tolerance={tol}",))
                                                  for tol in ("1e-4", "1e-6"))):
            results[name][str(n)] = show(n, time_steps(n, args.blocks, per_block, spd, overrides))
    for n in args.sizes:  # seven realisations on one rank (that study's 49 tasks on 7 ranks)
        per_block = max(7, int(1e3 * args.seconds / args.blocks / guess_ms.get(n, 0.02 * n ** 2)))
        results["rank_of_7"][str(n)] = show(n, time_steps(n, args.blocks, per_block, spd, realisations=7),
                                            "  (7 realisations on the rank)")
    if not args.no_cold:
        results["cold_first_step_s"] = cold_first_step_seconds()
        print(f"first step from an empty numba cache: {results['cold_first_step_s']:.0f} s", flush=True)
    results["load_average"] = os.getloadavg()  # other work on the machine while it ran
    with open(args.out, "w") as fh:
        json.dump(results, fh, indent=2)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
