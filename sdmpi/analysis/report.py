"""Writing a :class:`.reduce.Reduction`: the CSV table, the HDF5 archive, a text table.

Files (their columns and layout: docs/reduce.md, "Outputs" and "The HDF5 archive"):

* ``moduli.csv`` (oscillatory jobs; DESIGN.md contract 4), columns
  :data:`.reduce.MODULI_COLUMNS`, or ``viscosity.csv`` (steady shear), columns
  :data:`.reduce.VISCOSITY_COLUMNS`; jobs with a ``[physical]`` section get
  :data:`.reduce.PHYSICAL_COLUMNS` appended (SI). Floats in shortest round-trip form,
  ``nan`` where nothing is known yet; ``*_err`` is one standard error.
* ``errors.csv``: where each error comes from (:class:`.errors.EnsembleEstimate`,
  :data:`.errors.SOURCES`), one row per (phi, omega or rate, component, quantity).
* ``trust.csv``, ``trust.png``: the trust report of the dynamics (:mod:`.trust`).
* ``units.json`` (format ``sdmpi-units`` version 1): the unit of every column.
* ``moduli.h5`` / ``viscosity.h5`` (format ``sdmpi-moduli`` version 1): the table, the
  ensemble and per-realisation estimates, the job and the notes.
"""

from __future__ import annotations

import csv
import datetime
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from .. import __version__
from .errors import SOURCES
from .tables import csv_value
from .trust import TRUST_UNITS
from .reduce import TABLE_COMPONENTS, SMALL_ENSEMBLE, ReduceError, task_of

#: errors.csv columns after phi and omega (or rate): docs/reduce.md, "Outputs"
ERROR_COLUMNS = ("component", "quantity", "n_realisations", "err", "err_within",
                 "err_between", "dof", "dof_within", "dof_between", "source",
                 "small_ensemble")

UNITS = {"phi": "1", "omega": "1/t_D", "rate": "1/time unit", "G_prime": "eta_m/t_D",
         "G_dprime": "eta_m/t_D", "eta_prime": "eta_m", "eta_dprime": "eta_m", "eta": "eta_m",
         "N1": "eta_m gamma_dot", "N2": "eta_m gamma_dot", "Pi": "eta_m gamma_dot",
         # SI columns of jobs with a [physical] section (.reduce.PHYSICAL_COLUMNS)
         "omega_rad_per_s": "rad/s", "G_prime_Pa": "Pa", "G_prime_err_Pa": "Pa",
         "G_dprime_Pa": "Pa", "G_dprime_err_Pa": "Pa", "eta_prime_Pa_s": "Pa s",
         "eta_prime_err_Pa_s": "Pa s", "rate_per_s": "1/s", "Pe": "1", "eta_Pa_s": "Pa s",
         "eta_err_Pa_s": "Pa s", "eta_ci95_Pa_s": "Pa s", "shear_stress_Pa": "Pa"}


def write_table(rows, columns, path) -> Path:
    """Rows (dicts) as CSV with the header ``columns``, cells by :func:`.tables.csv_value`."""
    path = Path(path)
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(columns)
        for row in rows:
            out.writerow([csv_value(row[c]) for c in columns])
    return path


def write_csv(red, path) -> Path:
    """The table of ``red`` as CSV (header = ``red.columns``)."""
    return write_table(red.rows(), red.columns, path)


def write_h5(red, path) -> Path:
    """The table plus per-realisation values, dof, block sizes, the job text and the
    input file names (layout: docs/reduce.md, "The HDF5 archive")."""
    import h5py
    path = Path(path)
    rows = red.rows()
    with h5py.File(path, "w") as f:
        f.attrs.update({
            "format": "sdmpi-moduli", "format_version": 1, "kind": red.kind,
            "job_text": red.job_text, "input_files": json.dumps(list(red.files)),
            "seeds": json.dumps(list(red.seeds)), "components": " ".join(TABLE_COMPONENTS),
            "quantities": " ".join(red.quantities),
            "units": json.dumps({c: u for c, u in UNITS.items() if c in red.columns
                                 or c in red.quantities}),
            "notes": json.dumps(list(red.notes)), "sdmpi_version": __version__,
            "medium_applied": int(red.viewed),
            "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")})
        table = f.create_group("table")
        for c in red.columns:
            values = [row[c] for row in rows]
            if c == "component":
                table.create_dataset(c, data=np.array(values, dtype=object),
                                     dtype=h5py.string_dtype())
            else:
                table.create_dataset(c, data=np.array(values))
        groups = f.create_group("groups")
        groups["phi"] = red.phi
        groups[red.columns[1]] = red.control
        ens = f.create_group("ensemble")
        ens.attrs["axes"] = "group, component, quantity"
        ens.attrs["sources"] = " ".join(SOURCES)
        for name, value in red.ensemble._asdict().items():
            ens[name] = np.asarray(value)
        per = f.create_group("realisations")
        per.attrs["axes"] = "group, component, quantity, realisation"
        for name, value in red.per_realisation._asdict().items():
            per[name] = np.asarray(value)
        for name in ("file_index", "realisation", "task_id", "committed", "n_steps"):
            per[name] = getattr(red, name)
        if red.running is not None:
            run = f.create_group("running")
            run.attrs["axes"] = "group, component, quantity, realisation, time"
            run.attrs["discard_time"] = red.running["discard_time"]
            run["time"] = red.running["time"]
            run["values"] = red.running["values"]
    return path


