"""How loose an Ewald tolerance (or how short a lubrication cut-off) a Brownian run at
N = 27, phi = 0.45 can take.

On a fixed set of equilibrium hard-sphere configurations (Monte Carlo,
`sdmpi.dynamics.initial.hard_sphere_fluid`, one seed each) this compares, between the
reference ewald_tolerance (1e-6) and looser ones, the operators a Brownian step uses:

- R_FU^-1 (6N x 6N), the mobility that turns forces into velocities;
- the Brownian drift kT div R_FU^-1 (6N) and the Brownian stresslets
  -kT div(R_SU R_FU^-1) (5N), by centred finite differences over the 3N translations
  with the configuration's pair sets frozen (as the midpoint scheme sees them);
- eta_H = n <S_xy>/gamma_dot, the hydrodynamic part of the high-frequency viscosity.

Per configuration the error of a vector or matrix X is ||X_tol - X_ref|| / ||X_ref||
(Frobenius/Euclidean), of eta_H |eta_tol - eta_ref| / eta_ref; the systematic part of a
vector's error is its component along the reference, (X_tol - X_ref).X_ref / |X_ref|^2,
averaged over the configurations (a bias that averaging over an ensemble does not remove).
Also the CPU time of one `grand_resistance` at each tolerance, in units of a 297 x 297
LAPACK Cholesky timed in the same process. Writes JSON (default bench/ewald_tolerance.json).
With --cutoffs, the same comparison for shorter hydrodynamics.lubrication_cutoff values
against the default cut-off, all at the reference tolerance (default
bench/lubrication_cutoff.json). With --cost-only, only the cost field of the output file is
timed again, for the settings it holds (seconds instead of the ~40 CPU-minutes of the
errors, which do not depend on how fast the kernels are).

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python bench/ewald_tolerance.py [--cutoffs 1.5 1] [--cost-only]
"""

import argparse
import json
import platform
import time

import numpy as np
from scipy.linalg import lapack

from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro.basis import BASIS, to_five
from sdmpi.hydro.bulk import UNIT_SHEAR
from sdmpi.hydro.lubrication import DEFAULT_CUTOFF
from sdmpi.hydro.resistance import grand_resistance, mobility_divergence
from sdmpi.hydro.solvers import DenseSolver

KT = 1.0  # the errors are relative: any kT


def operators(pos, box, tol, h, cutoff=DEFAULT_CUTOFF):
    """R_FU^-1, kT div R_FU^-1, -kT div(R_SU R_FU^-1) and eta_H at one tolerance and
    lubrication cut-off."""
    n = len(pos)
    radii = np.ones(n)
    base = grand_resistance(pos, radii, box, 0.0, ewald_tol=tol, cutoff=cutoff)
    mobility = np.linalg.inv(base.blocks()[0])
    div_m, div_a = mobility_divergence(
        lambda moved, plan: grand_resistance(moved, radii, box, 0.0, ewald_tol=tol, cutoff=cutoff, plan=plan),
        base, h)
    return {"mobility": mobility, "drift": KT * div_m, "stresslets": -KT * div_a,
            "bulk_stresslet": -KT * div_a.reshape(n, 5).sum(axis=0), "eta_H": np.array([eta_h(base, box)])}


def eta_h(resistance, box):
    """eta_H = n <S_xy> for force- and torque-free spheres at unit shear rate
    (`hydro.bulk.hydrodynamic_viscosity`), from an assembled resistance."""
    n = resistance.n_particles
    einf = np.broadcast_to(to_five(UNIT_SHEAR), (n, 5))
    solver = DenseSolver(resistance)
    stresslets = solver.stresslets(solver.velocities(np.zeros((n, 6)), einf), einf)
    return n / float(np.prod(box)) * float((stresslets @ BASIS[:, 0, 1]).mean())


def cholesky_units(pos, box, settings, repeat=40):
    """CPU ms of one grand_resistance per setting (label -> (tolerance, cut-off)) and of a
    297 x 297 Cholesky, interleaved (medians)."""
    a = np.random.default_rng(0).standard_normal((297, 297))
    spd = a @ a.T + 297 * np.eye(297)
    runs = {"cholesky": lambda: lapack.dpotrf(spd)}
    runs.update({label: (lambda t=t, c=c: grand_resistance(pos, np.ones(len(pos)), box, 0.0, ewald_tol=t, cutoff=c))
                 for label, (t, c) in settings.items()})
    times = {k: [] for k in runs}
    for f in runs.values():
        f()
    for _ in range(repeat):
        for k, f in runs.items():
            t0 = time.process_time()
            for _ in range(5):
                f()
            times[k].append((time.process_time() - t0) / 5)
    ms = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
    return {"ms": ms, "cholesky_equivalents": {k: v / ms["cholesky"] for k, v in ms.items()}}


def configuration(n, phi, seed):
    """Configuration `seed` of the set: (positions, box) of a Monte Carlo hard-sphere fluid."""
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(seed))
    return pos, np.full(3, side)


