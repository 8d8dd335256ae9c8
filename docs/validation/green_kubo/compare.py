"""Green-Kubo at rest against exact and oscillatory results: the tables of README.md.

    python docs/validation/green_kubo/compare.py --dilute dilute_rest.h5 \\
        --rest fd27_rest.h5 --osc fd27_osc8pi.h5 fd27_osc32pi.h5 \\
        --rest2 ff27_rest.h5 --osc2 ff27_osc8pi.h5 > results.md

(the run files of the job files here; README.md gives the commands, and those of the
full-SD comparison, --sd). Dilute: G(t) at
each short lag, sampled as it is, against the exact O(phi^2) G(t) of hard spheres
without hydrodynamic interactions averaged over a step
(sdmpi.analysis.analytic.dilute_hard_sphere_relaxation), and G', G'' with each short-time
rule and window against the exact moduli (sdmpi.analysis.analytic.dilute_hard_sphere_moduli).
phi = 0.3: the Brownian and collision rows of Green-Kubo and of oscillatory runs of the
same model (free draining; far field). Full SD at phi = 0.45 (--sd): every short-time
rule against the oscillatory study of Schaink et al. (2000) reproduced in
docs/validation/schaink2000 and against its 80 pi control at the run's own time step.
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


#: the study's frequencies compared (rad/t_D) and rows
STUDY_OMEGA = tuple(x * math.pi for x in (2, 8, 16, 32, 80))
RULES = ("keep", "lag1", "contact", "linear")


def study_rows(path):
    """{(omega, component): (G', G'_err, G'', G''_err)} of a moduli.csv; "configurational"
    is brownian + interparticle + collision (errors in quadrature)."""
    import csv
    out = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            out[(float(r["omega"]), r["component"])] = tuple(
                float(r[c]) for c in ("G_prime", "G_prime_err", "G_dprime", "G_dprime_err"))
    for w in {k[0] for k in out}:
        parts = [out[(w, c)] for c in STREAMS]
        out[(w, "configurational")] = (sum(p[0] for p in parts), math.hypot(*(p[1] for p in parts)),
                                       sum(p[2] for p in parts), math.hypot(*(p[3] for p in parts)))
    return out


def study_steps(job_path):
    """{omega: time steps of all its tasks} of the study's job."""
    import sdmpi
    steps = {}
    for t in sdmpi.tasks(sdmpi.load_job(job_path)):
        steps[t.omega] = steps.get(t.omega, 0) + t.n_steps
    return steps


def z(a, ea, b, eb):
    return (a - b) / math.hypot(ea, eb)


def same_dt(reds, g, path):
    """The rows of an oscillatory table at the run's own time step (finite_size/dt_control:
    80 pi at dt = 5e-4) against Green-Kubo at its frequencies."""
    ref = study_rows(path)
    print(f"\nAgainst oscillatory runs at the same time step ({path}), z in brackets:\n")
    print("| omega | route | Brownian G' | Brownian G'' | eta_H |\n|---|---|---|---|---|")
    for w in sorted({q[0] for q in ref}):
        b1, e1, b2, e2 = ref[(w, "brownian")]
        h = ref[(w, "hydrodynamic")]
        print(f"| {w / math.pi:g} pi | oscillatory | {pm(b1, e1)} | {pm(b2, e2)} | "
              f"{pm(h[2] / w, h[3] / w, 3)} |")
        for rule in RULES:
            r = reds[rule]
            a1, f1, a2, f2 = (r.value(g.phi, w, "brownian", q) for q in
                              ("G_prime", "G_prime_err", "G_dprime", "G_dprime_err"))
            print(f"| | GK `{rule}` | {pm(a1, f1)} ({z(a1, f1, b1, e1):+.1f}) | {pm(a2, f2)} "
                  f"({z(a2, f2, b2, e2):+.1f}) | {pm(g.hydro.eta_h, g.hydro.err, 3)} "
                  f"({z(g.hydro.eta_h, g.hydro.err, h[2] / w, h[3] / w):+.1f}) |")


def totals_and_cost(reds, g, study, steps, gk_steps):
    """The total G'' per rule against the study's, and the steps the run at rest needs
    for the study's error bar of the Brownian G', G''."""
    b = STREAMS.index("brownian")
    print(f"\nTotal G'' (medium + hydrodynamic from the frames + configurational) and the "
          f"cost of the Brownian row: the steps Green-Kubo needs for the study's error bar, "
          f"{gk_steps} x (err_GK/err_study)^2, against the study's steps at that frequency "
          f"(every frequency from the same run at rest):\n")
    print("| omega | rule | total G'' | study | z | steps for G'_B | for G''_B | study's steps |")
    print("|---|---|---|---|---|---|---|---|")
    for k, w in enumerate(STUDY_OMEGA):
        key = min({q[0] for q in study}, key=lambda q: abs(q - w))
        if not math.isclose(key, w, rel_tol=1e-6):
            continue  # a frequency the oscillatory table does not have
        t, b1, b2 = study[(key, "total")], study[(key, "brownian")][1], study[(key, "brownian")][3]
        for rule in RULES:
            r, mod = reds[rule], reds[rule].groups[0].moduli
            a, e = r.value(g.phi, w, "total", "G_dprime"), r.value(g.phi, w, "total", "G_dprime_err")
            print(f"| {w / math.pi:g} pi | `{rule}` | {pm(a, e, 1)} | {pm(t[2], t[3], 1)} | "
                  f"{z(a, e, t[2], t[3]):+.1f} | {gk_steps * (mod.err[b, 0, k] / b1) ** 2:.3g} | "
                  f"{gk_steps * (mod.err[b, 1, k] / b2) ** 2:.3g} | {steps[key]:.3g} |")


