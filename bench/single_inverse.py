#!/usr/bin/env python3
"""Benchmark: a Brownian step with M_inf inverted in single against double precision.

The setting of `bench/bench_step.py` (jobs/schaink2000_newtonian.toml: phi = 0.45, Ewald
tolerance 1e-3, dense backend, one rank, BLAS on one thread), stepped in fresh processes
taken in pairs, double then single precision (A B A B), so that a drift of the machine's
speed falls on both alike. Single precision is what `grand_resistance` does from
`resistance.SINGLE_PRECISION_MIN_N` spheres on; each child sets that threshold to 1
(single) or beyond N (double). Each child times its steps in blocks interleaved with a
297 x 297 Cholesky (`bench_step.time_steps`): the figure is Cholesky-equivalents per
step, and the ratio single / double of each pair. Writes bench/single_inverse.json.

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python bench/single_inverse.py --sizes 27 64 125 343
"""

import argparse
import json
import os
import subprocess
import sys
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)


def child(precision, n, blocks):
    """Cholesky-equivalents per step at N = n with the given precision of the inversion (one
    process)."""
    from bench_step import cholesky_matrix, time_steps

    from sdmpi.hydro import resistance

    resistance.SINGLE_PRECISION_MIN_N = 1 if precision == "single" else n + 1
    result = time_steps(n, blocks, max(2, 300 // n), cholesky_matrix())
    print(json.dumps({"precision": precision, "n": n, "cholesky_equivalents": result["cholesky_equivalents"],
                      "cpu_ms_per_step": result["cpu_ms_per_step"], "cpu_cholesky_ms": result["cpu_cholesky_ms"]}))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[27, 64, 125, 343])
    ap.add_argument("--pairs", type=int, default=3)
    ap.add_argument("--blocks", type=int, default=5)
    ap.add_argument("--out", default="bench/single_inverse.json")
    ap.add_argument("--child", nargs=2, metavar=("PRECISION", "N"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], int(args.child[1]), args.blocks)
        return
    results = {"command": "python bench/single_inverse.py", "date": time.strftime("%Y-%m-%d", time.gmtime()),
               "sizes": {}}
    for n in args.sizes:
        pairs = []
        for _ in range(args.pairs):
            pair = {}
            for precision in ("double", "single"):
                out = subprocess.run([sys.executable, __file__, "--child", precision, str(n), "--blocks",
                                      str(args.blocks)], check=True, capture_output=True, text=True, env=os.environ)
                pair[precision] = json.loads(out.stdout.strip().splitlines()[-1])
            pair["ratio"] = pair["single"]["cholesky_equivalents"] / pair["double"]["cholesky_equivalents"]
            pairs.append(pair)
            print(f"N = {n}: double {pair['double']['cholesky_equivalents']:.1f}, single "
                  f"{pair['single']['cholesky_equivalents']:.1f} Cholesky-equivalents, ratio {pair['ratio']:.3f}",
                  flush=True)
        results["sizes"][str(n)] = pairs
    results["load_average"] = os.getloadavg()
    with open(args.out, "w") as fh:
        json.dump(results, fh, indent=2)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
