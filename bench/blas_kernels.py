"""Benchmark: OpenBLAS's generic kernels against those `sdmpi run` chooses for the CPU.

Where OpenBLAS cannot identify the CPU (a virtual machine reporting a generic model) it
runs its generic x86-64 kernels ("Prescott"); sdmpi's command line then chooses the
kernels the CPU's instruction sets allow (`sdmpi._blas_kernel`). This times both, each in
a fresh process with OPENBLAS_CORETYPE set, the two alternating (A B A B) so that a drift
of the shared machine's speed falls on both: a 297 x 297 Cholesky factorisation (the
project's reference unit), a 1000 x 1000 matrix product, the inverse of a 2058 x 2058
symmetric positive definite matrix by Cholesky (potrf + potri: the Schur complement of
M_inf at N = 343), and the CPU time of a dense Brownian SD step at N = 125 and 343
(jobs/finite_size_n125.toml and jobs/finite_size_n343.toml, one realisation). CPU times
(process time), one BLAS thread. Writes bench/blas_kernels.json.

    python bench/blas_kernels.py [--rounds 2] [--out bench/blas_kernels.json]
"""

import argparse
import datetime
import json
import os
import subprocess
import sys

from sdmpi._blas_kernel import cpu_flags, kernel_for

#: what one measurement process runs (prints one JSON line)
MEASURE = r"""
import json, time
import numpy as np
from scipy.linalg import lapack
from sdmpi._blas_kernel import openblas_kernel

def cpu(f, repeat):
    best = float("inf")
    for _ in range(repeat):
        t = time.process_time(); f(); best = min(best, time.process_time() - t)
    return best

rng = np.random.default_rng(1)
def spd(n):
    a = rng.standard_normal((n, n)); return np.asfortranarray(a @ a.T + n * np.eye(n))
c297, a1000, s2058 = spd(297), rng.standard_normal((1000, 1000)), spd(2058)
out = {"kernels": openblas_kernel(),
       "cholesky_297_ms": 1e3 * cpu(lambda: lapack.dpotrf(c297, lower=False), 50),
       "dgemm_1000_gflops": 2e-9 * 1000 ** 3 / cpu(lambda: a1000 @ a1000, 5)}
def inverse():
    ch, _ = lapack.dpotrf(s2058, lower=False, clean=False); lapack.dpotri(ch, lower=False)
out["spd_inverse_2058_s"] = cpu(inverse, 2)

from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation
for n, job, steps in ((125, "jobs/finite_size_n125.toml", 6), (343, "jobs/finite_size_n343.toml", 2)):
    real = Realisation(load_job(job, overrides=["ensemble.realisations=1"]),
                       enumerate_tasks(load_job(job, overrides=["ensemble.realisations=1"]))[0])
    real.advance(2)
    t = time.process_time(); real.advance(steps)
    out[f"dense_step_n{n}_s"] = (time.process_time() - t) / steps
print(json.dumps(out))
"""


def measure(kernel):
    env = dict(os.environ, OPENBLAS_CORETYPE=kernel, OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    res = subprocess.run([sys.executable, "-c", MEASURE], env=env, capture_output=True,
                         text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", default="bench/blas_kernels.json")
    args = ap.parse_args()
    chosen = kernel_for(cpu_flags())
    if chosen is None:
        sys.exit("this CPU has no AVX2: sdmpi leaves OpenBLAS's own choice, nothing to compare")
    runs = {"Prescott": [], chosen: []}
    for _ in range(args.rounds):
        for kernel in runs:
            runs[kernel].append(measure(kernel))
            print(kernel, runs[kernel][-1], flush=True)
    best = {k: {q: (min if q != "dgemm_1000_gflops" else max)(r[q] for r in rs)
                for q in rs[0] if q != "kernels"} for k, rs in runs.items()}
    speedup = {q: (best["Prescott"][q] / best[chosen][q] if q != "dgemm_1000_gflops"
                   else best[chosen][q] / best["Prescott"][q]) for q in best[chosen]}
    in_cholesky = {k: {q: v / (1e-3 * b["cholesky_297_ms"]) for q, v in b.items()
                       if q.endswith("_s")} for k, b in best.items()}
    result = {"command": "python bench/blas_kernels.py", "date": datetime.date.today().isoformat(),
              "cpu_flags_kernel": chosen, "loaded": {k: rs[0]["kernels"] for k, rs in runs.items()},
              "best_of_rounds": best, "speedup": speedup, "in_cholesky_297": in_cholesky,
              "runs": runs}
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)
    print(json.dumps({"speedup": speedup, "in_cholesky_297": in_cholesky}, indent=1))


if __name__ == "__main__":
    main()
