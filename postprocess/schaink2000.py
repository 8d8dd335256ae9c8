#!/usr/bin/env python3
"""Reproduce Schaink et al., J. Rheol. 44 (2000): run files -> every table and figure.

    postprocess/schaink2000.py --newtonian RUN.h5... [--phi-scan RUN.h5...]
        [--fixed-dt RUN.h5...] [--maxwell-lambda 0.5] [-o docs/validation/schaink2000]

Inputs (run files of `sdmpi run`; complete or partial: whatever is committed is used):

* ``--newtonian``: the Newtonian frequency scan (jobs/schaink2000_newtonian.toml; several
  files of the same job with different seeds are reduced together);
* ``--phi-scan``: the volume-fraction scan of the paper's Fig. 2 (one job whose
  system.phi lists the fractions);
* ``--fixed-dt``: the same system at (a few of) the scan's frequencies with one time
  step for all (e.g. the Newtonian job with ``--set integration.dt_max=5e-5 --set
  integration.steps_per_period=3``), which tells frequency and time-step effects apart.

The Maxwell-medium study (the paper's Fig. 8) needs no run: a Maxwell medium leaves the
trajectories unchanged and only filters the hydrodynamic stress (their eq. 32, eqs.
33-35), so it is the Newtonian scan reduced with one mode eta = 1, lambda =
``--maxwell-lambda`` applied after the fact (sdmpi.analysis.medium_view; ``sdmpi reduce
--medium``).

Outputs in OUTDIR (each written whole or not at all):

* ``newtonian/``, ``maxwell/``, ``phi_scan/``, ``fixed_dt/``: what ``sdmpi reduce``
  writes (moduli.csv, errors.csv, units.json, moduli.h5, its figures, among them the
  eta' components per contribution, viscosity_phi*.png);
* ``moduli.png`` (G', G'' vs omega; the paper's Fig. 4), ``omega_half.png`` (eta', eta''
  vs omega^-1/2; Fig. 5), ``eta_components.png`` (eta_H and eta vs omega against eq. 38;
  Fig. 7), ``maxwell.png`` (eta_m + eta_H of the Maxwell medium against eq. 41 built
  from our Newtonian eta_H(0) and from eq. 38; Fig. 8), ``phi_scan.png`` (eta' vs phi,
  eqs. 37, 38; Fig. 2), ``fixed_dt.png`` (eta'_H vs omega, scan and fixed dt);
* ``comparison.md``: the inputs, then the paper's statements one by one with our
  numbers and one-standard-error bars next to them and whether they are reproduced
  (:func:`statements`).

The tables and comparison.md are byte-identical when the same run files are processed
again. Units: omega in 1/t_D, moduli in eta_m/t_D, viscosities relative to eta_m.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fig2_viscosity_vs_phi  # noqa: E402
import fig4_moduli  # noqa: E402
import fig5_omega_half  # noqa: E402
import fig7_newtonian_viscosity  # noqa: E402
import fig8_maxwell_viscosity  # noqa: E402
from schaink_common import figure, p_value, pm, save, series  # noqa: E402

from sdmpi.analysis.analytic import maxwell_eta_h, maxwell_viscosity, schaink_eta_h  # noqa: E402
from sdmpi.analysis.reduce import PartialRunWarning, ReduceError, reduce_runs  # noqa: E402
from sdmpi.analysis.report import write_all  # noqa: E402
from sdmpi.config import Medium, Mode  # noqa: E402

#: the frequency above which the paper finds a plateau of G' (1/t_D)
PLATEAU_FROM = 8 * math.pi
#: a fit is acceptable when its chi^2 is below this upper-tail probability
P_FIT = 0.01
#: "within errors": within this many standard errors
Z = 2.0


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    p.add_argument("--newtonian", nargs="+", required=True, metavar="RUN.h5",
                   help="run files of the Newtonian frequency scan")
    p.add_argument("--phi-scan", nargs="+", default=[], metavar="RUN.h5",
                   help="run files of the volume-fraction scan (Fig. 2)")
    p.add_argument("--fixed-dt", nargs="+", default=[], metavar="RUN.h5",
                   help="run files of the fixed-time-step control")
    p.add_argument("--maxwell-lambda", type=float, default=0.5, metavar="LAMBDA",
                   help="relaxation time of the one-mode Maxwell medium [t_D] (default 0.5, "
                        "the paper's)")
    p.add_argument("-o", "--output", default="docs/validation/schaink2000", metavar="OUTDIR",
                   help="output directory (default docs/validation/schaink2000)")
    return p.parse_args(argv)


def reduce(paths, medium=None):
    """One reduction of the files (one system, oscillatory shear)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        red = reduce_runs(paths, medium=medium)
    if red.kind != "oscillatory":
        raise ReduceError(f"{paths[0]}: not an oscillatory-shear run")
    return red


