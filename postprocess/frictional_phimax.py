#!/usr/bin/env python3
"""Frictional suspensions: Krieger-Dougherty phi_max per friction coefficient, and flow curves.

    postprocess/frictional_phimax.py RUN.h5 [RUN2.h5 ...] [-o OUTDIR] [--skip-phi PHI ...]

Input: steady-shear run files of jobs with interparticle.kind = "frictional"
(jobs/frictional_mu*.toml and the same jobs at other f_r0). Files are grouped by (mu,
f_r0); each is reduced by sdmpi.analysis.reduce.reduce_runs (total relative viscosity,
one standard error from blocking and realisations). Then

* phi scan: for every (mu, f_r0) with at least two phi, a weighted least-squares fit of
  Krieger-Dougherty, eta_r = (1 - phi/phi_max)^(-2.5 phi_max) (sdmpi.analysis.models;
  the seed's model), and of Maron-Pierce, (1 - phi/phi_max)^(-2) (the divergence Mari et
  al. 2014 fit for phi_J), in log eta_r, one parameter phi_max with its standard error
  (curve_fit covariance, errors scaled to the fit's scatter); --skip-phi leaves those
  volume fractions out of the fits (e.g. points still in their start-up transient; they
  are still tabulated and drawn);
* flow curves: for every (mu, phi) at several f_r0, eta_r against the stress
  sigma a^2/F_R0 = eta_r / (6 pi f_r0) and the rate 6 pi eta_m a^2 gamma_dot / F_R0 =
  1/f_r0 (Mari et al.'s units); thickening is eta_r rising with stress.

Writes OUTDIR/frictional_viscosity.csv (mu, f_r0, rate, phi, eta, eta_err, the contact
springs' part eta_contact (mean of samples/stress_contact after the start-up), contacts
per particle z, sliding fraction, stress), OUTDIR/frictional_phimax.csv (mu, f_r0, model,
phi_max, phi_max_err, n_phi) and the plots phimax.png and flow_curves.png.
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

from sdmpi.analysis.models import krieger_dougherty, maron_pierce
from sdmpi.analysis.reduce import PartialRunWarning, ReduceError, open_run, reduce_runs

MODELS = {"krieger-dougherty": krieger_dougherty, "maron-pierce": maron_pierce}
COLUMNS = ("mu", "k_n", "k_t", "f_r0", "rate", "phi", "eta", "eta_err", "eta_contact", "z", "sliding",
           "stress")


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
        for g, phi in enumerate(red.phi):
            total = next(r for r in red.rows() if r["component"] == "total"
                         and math.isclose(r["phi"], phi))
            parts = [contact_means(path, red.task_id[g][red.file_index == k], discard)
                     for k, path in enumerate(files)]
            eta_c, z, slide = np.mean(parts, axis=0)
            rows.append(dict(mu=mu, k_n=k_n, k_t=k_t, f_r0=f_r0, rate=1 / f_r0, phi=float(phi),
                             eta=total["eta"], eta_err=total["eta_err"], eta_contact=eta_c,
                             z=z, sliding=slide,
                             stress=total["eta"] / (6 * math.pi * f_r0)))
    return rows


def fit_phi_max(phi, eta, err, model):
    """phi_max and its standard error of a fit of log eta to log model(phi, phi_max)."""
    phi, eta = np.asarray(phi), np.asarray(eta)
    rel = np.asarray(err) / eta
    sigma = rel if np.all(np.isfinite(rel)) and np.all(rel > 0) else None

    def log_model(x, phi_max):
        return np.log(model(x, max(phi_max, x.max() * (1 + 1e-9))))

    (best,), cov = curve_fit(log_model, phi, np.log(eta), p0=[min(0.64, 1.2 * phi.max())],
                             sigma=sigma, bounds=(phi.max() * (1 + 1e-6), 1.0))
    return float(best), float(math.sqrt(cov[0, 0]))


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
    print(f"{'mu':>5} {'k_n':>6} {'f_r0':>6} {'phi':>5} {'eta_r':>15} {'eta_contact':>11} {'z':>5} "
          f"{'sliding':>7} {'sigma a^2/F_R0':>14}")
    for r in rows:
        print(f"{r['mu']:5g} {r['k_n']:6g} {r['f_r0']:6g} {r['phi']:5g} "
              f"{r['eta']:8.2f} ± {r['eta_err']:4.2f} "
              f"{r['eta_contact']:11.2f} {r['z']:5.2f} {r['sliding']:7.2f} {r['stress']:14.4g}")

    scans = {}
    for r in rows:
        scans.setdefault((r["mu"], r["k_n"], r["k_t"], r["f_r0"]), []).append(r)
    fits = []
    for (mu, k_n, k_t, f_r0), rs in sorted(scans.items()):
        rs = [r for r in rs if not any(math.isclose(r["phi"], x) for x in args.skip_phi)]
        if len(rs) < 2:
            continue
        phi, eta, err = (np.array([r[k] for r in rs]) for k in ("phi", "eta", "eta_err"))
        for name, model in MODELS.items():
            best, err_best = fit_phi_max(phi, eta, err, model)
            fits.append(dict(mu=mu, k_n=k_n, k_t=k_t, f_r0=f_r0, model=name, phi_max=best,
                             phi_max_err=err_best, n_phi=len(rs)))
    _write(outdir / "frictional_phimax.csv", ("mu", "k_n", "k_t", "f_r0", "model", "phi_max", "phi_max_err",
                                              "n_phi"), fits)
    for fit in fits:
        print(f"mu = {fit['mu']:g}, k_n = {fit['k_n']:g}, k_t = {fit['k_t']:g}, f_r0 = "
              f"{fit['f_r0']:g}: {fit['model']} phi_max = "
              f"{fit['phi_max']:.3f} ± {fit['phi_max_err']:.3f} ({fit['n_phi']} phi)")
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
        fit = next((f for f in fits if (f["mu"], f["k_n"], f["k_t"], f["f_r0"]) == (mu, k_n, k_t, f_r0)
                    and f["model"] == "krieger-dougherty"), None)
        if fit is None:
            continue
        x = np.linspace(0.0, min(phi.max(), 0.995 * fit["phi_max"]), 100)
        ax.plot(x, krieger_dougherty(x, fit["phi_max"]), "-", color=colour,
                label=f"Krieger-Dougherty φ_max = {fit['phi_max']:.3f}")
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
