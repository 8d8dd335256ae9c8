"""Figures of a reduced oscillatory ensemble (matplotlib, Agg, PNG).

* :func:`plot_moduli`: G'(w) and G''(w) per contribution, log-log, one standard error
  bars; the medium (exact, Schaink et al. eq. 36) as a curve. Log axes cannot show values <= 0
  (e.g. G' of a Newtonian medium, or a noisy small contribution): those points are
  left out and the legend says how many.
* :func:`plot_viscosities`: eta'(w) = G''/w and eta''(w) = G'/w (Schaink et al. eq. 19) relative to
  eta_m, log w, linear eta; the medium curve and Schaink et al.'s prediction of the
  hydrodynamic part: eq. 38 eta_H(phi) (w-independent) in a Newtonian medium, eqs. 41-42
  (eta*_H(w) = eta_H(phi) eta*_m(w)/eta_0m, with eq. 38's eta_H) in a Maxwell medium.
* :func:`plot_lissajous`: stress-strain loops of one task, phase-averaged over its
  analysed periods, per contribution.

Steady shear:

* :func:`plot_running`: running averages (1/t) int_0^t of eta, N1, N2 and Pi per
  contribution from t = 0 (Dratler & Schowalter 1996, Figs. 9-10), the mean over realisations
  as thick lines and each realisation's total as thin lines; the discarded start-up shaded and
  the reported mean +- its 95% confidence interval (from the samples after it) as a band.

Units: w in 1/t_D, moduli in eta_m/t_D, viscosities relative to eta_m; steady shear: t
in the job's time unit, N1, N2, Pi in eta_m gamma_dot. Figures are built
on :class:`matplotlib.figure.Figure` (no pyplot state, no display needed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .analytic import maxwell_eta_h, schaink_eta_h
from .reduce import TABLE_COMPONENTS, lissajous_data, medium_moduli

STYLE = {  # component -> (colour, marker)
    "medium": ("0.35", None),
    "hydrodynamic": ("tab:blue", "o"),
    "brownian": ("tab:orange", "s"),
    "interparticle": ("tab:green", "^"),
    "collision": ("tab:red", "v"),
    "total": ("black", "D"),
}
LABEL = {"medium": "medium (exact, Schaink et al. 2000 eq. 36)", "hydrodynamic": "hydrodynamic",
         "brownian": "Brownian", "interparticle": "interparticle", "collision": "collision",
         "total": "total"}


def _figure(ncols, width=11.0, height=5.6):
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, height), layout="constrained")
    return fig, fig.subplots(1, ncols, squeeze=False)[0]


def _title(red, phi):
    job = red.job
    medium = job.medium.kind
    if job.medium.modes:
        medium += " (" + ", ".join(f"η={m.eta:g}, λ={m.lam:g} t_D" for m in job.medium.modes) + ")"
    n = ", ".join(sorted({str(int(k)) for k in red.ensemble.n_realisations[red.phi == phi, 1, 0]}))
    partial = "" if red.complete else ", PARTIAL RUN"
    return (f"{job.job.name}: φ = {phi:g}, N = {job.system.n_particles}, {medium} medium, "
            f"γ0 = {job.shear.gamma0:g}, realisations {n}{partial}")


def _active(red, sel):
    """Components worth drawing: the medium, the total, and parts not identically zero."""
    keep = []
    for c, name in enumerate(TABLE_COMPONENTS):
        m = red.ensemble.mean[sel, c]
        if name in ("medium", "total") or np.any(np.abs(m[np.isfinite(m)]) > 0):
            keep.append((c, name))
    return keep


def log_axes(ax, values):
    """Log-log axes; y limits from the shown values (not from error bars reaching
    towards zero); ticks at 1-2-5 with plain numbers on axes spanning < 2.5 decades."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    values = values[np.isfinite(values) & (values > 0)]
    if values.size:
        ax.set_ylim(values.min() / 2.0, values.max() * 2.0)
    else:   # nothing positive to show (all values <= 0 or unknown): a fixed range
        ax.set_ylim(1e-3, 1.0)
        ax.text(0.5, 0.5, "no positive values", transform=ax.transAxes, ha="center",
                color="0.5")
    for axis, (lo, hi) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        _plain_log_ticks(axis, lo, hi)


