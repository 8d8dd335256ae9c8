"""Benchmark: where the CPU time of a Brownian SD step goes, part by part.

The setting of `bench/bench_step.py` (jobs/schaink2000_newtonian.toml, phi = 0.45, one
rank, BLAS on one thread). Each part's functions are wrapped by a timer (process CPU time
around each call; the wrappers cost ~1 us a call) and one realisation is stepped; a part's
share is its time over the time of the steps, "the rest" is what no part claims (the
integrator, the overlap and near-contact corrections, the Brownian noise, small solves and
products, Python glue).

A second pass wraps every compiled kernel instead (each numba dispatcher of sdmpi's modules
and each SciPy LAPACK and BLAS routine the code calls) and gives their share of the step:
the arithmetic a step cannot shed by being organised differently. Its inverse,
"lockstep_ceiling", bounds the speed-up of stepping many realisations together in lockstep
with batched kernels: a batch shares the per-call work of the interpreter and numpy among
its realisations, but each realisation keeps its own kernels' arithmetic (one LAPACK
factorisation per matrix, the pair sums image by image). The bound is generous: numpy's
own dense products count as shareable. Writes bench/step_shares.json.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python bench/step_shares.py
"""

import argparse
import importlib
import json
import pkgutil
import time

import sdmpi  # before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does
from numba.core.registry import CPUDispatcher
from scipy.linalg import blas, lapack

from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation
from sdmpi.hydro import farfield, resistance, solvers

JOB = "jobs/schaink2000_newtonian.toml"

#: part -> (module, function name) pairs whose calls it owns (disjoint call trees)
PARTS = {
    "Ewald real-space sum": [(farfield, "_real_space_sum")],
    "Ewald reciprocal sum (phases, wave tensors, BLAS)": [(farfield, "_reciprocal_sum")],
    "far-field plans (pair search, wave vectors)": [(farfield, "plan_far_field"), (resistance, "plan_far_field")],
    "inverse of M_inf (Schur complement, potrf + potri)": [(resistance, "far_field_blocks")],
    "lubrication blocks and their dense partitions": [(resistance, "lubrication_partitions")],
    "far-field change of the random finite difference": [(resistance, "far_field_product")],
    "lubrication change of the random finite difference": [(resistance, "lubrication_product")],
    "Cholesky of R_FU": [(solvers.DenseSolver, "__init__")],
    "solves and products with R": [(solvers.DenseSolver, "velocities"), (solvers.DenseSolver, "stresslets"),
                                   (solvers.DenseSolver, "brownian_velocities")],
}


def timed(function, add, depth):
    """function wrapped so that the CPU time of each call is passed to add(seconds); a call
    made while another function sharing the counter `depth` (a one-element list) is being
    timed is not timed again."""
    def call(*args, **kwargs):
        if depth[0]:
            return function(*args, **kwargs)
        depth[0] += 1
        t0 = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            add(time.process_time() - t0)
            depth[0] -= 1
    return call


def instrument(totals):
    """Wrap every part's functions so that their CPU time is added to totals[part].
    Returns a function that puts the originals back."""
    originals, depth = [], [0]
    for part, targets in PARTS.items():
        totals[part] = 0.0
        for owner, name in targets:
            original = getattr(owner, name)
            originals.append((owner, name, original))

            def add(seconds, _part=part):
                totals[_part] += seconds

            setattr(owner, name, timed(original, add, depth))

    def restore():
        for owner, name, original in originals:
            setattr(owner, name, original)
    return restore


def instrument_kernels(clock):
    """Wrap every compiled kernel (module docstring: the numba dispatchers of sdmpi's
    modules, the double-precision routines of scipy.linalg.lapack and .blas and the
    routines their get_lapack_funcs and get_blas_funcs return, through which sdmpi calls
    them) so that its CPU time is added to clock[0] (calls made while one
    is already timed count once)."""
    depth = [0]

    def add(seconds):
        clock[0] += seconds

    for info in pkgutil.walk_packages(sdmpi.__path__, "sdmpi."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        for name, obj in list(vars(module).items()):
            if isinstance(obj, CPUDispatcher):
                setattr(module, name, timed(obj, add, depth))
    for module in (lapack, blas):
        for name in dir(module):
            if name.startswith("d") and callable(getattr(module, name)):
                setattr(module, name, timed(getattr(module, name), add, depth))
    # the routines looked up by type (single or double precision, `resistance.far_field_blocks`)
    for module, lookup in ((lapack, "get_lapack_funcs"), (blas, "get_blas_funcs")):
        def timed_lookup(names, arrays=(), *args, _find=getattr(module, lookup), **kwargs):
            found = _find(names, arrays, *args, **kwargs)
            return timed(found, add, depth) if callable(found) else [timed(f, add, depth) for f in found]
        setattr(module, lookup, timed_lookup)


def step_realisation(n):
    """A warmed-up realisation of the benchmark's job at N = n."""
    job = load_job(JOB, overrides=[f"system.n_particles={n}"])
    real = Realisation(job, enumerate_tasks(job)[0])
    real.advance(3)  # warm-up: numba caches, lubrication tables
    return real


def kernel_share(n, steps, clock):
    """The compiled kernels' share of the CPU time of `steps` steps at N = n and the
    lockstep ceiling it implies (module docstring)."""
    real = step_realisation(n)
    clock[0] = 0.0
    t0 = time.process_time()
    real.advance(steps)
    total = time.process_time() - t0
    return {"cpu_ms_per_step": 1e3 * total / steps, "kernel_ms_per_step": 1e3 * clock[0] / steps,
            "kernel_share": clock[0] / total, "lockstep_ceiling": total / clock[0], "steps": steps}


def shares(n, steps, totals):
    """The parts' shares of the CPU time of `steps` steps at N = n (totals: the
    instrumented parts' accumulators)."""
    real = step_realisation(n)
    for part in totals:
        totals[part] = 0.0
    t0 = time.process_time()
    real.advance(steps)
    total = time.process_time() - t0
    out = {part: t / total for part, t in totals.items()}
    out["the rest (integrator, corrections, noise, glue)"] = 1.0 - sum(out.values())
    return {"cpu_ms_per_step": 1e3 * total / steps, "steps": steps, "shares": out}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[27, 125])
    ap.add_argument("--kernel-sizes", type=int, nargs="+", default=[8, 27, 64, 125])
    ap.add_argument("--out", default="bench/step_shares.json")
    args = ap.parse_args()
    results = {"command": "python bench/step_shares.py", "job": JOB,
               "date": time.strftime("%Y-%m-%d", time.gmtime()), "sizes": {}, "kernels": {}}
    totals = {}
    restore = instrument(totals)
    for n in args.sizes:
        results["sizes"][str(n)] = shares(n, max(10, int(300 * (27 / n) ** 2)), totals)
    restore()  # the kernel pass times the step without the parts' wrappers
    clock = [0.0]
    instrument_kernels(clock)
    for n in args.kernel_sizes:
        results["kernels"][str(n)] = kernel_share(n, max(10, int(300 * (27 / n) ** 2)), clock)
    for n, r in results["sizes"].items():
        print(f"N = {n}: {r['cpu_ms_per_step']:.2f} ms per step")
        for part, share in r["shares"].items():
            print(f"  {100 * share:5.1f}%  {part}")
    for n, r in results["kernels"].items():
        print(f"N = {n}: compiled kernels {100 * r['kernel_share']:.0f}% of {r['cpu_ms_per_step']:.2f} ms "
              f"per step: lockstep ceiling {r['lockstep_ceiling']:.2f}x")
    with open(args.out, "w") as fh:
        json.dump(results, fh, indent=2)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
