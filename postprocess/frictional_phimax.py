#!/usr/bin/env python3
"""Frictional suspensions: phi_max per friction coefficient with honest intervals, and flow curves.

    postprocess/frictional_phimax.py RUN.h5 [RUN2.h5 ...] [-o OUTDIR] [--skip-phi PHI ...]

Input: steady-shear run files of jobs with interparticle.kind = "frictional"
(jobs/frictional_mu*.toml and the same jobs at other f_r0). Files are grouped by (mu,
k_n, k_t, f_r0, phi list); a group (e.g. the same job run with several seeds) is reduced
by sdmpi.analysis.reduce.reduce_runs: per realisation the mean total relative viscosity
after the start-up and its blocking error; per phi the mean over realisations with

    eta_err = max(err_between, err_within),

err_between = s/sqrt(R) the spread of the R realisation means (unbiased whatever the
correlations within a run, but with R - 1 degrees of freedom only: with R = 4 it comes
out below half its true value one time in seven) and err_within the propagated blocking
error of the runs (a floor against such a small spread; with one realisation it is the
only error). Then

* phi scan: for every (mu, k_n, k_t, f_r0) with at least two phi, a weighted
  least-squares fit of log eta_r to log of Krieger-Dougherty, (1 - phi/phi_max)^(-2.5
  phi_max) (sdmpi.analysis.analytic; the MigFlow thesis's model), and of Maron-Pierce, (1 -
  phi/phi_max)^(-2) (the divergence Mari et al. 2014 fit for phi_J), one parameter
  phi_max, weights 1/(eta_err/eta)^2. Its standard error phi_max_err is curve_fit's for
  these absolute weights, multiplied by sqrt(chi^2/dof) when that exceeds 1 (scatter
  beyond the errors, e.g. a model that does not fit, widens it; a fit better than its
  errors never narrows it). The 95% interval is phi_max +- t_{0.975, dof} phi_max_err,
  dof the smallest degrees of freedom of the fitted points' errors (R - 1; and at most
  n_phi - 1 when the error was scaled by chi^2/dof): the densest point dominates
  phi_max, and its error is as uncertain as its own R - 1 degrees of freedom allow. Measured on synthetic scans (4 phi, 4 realisations, 5-20%
  scatter; tests/test_postprocess_frictional.py) this covers the true phi_max 95-97% of
  the time (and +- t_{0.84, dof} phi_max_err 65-71%), where the plain +- 2 phi_max_err
  covered only 86-89%, and the 95% percentile interval of a bootstrap over the 4
  realisations only 61-66% (its spread is sqrt((R - 1)/R) of the sampling error, and
  coarse; so it is not used). Between friction coefficients the difference
  phi_max(mu_a) - phi_max(mu_b) gets the error sqrt(err_a^2 + err_b^2) (the runs at
  different mu are treated as independent; their shared starts, if anything, correlate
  them positively, which would make the true error smaller) and a 95% interval with the
  smaller dof.
  --skip-phi leaves volume fractions out of the fits (still tabulated and drawn);
* flow curves: for every (mu, phi) at several f_r0, eta_r against the stress
  sigma a^2/F_R0 = eta_r / (6 pi f_r0) and the rate 6 pi eta_m a^2 gamma_dot / F_R0 =
  1/f_r0 (Mari et al.'s units); thickening is eta_r rising with stress.

Writes OUTDIR/frictional_viscosity.csv (mu, k_n, k_t, f_r0, rate, phi, n_real, eta,
eta_err, eta_err_between, eta_err_within, dof, the contact springs' part eta_contact
(mean of samples/stress_contact after the start-up), contacts per particle z, sliding
fraction, stress), OUTDIR/frictional_phimax.csv (mu, k_n, k_t, f_r0, model, phi_max,
phi_max_err, dof, ci95_lo, ci95_hi, chi2_dof, n_phi), OUTDIR/frictional_phimax_diff.csv
(model, mu_a, mu_b, diff, diff_err, diff_ci95_lo, diff_ci95_hi, disjoint: whether the two
95% intervals are disjoint) and the plots phimax.png and flow_curves.png.
"""

import argparse
import csv
import math
import sys
import warnings
from pathlib import Path

import h5py
import numpy as np
from scipy.optimize import curve_fit

