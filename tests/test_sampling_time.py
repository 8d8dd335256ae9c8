"""Sample times: each stress stream is projected at the time its sample represents,
t_k + c dt with c the registry's ``sample_offset`` (sdmpi.config.stresses), and a step
moves the particles with its mean rate (gamma(t_{k+1}) - gamma(t_k))/dt.

Toy models that fail if the offset is not applied, not written, not read, or if the step
takes the start's rate gamma_dot(t_k) for the disturbance velocity."""

import math

import h5py
import numpy as np
import pytest

from sdmpi.analysis.projection import project_periods
from sdmpi.analysis.reduce import reduce_runs, sample_offsets
from sdmpi.config import enumerate_tasks, load_job, parse_job
from sdmpi.config.stresses import CONTRIBUTIONS, sample_offset
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.realisation import _at_step_rate
from sdmpi.dynamics.shear import NoShear, Oscillatory, Steady, affine_displacement, rate_of_strain
from sdmpi.hydro.basis import to_five
from sdmpi.hydro.geometry import Lattice
from .synthetic_run import write_run
from .runs import JOB, sdmpi as run_double
from .test_reduce import job_text

#: steps per period of test_reduce.job_text at 8 pi (spp = 16; 50 at 2 pi, set by dt_max)
N_PER = 16
#: the first harmonic of the collision toy stream, and of the hydrodynamic one
COLLISION, HYDRO = (0.7, 1.3), (0.1, 2.0)
STRESS_DATASETS = {c.dataset for c in CONTRIBUTIONS} | {"stress_hydrodynamic_maxwell",
                                                          "stresslets"}


def _sinusoid_run(path, attribute):
    """A noiseless synthetic run (tests/synthetic_run.py): a hydrodynamic stream sampled at
    t_k and a collision stream gamma0 (G' sin + G'' cos) sampled at t_k - dt/2, as the
    overlap correction's impulses are. ``attribute``: the collision dataset's
    sample_offset (None: absent, a file written without it)."""
    text = job_text(realisations=2, periods=6, discard=2, spp=N_PER)
    job = parse_job(text)
    series = {}
    for task in enumerate_tasks(job):
        w, t = task.omega, task.dt * (np.arange(task.n_steps) - 0.5)
        series[task.task_id] = {"stress_collision": job.shear.gamma0 * (
            COLLISION[0] * np.sin(w * t) + COLLISION[1] * np.cos(w * t))}
    write_run(path, text, {"hydrodynamic": HYDRO}, tasks=series)
    if attribute is not None:
        with h5py.File(path, "r+") as f:
            for task in f["tasks"].values():
                task["samples/stress_collision"].attrs["sample_offset"] = attribute
    return reduce_runs([path])


@pytest.mark.parametrize("attribute", [None, -0.5])
def test_a_stream_sampled_half_a_step_early_reduces_exactly_at_its_own_times(tmp_path, attribute):
    """Files without the attribute take the registry's -1/2 for the collision stream (they
    were written when the correction began the next step: `unrecorded_offset`); files
    with it, its value. The projection is exact for a sampled first harmonic (rectangle
    rule over whole periods, n = 50 and 16 >= 3), so G', G'' are the toy's to round-off
    (1e-12)."""
    red = _sinusoid_run(tmp_path / "run.h5", attribute)
    for phi in (0.3, 0.45):
        for omega in red.control:
            for comp, (g1, g2) in (("collision", COLLISION), ("hydrodynamic", HYDRO)):
                assert red.value(phi, omega, comp, "G_prime") == pytest.approx(g1, abs=1e-12)
                assert red.value(phi, omega, comp, "G_dprime") == pytest.approx(g2, abs=1e-12)


