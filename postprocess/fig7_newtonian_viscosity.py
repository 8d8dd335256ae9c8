#!/usr/bin/env python3
"""Schaink et al., J. Rheol. 44 (2000),
Fig. 7: complex viscosity vs omega of hard spheres in a Newtonian medium.

    postprocess/fig7_newtonian_viscosity.py RUN.h5 [RUN2.h5 ...] [-o fig7.png]

(a) eta'/eta_m, (b) eta''/eta_m vs omega: dots the hydrodynamic part eta_H, crosses the
total eta = eta_m + eta_H + eta_B (+ interparticle, zero for hard spheres); lines: the
medium (eta' = 1) and Schaink et al.'s eq. 38 fit of its SD eta_H(phi) (omega-independent).
The table checks Schaink et al.'s statements: eta'_H is constant within 2% over all
frequencies, and eq. 38 reproduces the SD eta_H within 1% (0 <= phi <= 0.45).
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from schaink_common import (describe, figure, parser, phis, pm, print_table,  # noqa: E402
                            reduce_systems, save, series)

from sdmpi.analysis.analytic import schaink_eta_h  # noqa: E402
from sdmpi.analysis.plots import legend_below  # noqa: E402


def main(argv=None):
    args = parser(__doc__.split("\n")[1], "schaink2000_fig7.png").parse_args(argv)
    draw(reduce_systems(args.runs, medium="newtonian"), args.output)
    return 0


def draw(reductions, path):
    """The figure (at ``path``) and the eta_H table of oscillatory Newtonian reductions."""
    fig, (a1, a2) = figure(2, width=11.5, height=6.4)
    colours = iter(["tab:blue", "tab:green", "tab:purple", "tab:brown"] * 4)
    for red in reductions:
        print(describe(red))
        for phi in phis([red]):
            c = next(colours)
            for ax, column in ((a1, "eta_prime"), (a2, "eta_dprime")):
                w, h, he = series(red, phi, "hydrodynamic", column)
                _, t, te = series(red, phi, "total", column)
                ax.errorbar(w, h, yerr=he, fmt="o", color=c, capsize=3,
                            label=f"SD η_H, φ = {phi:g}")
                ax.errorbar(w * 1.03, t, yerr=te, fmt="+", ms=9, color=c, capsize=3,
                            label=f"SD η = η_m + η_H + η_B, φ = {phi:g}")
                grid = np.geomspace(w.min() / 1.5, w.max() * 1.5, 50)
                pred = schaink_eta_h(phi) if column == "eta_prime" else 0.0
                ax.plot(grid, np.full_like(grid, pred), "--", color=c, lw=1,
                        label=f"η_H Schaink et al. eq. 38, φ = {phi:g}" if column == "eta_prime"
                        else None)
            w, h, he = series(red, phi, "hydrodynamic", "eta_prime")
            _, h2, he2 = series(red, phi, "hydrodynamic", "eta_dprime")
            _, t1, te1 = series(red, phi, "total", "eta_prime")
            _, t2, te2 = series(red, phi, "total", "eta_dprime")
            ok = np.isfinite(h)
            spread = (h[ok].max() - h[ok].min()) / h[ok].mean() if ok.sum() > 1 else np.nan
            eq38 = schaink_eta_h(phi)
            print_table(f"\nFig. 7, phi = {phi:g}: Schaink et al.: eta'_H constant within 2% over omega "
                        f"(ours: spread (max-min)/mean = {100 * spread:.1f}%); eq. 38 "
                        f"eta_H = {eq38:.4g}, within 1% of Schaink et al.'s SD",
                        ["omega", "eta'_H (SD)", "eq. 38", "SD/eq.38 - 1", "eta''_H (SD)",
                         "total eta'", "total eta''"],
                        [(f"{w[i]:.4g}", pm(h[i], he[i]), f"{eq38:.4g}",
                          f"{100 * (h[i] / eq38 - 1):+.1f}%", pm(h2[i], he2[i]),
                          pm(t1[i], te1[i]), pm(t2[i], te2[i])) for i in range(len(w))])
    for ax, name in ((a1, "(a) η′/η_m"), (a2, "(b) η″/η_m")):
        ax.axhline(1.0 if ax is a1 else 0.0, color="0.3", lw=1.2,
                   label="medium η_m" if ax is a1 else "medium (η″ = 0)")
        ax.set_xscale("log")
        ax.set_xlabel("ω  [1/t_D]")
        ax.set_ylabel(name[4:])
        ax.set_title(f"Fig. 7{name[:3]} (Schaink et al. 2000), {reductions[0].job.job.name}", fontsize=9)
        ax.grid(True, which="both", alpha=0.25)
        legend_below(ax)
    fig.suptitle("hard spheres in a Newtonian medium; bars ± one standard error", fontsize=9)
    save(fig, path)


if __name__ == "__main__":
    sys.exit(main())
