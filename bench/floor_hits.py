"""How often a Brownian step brings pairs to the floor, against the exact transition.

Near contact a pair's gap h follows a squared Bessel process, dh = c dt + sqrt(2 c h) dW
with D_rr = kT G = c h (G its relative mobility along the line of centres,
`sdmpi.dynamics.drift`), whose exact step from h0 is h1 = (c dt / 2) X with X a
non-central chi-square of 2 degrees of freedom and non-centrality 2 h0 / (c dt). Over one
run at rest (no shear; the setting of `bench/near_contact_structure.py`) this counts the
pairs the step leaves closer than the floor hydrodynamics.min_gap (the samples'
n_overlaps: the overlap correction's first search), and sums, over the same steps, the
exact probability P(h1 < min_gap) of every pair closer than the near-contact correction's
reach (NEAR_CONTACT_GAP) at the step's start, with c = kT G_p / h_p from the step's own
mobility. A ratio above 1 is the time-step error of the step near contact; it should fall
towards 1 as dt does. Prints one JSON line per seed, appended to bench/floor_hits.json.

    python bench/floor_hits.py [--n 27] [--dt 5e-4] [--seeds 21 22] [--relax 1.0] [--duration 2.0]
        [--kappa-one | --kappa-scale 1.03 [--scale-beyond 3]] [--correction-below 0.01]
        [--backend petsc-krylov --tolerance 1e-4 --ewald-tolerance 1e-4]
        [--scheme midpoint] [--no-near-contact]

--kappa-one gives the near-contact correction the isolated pair's kappa = 1 for every pair
(`near_contact_structure.use_kappa_one`, for comparison); --kappa-scale multiplies every
pair's kappa (an error of G_p), with --scale-beyond R only of the pairs at least R c dt
from contact (where `drift.near_contact_velocities` asks G_p less precisely beyond
FLOOR_REACH), and --correction-below gives the correction only to the
pairs below that gap (the exact count still sums every pair below NEAR_CONTACT_GAP). Each
row also has the gaps' distribution near contact: `gap_histogram`, the number of pairs
per bin of GAP_BINS summed over the steps' starts. --backend runs another solver
backend (petsc-krylov: by default its midpoint scheme), with the
solver and Lanczos --tolerance and the far field's --ewald-tolerance; --scheme another
drift scheme; --no-near-contact leaves the near-contact correction out.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.stats import ncx2

from near_contact_structure import job_at_rest, scale_kappa, use_kappa_one
from sdmpi.config.tasks import enumerate_tasks
from sdmpi.dynamics import drift
from sdmpi.dynamics.realisation import Realisation

#: the pairs the exact count sums (the near-contact correction's reach as the package has it)
EXACT_REACH = drift.NEAR_CONTACT_GAP
#: bins of the gaps' distribution (surface gap, radius 1)
GAP_BINS = np.linspace(0.0, 0.05, 21)


def exact_floor_probability(evaluation, kT, dt, min_gap):
    """Sum over the pairs of evaluation closer than EXACT_REACH of the exact squared
    Bessel probability that one step of dt leaves the pair below min_gap."""
    pairs = evaluation.pairs
    close = pairs.gap < EXACT_REACH
    if not close.any():
        return 0.0
    i, j, dx = pairs.i[close], pairs.j[close], pairs.dx[close]
    e = dx / np.linalg.norm(dx, axis=1)[:, None]
    g = evaluation.relative_mobility(i, j, e)
    h0 = np.maximum(pairs.gap[close], min_gap)
    half = 0.5 * (kT * g / h0) * dt  # c dt / 2
    return float(ncx2.cdf(min_gap / half, 2, h0 / half).sum())


def run(seed, n, phi, dt, relax, duration, backend=None, tolerance=None, ewald_tolerance=None, scheme=None,
        near_contact=True):
    """Observed floor hits and the exact prediction per step, over `duration` t_D after
    `relax` t_D of one run at rest (backend, tolerance, ewald_tolerance, scheme None: the
    job defaults; near_contact False: without the near-contact correction)."""
    job = job_at_rest("stokesian", n, phi, 10 ** 7, dt, seed=seed, backend=backend, tolerance=tolerance,
                      ewald_tolerance=ewald_tolerance, scheme=scheme)
    real = Realisation(job, enumerate_tasks(job)[0])
    real.model.near_contact = real.model.near_contact and near_contact
    real.advance(int(round(relax / dt)))
    predicted = [0.0]
    histogram = np.zeros(len(GAP_BINS) - 1)
    evaluate = real.model.at

    def at(positions, strain):  # the step's own evaluation, instrumented
        evaluation = evaluate(positions, strain)
        predicted[0] += exact_floor_probability(evaluation, real.kT, dt, job.hydrodynamics.min_gap)
        histogram[:] += np.histogram(evaluation.pairs.gap, GAP_BINS)[0]
        return evaluation

    real.model.at = at
    steps = int(round(duration / dt))
    observed = int(real.advance(steps)["n_overlaps"].sum())
    return {"seed": seed, "n_particles": n, "phi": phi, "dt": dt, "steps": steps,
            "relax_t_D": relax, "observed_per_step": observed / steps,
            "exact_per_step": predicted[0] / steps, "ratio": observed / max(predicted[0], 1e-300),
            "scheme": real.model.scheme, "near_contact_correction": real.model.near_contact,
            "gap_histogram": histogram.astype(int).tolist()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=27)
    parser.add_argument("--phi", type=float, default=0.45)
    parser.add_argument("--dt", type=float, default=5e-4)
    parser.add_argument("--seeds", type=int, nargs="+", default=[21, 22])
    parser.add_argument("--relax", type=float, default=1.0, help="t_D left out from the Monte Carlo start")
    parser.add_argument("--duration", type=float, default=2.0, help="t_D counted")
    parser.add_argument("--out", default=str(Path(__file__).with_name("floor_hits.json")))
    parser.add_argument("--kappa-one", action="store_true")
    parser.add_argument("--kappa-scale", type=float, default=None, help="every kappa times this")
    parser.add_argument("--scale-beyond", type=float, default=None,
                        help="--kappa-scale only for pairs at least this many c dt from contact")
    parser.add_argument("--correction-below", type=float, default=None,
                        help="the near-contact correction only below this gap")
    parser.add_argument("--backend", default=None)
    parser.add_argument("--tolerance", type=float, default=None)
    parser.add_argument("--ewald-tolerance", type=float, default=None)
    parser.add_argument("--scheme", default=None, help="brownian.scheme (rfd, midpoint, ...)")
    parser.add_argument("--no-near-contact", action="store_true", help="without the near-contact correction")
    args = parser.parse_args()
    if args.kappa_one:
        use_kappa_one()
    if args.kappa_scale is not None:
        scale_kappa(args.kappa_scale, args.scale_beyond, 6.0 * np.pi, args.dt)  # (kT = 6 pi: D0 = 1)
    if args.correction_below is not None:
        drift.NEAR_CONTACT_GAP = args.correction_below
    for seed in args.seeds:
        start = time.perf_counter()
        row = run(seed, args.n, args.phi, args.dt, args.relax, args.duration, args.backend, args.tolerance,
                  args.ewald_tolerance, args.scheme, not args.no_near_contact)
        row["kappa"] = "1" if args.kappa_one else "the pair's own" + (
            f" x {args.kappa_scale}" if args.kappa_scale is not None else "") + (
            f" beyond {args.scale_beyond} c dt" if args.scale_beyond is not None else "")
        row["correction_below"] = drift.NEAR_CONTACT_GAP
        row["backend"] = args.backend or "dense"
        row["seconds"] = round(time.perf_counter() - start)
        print(json.dumps(row), flush=True)
        with open(args.out, "a") as out:
            out.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