def main(argv=None):
    args = parse_args(argv)
    out = Path(args.output)
    try:
        newt = reduce(args.newtonian)
        if newt.job.medium.kind != "newtonian":
            raise ReduceError(f"--newtonian {args.newtonian[0]}: its medium is "
                              f"{newt.job.medium.kind}")
        maxw = reduce(args.newtonian, Medium("maxwell", (Mode(1.0, args.maxwell_lambda),)))
        phi = reduce(args.phi_scan) if args.phi_scan else None
        fixed = reduce(args.fixed_dt) if args.fixed_dt else None
        for name, red in (("newtonian", newt), ("maxwell", maxw), ("phi_scan", phi),
                          ("fixed_dt", fixed)):
            if red is not None:
                paths, notes = write_all(red, out / name)
                for note in red.notes + tuple(notes):
                    print(f"note: {name}: {note}", file=sys.stderr)
                print(f"wrote {out / name}/ ({', '.join(p.name for p in paths)})")
    except ReduceError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    fig4_moduli.draw([newt], out / "moduli.png")
    fig5_omega_half.draw([newt], out / "omega_half.png")
    fig7_newtonian_viscosity.draw([newt], out / "eta_components.png")
    fig8_maxwell_viscosity.draw([maxw], [newt], out / "maxwell.png")
    if phi is not None:
        fig2_viscosity_vs_phi.draw([phi], out / "phi_scan.png")
    if fixed is not None:
        draw_fixed_dt(newt, fixed, out / "fixed_dt.png")
    text = comparison(newt, maxw, phi, fixed)
    (out / "comparison.md").write_text(text)
    print(f"wrote {out / 'comparison.md'}")
    return 0


# --------------------------------------------------------------------------- statements


def constant_fit(values, errors):
    """Weighted mean, its standard error, chi^2/dof and dof of a constant fitted to the
    finite values with positive errors."""
    ok = np.isfinite(values) & np.isfinite(errors) & (errors > 0)
    if not ok.any():
        return math.nan, math.nan, math.nan, 0
    w = 1 / errors[ok] ** 2
    mean = float(np.sum(w * values[ok]) / w.sum())
    dof = int(ok.sum()) - 1
    chi2 = float(np.sum(w * (values[ok] - mean) ** 2) / dof) if dof else math.nan
    return mean, float(w.sum() ** -0.5), chi2, dof


def verdict(ok, undetermined=False) -> str:
    return "undetermined" if undetermined else ("reproduced" if ok else "NOT reproduced")


#: a trend is resolved when Z standard errors of its slope are below this (a change of
#: d(value)/d ln omega = 0.25, e.g. G' growing as omega^0.25, would then be seen)
RESOLVED = 0.25


def trend(slope, err, undetermined, want) -> str:
    """Verdict on a slope: ``want`` "flat" (a plateau) or "falls"; "not resolved" when
    its error is too large to tell (:data:`RESOLVED`)."""
    if undetermined or not np.isfinite(err):
        return "undetermined"
    if want == "flat":
        if abs(slope) >= Z * err:
            return "NOT reproduced (" + ("still grows)" if slope > 0 else "falls)")
        return "reproduced" if Z * err < RESOLVED else "not resolved (errors too large)"
    if slope <= -Z * err:
        return "reproduced"
    return "NOT reproduced (rises)" if slope >= Z * err else "not resolved (errors too large)"


