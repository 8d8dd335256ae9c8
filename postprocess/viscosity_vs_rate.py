#!/usr/bin/env python3
"""Steady-shear viscosity against shear rate and Peclet number, from run files.

    postprocess/viscosity_vs_rate.py RUN.h5 [RUN2.h5 ...] [-o OUTDIR]

Each steady-shear run file holds one shear rate (``physical.shear_rate`` or
``shear.rate``); files of the same system and rate with different seeds are reduced
together (sdmpi.analysis.reduce.reduce_runs). Writes OUTDIR/viscosity_vs_rate.csv, one
row per (phi, rate, component) with the reduced columns of viscosity.csv plus, for jobs
with a [physical] section, the SI columns (rate_per_s, Pe, eta_Pa_s, ...), prints the
total and the parts, and plots eta against the rate (1/s when physical, else Pe) with
95% intervals: OUTDIR/viscosity_vs_rate.png. Pe = 6 pi eta_m a^3 gamma_dot / kT.
"""

import argparse
import csv
import math
import sys
import warnings
from pathlib import Path

from sdmpi.analysis.reduce import PartialRunWarning, ReduceError, open_run, reduce_runs
from sdmpi.analysis.report import plus_minus

SHOWN = ("hydrodynamic", "brownian", "interparticle", "total")


def reductions(paths):
    """One steady-shear reduction per (phi, rate) of the files (ReduceError on mixed or
    unusable input)."""
    groups = {}
    for path in paths:
        job = open_run(path).job
        if job.shear.protocol != "steady":
            raise ReduceError(f"{path}: not a steady-shear job (shear.protocol = "
                              f"{job.shear.protocol!r})")
        groups.setdefault((job.system.phi, job.shear.rate), []).append(path)
    out = []
    for key in sorted(groups):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PartialRunWarning)
            red = reduce_runs(groups[key])
        for note in red.notes:
            print(f"note: {note}", file=sys.stderr)
        out.append(red)
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    p.add_argument("runs", nargs="+", metavar="RUN.h5", help="steady-shear run file(s)")
    p.add_argument("-o", "--output", default="viscosity_vs_rate", metavar="OUTDIR",
                   help="output directory (default viscosity_vs_rate)")
    args = p.parse_args(argv)
    try:
        reds = reductions(args.runs)
    except ReduceError as err:
        sys.exit(f"error: {err}")
    columns = max((red.columns for red in reds), key=len)
    rows = [row for red in reds for row in red.rows()]
    physical = "eta_Pa_s" in columns
    outdir = Path(args.output)
    outdir.mkdir(parents=True, exist_ok=True)
    with open(outdir / "viscosity_vs_rate.csv", "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(columns)
        for row in rows:
            out.writerow([row.get(c, math.nan) for c in columns])
    print(f"wrote {outdir / 'viscosity_vs_rate.csv'}")

    head = ["phi", "rate [1/s]" if physical else "rate [1/t_D]", "Pe"] + \
        [f"eta_{c[:5]} [eta_m]" for c in SHOWN] + (["eta_total [Pa s]"] if physical else [])
    lines = []
    for red in reds:
        by = {r["component"]: r for r in red.rows()}
        t = by["total"]
        rate = t["rate_per_s"] if physical else t["rate"]
        pe = t["Pe"] if physical else (t["rate"] if red.job.time_unit == "t_D" else math.nan)
        line = [f"{t['phi']:g}", f"{rate:.4g}", f"{pe:.4g}"]
        line += [plus_minus(by[c]["eta"], by[c]["eta_ci95"]) for c in SHOWN]
        if physical:
            line.append(plus_minus(t["eta_Pa_s"], t["eta_ci95_Pa_s"]))
        lines.append(line)
    widths = [max(len(x) for x in col) for col in zip(head, *lines)]
    for line in [head] + lines:
        print("  ".join(x.ljust(w) for x, w in zip(line, widths)).rstrip())
    print("(± half-width of the 95% confidence interval; Pe = 6 pi eta_m a^3 gamma_dot / kT)")
    _plot(reds, physical, outdir / "viscosity_vs_rate.png")


def _plot(reds, physical, path):
    from matplotlib.figure import Figure
    fig = Figure(figsize=(6.4, 4.8), layout="constrained")
    ax = fig.subplots()
    for comp, marker in (("total", "D"), ("hydrodynamic", "o"), ("interparticle", "s")):
        rows = [next(r for r in red.rows() if r["component"] == comp) for red in reds]
        x = [r["rate_per_s"] if physical else r["rate"] for r in rows]
        y = [r["eta"] for r in rows]
        ax.errorbar(x, y, yerr=[r["eta_ci95"] for r in rows], fmt=marker + "-", capsize=3,
                    label=comp)
    ax.set_xscale("log")
    ax.set_xlabel("shear rate γ̇ [1/s]" if physical else "Pe = γ̇ t_D")
    ax.set_ylabel("η / η_m (contribution)")
    if physical:
        scales = reds[0].scales
        pe = scales.peclet(scales.time)  # Pe per (1/s)
        top = ax.secondary_xaxis("top", functions=(lambda g: g * pe, lambda p: p / pe))
        top.set_xlabel("Pe = 6π η_m a³ γ̇ / kT")
    ax.legend(fontsize=8)
    ax.set_title(reds[0].job.job.name, fontsize=9)
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
