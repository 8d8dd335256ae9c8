"""A cheap test double of sdmpi.dynamics.Realisation (same interface, no physics).

A deterministic-random signal: a random walk of N points driven by the task's own stream
SeedSequence(job seed, spawn_key=(task_id,)); the PCG64 state is part of the realisation
state, so a restored state continues bit for bit. ``SDMPI_DOUBLE_SLEEP`` (seconds per
step) slows it down for the signal tests.
"""

import math
import os
import time

import numpy as np

from sdmpi.dynamics.setup import sample_fields

SLEEP = float(os.environ.get("SDMPI_DOUBLE_SLEEP", "0"))


class DoubleRealisation:
    def __init__(self, job, task):
        self.job, self.task = job, task
        seq = np.random.SeedSequence(job.job.seed, spawn_key=(task.task_id,))
        self.rng = np.random.Generator(np.random.PCG64(seq))
        self.n_particles = job.system.n_particles
        self.box = np.full(3, (4 * math.pi * self.n_particles / (3 * task.phi)) ** (1 / 3))
        self.n_steps, self.step, self.dt = task.n_steps, 0, task.dt
        self.x = self.rng.uniform(0, self.box[0], (self.n_particles, 3))
        self.omega = task.omega or 0.0
        self.gamma0 = job.shear.gamma0 or 0.0

    def sample_fields(self):
        return sample_fields(self.job)  # the real stream's datasets

    def state_fields(self):
        return {"positions": ((self.n_particles, 3), "f8"), "step": ((1,), "i8"),
                "rng": ((6,), "u8")}

    def get_state(self):
        st = self.rng.bit_generator.state
        mask = (1 << 64) - 1
        s, inc = st["state"]["state"], st["state"]["inc"]
        rng = np.array([s >> 64, s & mask, inc >> 64, inc & mask, st["has_uint32"],
                        st["uinteger"]], dtype=np.uint64)
        return {"positions": self.x.copy(), "step": np.array([self.step]), "rng": rng}

    def set_state(self, state):
        self.x = np.array(state["positions"], dtype=float)
        self.step = int(state["step"][0])
        a = [int(v) for v in state["rng"]]
        self.rng.bit_generator.state = {
            "bit_generator": "PCG64",
            "state": {"state": (a[0] << 64) | a[1], "inc": (a[2] << 64) | a[3]},
            "has_uint32": a[4], "uinteger": a[5]}

    def advance(self, n):
        n = min(n, self.n_steps - self.step)
        fields = self.sample_fields()
        out = {k: np.empty((n, *shape), dtype=d) for k, (shape, d, _, _) in fields.items()}
        for i in range(n):
            if SLEEP:
                time.sleep(SLEEP)
            t = self.step * self.dt
            kick = self.rng.standard_normal((self.n_particles, 3))
            self.x += 0.1 * kick
            out["time"][i] = t
            out["strain"][i] = self.gamma0 * math.sin(self.omega * t)
            out["rate"][i] = self.gamma0 * self.omega * math.cos(self.omega * t)
            m = self.x.T @ self.x / self.n_particles
            six = np.array([m[0, 0], m[1, 1], m[2, 2], m[0, 1], m[0, 2], m[1, 2]])
            out["stress_hydrodynamic"][i] = six
            out["stress_brownian"][i] = kick[:2].ravel()
            out["stress_interparticle"][i] = -six
            out["stress_collision"][i] = 0.25 * six
            out["n_overlaps"][i] = int(np.sum(np.abs(kick) > 2.5))
            out["n_overlaps_midpoint"][i] = int(np.sum(np.abs(kick) > 3.0))
            out["min_gap"][i] = float(np.min(np.abs(kick)))
            out["solver_iterations"][i] = out["lanczos_iterations"][i] = 0  # a direct backend
            out["solver_residual"][i] = 0.0
            if "stress_hydrodynamic_maxwell" in out:
                out["stress_hydrodynamic_maxwell"][i] = 0.5 * six
            if "stresslets" in out:
                out["stresslets"][i] = np.hstack([self.x, kick[:, :2]])
            self.step += 1
        return out
