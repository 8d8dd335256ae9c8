"""Benchmark: where the time of a Brownian step on the petsc-krylov backend goes, and how
many far-field products each part makes.

One realisation (the first task) of a job file, with --set overrides, stepped on one rank
(or, under ``mpirun -n P``, on the P ranks of ``ensemble.ranks_per_task = P``) exactly as
``sdmpi run`` steps it (`Realisation.advance`, one step at a time); after --warmup steps,
--steps steps are timed with the parts of the backend wrapped by timers (CPU time of the
outermost wrapped call; calls made inside another part count for that part) and every
far-field product (`KrylovSolver.far_rows`) counted for the part that asked for it:

* GMRES solves: the mixed-form solves of velocities (`KrylovSolver.velocities`);
* collision relative mobilities: f.R_FU^-1.f of the pairs an overlap correction moved
  (`KrylovSolver.mobility_forms`: one GMRES solve for each group of pairs far apart), for
  the collision stress;
* stresslets of velocities not from the last solve (`KrylovSolver.stresslets`: a CG
  solve M lambda = V, e.g. the start's Brownian stresslets of the midpoint scheme);
* Brownian far-field forces (`KrylovSolver.brownian_forces`: the Lanczos iteration);
* set-ups: the split resistance (pairs, lubrication, far-field operator) and the solver
  (`KrylovSolver.__init__`, `take_preconditioner`), at the start and the midpoint;
* the rest (integrator, overlap corrections, noise, glue).

A 297 x 297 LAPACK Cholesky is timed in the same process before and after (median CPU
ms): the step's CPU time over it is its cost in Cholesky-equivalents. Also the peak
resident memory of each rank (ru_maxrss, GiB, start and Monte Carlo included). Prints a JSON row;
--out FILE merges it into FILE under --label.

    python bench/krylov_shares.py jobs/large_n_krylov.toml --set 'shear.protocol="none"' \\
        --set integration.n_steps=10 --set integration.discard_steps=0 \\
        --set ensemble.ranks_per_task=1 --steps 3 --label rest_dt1e-3 --out bench/krylov_shares.json
"""

import argparse
import resource
import time

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np
from mpi4py import MPI

from bench_step import cholesky_matrix, cholesky_ms  # bench/ is on sys.path when run as a script
from workers import report

from sdmpi.config import enumerate_tasks
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.checks import load_job
from sdmpi.hydro import krylov, solvers, spectral
from sdmpi.hydro.geometry import Lattice

#: part -> the (owner, method) calls it owns
PARTS = {
    "GMRES solves (velocities)": [(krylov.KrylovSolver, "velocities")],
    "collision relative mobilities (a GMRES solve per group of corrected pairs)": [
        (krylov.KrylovSolver, "mobility_forms")],
    "stresslets of other velocities (CG)": [(krylov.KrylovSolver, "stresslets")],
    "Brownian far-field forces (Lanczos)": [(krylov.KrylovSolver, "brownian_forces")],
    "set-ups (split resistance, solver, preconditioner)": [
        (solvers, "split_resistance"), (krylov.KrylovSolver, "__init__"),
        (krylov.KrylovSolver, "take_preconditioner")],
}


#: stage of one far-field product (`SpectralFarField.matvec`) -> the calls it owns
STAGES = {
    "spreading (window sums onto the grid)": [(spectral, "_spread")],
    "FFTs and k-space kernel (rank 0)": [(spectral.SpectralFarField, "_velocity_grid")],
    "interpolation (window sums from the grid)": [(spectral, "_interpolate")],
    "periodic fold and pad of the z-padded grid": [(spectral, "_fold"), (spectral, "_pad")],
    "real-space pair blocks": [(spectral.SpectralFarField, "real_space")],
}


class Meter:
    """CPU seconds and far-field products per part of ``parts``; ``stack`` holds the
    parts being timed (the outermost claims the time and the products)."""

    def __init__(self, parts=PARTS):
        self.parts = parts
        self.reset()

    def reset(self):
        self.seconds = {part: 0.0 for part in self.parts}
        self.products = {part: 0 for part in [*self.parts, "the rest"]}
        self.stack = []

    def wrap(self, part, function):
        def call(*args, **kwargs):
            self.stack.append(part)
            t0 = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.stack.pop()
                if not self.stack:
                    self.seconds[part] += time.process_time() - t0
        return call

    def count(self, function):
        def call(*args, **kwargs):
            self.products[self.stack[0] if self.stack else "the rest"] += 1
            return function(*args, **kwargs)
        return call

    def install(self):
        for part, targets in self.parts.items():
            for owner, name in targets:
                setattr(owner, name, self.wrap(part, getattr(owner, name)))
        krylov.KrylovSolver.far_rows = self.count(krylov.KrylovSolver.far_rows)