def _plain_log_ticks(axis, lo, hi):
    """1-2-5 ticks labelled as plain numbers on a log axis spanning < 2.5 decades."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter
    if np.log10(hi / lo) < 2.5:
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(NullFormatter())


def legend_below(ax):
    """Legend below the axes, clear of the data."""
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2,
              frameon=False)


def _dodge(w, k):
    """Offset points of the k-th drawn component by a few % in omega (log axis) so that
    error bars at the same frequency do not hide each other."""
    return w * 1.025 ** (k - 1.5)


def _omega_grid(omega):
    lo, hi = np.nanmin(omega), np.nanmax(omega)
    return np.geomspace(lo / 1.5, hi * 1.5, 200)


def plot_moduli(red, path, phi) -> Path:
    """G', G'' vs w (log-log, error bars) per contribution at one phi."""
    sel = red.phi == phi
    w = red.control[sel]
    fig, (a1, a2) = _figure(2)
    grid = _omega_grid(w)
    for q, ax, name in ((0, a1, "G′"), (1, a2, "G″")):
        shown = []
        for c, comp in _active(red, sel):
            colour, marker = STYLE[comp]
            if comp == "medium":
                curve = np.array([medium_moduli(red.job, x)[q] for x in grid])
                if np.any(curve > 0):
                    shown.append(curve[curve > 0])
                    ax.plot(grid, curve, "-", color=colour, lw=1.5, label=LABEL[comp])
                else:
                    ax.plot([], [], "-", color=colour, label=LABEL[comp] + ": 0, not shown")
                continue
            m, e = red.ensemble.mean[sel, c, q], red.ensemble.err[sel, c, q]
            ok = np.isfinite(m) & (m > 0)
            shown.append(m[ok])
            # a bar reaching zero or below runs off the bottom of the log axis
            lower = np.where(m - e > 0, e, m * (1 - 1e-9))
            label = LABEL[comp] + (f" ({int(np.sum(~ok))} value(s) ≤ 0 not shown)"
                                   if np.any(~ok & np.isfinite(m)) else "")
            ax.errorbar(_dodge(w, c)[ok], m[ok], yerr=[lower[ok], e[ok]], fmt=marker + "-",
                        color=colour, ms=5, lw=1, capsize=3, label=label)
        log_axes(ax, np.concatenate(shown))
        _frequency_axes(ax, f"{name}  [η_m/t_D]", f"{name}(ω)")
    return _save(fig, red, phi, path)


