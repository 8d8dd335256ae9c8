#!/usr/bin/env python3
"""Dratler & Schowalter, J. Fluid Mech. 325, 53 (1996), sec. 4.2: the sensitivity of the
viscosity to one parameter at a time, from run files -> sensitivity.csv.

    postprocess/dratler1996_sensitivity.py --reference RUN.h5 --variant LABEL=RUN.h5 ...
        [-o docs/validation/dratler1996/sensitivity]

Inputs: run files of jobs/dratler1996_sensitivity.toml, the reference as it stands and
each variant with one or more keys changed (``make dratler1996-sensitivity``), one areal
fraction each. Units: a = 1, eta_m = 1, time (= strain) in 1/gamma_dot.

``sensitivity.csv``, one row per run (the reference first):

* ``label``, ``changed``: the job keys whose values differ from the reference's
  (``section.key=value``, job.name left out);
* ``realisations``, ``strain`` (the longest committed), ``eta``, ``eta_h``, ``eta_p`` with one
  standard error (as monolayer.csv: the larger of the spread between the realisations and
  the blocking error within them; eta = 1 + eta_h + eta_p, the paper's eq. 6);
* ``change``, ``change_err``: eta's relative change from the reference. With the same
  job.seed, system.n_particles and number of realisations the variants start from the
  reference's configurations (common random numbers): the change is the mean over the
  realisations of (eta_variant - eta_reference) / eta_reference, each realisation's eta
  its time average after the start-up and up to the shorter strain of the two (so the
  variant may change integration.dt, its discard_steps covering the same strain), and its error the
  standard error of that mean (``paired`` = 1). Otherwise the two means' ratio minus one with
  independent errors (``paired`` = 0);
* ``overlaps_mean``, ``overlaps_max``, ``smallest_gap`` (a) over the analysed samples.

The CSV file is byte-identical when the same run files are processed again. Exit status 2
with a message for an unusable run file or arguments.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dratler1996 import write_csv  # noqa: E402
from monolayer_table import analysed_samples, eta_of, overlap_statistics, ratio_of, reduce_model  # noqa: E402

from sdmpi.analysis.reduce import (ReduceError, medium_viscosity, open_run,  # noqa: E402
                                   read_stress, steady_quantities)

FIELDS = ["label", "changed", "realisations", "strain", "eta", "eta_err", "eta_h", "eta_h_err",
          "eta_p", "eta_p_err", "change", "change_err", "paired", "overlaps_mean",
          "overlaps_max", "smallest_gap"]


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--reference", required=True, metavar="RUN.h5",
                   help="run file of the job as it stands")
    p.add_argument("--variant", nargs="+", default=[], metavar="LABEL=RUN.h5",
                   help="run files of the variants, each after its label (the last = separates them)")
    p.add_argument("-o", "--output", default="docs/validation/dratler1996/sensitivity",
                   metavar="OUTDIR")
    args = p.parse_args(argv)
    variants = []
    for item in args.variant:
        label, sep, path = item.rpartition("=")
        if not sep or not label or not path:
            p.error(f"--variant takes LABEL=RUN.h5, not {item!r}")
        variants.append((label, path))
    args.variant = variants
    return args


def flat_job(job) -> dict[str, object]:
    """The job's keys as {"section.key": value} (job.name left out)."""
    flat = {}
    for section in dataclasses.fields(job):
        value = getattr(job, section.name)
        if not dataclasses.is_dataclass(value):
            continue
        for key, item in dataclasses.asdict(value).items():
            if (section.name, key) != ("job", "name"):
                flat[f"{section.name}.{key}"] = item
    return flat


def changed_keys(job, reference) -> str:
    """The keys whose values differ from the reference job's, "section.key=value" joined by
    spaces."""
    mine, ref = flat_job(job), flat_job(reference)
    return " ".join(f"{k}={mine[k]!r}" for k in sorted(mine) if mine[k] != ref.get(k))