from sdmpi.analysis.analytic import krieger_dougherty, maron_pierce
from sdmpi.analysis.reduce import (TABLE_COMPONENTS, PartialRunWarning, ReduceError,
                                   confidence_half_width, open_run, reduce_runs)

MODELS = {"krieger-dougherty": krieger_dougherty, "maron-pierce": maron_pierce}
LINES = {"krieger-dougherty": "-", "maron-pierce": "--"}
COLUMNS = ("mu", "k_n", "k_t", "f_r0", "rate", "phi", "n_real", "eta", "eta_err", "eta_err_between",
           "eta_err_within", "dof", "eta_contact", "z", "sliding", "stress")
FIT_COLUMNS = ("mu", "k_n", "k_t", "f_r0", "model", "phi_max", "phi_max_err", "dof", "ci95_lo",
               "ci95_hi", "chi2_dof", "n_phi")
DIFF_COLUMNS = ("model", "mu_a", "mu_b", "diff", "diff_err", "diff_ci95_lo", "diff_ci95_hi",
                "disjoint")
TOTAL = TABLE_COMPONENTS.index("total")


def contact_means(path, task_ids, discard):
    """Means after the start-up over the tasks: eta_contact, contacts per particle, the
    sliding fraction of contacts."""
    eta, z, slide = [], [], []
    with h5py.File(path, "r") as f:
        for t in task_ids:
            s = f[f"tasks/{t:06d}/samples"]
            n = int(f["progress"][t])
            n_part = int(f[f"tasks/{t:06d}"].attrs["n_particles"])
            contacts = s["n_contacts"][discard:n].astype(float)
            eta.append(np.mean(s["stress_contact"][discard:n, 3] / s["rate"][discard:n]))
            z.append(2 * contacts.mean() / n_part)
            slide.append(s["n_sliding"][discard:n].sum() / max(contacts.sum(), 1))
    return float(np.mean(eta)), float(np.mean(z)), float(np.mean(slide))


def table(paths):
    """One row per (file group, phi): the columns COLUMNS."""
    groups = {}
    for path in paths:
        job = open_run(path).job
        inter = job.interparticle
        if inter.kind != "frictional" or job.shear.protocol != "steady":
            raise ReduceError(f"{path}: not a steady-shear frictional job")
        groups.setdefault((inter.mu, inter.k_n, inter.k_t, inter.f_r0, job.system.phi),
                          []).append(path)
    rows = []
    for (mu, k_n, k_t, f_r0, _), files in sorted(groups.items()):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PartialRunWarning)
            red = reduce_runs(files)
        for note in red.notes:
            print(f"note: {note}", file=sys.stderr)
        discard = red.job.integration.discard_steps
        ens, per_real = red.ensemble, red.per_realisation
        for g, phi in enumerate(red.phi):
            present = per_real.n[g, TOTAL, 0] > 0
            if not present.any():      # a partial run: nothing after the start-up yet
                continue
            between, within = ens.err_between[g, TOTAL, 0], ens.err_within[g, TOTAL, 0]
            parts = [contact_means(path, red.task_id[g][(red.file_index == k) & present],
                                   discard) for k, path in enumerate(files)
                     if np.any((red.file_index == k) & present)]
            eta_c, z, slide = np.mean(parts, axis=0)
            eta = float(ens.mean[g, TOTAL, 0])
            rows.append(dict(mu=mu, k_n=k_n, k_t=k_t, f_r0=f_r0, rate=1 / f_r0, phi=float(phi),
                             n_real=int(present.sum()), eta=eta,
                             eta_err=float(ens.err[g, TOTAL, 0]),
                             eta_err_between=float(between), eta_err_within=float(within),
                             dof=int(ens.dof_between[g, TOTAL, 0] if present.sum() >= 2
                                     else ens.dof[g, TOTAL, 0]), eta_contact=eta_c, z=z,
                             sliding=slide, stress=eta / (6 * math.pi * f_r0)))
    return rows


