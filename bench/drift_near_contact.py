"""The Brownian drift of close pairs in a suspension: the rfd estimate against the exact
divergence, on configurations evolved at rest.

Full SD (`stokesian`), N = 27, phi = 0.45, the setting of `bench/near_contact_structure.py`
(no shear, dt = 5e-4, the Brownian Ewald default). A run at rest is stepped for --relax t_D,
then every --every steps its configuration x is taken, and there

* the exact drift kT div R_FU^-1 (the sum over the 3N translations of the derivatives of
  the mobility's columns, centred differences of step 1e-7 with the pair sets of x:
  `hydro.resistance.mobility_divergence`),
* the mean of the `rfd` drift over --samples antithetic noise pairs z, -z (the Brownian
  velocities of z and -z averaged: the noise cancels, the drift, even in z, stays),

are projected on every pair closer than --gap: the relative radial drift
e.(u_j - u_i) (e the unit line of centres), in units of c = kT G/h (G the pair's relative
mobility along e, h its gap), the coefficient of dh = c dt + sqrt(2 c h) dW for an
isolated pair (`sdmpi.dynamics.models`). Reported per pair: h, c, the exact radial drift
over c, the rfd mean over c with its standard error, the standard deviation of one rfd
sample's radial drift over c, and the curvature term kT (G_t1 + G_t2)/r over c (G_t the
relative mobilities along two unit tangents t perpendicular to e, r the pair's separation):
the mean rate at which tangential diffusion opens the gap, <|dr_perp|^2>/(2 r dt). A flat
pair density at contact (hard spheres in equilibrium, g constant) has zero radial flux
there, D_rr' = radial drift + curvature term with D_rr = c h, so the exact radial drift plus
the curvature term is c as h -> 0. The same for two spheres alone ("isolated_pair"). Prints
one JSON line, appended to
bench/drift_near_contact.json.

    OMP_NUM_THREADS=1 python bench/drift_near_contact.py [--seed 22] [--configs 8] [--samples 4000]
"""

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from near_contact_structure import job_at_rest
from sdmpi.config.tasks import enumerate_tasks
from sdmpi.dynamics.models import ResistanceModel
from sdmpi.dynamics.realisation import KT_REDUCED, Realisation
from sdmpi.hydro.resistance import grand_resistance, mobility_divergence

#: step of the centred differences (the gaps are >= 1e-4)
FD_STEP = 1e-7


def exact_drift(evaluation, kT, ewald_tol, min_gap, cutoff=2.0):
    """kT div R_FU^-1 (N, 6) at the evaluation's configuration (stokesian model at strain
    0), by centred differences over the 3N translations with its pair sets
    (`hydro.resistance.mobility_divergence`)."""
    base = evaluation.resistance

    def resistance_at(positions, plan):
        return grand_resistance(positions, base.radii, evaluation.model.box, 0.0, plan=plan, ewald_tol=ewald_tol,
                                cutoff=cutoff, min_gap=min_gap)

    div_m, _ = mobility_divergence(resistance_at, base, FD_STEP)
    return kT * div_m.reshape(-1, 6)


def rfd_drift_samples(evaluation, kT, dt, samples, rng):
    """(samples, N, 6) rfd drift samples, each the mean of the Brownian velocities of z and
    -z (no near-contact correction)."""
    shape = evaluation.solver.noise_shape
    out = []
    for _ in range(samples):
        z = rng.standard_normal(shape)
        out.append(0.5 * (evaluation.brownian_terms(z, kT, dt).velocities
                          + evaluation.brownian_terms(-z, kT, dt).velocities))
    return np.array(out)