def test_projected_at_the_step_start_g_prime_lags_by_pi_over_n_g_dprime(tmp_path):
    """The same file with sample_offset = 0 written for the collision stream (the
    attribute is read, not the registry's value): the start-of-step convention gives
    G' cos(pi/n) + G'' sin(pi/n) and G'' cos(pi/n) - G' sin(pi/n) exactly, i.e. G' too
    large by (pi/n) G'' (at n = 16: 0.24, 34% of G'; at n = 50: 0.08) up to a relative
    -(pi/n) G'/(2 G'') = -5% at n = 16 (tolerance 10%)."""
    red = _sinusoid_run(tmp_path / "run.h5", 0.0)
    g1, g2 = COLLISION
    for omega in red.control:
        phi_n = math.pi / red.job.steps_per_period(omega)
        measured = red.value(0.3, omega, "collision", "G_prime")
        assert measured == pytest.approx(g1 * math.cos(phi_n) + g2 * math.sin(phi_n), abs=1e-12)
        assert red.value(0.3, omega, "collision", "G_dprime") == pytest.approx(
            g2 * math.cos(phi_n) - g1 * math.sin(phi_n), abs=1e-12)
        assert (measured - g1) / (phi_n * g2) == pytest.approx(1.0, abs=0.1)
    assert sorted({red.job.steps_per_period(w) for w in red.control}) == [N_PER, 50]


def test_projection_takes_one_sample_time_per_signal():
    """project_periods with an array t0 equals one call per signal, and a signal sampled at
    t_k + c dt is exact only with t0 = c dt (1e-12)."""
    omega, gamma0, n = 3.0, 0.05, 12
    dt = 2 * math.pi / (omega * n)
    offsets = np.array([0.0, -0.5, 0.25])
    t = dt * (np.arange(5 * n)[None, :] + offsets[:, None])
    sigma = gamma0 * (0.4 * np.sin(omega * t) + 1.1 * np.cos(omega * t))
    g1, g2 = project_periods(sigma, gamma0, omega, n, 1, t0=offsets * dt)
    assert g1.shape == (3, 4)
    np.testing.assert_allclose(g1, 0.4, atol=1e-12)
    np.testing.assert_allclose(g2, 1.1, atol=1e-12)
    for c, row in zip(offsets, sigma):
        one = project_periods(row, gamma0, omega, n, 1, t0=c * dt)
        np.testing.assert_array_equal(one[0], g1[offsets == c][0])
    assert abs(project_periods(sigma[1], gamma0, omega, n, 1)[0] - 0.4).min() > 0.1


def test_the_run_file_records_each_stress_streams_sample_time(tmp_path):
    """`sdmpi run` (with the test double, tests/ensemble_double.py: the real sample stream's
    datasets) writes sample_offset on every stress dataset, the registry's value (the
    collision +1/2, the rest 0; Maxwell-filtered and per-particle stresses those of the
    hydrodynamic stream), and on no other dataset; the reducer reads them back."""
    job_path = tmp_path / "job.toml"
    job_path.write_text(JOB)
    out = tmp_path / "run.h5"
    res = run_double("run", job_path, "-o", out)
    assert res.returncode == 0, res.stderr
    job = parse_job(JOB)
    with h5py.File(out, "r") as f:
        for key, task in f["tasks"].items():
            for name, ds in task["samples"].items():
                if name in STRESS_DATASETS:
                    assert ds.attrs["sample_offset"] == sample_offset(name), (key, name)
                else:
                    assert "sample_offset" not in ds.attrs, (key, name)
            assert task["samples/stress_collision"].attrs["sample_offset"] == 0.5
        tasks = enumerate_tasks(job)
        np.testing.assert_array_equal(sample_offsets(f, job, tasks[0]), [0.0, 0.0, 0.0, 0.5])
    reduce_runs([out])


# ------------------------------------------------------------------ the step's mean rate


def _pair(protocol_overrides, model="stokesian", gap=0.02):
    """A realisation of two spheres at this surface gap, non-Brownian, in a large box."""
    job = load_job("jobs/demo.toml", overrides=[
        "system.n_particles=2", "system.phi=[0.01]", "brownian.enabled=false",
        "ensemble.realisations=1", f"hydrodynamics.model='{model}'", *protocol_overrides])
    real = Realisation(job, enumerate_tasks(job)[0])
    state = real.get_state()
    e = np.array([1.0, -1.0, 0.2]) / math.sqrt(2.04)
    centre = real.box / 2
    state["positions"] = np.array([centre - (1 + gap / 2) * e, centre + (1 + gap / 2) * e])
    return real, state


