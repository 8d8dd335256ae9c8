"""Seed 000 (Schaink et al. 2000) at small cost: phi = 0.45, N = 27, Brownian SD in a
viscous and in a Maxwell medium. The full studies are jobs/schaink2000_*.toml."""

import dataclasses
import math

import numpy as np
import pytest

from sdmpi.analysis.projection import project_periods
from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation

STEPS = 48  # per period in the Maxwell test: the point is the structure of the signal


def _run(omega, *overrides, steps=STEPS, periods=1):
    job = load_job("jobs/schaink2000_newtonian.toml", overrides=[
        f"shear.omega=[{omega}]", f"integration.steps_per_period={steps}", "integration.dt_max=1.0",
        f"integration.periods={periods}", "integration.discard_periods=0", *overrides])
    # the same task id at every frequency: the same initial configuration and noise
    task = dataclasses.replace(enumerate_tasks(job)[0], task_id=0)
    real = Realisation(job, task)
    return real.advance(real.n_steps)


def test_hydrodynamic_viscosity_frequency_independent():
    """eta'_H = G''_H/omega is the hydrodynamic viscosity eta_H(x(t)) averaged over the
    configurations visited (cos^2-weighted). With the same start, noise and time step
    (dt = 1e-3 t_D), omega = 20 pi (1 period) and 40 pi (2 periods) cover the same
    0.1 t_D of nearly the same trajectory (gamma0 = 0.02): their eta'_H must agree to 3%
    although eta_H differs by ~10% between configurations, and G'_H must be small (the
    hydrodynamic stress follows the rate). The ensemble statement (eq. 38) is in
    test_high_frequency_viscosity and the full study in jobs/schaink2000_newtonian.toml."""
    eta = []
    for omega, steps, periods in ((20 * math.pi, 100, 1), (40 * math.pi, 50, 2)):
        out = _run(omega, steps=steps, periods=periods)
        g1, g2 = project_periods(out["stress_hydrodynamic"][:, 3], 0.02, omega, steps)
        eta.append(g2.mean() / omega)
        assert abs(g1.mean()) < 0.1 * abs(g2.mean())
    assert eta[0] == pytest.approx(eta[1], rel=0.03)
    assert 2.0 < eta[0] < 7.0  # far above the dilute value 2.5 phi + 5.2 phi^2 = 2.18


def test_maxwell_medium_same_trajectories_filtered_stress():
    """Seed eq. 32: in a Maxwell medium the trajectories (and so the viscous-medium
    stresslets) are those of the viscous medium; eqs. 33-34: the hydrodynamic stress is
    that signal filtered by lambda dS/dt + S = S_0. Checked against an independent
    integration of the filter ODE on the piecewise-linear source."""
    from scipy.integrate import solve_ivp

    omega, lam = 20 * math.pi, 0.5
    newt = _run(omega)
    maxw = _run(omega, "medium.kind='maxwell'", f"medium.modes=[{{eta=1.0, lambda={lam}}}]")
    assert np.array_equal(newt["stress_hydrodynamic"], maxw["stress_hydrodynamic"])
    t = newt["time"]
    source = newt["stress_hydrodynamic"][:, 3]
    sol = solve_ivp(lambda s, y: (-y + np.interp(s, t, source)) / lam, (t[0], t[-1]), [0.0],
                    t_eval=t, rtol=1e-11, atol=1e-13, max_step=(t[1] - t[0]) / 4)
    got = maxw["stress_hydrodynamic_maxwell"][:, 3]
    assert np.allclose(got, sol.y[0], rtol=1e-7, atol=1e-9 * np.abs(source).max())