def statements(newt, maxw, phi_red, fixed):
    """The paper's statements, each (statement, the paper's words, ours, verdict)."""
    phi = float(newt.phi[0])
    rows = []
    w, g1, e1 = series(newt, phi, "total", "G_prime")
    hi = (w > PLATEAU_FROM * (1 + 1e-9)) & (g1 > 0)      # the paper's "omega > 8 pi"; a log needs G' > 0
    _, slope, slope_err, _ = fig5_omega_half.line_fit(np.log(w[hi]), np.log(g1[hi]),
                                                      e1[hi] / np.abs(g1[hi]))
    few = hi.sum() < 2 or not np.isfinite(slope_err)
    plateau, plateau_err, chi2, dof = constant_fit(g1[hi], e1[hi])
    at = np.isclose(w, PLATEAU_FROM, rtol=1e-9)
    below = ""
    if at.any() and np.isfinite(plateau):
        g8, e8 = float(g1[at][0]), float(e1[at][0])
        ratio, ratio_err = g8 / plateau, abs(g8 / plateau) * math.hypot(e8 / g8, plateau_err / plateau)
        below = f"; at 8 pi {pm(g8, e8)}, G'(8 pi)/plateau = {pm(ratio, ratio_err)}"
    rows.append((
        "G' plateau above 8 pi (Fig. 4)",
        "G' attains a plateau value for omega > 8 pi",
        "G' (total) at omega/pi = " + ", ".join(f"{x / math.pi:.3g}: {pm(a, b)}"
                                                for x, a, b in zip(w[hi], g1[hi], e1[hi]))
        + f"; d ln G'/d ln omega = {pm(slope, slope_err)}; plateau (weighted mean) "
        f"{pm(plateau, plateau_err)}, chi2/dof of a constant {chi2:.3g} (dof {dof}, p = "
        f"{p_value(chi2, dof):.3g})" + below,
        trend(slope, slope_err, few, want="flat")))

    wh, h, he = series(newt, phi, "hydrodynamic", "eta_prime")
    mean, mean_err, chi2, dof = constant_fit(h, he)
    spread = float(np.nanmax(np.abs(h / mean - 1))) if np.isfinite(mean) else math.nan
    p = p_value(chi2, dof)
    rows.append((
        "eta'_H independent of omega (Fig. 7)",
        "eta'_H independent of frequency within 2%",
        f"weighted mean {pm(mean, mean_err)}; largest deviation of a frequency "
        f"{100 * spread:.1f}%; chi2/dof of a constant {chi2:.3g} (dof {dof}, p = {p:.3g})",
        verdict(spread <= 0.02 or p > P_FIT, dof < 1)))

    eq38 = float(schaink_eta_h(phi))
    rows.append((
        "eta_H against eq. 38 (Fig. 7)",
        f"eq. 38 gives the SD eta_H within 1%: eta_H({phi:g}) = {eq38:.4g}",
        f"ours {pm(mean, mean_err)}: {100 * (mean / eq38 - 1):+.1f}% "
        f"({(mean - eq38) / mean_err:+.1f} standard errors)",
        verdict(abs(mean / eq38 - 1) <= 0.01 or abs(mean - eq38) < Z * mean_err,
                not np.isfinite(mean))))

    wb, b, be = series(newt, phi, "brownian", "eta_prime")
    _, bslope, bslope_err, _ = fig5_omega_half.line_fit(np.log(wb), b, be)
    rows.append((
        "Brownian part falls with omega (Figs. 4, 7)",
        "the Brownian contribution decreases with frequency",
        "eta'_B at omega/pi = " + ", ".join(f"{x / math.pi:.3g}: {pm(a, e)}"
                                            for x, a, e in zip(wb, b, be))
        + f"; d eta'_B/d ln omega = {pm(bslope, bslope_err)}",
        trend(bslope, bslope_err, not np.isfinite(bslope_err), want="falls")))

    fits = []
    for column, name in (("eta_prime", "eta'"), ("eta_dprime", "eta''")):
        x, v, e = series(newt, phi, "total", column)
        a, slope5, slope5_err, c2 = fig5_omega_half.line_fit(x ** -0.5, v, e)
        fits.append((name, a, slope5, slope5_err, c2, int(np.isfinite(v).sum()) - 2))
    (_, *_, c2_2, dof2) = fits[1]
    rows.append((
        "eta', eta'' against omega^-1/2 (Fig. 5)",
        "eta'' linear in omega^-1/2, as in experiments; eta' levels off at high omega",
        "; ".join(f"{n} = {a:.4g} + ({pm(s, se)}) omega^-1/2, chi2/dof {c:.3g} (dof {d})"
                  for n, a, s, se, c, d in fits),
        verdict(p_value(c2_2, dof2) > P_FIT, dof2 < 1)
        + ("" if dof2 < 1 else " (eta'' linear: chi2 p > 0.01)" if p_value(c2_2, dof2) > P_FIT
           else " (eta'' not linear)")))

    own = fig8_maxwell_viscosity.newtonian_eta_h([newt], phi)
    modes = maxw.job.medium.modes
    eta, lam = [m.eta for m in modes], [m.lam for m in modes]
    for label, eta_h0 in (("our Newtonian eta_H(0)", None if own is None else own[0]),
                          ("eq. 38", eq38)):
        z = []
        for q, column in enumerate(("eta_prime", "eta_dprime")):
            wm, hm, hme = series(maxw, phi, "hydrodynamic", column)
            if eta_h0 is not None:
                pred = maxwell_eta_h(wm, eta_h0 / sum(eta), eta, lam)[q]
                z.append((hm - pred) / hme)
        z = np.concatenate(z) if z else np.array([np.nan])
        zok = z[np.isfinite(z)]
        c2 = float(np.mean(zok ** 2)) if zok.size else math.nan
        rows.append((
            f"Maxwell medium: eta_H against eq. 41 from {label} (Fig. 8)",
            "eqs. 41-42 describe the hydrodynamic part in a Maxwell medium (lambda = "
            f"{lam[0]:g} t_D) very well",
            (f"eta_H(0) = {pm(*own)}; " if label.startswith("our") and own else "")
            + f"eta'_H, eta''_H at {zok.size // 2} frequencies: largest deviation "
            f"{np.max(np.abs(zok)) if zok.size else math.nan:.2f} standard errors, "
            f"chi2/point {c2:.3g}",
            verdict(p_value(c2, zok.size) > P_FIT, zok.size == 0)))

    diffs = []
    for red in (newt, maxw):
        wm, m1, e1m = series(red, phi, "medium", "eta_prime")
        _, m2, e2m = series(red, phi, "medium", "eta_dprime")
        if red.job.medium.kind == "maxwell":
            ref1, ref2 = maxwell_viscosity(wm, eta, lam)
        else:
            ref1, ref2 = np.ones_like(wm), np.zeros_like(wm)
        diffs.append(max(np.max(np.abs(m1 - ref1)), np.max(np.abs(m2 - ref2)),
                         np.max(e1m), np.max(e2m)))
    rows.append((
        "medium rows exact (eq. 36)",
        "the medium's eta*_m(omega) is analytic (eq. 36)",
        f"largest deviation of a medium row from eq. 36, or medium error: Newtonian "
        f"{diffs[0]:.2g}, Maxwell {diffs[1]:.2g}",
        verdict(max(diffs) <= 1e-12)))

    if phi_red is not None:
        parts, worst = [], 0.0
        for p_ in sorted(set(phi_red.phi.tolist())):
            wp, hp, hpe = series(phi_red, p_, "hydrodynamic", "eta_prime")
            ref = float(schaink_eta_h(p_))
            z_ = (hp[0] - ref) / hpe[0]
            worst = max(worst, abs(z_)) if np.isfinite(z_) else worst
            parts.append(f"phi {p_:g}: {pm(hp[0], hpe[0])} vs {ref:.4g} ({z_:+.1f} s.e.)")
        rows.append((
            "eta_H(phi) against eq. 38 (Fig. 2)",
            "eq. 38 fits the SD eta_H within 1% for 0 <= phi <= 0.45",
            f"at omega = {phi_red.control[0]:.4g}: " + "; ".join(parts),
            verdict(worst < Z, not parts)))

    if fixed is not None:
        parts, worst = [], 0.0
        for wf, hf, hfe in zip(*series(fixed, phi, "hydrodynamic", "eta_prime")):
            i = np.flatnonzero(np.isclose(wh, wf, rtol=1e-9))
            if not i.size:
                continue
            d, de = hf - h[i[0]], math.hypot(hfe, he[i[0]])
            worst = max(worst, abs(d / de)) if np.isfinite(d / de) else worst
            parts.append(f"omega/pi {wf / math.pi:.3g}: dt {fixed.job.time_step(wf):.3g} vs "
                         f"{newt.job.time_step(wf):.3g}: eta'_H {pm(hf, hfe)} vs "
                         f"{pm(h[i[0]], he[i[0]])}, difference {pm(d, de)}")
        rows.append((
            "time-step control (not in the paper)",
            "(the paper lowers dt with omega; a fixed-dt run separates the two effects)",
            "; ".join(parts) or "no frequency in common with the scan",
            ("no time-step effect within errors" if parts and worst < Z else
             "eta'_H depends on dt" if parts else "undetermined")))
    return rows


