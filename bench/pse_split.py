"""Benchmark: can the far-field Brownian forces use a positively split Ewald sum here?

The positively split Ewald (PSE) sampler (Fiore, Balboa Usabiaga, Donev & Swan, J. Chem.
Phys. 146, 124116 (2017); Fiore & Swan, J. Fluid Mech. 878, 544 (2019)) draws M_inf^1/2 z
as a wave-space part (the spectral operator W^T K W applied to K^1/2 times grid noise: one
FFT pair, no iteration) plus a real-space part (M_real + M_self)^1/2 z' by a Lanczos
iteration on the sparse real-space operator. The second needs M_real + M_self positive
definite. This assembles M_real + M_self of `sdmpi.hydro.spectral.SpectralFarField`
(Beenakker's splitting at the FTS level, column by column from its real-space product) at
Monte Carlo starts of jobs/finite_size_n27.toml (phi = 0.45) for several splitting
parameters xi and records its extreme eigenvalues, the real-space cut-off r_c and the
self terms (bench/pse_split.json).

    python bench/pse_split.py
"""

import datetime
import json

import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np

from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.spectral import SpectralFarField

JOB, XI, TOL = "jobs/finite_size_n27.toml", (0.689, 0.5, 0.4, 0.3, 0.2), 1e-4


def real_and_self(far):
    """M_real + M_self (11N x 11N, symmetrised) of a spectral far field, column by column."""
    m = 11 * far.n_particles
    out = np.zeros((m, m))
    for c in range(m):
        x, y = np.zeros(m), np.zeros(m)
        x[c] = 1.0
        far.real_space(x, y)
        out[:, c] = y
    out += np.diag(far._self)
    return 0.5 * (out + out.T)


def main():
    job = load_job(JOB)
    rows = []
    for task in enumerate_tasks(job)[:3]:  # three Monte Carlo starts
        real = Realisation(job, task)
        for xi in XI:
            far = SpectralFarField(real.positions.copy(), real.radii, Lattice(real.box, 0.0), tol=TOL, xi=xi)
            ev = np.linalg.eigvalsh(real_and_self(far))
            self_terms = far._self.reshape(real.n_particles, 11)[0]
            rows.append({"task": task.task_id, "xi": xi, "rcut": far.params.rcut,
                         "min_eigenvalue": float(ev[0]), "max_eigenvalue": float(ev[-1]),
                         "self_U_W_E": [float(self_terms[0]), float(self_terms[3]), float(self_terms[6])]})
            print(rows[-1], flush=True)
    with open("bench/pse_split.json", "w") as f:
        json.dump({"command": "python bench/pse_split.py", "date": datetime.date.today().isoformat(),
                   "job": JOB, "n_particles": job.system.n_particles, "ewald_tolerance": TOL,
                   "rows": rows}, f, indent=1)


if __name__ == "__main__":
    main()
