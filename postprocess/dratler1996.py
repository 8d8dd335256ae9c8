#!/usr/bin/env python3
"""Dratler & Schowalter, J. Fluid Mech. 325, 53 (1996): run files -> the study's tables.

    postprocess/dratler1996.py [--hydro RUN.h5 ...] [--repulsion RUN.h5 ...]
        [-o docs/validation/dratler1996] [--window STRAIN] [--no-plots]

Inputs: run files of jobs/dratler1996_hydro.toml (``--hydro``, interparticle.kind =
"none") and jobs/dratler1996_repulsion.toml (``--repulsion``), complete or partial
(whatever is committed is used; several files of one model are reduced together). At
least one model. Units: a = 1, eta_m = 1, time (= strain) in 1/gamma_dot.

Outputs in OUTDIR:

* ``hydro/``, ``repulsion/``: what ``sdmpi reduce`` writes for each model (viscosity.csv
  with eta = 1 + eta_h + eta_p, the paper's eq. 6, its parts per row, N1, N2; errors.csv,
  trust.csv, units.json, viscosity.h5 and, without ``--no-plots``, the running averages);
* ``monolayer.csv``: per model and areal fraction phi_a, the realisations, the longest
  committed strain, eta, eta_h, eta_p with one standard error (the larger of the spread between the
  realisations and the blocking error within them), the overlaps per configuration (mean
  and largest), the deepest overlap and smallest gap (a) and the strains at which
  realisations stopped on an overlap deeper than integration.overlap_stop;
* ``ratio.csv``: eta(repulsion)/eta(hydrodynamic only) per phi_a, errors as independent;
* ``neighbours.csv``: the paper's Fig. 13 quantity, the mean number of neighbours of a
  sphere, n(r_c) = 2 (pairs with centre distance < r_c) / N, for r_c = 2.00, 2.01, 2.05,
  per model, phi_a and trajectory frame (strain), averaged over the realisations that
  have the frame (column ``realisations``), from the runs' trajectories
  (output.trajectory_every > 0; frames after a stop are left out);
* ``windows.csv``: eta, eta_h, eta_p averaged over consecutive strain windows of width
  ``--window`` (default 10) from the start (start-up included; the paper's running averages, Figs. 6,
  7, 9), per model and phi_a, averaged over the realisations that reach the window's end;
* ``realisation_windows.csv``: the same windows per realisation (``seed``, the run file's
  job.seed, and ``realisation``, the job's realisation index), with the overlaps per
  configuration over each window (mean and largest; start-up included);
* ``neighbours.png`` (without ``--no-plots``): n(2.01) against strain.

The CSV files are byte-identical when the same run files are processed again. Exit
status 2 with a message for an unusable run file or arguments.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from monolayer_table import (analysed_samples, eta_of, overlap_statistics,  # noqa: E402
                             ratio_of, reduce_model)

from sdmpi.analysis.reduce import (TABLE_COMPONENTS, ReduceError, medium_viscosity,  # noqa: E402
                                   open_run, read_stress, steady_quantities)
from sdmpi.analysis.report import write_all  # noqa: E402
from sdmpi.analysis.trajectories import pair_counts, read  # noqa: E402
from sdmpi.ensemble.store import task_key  # noqa: E402

#: the paper's neighbour cut-offs r_c (centre distance, a; its Fig. 13)
CUTOFFS = (2.00, 2.01, 2.05)
#: default width of the strain windows of windows.csv (the paper's running averages,
#: Figs. 6, 7, 9)
WINDOW = 10.0
#: model name -> the interparticle.kind its job files use
KINDS = {"hydro": "none", "repulsion": "repulsion"}


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--hydro", nargs="+", default=[], metavar="RUN.h5",
                   help="run files of the hydrodynamic-only model")
    p.add_argument("--repulsion", nargs="+", default=[], metavar="RUN.h5",
                   help="run files of the model with the repulsion")
    p.add_argument("-o", "--output", default="docs/validation/dratler1996", metavar="OUTDIR")
    p.add_argument("--window", type=float, default=WINDOW, metavar="STRAIN",
                   help=f"width of the strain windows of windows.csv (default {WINDOW:g})")
    p.add_argument("--no-plots", action="store_true", help="tables only")
    args = p.parse_args(argv)
    if not args.hydro and not args.repulsion:
        p.error("give --hydro and/or --repulsion run files")
    if not args.window > 0:
        p.error(f"--window must be > 0, not {args.window:g}")
    return args


def check_model(name, files):
    """ReduceError unless every file is a monolayer run of this model."""
    for path in files:
        job = open_run(path).job
        if job.system.geometry != "monolayer":
            raise ReduceError(f"--{name} {path}: not a monolayer job (system.geometry = "
                              f"{job.system.geometry!r})")
        if job.interparticle.kind != KINDS[name]:
            raise ReduceError(f"--{name} {path}: interparticle.kind is "
                              f"{job.interparticle.kind!r}, this model's is {KINDS[name]!r}")


def committed_strain(red, phi) -> float:
    """The longest strain committed by a realisation at this phi_a in a reduction."""
    g = int(np.flatnonzero(np.isclose(red.phi, phi, rtol=1e-9))[0])
    return float(red.committed[g].max()) * red.job.integration.dt * red.job.shear.rate


def model_rows(name, red, files):
    """The monolayer.csv rows of one model's reduction."""
    rows = []
    for phi in sorted(set(red.phi.tolist()), reverse=True):
        (eta, eta_err), (h, h_err), (p, p_err) = (
            eta_of(red, phi, c) for c in ("total", "hydrodynamic", "interparticle"))
        ov = overlap_statistics(files, phi)
        rows.append({"model": name, "phi_a": phi, "realisations": ov["realisations"],
                     "strain": committed_strain(red, phi), "eta": eta, "eta_err": eta_err,
                     "eta_h": h, "eta_h_err": h_err, "eta_p": p, "eta_p_err": p_err,
                     "overlaps_mean": ov["mean"], "overlaps_max": ov["max"],
                     "deepest_overlap": ov["deepest"], "smallest_gap": ov["smallest_gap"],
                     "stops": " ".join(f"{s:.6g}" for s in ov["stops"])})
    return rows


