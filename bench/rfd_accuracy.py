"""Accuracy of the random finite difference's linearised resistance change, on stored
equilibrium configurations (not trajectories).

For Monte Carlo hard-sphere configurations (N, phi; default the seed study's N = 27,
phi = 0.45, in shear at strain 0.2), and several noise samples z on each, compares the
Brownian drift and Brownian stresslets of the `rfd` scheme as sdmpi computes them (the
resistance change to first order, `hydro.resistance.resistance_change`: the far-field
change as a matrix-free product with the assembly's own Ewald terms, the lubrication pair
by pair) against the same random finite difference taken between two full evaluations
(R assembled, inverted and factorised again at x + epsilon m), at the job's Ewald
tolerance (the Brownian default 1e-3). Reports the relative rms difference over all
samples of each quantity (sum of squared differences over sum of squares). Writes
bench/rfd_accuracy.json.

    OMP_NUM_THREADS=1 python bench/rfd_accuracy.py [--configs 20] [--samples 4]
"""

import argparse
import json
import math

import numpy as np

from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.dynamics.drift import rfd_length
from sdmpi.dynamics.setup import hydrodynamic_model
from sdmpi.dynamics.realisation import KT_REDUCED

JOB = "jobs/schaink2000_newtonian.toml"


def exact_difference(at, z, kT):
    """The rfd drift and stresslets with R evaluated in full at x + epsilon m."""
    n, zero = at.n_particles, np.zeros((at.n_particles, 5))
    unit_force = at.solver.brownian_forces(z)
    m = at.solver.velocities(unit_force, zero)
    step = rfd_length(at.min_gap)
    moved, _ = at.model.displaced(at, at.positions + step * m[:, :3], separate=False)
    m_moved = moved.velocities(unit_force, zero)
    return ((kT / step) * (m_moved - m),
            (kT / step) * (moved.stresslets(m_moved, zero) - at.solver.stresslets(m, zero)))


def linearised(at, z, kT):
    """sdmpi's rfd drift and stresslets (the noise part removed, no near-contact term)."""
    terms = at.brownian_terms(z, kT, 1.0)
    noise = math.sqrt(2 * kT) * at.solver.velocities(at.solver.brownian_forces(z), np.zeros((at.n_particles, 5)))
    return terms.velocities - noise, terms.stresslets


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--configs", type=int, default=20)
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--strain", type=float, default=0.2)
    ap.add_argument("--out", default="bench/rfd_accuracy.json")
    args = ap.parse_args()
    job = load_job(JOB)
    task = enumerate_tasks(job)[0]
    n, phi = job.system.n_particles, task.phi
    rng = np.random.default_rng(2026)
    sums = {key: np.zeros(2) for key in ("drift", "stress")}
    for c in range(args.configs):
        pos, side = hard_sphere_fluid(n, phi, rng, strain=args.strain)
        box = np.full(3, side)
        model = hydrodynamic_model(job, np.ones(n), box)
        at = model.at(pos, args.strain)
        for _ in range(args.samples):
            z = rng.standard_normal((n, 6))
            ref_drift, ref_stress = exact_difference(at, z, KT_REDUCED)
            drift, stress = linearised(at, z, KT_REDUCED)
            sums["drift"] += [np.sum((drift - ref_drift) ** 2), np.sum(ref_drift ** 2)]
            sums["stress"] += [np.sum((stress - ref_stress) ** 2), np.sum(ref_stress ** 2)]
        print(f"config {c + 1}/{args.configs}", flush=True)
    result = {"job": JOB, "n_particles": n, "phi": phi, "strain": args.strain, "configs": args.configs,
              "samples_per_config": args.samples, "ewald_tolerance": job.ewald_tolerance,
              "relative_rms": {k: float(math.sqrt(v[0] / v[1])) for k, v in sums.items()}}
    print(json.dumps(result["relative_rms"], indent=2))
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=2)


if __name__ == "__main__":
    main()