def plus_minus(mean, err) -> str:
    """'mean ± err' with the error to 2 significant digits and the mean to the same
    decimal place; exact values (err 0) with 5 significant digits; 'nan' if unknown."""
    if not math.isfinite(mean):
        return "nan"
    if err == 0 or not math.isfinite(err):
        return f"{mean:.5g}" + ("" if err == 0 else " ± nan")
    d = 1 - math.floor(math.log10(err))
    return f"{mean:.{d}f} ± {err:.{d}f}" if 0 <= d <= 8 else f"{mean:.4g} ± {err:.2g}"


def format_table(red) -> str:
    """The table as aligned text, values as mean +- one standard error (moduli columns
    for every kind but "steady")."""
    pm = plus_minus
    if red.kind != "steady":
        head = ["phi", "omega", "component", "n", "G'", "G''", "eta'", "eta''"]
        pairs = [("G_prime", "G_prime_err"), ("G_dprime", "G_dprime_err"),
                 ("eta_prime", "eta_prime_err"), ("eta_dprime", "eta_dprime_err")]
        units = "omega in 1/t_D; G', G'' in eta_m/t_D; eta', eta'' relative to eta_m"
    else:
        head = ["phi", "rate", "component", "n", "eta", "N1", "N2", "Pi"]
        pairs = [(q, f"{q}_ci95") for q in ("eta", "N1", "N2", "Pi")]
        rate = ("rate (Pe) in 1/t_D" if red.job.time_unit == "t_D"
                else "rate 1 = gamma_dot (time unit 1/gamma_dot)")
        units = f"{rate}; eta relative to eta_m; N1, N2, Pi in eta_m gamma_dot"
    def small(r):
        return r["component"] != "medium" and 0 < r["n_realisations"] < SMALL_ENSEMBLE
    lines = [[f"{r['phi']:g}", f"{r[red.columns[1]]:.5g}", r["component"],
              str(r["n_realisations"]) + ("*" if small(r) else "")]
             + [pm(r[m], r[e]) for m, e in pairs] for r in red.rows()]
    widths = [max(len(x) for x in col) for col in zip(head, *lines)]
    text = ["  ".join(x.ljust(w) for x, w in zip(row, widths)).rstrip()
            for row in [head] + lines]
    bars = "one standard error" if red.kind != "steady" else "95% confidence interval"
    flag = ([f"* fewer than {SMALL_ENSEMBLE} realisations: error bars rest on few runs"]
            if any(small(r) for r in red.rows()) else [])
    return "\n".join(text + [f"({units}; ± {bars})"] + flag)


def error_rows(red) -> list[dict]:
    """errors.csv: one row per (group, component, quantity) with :data:`ERROR_COLUMNS`
    (docs/reduce.md, "Outputs")."""
    e, out = red.ensemble, []
    control = red.columns[1]
    for g in range(len(red.phi)):
        for c, name in enumerate(TABLE_COMPONENTS):
            for q, quantity in enumerate(red.quantities):
                r = int(e.n_realisations[g, c, q])
                out.append({
                    "phi": float(red.phi[g]), control: float(red.control[g]),
                    "component": name, "quantity": quantity, "n_realisations": r,
                    "err": float(e.err[g, c, q]), "err_within": float(e.err_within[g, c, q]),
                    "err_between": float(e.err_between[g, c, q]), "dof": int(e.dof[g, c, q]),
                    "dof_within": int(e.dof_within[g, c, q]),
                    "dof_between": int(e.dof_between[g, c, q]),
                    "source": SOURCES[int(e.source[g, c, q])],
                    "small_ensemble": int(name != "medium" and 0 < r < SMALL_ENSEMBLE)})
    return out


def error_columns(red) -> tuple:
    """The header of errors.csv."""
    return ("phi", red.columns[1]) + ERROR_COLUMNS


def units_of(red) -> dict:
    """units.json: the unit of every column of the tables written for ``red`` and the
    conventions they follow (module docstring)."""
    rate = "1/t_D" if red.job.time_unit == "t_D" else "gamma_dot (time unit 1/gamma_dot)"
    base = dict(UNITS, rate=rate, component="label", quantity="label", source="label",
                n_realisations="count", dof="count", dof_within="count",
                dof_between="count", small_ensemble="flag (1: fewer than "
                f"{SMALL_ENSEMBLE} realisations)")
    stem = "moduli" if red.kind == "oscillatory" else "viscosity"

    def unit(column):
        for suffix in ("_err", "_ci95"):
            if column.endswith(suffix) and column[:-len(suffix)] in base:
                return base[column[:-len(suffix)]]
        return base[column]
    quantity_units = {q: base[q] for q in red.quantities}
    return {
        "format": "sdmpi-units", "format_version": 1,
        "time_unit": red.job.time_unit, "length_unit": "a (sphere radius)",
        "viscosity_unit": "eta_m (medium zero-shear viscosity)",
        "tables": {f"{stem}.csv": {c: unit(c) for c in red.columns},
                   "errors.csv": {c: unit(c) for c in error_columns(red)
                                  if c not in ("err", "err_within", "err_between")},
                   "trust.csv": {"phi": "1", red.columns[1]: unit(red.columns[1]),
                                 **{c: u.replace("time unit", red.job.time_unit)
                                    for c, u in TRUST_UNITS.items()}}},
        "errors.csv err, err_within, err_between": (
            "the unit of the row's quantity: " + ", ".join(f"{q} {u}" for q, u in
                                                           quantity_units.items())),
        "err": "*_err: one standard error, the larger of the within-realisation blocking "
               "error and the between-realisation spread (errors.csv: source); *_ci95: "
               "half-width of the 95% confidence interval (Student t, dof)",
        "physical_units": (None if red.scales is None else red.scales.as_dict()),
    }