def ratio_rows(rows):
    """ratio.csv rows: eta(repulsion)/eta(hydro) at the phi_a both models have."""
    eta = {(r["model"], r["phi_a"]): (r["eta"], r["eta_err"]) for r in rows}
    out = []
    for phi in sorted({r["phi_a"] for r in rows}, reverse=True):
        if ("hydro", phi) in eta and ("repulsion", phi) in eta:
            ratio, err = ratio_of(eta["repulsion", phi], eta["hydro", phi])
            out.append({"phi_a": phi, "ratio": ratio, "ratio_err": err})
    return out


def task_neighbours(path, summary, f, task):
    """(strains (F,), n(r_c) (F, len(CUTOFFS))) of one task's trajectory frames before
    a stop; empty if the run keeps no trajectory."""
    group = f"task_{task.task_id:06d}"
    if f"particles/{group}" not in f:
        return np.zeros(0), np.zeros((0, len(CUTOFFS)))
    _, _, stop = analysed_samples(summary, f, task)
    traj = read(path, group)
    strain = traj.time * summary.job.shear.rate
    keep = strain <= stop if stop is not None else np.ones(len(strain), bool)
    n = len(traj.positions[0]) if len(traj.positions) else 1
    counts = np.array([[pair_counts(x, traj.lattice(k), [0.0, rc])[0] for rc in CUTOFFS]
                       for k, x in enumerate(traj.positions) if keep[k]]).reshape(-1, len(CUTOFFS))
    return strain[keep], 2.0 * counts / n


def neighbour_rows(name, files):
    """neighbours.csv rows of one model: per phi_a and frame, the mean over realisations."""
    acc = {}
    for path in files:
        summary = open_run(path)
        with h5py.File(path, "r", locking=False) as f:
            for task in summary.tasks:
                strains, n = task_neighbours(path, summary, f, task)
                for s, row in zip(strains, n):
                    key = (task.phi, round(float(s), 9))
                    total, count = acc.get(key, (np.zeros(len(CUTOFFS)), 0))
                    acc[key] = (total + row, count + 1)
    rows = []
    for (phi, strain), (total, count) in sorted(acc.items(), key=lambda kv: (-kv[0][0], kv[0][1])):
        row = {"model": name, "phi_a": phi, "strain": strain, "realisations": count}
        row.update({f"n_{rc:.2f}": v for rc, v in zip(CUTOFFS, total / count)})
        rows.append(row)
    return rows


