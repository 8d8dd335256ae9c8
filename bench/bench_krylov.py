"""Benchmark: Brownian SD steps with the petsc-krylov backend at phi = 0.45 on a
sub-communicator of `--ranks` ranks (ranks_per_task), against dense (one rank) where
dense is affordable. Not part of the test suite; numbers go to bench/krylov.json (merged
per (backend, N, ranks, tolerances)) and the log-log cost plot to bench/krylov_cost.png.

Per run: one realisation of the demo job (oscillatory shear, Brownian, phi = 0.45,
N spheres, dt = 5e-4 t_D; solver.tolerance, solver.lanczos_tolerance and
hydrodynamics.ewald_tolerance from --tolerance (1e-8), --lanczos-tolerance (= --tolerance)
and --ewald-tolerance (1e-6); far field by N as in `krylov`: dense below
`krylov.DENSE_FAR_FIELD_MAX_N` particles, spectral from there on), one warm-up step (numba compilation, PETSc set-up), then
`--steps` timed steps. Recorded: wall time per step (max over ranks), Krylov and Lanczos
iterations per step, peak resident memory summed over the ranks (ru_maxrss), the
far-field operator used, a 297 x 297 LAPACK Cholesky timed on every rank before and
after the steps (wall ms) and the step's median wall time in units of the Cholesky's
median (Cholesky-equivalents: the shared machine's speed drifts 2x). Each (N, ranks) runs in its own process group so that peak
memory is per size.

  python bench/bench_krylov.py --sizes 343 1000 --ranks 2          # launches mpirun
  python bench/bench_krylov.py --sizes 343 1000 4096 --ranks 2 --tolerance 1e-6 \
      --lanczos-tolerance 1e-4 --ewald-tolerance 1e-4              # the fast settings
  python bench/bench_krylov.py --sizes 125 343 --backend dense --ranks 1
  python bench/bench_krylov.py --plot                                # plot from the JSON
"""

import argparse
import json
import os
import platform
import resource
import time
from pathlib import Path

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np

from bench_step import cholesky_matrix, cholesky_ms  # bench/ is on sys.path when run as a script
from workers import emit, run_worker

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "krylov.json"
PLOT = HERE / "krylov_cost.png"


def measure(n, backend, steps, tolerance, ewald_tolerance, lanczos_tolerance, far_field=None):
    """One realisation stepped on COMM_WORLD; returns the row (on every rank). far_field:
    "dense" or "spectral" (solver.far_field) instead of the choice by N
    (krylov.far_field_kind)."""
    from mpi4py import MPI

    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation
    from sdmpi.hydro import krylov

    comm = MPI.COMM_WORLD
    job = load_job(str(ROOT / "jobs" / "demo.toml"), overrides=[
        f"system.n_particles={n}", "system.phi=[0.45]", f"solver.backend='{backend}'",
        f"solver.tolerance={tolerance}", f"solver.lanczos_tolerance={lanczos_tolerance}",
        f"hydrodynamics.ewald_tolerance={ewald_tolerance}", f"ensemble.ranks_per_task={comm.size}",
        "ensemble.realisations=1", "shear.omega=[6.283185307179586]",
        "integration.steps_per_period=2000",  # dt = 5e-4 t_D, Schaink et al.'s largest
        *([f"solver.far_field='{far_field}'"] if far_field else [])])
    speed_before = machine_speed()
    spd = cholesky_matrix()
    chol = [cholesky_ms(spd)[0]]
    t0 = time.perf_counter()
    real = Realisation(job, enumerate_tasks(job)[0], comm if comm.size > 1 else None)
    t_init = time.perf_counter() - t0
    real.advance(1)  # warm-up
    comm.Barrier()
    times, its, lanczos = [], [], []
    for _ in range(steps):
        t0 = time.perf_counter()
        sample = real.advance(1)
        times.append(comm.allreduce(time.perf_counter() - t0, op=MPI.MAX))
        its.append(int(sample["solver_iterations"][0]))
        lanczos.append(int(sample["lanczos_iterations"][0]))
    rss = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 2 ** 20  # KiB -> GiB
    chol.append(cholesky_ms(spd)[0])
    chol = sorted(c for pair in comm.allgather(chol) for c in pair)  # every rank's, before and after
    far = "-" if backend != "petsc-krylov" else krylov.far_field_kind(far_field, n)
    return {"backend": backend, "n": n, "ranks": comm.size, "phi": 0.45, "tolerance": tolerance,
            "lanczos_tolerance": lanczos_tolerance, "ewald_tolerance": ewald_tolerance,
            "far_field": far, "far_field_forced": far_field is not None,
            "seconds_per_step": float(np.median(times)),
            "seconds_per_step_all": times, "iterations_per_step": its,
            "lanczos_per_step": lanczos, "peak_rss_gib_total": rss, "init_seconds": t_init,
            "dt": real.dt, "load_average_1min": os.getloadavg()[0],
            "dgemm_gflops_before_after": [speed_before, machine_speed()],
            "cholesky_wall_ms": chol,
            "cholesky_equivalents_per_step": 1e3 * float(np.median(times)) / float(np.median(chol))}


def machine_speed(n=1000, repeat=5):
    """This core's speed right now: one-thread DGEMM GFLOP/s (best of `repeat` n x n
    products). The VM's speed drifts (seen: 15 to 75 GFLOP/s within minutes), so every
    row records it before and after its steps."""
    a = np.random.default_rng(0).standard_normal((n, n))
    a @ a
    best = min(_timed(lambda: a @ a) for _ in range(repeat))
    return 2 * n ** 3 / best / 1e9


