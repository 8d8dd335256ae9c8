"""The equilibrium structure kept at rest: N spheres at volume fraction phi, no shear, Brownian,
stepped by one hydrodynamic model at the default time step, against a Monte Carlo chain of
the same N and phi (`sdmpi.dynamics.initial`: a start equilibrated by --mc-sweeps sweeps,
then --mc-configs samples --mc-every sweeps apart): the pair distribution g in shells of
surface gap near contact, and the high-frequency viscosity eta_H
(`sdmpi.hydro.bulk.hydrodynamic_viscosity`) of the evolved configurations. The first
--discard of the run's steps (the relaxation from its Monte Carlo start) are left out.
Errors: one standard error over 20 blocks (of the run; of the chain); with several
--seeds (independent runs, --workers processes at a time), the dynamics' error is the
standard error of the runs' means (which also holds when structural fluctuations outlast
a block).

    python bench/near_contact_structure.py MODEL [--phi 0.45] [--steps 10000] [--uncorrected] [--kappa-one]
        [--collisions separate|reflect] [--symmetric] [--dt 5e-4] [--seeds 11 ...] [--workers 1]
        [--ewald-tolerance TOL]

MODEL is a hydrodynamics.model (stokesian, far-field, free-draining); --uncorrected switches
the near-contact correction of `sdmpi.dynamics.drift` off, --kappa-one gives it the
isolated pair's kappa = 1 for every pair instead of the pair's own (both for comparison); --collisions
chooses the overlap correction's rule (`sdmpi.dynamics.collisions`; absent: the model's);
--symmetric moves only the two spheres of a pair in contact, by half the separation change
each, instead of acting through the mobility (the oblique reflection, for comparison). Prints one JSON
line, appended to bench/near_contact_structure.json (docs/physics.md quotes it).
"""

import argparse
import functools
import json
import math
import multiprocessing
import time
from pathlib import Path

import numpy as np

from sdmpi.analysis.trajectories import ideal_pair_counts, pair_counts
from sdmpi.config.loader import parse_job
from sdmpi.dynamics import drift
from sdmpi.dynamics.collisions import RULES, default_rule
from sdmpi.dynamics.initial import _mc_sweeps, hard_sphere_fluid
from sdmpi.dynamics.realisation import Realisation
from sdmpi.config.tasks import enumerate_tasks
from sdmpi.hydro.bulk import hydrodynamic_viscosity
from sdmpi.registry import HYDRODYNAMIC_MODELS
from sdmpi.hydro.geometry import Lattice

#: shells of surface gap (in a) where g is counted; after them, one more column: the first
#: two shells together, from contact to 3e-4 (the pairs that the exact dynamics would take
#: below the floor hydrodynamics.min_gap = 1e-4 are placed, or reflected, just above it by
#: the collision rule: counted from contact, they are where they belong)
EDGES = np.array([0.0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1])
JOB = """
[job]
name = "near-contact-structure"
seed = {seed}
[system]
n_particles = {n}
phi = [{phi}]
[shear]
protocol = "none"
[brownian]
enabled = true
{scheme}
[integration]
dt = {dt}
n_steps = {steps}
discard_steps = 0
[ensemble]
realisations = 1
[hydrodynamics]
model = "{model}"
{collisions}
{ewald}
{solver}
"""


def with_contact_shell(counts):
    """Counts per shell (EDGES) and, appended, those of the first two shells together."""
    return np.append(counts, counts[0] + counts[1])


def shell_counts(pos, box):
    """Pairs per gap shell of one configuration (nearest images, unit radii),
    `with_contact_shell`."""
    return with_contact_shell(pair_counts(pos, Lattice(box, 0.0), 2.0 + EDGES))


def ideal_counts(n, box):
    """Pairs per shell (`shell_counts`) of an ideal gas (g = 1) in the box."""
    return with_contact_shell(ideal_pair_counts(n, np.prod(box), 2.0 + EDGES))