def task_windows(summary, f, task, width):
    """{window index: (eta, eta_h, eta_p, overlaps mean, overlaps max)} of one task: the
    means over consecutive strain windows of this width from t = 0 (start-up included) up
    to a stop, whole windows only, eta = eta_m + the contributions (the paper's eq. 6), and
    the overlaps per configuration (n_overlaps) of the same samples."""
    job = summary.job
    _, _, stop = analysed_samples(summary, f, task)
    done = int(summary.progress[task.task_id])
    end = done if stop is None else min(done, int(round(stop / task.dt)))
    per = max(int(round(width / (task.dt * job.shear.rate))), 1)
    stress = read_stress(f, job, task, end, columns=slice(None))       # (C, end, 6)
    eta = steady_quantities(stress, job.shear.rate)[:, 0]             # (C, end)
    overlaps = f[f"tasks/{task_key(task.task_id)}/samples"]["n_overlaps"][:end]
    hydro = TABLE_COMPONENTS.index("hydrodynamic") - 1
    inter = TABLE_COMPONENTS.index("interparticle") - 1
    out = {}
    for k in range(end // per):
        part = eta[:, k * per:(k + 1) * per].mean(axis=1)
        n = overlaps[k * per:(k + 1) * per]
        out[k] = (medium_viscosity(job) + part.sum(), part[hydro], part[inter],
                  float(n.mean()), int(n.max()))
    return out


def window_rows(name, files, width):
    """(windows.csv rows, realisation_windows.csv rows) of one model: per phi_a and strain
    window, eta and its parts averaged over the realisations that reach the window's end;
    and per realisation and window, eta, its parts and the overlaps per configuration."""
    acc, per_task = {}, []
    for path in files:
        summary = open_run(path)
        with h5py.File(path, "r", locking=False) as f:
            for task in summary.tasks:
                for k, (eta, eta_h, eta_p, n_mean, n_max) in task_windows(summary, f, task, width).items():
                    acc.setdefault((task.phi, k), []).append((eta, eta_h, eta_p))
                    per_task.append({"model": name, "phi_a": task.phi, "seed": summary.job.job.seed,
                                     "realisation": task.realisation,
                                     "strain_from": k * width, "strain_to": (k + 1) * width,
                                     "eta": eta, "eta_h": eta_h, "eta_p": eta_p,
                                     "overlaps_mean": n_mean, "overlaps_max": n_max})
    rows = []
    for (phi, k), values in sorted(acc.items(), key=lambda kv: (-kv[0][0], kv[0][1])):
        eta, eta_h, eta_p = np.mean(values, axis=0)
        rows.append({"model": name, "phi_a": phi, "strain_from": k * width,
                     "strain_to": (k + 1) * width, "realisations": len(values),
                     "eta": eta, "eta_h": eta_h, "eta_p": eta_p})
    per_task.sort(key=lambda r: (-r["phi_a"], r["seed"], r["realisation"], r["strain_from"]))
    return rows, per_task


def write_csv(path, rows, fields):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, lineterminator="\n")
        w.writeheader()
        for row in rows:
            w.writerow({k: (repr(float(v)) if isinstance(v, (float, np.floating)) else v)
                        for k, v in row.items()})


def draw_neighbours(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for (model, phi) in sorted({(r["model"], r["phi_a"]) for r in rows}):
        sel = [r for r in rows if r["model"] == model and r["phi_a"] == phi]
        ax.plot([r["strain"] for r in sel], [r["n_2.01"] for r in sel],
                "-" if model == "repulsion" else "--", label=f"{model}, phi_a = {phi:g}")
    ax.set_xlabel("strain")
    ax.set_ylabel("neighbours per sphere, r_c = 2.01 a")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.output)
    models = {name: files for name, files in (("hydro", args.hydro),
                                              ("repulsion", args.repulsion)) if files}
    rows, neighbours, windows, realisation_windows = [], [], [], []
    try:
        for name, files in models.items():
            check_model(name, files)
        for name, files in models.items():
            red = reduce_model(files)
            _, notes = write_all(red, out / name, plots=not args.no_plots)
            for note in notes:
                print(f"note: {name}: {note}", file=sys.stderr)
            rows += model_rows(name, red, files)
            neighbours += neighbour_rows(name, files)
            model_windows, model_realisation_windows = window_rows(name, files, args.window)
            windows += model_windows
            realisation_windows += model_realisation_windows
    except (ReduceError, OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    write_csv(out / "monolayer.csv", rows, list(rows[0]))
    write_csv(out / "ratio.csv", ratio_rows(rows), ["phi_a", "ratio", "ratio_err"])
    write_csv(out / "neighbours.csv", neighbours, ["model", "phi_a", "strain", "realisations",
                                                   *(f"n_{rc:.2f}" for rc in CUTOFFS)])
    write_csv(out / "windows.csv", windows, ["model", "phi_a", "strain_from", "strain_to",
                                             "realisations", "eta", "eta_h", "eta_p"])
    write_csv(out / "realisation_windows.csv", realisation_windows,
              ["model", "phi_a", "seed", "realisation", "strain_from", "strain_to", "eta", "eta_h", "eta_p",
               "overlaps_mean", "overlaps_max"])
    if neighbours and not args.no_plots:
        draw_neighbours(neighbours, out / "neighbours.png")
    print(f"wrote {out}/ (monolayer.csv, ratio.csv, neighbours.csv, windows.csv, "
          "realisation_windows.csv)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
