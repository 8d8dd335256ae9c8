"""A solver backend, a hydrodynamic model, an interparticle force and a writer defined
outside sdmpi, registered by this module, and `sdmpi` run with them (tests/test_extension.py):
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
* interparticle.kind = "split-repulsion" (keys f0, tau): the repulsion of Dratler &
  Schowalter (1996), F(h) = f0 tau e^(-tau h)/(1 + e^(-tau h)), written here as two forces
  of half its strength each (`HalfRepulsion`, a pair law of its own), the second of which
  also samples ``pairs_seen``, the pairs it has seen within the cut-off so far, and keeps
  that count as its state. Halving is exact in floating point, so the two halves sum to
  the samples of "repulsion" bit for bit.
"""

import sys

from sdmpi import cli  # first: sets the thread variables before numpy is imported

import numpy as np  # noqa: E402
from scipy.linalg import solve_triangular  # noqa: E402

from sdmpi.config import enumerate_tasks  # noqa: E402
from sdmpi.dynamics.forces import FORCE_UNIT, ForceTerms, PairForce, pair_forces  # noqa: E402
from sdmpi.dynamics.models import BrownianTerms, FreeDrainingModel  # noqa: E402
from sdmpi.ensemble.h5 import new_dataset  # noqa: E402
from sdmpi.hydro.backend import SolverBackend  # noqa: E402
from sdmpi.registry import (FORCES, HYDRODYNAMIC_MODELS, SOLVER_BACKENDS, WRITERS, BackendSpec,  # noqa: E402
                            ForceSpec, ModelSpec, Spec)

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

    def describe(self, job, done):
        return f"step times: {sum(done)} committed (extra/NNNNNN/time)"


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


class HalfRepulsion:
    """Half of F(h) = F0 tau e^(-tau h)/(1 + e^(-tau h)) (a `sdmpi.dynamics.forces.PairLaw`;
    the potential is not needed to step)."""

    def __init__(self, f0, tau):
        self.f0, self.tau = 0.5 * f0, tau

    def magnitude(self, gap, a_i=1.0, a_j=1.0):
        e = np.exp(-self.tau * np.maximum(gap, 0.0))
        return self.f0 * self.tau * e / (1.0 + e)


class CountingPairForce:
    """The pair forces of a law (a `sdmpi.dynamics.forces.Force` written out), sampling
    ``pairs_seen``: the pairs within the cut-off summed over the steps so far (state)."""

    def __init__(self, law, radii):
        self.law, self.radii, self.seen = law, radii, 0

    def terms(self, pairs):
        n = len(self.radii)
        forces, virial = pair_forces(self.law, pairs, n, self.radii)
        return ForceTerms(np.hstack([forces, np.zeros((n, 3))]), virial, {"pairs": len(pairs.i)})

    def sample_fields(self, stress_unit):
        return {"pairs_seen": ((), "i8", "1", "pairs within the cut-off, summed over the steps so far")}

    def sample(self, terms, stress):
        self.seen += terms.counts["pairs"]
        return {"pairs_seen": self.seen}

    def advance(self, velocities, rate, dt):
        pass

    def state_fields(self):
        return {"pairs_seen": ((1,), "i8")}

    def get_state(self):
        return {"pairs_seen": np.array([self.seen], dtype=np.int64)}

    def set_state(self, state):
        self.seen = int(state["pairs_seen"][0])


def split_repulsion(setting, *, f0, tau):
    """The forces of interparticle.kind = "split-repulsion": two halves of the repulsion."""
    law = HalfRepulsion(FORCE_UNIT * f0, tau)
    return [PairForce(law, setting.radii), CountingPairForce(law, setting.radii)]


SOLVER_BACKENDS.register(BackendSpec("numpy-cholesky", "numpy Cholesky on one rank", NumpyCholeskySolver,
                                     dense_matrices=4))
HYDRODYNAMIC_MODELS.register(ModelSpec("viscous-free-draining", "free draining, twice as viscous",
                                       ViscousFreeDraining, solves=False))
WRITERS.register(Spec("step-times", "the time of every step", StepTimes))
FORCES.register(ForceSpec("split-repulsion", "the repulsion as two halves", split_repulsion, keys=("f0", "tau")))

if __name__ == "__main__":
    sys.exit(cli.main(sys.argv[1:]))
