"""Benchmark: assemble R and solve one mobility problem at phi = 0.45 (one rank, BLAS
threads pinned to 1 by the Makefile). Writes a JSON file and prints a table of where the
time goes: Ewald real space, Ewald reciprocal space, the inverse of M_inf (its block form,
`hydro.resistance`), lubrication, factorisation of R_FU and solve. Median of `repeat` runs after a warm-up
(numba compilation excluded)."""

import argparse
import json
import os
import platform
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np

from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro import farfield, lubrication, resistance, solvers
from sdmpi.hydro.basis import to_five
from sdmpi.hydro.geometry import Lattice


def one_solve(pos, side, timings):
    n = len(pos)
    radii = np.ones(n)
    lattice = Lattice([side] * 3, 0.0)
    t0 = time.perf_counter()
    plan = farfield.plan_far_field(pos, radii, lattice, tol=resistance.DEFAULT_EWALD_TOL)
    mob = np.zeros((farfield.NDOF * n, farfield.NDOF * n))
    grid = plan.grid
    farfield._real_space_sum(pos, radii, *plan.images, plan.table, grid.values, grid.r0, grid.h,
                             plan.params.xi, farfield.BASIS, mob)
    t1 = time.perf_counter()
    farfield._reciprocal_sum(pos, radii, plan, mob)
    for i in range(n):
        s = slice(farfield.NDOF * i, farfield.NDOF * (i + 1))
        mob[s, s] += plan.self_blocks[1.0]
    t2 = time.perf_counter()
    far = resistance.far_field_blocks(mob)
    t3 = time.perf_counter()
    pairs = lubrication.close_pairs(pos, radii, lattice)
    res = resistance.from_blocks(far, lubrication.lubrication_partitions(radii, pairs, n), pairs, None, pos, radii)
    t4 = time.perf_counter()
    solver = solvers.DenseSolver(res)
    e5 = np.broadcast_to(to_five(np.array([[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]])), (n, 5))
    vel = solver.velocities(np.zeros((n, 6)), e5)
    solver.stresslets(vel, e5)
    t5 = time.perf_counter()
    for key, dt in zip(["ewald_real", "ewald_recip", "invert_M", "lubrication", "factor_solve"],
                       [t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4]):
        timings.setdefault(key, []).append(dt)
    timings.setdefault("total", []).append(t5 - t0)
    return plan.params


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="+", default=[27, 125, 343])
    ap.add_argument("--repeat", type=int, default=11)
    ap.add_argument("--out", default="bench/results.json")
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    results = {"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
               "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"), "phi": 0.45, "sizes": {}}
    print(f"{'N':>5} {'xi':>6} {'real':>9} {'recip':>9} {'inv M':>9} {'lub':>9} {'solve':>9} {'total':>9}  [ms]")
    for n in args.sizes:
        pos, side = hard_sphere_fluid(n, 0.45, rng)
        one_solve(pos, side, {})  # warm-up (numba compile / cache load)
        timings = {}
        for _ in range(args.repeat):
            par = one_solve(pos, side, timings)
        med = {k: float(np.median(v)) for k, v in timings.items()}
        results["sizes"][str(n)] = med | {"xi": par.xi, "rcut": par.rcut, "kcut": par.kcut}
        print(f"{n:5d} {par.xi:6.3f}" + "".join(f" {1e3 * med[k]:9.1f}" for k in
              ("ewald_real", "ewald_recip", "invert_M", "lubrication", "factor_solve", "total")))
    with open(args.out, "w") as fh:
        json.dump(results, fh, indent=2)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
