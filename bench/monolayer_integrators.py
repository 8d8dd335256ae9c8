"""The sheared monolayer of Dratler & Schowalter (1996) at phi_a = 0.6, hydrodynamic
interactions only, with sdmpi's numerics and with the paper's: Euler-Maruyama with the far
field of every step, against fourth-order Adams-Bashforth with the far field of every step
or held for 0.1 time units (`integration.scheme`, `hydrodynamics.far_field_refresh`).

One realisation (task 0 of jobs/monolayer_hydro.toml at phi_a = 0.6, N = 25) per case, to
a strain of STRAIN. Per case: the cost per step, the mean number of overlapping pairs per
configuration and the share of steps with any (the monolayer keeps its overlaps), the
deepest overlap, and the mean hydrodynamic shear stress over the second half (the sample
stream's stress_hydrodynamic xy, eta_m gamma_dot; Dratler & Schowalter's eta_h). Writes
bench/monolayer_integrators.json.

    OMP_NUM_THREADS=1 python bench/monolayer_integrators.py
"""

import json
import time
from pathlib import Path

import numpy as np

from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics.realisation import Realisation

JOB = "jobs/monolayer_hydro.toml"
STRAIN = 20.0
#: (integration.scheme, hydrodynamics.far_field_refresh, dt)
CASES = (("euler-maruyama", 0.0, 2.5e-3), ("adams-bashforth-4", 0.0, 2.5e-3), ("adams-bashforth-4", 0.1, 2.5e-3),
         ("adams-bashforth-4", 0.1, 5e-4), ("euler-maruyama", 0.0, 5e-4))


def run(scheme, refresh, dt):
    """The measurements of one case (module docstring)."""
    steps = round(STRAIN / dt)
    job = load_job(JOB, [f"integration.dt={dt}", f"integration.n_steps={steps}", "integration.discard_steps=0",
                         f'integration.scheme="{scheme}"', f"hydrodynamics.far_field_refresh={refresh}",
                         "system.phi=[0.6]", "ensemble.realisations=1"])
    real = Realisation(job, enumerate_tasks(job)[0])
    start = time.perf_counter()
    samples = real.advance(steps)
    elapsed = time.perf_counter() - start
    kept = np.isfinite(samples["stress_hydrodynamic"][:, 3])
    overlaps = samples["n_overlaps"][kept]
    shear = samples["stress_hydrodynamic"][kept, 3]
    return {"scheme": scheme, "far_field_refresh": refresh, "dt": dt, "steps": steps,
            "stopped_at": int(real.geometry.stopped_at), "ms_per_step": 1e3 * elapsed / steps,
            "mean_overlaps": float(overlaps.mean()), "steps_with_overlaps": float((overlaps > 0).mean()),
            "deepest_gap": float(np.nanmin(samples["min_gap"])),
            "mean_shear_stress_second_half": float(shear[len(shear) // 2:].mean())}


def main():
    rows = []
    for case in CASES:
        rows.append(run(*case))
        print(rows[-1], flush=True)
    out = Path(__file__).with_name("monolayer_integrators.json")
    out.write_text(json.dumps({"job": JOB, "phi_a": 0.6, "strain": STRAIN, "cases": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