def write_errors_csv(red, path) -> Path:
    """errors.csv (:func:`error_rows`)."""
    return write_table(error_rows(red), error_columns(red), path)


def write_units(red, path) -> Path:
    """units.json (:func:`units_of`)."""
    Path(path).write_text(json.dumps(units_of(red), indent=1, sort_keys=True) + "\n")
    return Path(path)


def check_output_dir(outdir) -> None:
    """Refuse (ReduceError) an output path that is a file, lies below a file, or lies in
    a directory this process cannot write."""
    outdir = Path(outdir)
    for p in (outdir, *outdir.parents):
        if p.exists():
            if not p.is_dir():
                raise ReduceError(f"-o {outdir}: {p} exists and is not a directory; give "
                                  f"a directory for the outputs")
            if not os.access(p, os.W_OK | os.X_OK):
                raise ReduceError(f"-o {outdir}: cannot write into {p} (permission denied)")
            return


def write_all(red, outdir, *, plots=True, task_id=None):
    """Write ``moduli.csv`` + ``moduli.h5`` (``viscosity.*`` for steady shear),
    ``errors.csv``, ``trust.csv`` (:mod:`.trust`), ``units.json`` and the figures
    (``trust.png``, then :func:`.plots.plot_all`; steady shear:
    :func:`.plots.plot_running_all`) into ``outdir`` (created). Everything is
    first written into a temporary directory inside ``outdir`` and then renamed into
    place, so a failure (ReduceError, e.g. a bad ``task_id``, or a full disk) leaves
    ``outdir`` as it was and removes a directory it created. Returns (paths written,
    notes); OSError is raised as ReduceError."""
    if task_id is not None:  # checked with or without the plots that use it
        task_of(red, task_id)
    stem = "moduli" if red.kind == "oscillatory" else "viscosity"

    def produce(staging):
        from .trust import plot_trust, trust_rows, warnings_of, write_trust_csv
        trust = trust_rows(red)
        paths = [write_csv(red, staging / f"{stem}.csv"), write_h5(red, staging / f"{stem}.h5"),
                 write_errors_csv(red, staging / "errors.csv"),
                 write_trust_csv(red, trust, staging / "trust.csv"),
                 write_units(red, staging / "units.json")]
        if plots and any(row["steps"] for row in trust):
            paths.append(plot_trust(red, trust, staging / "trust.png"))
        notes = [f"WARNING (trust report): {w}" for w in warnings_of(red, trust)]
        if plots and red.kind == "oscillatory":
            from .plots import plot_all
            figures, more = plot_all(red, staging, task_id)
            paths, notes = paths + figures, notes + more
        elif plots:
            from .plots import plot_running_all
            paths += plot_running_all(red, staging)
        return paths, notes
    return staged(outdir, produce)


def staged(outdir, produce):
    """Run ``produce(staging)`` -> (paths written into staging, notes) with ``staging`` a
    temporary directory inside ``outdir`` (created), then rename every path into
    ``outdir``: a file there is either the old one or the complete new one. A failure
    (ReduceError, a full disk) leaves ``outdir`` as it was and removes the directories
    made for it; OSError is raised as ReduceError. Returns (final paths, notes)."""
    outdir = Path(outdir)
    check_output_dir(outdir)
    created = [p for p in (outdir, *outdir.parents) if not p.exists()]
    staging = None
    try:
        outdir.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".reduce-", suffix=".tmp", dir=outdir))
        paths, notes = produce(staging)
        final = []
        for path in paths:
            os.replace(path, outdir / path.name)
            final.append(outdir / path.name)
        return final, notes
    except OSError as err:
        _undo(staging, created)
        raise ReduceError(f"cannot write the outputs into {outdir}: {err}") from None
    except BaseException:
        _undo(staging, created)
        raise
    finally:
        if staging is not None and staging.exists():
            shutil.rmtree(staging, ignore_errors=True)


def _undo(staging, created) -> None:
    """Remove the staging directory and the directories write_all created."""
    if staging is not None:
        shutil.rmtree(staging, ignore_errors=True)
    for p in created:                      # deepest first
        try:
            p.rmdir()
        except OSError:
            pass
