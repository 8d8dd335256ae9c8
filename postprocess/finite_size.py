#!/usr/bin/env python3
"""The finite-size study: the Schaink et al. (2000) moduli against the number of spheres.

    postprocess/finite_size.py --runs N64.h5 N125.h5 ... [--control DT.h5]
        [--reference docs/validation/schaink2000/newtonian/moduli.csv]
        [--eta-inf bench/eta_inf.json] [-o docs/validation/finite_size]

Inputs: run files of `sdmpi run` (complete or partial: whatever is committed is used) of
the same system (phi = 0.45, gamma0 = 0.02, Brownian hard spheres, Newtonian medium) at
one N each (jobs/finite_size_n*.toml, one time step dt = 5e-4 t_D at every frequency);
``--reference``: the committed N = 27 frequency scan (moduli.csv as `sdmpi reduce` writes
it, from `make schaink2000`; dt = 5e-4 ... 5e-5 t_D, 500 steps per period), the time-step
reference, and the N = 27 point of the fits when no run file has N = 27; ``--control``:
the time-step control (jobs/finite_size_dt_control.toml: N = 27 at 80 pi with dt = 5e-4,
as long as the reference); ``--eta-inf``: the equilibrium high-frequency viscosity
eta'_inf(N) (bench/eta_inf.json), the anchor for eta'_H = eta'_inf - 1. Sizes whose run
files are gone enter by their reduced tables (``--tables N=MODULI.csv``, e.g. the
committed ``N64/moduli.csv``), and the control by its table likewise.

Outputs in OUTDIR:

* ``N<n>/``: what `sdmpi reduce` writes for each run file, and ``N<n>/maxwell/`` the same
  run reduced for a Maxwell medium (eta = 1, lambda = 0.5 t_D; Schaink et al. eqs. 32-35),
  with ``N<n>/maxwell.png``: its hydrodynamic viscosity against eq. 41 built from that
  N's own eta_H(0) (postprocess/fig8_maxwell_viscosity.py);
* ``dt_control/``: the control reduced;
* ``quantities.csv``: per N, each quantity with one standard error (:data:`QUANTITIES`);
* ``extrapolation.csv``: per quantity and variable x (column ``in``: 1/L, L the box side
  in radii, or 1/N), the weighted fit Q(N) = Q_inf + c x over the sizes that have it, Q_inf
  and c with standard errors, chi^2 per degree of freedom, the degrees of freedom, p: the
  probability of a chi^2 at least as large if Q were linear in x with these errors, and
  N_within: the N from which |c| x is below the error of Q_inf;
* ``moduli.png`` (G', G'' against omega, every N), ``viscosities.png`` (eta', eta''),
  ``size.png`` (each quantity against 1/L with both fits);
* ``summary.md``: the numbers above as text, the eta'_H check, and the time-step controls
  (the control and an N = 27 run against the reference, frequency by frequency).

The two forms are empirical here: a sphere's mobility in a periodic box carries a 1/L
correction (Hasimoto, J. Fluid Mech. 5, 317 (1959)), while the shear viscosity of simple
fluids shows no 1/L term (Yeh & Hummer, J. Phys. Chem. B 108, 15873 (2004)); 1/N is
1/L^3 at fixed phi, a correction that falls with the box volume. chi^2 and p say which
the data allow.

Tables are byte-identical when the same inputs are processed again. Units: omega in
rad/t_D, moduli in eta_m/t_D, viscosities relative to eta_m, L in sphere radii.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fig8_maxwell_viscosity  # noqa: E402
from schaink_common import figure, p_value, pm, save, weighted_line  # noqa: E402

from sdmpi.analysis.reduce import PartialRunWarning, ReduceError, reduce_runs  # noqa: E402
from sdmpi.analysis.report import write_all  # noqa: E402
from sdmpi.config import Medium, Mode  # noqa: E402

PHI = 0.45
#: frequencies of the study [rad/t_D]: the G' plateau is taken above 8 pi
EIGHT_PI = 8 * math.pi
#: name -> (description, function of a table's rows giving (value, error))
QUANTITIES = {}


def quantity(name, description):
    def register(function):
        QUANTITIES[name] = (description, function)
        return function
    return register


def box_side(n: int, phi: float = PHI) -> float:
    """Side of the cubic box of n unit spheres at volume fraction phi, in radii."""
    return (4 * math.pi * n / (3 * phi)) ** (1 / 3)


#: the variables Q is extrapolated in: name -> x(N) (x -> 0 as N -> infinity)
FIT_VARIABLES = {"1/L": lambda n: 1 / box_side(n), "1/N": lambda n: 1 / n}


def size_where(variable: str, x: float) -> float:
    """The N at which the fit variable (FIT_VARIABLES) takes the value x (infinite at 0)."""
    if x == 0:
        return math.inf
    if variable == "1/N":
        return 1 / x
    return 3 * PHI / (4 * math.pi * x ** 3)


def rows_of(path) -> list[dict]:
    """The phi = 0.45 rows of a moduli.csv, numbers as floats."""
    with open(path, newline="") as fh:
        rows = [{k: (v if k == "component" else float(v)) for k, v in r.items()}
                for r in csv.DictReader(fh)]
    return [r for r in rows if math.isclose(r["phi"], PHI, rel_tol=1e-9)]


def column(rows, component, name, low=0.0):
    """(omega, value, err) of one component above ``low``, sorted by omega."""
    sel = sorted((r for r in rows if r["component"] == component and r["omega"] > low * (1 - 1e-9)),
                 key=lambda r: r["omega"])
    return tuple(np.array([r[k] for r in sel]) for k in ("omega", name, name + "_err"))


def weighted_mean(values, errors):
    ok = np.isfinite(values) & np.isfinite(errors) & (errors > 0)
    if not ok.any():
        return math.nan, math.nan
    w = 1 / errors[ok] ** 2
    return float(np.sum(w * values[ok]) / w.sum()), float(w.sum() ** -0.5)


def at(rows, component, name, omega):
    """(value, err) of one component at one frequency (nan if absent)."""
    for r in rows:
        if r["component"] == component and math.isclose(r["omega"], omega, rel_tol=1e-6):
            return r[name], r[name + "_err"]
    return math.nan, math.nan


@quantity("eta_H", "eta'_H, the hydrodynamic dynamic viscosity, weighted mean over every "
                   "frequency (frequency-independent within errors: Schaink et al. Fig. 7)")
def _eta_h(rows):
    _, v, e = column(rows, "hydrodynamic", "eta_prime")
    return weighted_mean(v, e)


@quantity("G_plateau", "G' (total) on its plateau: weighted mean above 8 pi [eta_m/t_D]")
def _plateau(rows):
    _, v, e = column(rows, "total", "G_prime", low=EIGHT_PI * 1.5)
    return weighted_mean(v, e)


@quantity("G_8pi", "G' (total) at 8 pi [eta_m/t_D]")
def _g_8pi(rows):
    return at(rows, "total", "G_prime", EIGHT_PI)


@quantity("eta_B_8pi", "eta'_B, the Brownian dynamic viscosity, at 8 pi")
def _eta_b(rows):
    return at(rows, "brownian", "eta_prime", EIGHT_PI)


@quantity("eta_dprime_half", "B of eta'' (total) = A + B omega^-1/2, weighted fit over 8 pi ... "
                             "80 pi with a free intercept A, the form of Schaink et al.'s Fig. 5 "
                             "[eta_m t_D^-1/2]")
def _half(rows):
    omega, v, e = column(rows, "total", "eta_dprime", low=EIGHT_PI)
    if len(omega) < 3:
        return math.nan, math.nan
    fit = weighted_line(omega ** -0.5, v, e)
    return fit.b, fit.b_err


def reduce(paths, medium=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        return reduce_runs([str(p) for p in paths], medium=medium)


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    p.add_argument("--runs", nargs="+", default=[], metavar="RUN.h5",
                   help="run files, one N each (jobs/finite_size_n*.toml)")
    p.add_argument("--control", metavar="RUN.h5|MODULI.csv",
                   help="the time-step control's run file, or its reduced table")
    p.add_argument("--tables", nargs="+", default=[], metavar="N=MODULI.csv",
                   help="sizes whose run files are gone, by their reduced tables (e.g. "
                        "64=docs/validation/finite_size/N64/moduli.csv)")
    p.add_argument("--reference", default="docs/validation/schaink2000/newtonian/moduli.csv",
                   metavar="MODULI.csv", help="the N = 27 study's table")
    p.add_argument("--eta-inf", default="bench/eta_inf.json", metavar="JSON",
                   help="equilibrium eta'_inf(N) (bench/eta_inf_table.py)")
    p.add_argument("-o", "--output", default="docs/validation/finite_size", metavar="OUTDIR")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    tables, runs, notes = {27: rows_of(args.reference)}, set(), []
    try:
        for path in args.runs:
            red = reduce([path])
            n = red.job.system.n_particles
            written, _ = write_all(red, out / f"N{n}")
            maxw = reduce([path], Medium("maxwell", (Mode(1.0, 0.5),)))
            write_all(maxw, out / f"N{n}" / "maxwell")
            fig8_maxwell_viscosity.draw([maxw], [red], out / f"N{n}" / "maxwell.png")
            tables[n] = rows_of(out / f"N{n}" / "moduli.csv")
            runs.add(n)
            notes.append(f"N = {n}: {path}, " + ("complete" if red.complete else
                                                 "PARTIAL (committed samples only)"))
        for item in args.tables:
            n, _, path = item.partition("=")
            tables[int(n)] = rows_of(path)
            runs.add(int(n))
            notes.append(f"N = {n}: the table {path}")
        control = None
        if args.control and args.control.endswith(".csv"):
            control = rows_of(args.control)
        elif args.control:
            red = reduce([args.control])
            write_all(red, out / "dt_control")
            control = rows_of(out / "dt_control" / "moduli.csv")
    except ReduceError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    eta_inf = {int(r["n_particles"]): (r["eta_inf"] - 1.0, r["err"])
               for r in json.loads(Path(args.eta_inf).read_text())["rows"]
               if math.isclose(r["phi"], PHI)}
    none = (math.nan, math.nan)
    values = {n: {q: fn(tables[n]) if n in tables else none for q, (_, fn) in QUANTITIES.items()}
              for n in sorted(set(tables) | set(eta_inf))}
    for n in values:
        values[n]["eta_inf_minus_1"] = eta_inf.get(n, none)
    fits = {(q, var): extrapolate(values, q, var)
            for q in [*QUANTITIES, "eta_inf_minus_1"] for var in FIT_VARIABLES}
    write_quantities(values, out / "quantities.csv")
    write_extrapolation(fits, out / "extrapolation.csv")
    draw_spectra({n: rows for n, rows in tables.items() if n in runs}, rows_of(args.reference), out)
    draw_size(values, fits, out / "size.png")
    (out / "summary.md").write_text(summary(values, fits, notes, rows_of(args.reference)) + time_steps(
        rows_of(args.reference), tables[27] if 27 in runs else None, control))
    print(f"wrote {out / 'summary.md'}")
    return 0


def extrapolate(values, q, variable):
    """Weighted fit Q = Q_inf + c x over the sizes where Q is known, x = 1/L or 1/N
    (``variable``, FIT_VARIABLES); N_within: the N from which |c| x < err(Q_inf)."""
    sizes = sorted(n for n in values if math.isfinite(values[n][q][1]))
    if len(sizes) < 2:
        return {"sizes": sizes, "Q_inf": math.nan, "Q_inf_err": math.nan, "c": math.nan,
                "c_err": math.nan, "chi2_per_dof": math.nan, "dof": 0, "p": math.nan, "N_within": math.nan}
    x = np.array([FIT_VARIABLES[variable](n) for n in sizes])
    y = np.array([values[n][q][0] for n in sizes])
    e = np.array([values[n][q][1] for n in sizes])
    fit = weighted_line(x, y, e)
    n_within = size_where(variable, fit.a_err / abs(fit.b)) if fit.b != 0 else 0.0
    return {"sizes": sizes, "Q_inf": fit.a, "Q_inf_err": fit.a_err, "c": fit.b,
            "c_err": fit.b_err, "chi2_per_dof": fit.chi2, "dof": fit.dof,
            "p": p_value(fit.chi2, fit.dof),
            "N_within": n_within}


def write_quantities(values, path):
    sizes = sorted(values)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["quantity", *[x for n in sizes for x in (f"N{n}", f"N{n}_err")]])
        for q in values[sizes[0]]:
            w.writerow([q, *[f"{v:.10g}" for n in sizes for v in values[n][q]]])


def write_extrapolation(fits, path):
    keys = ["Q_inf", "Q_inf_err", "c", "c_err", "chi2_per_dof", "dof", "p", "N_within"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["quantity", "in", "sizes", *keys])
        for (q, variable), fit in fits.items():
            w.writerow([q, variable, " ".join(map(str, fit["sizes"])), *[f"{fit[k]:.10g}" for k in keys]])


def draw_spectra(tables, reference, out):
    """G', G'' and eta', eta'' (total) against omega for every N, and the N = 27 study."""
    for name, columns, labels in (
            ("moduli.png", ("G_prime", "G_dprime"), ("G′  [η_m/t_D]", "G″  [η_m/t_D]")),
            ("viscosities.png", ("eta_prime", "eta_dprime"), ("η′/η_m", "η″/η_m"))):
        fig, axes = figure(2, width=10.0, height=4.2)
        for ax, col, label in zip(axes, columns, labels):
            omega, v, e = column(reference, "total", col)
            ax.errorbar(omega, v, e, marker="s", ms=3, capsize=2, ls=":", color="0.5",
                        label="N = 27, study (500 steps per period)")
            for n, rows in sorted(tables.items()):
                omega, v, e = column(rows, "total", col)
                ax.errorbar(omega, v, e, marker="o", ms=4, capsize=2,
                            label=f"N = {n}, dt = 5e-4")
            ax.set(xscale="log", xlabel="ω  [rad/t_D]", ylabel=label)
            if col in ("G_prime", "G_dprime"):
                ax.set_yscale("log")
            ax.legend(fontsize=8)
        fig.suptitle(f"Brownian hard spheres, φ = {PHI}, total moduli against N "
                     "(Schaink et al. 2000 protocol)", fontsize=10)
        save(fig, out / name)


def draw_size(values, fits, path):
    """Each quantity against 1/L, with its fits in 1/L (a line) and in 1/N (a curve here)
    and their Q_inf at 1/L = 0."""
    names = list(dict.fromkeys(q for q, _ in fits))
    fig, axes = figure(len(names), width=3.0 * len(names), height=3.4)
    for ax, q in zip(axes, names):
        sizes = sorted(values)
        x = np.array([1 / box_side(n) for n in sizes])
        y = np.array([values[n][q][0] for n in sizes])
        e = np.array([values[n][q][1] for n in sizes])
        ax.errorbar(x, y, e, marker="o", ls="none", capsize=2, color="k")
        for k, variable in enumerate(FIT_VARIABLES):
            fit = fits[q, variable]
            if math.isfinite(fit["Q_inf"]):
                xs = np.linspace(0, x.max() * 1.05, 40)
                along = [FIT_VARIABLES[variable](size_where("1/L", v)) if v > 0 else 0.0 for v in xs]
                ax.plot(xs, fit["Q_inf"] + fit["c"] * np.array(along), "--", lw=1, color=f"C{k}",
                        label=f"fit in {variable}")
                ax.errorbar([0.002 * k], [fit["Q_inf"]], [fit["Q_inf_err"]], marker="s", ms=3,
                            color=f"C{k}", capsize=2)
        ax.set(xlabel="1/L  [1/a]", title=q, xlim=(-0.005, None))
        ax.tick_params(labelsize=7)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=6)
    save(fig, path)


def summary(values, fits, notes, reference) -> str:
    """summary.md's numbers: the quantities per N with their fits in 1/L and 1/N, the same
    quantities of the reference study (N = 27 at its own time steps), and eta'_H against
    the equilibrium eta'_inf - 1."""
    sizes = sorted(values)
    lines = ["# Finite-size study: the numbers", "",
             "Written by postprocess/finite_size.py. phi = 0.45, gamma0 = 0.02; one standard "
             "error.", "", *[f"- {note}" for note in notes], "",
             "| quantity | " + " | ".join(f"N = {n} (L = {box_side(n):.2f})" for n in sizes)
             + "".join(f" | Q_inf (fit in {v}) | N within error ({v})" for v in FIT_VARIABLES) + " |",
             "|---|" + "---|" * len(sizes) + "---|---|" * len(FIT_VARIABLES)]
    for q in dict.fromkeys(q for q, _ in fits):
        cells = [pm(*values[n][q]) for n in sizes]
        for variable in FIT_VARIABLES:
            fit = fits[q, variable]
            n_within = f"{fit['N_within']:.0f}" if math.isfinite(fit["N_within"]) else "-"
            cells += [f"{pm(fit['Q_inf'], fit['Q_inf_err'])} (sizes {', '.join(map(str, fit['sizes']))}, "
                      f"chi2/dof {fit['chi2_per_dof']:.3g}, dof {fit['dof']}, p {fit['p']:.2g})", n_within]
        lines.append(f"| {q} | " + " | ".join(cells) + " |")
    lines += ["", "Quantities: " + "; ".join(f"{q}: {d}" for q, (d, _) in QUANTITIES.items())
              + "; eta_inf_minus_1: the equilibrium eta'_inf - 1 (bench/eta_inf.json).", "",
              "The same quantities of the reference study (N = 27, 500 steps per period, "
              "dt = 5e-4 ... 5e-5): " + "; ".join(f"{q} {pm(*fn(reference))}"
                                                  for q, (_, fn) in QUANTITIES.items()) + ".", ""]
    lines += ["## eta'_H against the equilibrium eta'_inf - 1 (linear response)", ""]
    for n in sizes:
        (a, ea), (b, eb) = values[n]["eta_H"], values[n]["eta_inf_minus_1"]
        z = (a - b) / math.hypot(ea, eb) if math.isfinite(a + b) else math.nan
        lines.append(f"- N = {n}: eta'_H {pm(a, ea)}, eta'_inf - 1 {pm(b, eb)}: "
                     f"difference {z:+.1f} standard errors")
    return "\n".join(lines) + "\n"