def _frequency_axes(ax, ylabel, title):
    """Labels, grid and legend of a panel against the frequency."""
    ax.set_xlabel("ω  [1/t_D]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.25)
    legend_below(ax)


def _save(fig, red, phi, path) -> Path:
    """Title (system and error-bar convention) and PNG output of a moduli/viscosity figure."""
    fig.suptitle(_title(red, phi) + "\nbars: ± one standard error; points offset by a few % in ω "
                 "for legibility", fontsize=10)
    fig.savefig(path, dpi=120)
    return Path(path)


def hydrodynamic_prediction(job, phi, omega):
    """Schaink et al.'s hydrodynamic (eta'_H, eta''_H) relative to eta_m: eq. 38
    (w-independent, eta''_H = 0) for a Newtonian medium, eqs. 41-42 with eq. 38's
    eta_H(phi) for a Maxwell medium; eq. 38 is a fit for 0 <= phi <= 0.45."""
    omega = np.asarray(omega, float)
    eta_h = schaink_eta_h(phi)
    if job.medium.kind == "maxwell":
        modes = job.medium.modes
        eta = np.array([m.eta for m in modes])
        return maxwell_eta_h(omega, eta_h / eta.sum(), eta, [m.lam for m in modes])
    return np.full_like(omega, eta_h), np.zeros_like(omega)


def plot_viscosities(red, path, phi) -> Path:
    """eta', eta'' vs w per contribution at one phi, with the analytic medium curve and
    Schaink et al.'s hydrodynamic prediction (eq. 38; eqs. 41-42 for Maxwell media)."""
    sel = red.phi == phi
    w = red.control[sel]
    grid = _omega_grid(w)
    fig, (a1, a2) = _figure(2)
    maxwell = red.job.medium.kind == "maxwell"
    pred = hydrodynamic_prediction(red.job, phi, grid)
    pred_label = ("hydrodynamic, Schaink et al. eqs. 41-42 with η_H(φ) of eq. 38" if maxwell
                  else "hydrodynamic, Schaink et al. eq. 38 (ω-independent)")
    for q, ax, name in ((1, a1, "η′"), (0, a2, "η″")):
        # eta' = G''/w (quantity 1), eta'' = G'/w (quantity 0)
        for c, comp in _active(red, sel):
            colour, marker = STYLE[comp]
            if comp == "medium":
                curve = np.array([medium_moduli(red.job, x)[q] for x in grid]) / grid
                ax.plot(grid, curve, "-", color=colour, lw=1.5, label=LABEL[comp])
                continue
            m, e = red.ensemble.mean[sel, c, q] / w, red.ensemble.err[sel, c, q] / w
            ax.errorbar(_dodge(w, c), m, yerr=e, fmt=marker, color=colour, ms=5, capsize=3,
                        label=LABEL[comp])
        ax.plot(grid, pred[0 if q == 1 else 1], "--", color=STYLE["hydrodynamic"][0], lw=1.2,
                label=pred_label)
        ax.axhline(0.0, color="0.7", lw=0.6)
        ax.set_xscale("log")
        _plain_log_ticks(ax.xaxis, *ax.get_xlim())
        _frequency_axes(ax, f"{name} / η_m", f"{name}(ω) = {'G″' if q == 1 else 'G′'}/ω  (Schaink et al. eq. 19)")
    return _save(fig, red, phi, path)


def plot_lissajous(red, path, task_id=None, file_index=0) -> Path:
    """Stress-strain (Lissajous) figure of one task. Per contribution, the ellipse of
    its first harmonic, gamma0 (G' sin + G'' cos) with this task's G', G'' (the
    projection of the phase-averaged signal at its sample times, eq. 18); the total stress
    phase-averaged over the task's analysed periods, and its last period unaveraged, as
    thin lines.
    Axes gamma/gamma0 and sigma_xy/gamma0, so that an ellipse crosses gamma = 0 at
    +-G'' and reaches gamma/gamma0 = 1 at G'."""
    from .projection import project_periods
    d = lissajous_data(red, task_id, file_index)
    n = d["strain"].size
    dt = 2.0 * np.pi / (d["omega"] * n)
    g1, g2 = project_periods(d["stress"], d["gamma0"], d["omega"], n, t0=d["sample_offset"] * dt)
    g1[0, 0], g2[0, 0] = medium_moduli(red.job, d["omega"])  # exact, not round-off
    amplitude = np.hypot(g1, g2).max()
    fig, (ax,) = _figure(1, width=6.6, height=6.2)
    x = np.append(d["strain"], d["strain"][0]) / d["gamma0"]
    close = lambda y: np.append(y, y[0]) / d["gamma0"]  # noqa: E731
    ax.plot(x, close(d["last"]), "-", color="0.87", lw=0.5, label="total, last period (clipped)")
    ax.plot(x, close(d["stress"][-1]), "-", color="0.6", lw=0.6,
            label=f"total, averaged over {d['n_periods']} period(s)")
    phase = np.linspace(0.0, 2.0 * np.pi, 361)
    for c, comp in enumerate(TABLE_COMPONENTS):
        if comp not in ("medium", "total") and not np.any(d["stress"][c]):
            continue
        colour, _ = STYLE[comp]
        ellipse = g1[c, 0] * np.sin(phase) + g2[c, 0] * np.cos(phase)
        ax.plot(np.sin(phase), ellipse, "-", color=colour, lw=2.2 if comp == "total" else 1.6,
                label=f"{LABEL[comp].split(' (')[0]}: G′ = {g1[c, 0]:.3g}, G″ = {g2[c, 0]:.3g}")
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.axvline(0.0, color="0.6", lw=0.6)
    ax.set_ylim(-1.6 * amplitude, 1.6 * amplitude)   # noisy sample traces are clipped
    ax.set_xlabel("strain γ/γ0")
    ax.set_ylabel("stress σ_xy/γ0  [η_m/t_D]")
    ax.set_title(f"Lissajous, task {d['task_id']} (realisation {d['realisation']}): "
                 f"φ = {d['phi']:g}, ω = {d['omega']:.4g}/t_D\n"
                 f"ellipses: first harmonic of each contribution (crosses γ = 0 at ±G″, "
                 f"reaches γ/γ0 = 1 at G′)", fontsize=9)
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2,
              frameon=False)
    fig.savefig(path, dpi=120)
    return Path(path)


