#!/usr/bin/env python3
"""Schaink et al., J. Rheol. 44 (2000),
Fig. 2: viscosity eta'/eta_m vs volume fraction phi (Newtonian medium).

    postprocess/fig2_viscosity_vs_phi.py RUN.h5 [RUN2.h5 ...] [--omega 18.85] [-o fig2.png]

At the frequency nearest --omega (default 6 pi, the caption's; the text says 2 pi):
+ 1 + eta'_H/eta_m and o 1 + (eta'_H + eta'_B)/eta_m (our "total", which adds the
interparticle part, zero for hard spheres) per phi, with the Batchelor-Green relation
(Schaink et al. eq. 37, dashed) and Schaink et al.'s fit of its SD eta_H (eq. 38, solid, stated within 1%
for 0 <= phi <= 0.45). Needs runs at several phi (one job with a phi list, or several jobs)
to show a curve; with one phi it still prints the comparison.
"""

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from schaink_common import (describe, figure, parser, phis, pm, print_table,  # noqa: E402
                            reduce_systems, save, series)

from sdmpi.analysis.analytic import batchelor_green, schaink_eta_h  # noqa: E402


def main(argv=None):
    p = parser(__doc__.split("\n")[1], "schaink2000_fig2.png")
    p.add_argument("--omega", type=float, default=6 * math.pi,
                   help="frequency [1/t_D] (nearest available is used; default 6 pi)")
    args = p.parse_args(argv)
    draw(reduce_systems(args.runs, medium="newtonian"), args.output, args.omega)
    return 0


def draw(reductions, path, omega=6 * math.pi):
    """The figure (at ``path``) and the table of eta' vs phi at the frequency nearest
    ``omega`` of oscillatory Newtonian reductions."""
    points = []  # (phi, omega, 1 + eta_H, err, total, err)
    for red in reductions:
        print(describe(red))
        for phi in phis([red]):
            w, h, he = series(red, phi, "hydrodynamic", "eta_prime")
            _, t, te = series(red, phi, "total", "eta_prime")
            i = int(np.argmin(np.abs(np.log(w / omega))))
            points.append((phi, w[i], 1 + h[i], he[i], t[i], te[i]))
    points.sort()
    if len({p[0] for p in points}) < 2:
        print("note: runs at a single phi: Fig. 2 needs several volume fractions for a curve",
              file=sys.stderr)
    fig, (ax,) = figure()
    grid = np.linspace(0, max(0.5, max(p[0] for p in points) * 1.1), 200)
    ax.plot(grid, batchelor_green(grid), "--", color="0.3", label="Batchelor & Green (Schaink et al. eq. 37)")
    g38 = grid[grid <= 0.45]
    ax.plot(g38, 1 + schaink_eta_h(g38), "-", color="tab:blue", lw=1,
            label="1 + η_H/η_m, Schaink et al. eq. 38 (0 ≤ φ ≤ 0.45)")
    arr = np.array(points)
    ax.errorbar(arr[:, 0], arr[:, 2], yerr=arr[:, 3], fmt="+", ms=9, color="tab:blue",
                capsize=3, label="SD: 1 + η′_H/η_m")
    ax.errorbar(arr[:, 0], arr[:, 4], yerr=arr[:, 5], fmt="o", mfc="none", color="black",
                capsize=3, label="SD: 1 + (η′_H + η′_B)/η_m (total)")
    omegas = ", ".join(sorted({f"{p[1]:.4g}" for p in points}))
    ax.set_xlabel("volume fraction φ")
    ax.set_ylabel("η′ / η_m")
    ax.set_title(f"Fig. 2 (Schaink et al. 2000): η′ vs φ at ω = {omegas} /t_D\n"
                 f"{reductions[0].job.job.name}; bars ± one standard error", fontsize=9)
    ax.grid(True, alpha=0.25)
    ax.legend(fontsize=8)
    save(fig, path)
    print_table("\nFig. 2: ours vs Schaink et al. 2000 (eq. 38 reproduces Schaink et al.'s SD eta_H within 1%)",
                ["phi", "omega", "1+eta'_H (SD)", "1+eta_H eq.38", "dev.", "eq. 37", "total eta' (SD)"],
                [(f"{p:g}", f"{w:.4g}", pm(h, he), f"{1 + schaink_eta_h(p):.4g}",
                  f"{100 * (h / (1 + schaink_eta_h(p)) - 1):+.1f}%", f"{batchelor_green(p):.4g}",
                  pm(t, te)) for p, w, h, he, t, te in points])


if __name__ == "__main__":
    sys.exit(main())
