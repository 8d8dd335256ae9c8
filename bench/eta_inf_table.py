"""High-frequency viscosity eta'_inf(phi) = 1 + eta_H of equilibrium hard-sphere configurations
(Monte Carlo starts of sdmpi.dynamics.initial.hard_sphere_fluid, independent seeds), full SD
(far field + lubrication, Ewald tolerance 1e-6), one standard error over the configurations;
writes bench/eta_inf.json (docs/validation.md compares it with Schaink et al. 2000 eq. 38).
Rows of other (N, phi) already in the file are kept, so a size or volume fraction can be
added without recomputing the others; "commands" lists the invocations that wrote it.

    python bench/eta_inf_table.py [--configs 30] [--sizes 27 64 125] [--phis 0.1 ... 0.5]
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro.bulk import hydrodynamic_viscosity

PHIS = (0.1, 0.2, 0.3, 0.4, 0.45, 0.5)


def measure(n, phi, configs, seed=2026):
    values = []
    for k in range(configs):
        rng = np.random.default_rng([seed, n, int(round(1000 * phi)), k])
        pos, side = hard_sphere_fluid(n, phi, rng)
        values.append(hydrodynamic_viscosity(pos, np.full(3, side)))
    values = np.array(values)
    return 1 + values.mean(), values.std(ddof=1) / math.sqrt(configs)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", type=int, default=30)
    parser.add_argument("--sizes", type=int, nargs="+", default=[27, 64, 125])
    parser.add_argument("--phis", type=float, nargs="+", default=list(PHIS))
    parser.add_argument("--out", default=str(Path(__file__).with_name("eta_inf.json")))
    args = parser.parse_args()
    out = Path(args.out)
    old = json.loads(out.read_text()) if out.exists() else {"rows": []}
    commands = old.get("commands", [])
    rows = []
    for n in args.sizes:
        for phi in args.phis:
            t = time.perf_counter()
            mean, err = measure(n, phi, args.configs)
            rows.append({"n_particles": n, "phi": phi, "eta_inf": mean, "err": err, "configs": args.configs})
            print(f"N = {n:4d} phi = {phi:.2f}: eta'_inf = {mean:.3f} +- {err:.3f} "
                  f"({time.perf_counter() - t:.0f} s)", flush=True)
    new = {(row["n_particles"], row["phi"]) for row in rows}
    kept = [row for row in old["rows"] if (row["n_particles"], row["phi"]) not in new]
    rows = sorted(kept + rows, key=lambda row: (row["n_particles"], row["phi"]))
    commands.append(" ".join(["python bench/eta_inf_table.py", *sys.argv[1:]]).strip())
    out.write_text(json.dumps({"commands": commands, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