def monte_carlo(n, phi, configs, eta_every, sweeps=5000, every=5, step=0.12):
    """g per shell and eta_H of a Monte Carlo chain: hard_sphere_fluid equilibrated by
    `sweeps` sweeps, then `configs` samples `every` sweeps apart (trial step `step`, ~50%
    acceptance at phi = 0.45)."""
    rng = np.random.default_rng([7, n, int(1000 * phi)])
    pos, side = hard_sphere_fluid(n, phi, rng, sweeps=sweeps)
    box, radii = np.full(3, side), np.ones(n)
    ideal = ideal_counts(n, box)
    counts, etas = [], []
    for k in range(configs):
        _mc_sweeps(pos, side, radii, step, every, int(rng.integers(2 ** 31)), 0.0)
        counts.append(shell_counts(pos, box) / ideal)
        if k % eta_every == 0:
            etas.append(hydrodynamic_viscosity(pos, box))
    return np.array(counts), np.array(etas)


def job_at_rest(model, n, phi, steps, dt, collisions=None, ewald_tolerance=None, seed=11, backend=None,
                tolerance=None, scheme=None):
    """The job of one run at rest (JOB; collisions, ewald_tolerance, backend, tolerance
    (solver and Lanczos), scheme (brownian.scheme) None: the defaults)."""
    rule = f'collisions = "{collisions}"' if collisions else ""
    ewald = f"ewald_tolerance = {ewald_tolerance}" if ewald_tolerance else ""
    solver = "[solver]\n" + (f'backend = "{backend}"\n' if backend else "") + (
        f"tolerance = {tolerance}\nlanczos_tolerance = {tolerance}\n" if tolerance else "")
    return parse_job(JOB.format(seed=seed, n=n, phi=phi, steps=steps, model=model, dt=dt, collisions=rule,
                                ewald=ewald, solver=solver, scheme=f'scheme = "{scheme}"' if scheme else ""))


def use_kappa_one():
    """The near-contact correction with kappa = 1 for every pair (the isolated pair at
    contact) in this process and the worker processes it forks."""
    drift.squeeze_fraction = lambda mobility, gap, radius_i, radius_j: np.ones(len(gap))


def scale_kappa(factor, beyond=None, kT=None, dt=None):
    """The near-contact correction with every pair's kappa times factor (an error of its
    relative mobility G_p) in this process and the worker processes it forks; with beyond,
    only the pairs at least beyond c dt from contact (`drift.contact_reach`, as
    `drift.near_contact_velocities` measures the reach)."""
    exact = drift.squeeze_fraction

    def scaled(mobility, gap, radius_i, radius_j):
        kappa = exact(mobility, gap, radius_i, radius_j)
        if beyond is None:
            return factor * kappa
        reach = drift.contact_reach(gap, radius_i, radius_j, kT, dt)
        return np.where(reach >= beyond, factor, 1.0) * kappa

    drift.squeeze_fraction = scaled


def dynamics(model, n, phi, steps, eta_every, dt, collisions, ewald_tolerance=None, seed=11):
    """g per shell (one row per step) and eta_H every eta_every steps of one run at rest, of
    the configurations the model is evaluated at (each step's start, overlaps corrected)."""
    job = job_at_rest(model, n, phi, steps, dt, collisions, ewald_tolerance, seed)
    real = Realisation(job, enumerate_tasks(job)[0])
    ideal = ideal_counts(n, real.box)
    counts, etas = np.empty((steps, len(EDGES))), []
    for k in range(steps):
        real.advance(1)
        pos = real.positions  # the next step's start, overlaps corrected
        counts[k] = shell_counts(pos, real.box) / ideal
        if k % eta_every == 0:
            etas.append(hydrodynamic_viscosity(pos, real.box))
    return counts, np.array(etas)


