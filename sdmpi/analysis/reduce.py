"""Gather and reduce: run files -> ensemble-averaged moduli with one standard error.

Pipeline (Schaink et al., J. Rheol. 44 (2000), eqs. 17-19, 36; the manual:
docs/reduce.md):

1. Read and validate each run file (:func:`sdmpi.ensemble.store.read_summary`); several
   files are reduced together only if they hold the same system with different seeds
   (any other difference is refused, key by key).
2. Per task, read the committed samples of the xy stress of each stored contribution
   (hydrodynamic: ``stress_hydrodynamic_maxwell`` in a Maxwell medium, eqs. 33-35, 42;
   Brownian, eq. 16; interparticle; collision) and the time each stream's sample k
   represents, t_k + c dt (c: the dataset's ``sample_offset``, else the registry's,
   `sdmpi.config.stresses`).
3. Oscillatory jobs: project every whole period after the ``discard_periods`` on sin and
   cos at those times (:func:`.projection.project_periods`, eq. 18):

       G'  = w/(pi gamma0) int_period sigma_xy sin(w t) dt,
       G'' = w/(pi gamma0) int_period sigma_xy cos(w t) dt;

   the medium's moduli are analytic (:func:`medium_moduli`, eq. 36); the total is formed
   per period and reduced like the parts.
4. Per realisation the blocking error of the per-period values, over the ensemble the
   period-weighted mean and the larger of the spread between realisations and the
   propagated errors (:mod:`.errors`); eta' = G''/w, eta'' = G'/w (eq. 19).

Another medium after the fact (``medium=``, :mod:`.medium_view`) filters the stored
viscous ``stress_hydrodynamic`` by that medium's modes. Steady-shear jobs give
``viscosity.csv`` (eta, N1, N2, Pi per component, with ``*_err`` and ``*_ci95``; Dratler &
Schowalter 1996; definitions in docs/physics.md, "Steady shear"), with running averages
per realisation (:attr:`Reduction.running`); monolayers per layer volume 2 a L^2 (their
eq. 6). Runs at rest are refused here (:mod:`.at_rest` reduces them by Green-Kubo).
Partial runs are reduced from what is committed, each incomplete task named in
:attr:`Reduction.notes`; files that are not intact run files raise :class:`ReduceError`.

Units: radius a = 1, eta_m = 1, time t_D (1/gamma_dot for non-Brownian steady shear);
omega in 1/t_D, moduli in eta_m/t_D, viscosities relative to eta_m.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Job, units
from ..config.schema import toml_name
from ..config.stresses import CONTRIBUTIONS, contribution_datasets, sample_offset, unrecorded_offset
from ..ensemble.h5 import open_read
from .analytic import maxwell_moduli
from .errors import SOURCES, Blocking, EnsembleEstimate, blocking, combine
from .projection import project_periods, viscosities

#: rows of moduli.csv per (phi, omega), in this order
TABLE_COMPONENTS = ("medium", *(c.component for c in CONTRIBUTIONS), "total")
#: moduli.csv columns (DESIGN.md contract 4)
MODULI_COLUMNS = ("phi", "omega", "component", "n_realisations", "G_prime", "G_prime_err",
                  "G_dprime", "G_dprime_err", "eta_prime", "eta_prime_err", "eta_dprime",
                  "eta_dprime_err")
#: quantities of a steady-shear reduction (docs/physics.md, "Steady shear"), in units of
#: eta_m gamma_dot
STEADY_QUANTITIES = ("eta", "N1", "N2", "Pi")
#: viscosity.csv columns (steady shear): per quantity mean, one standard error, and the
#: half-width of the 95% confidence interval; dof of the intervals last
VISCOSITY_COLUMNS = ("phi", "rate", "component", "n_realisations") + tuple(
    c for q in STEADY_QUANTITIES for c in (q, f"{q}_err", f"{q}_ci95")) + ("dof",)
#: SI columns appended when the job has a [physical] section (sdmpi.config.units):
#: oscillatory omega (rad/s), moduli (Pa), eta' (Pa s); steady shear rate (1/s), Peclet
#: number 6 pi eta_m a^3 gamma_dot / kT, eta (Pa s) and the shear stress eta x gamma_dot (Pa)
PHYSICAL_COLUMNS = {
    "oscillatory": ("omega_rad_per_s", "G_prime_Pa", "G_prime_err_Pa", "G_dprime_Pa",
                    "G_dprime_err_Pa", "eta_prime_Pa_s", "eta_prime_err_Pa_s"),
    "steady": ("rate_per_s", "Pe", "eta_Pa_s", "eta_err_Pa_s", "eta_ci95_Pa_s",
               "shear_stress_Pa"),
}
#: ensembles of fewer realisations than this are flagged (notes, errors.csv)
SMALL_ENSEMBLE = 4
#: confidence level of the *_ci95 columns
CONFIDENCE = 0.95
#: at most this many points per running-average curve (Reduction.running)
RUNNING_POINTS = 400
#: index of the xy component in the stored 6-vectors (component_order xx yy zz xy xz yz)
XY = 3

#: job keys that may differ between files reduced together: identification, the seed
#: and the ensemble size, and keys that change how a job runs but not its results.
FREE_KEYS = frozenset({"job.name", "job.seed", "ensemble.realisations",
                       "ensemble.ranks_per_task", "output.per_particle",
                       "output.checkpoint_every", "solver.backend", "solver.tolerance"})


class ReduceError(Exception):
    """Input that cannot be reduced (not a run file, damaged, incompatible files)."""


class PartialRunWarning(UserWarning):
    """Some tasks are not finished: the reduction uses what is committed."""


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class Reduction:
    """The reduced ensemble of one system (one or several run files).

    kind          "oscillatory" (quantities G', G'') or "steady" (quantity eta)
    job, job_text the job of the first file (canonical TOML text)
    files         input paths; seeds (per file)
    phi, control  (G,) per task group: volume fraction and omega (1/t_D) or shear rate
    quantities    names of the last axis Q: ("G_prime", "G_dprime") or STEADY_QUANTITIES
    ensemble      :class:`.errors.EnsembleEstimate`, fields (G, C, Q), C = len(TABLE_COMPONENTS)
    per_realisation :class:`.errors.Blocking`, fields (G, C, Q, R), realisations R of all
                  files (n == 0: nothing committed after the start-up, absent)
    file_index, realisation  (R,): which file and which realisation of that file
    task_id       (G, R): the task of group g, realisation r in its file
    committed, n_steps  (G, R): samples committed and planned per task
    notes         human-readable remarks (partial runs, single realisations, ...)
    viewed        True when ``job`` holds a medium other than the run's (``--medium``,
                  :mod:`.medium_view`): the hydrodynamic stress is the stored viscous one,
                  filtered by that medium here
    running       steady shear only (else None): {"time": (T,) sample times in the job's
                  time unit, "values": (G, C, Q, R, T) running averages (1/t) sum over
                  samples 0..k of each quantity per realisation, NaN after a partial
                  task's last committed sample, "discard_time": time of discard_steps}
    """

    kind: str
    job: Job
    job_text: str
    files: tuple
    seeds: tuple
    phi: np.ndarray
    control: np.ndarray
    quantities: tuple
    ensemble: EnsembleEstimate
    per_realisation: Blocking
    file_index: np.ndarray
    realisation: np.ndarray
    task_id: np.ndarray
    committed: np.ndarray
    n_steps: np.ndarray
    notes: tuple
    running: dict | None = None
    viewed: bool = False

    @property
    def complete(self) -> bool:
        """True when every task of every file ran to its end."""
        return bool(np.all(self.committed == self.n_steps))

    @property
    def columns(self) -> tuple:
        base = MODULI_COLUMNS if self.kind == "oscillatory" else VISCOSITY_COLUMNS
        return base + (PHYSICAL_COLUMNS[self.kind] if self.scales is not None else ())

    @property
    def scales(self):
        """The SI values of the reduced units (:class:`sdmpi.config.units.Scales`), or
        None when the job has no [physical] section."""
        return units.scales(self.job)

    def rows(self) -> list[dict]:
        """The table, one dict per (group, component) in the order of :attr:`columns`
        (moduli.csv for oscillatory jobs, viscosity.csv for steady ones)."""
        e = self.ensemble
        out = []
        for g in range(len(self.phi)):
            for c, name in enumerate(TABLE_COMPONENTS):
                row = {"phi": float(self.phi[g]), self.columns[1]: float(self.control[g]),
                       "component": name, "n_realisations": int(e.n_realisations[g, c, 0])}
                if self.kind == "oscillatory":
                    w = float(self.control[g])
                    (g1, g2), (s1, s2) = e.mean[g, c], e.err[g, c]
                    eta1, eta2 = viscosities(g1, g2, w)
                    err1, err2 = viscosities(s1, s2, w)
                    row.update(G_prime=float(g1), G_prime_err=float(s1), G_dprime=float(g2),
                               G_dprime_err=float(s2), eta_prime=float(eta1),
                               eta_prime_err=float(err1), eta_dprime=float(eta2),
                               eta_dprime_err=float(err2))
                else:
                    half = ensemble_half_width(e, (g, c))
                    for q, name in enumerate(STEADY_QUANTITIES):
                        row[name] = float(e.mean[g, c, q])
                        row[f"{name}_err"] = float(e.err[g, c, q])
                        row[f"{name}_ci95"] = float(half[q])
                    row["dof"] = int(e.dof[g, c, 0])
                if self.scales is not None:
                    row.update(physical_columns(row, self.kind, self.scales))
                out.append(row)
        return out

    def value(self, phi, control, component, column):
        """One table entry, e.g. ``value(0.45, 2 * pi, "hydrodynamic", "eta_prime")``
        (phi and omega/rate matched to 1e-9 relative)."""
        for row in self.rows():
            if (row["component"] == component and math.isclose(row["phi"], phi, rel_tol=1e-9)
                    and math.isclose(row[self.columns[1]], control, rel_tol=1e-9)):
                return row[column]
        raise KeyError(f"no row phi={phi}, {self.columns[1]}={control}, {component}")


# --------------------------------------------------------------------------- physics


def medium_moduli(job: Job, omega):
    """(G'_m, G''_m) of the suspending medium alone, in eta_m/t_D (Schaink et al. eq. 36, 19).

    Newtonian: sigma_xy = eta_m gamma_dot, so G' = 0 and G'' = eta_m w = w (eta_m = 1).
    Maxwell, modes (eta_k, lambda_k): :func:`.analytic.maxwell_moduli`,
    G' = sum_k eta_k lambda_k w^2/(1 + (lambda_k w)^2), G'' = sum_k eta_k w/(1 + (lambda_k w)^2).
    Exact: the reducer reports them with zero error."""
    if job.medium.kind == "maxwell":
        modes = job.medium.modes
        g1, g2 = maxwell_moduli(omega, [m.eta for m in modes], [m.lam for m in modes])
        return float(g1), float(g2)
    return 0.0, float(omega)


def physical_columns(row: dict, kind: str, scales) -> dict:
    """The SI columns (:data:`PHYSICAL_COLUMNS`) of one table row in reduced units."""
    stress, eta, rate = scales.stress, scales.viscosity, 1.0 / scales.time
    if kind == "oscillatory":
        return {"omega_rad_per_s": row["omega"] * rate,
                **{f"{q}_Pa": row[q] * stress for q in ("G_prime", "G_prime_err", "G_dprime",
                                                        "G_dprime_err")},
                "eta_prime_Pa_s": row["eta_prime"] * eta,
                "eta_prime_err_Pa_s": row["eta_prime_err"] * eta}
    return {"rate_per_s": row["rate"] * rate, "Pe": scales.peclet(row["rate"]),
            "eta_Pa_s": row["eta"] * eta, "eta_err_Pa_s": row["eta_err"] * eta,
            "eta_ci95_Pa_s": row["eta_ci95"] * eta,
            "shear_stress_Pa": row["eta"] * row["rate"] * stress}


def confidence_half_width(err, dof, level=CONFIDENCE):
    """Half-width t_{(1+level)/2, dof} x err of the two-sided confidence interval of a
    mean with standard error ``err`` and ``dof`` degrees of freedom (Student t); 0 where
    err is 0 (exact values), NaN where dof < 1."""
    from scipy.stats import t as student_t
    err, dof = np.asarray(err, float), np.asarray(dof)
    with np.errstate(invalid="ignore"):
        q = student_t.ppf(0.5 + 0.5 * level, np.where(dof >= 1, dof, 1))
    return np.where(err == 0, 0.0, np.where(dof >= 1, q * err, np.nan))


def ensemble_half_width(e: EnsembleEstimate, index=(), level=CONFIDENCE):
    """Half-width of the confidence interval of the ensemble means ``e`` (at ``index``):
    the wider of the between interval t_{R-1} err_between and the within interval
    t_{dof_within} err_within (:func:`confidence_half_width`), so that, as ``err``, it
    is never narrower than either estimate supports; 0 for exact values."""
    between = confidence_half_width(e.err_between[index], e.dof_between[index], level)
    within = confidence_half_width(e.err_within[index], e.dof_within[index], level)
    return np.where(e.err[index] == 0, 0.0, np.fmax(between, within))


def medium_viscosity(job: Job) -> float:
    """Zero-shear (steady-state) viscosity of the medium, relative to eta_m."""
    if job.medium.kind == "maxwell":
        return float(sum(m.eta for m in job.medium.modes))
    return 1.0


#: the sample datasets of the viscous-medium stress contributions
VISCOUS_DATASETS = contribution_datasets("newtonian")
#: contribution datasets a run file may lack, reduced as zero (`StressContribution.absent_is_zero`)
ABSENT_IS_ZERO = frozenset(c.dataset for c in CONTRIBUTIONS if c.absent_is_zero)


def sample_offsets(f, job: Job, task, viewed=False):
    """(C,) the time each contribution's sample k represents, t_k + c dt, as c (units of
    dt): the ``sample_offset`` attribute of the stress datasets that :func:`read_stress`
    reads, or the registry's value (`sdmpi.config.stresses`) for a file written without it
    (`unrecorded_offset`) or a dataset it lacks (`sample_offset`)."""
    from ..ensemble.store import task_key
    group = f[f"tasks/{task_key(task.task_id)}/samples"]
    names = VISCOUS_DATASETS if viewed else contribution_datasets(job.medium.kind)
    return np.array([float(group[n].attrs.get("sample_offset", unrecorded_offset(n))) if n in group
                     else sample_offset(n) for n in names])


def read_stress(f, job: Job, task, committed, viewed=False, columns=XY):
    """(C, committed) xy stress of one task per contribution (``columns = slice(None)``:
    (C, committed, 6)), C = len(CONTRIBUTIONS): as stored for the run's own medium,
    or (``viewed``) the viscous stress with the hydrodynamic part filtered by
    ``job.medium`` (:func:`.medium_view.filtered_stress`)."""
    if not viewed:
        return _read_xy(f, task, committed, contribution_datasets(job.medium.kind), columns)
    from .medium_view import filtered_stress
    stress = _read_xy(f, task, committed, VISCOUS_DATASETS, columns)
    stress[0] = filtered_stress(stress[0], job.medium, task.dt)
    return stress


# --------------------------------------------------------------------------- files


def open_run(path):
    """Validate one run file and return its :class:`sdmpi.ensemble.store.RunSummary`
    (job, tasks, progress); :class:`ReduceError` if it is not an intact run file."""
    from ..ensemble.store import StoreError, read_summary
    if not Path(path).is_file():
        raise ReduceError(f"{path}: no such file")
    try:
        summary = read_summary(path)
    except StoreError as err:
        raise ReduceError(str(err)) from None
    damaged = [str(d) for d in summary.damage if d.what == "samples"]
    if damaged:
        raise ReduceError("\n  ".join([f"{path}: committed samples are damaged (checksums):",
                                        *damaged]) + "\n'sdmpi run' with the same job "
                          "recomputes them (bit for bit); then reduce again")
    return summary


def job_items(job: Job) -> dict:
    """``{"section.key": value}`` for every key of a resolved job (schema order)."""
    items = {}
    for section in dataclasses.fields(job):
        values = getattr(job, section.name)
        for f in dataclasses.fields(values):
            items[f"{section.name}.{toml_name(f)}"] = getattr(values, f.name)
    return items


def check_same_system(summaries) -> None:
    """Refuse (ReduceError) files whose jobs differ in anything but :data:`FREE_KEYS`,
    or that share a seed (their realisations would be copies of each other)."""
    first = summaries[0]
    ref = job_items(first.job)
    seen = {}
    for s in summaries:
        seed = s.job.job.seed
        if seed in seen:
            same = "is given twice" if Path(seen[seed]).resolve() == Path(s.path).resolve() \
                else f"and {seen[seed]} have the same job.seed = {seed}"
            raise ReduceError(
                f"{s.path} {same}: realisations are keyed by (seed, task id), so the "
                f"files would hold the same realisations and their spread would be "
                f"counted twice; reduce each once, or run the extra realisations with "
                f"another seed (--set job.seed=...)")
        seen[seed] = s.path
        items = job_items(s.job)
        diff = [f"{k} = {items[k]!r} (in {first.path}: {ref[k]!r})"
                for k in ref if k not in FREE_KEYS and items[k] != ref[k]]
        if diff:
            raise ReduceError(
                f"{s.path} is not the same system as {first.path}; files are reduced "
                f"together only if their jobs differ in {', '.join(sorted(FREE_KEYS))} "
                f"alone. Differences:\n  " + "\n  ".join(diff))


def _read_xy(f, task, committed, names, columns=XY):
    """(len(names), committed) xy stress of one task, committed samples only (with
    ``columns = slice(None)``: (len(names), committed, 6), all components); checks
    that the samples are stored at t_k = k dt (the projection's times are t_k + c dt,
    `sample_offsets`)."""
    from ..ensemble.store import task_key
    group = f[f"tasks/{task_key(task.task_id)}/samples"]
    missing = [n for n in names if n not in group and n not in ABSENT_IS_ZERO]
    if missing:
        raise ReduceError(f"{f.filename}: task {task.task_id} has no sample dataset(s) "
                          f"{', '.join(missing)}; this job's reduction needs them")
    if committed:
        k = np.unique([0, min(committed, 64) - 1, committed - 1])
        t = group["time"][k.tolist()] if "time" in group else k * task.dt
        if not np.allclose(t, k * task.dt, rtol=1e-9, atol=1e-12 * task.dt):
            raise ReduceError(f"{f.filename}: task {task.task_id}: samples are not at "
                              f"t_k = k dt (time[{k.tolist()}] = {t.tolist()})")
    shape = group["stress_hydrodynamic"][:0, columns].shape[1:]
    return np.stack([group[n][:committed, columns] if n in group else np.zeros((committed, *shape))
                     for n in names])


def task_series(job: Job, task, stress, offsets=0.0):
    """Per-value series of one task, (C, Q, n): per whole period (G', G'') after the
    start-up for oscillatory jobs, per sample (eta, N1, N2, Pi) after discard_steps for
    steady ones (docs/physics.md, "Steady shear"). ``stress``: the contributions' stress of the committed
    samples (`read_stress`), (C, committed) xy for oscillatory jobs and (C, committed, 6)
    6-vectors for steady ones; ``offsets``: (C,) or one number, sample k of contribution c
    represents t_k + offsets[c] dt (`sample_offsets`; the projection's sample times).
    Rows follow TABLE_COMPONENTS; the medium row is its exact value repeated and the total row
    is medium + the contributions, value by value."""
    if job.shear.protocol == "oscillatory":
        n = job.steps_per_period(task.omega)
        g1, g2 = project_periods(stress, job.shear.gamma0, task.omega, n, task.discard_steps // n,
                                 t0=np.asarray(offsets, float) * task.dt)
        parts = np.stack([g1, g2], axis=1)                         # (C, 2, P)
        medium = np.array(medium_moduli(job, task.omega))
    else:
        parts = steady_quantities(stress[:, task.discard_steps:], job.shear.rate)  # (C, 4, M)
        medium = np.array([medium_viscosity(job), 0.0, 0.0, 0.0])
    med = np.broadcast_to(medium[:, None], parts.shape[1:])
    return np.concatenate([med[None], parts, (med + parts.sum(axis=0))[None]])


def steady_quantities(stress, rate):
    """(..., n, 6) stress 6-vectors (xx yy zz xy xz yz) -> (..., 4, n): eta, N1, N2, Pi
    per sample in units of eta_m gamma_dot: eta = Sigma_xy, N1 = Sigma_xx - Sigma_yy,
    N2 = Sigma_yy - Sigma_zz, Pi = -tr(Sigma)/3, each over gamma_dot."""
    s = np.moveaxis(np.asarray(stress, float), -1, -2) / rate       # (..., 6, n)
    xx, yy, zz, xy = s[..., 0, :], s[..., 1, :], s[..., 2, :], s[..., 3, :]
    return np.stack([xy, xx - yy, yy - zz, -(xx + yy + zz) / 3.0], axis=-2)


def running_average(x, points=RUNNING_POINTS):
    """Running averages (1/(k+1)) sum_{i <= k} x_i along the last axis, and the indices
    k at which they are kept (about ``points`` of them, geometrically spaced, the last
    sample always included)."""
    x = np.asarray(x, float)
    n = x.shape[-1]
    keep = np.unique(np.concatenate([np.geomspace(1, n, min(points, n)).astype(int) - 1,
                                     [n - 1]])) if n else np.zeros(0, int)
    csum = np.cumsum(x, axis=-1)
    return csum[..., keep] / (keep + 1), keep


def periods_needed(job: Job, task) -> str:
    """What a task needs before it contributes anything, for the notes."""
    if job.shear.protocol == "oscillatory":
        n = job.steps_per_period(task.omega)
        return f"{task.discard_steps + n} steps (discarded start-up + one whole period)"
    return f"more than {task.discard_steps} steps (the discarded start-up)"


# --------------------------------------------------------------------------- reduce


def reduce_runs(paths, medium=None) -> Reduction:
    """Reduce one or several run files of the same system (module docstring).

    medium: None (the run's own medium), or a :class:`sdmpi.config.Medium` applied after
    the fact to the stored viscous hydrodynamic stress (:mod:`.medium_view`); the
    reduction's job then holds that medium. Raises ReduceError for unusable input
    (including a medium that the job cannot take); warns (:class:`PartialRunWarning`)
    when some tasks are unfinished (details in ``Reduction.notes``)."""
    paths = [str(p) for p in paths]
    summaries, job, job_text, viewed = open_runs(paths, medium)
    if job.shear.protocol == "none":
        raise ReduceError(
            f"{paths[0]}: a quiescent job (shear.protocol = \"none\") imposes no "
            f"deformation, so it has no projected moduli or viscosity; its moduli follow "
            f"by Green-Kubo (sdmpi.analysis.at_rest.reduce_at_rest, which `sdmpi reduce` "
            f"uses for it)")
    kind = "oscillatory" if job.shear.protocol == "oscillatory" else "steady"
    columns_read = XY if kind == "oscillatory" else slice(None)

    groups = list(dict.fromkeys((t.phi, t.omega) for t in summaries[0].tasks))
    file_index, realisation, columns = _realisation_columns(summaries, groups)
    notes = []

    n_groups, n_real = len(groups), len(columns)
    series = [[None] * n_real for _ in range(n_groups)]
    running = None
    if kind == "steady":
        n_planned = summaries[0].tasks[0].n_steps
        _, keep = running_average(np.zeros(n_planned))
        running = {"time": keep * summaries[0].tasks[0].dt,
                   "values": np.full((n_groups, len(TABLE_COMPONENTS), len(STEADY_QUANTITIES),
                                      n_real, keep.size), np.nan),
                   "discard_time": job.integration.discard_steps * job.integration.dt}
    committed = np.zeros((n_groups, n_real), dtype=np.int64)
    planned = np.zeros_like(committed)
    task_id = np.zeros_like(committed)
    partial = []
    for i, s in enumerate(summaries):
        with open_read(s.path) as f:
            for col, (fi, tasks) in enumerate(zip(file_index, columns)):
                if fi != i:
                    continue
                for g, task in enumerate(tasks):
                    done = int(s.progress[task.task_id])
                    stress = read_stress(f, job, task, done, viewed, columns_read)
                    stress, stop_note = _until_stop(stress, s.path, task)
                    notes += [stop_note] if stop_note else []
                    x = task_series(job, task, stress, sample_offsets(f, job, task, viewed))
                    if running is not None and done:
                        _running_into(running["values"][g, :, :, col], job, stress, keep)
                    series[g][col] = x
                    committed[g, col], planned[g, col] = done, task.n_steps
                    task_id[g, col] = task.task_id
                    if done < task.n_steps:
                        partial.append((i, task.task_id,
                                        _partial_note(s.path, job, task, done, x.shape[-1])))
    notes += [text for *_, text in sorted(partial)]

    per_real = [[blocking(x) for x in row] for row in series]       # fields (C, Q)
    stacked = _stack_blocking(per_real)                             # fields (G, C, Q, R)
    ens = combine(stacked)                                          # fields (G, C, Q)
    ens = _exact_medium(ens, job, groups, kind)

    notes += _ensemble_notes(ens, groups, kind, job)
    if not np.all(committed == planned):
        warnings.warn(f"partial run: {int(np.sum(committed < planned))} of {committed.size} "
                      f"tasks unfinished; reducing what is committed", PartialRunWarning,
                      stacklevel=2)
    control = np.array([c if kind == "oscillatory" else job.shear.rate for _, c in groups])
    if viewed:
        modes = job.medium.modes or ()
        notes.insert(0, f"medium {job.medium.kind}"
                     + "".join(f" (eta={m.eta:g}, lambda={m.lam:g})" for m in modes)
                     + f" applied after the fact to the viscous hydrodynamic stress of a "
                     f"{summaries[0].job.medium.kind} run (the trajectories are the same)")
    return Reduction(kind, job, job_text, tuple(paths),
                     tuple(s.job.job.seed for s in summaries),
                     np.array([p for p, _ in groups]), control,
                     ("G_prime", "G_dprime") if kind == "oscillatory" else STEADY_QUANTITIES,
                     ens, stacked, np.array(file_index), np.array(realisation), task_id,
                     committed, planned, tuple(notes), running, viewed)


def _realisation_columns(summaries, groups):
    """Every realisation of the run files, in file order: its file index, its index
    within the file, and its task in each group (phi, omega)."""
    file_index, realisation, columns = [], [], []
    for i, s in enumerate(summaries):
        by_group = {}
        for t in s.tasks:
            by_group.setdefault((t.phi, t.omega), []).append(t)
        for r in range(s.job.ensemble.realisations):
            file_index.append(i)
            realisation.append(r)
            columns.append([by_group[key][r] for key in groups])
    return file_index, realisation, columns


def _ensemble_notes(ens: EnsembleEstimate, groups, kind: str, job: Job) -> list[str]:
    """Notes on task groups whose error bars need a caveat: no data yet, a single
    realisation, or fewer than SMALL_ENSEMBLE."""
    notes = []
    for g, (phi, control) in enumerate(groups):
        r = int(ens.n_realisations[g, 0, 0])
        where = f"phi = {phi:g}, " + (f"omega = {control:.6g}" if kind == "oscillatory"
                                      else f"rate = {job.shear.rate:g}")
        if r == 0:
            notes.append(f"{where}: no realisation has data after the start-up yet; its "
                         f"rows are NaN (the medium row is exact)")
        elif r == 1:
            notes.append(f"{where}: a single realisation; its error comes from blocking "
                         f"within that run (dof {int(ens.dof[g, 1, 0])}) and may be too small")
        elif r < SMALL_ENSEMBLE:
            notes.append(f"{where}: only {r} realisations (fewer than {SMALL_ENSEMBLE}): "
                         f"the spread between them is a poor error estimate, so each error "
                         f"is the larger of it and the blocking error within the runs "
                         f"(errors.csv says which)")
    return notes


def open_runs(paths, medium=None):
    """Validate the run files ``paths`` of one system (:func:`open_run`,
    :func:`check_same_system`) and return (summaries, job, job_text, viewed): the first
    file's job, with ``medium`` (not None and not the run's) applied after the fact
    (:mod:`.medium_view`; ``viewed`` True). Raises ReduceError."""
    if not paths:
        raise ReduceError("no run file given")
    summaries = [open_run(p) for p in paths]
    check_same_system(summaries)
    job, job_text, viewed = summaries[0].job, summaries[0].job_text, False
    if medium is not None and medium != job.medium:
        from ..config import canonical_text
        from .medium_view import MediumError, view_job
        try:
            job = view_job(job, medium, paths[0])
        except MediumError as err:
            raise ReduceError(str(err)) from None
        job_text, viewed = canonical_text(job), True
    return summaries, job, job_text, viewed


def _until_stop(stress, path, task):
    """The samples before a stop on an overlap (monolayers, sdmpi.dynamics.monolayer: every
    sample from the stop on is NaN) and a note on the stop (None: no stop)."""
    bad = np.isnan(stress).any(axis=tuple(a for a in range(stress.ndim) if a != 1))
    if not bad.any():
        return stress, None
    stop = int(np.argmax(bad))
    return stress[:, :stop], (
        f"{path}: task {task.task_id} (phi = {task.phi:g}, realisation {task.realisation}) "
        f"stopped on an overlap deeper than integration.overlap_stop at step {stop} "
        f"(t = {stop * task.dt:.4g}); {max(stop - task.discard_steps, 0)} samples after the "
        f"start-up used")


def _running_into(out, job: Job, stress, keep):
    """Running averages of one steady task from t = 0 into out (C, Q, T) at the sample
    indices ``keep`` that it has committed (the rest stays NaN)."""
    parts = steady_quantities(stress, job.shear.rate)                # (C, Q, done)
    medium = np.array([medium_viscosity(job), 0.0, 0.0, 0.0])[:, None]
    full = np.concatenate([np.broadcast_to(medium, parts.shape[1:])[None], parts,
                           (medium + parts.sum(axis=0))[None]])
    have = keep < full.shape[-1]
    out[..., have] = np.cumsum(full, axis=-1)[..., keep[have]] / (keep[have] + 1)


def _stack_blocking(per_real):
    """Blocking results per [group][realisation] with fields (C, Q) -> one Blocking with
    fields (G, C, Q, R), the realisation axis last as :func:`.errors.combine` wants."""
    return Blocking(*(np.stack([np.stack([b[k] for b in row], axis=-1) for row in per_real])
                      for k in range(len(Blocking._fields))))


def _exact_medium(ens: EnsembleEstimate, job: Job, groups, kind) -> EnsembleEstimate:
    """Put the medium's exact values (Schaink et al. eq. 36; steady shear: eta_0m and no normal
    stresses) into row 0 with zero errors, instead
    of the average of identical numbers (equal to round-off) or NaN when no data."""
    mean, err = ens.mean.copy(), ens.err.copy()
    within, between, source = ens.err_within.copy(), ens.err_between.copy(), ens.source.copy()
    for g, (_, omega) in enumerate(groups):
        mean[g, 0] = (medium_moduli(job, omega) if kind == "oscillatory"
                      else (medium_viscosity(job), 0.0, 0.0, 0.0))
        err[g, 0] = within[g, 0] = between[g, 0] = 0.0
        source[g, 0] = SOURCES.index("exact")
    return ens._replace(mean=mean, err=err, err_within=within, err_between=between,
                        source=source)


def _partial_note(path, job: Job, task, done: int, n_values: int) -> str:
    """One line on an unfinished task: how far it got and what of it is used."""
    head = (f"{path}: task {task.task_id} (phi = {task.phi:g}"
            + (f", omega = {task.omega:.6g}" if task.omega is not None else "")
            + f", realisation {task.realisation}) unfinished: {done}/{task.n_steps} steps")
    if job.shear.protocol == "oscillatory":
        n = job.steps_per_period(task.omega)
        used = f"{n_values} of {(task.n_steps - task.discard_steps) // n} periods used"
    else:
        used = f"{n_values} of {task.n_steps - task.discard_steps} samples used"
    if n_values == 0:
        return f"{head}; contributes nothing (needs {periods_needed(job, task)})"
    return f"{head}; {used}"


# --------------------------------------------------------------------------- one task


def task_of(red: Reduction, task_id, file_index=0):
    """The task ``task_id`` of run file ``file_index`` (ReduceError if it has none)."""
    path = red.files[file_index]
    tasks = {t.task_id: t for t in open_run(path).tasks}
    if task_id not in tasks:
        raise ReduceError(f"{path} has no task {task_id} (tasks 0..{len(tasks) - 1})")
    return tasks[task_id]


def lissajous_data(red: Reduction, task_id=None, file_index=0) -> dict:
    """Stress-strain loop of one task (oscillatory jobs), phase-averaged over the
    whole periods it contributes: for each phase j = 0..n-1 of a period (w t = 2 pi j/n)
    the mean over those periods of each contribution's xy stress.

    task_id: a task of file ``file_index``; default, in the first group that has analysed
    periods, the task with the most of them. Returns dict with ``task_id, file, phi, omega,
    gamma0, n_periods``, ``strain`` (n,) = gamma(t_j), ``stress`` (C, n) per TABLE_COMPONENTS
    in eta_m/t_D (medium analytic: gamma0 (G'_m sin + G''_m cos)), ``sample_offset`` (C,)
    the time stress[c, j] represents, (j + sample_offset[c]) dt (`sample_offsets`; 0 for
    the medium and the total), and ``last`` (n,) the total stress of the last analysed
    period, unaveraged."""
    if red.kind != "oscillatory":
        raise ReduceError("a Lissajous figure needs an oscillatory job")
    job = red.job
    if task_id is None:
        cols = np.flatnonzero(red.file_index == file_index)
        used = red.per_realisation.n[:, 1, 0][:, cols]                 # (G, R of the file)
        g = int(np.argmax(used.max(axis=1) > 0))     # the first group with data (else 0)
        task_id = int(red.task_id[g, cols[int(np.argmax(used[g]))]])
    path = red.files[file_index]
    task = task_of(red, task_id, file_index)
    n = job.steps_per_period(task.omega)
    first = task.discard_steps // n
    cols = np.flatnonzero(red.file_index == file_index)
    done = int(red.committed[:, cols][red.task_id[:, cols] == task_id][0])
    with open_read(path) as f:
        xy = read_stress(f, job, task, done, red.viewed)
        offsets = np.concatenate([[0.0], sample_offsets(f, job, task, red.viewed), [0.0]])
    n_periods = max(done // n - first, 0)
    if n_periods == 0:
        raise ReduceError(f"task {task_id} has no whole period after the start-up yet")
    cycles = xy[:, first * n:(first + n_periods) * n].reshape(len(xy), n_periods, n)
    phase = 2.0 * np.pi * np.arange(n) / n
    gamma0 = job.shear.gamma0
    g1, g2 = medium_moduli(job, task.omega)
    medium = gamma0 * (g1 * np.sin(phase) + g2 * np.cos(phase))
    parts = cycles.mean(axis=1)
    stress = np.concatenate([medium[None], parts, (medium + parts.sum(axis=0))[None]])
    return {"task_id": task_id, "file": path, "phi": task.phi, "omega": task.omega,
            "realisation": task.realisation, "gamma0": gamma0, "n_periods": n_periods,
            "strain": gamma0 * np.sin(phase), "stress": stress, "sample_offset": offsets,
            "last": medium + cycles[:, -1].sum(axis=0)}
