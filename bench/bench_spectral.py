"""Benchmark: the spectral Ewald far field (sdmpi/hydro/spectral.py), phi = 0.45,
Lees-Edwards strain 0.3, Ewald tolerances 1e-4 (the default) and 1e-6, BLAS threads pinned
to 1.

Per N, tolerance and rank count (each in a fresh process, so that peak memory is its own):
  setup   - SpectralFarField(...) (pair search, real-space blocks, grid and kernel)
  matvec  - one product, median of `repeat` (wall clock; the slowest rank counts)
  parts   - per rank, the compute of a matvec: real space, spreading, FFTs + k-space
            kernel (rank 0), interpolation (process CPU time, median: on a shared machine
            the wall clock also counts waiting for a core); with 2 ranks also the
            Reduce + Bcast of the grid (wall clock)
  memory  - peak resident set size growth over setup + products (MiB, largest rank)
  error   - |y - M x| / |M x|: against the dense Ewald sum (far_field_mobility,
            tol = 1e-10) for N <= --dense-max, else against the spectral product at
            tol * 1e-3 (self-convergence).
Configurations: hard spheres from a lattice start with a short Monte Carlo run (timings
do not need equilibrium). Not part of the test suite. Usage:

  python bench/bench_spectral.py                       # N = 343, 1000, 4096; 1 and 2 ranks
  python bench/bench_spectral.py --sizes 343 --ranks 1 --tols 1e-4 --out /tmp/s.json
"""

import argparse
import json
import os
import platform
import resource
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np

from workers import emit, run_worker  # bench/ is on sys.path when run as a script

PHI, STRAIN = 0.45, 0.3


def _rss_mib():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _median_time(fn, repeat, clock=time.perf_counter, barrier=None):
    times = []
    for _ in range(repeat):
        if barrier is not None:
            barrier()
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return float(np.median(times))


def measure(n, tol, repeat, dense_max):
    from mpi4py import MPI

    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro.farfield import far_field_mobility
    from sdmpi.hydro.geometry import Lattice
    from sdmpi.hydro.spectral import SpectralFarField, _fold, _interpolate, _pad, _spread
    from sdmpi.hydro.basis import BASIS

    comm = MPI.COMM_WORLD
    rng = np.random.default_rng(1)
    pos, side = hard_sphere_fluid(n, PHI, rng, sweeps=10, strain=STRAIN)
    radii = np.ones(n)
    lattice = Lattice(np.full(3, side), STRAIN)
    x = rng.standard_normal(11 * n)
    SpectralFarField(pos[:8], radii[:8], lattice, tol, comm).matvec(x[:88])  # numba warm-up
    base = _rss_mib()
    comm.Barrier()
    t0 = time.perf_counter()
    op = SpectralFarField(pos, radii, lattice, tol, comm)
    setup = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    y = op.matvec(x)
    matvec = comm.allreduce(_median_time(lambda: op.matvec(x), repeat, barrier=comm.Barrier), op=MPI.MAX)
    memory = comm.allreduce(_rss_mib() - base, op=MPI.MAX)
    row = {"N": n, "ranks": comm.size, "tol": op.tol, "setup": setup, "matvec": matvec,
           "memory_MiB": memory, "pairs": comm.allreduce(len(op._pi)),
           "real_blocks_MiB": comm.allreduce(op._blocks.nbytes) / 2 ** 20,
           "xi": op.params.xi, "rcut": op.params.rcut, "grid": list(op.params.grid),
           "window_points": op._stencils.pad}
    par, st = op.params, op._stencils
    padded, contiguous, fk = op.work_grids()
    grid = padded[:, :, :par.grid[2]]
    clock = time.process_time
    yy = np.zeros_like(x)

    def spread():
        padded.fill(0.0)
        _spread(op._radii, op._order, x, par.alpha, BASIS, *st.arrays(), padded)
        _fold(padded, par.grid[2])

    def interpolate():
        _pad(padded, par.grid[2])
        _interpolate(op._radii, op._order, padded, par.alpha, BASIS, *st.arrays(), yy)

    parts = {"real": _median_time(lambda: op.real_space(x, yy), repeat, clock),
             "spread": _median_time(spread, repeat, clock),
             "fft_kernel": (_median_time(lambda: op._velocity_grid(grid, fk), repeat, clock)
                            if comm.rank == 0 else 0.0),
             "interpolate": _median_time(interpolate, repeat, clock)}
    parts["total"] = sum(parts.values())
    row["parts_cpu"] = comm.gather(parts)
    if comm.size > 1:
        def grid_comm():
            comm.Reduce(MPI.IN_PLACE if comm.rank == 0 else contiguous, contiguous, op=MPI.SUM, root=0)
            comm.Bcast(contiguous, root=0)

        row["grid_reduce_bcast"] = comm.allreduce(_median_time(grid_comm, repeat, barrier=comm.Barrier),
                                                  op=MPI.MAX)
    if comm.size == 1:
        row["matvec_cpu"] = _median_time(lambda: op.matvec(x), repeat, clock)
        del op
        if n <= dense_max:
            ref = far_field_mobility(pos, radii, np.full(3, side), STRAIN, tol=1e-10) @ x
            row["error_against"] = "dense Ewald sum, tol 1e-10"
        else:
            tight = row["tol"] * 1e-3
            ref = SpectralFarField(pos, radii, lattice, tol=tight).matvec(x)
            row["error_against"] = f"spectral, tol {tight:g}"
        row["error"] = float(np.linalg.norm(y - ref) / np.linalg.norm(ref))
    return row if comm.rank == 0 else None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[343, 1000, 4096])
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--tols", type=float, nargs="+", default=[1e-4, 1e-6])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--dense-max", type=int, default=343)
    ap.add_argument("--out", default="bench/spectral.json")
    ap.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--tol", type=float, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        row = measure(args.worker, args.tol, args.repeat, args.dense_max)
        if row is not None:
            emit([row])
        return
    rows = []
    for n in args.sizes:
        for tol in args.tols:
            for p in args.ranks:
                rows += run_worker(__file__, [n, "--tol", tol, "--repeat", args.repeat, "--dense-max",
                                              args.dense_max], p)
                r = rows[-1]
                parts = " | ".join(" ".join(f"{k} {v:.4f}" for k, v in p.items()) for p in r["parts_cpu"])
                print(f"N={r['N']:>5} tol={tol:g} ranks={r['ranks']} setup {r['setup']:.3f} s  "
                      f"matvec {r['matvec']:.4f} s  memory {r['memory_MiB']:.0f} MiB  "
                      f"error {r.get('error', float('nan')):.2e}  CPU per rank: {parts}  "
                      f"grid comm {r.get('grid_reduce_bcast', 0):.4f} s", flush=True)
    with open(args.out, "w") as f:
        json.dump({"machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                   "load_average_at_end": os.getloadavg(), "unit": "s (median), MiB",
                   "phi": PHI, "strain": STRAIN, "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