def fit_phi_max(phi, eta, err, model):
    """phi_max and its standard error from a weighted least-squares fit of log eta to
    log model(phi, phi_max), sigma = err/eta (absolute), the error widened by
    sqrt(chi^2/dof) when that exceeds 1 (module docstring)."""
    phi, eta = np.asarray(phi), np.asarray(eta)
    rel = np.asarray(err) / eta
    weighted = np.all(np.isfinite(rel)) and np.all(rel > 0)
    sigma = rel if weighted else None

    def log_model(x, phi_max):
        return np.log(model(x, max(phi_max, x.max() * (1 + 1e-9))))

    (best,), cov = curve_fit(log_model, phi, np.log(eta), p0=[min(0.64, 1.2 * phi.max())],
                             sigma=sigma, absolute_sigma=weighted,
                             bounds=(phi.max() * (1 + 1e-6), 1.0))
    scale = math.sqrt(max(1.0, chi2_dof(phi, eta, err, model, best))) if weighted else 1.0
    return float(best), float(scale * math.sqrt(cov[0, 0]))


def chi2_dof(phi, eta, err, model, phi_max):
    """chi^2 per degree of freedom of the log fit (nan for a single point)."""
    resid = (np.log(eta) - np.log(model(np.asarray(phi), phi_max))) * np.asarray(eta) / err
    return float(np.sum(resid ** 2) / (len(phi) - 1)) if len(phi) > 1 else math.nan


def phi_max_interval(phi, eta, err, dof, model):
    """phi_max, its standard error, dof and 95% interval (module docstring), chi^2/dof."""
    best, err_best = fit_phi_max(phi, eta, err, model)
    chi2 = chi2_dof(phi, eta, err, model, best)
    if chi2 > 1:                # the error was scaled by the fit's scatter: its dof
        dof = min(dof, len(phi) - 1)
    half = float(confidence_half_width(err_best, dof))
    return dict(phi_max=best, phi_max_err=err_best, dof=dof, ci95_lo=best - half,
                ci95_hi=best + half, chi2_dof=chi2)


def phi_scan_fits(rows, skip_phi):
    """Fits (FIT_COLUMNS) per (mu, k_n, k_t, f_r0) and model, and the differences
    (DIFF_COLUMNS) between the mu of the same (k_n, k_t, f_r0) and model."""
    scans = {}
    for r in rows:
        scans.setdefault((r["mu"], r["k_n"], r["k_t"], r["f_r0"]), []).append(r)
    fits = []
    for key, rs in sorted(scans.items()):
        rs = [r for r in rs if not any(math.isclose(r["phi"], x) for x in skip_phi)]
        if len(rs) < 2:
            continue
        phi, eta, err = (np.array([r[k] for r in rs]) for k in ("phi", "eta", "eta_err"))
        dof = min(r["dof"] for r in rs)
        for name, model in MODELS.items():
            fits.append(dict(zip(("mu", "k_n", "k_t", "f_r0"), key), model=name, n_phi=len(rs),
                             **phi_max_interval(phi, eta, err, dof, model)))
    diffs = []
    for a in fits:
        for b in fits:
            if a["mu"] < b["mu"] and all(a[k] == b[k] for k in ("k_n", "k_t", "f_r0", "model")):
                d, e = a["phi_max"] - b["phi_max"], math.hypot(a["phi_max_err"], b["phi_max_err"])
                half = float(confidence_half_width(e, min(a["dof"], b["dof"])))
                disjoint = a["ci95_lo"] > b["ci95_hi"] or b["ci95_lo"] > a["ci95_hi"]
                diffs.append(dict(model=a["model"], mu_a=a["mu"], mu_b=b["mu"], diff=d, diff_err=e,
                                  diff_ci95_lo=d - half, diff_ci95_hi=d + half, disjoint=disjoint))
    return scans, fits, diffs


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    p.add_argument("runs", nargs="+", metavar="RUN.h5", help="frictional steady-shear run files")
    p.add_argument("-o", "--output", default="frictional", metavar="OUTDIR",
                   help="output directory (default frictional)")
    p.add_argument("--skip-phi", type=float, nargs="+", default=[], metavar="PHI",
                   help="volume fractions left out of the fits (default: none)")
    args = p.parse_args(argv)
    try:
        rows = table(args.runs)
    except ReduceError as err:
        sys.exit(f"error: {err}")
    outdir = Path(args.output)
    outdir.mkdir(parents=True, exist_ok=True)
    _write(outdir / "frictional_viscosity.csv", COLUMNS, rows)
    print(f"{'mu':>5} {'k_n':>6} {'f_r0':>6} {'phi':>5} {'R':>2} {'eta_r':>15} {'between':>7} "
          f"{'within':>6} {'eta_contact':>11} {'z':>5} {'sliding':>7} {'sigma a^2/F_R0':>14}")
    for r in rows:
        print(f"{r['mu']:5g} {r['k_n']:6g} {r['f_r0']:6g} {r['phi']:5g} {r['n_real']:2d} "
              f"{r['eta']:8.2f} ± {r['eta_err']:4.2f} {r['eta_err_between']:7.2f} "
              f"{r['eta_err_within']:6.2f} {r['eta_contact']:11.2f} {r['z']:5.2f} "
              f"{r['sliding']:7.2f} {r['stress']:14.4g}")

    scans, fits, diffs = phi_scan_fits(rows, args.skip_phi)
    _write(outdir / "frictional_phimax.csv", FIT_COLUMNS, fits)
    _write(outdir / "frictional_phimax_diff.csv", DIFF_COLUMNS, diffs)
    for fit in fits:
        print(f"mu = {fit['mu']:g}, k_n = {fit['k_n']:g}, k_t = {fit['k_t']:g}, f_r0 = "
              f"{fit['f_r0']:g}: {fit['model']} phi_max = {fit['phi_max']:.3f} ± "
              f"{fit['phi_max_err']:.3f}, 95% [{fit['ci95_lo']:.3f}, {fit['ci95_hi']:.3f}] "
              f"(dof {fit['dof']}, chi2/dof {fit['chi2_dof']:.2f}, {fit['n_phi']} phi)")
    for d in diffs:
        print(f"{d['model']}: phi_max(mu = {d['mu_a']:g}) - phi_max(mu = {d['mu_b']:g}) = "
              f"{d['diff']:.3f} ± {d['diff_err']:.3f}, 95% [{d['diff_ci95_lo']:.3f}, "
              f"{d['diff_ci95_hi']:.3f}]; 95% intervals "
              f"{'disjoint' if d['disjoint'] else 'overlap'}")
    _plot_scans(scans, fits, outdir / "phimax.png")
    _plot_flow(rows, outdir / "flow_curves.png")