def product_stages(n, tol, repeat):
    """CPU ms per stage of one spectral far-field product at N = n (a simple cubic
    lattice at phi = 0.45, jittered by 0.02 a; one rank), over ``repeat`` products, with
    the grid, the window's support points per axis and the real-space pair images."""
    side = (4 * np.pi * n / (3 * 0.45)) ** (1 / 3)
    k = round(n ** (1 / 3))
    cells = np.stack(np.meshgrid(*[np.arange(k)] * 3, indexing="ij"), -1).reshape(-1, 3)
    pos = (cells + 0.5) * side / k + 0.02 * np.random.default_rng(1).standard_normal((k ** 3, 3))
    far = spectral.SpectralFarField(pos, np.ones(k ** 3), Lattice(np.full(3, side), 0.0), tol)
    x = np.random.default_rng(2).standard_normal(11 * k ** 3)
    far.matvec(x)  # compiled, work arrays touched
    meter = Meter(STAGES)
    meter.install()
    t0 = time.process_time()
    for _ in range(repeat):
        far.matvec(x)
    total = time.process_time() - t0
    ms = {stage: 1e3 * s / repeat for stage, s in meter.seconds.items()}
    ms["the rest (self part, copies, glue)"] = 1e3 * total / repeat - sum(ms.values())
    return {"n": k ** 3, "ewald_tolerance": tol, "grid": list(far.params.grid),
            "window_points_per_axis": far._stencils.e12.shape[1], "pair_images": len(far._pi),
            "cpu_ms_per_product": 1e3 * total / repeat, "cpu_ms_by_stage": ms}


def measure(job_path, overrides, warmup, steps):
    """The row of one realisation: CPU per step and per part, products per part,
    iterations, Cholesky-equivalents."""
    comm = MPI.COMM_WORLD
    job = load_job(job_path, overrides)
    spd = cholesky_matrix()
    chol = [cholesky_ms(spd)[1]]
    meter = Meter()
    meter.install()
    real = Realisation(job, enumerate_tasks(job)[0], comm if comm.size > 1 else None)
    real.advance(warmup)
    meter.reset()
    w0, c0 = time.perf_counter(), time.process_time()
    samples = real.advance(steps)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    chol.append(cholesky_ms(spd)[1])
    per_step = {part: s / steps for part, s in meter.seconds.items()}
    per_step["the rest"] = cpu / steps - sum(per_step.values())
    chol_ms = float(np.median(chol))
    return {"job": job_path, "overrides": overrides, "ranks": comm.size, "n": job.system.n_particles,
            "dt": real.dt, "steps": steps, "cpu_s_per_step": cpu / steps, "wall_s_per_step": wall / steps,
            "cholesky_ms": chol, "cholesky_equivalents_per_step": 1e3 * cpu / steps / chol_ms,
            "cpu_s_per_step_by_part": per_step,
            "products_per_step": {p: k / steps for p, k in meter.products.items()},
            "solver_iterations": samples["solver_iterations"].tolist(),
            "lanczos_iterations": samples["lanczos_iterations"].tolist(),
            "n_overlaps": samples["n_overlaps"].tolist(),
            "n_overlaps_midpoint": samples["n_overlaps_midpoint"].tolist(),
            "peak_rss_gib_per_rank": comm.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("job", nargs="?", help="the job file (absent: --product only)")
    ap.add_argument("--product", type=int, nargs="*", default=[], metavar="N",
                    help="profile one spectral far-field product at these N instead")
    ap.add_argument("--ewald-tolerance", type=float, default=1e-4, help="for --product")
    ap.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE")
    ap.add_argument("--warmup", type=int, default=1)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--label", default=None)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if args.product:
        spd = cholesky_matrix()
        rows = [product_stages(n, args.ewald_tolerance, args.steps) for n in args.product]
        row = {"products": rows, "cholesky_ms": cholesky_ms(spd)[1]}
    else:
        row = measure(args.job, args.overrides, args.warmup, args.steps)
    if MPI.COMM_WORLD.rank:
        return
    report(row, args.out, args.label or "-".join(args.overrides) or args.job or "products")


if __name__ == "__main__":
    main()