def test_a_step_is_the_exact_affine_and_disturbance_displacement_of_its_strain():
    """Two lubricated spheres 0.02 apart in oscillatory shear (omega = 2 pi, gamma0 = 0.5,
    20 steps per period), step 3: at a frozen configuration the disturbance velocity is
    linear in the rate, u = gamma_dot u_1, so the exact displacement of the flow over the
    step is (gamma(t_4) - gamma(t_3)) (y e_x + u_1). The step reproduces it to round-off
    (1e-13 a; measured 0); the start's rate would miss it by (gamma_dot(t_3) dt - dgamma)
    |u_1|, here 7e-3 a (checked, so that the test can fail): the pair's relative velocity
    along its line of centres is (1 - A) times the affine one with A = 0.93, so it would be
    driven like the rate of A/(2(1 - A)) = 6 steps later."""
    real, state = _pair(["shear.omega=[6.283185307179586]", "shear.gamma0=0.5",
                         "integration.steps_per_period=20"])
    k = 3
    state["step"][0] = k
    real.set_state(state)
    protocol, dt = real.protocol, real.dt
    s0, s1 = protocol.strain(k * dt), protocol.strain((k + 1) * dt)
    pos = Lattice(real.box, s0).wrap(real.positions)
    u1 = real.model.at(pos, s0).velocities(np.zeros((2, 6)), np.tile(to_five(rate_of_strain(1.0)), (2, 1)))
    exact = Lattice(real.box, s1).wrap(pos + (s1 - s0) * u1[:, :3] + affine_displacement(pos, s0, s1))
    real.advance(1)
    assert np.abs(real.positions - exact).max() < 1e-13
    start_rate = Lattice(real.box, s1).wrap(pos + protocol.rate(k * dt) * dt * u1[:, :3]
                                            + affine_displacement(pos, s0, s1))
    assert np.abs(start_rate - exact).max() > 1e-3


def test_steady_and_no_shear_steps_are_unchanged():
    """Where the mean rate is the rate (steady shear, no shear) the step takes the very
    velocities of the rate (bit for bit: the same array); the mean rate of steady shear is
    its rate exactly, not the rounded difference of two strains; gamma_dot(t_k) = 0 with
    a nonzero mean rate takes one more solve, equal to the scaled one (1e-12)."""
    for t0 in (0.0, 0.1, 12345.678):
        assert Steady(0.3).mean_rate(t0, t0 + 1e-3) == 0.3
        assert NoShear().mean_rate(t0, t0 + 1e-3) == 0.0
    osc = Oscillatory(0.5, 2.0)
    assert osc.mean_rate(0.1, 0.2) == pytest.approx(
        0.5 * 2.0 * math.cos(0.3) * math.sin(0.1) / 0.1, rel=1e-12)   # cos(w t_m) sinc(w dt/2)
    real, state = _pair(["shear.protocol='steady'", "shear.rate=1.0", "integration.dt=1e-3",
                         "integration.n_steps=4", "integration.discard_steps=0"])
    real.set_state(state)
    at = real.model.at(real.positions, 0.0)
    e1 = np.tile(to_five(rate_of_strain(1.0)), (2, 1))
    u = at.velocities(np.zeros((2, 6)), e1)
    assert _at_step_rate(at, u, 1.0, 1.0) is u
    np.testing.assert_allclose(_at_step_rate(at, 0.0 * u, 0.0, 0.3), 0.3 * u, rtol=1e-12, atol=1e-15)


# ------------------------------------------------------------------ which time a stream represents


