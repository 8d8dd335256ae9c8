#!/usr/bin/env python3
"""Dratler & Schowalter, J. Fluid Mech. 325 (1996): sheared monolayers, purely
hydrodynamic vs with the short-range repulsion; our viscosities and overlap statistics
next to Dratler & Schowalter's (1996) statements, as Markdown tables.

    postprocess/monolayer_table.py RUN.h5 [RUN2.h5 ...]

Run files of jobs/monolayer_hydro.toml and jobs/monolayer_repulsion.toml (or any
monolayer jobs; files of one model are reduced together, so extra realisations with
another seed can be added). Per model and areal fraction phi_a:

- eta = 1 + eta_h + eta_p (Dratler & Schowalter 1996 eq. 6; `sdmpi reduce`'s total row) and its parts eta_h
  (hydrodynamic) and eta_p (interparticle), +- one standard error (`eta_of`);
- overlaps per configuration (n_overlaps, mean and largest over the samples after the
  start-up and before a stop), the deepest overlap and the smallest surface gap;
- realisations stopped on an overlap deeper than integration.overlap_stop, and when.

Then the ratio eta(repulsion)/eta(hydrodynamic) per phi_a. Dratler & Schowalter give their viscosities
as figures only; its statements are quoted next to ours.
"""

import argparse
import math
import sys
import warnings

import h5py
import numpy as np

from sdmpi.analysis.reduce import (TABLE_COMPONENTS, PartialRunWarning, ReduceError, open_run,
                                   reduce_runs)
from sdmpi.analysis.errors import ensemble_average
from sdmpi.analysis.report import plus_minus
from sdmpi.ensemble.store import task_key

MODELS = {"none": "hydrodynamic only", "repulsion": "repulsion"}

#: Dratler & Schowalter's (1996) statements (sec. 4), per model and areal fraction
SEED = {
    ("none", 0.2): "usually <= 1 overlap per 25-sphere configuration",
    ("none", 0.5): "overlaps > 10 most of the time, > 20 often (Fig. 4); ~1 per 2 spheres; "
                   "eta_h still rising at t = 500 (Fig. 6)",
    ("none", 0.6): "up to 40 overlaps (23 in Fig. 12a); runs stop on > 2% overlaps before "
                   "t = 500 (one at t ~ 96); eta = 15-21 (averaged to t = 70)",
    ("repulsion", None): "no overlaps at any phi_a (smallest gap O(1e-5) at tau = 1.25e6)",
}
RATIO_SEED = {0.2: "agree (Fig. 11: phi_a <= 0.4)", 0.3: "agree (Fig. 11)",
              0.4: "agree (Fig. 11)",
              0.5: "~0.7: eta(hydro) ~40% above eta(repulsion) at t = 500 (Fig. 9c)",
              0.6: "0.47: eta(repulsion) 53% smaller (Fig. 11)"}