def describe_inputs(name, red) -> list[str]:
    """Markdown lines on one reduction's inputs."""
    job = red.job
    steps = int(red.n_steps.sum())
    n = sorted({int(k) for k in red.ensemble.n_realisations[:, 1, 0]})
    omegas = sorted(set(red.control.tolist()))
    line = (f"- **{name}**: job `{job.job.name}`, files "
            + ", ".join(f"`{Path(f).name}`" for f in red.files)
            + f" (seeds {', '.join(map(str, red.seeds))}); N = {job.system.n_particles}, "
            f"phi = {', '.join(f'{p:g}' for p in sorted(set(red.phi.tolist())))}, "
            f"omega/pi = {', '.join(f'{w / math.pi:.3g}' for w in omegas)}; "
            "periods (discarded) " + ", ".join(f"{job.periods(w)} ({job.discarded_periods(w)})"
                                               for w in omegas) + ", "
            f"dt = {', '.join(f'{job.time_step(w):.3g}' for w in omegas)}; "
            f"realisations per (phi, omega) {'/'.join(map(str, n))}; "
            f"{int(red.committed.sum())}/{steps} steps committed"
            + ("" if red.complete else " (PARTIAL)"))
    return [line]


def comparison(newt, maxw, phi_red, fixed) -> str:
    """comparison.md: inputs and the statement-by-statement table."""
    lines = ["# Schaink et al. (2000): the paper's statements and ours", "",
             "Written by `postprocess/schaink2000.py`; tables in `newtonian/`, `maxwell/`, "
             "`phi_scan/`, `fixed_dt/` (`moduli.csv` as written by `sdmpi reduce`; "
             "`errors.csv` says where each error comes from). Errors are one standard "
             "error; omega in 1/t_D, viscosities relative to eta_m.", "", "## Inputs", ""]
    for name, red in (("Newtonian scan", newt), ("phi scan", phi_red),
                      ("fixed-dt control", fixed)):
        if red is not None:
            lines += describe_inputs(name, red)
    modes = maxw.job.medium.modes
    lines += [f"- **Maxwell medium**: the Newtonian scan with the mode eta = {modes[0].eta:g}, "
              f"lambda = {modes[0].lam:g} t_D applied to its hydrodynamic stress "
              f"(`sdmpi reduce --medium maxwell:eta={modes[0].eta:g},lambda={modes[0].lam:g}`)",
              "", "## Statements", "",
              "| statement | the paper | ours | verdict |", "|---|---|---|---|"]
    for row in statements(newt, maxw, phi_red, fixed):
        lines.append("| " + " | ".join(str(c).replace("|", "/") for c in row) + " |")
    return "\n".join(lines) + "\n"


def draw_fixed_dt(newt, fixed, path):
    """eta'_H vs omega of the scan (dt falling with omega) and of the fixed-dt control."""
    fig, (ax,) = figure()
    phi = float(newt.phi[0])
    for red, fmt, label in ((newt, "o", "scan (dt falls with ω)"),
                            (fixed, "s", "fixed dt = "
                             + ", ".join(sorted({f"{fixed.job.time_step(w):.3g}"
                                                 for w in fixed.control})))):
        w, h, e = series(red, phi, "hydrodynamic", "eta_prime")
        ax.errorbar(w, h, yerr=e, fmt=fmt, mfc="none", capsize=3, label=label)
    ax.axhline(schaink_eta_h(phi), ls="--", color="0.4", label="Schaink et al. eq. 38")
    ax.set_xscale("log")
    ax.set_xlabel("ω  [1/t_D]")
    ax.set_ylabel("η′_H / η_m")
    ax.set_title(f"time-step control: φ = {phi:g}; bars ± one standard error", fontsize=9)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8)
    save(fig, path)


if __name__ == "__main__":
    sys.exit(main())
