"""The collision stress against the time step and the lubrication floor: N spheres at
volume fraction phi at rest, Brownian, one hydrodynamic model, one realisation per
(dt, min_gap), the contact part of the osmotic pressure implied by the overlap correction,
Pi_c/(n kT) = -tr(sigma_collision)/(3 n kT), and the share of steps with a pair in contact.
Without lubrication (far-field, free-draining) this is the hard-sphere contact pressure,
4 phi g(2) (Carnahan-Starling: 8.39 at phi = 0.45); with lubrication (stokesian) pairs
never touch in continuous time, and Pi_c measures the floor and the step
(docs/physics.md, Collision stress). Errors: one standard error over 10 blocks of the run.

    python bench/collision_convergence.py [--model stokesian] [--phi 0.45] [--steps 3000]
        [--dt 2e-3 1e-3 5e-4 2.5e-4] [--min-gap 1e-4 3e-5]

Prints one JSON line per (dt, min_gap), appended to bench/collision_convergence.json.
"""

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from sdmpi.config.loader import parse_job
from sdmpi.config.tasks import enumerate_tasks
from sdmpi.registry import HYDRODYNAMIC_MODELS
from sdmpi.dynamics.realisation import KT_REDUCED, Realisation

JOB = """
[job]
name = "collision-convergence"
seed = 17
[system]
n_particles = {n}
phi = [{phi}]
[shear]
protocol = "none"
[brownian]
enabled = true
[integration]
dt = {dt}
n_steps = {steps}
discard_steps = 0
[hydrodynamics]
model = "{model}"
min_gap = {min_gap}
"""


def measure(model, n, phi, dt, min_gap, steps, blocks=10):
    """Pi_c/(n kT) with its standard error, and the share of steps with a correction."""
    job = parse_job(JOB.format(model=model, n=n, phi=phi, dt=dt, steps=steps, min_gap=min_gap))
    real = Realisation(job, enumerate_tasks(job)[0])
    out = real.advance(steps)
    pressure = -out["stress_collision"][:, :3].sum(axis=1) / 3 / (n / real.volume * KT_REDUCED)
    means = pressure[: steps // blocks * blocks].reshape(blocks, -1).mean(axis=1)
    contacts = float(np.mean(out["n_overlaps"] > 0))
    return float(means.mean()), float(means.std(ddof=1) / math.sqrt(blocks)), contacts


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", choices=HYDRODYNAMIC_MODELS.names(), default="stokesian")
    parser.add_argument("--n", type=int, default=27)
    parser.add_argument("--phi", type=float, default=0.45)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--dt", type=float, nargs="+", default=[2e-3, 1e-3, 5e-4, 2.5e-4])
    parser.add_argument("--min-gap", type=float, nargs="+", default=[1e-4, 3e-5])
    parser.add_argument("--out", default=str(Path(__file__).with_name("collision_convergence.json")))
    args = parser.parse_args()
    for min_gap in args.min_gap:
        for dt in args.dt:
            start = time.perf_counter()
            mean, err, contacts = measure(args.model, args.n, args.phi, dt, min_gap, args.steps)
            row = {"model": args.model, "n_particles": args.n, "phi": args.phi, "dt": dt,
                   "min_gap": min_gap, "steps": args.steps, "pressure_collision": mean,
                   "pressure_collision_err": err, "steps_with_contacts": contacts,
                   "seconds": round(time.perf_counter() - start)}
            print(json.dumps(row), flush=True)
            with open(args.out, "a") as out:
                out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
