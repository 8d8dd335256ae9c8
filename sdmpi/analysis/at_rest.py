"""Reduce run files at rest (``shear.protocol = "none"``) by Green-Kubo: G(t), G'(w), G''(w).

The estimator is :mod:`.green_kubo`'s; this module reads the run files (the checks of
:func:`.reduce.reduce_runs`: intact files of one system, distinct seeds, committed
samples only) and writes the tables. Per task, the stress 6-vectors of the
configurational contributions (:data:`STREAMS`: Brownian, interparticle, collision) after
``integration.discard_steps`` are correlated with their sum. Rows of ``moduli_gk.csv``
(the columns of moduli.csv):

* ``medium``: exact (Schaink et al. 2000 eq. 36);
* ``hydrodynamic``: instantaneous, eta_H times the medium's moduli, eta_H = eta'_inf - 1
  (Schaink et al. 2000, eqs. 32-38): 5/2 phi for free draining (exact); with
  hydrodynamic interactions from the committed trajectory frames, one
  :func:`sdmpi.hydro.bulk.hydrodynamic_viscosity` per frame, errors by
  :func:`.errors.ensemble_average`; NaN without frames or with lubrication settings that
  :func:`sdmpi.hydro.solve_mobility` does not take (:func:`hydrodynamic_settings`);
* ``brownian``, ``interparticle``, ``collision``: Green-Kubo cross-correlations with the
  configurational stress, lags 0-4 by the short-time rule (:func:`default_lag0`:
  ``contact`` without lubrication, ``lag1`` with it);
* ``total``: their sum (NaN where the hydrodynamic row is), errors in quadrature.

Validated for free draining only (tests/test_green_kubo.py); with hydrodynamic
interactions the reduction warns (``green_kubo.json``, terminal). The manual, and what
agrees with oscillatory runs: docs/reduce.md, "Runs at rest: Green-Kubo";
docs/validation/green_kubo/.

Units: t and 1/omega in t_D, G, G', G'' in eta_m/t_D, eta', eta'' relative to eta_m.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..config.stresses import CONTRIBUTIONS
from ..ensemble.h5 import open_read
from ..registry import HYDRODYNAMIC_MODELS
from . import green_kubo as gk
from .reduce import (MODULI_COLUMNS, TABLE_COMPONENTS, PartialRunWarning, ReduceError,
                     medium_moduli, open_runs, read_stress)

#: the configurational contributions correlated at rest (the rows of relaxation.csv
#: before their sum, "total")
STREAMS = tuple(c.component for c in CONTRIBUTIONS[1:])
#: relaxation.csv columns
RELAXATION_COLUMNS = ("phi", "lag", "t", "component", "n_realisations", "G", "G_err")
#: relaxation.csv components: the streams and their sum (the configurational stress)
RELAXATION_COMPONENTS = STREAMS + ("total",)
#: hydrodynamic models whose Green-Kubo moduli are validated (module docstring)
VALIDATED_MODELS = ("free-draining",)
#: the shortest window in lags (the contact rule fits lags 5-20)
MIN_LAGS = 32
#: the Einstein coefficient: free-draining hydrodynamic stress 5/2 phi x the medium's
EINSTEIN = 2.5


@dataclass(frozen=True)
class Group:
    """One volume fraction: dt, box volume, window (max_lag steps), the reported lags and
    frequencies, the ensembles of G(t) (fields (S + 1, L)) and of (G', G'') (fields
    (S + 1, 2, W)), per-realisation G(t) of the sum (R, L; NaN when absent), per
    realisation the file index and task id, the tail check and ``hydro``: the
    :class:`Hydrodynamic` factor of the hydrodynamic row."""
    phi: float
    dt: float
    volume: float
    max_lag: int
    lags: np.ndarray
    omega: np.ndarray
    relaxation: object
    moduli: object
    per_realisation: np.ndarray
    file_index: tuple
    task_id: tuple
    tail: tuple
    hydro: "Hydrodynamic"
    #: the rows of ``relaxation``, in order
    components: tuple = RELAXATION_COMPONENTS


class Hydrodynamic(NamedTuple):
    """The hydrodynamic row of a group as eta_H times the medium's moduli: ``eta_h`` and
    its standard error ``err`` (NaN when unknown), the configurations it rests on
    (``frames``, 0 when exact or unknown) and how it was obtained (``how``)."""
    eta_h: float
    err: float
    frames: int
    how: str


@dataclass(frozen=True)
class RestReduction:
    """The Green-Kubo reduction of runs at rest (module docstring)."""
    job: object
    job_text: str
    files: tuple
    seeds: tuple
    groups: tuple
    lag0: str
    validated: bool
    warnings: tuple
    notes: tuple
    committed: np.ndarray
    n_steps: np.ndarray
    viewed: bool = False
    #: the table kind (:func:`.report.format_table` prints its moduli columns)
    kind = "green-kubo"
    columns = MODULI_COLUMNS

    @property
    def complete(self) -> bool:
        return bool(np.all(self.committed == self.n_steps))

    def relaxation_rows(self) -> list[dict]:
        out = []
        for g in self.groups:
            e = g.relaxation
            for i, lag in enumerate(g.lags):
                for c, name in enumerate(RELAXATION_COMPONENTS):
                    out.append({"phi": g.phi, "lag": int(lag), "t": float(lag * g.dt),
                                "component": name,
                                "n_realisations": int(e.n_realisations[c, i]),
                                "G": float(e.mean[c, i]), "G_err": float(e.err[c, i])})
        return out

    def rows(self) -> list[dict]:
        """moduli_gk.csv, one dict per (phi, omega, component)."""
        out = []
        for g in self.groups:
            e = g.moduli
            for k, w in enumerate(g.omega):
                med = np.array(medium_moduli(self.job, w))
                n = int(e.n_realisations[-1, 0, k])
                values = {"medium": (med, np.zeros(2)),
                          "hydrodynamic": (g.hydro.eta_h * med, g.hydro.err * np.abs(med))}
                for c, name in enumerate(STREAMS):
                    values[name] = (e.mean[c, :, k], e.err[c, :, k])
                hyd, hyd_err = values["hydrodynamic"]
                values["total"] = (med + hyd + e.mean[-1, :, k],
                                   np.hypot(hyd_err, e.err[-1, :, k]))
                for name in TABLE_COMPONENTS:
                    (g1, g2), (s1, s2) = values[name]
                    out.append({"phi": g.phi, "omega": float(w), "component": name,
                                "n_realisations": n, "G_prime": float(g1),
                                "G_prime_err": float(s1), "G_dprime": float(g2),
                                "G_dprime_err": float(s2), "eta_prime": float(g2 / w),
                                "eta_prime_err": float(s2 / w), "eta_dprime": float(g1 / w),
                                "eta_dprime_err": float(s1 / w)})
        return out

    def value(self, phi, omega, component, column):
        """One moduli_gk.csv entry (phi, omega matched to 1e-9 relative)."""
        for row in self.rows():
            if (row["component"] == component and math.isclose(row["phi"], phi, rel_tol=1e-9)
                    and math.isclose(row["omega"], omega, rel_tol=1e-9)):
                return row[column]
        raise KeyError(f"no row phi={phi}, omega={omega}, {component}")

    def metadata(self) -> dict:
        """green_kubo.json: the method, its choices and limits, per group (module
        docstrings of this module and :mod:`.green_kubo`)."""
        job = self.job
        return {
            "format": "sdmpi-green-kubo", "format_version": 1,
            "method": "Green-Kubo at rest: G_A(t) = (V/kT) <sigma_A(t) sigma_C(0)>, sigma_C "
                      "the configurational (Brownian + interparticle + collision) stress, "
                      "averaged over the five deviatoric components xy, xz, yz, (xx-yy)/2, "
                      "(xx+yy-2zz)/(2 sqrt3) (Daivis & Evans 1994); G*(w) = i w int_0^t_M "
                      "G(t) exp(-i w t) dt by the trapezoid rule from t = 0 on lags m dt",
            "kT": 6 * math.pi, "kT_unit": "eta_m a^3 / t_D",
            "hydrodynamics_model": job.hydrodynamics.model,
            "validated": self.validated,
            "lag0_rule": self.lag0,
            "lag0_rule_meaning": {
                "keep": "every lag as sampled (lags 0-4 carry the overlap correction's "
                        "and the Brownian estimator's per-step artefacts)",
                "lag1": "the lag-0 correlation replaced by the lag-1 value (removes white "
                        "per-step estimator noise only)",
                "contact": f"lags 0-{gk.CONTACT_REPLACED - 1} replaced by the step means "
                           f"of c t^-1/2 + b fitted to lags {gk.CONTACT_FIT_LAGS[0]}-"
                           f"{gk.CONTACT_FIT_LAGS[-1]} (the hard-sphere short-time form); "
                           "measured on free draining against the exact dilute G(t): the "
                           "sampled lags 0-4 are 2.6, 0.62, 0.95, 1.02, 1.09 times exact, "
                           "lags 5-32 1.13-1.20 (the O(phi^3) excess)",
                "linear": f"lags 0-{gk.CONTACT_REPLACED - 1} replaced by the straight line "
                          f"a + b t fitted to lags {gk.CONTACT_FIT_LAGS[0]}-"
                          f"{gk.CONTACT_FIT_LAGS[-1]} (a G(t) finite and smooth at t = 0, as "
                          "with full lubrication)"}[self.lag0],
            "hydrodynamic_row": "eta_H x the medium's moduli, eta_H per group (eta_h, "
                                "eta_h_err, eta_h_frames, eta_h_how)",
            "errors": "one standard error: per realisation, Flyvbjerg-Petersen blocking of "
                      f"{gk.BASE_BLOCKS} blocks of time origins; over realisations the "
                      "larger of the between spread and the propagated within errors "
                      "(realisations weighted by their number of time origins)",
            "omega_grid": f"2 pi 2^(j/{gk.POINTS_PER_OCTAVE}) from 1/t_M to "
                          f"{gk.MAX_OMEGA_DT}/dt",
            "groups": [{"phi": g.phi, "dt": g.dt, "volume": g.volume, "window": g.max_lag * g.dt,
                        "max_lag": g.max_lag, "omega_min": float(g.omega[0]) if g.omega.size
                        else None, "omega_max": float(g.omega[-1]) if g.omega.size else None,
                        "n_realisations": int(g.relaxation.n_realisations[-1, 0]),
                        "tail_decayed": g.tail[0], "tail_mean": g.tail[1],
                        "tail_err": g.tail[2], "eta_h": g.hydro.eta_h,
                        "eta_h_err": g.hydro.err, "eta_h_frames": g.hydro.frames,
                        "eta_h_how": g.hydro.how} for g in self.groups],
            "units": {"t": "t_D", "omega": "1/t_D", "G": "eta_m/t_D", "G_prime": "eta_m/t_D",
                      "G_dprime": "eta_m/t_D", "eta_prime": "eta_m", "eta_dprime": "eta_m",
                      "volume": "a^3", "dt": "t_D", "window": "t_D"},
            "warnings": list(self.warnings), "notes": list(self.notes),
            "input_files": list(self.files), "seeds": list(self.seeds),
            "medium_applied": int(self.viewed), "job_text": self.job_text,
        }


def quiescent(path) -> bool:
    """Whether ``path`` is a run file of a job at rest (shear.protocol = "none"); False
    for anything unreadable (the reducer then says why)."""
    import tomllib
    try:
        with open_read(path) as f:
            text = f.attrs["job_text"]
        text = text.decode() if isinstance(text, bytes) else str(text)
        return tomllib.loads(text)["shear"]["protocol"] == "none"
    except Exception:  # noqa: BLE001 - any failure: not recognisably a run at rest
        return False


def default_lag0(job) -> str:
    """The short-time rule a run at rest gets by default: "contact" without lubrication
    (a G(t) rising as t^-1/2 at short times, validated for free draining), "lag1" with it
    (a G(t) finite at t = 0, where "contact" over-reads G'' at high frequency:
    docs/validation/green_kubo/README.md)."""
    hyd = job.hydrodynamics
    return "lag1" if HYDRODYNAMIC_MODELS[hyd.model].lubrication and hyd.lubrication else "contact"


def reduce_at_rest(paths, *, window=None, lag0=None, medium=None, omega=None) -> RestReduction:
    """Green-Kubo reduction of one or several run files at rest of the same system.

    window: t_M in t_D (default: :data:`.green_kubo.WINDOW_FRACTION` of the longest
    analysed realisation of each group); lag0: :data:`.green_kubo.LAG0_RULES` (default
    "contact", the only one validated); medium: as :func:`.reduce.reduce_runs`
    (the medium and hydrodynamic rows); omega: the frequencies (1/t_D) to report instead
    of the grid :func:`.green_kubo.omega_grid` (each in (0, MAX_OMEGA_DT/dt]). Raises
    ReduceError for unusable input; warns (:class:`.reduce.PartialRunWarning`) for
    unfinished tasks."""
    paths = [str(p) for p in paths]
    summaries, job, job_text, viewed = open_runs(paths, medium)
    if job.shear.protocol != "none":
        raise ReduceError(f"{paths[0]}: Green-Kubo needs a run at rest "
                          f"(shear.protocol = \"none\"), not {job.shear.protocol!r}")
    if job.system.geometry != "bulk":
        raise ReduceError(f"{paths[0]}: Green-Kubo needs an isotropic bulk suspension; "
                          f"system.geometry = {job.system.geometry!r} is not reduced at rest")
    model = job.hydrodynamics.model
    rule = lag0 or default_lag0(job)
    if rule not in gk.LAG0_RULES:
        raise ReduceError(f"lag0 = {rule!r}; allowed: {', '.join(gk.LAG0_RULES)}")
    if window is not None and not (window > 0 and math.isfinite(window)):
        raise ReduceError(f"--gk-window = {window!r}: must be a positive time in t_D")
    validated = model in VALIDATED_MODELS and rule == "contact"
    warn = [] if validated else [
        f"Green-Kubo with hydrodynamics.model = {model!r} and lag-0 rule {rule!r} is NOT "
        f"validated (only free draining is): the sampled Brownian stress carries per-step "
        f"estimator noise (the short-time rule removes it where it is white) and "
        f"lubrication changes the short-time form; compare with oscillatory runs before "
        f"using these moduli (docs/validation/green_kubo/README.md says what agrees)"]
    tasks = []                                    # (file index, task) over all files
    for i, s in enumerate(summaries):
        tasks += [(i, t) for t in s.tasks]
    groups, notes, partial = [], [], []
    for phi in dict.fromkeys(t.phi for _, t in tasks):
        members = [(i, t) for i, t in tasks if t.phi == phi]
        group = _reduce_group(float(phi), members, summaries, paths, job, viewed, window,
                              omega, rule, notes, partial)
        groups.append(group)
    if partial:
        warnings.warn(f"partial run: {len(partial)} of {len(tasks)} tasks unfinished; "
                      f"reducing what is committed", PartialRunWarning, stacklevel=2)
    committed = np.array([int(summaries[i].progress[t.task_id]) for i, t in tasks])
    planned = np.array([t.n_steps for _, t in tasks])
    return RestReduction(job, job_text, tuple(paths), tuple(s.job.job.seed for s in summaries),
                         tuple(groups), rule, validated, tuple(warn), tuple(partial + notes),
                         committed, planned, viewed)


def _window(phi, members, summaries, window, omega):
    """(dt, max_lag, samples needed per realisation, lags, omega) of one group; ReduceError
    when no realisation is long enough or a frequency is outside (0, MAX_OMEGA_DT/dt]."""
    lengths = [max(int(summaries[i].progress[t.task_id]) - t.discard_steps, 0)
               for i, t in members]
    dt, longest = members[0][1].dt, max(lengths)
    max_lag = (int(round(window / dt)) if window is not None
               else int(gk.WINDOW_FRACTION * longest))
    need = 2 * max_lag + gk.BASE_BLOCKS
    if max_lag < MIN_LAGS or longest < need:
        raise ReduceError(
            f"phi = {phi:g}: Green-Kubo with a window of {max_lag} lags "
            f"({max_lag * dt:.4g} t_D; at least {MIN_LAGS}) needs {need} samples after "
            f"the start-up in a realisation (twice the window plus {gk.BASE_BLOCKS}); "
            f"the longest has {longest}: nothing to reduce ("
            + ("a longer --gk-window" if max_lag < MIN_LAGS else
               "a shorter --gk-window, or longer runs") + ")")
    if omega is None:
        omega = gk.omega_grid(dt, max_lag * dt)
    else:
        omega = np.array(omega, float).ravel()
        if not np.all((omega > 0) & (omega <= gk.MAX_OMEGA_DT / dt * (1 + 1e-12))):
            raise ReduceError(f"omega = {list(omega)}: each must lie in (0, "
                              f"{gk.MAX_OMEGA_DT / dt:.6g}] (MAX_OMEGA_DT/dt at dt = {dt:g})")
    return dt, max_lag, need, gk.report_lags(max_lag), omega


def _reduce_group(phi, members, summaries, paths, job, viewed, window, omega, rule, notes,
                  partial) -> Group:
    """One volume fraction's :class:`Group` from its (file index, task) members; appends
    to ``notes`` and ``partial`` what the reduction should say."""
    from ..ensemble.store import task_key
    dt, max_lag, need, lags, omega = _window(phi, members, summaries, window, omega)
    values, frames, volume = [], [], None
    for i, t in members:
        done = int(summaries[i].progress[t.task_id])
        n = max(done - t.discard_steps, 0)
        if done < t.n_steps:
            partial.append(f"{paths[i]}: task {t.task_id} (phi = {phi:g}, realisation "
                           f"{t.realisation}) unfinished: {done}/{t.n_steps} steps")
        if n < need:
            values.append(None)
            notes.append(f"{paths[i]}: task {t.task_id} (phi = {phi:g}) has {n} samples "
                         f"after the start-up; Green-Kubo needs {need} (twice the window "
                         f"of {max_lag} lags plus {gk.BASE_BLOCKS}): contributes nothing")
            continue
        with open_read(paths[i]) as f:
            box = np.array(f[f"tasks/{task_key(t.task_id)}"].attrs["box"], float)
            stress = read_stress(f, job, t, done, viewed, slice(None))[1:]
        volume = float(np.prod(box))
        values.append(gk.realisation_values(stress[:, t.discard_steps:], dt, volume,
                                            gk_kt(), max_lag, omega, lags, rule))
        frames.append((paths[i], t, box))
    relax, mod = gk.ensemble(values)
    per = np.array([v.relaxation.mean[-1] if v is not None else np.full(lags.size, np.nan)
                    for v in values])
    tail = gk.tail_check(relax.mean[-1], relax.err[-1])
    if not tail[0]:
        notes.append(f"phi = {phi:g}: G(t) has not decayed within the window "
                     f"t_M = {max_lag * dt:.4g} t_D (its last tenth averages "
                     f"{tail[1]:.3g} +- {tail[2]:.3g}): the moduli miss the tail; "
                     f"use a longer window (--gk-window) or longer runs")
    r = int(relax.n_realisations[-1, 0])
    if r < 4:
        notes.append(f"phi = {phi:g}: only {r} realisation(s): the error bars rest on "
                     f"few runs")
    hydro = hydrodynamic_factor(job, phi, frames)
    if math.isnan(hydro.eta_h):
        notes.append(f"phi = {phi:g}: hydrodynamic and total rows NaN: {hydro.how}")
    return Group(phi, float(dt), volume, max_lag, lags, omega, relax, mod, per,
                 tuple(i for i, _ in members), tuple(t.task_id for _, t in members), tail,
                 hydro)


def hydrodynamic_settings(job):
    """The :func:`sdmpi.hydro.solve_mobility` keywords that reproduce the job's
    hydrodynamic stresslets at unit rate (far field to ``hydrodynamics.ewald_tolerance``,
    lubrication when the model has it and ``hydrodynamics.lubrication`` is on, the job's
    solver backend), or a str saying why none do: solve_mobility applies lubrication with
    the default cut-off and minimum gap of :mod:`sdmpi.hydro.lubrication` only."""
    from ..hydro.lubrication import DEFAULT_CUTOFF, DEFAULT_MIN_GAP
    hyd = job.hydrodynamics
    lubrication = HYDRODYNAMIC_MODELS[hyd.model].lubrication and hyd.lubrication
    if lubrication and (hyd.lubrication_cutoff, hyd.min_gap) != (DEFAULT_CUTOFF,
                                                                 DEFAULT_MIN_GAP):
        return (f"eta_H from frames needs hydrodynamics.lubrication_cutoff = "
                f"{DEFAULT_CUTOFF:g} and hydrodynamics.min_gap = {DEFAULT_MIN_GAP:g} (the "
                f"job has {hyd.lubrication_cutoff:g}, {hyd.min_gap:g})")
    return dict(lubrication=bool(lubrication), ewald_tol=job.ewald_tolerance,
                solver=job.solver.backend)


def frame_viscosities(path, task, box, settings) -> np.ndarray:
    """eta_H (:func:`sdmpi.hydro.bulk.hydrodynamic_viscosity`, relative to eta_m) of each
    committed trajectory frame of ``task`` in the run file ``path`` taken at or after
    ``task.discard_steps``, in the periodic ``box``, solved with ``settings``
    (:func:`hydrodynamic_settings`); empty when the file keeps no frames."""
    from ..ensemble.trajectory import group_name
    from ..hydro.bulk import hydrodynamic_viscosity
    from .trajectories import groups, read
    name = group_name(task.task_id)
    if name not in groups(path):
        return np.zeros(0)
    traj = read(path, name)
    with open_read(path) as f:
        radii = np.array(f[f"particles/{name}/radius"], float)
    keep = np.flatnonzero(traj.step >= task.discard_steps)
    return np.array([hydrodynamic_viscosity(traj.positions[k], box, radii=radii,
                                            strain=float(np.nan_to_num(traj.strain[k])),
                                            **settings) for k in keep])


def hydrodynamic_factor(job, phi, frames) -> Hydrodynamic:
    """The group's :class:`Hydrodynamic`: free draining 5/2 phi (Einstein, exact); with
    hydrodynamic interactions the ensemble average of :func:`frame_viscosities` over the
    realisations ``frames`` ((path, task, box) each), NaN with the reason when
    there are no frames or :func:`hydrodynamic_settings` has none."""
    from .errors import ensemble_average
    if not HYDRODYNAMIC_MODELS[job.hydrodynamics.model].solves:
        return Hydrodynamic(EINSTEIN * phi, 0.0, 0, "5/2 phi (free draining, exact)")
    settings = hydrodynamic_settings(job)
    if isinstance(settings, str):
        return Hydrodynamic(math.nan, math.nan, 0, settings)
    values = [frame_viscosities(path, t, box, settings) for path, t, box in frames]
    count = sum(v.size for v in values)
    if count == 0:
        return Hydrodynamic(math.nan, math.nan, 0, "no trajectory frames after the start-up "
                            "(output.trajectory_every = K > 0 keeps them)")
    e = ensemble_average([v for v in values if v.size])
    return Hydrodynamic(float(e.mean), float(e.err), count,
                        f"(1/V) sum S_H,xy per unit shear rate (sdmpi.hydro.bulk."
                        f"hydrodynamic_viscosity) of {count} trajectory frames after the "
                        f"start-up, averaged over the realisations")


def gk_kt() -> float:
    """kT in reduced units: 6 pi eta_m a^3 / t_D (t_D = 6 pi eta_m a^3 / kT)."""
    from ..dynamics.realisation import KT_REDUCED
    return KT_REDUCED


# --------------------------------------------------------------------------- writing


def write_at_rest(red: RestReduction, outdir, *, plots=True, task_id=None):
    """Write ``relaxation.csv``, ``moduli_gk.csv``, ``green_kubo.json`` and (``plots``)
    ``green_kubo_phi<phi>.png`` into ``outdir``, each whole or not at all
    (:func:`.report.staged`). task_id: a task of the first file whose own G(t) the figure
    shows beside the ensemble's (ReduceError if the file has none). Returns (paths,
    notes)."""
    from .report import staged, write_table
    if task_id is not None and not any(task_id in g.task_id and g.file_index[
            g.task_id.index(task_id)] == 0 for g in red.groups):
        n = sum(len(g.task_id) for g in red.groups)
        raise ReduceError(f"{red.files[0]} has no task {task_id} (tasks 0..{n - 1})")

    def produce(staging):
        paths = [write_table(red.relaxation_rows(), RELAXATION_COLUMNS,
                              staging / "relaxation.csv"),
                 write_table(red.rows(), MODULI_COLUMNS, staging / "moduli_gk.csv")]
        text = json.dumps(red.metadata(), indent=1, sort_keys=True, allow_nan=True) + "\n"
        (staging / "green_kubo.json").write_text(text)
        paths.append(staging / "green_kubo.json")
        if plots:
            from .plots import plot_green_kubo
            paths += [plot_green_kubo(red, g, staging / f"green_kubo_phi{g.phi:g}.png", task_id)
                      for g in red.groups]
        return paths, []
    return staged(outdir, produce)
