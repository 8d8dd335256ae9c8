#!/usr/bin/env python3
"""Schaink et al., J. Rheol. 44 (2000),
Fig. 5: eta'/eta_m and eta''/eta_m vs omega^(-1/2) (Newtonian medium).

    postprocess/fig5_omega_half.py RUN.h5 [RUN2.h5 ...] [-o fig5.png]

The experiments Schaink et al. compare with (van der Werff et al. 1989) found eta' and eta''
linear in omega^(-1/2); Schaink et al. report that their eta'' agrees, while its eta' lies
below the experiments and levels off ("for small omega eta' is constant"). We plot the
total eta', eta'' per phi against omega^(-1/2) (omega in 1/t_D) with weighted straight-line
fits to our points, and print the fits: a straight line describes eta'' if its
chi^2/dof is about 1.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sdmpi.analysis.plots import legend_below  # noqa: E402
from schaink_common import (describe, figure, parser, phis, pm, print_table,  # noqa: E402
                            reduce_systems, save, series, weighted_line)


def line_fit(x, y, e):
    """Weighted least squares y = a + b x with weights 1/e^2; returns (a, b, b_err,
    chi2/dof), b_err the slope's standard error for these absolute errors (nan where
    undetermined: fewer than 2 usable points; chi2/dof needs 3)."""
    fit = weighted_line(x, y, e)
    return fit.a, fit.b, fit.b_err, fit.chi2


def main(argv=None):
    args = parser(__doc__.split("\n")[1], "schaink2000_fig5.png").parse_args(argv)
    draw(reduce_systems(args.runs, medium="newtonian"), args.output)
    return 0


def draw(reductions, path):
    """The figure (at ``path``) and the fit table of oscillatory Newtonian reductions."""
    fig, (ax,) = figure(width=6.8, height=6.4)
    rows = []
    colours = iter(["tab:red", "tab:blue", "tab:green", "tab:purple", "tab:brown"] * 4)
    for red in reductions:
        print(describe(red))
        for phi in phis([red]):
            colour = next(colours)
            for column, marker, name in (("eta_prime", "+", "η′"), ("eta_dprime", "D", "η″")):
                w, v, e = series(red, phi, "total", column)
                x = w ** -0.5
                ax.errorbar(x, v, yerr=e, fmt=marker, ms=9 if marker == "+" else 5,
                            mfc="none", color=colour, capsize=3,
                            label=f"SD {name}/η_m, φ = {phi:g}")
                a, b, _, chi2 = line_fit(x, v, e)
                if np.isfinite(b):
                    grid = np.linspace(0, x.max() * 1.1, 50)
                    ax.plot(grid, a + b * grid, "--", color=colour, lw=0.8)
                rows.append((f"{phi:g}", name, f"{a:.4g}", f"{b:.4g}", f"{chi2:.3g}",
                             ", ".join(pm(val, err) for val, err in zip(v, e))))
    ax.plot([], [], "--", color="0.3", lw=0.8, label="weighted linear fits to SD")
    ax.set_xlabel("ω^-½  [t_D^½]")
    ax.set_ylabel("η′/η_m, η″/η_m  (total)")
    ax.set_xlim(left=0)
    ax.set_title("Fig. 5 (Schaink et al. 2000): complex viscosity vs ω^-½\n"
                 f"{reductions[0].job.job.name}; bars ± one standard error", fontsize=9)
    ax.grid(True, alpha=0.25)
    legend_below(ax)
    save(fig, path)
    print_table("\nFig. 5: straight lines eta = a + b omega^(-1/2) fitted to our points "
                "(Schaink et al.: eta'' linear like the experiments; eta' levels off)",
                ["phi", "", "a", "b", "chi2/dof", "values (ascending omega)"], rows)


if __name__ == "__main__":
    sys.exit(main())
