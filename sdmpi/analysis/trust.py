"""How far to trust the dynamics of a reduced run: the trust report (trust.csv, trust.png).

Per (phi, omega or rate) group, over every committed sample of every realisation (the
start-up included: it is the same dynamics), from the per-step sample fields of the run
file (docs/store.md):

* ``steps_per_time``: time steps per unit of the job's time unit (t_D for Brownian jobs),
  1/dt;
* ``overlaps_per_time``, ``overlaps_per_step``: overlapping pairs found and separated at
  the start of a step (``n_overlaps``), summed over steps, per unit time and per step;
  ``midpoint_*`` the same for the Brownian midpoint (``n_overlaps_midpoint``);
* ``min_gap_min``, ``min_gap_p01``, ``min_gap_p10``, ``min_gap_median``: the distribution
  of the per-step smallest surface gap (``min_gap``, in radii; negative: an overlap);
* ``solver_iterations_per_step``, ``solver_residual_max``, ``lanczos_iterations_per_step``:
  iterative-solver statistics (0 for the direct backends);
* ``g_gap_1e-3``, ``g_gap_1e-2``, ``g_gap_1e-1``: the pair distribution function near contact
  from the H5MD trajectories (``output.trajectory_every``; NaN without them), averaged over
  the committed frames of every task and over the pair-gap shells h = r - a_i - a_j in
  [0, 1e-3), [1e-3, 1e-2), [1e-2, 1e-1) (radii): pairs counted per shell divided by the count
  an ideal gas of the same density would put there, sum_pairs 4 pi / (3 V) ((a_i + a_j +
  h_hi)^3 - (a_i + a_j + h_lo)^3) per frame. For hard spheres in equilibrium it stays near
  the contact value g(2a) in every shell; a pile-up of pairs at the smallest gaps (a drift
  too small near contact) shows as a rise towards the first shell.

Fields that a file does not hold are NaN. Warnings are raised when the overlap
corrections per step and sphere at the start or at the midpoint exceed what the time step
should leave (`overlap_threshold`; the pairs near contact, and so the corrections of a
given dt, grow in proportion to N), or when the smallest gap is deeper than
:data:`DEEP_OVERLAP` radii. With lubrication no pair reaches contact, but the exact
near-contact dynamics (the squared Bessel transition of the gap, docs/numerics.md) still
take pairs below the floor hydrodynamics.min_gap, where the overlap correction places
them: at phi = 0.45 and min_gap = 1e-4, :data:`FLOOR_RATE` per step and sphere
(bench/floor_hits.py: 1.2-1.4e-3 at dt = 5e-4, N = 27 and 125, 1.1-1.2e-3 at dt = 2.5e-4),
with a step that resolves the closest pairs 0.96-1.1 times that (``rfd`` with the
near-contact correction, the dense backends' default, on any backend) and 2.0-2.5 times with one that does
not (the midpoint scheme, petsc-krylov's default, or the correction with kappa = 1). The warning for
lubricated bulk suspensions therefore fires above :data:`FLOOR_EXCESS_WARN` times that rate,
scaled to the run's phi by the hard-sphere contact density phi g(2a) (Carnahan-Starling)
and to its floor in proportion to min_gap (the pairs below the floor of a finite density
of pairs near contact); other runs (no lubrication, monolayers) warn above
:data:`OVERLAPS_PER_SPHERE_WARN`.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..registry import DRIFT_SCHEMES, HYDRODYNAMIC_MODELS, SOLVER_BACKENDS, backend_for, default_drift_scheme
from .tables import csv_value

#: without lubrication: warn when more overlapping pairs than this are corrected per step
#: and sphere (on average; 0.02 per step at N = 27)
OVERLAPS_PER_SPHERE_WARN = 7.5e-4
#: pairs per step and sphere that the exact near-contact transition takes below the floor
#: at phi = 0.45, hydrodynamics.min_gap = 1e-4, dt = 5e-4 (bench/floor_hits.json, module
#: docstring)
FLOOR_RATE, FLOOR_RATE_PHI, FLOOR_RATE_GAP = 1.3e-3, 0.45, 1e-4
#: with lubrication: warn above this multiple of the exact rate at the run's phi and floor
FLOOR_EXCESS_WARN = 1.5
#: warn when a step starts with an overlap deeper than this (surface gap, radii)
DEEP_OVERLAP = -0.05

TRUST_COLUMNS = ("n_tasks", "steps", "time", "steps_per_time", "overlaps_per_time",
                 "overlaps_per_step", "midpoint_overlaps_per_time",
                 "midpoint_overlaps_per_step", "min_gap_min", "min_gap_p01", "min_gap_p10",
                 "min_gap_median", "solver_iterations_per_step", "solver_residual_max",
                 "lanczos_iterations_per_step", "g_gap_1e-3", "g_gap_1e-2", "g_gap_1e-1")
#: the unit of each column (time: the job's time unit)
TRUST_UNITS = {"n_tasks": "count", "steps": "count", "time": "time unit",
               "steps_per_time": "1/time unit", "overlaps_per_time": "1/time unit",
               "overlaps_per_step": "1", "midpoint_overlaps_per_time": "1/time unit",
               "midpoint_overlaps_per_step": "1", "min_gap_min": "a", "min_gap_p01": "a",
               "min_gap_p10": "a", "min_gap_median": "a", "solver_iterations_per_step": "1",
               "solver_residual_max": "1", "lanczos_iterations_per_step": "1",
               "g_gap_1e-3": "1", "g_gap_1e-2": "1", "g_gap_1e-1": "1"}
#: the gap shells of the near-contact g (radii)
GAP_SHELLS = (0.0, 1e-3, 1e-2, 1e-1)

FIELDS = ("n_overlaps", "n_overlaps_midpoint", "min_gap", "solver_iterations",
          "solver_residual", "lanczos_iterations")


def group_samples(red, g):
    """{field: concatenated committed samples of every task of group g}, and the steps
    and total time they span (sum of committed x dt); missing fields are absent."""
    from ..ensemble.store import task_key
    from ..ensemble.h5 import open_read
    out, steps, time = {f: [] for f in FIELDS}, 0, 0.0
    for i, path in enumerate(red.files):      # validated by the reduction already
        with open_read(path) as f:
            for col in np.flatnonzero(red.file_index == i):
                group = f[f"tasks/{task_key(int(red.task_id[g, col]))}"]
                done = int(red.committed[g, col])
                for name in FIELDS:
                    if name in group["samples"]:
                        out[name].append(group["samples"][name][:done])
                steps += done
                time += done * float(group.attrs["dt"])
    return {k: np.concatenate(v) for k, v in out.items() if v}, steps, time


def near_contact_g(red, g):
    """g in the GAP_SHELLS of group g from the committed trajectory frames of its tasks
    (module docstring); NaN when the run holds no trajectories."""
    from ..ensemble.store import task_key
    from ..ensemble.h5 import open_read
    from .trajectories import groups, read
    counts, ideal = np.zeros(len(GAP_SHELLS) - 1), np.zeros(len(GAP_SHELLS) - 1)
    edges = np.asarray(GAP_SHELLS)
    for i, path in enumerate(red.files):
        present = set(groups(path))
        for col in np.flatnonzero(red.file_index == i):
            key = task_key(int(red.task_id[g, col]))
            if f"task_{key}" not in present:
                continue
            traj = read(path, f"task_{key}")
            with open_read(path) as f:
                radii = f[f"tasks/{key}/radii"][()]
            a, b = np.triu_indices(len(radii), k=1)
            contact = radii[a] + radii[b]
            shell_volume = 4 * np.pi / 3 * ((contact[:, None] + edges[1:]) ** 3
                                            - (contact[:, None] + edges[:-1]) ** 3).sum(axis=0)
            for frame, x in enumerate(traj.positions):
                lattice = traj.lattice(frame)
                gap = np.linalg.norm(lattice.nearest_image(x[b] - x[a]), axis=1) - contact
                counts += np.histogram(gap, edges)[0]
                ideal += shell_volume / lattice.volume
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(ideal > 0, counts / ideal, np.nan)


def trust_rows(red) -> list[dict]:
    """One dict per group: phi, omega or rate, then :data:`TRUST_COLUMNS`."""
    rows = []
    for g in range(len(red.phi)):
        data, steps, time = group_samples(red, g)

        def total(name):
            return float(np.sum(data[name], dtype=np.int64)) if name in data else np.nan

        def per_step(name, reduce=np.mean):
            return float(reduce(data[name])) if name in data and steps else np.nan
        gaps = data.get("min_gap", np.zeros(0))
        gaps = gaps[np.isfinite(gaps)]
        q = np.quantile(gaps, [0.0, 0.01, 0.1, 0.5]) if gaps.size else [np.nan] * 4
        per_time = (lambda x: x / time) if time > 0 else (lambda x: np.nan)
        per = (lambda x: x / steps) if steps else (lambda x: np.nan)
        rows.append({
            "phi": float(red.phi[g]), red.columns[1]: float(red.control[g]),
            "n_tasks": int(np.sum(red.committed[g] > 0)), "steps": steps, "time": time,
            "steps_per_time": steps / time if time > 0 else np.nan,
            "overlaps_per_time": per_time(total("n_overlaps")),
            "overlaps_per_step": per(total("n_overlaps")),
            "midpoint_overlaps_per_time": per_time(total("n_overlaps_midpoint")),
            "midpoint_overlaps_per_step": per(total("n_overlaps_midpoint")),
            "min_gap_min": float(q[0]), "min_gap_p01": float(q[1]),
            "min_gap_p10": float(q[2]), "min_gap_median": float(q[3]),
            "solver_iterations_per_step": per_step("solver_iterations"),
            "solver_residual_max": per_step("solver_residual", np.max),
            "lanczos_iterations_per_step": per_step("lanczos_iterations"),
            **dict(zip(("g_gap_1e-3", "g_gap_1e-2", "g_gap_1e-1"), near_contact_g(red, g).tolist())),
            "_gaps": gaps})
    return rows


def exact_floor_rate(phi: float, min_gap: float) -> float:
    """Pairs per step and sphere that the exact near-contact dynamics of a lubricated
    suspension take below the floor min_gap (radii): :data:`FLOOR_RATE` scaled by the
    hard-sphere contact density phi g(2a), g(2a) = (1 - phi/2)/(1 - phi)^3
    (Carnahan & Starling, J. Chem. Phys. 51, 635 (1969)), and by min_gap."""
    def contact_density(p):
        return p * (1 - p / 2) / (1 - p) ** 3
    return FLOOR_RATE * contact_density(phi) / contact_density(FLOOR_RATE_PHI) * min_gap / FLOOR_RATE_GAP


def overlap_threshold(job, phi: float) -> tuple[float, str]:
    """The overlap corrections per step and sphere above which the trust report warns, and
    what it is (module docstring)."""
    if _lubricated_bulk(job):
        rate = exact_floor_rate(phi, job.hydrodynamics.min_gap)
        return FLOOR_EXCESS_WARN * rate, (f"{FLOOR_EXCESS_WARN:g} x the {rate:.2g} that exact "
                                          f"near-contact dynamics take below the floor")
    return OVERLAPS_PER_SPHERE_WARN, f"{OVERLAPS_PER_SPHERE_WARN:g}"


def _lubricated_bulk(job) -> bool:
    """A bulk suspension with lubrication (the overlap bar of the exact near-contact dynamics)."""
    hyd = job.hydrodynamics
    return job.system.geometry == "bulk" and hyd.lubrication and HYDRODYNAMIC_MODELS[hyd.model].lubrication


def _scheme_hint(job) -> str:
    """For a lubricated bulk Brownian run whose drift scheme takes no near-contact
    correction (the midpoint; brownian.scheme or its backend's default), what the overlap
    warning says of it; else ""."""
    backend = backend_for(job.solver.backend, job.system.n_particles, job.ensemble.ranks_per_task)
    scheme = job.brownian.scheme or (default_drift_scheme(backend) if backend in SOLVER_BACKENDS else None)
    if not (_lubricated_bulk(job) and job.brownian.enabled and scheme in DRIFT_SCHEMES) or \
            DRIFT_SCHEMES[scheme].near_contact:
        return ""
    return (f"; the {scheme} scheme takes no near-contact correction and leaves about twice the "
            f'exact count below the floor (brownian.scheme = "rfd" does not)')


def warnings_of(red, rows) -> list[str]:
    """The threshold warnings of the trust report (module docstring)."""
    out = []
    # monolayers keep and count their overlaps (Dratler & Schowalter 1996), others correct them
    handled = "kept" if red.job.system.geometry == "monolayer" else "corrected"
    n = red.job.system.n_particles
    hint = _scheme_hint(red.job)
    for row in rows:
        where = f"phi = {row['phi']:g}, {red.columns[1]} = {row[red.columns[1]]:.6g}"
        limit, what = overlap_threshold(red.job, row["phi"])
        for key, name in (("overlaps_per_step", "start"),
                          ("midpoint_overlaps_per_step", "Brownian midpoint")):
            if row[key] / n > limit:
                out.append(f"{where}: {row[key]:.3g} overlapping pairs {handled} per step at "
                           f"the {name} ({row[key] / n:.3g} per sphere, above {what}): the "
                           f"time step is large for the closest pairs; if the moduli matter "
                           f"at this level, check them at a smaller dt{hint} "
                           f"(docs/reduce.md#trust-report)")
        if row["min_gap_min"] < DEEP_OVERLAP:
            out.append(f"{where}: a step started with an overlap of {-row['min_gap_min']:.3g} "
                       f"radii (deeper than {-DEEP_OVERLAP:g})")
    return out


def write_trust_csv(red, rows, path) -> Path:
    """trust.csv: phi, omega (or rate), then :data:`TRUST_COLUMNS`."""
    columns = ("phi", red.columns[1]) + TRUST_COLUMNS
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(columns)
        for row in rows:
            out.writerow([csv_value(row[c]) for c in columns])
    return Path(path)


def group_labels(red, rows) -> list[str]:
    """The plot label of each trust row's group: "φ = 0.45, ω = 25.13" (steady shear:
    the rate, γ̇)."""
    control = red.columns[1]
    symbol = {"omega": "ω", "rate": "γ̇"}.get(control, control)
    return [f"φ = {r['phi']:g}, {symbol} = {r[control]:.4g}" for r in rows]


def plot_trust(red, rows, path) -> Path:
    """trust.png: the distribution of the per-step smallest gap per group (left) and the
    overlap corrections per unit time at the start and the midpoint (right)."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(11.0, 4.8), layout="constrained")
    a1, a2 = fig.subplots(1, 2)
    labels = group_labels(red, rows)
    for row, label in zip(rows, labels):
        gaps = row["_gaps"]
        if gaps.size:
            a1.hist(gaps, bins=40, histtype="step", label=label)
    a1.axvline(0.0, color="0.5", lw=0.8)
    a1.set_xlabel("smallest surface gap per step  [a]")
    a1.set_ylabel("steps")
    a1.set_title("distribution of the minimum gap")
    x = np.arange(len(rows))
    a2.bar(x - 0.2, [r["overlaps_per_time"] for r in rows], 0.4, label="start of step")
    a2.bar(x + 0.2, [r["midpoint_overlaps_per_time"] for r in rows], 0.4,
           label="Brownian midpoint")
    a2.set_xticks(x, labels, rotation=30, ha="right", fontsize=7)
    a2.set_ylabel(f"overlap corrections per {red.job.time_unit}")
    a2.set_title("overlap corrections")
    for ax in (a1, a2):
        ax.grid(True, alpha=0.25)
        ax.legend(fontsize=7)
    fig.suptitle(f"{red.job.job.name}: trust report (all committed steps)", fontsize=10)
    fig.savefig(path, dpi=120)
    return Path(path)
