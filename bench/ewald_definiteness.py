"""Whether the far-field mobility stays positive definite at a loose Ewald tolerance.

The Ewald sums' truncation error is relative to the mobility's scale; the smallest
eigenvalue of M_inf (11N x 11N) is ~5e-3 of it for unit spheres, so in small boxes, where
the sums converge slowest, a loose tolerance can leave M_inf indefinite. For equal unit
spheres at volume fraction phi in boxes of side L = (4 pi N / 3 phi)^(1/3), this prints
the smallest eigenvalue of M_inf at each tolerance, per N, over Monte Carlo hard-sphere
configurations (`sdmpi.dynamics.initial.hard_sphere_fluid`, seeds 0 .. --configs - 1):
the minimum over them. Writes bench/ewald_definiteness.json (docs/performance.md quotes it;
`config.schema.LOOSE_EWALD_MIN_SIDE` rests on it).

    OMP_NUM_THREADS=1 python bench/ewald_definiteness.py [--sizes 1 2 3 4 8 27] [--phi 0.3 0.45]
"""

import argparse
import json

import numpy as np

from sdmpi.dynamics.initial import cubic_box, hard_sphere_fluid
from sdmpi.hydro.farfield import far_field_mobility


def smallest_eigenvalue(n, phi, tol, seed):
    """The smallest eigenvalue of M_inf of one Monte Carlo configuration (box side
    `initial.cubic_box`)."""
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(seed))
    mob = far_field_mobility(pos, np.ones(n), np.full(3, side), 0.0, tol=tol)
    return float(np.linalg.eigvalsh(0.5 * (mob + mob.T))[0])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 2, 3, 4, 8, 27])
    parser.add_argument("--phi", type=float, nargs="+", default=[0.3, 0.45])
    parser.add_argument("--tolerances", type=float, nargs="+", default=[1e-2, 1e-3, 1e-4, 1e-6])
    parser.add_argument("--configs", type=int, default=5)
    parser.add_argument("--out", default="bench/ewald_definiteness.json")
    args = parser.parse_args()
    rows = []
    for phi in args.phi:
        for n in args.sizes:
            side = cubic_box(n, phi)
            smallest = {f"{tol:g}": min(smallest_eigenvalue(n, phi, tol, seed) for seed in range(args.configs))
                        for tol in args.tolerances}
            rows.append({"n": n, "phi": phi, "side": side, "configs": args.configs, "smallest_eigenvalue": smallest})
            print(f"N = {n:3d}, phi = {phi:g}, side {side:5.2f}: " +
                  "  ".join(f"{t}: {v:+.2e}" for t, v in smallest.items()), flush=True)
    with open(args.out, "w") as fh:
        json.dump({"command": "python bench/ewald_definiteness.py", "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
