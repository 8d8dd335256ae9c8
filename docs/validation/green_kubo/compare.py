"""Green-Kubo at rest against exact and oscillatory results: the tables of README.md.

    python docs/validation/green_kubo/compare.py --dilute dilute_rest.h5 \\
        --rest fd27_rest.h5 --osc fd27_osc8pi.h5 fd27_osc32pi.h5 \\
        --rest2 ff27_rest.h5 --osc2 ff27_osc8pi.h5 > results.md

(the run files of the job files here; README.md gives the commands). Dilute: G(t) at
each short lag, sampled as it is, against the exact O(phi^2) G(t) of hard spheres
without hydrodynamic interactions averaged over a step
(sdmpi.analysis.analytic.dilute_hard_sphere_relaxation), and G', G'' with each short-time
rule and window against the exact moduli (sdmpi.analysis.analytic.dilute_hard_sphere_moduli).
phi = 0.3: the Brownian and collision rows of Green-Kubo and of oscillatory runs of the
same model (free draining; far field).
"""

import argparse
import math
import warnings

import numpy as np
from scipy.integrate import quad

from sdmpi.analysis import green_kubo as gk
from sdmpi.analysis.at_rest import STREAMS, reduce_at_rest
from sdmpi.analysis.analytic import dilute_hard_sphere_moduli, dilute_hard_sphere_relaxation
from sdmpi.analysis.reduce import PartialRunWarning, reduce_runs

COLLISION = STREAMS.index("collision")


def step_mean(m, dt):
    """Exact dilute G(t)/phi^2 averaged over a step: the correlation of step means at lag m."""
    f = lambda t: float(dilute_hard_sphere_relaxation(t))
    if m == 0:
        return 2 * quad(lambda t: f(t) * (1 - t / dt), 0, dt, limit=200)[0] / dt
    return (quad(lambda t: f(t) * (t / dt - m + 1), (m - 1) * dt, m * dt, limit=200)[0]
            + quad(lambda t: f(t) * (m + 1 - t / dt), m * dt, (m + 1) * dt, limit=200)[0]) / dt


def pm(x, e, d=2):
    return f"{x:.{d}f} ± {e:.{d}f}"


def dilute(path):
    print(f"## Dilute free draining at rest ({path})\n")
    red = reduce_at_rest([path], window=1.0, lag0="keep")
    g = red.groups[0]
    phi2 = g.phi ** 2
    n = int(g.relaxation.n_realisations[-1, 0])
    print(f"N = {red.job.system.n_particles}, phi = {g.phi:g}, dt = {g.dt:g}, {n} realisations; "
          f"G(t)/phi^2 as sampled (rule `keep`) against the exact step mean\n")
    print("| lag | t | sampled G/phi^2 | exact | ratio |\n|---|---|---|---|---|")
    for i, lag in enumerate(g.lags):
        if lag <= 8 or lag in (16, 32, 64, 128, 256):
            ex = step_mean(int(lag), g.dt)
            m, e = g.relaxation.mean[-1, i] / phi2, g.relaxation.err[-1, i] / phi2
            print(f"| {lag} | {lag * g.dt:g} | {pm(m, e)} | {ex:.2f} | {pm(m / ex, e / ex, 3)} |")
    for window in (1.0, None):
        reds = {rule: reduce_at_rest([path], window=window, lag0=rule)
                for rule in ("contact", "keep", "lag1")}
        g = reds["contact"].groups[0]
        lags = np.arange(g.max_lag + 1)
        exact_g = dilute_hard_sphere_relaxation(np.maximum(lags, 1) * g.dt)
        exact_g[:32] = [step_mean(m, g.dt) for m in range(32)]
        print(f"\nG'/phi^2, G''/phi^2 (collision row), window {g.max_lag * g.dt:g} t_D, "
              f"against the exact moduli and (in brackets) the exact G(t) put through the "
              f"same window and rule\n")
        print("| omega | rule | G'/phi^2 | exact | G''/phi^2 | exact |\n|---|---|---|---|---|---|")
        for k, w in enumerate(g.omega):
            if not any(math.isclose(w, x * math.pi) for x in (0.5, 1, 2, 4, 8, 16, 32)):
                continue
            e1, e2 = dilute_hard_sphere_moduli(w)
            for rule, r in reds.items():
                mod = r.groups[0].moduli
                a1, s1 = mod.mean[COLLISION, 0, k] / phi2, mod.err[COLLISION, 0, k] / phi2
                a2, s2 = mod.mean[COLLISION, 1, k] / phi2, mod.err[COLLISION, 1, k] / phi2
                t1, t2 = (float(x[0]) for x in gk.transform(gk.apply_lag0(exact_g, rule),
                                                            g.dt, [w]))
                print(f"| {w / math.pi:g} pi | {rule} | {pm(a1, s1)} | {float(e1):.2f} "
                      f"({t1:.2f}) | {pm(a2, s2)} | {float(e2):.2f} ({t2:.2f}) |")
    print()


def phi03(rest, osc):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        reds = {rule: reduce_at_rest([rest], lag0=rule) for rule in ("contact", "keep")}
        oscs = [reduce_runs([p]) for p in osc]
    g = reds["contact"].groups[0]
    print(f"## {reds['contact'].job.hydrodynamics.model}, phi = {g.phi:g}: Green-Kubo ({rest}) "
          f"against oscillatory runs\n")
    raw = reds["keep"].groups[0].relaxation
    for row in ("brownian", "collision"):
        c = STREAMS.index(row)
        print(f"G_A(t) of the {row} row as sampled (its correlation with the configurational "
              f"stress), lags 0-8 (eta_m/t_D): "
              + ", ".join(pm(raw.mean[c, i], raw.err[c, i], 2) for i in range(9)) + "\n")
    steps = int(reds["contact"].committed.sum())
    print(f"At rest: {int(g.relaxation.n_realisations[-1, 0])} realisations, {steps} steps "
          f"committed, window {g.max_lag * g.dt:g} t_D. Brownian and collision rows "
          f"(eta_m/t_D):\n")
    print("| omega | row | route | steps | G' | G'' |\n|---|---|---|---|---|---|")
    for red in oscs:
        w, phi = float(red.control[0]), float(red.phi[0])
        k = int(np.argmin(np.abs(g.omega - w)))
        for row in ("brownian", "collision"):
            c = STREAMS.index(row)
            for rule, r in reds.items():
                mod = r.groups[0].moduli
                print(f"| {w / math.pi:g} pi | {row} | Green-Kubo, {rule} | {steps} | "
                      f"{pm(mod.mean[c, 0, k], mod.err[c, 0, k])} | "
                      f"{pm(mod.mean[c, 1, k], mod.err[c, 1, k])} |")
            cols = [red.value(phi, w, row, q) for q in
                    ("G_prime", "G_prime_err", "G_dprime", "G_dprime_err")]
            print(f"| {w / math.pi:g} pi | {row} | oscillatory, gamma0 = "
                  f"{red.job.shear.gamma0:g} | {int(red.committed.sum())} | {pm(*cols[:2])} | "
                  f"{pm(*cols[2:])} |")
    print()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dilute")
    parser.add_argument("--rest")
    parser.add_argument("--osc", nargs="*", default=[])
    parser.add_argument("--rest2", help="a second run at rest (another model)")
    parser.add_argument("--osc2", nargs="*", default=[])
    args = parser.parse_args()
    if args.dilute:
        dilute(args.dilute)
    for rest, osc in ((args.rest, args.osc), (args.rest2, args.osc2)):
        if rest:
            phi03(rest, osc)


if __name__ == "__main__":
    main()
