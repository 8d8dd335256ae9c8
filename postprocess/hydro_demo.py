"""Hydrodynamics demonstration, without a run file (`python postprocess/hydro_demo.py`).

1. An isolated sphere and Hasimoto's simple cubic lattice (periodic Ewald sums).
2. The high-frequency hydrodynamic viscosity of equilibrium hard-sphere suspensions at
   phi = 0.45 (N = 27), averaged over independent configurations, against Schaink et al. 2000
   eq. 38 (Schaink et al. 2000).
"""

import argparse
import math
import time

import numpy as np

from sdmpi.analysis.analytic import schaink_eta_h
from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro import solve_mobility
from sdmpi.hydro.bulk import hydrodynamic_viscosity


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=27, help="particles per configuration (a cube)")
    ap.add_argument("--phi", type=float, default=0.45)
    ap.add_argument("--configs", type=int, default=8)
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()

    print("1. single sphere, force F = e_x, viscosity 1, radius 1")
    print(f"   {'box L':>8} {'6 pi U/F':>12} {'Hasimoto':>12}")
    for side in (None, 5.0, 10.0, 20.0, 40.0):
        u, _, _ = solve_mobility(np.zeros((1, 3)), None if side is None else [side] * 3, forces=[[1.0, 0, 0]])
        ref = 1.0 if side is None else 1 - 2.837297 / side + 4.18879 / side ** 3
        print(f"   {'inf' if side is None else side:>8} {6 * math.pi * u[0, 0]:12.8f} {ref:12.8f}")

    print(f"\n2. high-frequency viscosity, phi = {args.phi}, N = {args.n}, {args.configs} configurations")
    rng = np.random.default_rng(args.seed)
    values = []
    t0 = time.perf_counter()
    for c in range(args.configs):
        pos, side = hard_sphere_fluid(args.n, args.phi, rng)
        values.append(hydrodynamic_viscosity(pos, [side] * 3))
        print(f"   configuration {c + 1}: eta_H = {values[-1]:.4f}")
    mean, err = np.mean(values), np.std(values, ddof=1) / math.sqrt(len(values))
    print(f"   eta'_inf = 1 + eta_H = {1 + mean:.4f} +- {err:.4f} (one standard error)")
    print(f"   Schaink et al. 2000 eq. 38:      1 + eta_H = {1 + schaink_eta_h(args.phi):.4f}")
    print(f"   ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
