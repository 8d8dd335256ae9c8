#!/usr/bin/env python3
"""Schaink et al., J. Rheol. 44 (2000),
Fig. 4: G'(omega) and G''(omega) of hard spheres in a Newtonian medium.

    postprocess/fig4_moduli.py RUN.h5 [RUN2.h5 ...] [-o fig4.png]

Total moduli (medium + hydrodynamic + Brownian + interparticle) vs omega, log-log, one
panel per phi. Schaink et al. compare with omega^(-1/2) fits to experiments (van der Werff et
al. 1989) whose parameters it does not print; overlaid here are what can be computed:
the medium plus Schaink et al.'s hydrodynamic part, G'' = omega (1 + eta_H(phi)) with eta_H from
eq. 38 (the high-frequency limit, where the Brownian part fades), and an omega^(1/2) guide
(the experiments' eta', eta'' ~ omega^(-1/2)) through our lowest-frequency G''. The table
checks Schaink et al.'s statement that G' reaches a plateau for omega > 8 pi.
"""

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from schaink_common import (describe, figure, parser, phis, pm, print_table,  # noqa: E402
                            reduce_systems, save, series)

from sdmpi.analysis.analytic import schaink_eta_h  # noqa: E402
from sdmpi.analysis.plots import legend_below, log_axes  # noqa: E402


def main(argv=None):
    args = parser(__doc__.split("\n")[1], "schaink2000_fig4.png").parse_args(argv)
    draw(reduce_systems(args.runs, medium="newtonian"), args.output)
    return 0


def draw(reductions, path):
    """The figure (at ``path``) and the plateau table of oscillatory Newtonian
    reductions, one panel per (reduction, phi)."""
    panels = [(red, phi) for red in reductions for phi in phis([red])]
    fig, axes = figure(len(panels), width=5.6 * len(panels), height=5.6)
    for ax, (red, phi) in zip(axes, panels):
        print(describe(red))
        w, g1, e1 = series(red, phi, "total", "G_prime")
        _, g2, e2 = series(red, phi, "total", "G_dprime")
        ok1 = np.isfinite(g1) & (g1 > 0)
        ax.errorbar(w[ok1], g1[ok1], yerr=[np.minimum(e1[ok1], g1[ok1] * (1 - 1e-9)), e1[ok1]],
                    fmt="D", color="black", capsize=3,
                    label="SD: G′ (total)" + (f"; {int(np.sum(~ok1))} value(s) ≤ 0 or nan "
                                              "not shown" if not ok1.all() else ""))
        ax.errorbar(w, g2, yerr=[np.minimum(e2, g2 * (1 - 1e-9)), e2], fmt="+", ms=10,
                    color="tab:red", capsize=3, label="SD: G″ (total)")
        grid = np.geomspace(w.min() / 1.5, w.max() * 1.5, 100)
        ax.plot(grid, grid * (1 + schaink_eta_h(phi)), "--", color="tab:blue",
                label="G″ = ω (1 + η_H), η_H of Schaink et al. eq. 38")
        if np.isfinite(g2[0]):
            ax.plot(grid, g2[0] * np.sqrt(grid / w[0]), ":", color="0.4",
                    label="∝ ω^½ (experiments: η′, η″ ∝ ω^-½)")
        ax.axvline(8 * math.pi, color="0.7", lw=0.8)
        ax.text(8 * math.pi, 0.98, " 8π", transform=ax.get_xaxis_transform(), va="top",
                fontsize=8, color="0.4")
        log_axes(ax, np.concatenate([g1, g2]))   # y range from the values, not the bars
        ax.set_xlabel("ω  [1/t_D]")
        ax.set_ylabel("G′, G″  [η_m/t_D]")
        ax.set_title(f"Fig. 4 (Schaink et al. 2000): φ = {phi:g}, N = {red.job.system.n_particles}\n"
                     f"{red.job.job.name}; bars ± one standard error"
                     + ("" if red.complete else "; PARTIAL"), fontsize=9)
        ax.grid(True, which="both", alpha=0.25)
        legend_below(ax)
        ref = int(np.argmin(np.abs(w - 8 * math.pi)))
        print_table(f"\nFig. 4, phi = {phi:g}: Schaink et al.: 'G' attains a plateau value for "
                    f"omega > 8 pi' (ratio to our G' at omega = {w[ref]:.4g})",
                    ["omega", "omega/pi", "G' (SD)", "G'/G'(8pi)", "G'' (SD)",
                     "omega(1+eta_H eq.38)"],
                    [(f"{x:.4g}", f"{x / math.pi:.3g}", pm(a, ae),
                      f"{a / g1[ref]:.3g}" if np.isfinite(a / g1[ref]) else "nan", pm(b, be),
                      f"{x * (1 + schaink_eta_h(phi)):.4g}")
                     for x, a, ae, b, be in zip(w, g1, e1, g2, e2)])
    save(fig, path)


if __name__ == "__main__":
    sys.exit(main())
