"""Benchmark: the petsc-dense backend (ScaLAPACK Cholesky of R_FU through PETSc) against
dense (LAPACK, one rank), on 1 and 2 ranks, phi = 0.45, BLAS threads pinned to 1.

Per N, R is assembled once (replicated on every rank, not timed here: see
bench_hydro.py), then, median of `repeat`:
  build  - make_solver: distribute R_FU, factorise (and, petsc-dense, copy L out for the
           Brownian product)
  solve  - velocities + stresslets for a shear flow (one triangular solve pair, gathered)
  brown  - brownian_forces (C z)
Not part of the test suite. Usage:

  python bench/bench_petsc.py                  # launches itself on 1 and 2 ranks
  python bench/bench_petsc.py --ranks 1 2 4 --sizes 125 343 --out bench/petsc_results.json
"""

import argparse
import json
import os
import platform
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np

from workers import emit, run_worker  # bench/ is on sys.path when run as a script


def measure(sizes, repeat):
    from mpi4py import MPI

    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro.basis import to_five
    from sdmpi.hydro.resistance import grand_resistance
    from sdmpi.hydro.solvers import make_solver

    comm = MPI.COMM_WORLD
    rows = []
    for n in sizes:
        rng = np.random.default_rng(1)
        pos, side = hard_sphere_fluid(n, 0.45, rng)
        res = grand_resistance(pos, np.ones(n), [side] * 3, 0.0)
        e5 = np.broadcast_to(to_five(np.array([[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]])), (n, 5))
        z = rng.standard_normal((n, 6))
        backends = [("petsc-dense", comm)] + ([("dense", None)] if comm.rank == 0 else [])
        for name, c in backends:
            times = {"build": [], "solve": [], "brown": []}
            for _ in range(repeat + 1):  # first: warm-up
                if c is not None:
                    c.Barrier()
                t0 = time.perf_counter()
                solver = make_solver(name, res, c)
                t1 = time.perf_counter()
                vel = solver.velocities(np.zeros((n, 6)), e5)
                solver.stresslets(vel, e5)
                t2 = time.perf_counter()
                solver.brownian_forces(z)
                t3 = time.perf_counter()
                for key, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
                    times[key].append(dt)
                del solver
            med = {k: float(np.median(v[1:])) for k, v in times.items()}
            if c is not None:  # the slowest rank counts
                med = {k: comm.allreduce(v, op=MPI.MAX) for k, v in med.items()}
            if comm.rank == 0:
                rows.append({"N": n, "backend": name, "ranks": comm.size if c is not None else 1,
                             **med, "total": sum(med.values())})
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[125, 343])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default="bench/petsc_results.json")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        rows = measure(args.sizes, args.repeat)
        if rows:
            emit(rows)
        return
    rows = []
    for p in args.ranks:
        rows += run_worker(__file__, ["--repeat", args.repeat, "--sizes", *args.sizes], p)
    seen, table = set(), []
    for r in sorted(rows, key=lambda r: (r["N"], r["backend"] != "dense", r["ranks"])):
        key = (r["N"], r["backend"], r["ranks"])
        if key not in seen:
            seen.add(key)
            table.append(r)
    print(f"{'N':>5} {'backend':>12} {'ranks':>5} {'build':>9} {'solve':>9} {'brown':>9} {'total':>9}")
    for r in table:
        print(f"{r['N']:>5} {r['backend']:>12} {r['ranks']:>5} {r['build']:>9.4f} "
              f"{r['solve']:>9.4f} {r['brown']:>9.4f} {r['total']:>9.4f}")
    with open(args.out, "w") as f:
        json.dump({"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                   "unit": "s (median)", "rows": table}, f, indent=1)


if __name__ == "__main__":
    main()