def summary(samples, blocks=None):
    """Mean and standard error (over blocks of consecutive samples, or over samples)."""
    if blocks:
        samples = samples[: len(samples) // blocks * blocks].reshape(blocks, -1, *samples.shape[1:]).mean(axis=1)
    return samples.mean(axis=0), samples.std(axis=0, ddof=1) / math.sqrt(len(samples))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", choices=HYDRODYNAMIC_MODELS.names())
    parser.add_argument("--n", type=int, default=27)
    parser.add_argument("--phi", type=float, default=0.45)
    parser.add_argument("--steps", type=int, default=10000)
    parser.add_argument("--mc-configs", type=int, default=100000)
    parser.add_argument("--mc-sweeps", type=int, default=5000)
    parser.add_argument("--mc-every", type=int, default=5)
    parser.add_argument("--discard", type=float, default=0.2)
    parser.add_argument("--seeds", type=int, nargs="+", default=[11])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--uncorrected", action="store_true")
    parser.add_argument("--kappa-one", action="store_true")
    parser.add_argument("--collisions", choices=RULES)
    parser.add_argument("--symmetric", action="store_true")
    parser.add_argument("--dt", type=float, default=5e-4)
    parser.add_argument("--ewald-tolerance", type=float, help="absent: the Brownian default")
    parser.add_argument("--out", default=str(Path(__file__).with_name("near_contact_structure.json")))
    args = parser.parse_args()
    if args.uncorrected:
        drift.NEAR_CONTACT_GAP = 0.0
    if args.kappa_one:
        use_kappa_one()
    if args.symmetric:
        symmetric = Realisation._separate
        Realisation._separate = lambda self, pos, strain, reflect=False, mobility=None: symmetric(
            self, pos, strain, reflect)
    start = time.perf_counter()
    runs = functools.partial(dynamics, args.model, args.n, args.phi, args.steps, 100, args.dt, args.collisions,
                             args.ewald_tolerance)
    with multiprocessing.Pool(args.workers) as pool:
        per_seed = pool.map(runs, args.seeds)
    skip = int(args.discard * args.steps)
    g_mc, eta_mc = monte_carlo(args.n, args.phi, args.mc_configs, max(args.mc_configs // 100, 1),
                               args.mc_sweeps, args.mc_every)
    if len(per_seed) == 1:
        g_sd, eta_sd = per_seed[0]
        (g1, e1), (h1, f1) = summary(g_sd[skip:], blocks=20), summary(eta_sd[skip // 100:], blocks=16)
    else:  # the runs' means as independent samples
        (g1, e1) = summary(np.array([g[skip:].mean(axis=0) for g, _ in per_seed]))
        (h1, f1) = summary(np.array([eta[skip // 100:].mean() for _, eta in per_seed]))
    (g2, e2), (h2, f2) = summary(g_mc, blocks=20), summary(eta_mc, blocks=20)
    row_rule = args.collisions or default_rule(args.model)
    row = {"model": args.model, "near_contact_correction": not args.uncorrected,
           "kappa": "1" if args.kappa_one else "the pair's own", "n_particles": args.n,
           "phi": args.phi, "dt": args.dt, "steps": args.steps, "discarded_steps": skip,
           "ewald_tolerance": job_at_rest(args.model, args.n, args.phi, args.steps, args.dt,
                                          ewald_tolerance=args.ewald_tolerance).ewald_tolerance,
           **({"seed": args.seeds[0]} if len(args.seeds) == 1 else {"seeds": args.seeds}),
           "collisions": row_rule,
           # separate moves the two spheres of a pair (collisions.remove_overlaps), reflect
           # acts through the mobility unless --symmetric
           "collision_moves": "symmetric" if args.symmetric or row_rule == "separate" else "through the mobility",
           "mc_configs": args.mc_configs,
           "mc_start_sweeps": args.mc_sweeps, "mc_every_sweeps": args.mc_every,
           "gap_shells": EDGES.tolist(), "last_column": "gaps 0 to 3e-4 (the first two shells together)",
           "g_dynamics": g1.tolist(), "g_dynamics_err": e1.tolist(),
           "g_mc": g2.tolist(), "g_mc_err": e2.tolist(), "eta_h_dynamics": [float(h1), float(f1)],
           "eta_h_mc": [float(h2), float(f2)],
           **({} if len(per_seed) == 1 else
              {"g_dynamics_per_seed": [g[skip:].mean(axis=0).tolist() for g, _ in per_seed]}),
           "seconds": round(time.perf_counter() - start)}
    print(json.dumps(row))
    with open(args.out, "a") as out:
        out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