def test_collision_impulses_represent_the_middle_of_their_step():
    """Real code, free draining, non-Brownian: two hard spheres in contact along a
    compressional axis (omega = 1, gamma0 = 0.5; min_gap 1e-9, so that every step of the
    contact overlaps and is corrected). Over the first quarter period the shear holds them
    in contact; the collision stream at n = 32 steps per period is compared with a
    reference at 2048 (its own offset error 64 times smaller) at t_k + c dt. Measured rms
    differences, relative to the peak: 0.089 at c = 0 (the step's start), 0.022 at +1/2,
    0.055 at +1 (the step's end), 0.127 at +3/2 (0.042, 0.010, 0.028, 0.062 at n = 64:
    first order in dt). The best single c of this toy is ~0.65 (0.013), between the step's
    mean rate (+1/2) and the lines of centres, which the correction takes after the step
    (+1). Tolerance: +1/2 must reduce the error of +1 to below 0.7 of it (measured 0.4)
    and beat the step's start."""
    def collision_stream(n):
        real, state = _pair(["shear.omega=[1.0]", "shear.gamma0=0.5", f"integration.steps_per_period={n}",
                             "integration.periods=1", "integration.discard_periods=0",
                             "hydrodynamics.lubrication_cutoff=0.01", "hydrodynamics.min_gap=1e-9"],
                            model="free-draining", gap=0.0)
        real.set_state(state)
        return real.advance(real.n_steps)["stress_collision"][:, 3], real.dt
    ref, dt_ref = collision_stream(2048)
    xy, dt = collision_stream(32)
    t_ref, t = dt_ref * np.arange(len(ref)), dt * np.arange(len(xy))
    inside = np.flatnonzero(xy)[1:-1]              # in contact, away from its start and end
    assert len(inside) >= 5

    def error(c):
        diff = xy[inside] - np.interp(t[inside] + c * dt, t_ref, ref)
        return np.sqrt(np.mean(diff ** 2)) / np.abs(ref).max()
    assert error(0.5) < 0.7 * error(1.0)
    assert error(0.5) < error(0.0)


def test_explicit_state_streams_are_best_taken_at_the_step_start():
    """Why the Brownian and interparticle streams keep offset 0: a linear toy of the
    explicit step, x_{k+1} = x_k - (dt/tau) x_k + (gamma(t_{k+1}) - gamma(t_k)), whose
    stream x_k (a function of the configuration) has the exact modulus
    G* = i w tau/(1 + i w tau). The step's error acts like a shift of
    (dt/2) d ln G*/d ln w = (dt/2)/(1 + i w tau), so offset 0 is never further than
    (dt/(2 tau)) |G*| from exact, the explicit step's own accuracy, while +1/2 adds
    (pi/n) |G*| where the stream is elastic. At w tau = 10 (elastic) offset 0 is within
    0.1 (pi/n) |G*| (measured 0.098; tolerance 0.15) and +1/2 moves G'' by (pi/n) |G*|
    (measured 0.98, 15% of G''; tolerance 0.9); at w tau = 0.05 (viscous) +1/2 is exact
    to 0.05 (pi/n) |G*| (tolerance 0.1) and offset 0 is off in G' by (pi/n) G'' =
    dt/(2 tau) G' (measured 0.996 of it; tolerance 5%), i.e. 0.31 of G' at this coarse
    dt = 0.63 tau. n = 200 steps per period."""
    n, omega = 200, 1.0
    dt = 2 * math.pi / (omega * n)

    def toy(wtau):
        tau = wtau / omega
        t = dt * np.arange(40 * n + 1)
        gamma = np.sin(omega * t)
        x, out = 0.0, np.empty(40 * n)
        for k in range(40 * n):
            out[k] = x
            x += -dt * x / tau + gamma[k + 1] - gamma[k]
        exact = 1j * wtau / (1 + 1j * wtau)
        return out, exact
    for wtau in (10.0, 0.05):
        x, exact = toy(wtau)
        err = {c: np.array([g.mean() for g in project_periods(x, 1.0, omega, n, 20, t0=c * dt)])
               - [exact.real, exact.imag] for c in (0.0, 0.5)}
        scale = math.pi / n * abs(exact)
        if wtau > 1:
            assert np.abs(err[0.0]).max() < 0.15 * scale
            assert abs(err[0.5][1]) > 0.9 * scale
        else:
            assert err[0.0][0] == pytest.approx(-dt / (2 * wtau / omega) * exact.real, rel=0.05)
            assert np.abs(err[0.5]).max() < 0.1 * scale
