"""A solver backend, a hydrodynamic model and a writer defined outside sdmpi, registered by
this module, and `sdmpi` run with them (tests/test_extension.py):
python tests/extension_plugin.py run JOB.toml -o RUN.h5 [--set ...]

* solver.backend = "numpy-cholesky": R_FU = L L^T by numpy's Cholesky, solves by two
  triangular solves (scipy), the Brownian forces L z; the generic forms of
  `SolverBackend` for the rest.
* hydrodynamics.model = "viscous-free-draining": free draining in a medium VISCOSITY
  times as viscous as the job's: every resistance scales with the viscosity
  (`ViscousEvaluation`), so a non-Brownian job's hydrodynamic stress is VISCOSITY times
  that of "free-draining" and its motion the same.
* writer "step-times": ``extra/NNNNNN/time``, the time of every step's sample, one row per
  step (a toy output that a test compares with the sample stream's ``time``).
"""

import sys

from sdmpi import cli  # first: sets the thread variables before numpy is imported

import numpy as np  # noqa: E402
from scipy.linalg import solve_triangular  # noqa: E402

from sdmpi.config import enumerate_tasks  # noqa: E402
from sdmpi.dynamics.models import BrownianTerms, FreeDrainingModel  # noqa: E402
from sdmpi.ensemble.h5 import new_dataset  # noqa: E402
from sdmpi.hydro.backend import SolverBackend  # noqa: E402
from sdmpi.registry import (HYDRODYNAMIC_MODELS, SOLVER_BACKENDS, WRITERS, BackendSpec, ModelSpec,  # noqa: E402
                            Spec)

#: the medium's viscosity over the job's (eta_m)
VISCOSITY = 2.0


class NumpyCholeskySolver(SolverBackend):
    """R_FU = L L^T (numpy.linalg.cholesky) of a `GrandResistance`, on one rank."""

    def __init__(self, resistance, comm=None):
        self.resistance, self.n = resistance, resistance.n_particles
        self.noise_shape = (self.n, 6)
        self._lower = np.linalg.cholesky(resistance.r_fu)  # LinAlgError unless positive definite

    def velocities(self, forces, einf):
        rhs = forces.ravel() + self.resistance.strain_forces(einf)
        half = solve_triangular(self._lower, rhs, lower=True)
        return solve_triangular(self._lower.T, half, lower=False).reshape(self.n, 6)

    def stresslets(self, velocities, einf):
        return self.resistance.stresslets(velocities, einf)

    def brownian_forces(self, noise):
        return (self._lower @ noise.ravel()).reshape(self.n, 6)


class ViscousEvaluation:
    """An evaluation in a medium VISCOSITY (c) times as viscous as that of ``inner``: R -> c R,
    so U' = R_FU^-1 (F/c + R_FE e_inf), S = c (R_SE e_inf - R_SU U'), the relative
    mobilities / c, and the Brownian terms those of kT/c (velocities of covariance
    2 (kT/c) R_FU^-1 / dt and drift (kT/c) div R_FU^-1) with the stresslets times c."""

    def __init__(self, inner):
        self.inner = inner
        self.positions, self.n_particles, self.pairs = inner.positions, inner.n_particles, inner.pairs

    def velocities(self, forces, einf):
        return self.inner.velocities(forces / VISCOSITY, einf)

    def stresslets(self, velocities, einf):
        return VISCOSITY * self.inner.stresslets(velocities, einf)

    def relative_mobility(self, i, j, e):
        return self.inner.relative_mobility(i, j, e) / VISCOSITY

    def brownian(self, rng, kT, dt):
        terms = self.inner.brownian(rng, kT / VISCOSITY, dt)
        return BrownianTerms(terms.velocities, VISCOSITY * terms.stresslets, terms.midpoint_overlaps)

    def stats(self):
        return self.inner.stats()


class ViscousFreeDraining(FreeDrainingModel):
    """Free draining in a medium VISCOSITY times as viscous."""

    def at(self, positions, strain):
        return ViscousEvaluation(super().at(positions, strain))


class StepTimes:
    """A writer (`sdmpi.ensemble.writers.Writer`): the time of every step, extra/NNNNNN/time."""

    def enabled(self, job):
        return True

    def create(self, f, job, tasks, layouts):
        for task in tasks:
            new_dataset(f, f"extra/{task.task_id:06d}/time", (task.n_steps,), "f8")

    def recorder(self, job, task, realisation, run_file, start):
        return StepTimesRecorder(f"extra/{task.task_id:06d}/time", run_file, start)

    def carry_over(self, old, new, job, task_id, done):
        path = f"extra/{task_id:06d}/time"
        new[path][:done] = old[path][:done]

    def file_bytes(self, job):
        return 8.0 * sum(task.n_steps for task in enumerate_tasks(job))


class StepTimesRecorder:
    """One task's step times since its last checkpoint."""

    def __init__(self, path, run_file, start):
        self.path, self.run_file, self.start, self.rows = path, run_file, start, []

    def before(self, step, realisation):
        pass

    def after(self, step, sample, realisation):
        self.rows.append(sample["time"][0])

    def flush(self, stop):
        self.run_file.write(self.path, slice(self.start, stop), np.array(self.rows))
        self.start, self.rows = stop, []


SOLVER_BACKENDS.register(BackendSpec("numpy-cholesky", "numpy Cholesky on one rank", NumpyCholeskySolver,
                                     dense_matrices=4))
HYDRODYNAMIC_MODELS.register(ModelSpec("viscous-free-draining", "free draining, twice as viscous",
                                       ViscousFreeDraining, solves=False))
WRITERS.register(Spec("step-times", "the time of every step", StepTimes))

if __name__ == "__main__":
    sys.exit(cli.main(sys.argv[1:]))