def _write(path, columns, rows):
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(columns)
        for row in rows:
            out.writerow([row[c] for c in columns])
    print(f"wrote {path}")


def _plot_scans(scans, fits, path):
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.subplots()
    for k, ((mu, k_n, k_t, f_r0), rs) in enumerate(sorted(scans.items())):
        if len(rs) < 2:
            continue
        colour = f"C{k}"
        phi = np.array([r["phi"] for r in rs])
        ax.errorbar(phi, [r["eta"] for r in rs], yerr=[r["eta_err"] for r in rs], fmt="o",
                    color=colour, capsize=3, label=f"μ = {mu:g}, k_n = {k_n:g}, rate = {1 / f_r0:g}")
        for fit in fits:
            if (fit["mu"], fit["k_n"], fit["k_t"], fit["f_r0"]) != (mu, k_n, k_t, f_r0):
                continue
            x = np.linspace(0.0, min(phi.max(), 0.995 * fit["phi_max"]), 100)
            ax.plot(x, MODELS[fit["model"]](x, fit["phi_max"]), LINES[fit["model"]], color=colour,
                    label=f"{fit['model']} φ_max = {fit['phi_max']:.3f} "
                          f"± {fit['phi_max_err']:.3f}")
    ax.set_yscale("log")
    _finish(fig, ax, "φ", 7, path)


def _plot_flow(rows, path):
    curves = {}
    for r in rows:
        curves.setdefault((r["mu"], r["phi"]), []).append(r)
    curves = {k: sorted(v, key=lambda r: r["stress"]) for k, v in curves.items() if len(v) > 1}
    if not curves:
        return
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.subplots()
    for (mu, phi), rs in sorted(curves.items()):
        ax.errorbar([r["stress"] for r in rs], [r["eta"] for r in rs],
                    yerr=[r["eta_err"] for r in rs], fmt="o-", capsize=3,
                    label=f"μ = {mu:g}, φ = {phi:g}")
    ax.set_xscale("log")
    _finish(fig, ax, "σ a² / F_R0 = η_r / (6π f_r0)", 8, path)


def _finish(fig, ax, xlabel, fontsize, path):
    ax.set_xlabel(xlabel)
    ax.set_ylabel("η_r")
    ax.legend(fontsize=fontsize)
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