def plot_all(red, outdir, task_id=None):
    """Every figure of an oscillatory reduction into ``outdir``: moduli_phi<phi>.png and
    viscosity_phi<phi>.png per volume fraction and lissajous.png. Returns (paths,
    notes); a note says why the Lissajous figure is missing when the default task has
    no analysed period yet (an explicitly chosen ``task_id`` raises instead)."""
    from .reduce import ReduceError
    outdir = Path(outdir)
    paths, notes = [], []
    for phi in dict.fromkeys(red.phi.tolist()):
        if not np.any(red.ensemble.n_realisations[red.phi == phi, 1:] > 0):
            notes.append(f"no figures for phi = {phi:g}: no realisation has data after the "
                         f"start-up yet")
            continue
        tag = f"phi{phi:g}"
        paths.append(plot_moduli(red, outdir / f"moduli_{tag}.png", phi))
        paths.append(plot_viscosities(red, outdir / f"viscosity_{tag}.png", phi))
    if task_id is None and not np.any(red.per_realisation.n[:, 1] > 0):
        return paths, notes + ["no Lissajous figure: no task has a whole period after the "
                               "start-up yet"]
    try:
        paths.append(plot_lissajous(red, outdir / "lissajous.png", task_id))
    except ReduceError as err:
        if task_id is not None:
            raise
        notes.append(f"no Lissajous figure: {err}")
    return paths, notes


STEADY_LABEL = {"eta": "η / η_m  (relative viscosity)", "N1": "N1 / (η_m γ̇)",
                "N2": "N2 / (η_m γ̇)", "Pi": "Π / (η_m γ̇)  (particle pressure)"}


def plot_running(red, path, phi) -> Path:
    """Running averages of eta, N1, N2, Pi vs time for one phi of a steady-shear
    reduction (module docstring)."""
    from .reduce import STEADY_QUANTITIES, ensemble_half_width
    g = int(np.flatnonzero(red.phi == phi)[0])
    run = red.running
    t = run["time"] + red.job.time_step(None)    # average over samples 0..k spans (k+1) dt
    from matplotlib.figure import Figure
    fig = Figure(figsize=(11.0, 8.8))
    axes = fig.subplots(2, 2).ravel()
    e = red.ensemble
    for q, (ax, name) in enumerate(zip(axes, STEADY_QUANTITIES)):
        for c, comp in _active(red, red.phi == phi):
            colour, _ = STYLE[comp]
            curves = run["values"][g, c, q]                         # (R, T)
            if comp == "total":
                for r, curve in enumerate(curves):
                    ax.plot(t, curve, "-", color="0.6", lw=0.6,
                            label="total, each realisation" if r == 0 else None)
            with np.errstate(all="ignore"):
                mean = np.nanmean(curves, axis=0) if np.any(np.isfinite(curves)) else curves[0]
            label = ("medium (exact)" if comp == "medium"
                     else LABEL[comp] + " (mean of realisations)")
            ax.plot(t, mean, "-", color=colour, lw=2.0 if comp == "total" else 1.5,
                    label=label)
            m = e.mean[g, c, q]
            half = float(ensemble_half_width(e, (g, c, q)))
            if np.isfinite(m) and np.isfinite(half) and half > 0:
                late = t >= run["discard_time"]
                ax.fill_between(t[late], m - half, m + half, color=colour, alpha=0.18, lw=0)
        ax.axvspan(0.0, run["discard_time"], color="0.9", zorder=0,
                   label="discarded start-up")
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_xlim(0.0, t[-1])
        ax.set_xlabel(f"t  [{red.job.time_unit}]")
        ax.set_ylabel(STEADY_LABEL[name])
        ax.set_title(f"running average of {name}")
        ax.grid(True, which="both", alpha=0.25)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=3, frameon=False)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.91, bottom=0.14, hspace=0.3, wspace=0.22)
    job = red.job
    n = int(e.n_realisations[g, 1, 0])
    brown = f"Pe = {job.shear.rate:g}" if job.brownian.enabled else "non-Brownian"
    fig.suptitle(f"{job.job.name}: φ = {phi:g}, N = {job.system.n_particles}, steady shear "
                 f"({brown}), interparticle {job.interparticle.kind}, realisations {n}"
                 + ("" if red.complete else ", PARTIAL RUN")
                 + "\nbands: reported mean ± 95% confidence interval (samples after the "
                 "start-up)", fontsize=10)
    fig.savefig(path, dpi=120)
    return Path(path)