def task_etas(path) -> tuple[np.ndarray, np.ndarray]:
    """(committed samples after the start-up and before a stop (R,), their total eta per
    sample (R, T) padded with nan) of every task of a one-phi run file, in task order."""
    summary = open_run(path)
    job = summary.job
    per_task = []
    with h5py.File(path, "r", locking=False) as f:
        for task in summary.tasks:
            _, _, stop = analysed_samples(summary, f, task)
            end = int(summary.progress[task.task_id])
            if stop is not None:
                end = min(end, int(round(stop / task.dt)))
            stress = read_stress(f, job, task, end, columns=slice(None))   # (C, end, 6)
            eta = steady_quantities(stress, job.shear.rate)[:, 0].sum(axis=0) + medium_viscosity(job)
            per_task.append(eta[task.discard_steps:])
    longest = max((len(e) for e in per_task), default=0)
    table = np.full((len(per_task), longest), np.nan)
    for k, eta in enumerate(per_task):
        table[k, :len(eta)] = eta
    return np.array([len(e) for e in per_task]), table


def paired_change(path, reference) -> tuple[float, float]:
    """(mean relative change of eta, its standard error) over realisations that start alike,
    each realisation's eta averaged over the strain both runs committed after their
    start-ups (with different time steps, the samples of that strain in each)."""
    (n_v, eta_v), (n_r, eta_r) = task_etas(path), task_etas(reference)
    dt_v = [task.dt for task in open_run(path).tasks]
    dt_r = [task.dt for task in open_run(reference).tasks]
    changes = []
    for k in range(len(n_v)):
        strain = min(n_v[k] * dt_v[k], n_r[k] * dt_r[k])
        m_v, m_r = (int(math.floor(strain / dt * (1 + 1e-12))) for dt in (dt_v[k], dt_r[k]))
        if m_v > 0 and m_r > 0:
            ref = eta_r[k, :m_r].mean()
            changes.append((eta_v[k, :m_v].mean() - ref) / ref)
    if len(changes) < 2:
        raise ReduceError(f"{path}: fewer than two realisations with samples past the start-up")
    changes = np.array(changes)
    return float(changes.mean()), float(changes.std(ddof=1) / math.sqrt(len(changes)))


def run_row(label, path, reference):
    """The sensitivity.csv row of one run file against the reference run file."""
    summary, ref_summary = open_run(path), open_run(reference)
    job, ref_job = summary.job, ref_summary.job
    if job.system.geometry != "monolayer" or len(job.system.phi) != 1:
        raise ReduceError(f"{path}: not a monolayer run at one areal fraction")
    if job.system.phi != ref_job.system.phi:
        raise ReduceError(f"{path}: system.phi = {list(job.system.phi)}, the reference's is "
                          f"{list(ref_job.system.phi)}")
    phi = job.system.phi[0]
    red = reduce_model([path])
    (eta, eta_err), (h, h_err), (p, p_err) = (
        eta_of(red, phi, c) for c in ("total", "hydrodynamic", "interparticle"))
    ov = overlap_statistics([path], phi)
    paired = (job.job.seed == ref_job.job.seed and len(summary.tasks) == len(ref_summary.tasks)
              and job.system.n_particles == ref_job.system.n_particles)
    if path == reference:
        change, change_err = 0.0, 0.0
    elif paired:
        change, change_err = paired_change(path, reference)
    else:
        ref_red = reduce_model([reference])
        ratio, change_err = ratio_of((eta, eta_err), eta_of(ref_red, phi, "total"))
        change = ratio - 1.0
    strain = float(red.committed[0].max()) * job.integration.dt * job.shear.rate
    return {"label": label, "changed": changed_keys(job, ref_job), "realisations": ov["realisations"],
            "strain": strain, "eta": eta, "eta_err": eta_err, "eta_h": h, "eta_h_err": h_err,
            "eta_p": p, "eta_p_err": p_err, "change": change, "change_err": change_err,
            "paired": int(paired), "overlaps_mean": ov["mean"], "overlaps_max": ov["max"],
            "smallest_gap": ov["smallest_gap"]}


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.output)
    try:
        rows = [run_row(label, path, args.reference)
                for label, path in [("reference", args.reference), *args.variant]]
        out.mkdir(parents=True, exist_ok=True)
    except (ReduceError, OSError, ValueError, KeyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    write_csv(out / "sensitivity.csv", rows, FIELDS)
    print(f"wrote {out}/sensitivity.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
