"""Brownian SD dynamics: periodic self-diffusion, oscillatory shear of a simple cubic
lattice (Newtonian and Maxwell media), checkpointable state. Fluctuation-dissipation and the
drift of every drift scheme: tests/test_dynamics_contract.py."""

import math

import numpy as np
import pytest

from sdmpi.analysis.projection import project_periods
from sdmpi.config import enumerate_tasks, load_job
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.media import MaxwellFilter
from sdmpi.hydro.bulk import hydrodynamic_viscosity

def _job(*overrides):
    return load_job("jobs/demo.toml", overrides=list(overrides))


def test_split_rfd_draws_the_stress_noise_after_the_steps_other_noise():
    """A realisation with rfd-split draws z, the near-contact z', then z_stress each step: its
    first step's displacement equals rfd's from the same start (the same z and z'), and the
    stress differs."""
    samples, positions = {}, {}
    for scheme in ("rfd", "rfd-split"):
        job = _job("system.n_particles=8", f"brownian.scheme='{scheme}'")
        real = Realisation(job, enumerate_tasks(job)[0])
        samples[scheme] = real.advance(1)
        positions[scheme] = real.positions.copy()
    assert np.array_equal(positions["rfd"], positions["rfd-split"])
    assert np.array_equal(samples["rfd"]["stress_hydrodynamic"], samples["rfd-split"]["stress_hydrodynamic"])
    assert not np.array_equal(samples["rfd"]["stress_brownian"], samples["rfd-split"]["stress_brownian"])


def test_single_sphere_self_diffusion_in_periodic_box():
    """Equilibrium, one sphere per box of side L: D/D0 = 1 - 2.837297/L + 4.18879/L^3.
    Estimated from 3 x 3000 one-step displacements: relative standard error
    sqrt(2/9000) = 1.5%; tolerance 6% (4 sigma). L = 3.47 (phi = 0.1) gives D/D0 = 0.28,
    far from 1, so a missing periodic correction fails."""
    job = _job("system.n_particles=1", "system.phi=[0.1]", "shear.protocol='none'",
               "integration.dt=0.001", "integration.n_steps=3000", "integration.discard_steps=0")
    real = Realisation(job, enumerate_tasks(job)[0])
    steps = []
    for _ in range(3000):
        before = real.positions.copy()
        real.advance(1)
        d = real.positions - before
        d -= np.round(d / real.box) * real.box
        steps.append(d[0])
    side = real.box[0]
    measured = np.mean(np.square(steps)) / (2 * real.dt)
    expected = 1 - 2.837297 / side + 4.18879 / side ** 3
    assert measured == pytest.approx(expected, rel=0.06)


def _lattice_moduli(medium, steps_per_period=256, periods=12, discard=10, omega=2 * math.pi):
    job = _job("system.n_particles=1", "system.phi=[0.2]", "brownian.enabled=false",
               f"shear.omega=[{omega}]", "shear.gamma0=0.02",
               f"integration.steps_per_period={steps_per_period}", f"integration.periods={periods}",
               f"integration.discard_periods={discard}", *medium)
    real = Realisation(job, enumerate_tasks(job)[0])
    out = real.advance(real.n_steps)
    moduli = {}
    for key in ("stress_hydrodynamic", "stress_hydrodynamic_maxwell"):
        if key in out:
            g1, g2 = project_periods(out[key][:, 3], 0.02, omega, steps_per_period, discard)
            moduli[key] = (g1.mean(), g2.mean())
    return real, moduli