def reduce_model(files):
    """The reduction of one model's files, its notes printed to stderr."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        red = reduce_runs(files)
    for note in red.notes:
        print(f"note: {note}", file=sys.stderr)
    return red


def analysed_samples(summary, f, task):
    """(overlaps per configuration, smallest gaps, stop strain or None) of one task of an
    open run file ``f``: its committed samples after the start-up and before a stop (a
    stopped realisation's later samples hold n_overlaps < 0)."""
    done = int(summary.progress[task.task_id])
    samples = f[f"tasks/{task_key(task.task_id)}/samples"]
    n = samples["n_overlaps"][:done]
    gap = samples["min_gap"][:done]
    stopped = np.flatnonzero(n < 0)
    end = int(stopped[0]) if stopped.size else done
    stop = end * task.dt if stopped.size else None
    return n[task.discard_steps:end], gap[task.discard_steps:end], stop


def overlap_statistics(files, phi):
    """Overlap statistics of every realisation at this phi_a in these run files, over the
    samples after the start-up and before a stop: dict with mean and max overlaps per
    configuration, the mean's standard error ``err`` (as `eta_of`'s: the larger of the
    spread between the realisations and the blocking error within them,
    `sdmpi.analysis.errors.ensemble_average`), the deepest overlap (a, 0 if none), the
    smallest gap (a) and the stops as strains."""
    counts, gaps, stops, n_real = [], [], [], 0
    for path in files:
        summary = open_run(path)
        with h5py.File(path, "r", locking=False) as f:  # also a running job's file
            for task in summary.tasks:
                if not math.isclose(task.phi, phi, rel_tol=1e-9):
                    continue
                n_real += 1
                n, gap, stop = analysed_samples(summary, f, task)
                if stop is not None:
                    stops.append(stop)
                counts.append(n)
                gaps.append(gap)
    err = float(ensemble_average(counts).err) if counts else math.nan
    counts = np.concatenate(counts) if counts else np.zeros(0)
    gaps = np.concatenate(gaps) if gaps else np.zeros(0)
    smallest = float(gaps.min()) if gaps.size else math.nan
    return {"mean": float(counts.mean()) if counts.size else math.nan, "err": err,
            "max": int(counts.max()) if counts.size else 0,
            "deepest": max(-smallest, 0.0), "smallest_gap": smallest,
            "stops": stops, "realisations": n_real}


def eta_of(red, phi, component):
    """(mean, standard error) of eta for one component at one phi_a. The error is the larger
    of the spread between realisations and the blocking error within them: with R = 2
    realisations the spread (1 degree of freedom) alone can be far too small by chance."""
    g = int(np.flatnonzero(np.isclose(red.phi, phi, rtol=1e-9))[0])
    c = TABLE_COMPONENTS.index(component)
    e = red.ensemble
    return float(e.mean[g, c, 0]), float(e.err[g, c, 0])


def ratio_of(num, den):
    """(a/b, its standard error) of two (mean, standard error) pairs taken as independent."""
    (a, ae), (b, be) = num, den
    ratio = a / b
    return ratio, abs(ratio) * math.hypot(ae / a, be / b)


def seed_says(kind, phi):
    return SEED.get((kind, round(phi, 6)), SEED.get((kind, None), ""))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    p.add_argument("runs", nargs="+", metavar="RUN.h5", help="run files of monolayer jobs")
    args = p.parse_args(argv)
    try:
        by_model = {}
        for path in args.runs:
            job = open_run(path).job
            if job.system.geometry != "monolayer":
                sys.exit(f"error: {path}: not a monolayer job (system.geometry = "
                         f"{job.system.geometry!r})")
            by_model.setdefault(job.interparticle.kind, []).append(path)
        reductions = {kind: reduce_model(files) for kind, files in by_model.items()}
    except ReduceError as err:
        sys.exit(f"error: {err}")

    print("| phi_a | model | eta | eta_h | eta_p | overlaps per config. mean / max "
          "| deepest overlap (a) | smallest gap (a) | stopped (strain) | Dratler & Schowalter |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    totals = {}
    for kind, red in reductions.items():
        job = red.job
        for phi in sorted(set(red.phi.tolist())):
            tot, hyd, inter = (eta_of(red, phi, c) for c in ("total", "hydrodynamic", "interparticle"))
            totals[kind, phi] = tot
            ov = overlap_statistics(by_model[kind], phi)
            stops = ", ".join(f"{s:.3g}" for s in ov["stops"]) or "none"
            print(f"| {phi:g} | {MODELS.get(kind, kind)} (R = {ov['realisations']}, strain "
                  f"{job.integration.n_steps * job.integration.dt:g}) "
                  f"| {plus_minus(*tot)} | {plus_minus(*hyd)} | {plus_minus(*inter)} "
                  f"| {ov['mean']:.2f} / {ov['max']} | {ov['deepest']:.2g} "
                  f"| {ov['smallest_gap']:.2g} | {stops} | {seed_says(kind, phi)} |")
    phis = sorted({phi for _, phi in totals})
    if "none" in reductions and "repulsion" in reductions:
        print("\n| phi_a | eta(repulsion) / eta(hydrodynamic only) | Dratler & Schowalter |")
        print("|---|---|---|")
        for phi in phis:
            if ("none", phi) in totals and ("repulsion", phi) in totals:
                ratio, err = ratio_of(totals["repulsion", phi], totals["none", phi])
                print(f"| {phi:g} | {plus_minus(ratio, err)} | {RATIO_SEED.get(round(phi, 6), '')} |")
    print("\n(+-: one standard error, the larger of the spread between realisations and the "
          "blocking error within them)")


if __name__ == "__main__":
    main()
