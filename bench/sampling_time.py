"""Two spheres in oscillatory shear (omega = 1, gamma0 = 0.5, non-Brownian), stepped by
`sdmpi.dynamics.Realisation`: the numbers of docs/physics.md "Sample times".

1. A lubricated pair (stokesian, initial gap 0.04 along a compressional axis): the largest
   |ln(gap / gap_ref)| over the first half period at 16 ... 128 steps per period against a
   4096-step reference, with the step's mean rate in the disturbance velocity (as sdmpi
   steps) and with the start's rate gamma_dot(t_k) instead.
2. A hard-sphere pair held in contact by the shear (free draining, min_gap 1e-9): the rms
   difference of the collision stream at 32 and 64 steps per period from a 2048-step
   reference read at t_k + c dt, for c = 0, -1/2, +1/2 and the best c.

    python bench/sampling_time.py        # ~10 s on one core
"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sdmpi.config import enumerate_tasks, load_job  # noqa: E402
from sdmpi.dynamics import Realisation  # noqa: E402

JOB = Path(__file__).resolve().parents[1] / "jobs" / "demo.toml"


class StartRate:
    """A protocol whose step rate is the start's rate (for comparison only)."""

    def __init__(self, protocol):
        self.protocol = protocol

    def strain(self, t):
        return self.protocol.strain(t)

    def rate(self, t):
        return self.protocol.rate(t)

    def mean_rate(self, t0, t1):
        return self.protocol.rate(t0)


def pair(n, model, gap, periods=1, extra=(), start_rate=False):
    job = load_job(JOB, overrides=[
        "system.n_particles=2", "system.phi=[0.01]", "brownian.enabled=false",
        "ensemble.realisations=1", f"hydrodynamics.model='{model}'", "shear.omega=[1.0]",
        "shear.gamma0=0.5", f"integration.steps_per_period={n}", f"integration.periods={periods}",
        "integration.discard_periods=0", *extra])
    real = Realisation(job, enumerate_tasks(job)[0])
    if start_rate:
        real.protocol = StartRate(real.protocol)
    state = real.get_state()
    e = np.array([1.0, -1.0, 0.2]) / math.sqrt(2.04)
    centre = real.box / 2
    state["positions"] = np.array([centre - (1 + gap / 2) * e, centre + (1 + gap / 2) * e])
    real.set_state(state)
    return real


def gaps(n, start_rate):
    real = pair(n, "stokesian", 0.04, start_rate=start_rate)
    out = np.empty(real.n_steps)
    for k in range(real.n_steps):
        out[k] = np.linalg.norm(real.positions[1] - real.positions[0]) - 2
        real.advance(1)
    return out


def collision_stream(n):
    real = pair(n, "free-draining", 0.0, extra=("hydrodynamics.lubrication_cutoff=0.01",
                                                  "hydrodynamics.min_gap=1e-9"))
    return real.advance(real.n_steps)["stress_collision"][:, 3], real.dt


def main():
    ref = gaps(4096, False)
    print("lubricated pair: max |ln(gap/gap_ref)| over the first half period")
    for n in (16, 32, 64, 128):
        r = ref[::4096 // n][:n // 2]
        row = [np.abs(np.log(gaps(n, s)[:n // 2] / r)).max() for s in (False, True)]
        print(f"  n = {n:4d}: mean rate {row[0]:.2f}, start rate {row[1]:.2f}", flush=True)
    ref, dt_ref = collision_stream(2048)
    t_ref = dt_ref * np.arange(len(ref))
    print("collision pair: rms difference / peak from the reference at t_k + c dt")
    for n in (32, 64):
        xy, dt = collision_stream(n)
        t, inside = dt * np.arange(n), np.flatnonzero(xy)[1:-1]

        def error(c):
            return np.sqrt(np.mean((xy[inside] - np.interp(t[inside] + c * dt, t_ref, ref)) ** 2)) \
                / np.abs(ref).max()
        cs = np.linspace(-1.0, 0.5, 61)
        best = cs[np.argmin([error(c) for c in cs])]
        print(f"  n = {n:3d}: c = 0 {error(0.0):.3f}, c = -1/2 {error(-0.5):.3f}, "
              f"c = +1/2 {error(0.5):.3f}, best c = {best:+.3f} ({error(best):.3f})", flush=True)


if __name__ == "__main__":
    main()