def test_simple_cubic_lattice_newtonian_and_maxwell():
    """Non-Brownian, one sphere per cubic cell: the particle follows the affine flow and
    the stress is eta_H(gamma) gamma_dot with eta_H even in gamma, so G' = 0 to round-off
    and G''/omega = eta_H(0) + O(gamma0^2). In a one-mode Maxwell medium the
    hydrodynamic stress is that signal filtered: eta* = eta_N/(1 + i omega lambda)."""
    omega, lam = 2 * math.pi, 0.5
    real, newt = _lattice_moduli([])
    g1, g2 = newt["stress_hydrodynamic"]
    eta0 = hydrodynamic_viscosity(real.positions, real.box)
    assert abs(g1) < 1e-10 * g2
    # gamma0^2 = 4e-4: the strain dependence of eta_H enters at that relative order
    assert g2 / omega == pytest.approx(eta0, rel=1e-3)
    _, maxw = _lattice_moduli(["medium.kind='maxwell'", f"medium.modes=[{{eta=1.0, lambda={lam}}}]"])
    m1, m2 = maxw["stress_hydrodynamic_maxwell"]
    eta_n = g2 / omega
    denom = 1 + (omega * lam) ** 2
    # 256 steps per period: the linear-in-step source of the exact filter update is
    # accurate to (omega dt)^2/12 = 5e-5
    assert m2 / omega == pytest.approx(eta_n / denom, rel=1e-4)
    assert m1 / omega == pytest.approx(eta_n * omega * lam / denom, rel=1e-4)


def test_maxwell_filter_exact_for_linear_source():
    """The step update integrates lambda dS/dt + S = eta S0 exactly for linear S0."""
    filt = MaxwellFilter((0.7,), (0.3,), 0.05)
    modes = np.array([[2.0]])
    s_old, s_new = np.array([1.0]), np.array([1.5])
    filt.update(modes, s_old, s_new)
    # exact: y' = (-y + eta (s_old + (s_new - s_old) t/dt)) / lam, y(0) = 2
    from scipy.integrate import solve_ivp
    sol = solve_ivp(lambda t, y: (-y + 0.7 * (1.0 + 0.5 * t / 0.05)) / 0.3, (0, 0.05), [2.0],
                    rtol=1e-12, atol=1e-14)
    assert modes[0, 0] == pytest.approx(sol.y[0, -1], rel=1e-10)


def test_state_round_trip_is_bitwise():
    job = _job("medium.kind='maxwell'", "medium.modes=[{eta=0.6, lambda=0.5}, {eta=0.4, lambda=0.1}]",
               "output.per_particle=true")
    task = enumerate_tasks(job)[1]
    straight = Realisation(job, task)
    first = straight.advance(7)
    rest = straight.advance(6)
    resumed = Realisation(job, task)
    resumed.advance(3)  # a different history, overwritten by the state
    copy = Realisation(job, task)
    copy.advance(7)
    resumed.set_state(copy.get_state())
    again = resumed.advance(6)
    assert set(rest) == set(again) and "stresslets" in rest
    for key in rest:
        assert np.array_equal(rest[key], again[key]), key
    assert first["time"][0] == 0.0 and rest["time"][0] == 7 * task.dt


def test_indefinite_far_field_names_the_ewald_tolerance():
    """Two spheres at phi = 0.45 (box side 2.65): Ewald sums to 1e-3 leave M_inf indefinite
    at the start of seed 1's realisation. It stops with a RealisationFailed that names the task, the
    step and hydrodynamics.ewald_tolerance (not the time step); the job's own default for
    so small a box (1e-4) runs."""
    from sdmpi.dynamics.realisation import RealisationFailed

    job = _job("job.seed=1", "system.n_particles=2", "system.phi=[0.45]", "hydrodynamics.ewald_tolerance=1e-3")
    real = Realisation(job, enumerate_tasks(job)[0])
    with pytest.raises(RealisationFailed, match=r"task 0, step 0: the far-field mobility M_inf is not "
                                                r"positive definite .*hydrodynamics\.ewald_tolerance = 0\.001"):
        real.advance(1)
    job = _job("job.seed=1", "system.n_particles=2", "system.phi=[0.45]")
    assert job.ewald_tolerance == 1e-4
    real = Realisation(job, enumerate_tasks(job)[0])
    real.advance(3)
    assert np.all(np.isfinite(real.positions))