def _setting(label, reference):
    """(tolerance, cut-off) of a label of the cost field: "T", "T, cutoff C" or "cutoff C"
    (at the reference tolerance)."""
    tol, cutoff = reference, DEFAULT_CUTOFF
    for part in label.split(", "):
        if part.startswith("cutoff "):
            cutoff = float(part.split()[1])
        else:
            tol = float(part)
    return tol, cutoff


def refresh_cost(args):
    """Re-times the cost field of an existing result file for its own settings."""
    out = args.out or ("bench/lubrication_cutoff.json" if args.cutoffs else "bench/ewald_tolerance.json")
    with open(out) as fh:
        result = json.load(fh)
    settings = {label: _setting(label, result["reference"]) for label in result["cost"]["ms"]
                if label != "cholesky"}
    result["cost"] = cholesky_units(*configuration(result["n"], result["phi"], 0), settings)
    result["cost_date"] = time.strftime("%Y-%m-%d", time.gmtime())
    with open(out, "w") as fh:
        json.dump(result, fh, indent=1)
    print("grand_resistance cost [Cholesky-297 equivalents]:",
          {k: round(v, 2) for k, v in result["cost"]["cholesky_equivalents"].items()})


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--configs", type=int, default=20)
    ap.add_argument("--n", type=int, default=27)
    ap.add_argument("--phi", type=float, default=0.45)
    ap.add_argument("--reference", type=float, default=1e-6)
    ap.add_argument("--tolerances", type=float, nargs="+", default=[1e-5, 1e-4])
    ap.add_argument("--cutoffs", type=float, nargs="+",
                    help="compare these lubrication cut-offs (at the reference tolerance) instead")
    ap.add_argument("--h", type=float, default=1e-5, help="finite-difference step [a]")
    ap.add_argument("--out")
    ap.add_argument("--cost-only", action="store_true",
                    help="re-time only the cost of the settings already in the output file "
                         "(the errors do not depend on the speed of the kernels) and rewrite its "
                         "cost field")
    args = ap.parse_args()
    if args.cost_only:
        refresh_cost(args)
        return
    if args.cutoffs:
        settings = {f"cutoff {c:g}": (args.reference, c) for c in args.cutoffs}
        args.out = args.out or "bench/lubrication_cutoff.json"
        del args.tolerances
    else:
        settings = {f"{t:g}": (t, DEFAULT_CUTOFF) for t in args.tolerances}
        args.out = args.out or "bench/ewald_tolerance.json"
        del args.cutoffs
    reference = f"{args.reference:g}, cutoff {DEFAULT_CUTOFF:g}"
    errors = {label: {} for label in settings}
    configs = []
    for seed in range(args.configs):
        pos, box = configuration(args.n, args.phi, seed)
        configs.append((pos, box))
        ref = operators(pos, box, args.reference, args.h)
        for label, (t, c) in settings.items():
            got = operators(pos, box, t, args.h, c)
            for key, r in ref.items():
                d = got[key] - r
                e = errors[label].setdefault(key, {"relative": [], "systematic": []})
                e["relative"].append(float(np.linalg.norm(d) / np.linalg.norm(r)))
                e["systematic"].append(float(np.vdot(d, r) / np.vdot(r, r)))
        print(f"config {seed}: eta_H = {ref['eta_H'][0]:.4f}, "
              + ", ".join(f"{label}: drift {errors[label]['drift']['relative'][-1]:.1e}"
                          for label in settings), flush=True)
    summary = {}
    for t, per in errors.items():
        summary[t] = {key: {"mean_relative": float(np.mean(e["relative"])),
                            "max_relative": float(np.max(e["relative"])),
                            "mean_systematic": float(np.mean(e["systematic"])),
                            "below_0.2_percent": bool(max(np.mean(e["relative"]),
                                                          abs(np.mean(e["systematic"]))) < 2e-3)}
                      for key, e in per.items()}
    result = {"command": "python bench/ewald_tolerance.py " + " ".join(
                  f"--{k.replace('_', '-')} {v if not isinstance(v, list) else ' '.join(map(str, v))}"
                  for k, v in vars(args).items() if k != "out"),
              "n": args.n, "phi": args.phi, "configs": args.configs, "reference": args.reference,
              "reference_cutoff": DEFAULT_CUTOFF,
              "summary": summary, "per_config": errors,
              "cost": cholesky_units(*configs[0], {reference: (args.reference, DEFAULT_CUTOFF), **settings}),
              "machine": platform.processor() or platform.machine(), "python": platform.python_version()}
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=1)
    for t, per in summary.items():
        print(f"{t} against {reference}:")
        for key, s in per.items():
            print(f"  {key:15s} mean {s['mean_relative']:.2e}  max {s['max_relative']:.2e}  "
                  f"systematic {s['mean_systematic']:+.2e}  {'ok' if s['below_0.2_percent'] else 'TOO LARGE'}")
    print("grand_resistance cost [Cholesky-297 equivalents]:",
          {k: round(v, 2) for k, v in result["cost"]["cholesky_equivalents"].items()})


if __name__ == "__main__":
    main()