def schaink(rest, study_csv, study_job, window, same_dt_csv=None):
    """Full SD at rest against the oscillatory study: G(t), eta_H, and per frequency, row
    and short-time rule G', G'' with the combined-error distance and the cost."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        reds = {rule: reduce_at_rest([rest], lag0=rule, window=window, omega=STUDY_OMEGA)
                for rule in RULES}
    study, steps = study_rows(study_csv), study_steps(study_job)
    red = reds["keep"]
    g = red.groups[0]
    n_real, gk_steps = int(g.relaxation.n_realisations[-1, 0]), int(red.committed.sum())
    print(f"## Full SD (`stokesian`), N = {red.job.system.n_particles}, phi = {g.phi:g}: "
          f"Green-Kubo ({rest}) against the oscillatory study ({study_csv})\n")
    print(f"At rest: {n_real} realisations, {gk_steps} steps committed (dt = {g.dt:g}), "
          f"window {g.max_lag * g.dt:.4g} t_D; tail of G over the window's last tenth "
          f"{g.tail[1]:.2f} ± {g.tail[2]:.2f} eta_m/t_D.\n")
    b = STREAMS.index("brownian")
    shown = [i for i, lag in enumerate(g.lags) if lag <= 5 or lag in (10, 20, 50)
             or lag == g.lags[np.argmin(np.abs(g.lags - 200))]
             or lag == g.lags[np.argmin(np.abs(g.lags - 1000))] or lag == g.lags[-1]]
    print("G_A(t) of the Brownian row as sampled (rule `keep`), eta_m/t_D:\n")
    print("| lag | " + " | ".join(str(g.lags[i]) for i in shown) + " |")
    print("|---" * (len(shown) + 1) + "|")
    print("| G | " + " | ".join(pm(g.relaxation.mean[b, i], g.relaxation.err[b, i], 1)
                                for i in shown) + " |\n")
    hyd = [v for k, v in study.items() if k[1] == "hydrodynamic"]
    weights = [1 / (v[3] / k) ** 2 for (k, c), v in study.items() if c == "hydrodynamic"]
    eta_study = sum(w_ * v[2] / k for w_, ((k, c), v) in
                    zip(weights, [(k, v) for k, v in study.items() if k[1] == "hydrodynamic"]))
    eta_study /= sum(weights)
    print(f"Hydrodynamic row: eta_H = eta'_inf - 1 from {g.hydro.frames} trajectory frames "
          f"at rest = {pm(g.hydro.eta_h, g.hydro.err, 3)}; the study's eta'_H, weighted mean "
          f"over its {len(hyd)} frequencies, {pm(eta_study, math.sqrt(1 / sum(weights)), 3)} "
          f"(difference {z(g.hydro.eta_h, g.hydro.err, eta_study, math.sqrt(1 / sum(weights))):+.1f} "
          f"combined standard errors).\n")
    print("Per frequency (eta_m/t_D): the study's rows, then Green-Kubo per short-time rule "
          "with, in brackets, z = (Green-Kubo - study)/combined standard error; "
          "configurational = brownian + interparticle + collision:\n")
    rows = ("brownian", "collision", "configurational")
    cols = [STREAMS.index("brownian"), STREAMS.index("collision"), -1]
    print("| omega | route | " + " | ".join(f"{r} G' | {r} G''" for r in rows) + " |")
    print("|---|---|" + "---|---|" * len(rows))
    for k, w in enumerate(STUDY_OMEGA):
        key = min({q[0] for q in study}, key=lambda q: abs(q - w))
        if not math.isclose(key, w, rel_tol=1e-6):
            continue  # a frequency the oscillatory table does not have
        ref = [study[(key, r)] for r in rows]
        print(f"| {w / math.pi:g} pi | study | " + " | ".join(
            f"{pm(v[0], v[1])} | {pm(v[2], v[3])}" for v in ref) + " |")
        for rule in RULES:
            mod = reds[rule].groups[0].moduli
            cells = []
            for c, v in zip(cols, ref):
                for q in (0, 1):
                    a, e = mod.mean[c, q, k], mod.err[c, q, k]
                    cells.append(f"{pm(a, e)} ({z(a, e, v[2 * q], v[2 * q + 1]):+.1f})")
            print(f"| | GK `{rule}` | " + " | ".join(cells) + " |")
    totals_and_cost(reds, g, study, steps, gk_steps)
    if same_dt_csv:
        same_dt(reds, g, same_dt_csv)
    print()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dilute")
    parser.add_argument("--rest")
    parser.add_argument("--osc", nargs="*", default=[])
    parser.add_argument("--rest2", help="a second run at rest (another model)")
    parser.add_argument("--osc2", nargs="*", default=[])
    parser.add_argument("--sd", help="a full-SD run at rest (sd27_rest.toml)")
    parser.add_argument("--study", help="the oscillatory study's moduli.csv")
    parser.add_argument("--study-job", help="the study's job file (for its steps)")
    parser.add_argument("--same-dt", help="an oscillatory moduli.csv at the run's dt")
    parser.add_argument("--sd-window", nargs="*", default=[None],
                        type=lambda x: None if x == "default" else float(x),
                        help="Green-Kubo windows (t_D) for --sd, 'default' the reducer's")
    args = parser.parse_args()
    if args.dilute:
        dilute(args.dilute)
    for rest, osc in ((args.rest, args.osc), (args.rest2, args.osc2)):
        if rest:
            phi03(rest, osc)
    if args.sd:
        for window in args.sd_window:
            schaink(args.sd, args.study, args.study_job, window, args.same_dt)


if __name__ == "__main__":
    main()
