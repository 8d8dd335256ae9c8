"""Benchmark: the parts of a Brownian step's drift on `petsc-krylov` by scheme, at one
configuration (the start of jobs/large_n_krylov.toml at rest, one rank, its tolerances).

For `rfd`: the Brownian forces and m = R_FU^-1 F_B (Lanczos and one solve), the random
finite difference's change (`KrylovSolver.mobility_change`: the far-field change and one
solve), and the near-contact correction (`drift.near_contact_velocities`: its independent
direction m' (Lanczos and one solve), the relative mobilities G_p of the pairs below
`drift.NEAR_CONTACT_GAP` in the solves `mobility_forms` groups them into, and the
velocities of the correction's forces). For `midpoint`: the whole Brownian
part (forces, m, the displaced evaluation and its solve). Seconds of wall time beside a
297 x 297 LAPACK Cholesky timed in the same process (its Cholesky-equivalents). Prints
one JSON row; --out FILE appends it.

    python bench/rfd_krylov.py [--n 1000] [--dt 5e-4] [--out bench/rfd_krylov.json]
"""

import argparse
import json
import time
from pathlib import Path

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np

from bench_step import cholesky_matrix, cholesky_ms

from sdmpi.config.tasks import enumerate_tasks
from sdmpi.dynamics.drift import NEAR_CONTACT_GAP, near_contact_velocities, rfd_terms
from sdmpi.dynamics.realisation import Realisation

ROOT = Path(__file__).resolve().parents[1]


def timed(call, *args):
    """(call(*args), its wall seconds)."""
    start = time.perf_counter()
    out = call(*args)
    return out, time.perf_counter() - start


def measure(n, dt):
    """The row of the module docstring at N = n."""
    sets = ["ensemble.ranks_per_task=1", 'shear.protocol="none"', "integration.n_steps=10",
            "integration.discard_steps=0", f"integration.dt={dt}", f"system.n_particles={n}"]
    row = {"n_particles": n, "dt": dt}
    for scheme in ("midpoint", "rfd"):
        job = sdmpi.load_job(ROOT / "jobs" / "large_n_krylov.toml", [*sets, f'brownian.scheme="{scheme}"'])
        real = Realisation(job, enumerate_tasks(job)[0])
        kT, dt = real.kT, job.integration.dt
        evaluation = real.model.at(real.positions, 0.0)
        evaluation.brownian_terms(np.random.default_rng(0).standard_normal(evaluation.solver.noise_shape), kT, dt)
        evaluation = real.model.at(real.positions, 0.0)  # (compiled: time a fresh evaluation)
        z = np.random.default_rng(1).standard_normal(evaluation.solver.noise_shape)
        solver = evaluation.solver
        if scheme == "midpoint":
            _, row["midpoint_brownian_s"] = timed(evaluation.model.drift.brownian, evaluation, z, kT, dt,
                                                  lambda m: 0.0)
            row["midpoint_iterations"] = evaluation.stats()["solver_iterations"]
            continue
        m, row["rfd_forces_and_m_s"] = timed(solver.brownian_velocities, z)
        before = solver.stats["iterations"]
        _, row["rfd_change_s"] = timed(rfd_terms, evaluation, m, kT)
        row["rfd_change_iterations"] = solver.stats["iterations"] - before
        pairs = evaluation.pairs
        row["near_contact_pairs"] = int((pairs.gap < NEAR_CONTACT_GAP * 0.5 * pairs.radii_sum).sum())
        velocities, solves = solver.velocities, []
        solver.velocities = lambda *args: solves.append(1) or velocities(*args)  # count the solves
        z_near = np.random.default_rng(2).standard_normal(solver.noise_shape)
        before, lanczos = solver.stats["iterations"], solver.stats["lanczos"]
        _, row["near_contact_s"] = timed(near_contact_velocities, evaluation, m, z_near, kT, dt)
        row["near_contact_iterations"] = solver.stats["iterations"] - before
        row["near_contact_lanczos"] = solver.stats["lanczos"] - lanczos
        row["near_contact_solves"] = len(solves)  # m', the forms solved, the correction's velocities
    row["cholesky_ms"] = float(np.median([cholesky_ms(cholesky_matrix())[0] for _ in range(5)]))
    for key in [k for k in row if k.endswith("_s")]:
        row[key[:-2] + "_cholesky_equivalents"] = round(1e3 * row[key] / row["cholesky_ms"])
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--dt", type=float, default=5e-4, help="time step (t_D): the near-contact correction's reach")
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    row = measure(args.n, args.dt)
    print(json.dumps(row), flush=True)
    if args.out:
        with open(args.out, "a") as out:
            out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
