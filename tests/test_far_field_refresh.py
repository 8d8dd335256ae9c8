"""hydrodynamics.far_field_refresh: the far-field mobility held between refreshes, the
lubrication of every step's own configuration (Dratler & Schowalter 1996)."""

import subprocess
import sys

import numpy as np
import pytest

import sdmpi
from sdmpi.dynamics.realisation import Realisation

from .runs import child_env, fresh_lubrication_tables

#: eight spheres in non-Brownian steady shear with full Stokesian dynamics, dt = 0.01
STEADY = ['shear.protocol="steady"', "brownian.enabled=false", "system.n_particles=8", "system.phi=[0.3]",
          "integration.dt=0.01", "integration.n_steps=12", "integration.discard_steps=0", "ensemble.realisations=1"]


def _samples(*sets, steps=12):
    job = sdmpi.load_job("jobs/demo.toml", [*STEADY, *sets])
    fresh_lubrication_tables()
    real = Realisation(job, sdmpi.tasks(job)[0])
    return real, real.advance(steps)


def test_refresh_every_step_is_no_refresh():
    """Held for one step, the far field is that of the step's own configuration: the same
    samples bit for bit as without holding it (the held blocks are the same numbers, only
    computed in another call). (Not so with adams-bashforth-4, whose Runge-Kutta start-up
    evaluates its stages with the far field of the step's start.)"""
    _, plain = _samples()
    _, held = _samples("hydrodynamics.far_field_refresh=0.01")
    for key in plain:
        assert np.array_equal(plain[key], held[key]), key


def test_held_far_field_changes_the_stress_a_little():
    """Held for 5 steps (a strain of 0.05), the far field lags the configuration: the
    hydrodynamic stress differs from the fresh one by an amount growing over each interval
    (measured 1.5e-3, 3.0e-3, 4.6e-3, 6.3e-3 of the largest stress at steps 1-4), and drops
    at the refreshes, steps 5 and 10 (7.7e-5 and 1.2e-4: only the configurations' drift
    apart remains). Taken: every difference below 1e-2, and the last one before each
    refresh above 10 times that at the refresh."""
    _, plain = _samples()
    _, held = _samples("hydrodynamics.far_field_refresh=0.05")
    a, b = plain["stress_hydrodynamic"], held["stress_hydrodynamic"]
    assert np.array_equal(a[0], b[0])
    difference = np.abs(a - b).max(axis=1) / np.abs(a).max()
    assert difference.max() < 1e-2, difference
    assert difference[4] > 10 * difference[5] and difference[9] > 10 * difference[10], difference


@pytest.mark.parametrize("stop", [3, 5])
def test_resume_between_refreshes_is_bitwise(stop):
    """A state saved between refreshes (3) or at one (5) holds the start of the last
    refresh, from which the restored realisation rebuilds the held far field: it steps on
    bit for bit."""
    sets = ["hydrodynamics.far_field_refresh=0.05", 'integration.scheme="adams-bashforth-4"']
    straight, _ = _samples(*sets, steps=stop)
    state = straight.get_state()
    rest = straight.advance(12 - stop)
    job = sdmpi.load_job("jobs/demo.toml", [*STEADY, *sets])
    resumed = Realisation(job, sdmpi.tasks(job)[0])
    resumed.set_state(state)
    again = resumed.advance(12 - stop)
    for key in rest:
        assert np.array_equal(rest[key], again[key]), key


@pytest.mark.parametrize("sets,why", [
    (["brownian.enabled=true"], "the Brownian drift needs the mobility of the step's own configuration"),
    (['hydrodynamics.model="free-draining"'], "the free-draining model has no far field"),
    (['solver.backend="petsc-krylov"'], "held only by the backends that form it"),
])
def test_far_field_refresh_refused_where_it_does_not_apply(sets, why):
    cmd = [sys.executable, "-m", "sdmpi", "validate", "jobs/demo.toml", "--set", "hydrodynamics.far_field_refresh=0.1"]
    for s in [*STEADY[:2], *sets]:
        cmd += ["--set", s]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=120)
    assert res.returncode == 2 and "hydrodynamics.far_field_refresh = 0.1" in res.stderr and why in res.stderr, \
        res.stderr


def test_far_field_refresh_with_auto_follows_what_auto_resolves_to():
    """solver.backend = "auto" holds the far field where it resolves to a direct backend
    (N = 8: dense) and is refused where it resolves to petsc-krylov (N >= 1000 on one rank)."""
    from sdmpi.config import JobError

    sets = [*STEADY[:2], "hydrodynamics.far_field_refresh=0.1", 'solver.backend="auto"']
    assert sdmpi.load_job("jobs/demo.toml", sets).hydrodynamics.far_field_refresh == 0.1  # N = 8: dense
    with pytest.raises(JobError, match="held only by the backends that form it"):
        sdmpi.load_job("jobs/demo.toml", [*sets, "system.n_particles=1000"])