def plot_running_all(red, outdir) -> list:
    """running_phi<phi>.png for every volume fraction of a steady-shear reduction."""
    outdir = Path(outdir)
    return [plot_running(red, outdir / f"running_phi{phi:g}.png", phi)
            for phi in dict.fromkeys(red.phi.tolist())]


def plot_green_kubo(red, group, path, task_id=None) -> Path:
    """A run at rest (:mod:`.at_rest`): G(t) per configurational contribution and their
    sum (log-log, t > 0, one standard error; the thin line: task ``task_id`` of the first
    file alone), and the Green-Kubo G'(w), G''(w) rows of moduli_gk.csv (log-log)."""
    fig, (ax_t, ax_w) = _figure(2)
    t = group.lags * group.dt
    shown = []
    for c, name in enumerate(group.components):
        m, e = group.relaxation.mean[c], group.relaxation.err[c]
        if name != "total" and not np.any(np.abs(m[np.isfinite(m)]) > 0):
            continue
        colour, marker = STYLE[name]
        ax_t.errorbar(t[1:], m[1:], yerr=e[1:], color=colour, marker=marker, ms=3, lw=1,
                      capsize=2, label=f"{LABEL[name]} (G(0) = {m[0]:.4g})")
        shown.append(m[1:])
    if task_id is not None and task_id in group.task_id:
        r = group.task_id.index(task_id)
        ax_t.plot(t[1:], group.per_realisation[r, 1:], color="0.5", lw=0.8,
                  label=f"task {task_id} alone (total)")
    log_axes(ax_t, np.concatenate(shown))
    ax_t.set_xlabel("t (t_D)")
    ax_t.set_ylabel("G(t) (η_m/t_D)")
    ax_t.set_title(f"relaxation modulus, window {group.max_lag * group.dt:.3g} t_D")
    legend_below(ax_t)
    rows = [r for r in red.rows() if r["phi"] == group.phi]
    values = []
    for k, name in enumerate(TABLE_COMPONENTS):
        sel = [r for r in rows if r["component"] == name]
        w = np.array([r["omega"] for r in sel])
        g1 = np.array([r["G_prime"] for r in sel])
        g2 = np.array([r["G_dprime"] for r in sel])
        if name not in ("medium", "total") and not np.any(np.abs(g2[np.isfinite(g2)]) > 0):
            continue
        colour, marker = STYLE[name]
        for g, err, fill, q in ((g1, [r["G_prime_err"] for r in sel], "full", "G'"),
                                (g2, [r["G_dprime_err"] for r in sel], "none", "G''")):
            ax_w.errorbar(_dodge(w, k), g, yerr=err, color=colour, marker=marker or ".",
                          fillstyle=fill, ms=4, lw=0.8, capsize=2, label=f"{q} {name}")
            values.append(g)
    log_axes(ax_w, np.concatenate(values))
    ax_w.set_xlabel("ω (1/t_D)")
    ax_w.set_ylabel("G', G'' (η_m/t_D)")
    ax_w.set_title("Green-Kubo moduli (filled G', open G'')")
    legend_below(ax_w)
    job = red.job
    n = int(group.relaxation.n_realisations[-1, 0])
    flag = "" if red.validated else ", NOT VALIDATED for this model"
    fig.suptitle(f"{job.job.name}: at rest, φ = {group.phi:g}, N = {job.system.n_particles}, "
                 f"{job.hydrodynamics.model}, lag-0 rule {red.lag0}, realisations {n}"
                 + ("" if red.complete else ", PARTIAL RUN") + flag, fontsize=10)
    fig.savefig(path, dpi=110)
    return Path(path)