#: (component, column) compared between time steps
CHECKED = (("total", "G_prime"), ("total", "G_dprime"), ("hydrodynamic", "eta_prime"),
           ("brownian", "eta_prime"))


def time_steps(reference, n27, control) -> str:
    """The time-step controls: each table's values against the reference's (500 steps per
    period, dt <= 5e-4) at the frequencies both have, as differences in standard errors."""
    lines = []
    for title, rows in (("the control (80 pi, as long as the study)", control),
                        ("the N = 27 run of the study's own protocol at dt = 5e-4", n27)):
        if rows is None:
            continue
        lines += ["", f"## Time step: {title} against the study (dt = 5e-4 ... 5e-5)", "",
                  "| omega | dt here, study | " + " | ".join(f"{c} {k}" for c, k in CHECKED)
                  + " |", "|---|---|" + "---|" * len(CHECKED)]
        for omega in sorted({r["omega"] for r in rows}):
            cells = []
            for comp, col in CHECKED:
                (a, ea), (b, eb) = at(rows, comp, col, omega), at(reference, comp, col, omega)
                z = (a - b) / math.hypot(ea, eb)
                cells.append(f"{pm(a, ea)} vs {pm(b, eb)} ({z:+.1f})")
            study_dt = min(5e-4, 2 * math.pi / omega / 500)
            lines.append(f"| {omega / math.pi:.0f} pi | 5e-4, {study_dt:.3g} | "
                         + " | ".join(cells) + " |")
    return "\n".join(lines) + ("\n" if lines else "")


if __name__ == "__main__":
    sys.exit(main())