def tangential_mobility(evaluation, i, j, e):
    """G_t1 + G_t2 of the pairs (i, j) with unit lines of centres e: the relative mobilities
    t.(M_jj + M_ii - M_ij - M_ji).t along two unit tangents t perpendicular to e and to each
    other (their sum does not depend on the choice of the tangents)."""
    helper = np.where(np.abs(e[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(e, helper)
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(e, t1)
    return sum(evaluation.relative_mobility(i, j, t) for t in (t1, t2))


def isolated_pair(gaps=(2e-4, 1e-3, 3e-3)):
    """The same quantities for two spheres alone (box of side 10, the stokesian model at
    ewald_tolerance 1e-6), per gap: c, the exact radial drift over c, the curvature term
    over c."""
    rows = []
    for gap in gaps:
        pos = np.array([[3.0, 4.0, 5.0], [5.0 + gap, 4.0, 5.0]])
        model = ResistanceModel(np.ones(2), np.full(3, 10.0), lubrication=True, ewald_tol=1e-6, cutoff=2.0,
                                min_gap=1e-4, scheme="rfd")
        evaluation = model.at(pos, 0.0)
        exact = exact_drift(evaluation, KT_REDUCED, 1e-6, 1e-4)
        i, j, e = np.array([0]), np.array([1]), np.array([[1.0, 0.0, 0.0]])
        c = KT_REDUCED * evaluation.relative_mobility(i, j, e)[0] / gap
        rows.append({"gap": gap, "c": float(c), "exact_over_c": float((exact[1, 0] - exact[0, 0]) / c),
                     "curvature_over_c": float(KT_REDUCED * tangential_mobility(evaluation, i, j, e)[0]
                                               / (2 + gap) / c)})
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=22)
    ap.add_argument("--configs", type=int, default=8)
    ap.add_argument("--samples", type=int, default=4000)
    ap.add_argument("--relax", type=float, default=1.0, help="t_D stepped before the first configuration")
    ap.add_argument("--every", type=int, default=400, help="steps between configurations")
    ap.add_argument("--gap", type=float, default=1e-2, help="pairs closer than this (a) are reported")
    ap.add_argument("--out", default=str(Path(__file__).with_name("drift_near_contact.json")))
    args = ap.parse_args()
    dt = 5e-4
    job = job_at_rest("stokesian", 27, 0.45, 10 ** 7, dt, seed=args.seed)
    real = Realisation(job, enumerate_tasks(job)[0])
    real.advance(int(round(args.relax / dt)))
    rng = np.random.default_rng(args.seed)
    rows, start = [], time.time()
    for _ in range(args.configs):
        real.advance(args.every)
        evaluation = real.model.at(real.positions, 0.0)
        exact = exact_drift(evaluation, real.kT, job.ewald_tolerance, job.hydrodynamics.min_gap,
                            job.hydrodynamics.lubrication_cutoff)
        samples = rfd_drift_samples(evaluation, real.kT, dt, args.samples, rng)
        pairs = evaluation.pairs
        close = pairs.gap < args.gap
        i, j, dx = pairs.i[close], pairs.j[close], pairs.dx[close]
        e = dx / np.linalg.norm(dx, axis=1)[:, None]
        c = real.kT * evaluation.relative_mobility(i, j, e) / np.maximum(pairs.gap[close], job.hydrodynamics.min_gap)
        radial_exact = np.einsum("pc,pc->p", e, exact[j, :3] - exact[i, :3])
        curvature = real.kT * tangential_mobility(evaluation, i, j, e) / np.linalg.norm(dx, axis=1)
        radial = np.einsum("pc,spc->sp", e, samples[:, j, :3] - samples[:, i, :3])
        for p in range(len(i)):
            rows.append({"gap": float(pairs.gap[close][p]), "c": float(c[p]),
                         "exact_over_c": float(radial_exact[p] / c[p]),
                         "rfd_over_c": float(radial[:, p].mean() / c[p]),
                         "rfd_over_c_err": float(radial[:, p].std() / math.sqrt(args.samples) / c[p]),
                         "rfd_sample_std_over_c": float(radial[:, p].std() / c[p]),
                         "curvature_over_c": float(curvature[p] / c[p])})
            print(json.dumps(rows[-1]), flush=True)
    result = {"model": "stokesian", "n_particles": 27, "phi": 0.45, "dt": dt, "seed": args.seed,
              "ewald_tolerance": job.ewald_tolerance, "configs": args.configs, "samples": args.samples,
              "pairs": rows, "isolated_pair": isolated_pair(), "seconds": round(time.time() - start)}
    with open(args.out, "a") as fh:
        fh.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    main()