def _timed(work):
    t0 = time.perf_counter()
    work()
    return time.perf_counter() - t0


def settings(row):
    """(solver, Lanczos, Ewald) tolerances of a row (rows from before the Lanczos and Ewald
    columns: Lanczos = solver tolerance, Ewald 1e-6)."""
    return (row["tolerance"], row.get("lanczos_tolerance", row["tolerance"]), row.get("ewald_tolerance", 1e-6))


def label(setting):
    return "tol {:g}, Lanczos {:g}, Ewald {:g}".format(*setting)


def merge(rows):
    data = json.loads(OUT.read_text()) if OUT.exists() else {"rows": []}

    def key(r):
        return r["backend"], r["n"], r["ranks"], settings(r), r["far_field"], r.get("far_field_forced", False)

    new = {key(r) for r in rows}
    data["rows"] = [r for r in data["rows"] if key(r) not in new] + rows
    data["rows"].sort(key=lambda r: (r["backend"], r["ranks"], settings(r), r["n"]))
    data["machine"] = {"cpus": os.cpu_count(), "python": platform.python_version(),
                       "note": "2 cores shared with other jobs: times include contention"}
    # d log(time) / d log(N) between consecutive sizes (petsc-krylov, 2 ranks, per
    # setting), with the load averages the two were measured at (the machine is shared)
    data["cost_exponents_2_ranks"] = []
    for setting in sorted({settings(r) for r in data["rows"]}):
        kry = sorted((r for r in data["rows"] if r["backend"] == "petsc-krylov" and r["ranks"] == 2
                      and settings(r) == setting and not r.get("far_field_forced")), key=lambda r: r["n"])
        data["cost_exponents_2_ranks"] += [
            {"settings": label(setting), "from": a["n"], "to": b["n"],
             "exponent": float(np.log(b["seconds_per_step"] / a["seconds_per_step"]) / np.log(b["n"] / a["n"])),
             "load_averages": [a.get("load_average_1min"), b.get("load_average_1min")]}
            for a, b in zip(kry, kry[1:])]
    OUT.write_text(json.dumps(data, indent=1) + "\n")
    return data


def plot(data):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4))
    groups = {}
    for r in data["rows"]:
        if not r.get("far_field_forced"):  # the --far-field rows: the crossover, not the plot
            groups.setdefault((r["backend"], r["ranks"], settings(r)), []).append(r)
    for (backend, ranks, setting), rows in sorted(groups.items()):
        rows.sort(key=lambda r: r["n"])
        ax.loglog([r["n"] for r in rows], [r["seconds_per_step"] for r in rows], "o-",
                  label=f"{backend}, {ranks} rank(s)" + ("" if backend == "dense" else f"\n{label(setting)}"))
    fast = [rows for (backend, ranks, _), rows in groups.items() if backend == "petsc-krylov" and ranks == 2]
    if fast:
        kry = min(fast, key=lambda rows: rows[-1]["seconds_per_step"])
        n0, t0 = kry[0]["n"], kry[0]["seconds_per_step"]
        ns = np.array([n0, max(r["n"] for r in kry)])
        ax.loglog(ns, t0 * (ns / n0) ** 1.5, "k--", lw=0.8, label="N^1.5")
    ax.plot([1000, 4096], [3.0, 15.0], "k*", ms=9, label="targets (issue 6), 2 ranks")
    ax.set_xlabel("N (phi = 0.45)")
    ax.set_ylabel("wall time per Brownian step [s]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(PLOT, dpi=120)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[])
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--backend", default="petsc-krylov")
    parser.add_argument("--steps", type=int, default=3)
    parser.add_argument("--tolerance", type=float, default=1e-8, help="solver.tolerance")
    parser.add_argument("--lanczos-tolerance", type=float, default=None,
                        help="solver.lanczos_tolerance (default: --tolerance)")
    parser.add_argument("--ewald-tolerance", type=float, default=1e-6,
                        help="hydrodynamics.ewald_tolerance")
    parser.add_argument("--far-field", choices=["dense", "spectral"], default=None,
                        help="petsc-krylov's far field (default: by N, krylov.DENSE_FAR_FIELD_MAX_N)")
    parser.add_argument("--plot", action="store_true")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        from mpi4py import MPI

        row = measure(args.sizes[0], args.backend, args.steps, args.tolerance, args.ewald_tolerance,
                      args.lanczos_tolerance or args.tolerance, args.far_field)
        if MPI.COMM_WORLD.rank == 0:
            emit([row])
        return
    for n in args.sizes:
        (row,) = run_worker(__file__, ["--sizes", n, "--backend", args.backend, "--steps", args.steps,
                                       "--tolerance", args.tolerance, "--ewald-tolerance",
                                       args.ewald_tolerance, "--lanczos-tolerance",
                                       args.lanczos_tolerance or args.tolerance,
                                       *(["--far-field", args.far_field] if args.far_field else [])],
                            args.ranks, cwd=ROOT)
        print(json.dumps({k: v for k, v in row.items() if not k.endswith("_all")}), flush=True)
        merge([row])
    if args.plot or args.sizes:
        plot(json.loads(OUT.read_text()))


if __name__ == "__main__":
    main()
