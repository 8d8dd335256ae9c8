"""Step one task of the demonstration job from Python and plot its stress.

    python docs/examples/step_and_plot.py [OUT.png]

Loads jobs/demo.toml with 8 spheres, steps its first task (phi = 0.3, omega = 2 pi per
t_D) for one period, and plots the shear stress sigma_xy of each contribution against
the imposed strain gamma(t) = gamma0 sin(omega t) (docs/api.md).
"""

import math
import os
import sys
from pathlib import Path

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")  # one BLAS thread: the numbers of `sdmpi run`

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import sdmpi  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
out = Path(sys.argv[1] if len(sys.argv) > 1 else "step_and_plot.png")

job = sdmpi.load_job(ROOT / "jobs" / "demo.toml", ["system.n_particles=8"])
task = sdmpi.tasks(job)[0]
r = sdmpi.Realisation(job, task)
period = round(2 * math.pi / task.omega / task.dt)  # steps per period
samples = r.advance(period)

fig, ax = plt.subplots(figsize=(6, 4))
for name, stress in samples.stress.items():
    ax.plot(samples["time"], stress[:, 3], label=name)  # column 3: xy
ax.set_xlabel("t [t_D]")
ax.set_ylabel("sigma_xy [eta_m / t_D]")
strain_axis = ax.twinx()
strain_axis.plot(samples["time"], samples["strain"], "k:", label="strain")
strain_axis.set_ylabel("gamma")
ax.legend(loc="upper right")
ax.set_title(f"phi = {task.phi}, omega = {task.omega:.3g} / t_D, N = {len(r.positions)}")
fig.tight_layout()
fig.savefig(out, dpi=100)
print(f"{r.step} steps to t = {r.time:.3f} t_D; "
      f"mean hydrodynamic sigma_xy {samples.stress['hydrodynamic'][:, 3].mean():.4g}; wrote {out}")
