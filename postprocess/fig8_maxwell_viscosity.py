#!/usr/bin/env python3
"""Schaink et al., J. Rheol. 44 (2000),
Fig. 8: complex viscosity vs omega of hard spheres in a Maxwell medium.

    postprocess/fig8_maxwell_viscosity.py MAXWELL_RUN.h5 [...] [--newtonian RUN.h5 ...] [-o fig8.png]

(a) eta'/eta_m, (b) eta''/eta_m vs omega: solid line the medium eta*_m(omega) (Schaink et al. eq. 36,
summed over modes); crosses our eta_m + eta_H; dashed Schaink et al.'s prediction eta_m + eta_H
with eta*_H(omega) = (eta_H(0)/eta_0m) eta*_m(omega) (eqs. 41-42) and eta_H(0) from eq. 38;
dots the total eta_m + eta_H + eta_B. With --newtonian (run files of the Newtonian job at
the same phi) eta_H(0) is also taken from our own SD (eta'_H averaged over omega, weighted
by 1/err^2), dotted. The table sets our eta'_H, eta''_H beside eqs. 41-42.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from schaink_common import (describe, figure, parser, phis, pm, print_table,  # noqa: E402
                            reduce_systems, save, series)

from sdmpi.analysis.analytic import maxwell_eta_h, maxwell_viscosity, schaink_eta_h  # noqa: E402


def newtonian_eta_h(reductions, phi):
    """(eta_H, err) of our Newtonian runs at phi: weighted mean of eta'_H over omega."""
    for red in reductions:
        if np.any(np.isclose(red.phi, phi)):
            _, h, e = series(red, phi, "hydrodynamic", "eta_prime")
            ok = np.isfinite(h) & (e > 0)
            if ok.any():
                wts = 1 / e[ok] ** 2
                return float(np.sum(wts * h[ok]) / wts.sum()), float(wts.sum() ** -0.5)
    return None


def main(argv=None):
    p = parser(__doc__.split("\n")[1], "schaink2000_fig8.png")
    p.add_argument("--newtonian", nargs="+", default=[], metavar="RUN.h5",
                   help="Newtonian run files: eta_H(0) from our own SD as well")
    args = p.parse_args(argv)
    newtonian = reduce_systems(args.newtonian, medium="newtonian") if args.newtonian else []
    draw(reduce_systems(args.runs, medium="maxwell"), newtonian, args.output)
    return 0


def draw(reductions, newtonian, path):
    """The figure (at ``path``) and the eqs. 41-42 table of Maxwell-medium reductions;
    ``newtonian``: Newtonian reductions for our own eta_H(0) (may be empty)."""
    fig, (a1, a2) = figure(2, width=11.5, height=5.2)
    for red in reductions:
        print(describe(red))
        modes = red.job.medium.modes
        eta, lam = np.array([m.eta for m in modes]), np.array([m.lam for m in modes])
        for phi in phis([red]):
            w, _, _ = series(red, phi, "medium", "eta_prime")
            grid = np.geomspace(w.min() / 2, w.max() * 2, 200)
            m1, m2 = maxwell_viscosity(grid, eta, lam)
            p1, p2 = maxwell_eta_h(grid, schaink_eta_h(phi) / eta.sum(), eta, lam)
            ours = newtonian_eta_h(newtonian, phi)
            rows = {}
            for ax, column, medium, pred, q in ((a1, "eta_prime", m1, p1, 0),
                                                (a2, "eta_dprime", m2, p2, 1)):
                _, md, _ = series(red, phi, "medium", column)
                _, h, he = series(red, phi, "hydrodynamic", column)
                _, t, te = series(red, phi, "total", column)
                ax.plot(grid, medium, "-", color="0.3", lw=1.4, label="medium η_m(ω), Schaink et al. eq. 36")
                ax.errorbar(w, md + h, yerr=he, fmt="+", ms=10, color="tab:blue", capsize=3,
                            label="SD: η_m + η_H")
                ax.plot(grid, medium + pred, "--", color="tab:blue", lw=1.2,
                        label="η_m + η_H, Schaink et al. eqs. 41-42 with η_H(0) of eq. 38")
                if ours is not None:
                    own = maxwell_eta_h(grid, ours[0] / eta.sum(), eta, lam)[q]
                    ax.plot(grid, medium + own, ":", color="tab:green", lw=1.4,
                            label=f"η_m + η_H, eqs. 41-42 with our Newtonian η_H = {ours[0]:.3g}")
                ax.errorbar(w * 1.03, t, yerr=te, fmt="o", color="black", ms=5, capsize=3,
                            label="SD: η_m + η_H + η_B (total)")
                rows[column] = (h, he, maxwell_eta_h(w, schaink_eta_h(phi) / eta.sum(), eta,
                                                      lam)[q])
            h1, e1, q1 = rows["eta_prime"]
            h2, e2, q2 = rows["eta_dprime"]
            print_table(f"\nFig. 8, phi = {phi:g}: Schaink et al.: eqs. 41-42 (with eq. 38's eta_H(0) = "
                        f"{schaink_eta_h(phi):.4g}) describe the SD eta_H 'very well'"
                        + (f"; our Newtonian eta_H = {pm(*ours)}" if ours else ""),
                        ["omega", "eta'_H (SD)", "eq. 41", "SD/eq.41", "eta''_H (SD)",
                         "eq. 41", "SD/eq.41"],
                        [(f"{w[i]:.4g}", pm(h1[i], e1[i]), f"{q1[i]:.4g}", f"{h1[i] / q1[i]:.3f}",
                          pm(h2[i], e2[i]), f"{q2[i]:.4g}", f"{h2[i] / q2[i]:.3f}")
                         for i in range(len(w))])
    for ax, name in ((a1, "(a) η′/η_m"), (a2, "(b) η″/η_m")):
        ax.set_xscale("log")
        ax.set_xlabel("ω  [1/t_D]")
        ax.set_ylabel(name[4:])
        ax.set_ylim(bottom=0)
        ax.set_title(f"Fig. 8{name[:3]} (Schaink et al. 2000), {reductions[0].job.job.name}", fontsize=9)
        ax.grid(True, which="both", alpha=0.25)
        ax.legend(fontsize=7.5)
    modes = ", ".join(f"η={m.eta:g}, λ={m.lam:g} t_D" for m in reductions[0].job.medium.modes)
    fig.suptitle(f"hard spheres in a Maxwell medium ({modes}); bars ± one standard error",
                 fontsize=9)
    save(fig, path)


if __name__ == "__main__":
    sys.exit(main())
