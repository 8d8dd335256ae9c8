"""Shared helpers of the scripts that rebuild the figures of Schaink et al., J. Rheol. 44
(2000) from run files of the jobs/schaink2000_*.toml jobs.

Each figure script takes run files (complete, partial or small: whatever is committed is
used), reduces them with :func:`sdmpi.analysis.reduce.reduce_runs` (files of the same
system together, different systems, e.g. several volume fractions run as separate
jobs, apart), draws the figure with Schaink et al.'s models overlaid, and prints a table of
our numbers next to Schaink et al.'s statements. Units: omega in 1/t_D, moduli in eta_m/t_D,
viscosities relative to eta_m.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np
from scipy.stats import chi2 as chi2_dist

from sdmpi.analysis.reduce import (FREE_KEYS, PartialRunWarning, ReduceError, job_items,
                                   open_run, reduce_runs)
from sdmpi.analysis.report import plus_minus

SEED = "Schaink et al., J. Rheol. 44 (2000)"


def parser(description: str, default_out: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("runs", nargs="+", metavar="RUN.h5", help="run file(s)")
    p.add_argument("-o", "--output", default=default_out, metavar="FIG.png",
                   help=f"figure file (default {default_out})")
    return p


def reduce_systems(paths, medium=None):
    """Reductions of the run files, one per system (files differing only in
    sdmpi.analysis.reduce.FREE_KEYS are reduced together), optionally only those with
    the given medium kind. Exits with status 2 and a message on bad input; prints the
    reducer's notes on partial runs to stderr."""
    try:
        groups = {}
        for path in paths:
            job = open_run(path).job
            key = tuple((k, repr(v)) for k, v in job_items(job).items() if k not in FREE_KEYS)
            groups.setdefault(key, []).append(path)
        reductions = []
        for files in groups.values():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PartialRunWarning)
                red = reduce_runs(files)
            for note in red.notes:
                print(f"note: {note}", file=sys.stderr)
            reductions.append(red)
    except ReduceError as err:
        sys.exit(f"error: {err}")
    if medium is not None:
        reductions = [r for r in reductions if r.job.medium.kind == medium]
        if not reductions:
            sys.exit(f"error: none of the run files has a {medium} medium")
    oscillatory = [r for r in reductions if r.kind == "oscillatory"]
    if not oscillatory:
        sys.exit("error: no oscillatory-shear run among the files")
    return oscillatory


def series(red, phi, component, column):
    """(omega, value, err) arrays of one component at one phi, sorted by omega; column
    is a moduli.csv column (G_prime, G_dprime, eta_prime, eta_dprime)."""
    rows = [r for r in red.rows() if r["component"] == component
            and math.isclose(r["phi"], phi, rel_tol=1e-9)]
    rows.sort(key=lambda r: r["omega"])
    return tuple(np.array([r[k] for r in rows]) for k in ("omega", column, column + "_err"))


class LineFit(NamedTuple):
    """y = a + b x: intercept and slope with their standard errors, chi^2/dof, dof."""

    a: float
    a_err: float
    b: float
    b_err: float
    chi2: float
    dof: int


def weighted_line(x, y, e) -> LineFit:
    """Weighted least squares y = a + b x (weights 1/e^2) over the finite points with
    positive errors; standard errors for these absolute errors (nan where undetermined:
    fewer than 2 points; chi^2/dof needs 3)."""
    x, y, e = (np.asarray(v, dtype=float) for v in (x, y, e))
    ok = np.isfinite(y) & np.isfinite(e) & (e > 0)
    if ok.sum() < 2:
        return LineFit(*(np.nan,) * 5, 0)
    w, x, y = 1 / e[ok] ** 2, x[ok], y[ok]
    s, sx, sxx = w.sum(), np.sum(w * x), np.sum(w * x * x)
    sy, sxy = np.sum(w * y), np.sum(w * x * y)
    det = s * sxx - sx ** 2
    a, b = (sxx * sy - sx * sxy) / det, (s * sxy - sx * sy) / det
    dof = int(ok.sum()) - 2
    chi2 = float(np.sum(w * (y - a - b * x) ** 2) / dof) if dof > 0 else np.nan
    return LineFit(float(a), float(np.sqrt(sxx / det)), float(b), float(np.sqrt(s / det)),
                   chi2, dof)


def p_value(chi2_per_dof, dof):
    """Upper-tail probability of a chi^2 of ``chi2_per_dof`` x dof (nan if dof < 1)."""
    return float(chi2_dist.sf(chi2_per_dof * dof, dof)) if dof >= 1 else math.nan


def phis(reductions):
    """All volume fractions of the reductions, sorted."""
    return sorted({float(p) for red in reductions for p in red.phi})


def pm(mean, err, digits=None) -> str:
    """'mean ± err' (sdmpi.analysis.report.plus_minus; ``digits`` is ignored)."""
    return plus_minus(float(mean), float(err))


def print_table(title, head, rows) -> None:
    """An aligned text table."""
    cells = [[str(c) for c in row] for row in rows]
    widths = [max(len(x) for x in col) for col in zip(head, *cells)]
    print(title)
    for row in [head] + cells:
        print("  " + "  ".join(x.ljust(w) for x, w in zip(row, widths)).rstrip())


def figure(ncols=1, width=6.4, height=5.0):
    """A matplotlib Figure (Agg, no pyplot) and its axes."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, height), layout="constrained")
    return fig, fig.subplots(1, ncols, squeeze=False)[0]


def save(fig, path) -> None:
    fig.savefig(path, dpi=120)
    print(f"wrote {Path(path)}")


def describe(red) -> str:
    """One line on a reduction: job, system, ensemble size, completeness."""
    n = sorted({int(k) for k in red.ensemble.n_realisations[:, 1, 0]})
    state = "complete" if red.complete else "PARTIAL (committed samples only)"
    return (f"{red.job.job.name}: N = {red.job.system.n_particles}, {red.job.medium.kind} "
            f"medium, {len(red.files)} file(s), realisations per (phi, omega) "
            f"{'/'.join(map(str, n))}, {state}")
