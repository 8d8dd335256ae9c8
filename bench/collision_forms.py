"""Benchmark: the collision stress on the petsc-krylov backend with the relative mobilities
of the corrected pairs from shared solves (`KrylovSolver.mobility_forms`, one GMRES solve
for each group of pairs far apart) against one solve per pair (the generic
`SolverBackend.mobility_forms`), in paired runs.

The relative mobilities enter only the collision stress (the impulse s/(G dt) of a pair
moved apart symmetrically), not the motion: two runs of the same realisation (same job,
seed and task) step through the same configurations, one with each form, and differ only
in their samples' stress_collision. For each run: the far-field products that the
relative mobilities asked for per step; for the pair of runs: the largest difference of
stress_collision over the steps and components, relative to the RMS collision stress and
to the RMS of the particle stress (hydrodynamic + Brownian + interparticle + collision),
over all six components and for the shear component xy alone. Prints a JSON row; --out
FILE merges it into FILE under --label.

    python bench/collision_forms.py jobs/large_n_krylov.toml --set system.n_particles=343 \\
        --set ensemble.ranks_per_task=1 --steps 10 --label n343 --out bench/collision_forms.json
"""

import argparse

import numpy as np
from workers import report  # bench/ is on sys.path when run as a script

from sdmpi.config import enumerate_tasks
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.checks import load_job
from sdmpi.hydro import backend, krylov

#: the particle stresses of a sample, summed into the step's stress
PARTICLE_STRESSES = ("stress_hydrodynamic", "stress_brownian", "stress_interparticle", "stress_collision")
#: index of the xy component in the samples' 6-component stresses (xx, yy, zz, xy, xz, yz)
XY = 3


def run(job, steps, per_pair):
    """The samples of `steps` steps of the job's first task, with one solve per pair
    (per_pair) or the backend's shared solves, and the far-field products per step of the
    relative mobilities."""
    forms = backend.SolverBackend.mobility_forms if per_pair else krylov.KrylovSolver.mobility_forms
    far_rows, counted = krylov.KrylovSolver.far_rows, {"inside": False, "products": 0}

    def counting_forms(self, forces):
        counted["inside"] = True
        try:
            return forms(self, forces)
        finally:
            counted["inside"] = False

    def counting_rows(self, lam_local):
        counted["products"] += counted["inside"]
        return far_rows(self, lam_local)

    saved = krylov.KrylovSolver.mobility_forms
    krylov.KrylovSolver.mobility_forms, krylov.KrylovSolver.far_rows = counting_forms, counting_rows
    try:
        samples = Realisation(job, enumerate_tasks(job)[0]).advance(steps)
    finally:
        krylov.KrylovSolver.mobility_forms, krylov.KrylovSolver.far_rows = saved, far_rows
    return samples, counted["products"] / steps


def compare(job_path, overrides, steps):
    """The row of a pair of runs (module docstring)."""
    job = load_job(job_path, overrides)
    shared, shared_products = run(job, steps, per_pair=False)
    exact, exact_products = run(job, steps, per_pair=True)
    same_motion = all(np.array_equal(shared[k], exact[k]) for k in ("stress_hydrodynamic", "stress_brownian"))
    total = sum(exact[k] for k in PARTICLE_STRESSES)
    diff = shared["stress_collision"] - exact["stress_collision"]
    rms_collision = float(np.sqrt(np.mean(exact["stress_collision"] ** 2)))
    rms_total = float(np.sqrt(np.mean(total ** 2)))
    rms_total_xy = float(np.sqrt(np.mean(total[:, XY] ** 2)))
    return {"job": job_path, "overrides": overrides, "n": job.system.n_particles, "steps": steps,
            "same_trajectory": bool(same_motion),
            "corrected_pairs_per_step": float(np.mean(exact["n_overlaps"])),
            "products_per_step_relative_mobilities": {"shared": shared_products, "per_pair": exact_products},
            "collision_stress_max_abs_difference": float(np.abs(diff).max()),
            "relative_to_rms_collision_stress": float(np.abs(diff).max() / rms_collision) if rms_collision else 0.0,
            "relative_to_rms_total_stress": float(np.abs(diff).max() / rms_total),
            "xy_max_abs_difference": float(np.abs(diff[:, XY]).max()),
            "xy_relative_to_rms_total_stress_xy": float(np.abs(diff[:, XY]).max() / rms_total_xy),
            "mean_collision_stress_xy": {"shared": float(shared["stress_collision"][:, XY].mean()),
                                         "per_pair": float(exact["stress_collision"][:, XY].mean())},
            "rms_collision_stress": rms_collision, "rms_total_stress": rms_total,
            "rms_total_stress_xy": rms_total_xy}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("job")
    ap.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE")
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--label", default=None)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    row = compare(args.job, args.overrides, args.steps)
    report(row, args.out, args.label or "-".join(args.overrides))


if __name__ == "__main__":
    main()
