"""The time integrators (`sdmpi.dynamics.integrators`, integration.scheme): the
fourth-order Adams-Bashforth integrator's exactness, order and resumability, and the
messages that refuse what it does not integrate."""

import subprocess
import sys

import h5py
import numpy as np
import pytest

import sdmpi
from sdmpi.dynamics.realisation import Realisation
from sdmpi.dynamics.integrators import AdamsBashforth4, EulerMaruyama, Motion, Step
from sdmpi.dynamics.shear import Steady
from sdmpi.hydro.geometry import Lattice

from .runs import child_env, fresh_lubrication_tables

#: three free-draining spheres in steady shear that push each other apart by the smooth
#: repulsion of Dratler & Schowalter (1996), never touching (smallest gap 0.019): a smooth
#: deterministic trajectory; steps of the start-up (k < 3) and of AB4 alike
SMOOTH = ['shear.protocol="steady"', "brownian.enabled=false", "system.n_particles=3", "system.phi=[0.3]",
          "integration.discard_steps=0", 'interparticle.kind="repulsion"', "interparticle.f0=0.5",
          "interparticle.tau=8.0", "hydrodynamics.lubrication_cutoff=3.5", 'hydrodynamics.model="free-draining"',
          "ensemble.realisations=1"]
DEMO = "jobs/demo.toml"


def _smooth_run(scheme, n_steps, duration=2.0, extra=()):
    """The end positions and box of the smooth problem over ``duration`` in ``n_steps`` steps."""
    job = sdmpi.load_job(DEMO, [*SMOOTH, f'integration.scheme="{scheme}"', f"integration.dt={duration / n_steps}",
                                f"integration.n_steps={n_steps}", *extra])
    real = Realisation(job, sdmpi.tasks(job)[0])
    samples = real.advance(n_steps)
    assert not samples["n_overlaps"].any()
    return real.positions, real.box


def test_adams_bashforth_is_exact_for_cubic_motion_through_the_lees_edwards_boundary():
    """One sphere with U' = (0, c + b t, 0) in steady shear: y = y0 + c t + b t^2/2 and
    x = x0 + rate (y0 t + c t^2/2 + b t^3/6), a cubic that the Runge-Kutta start-up and AB4
    integrate exactly. The sphere crosses the Lees-Edwards boundary y = L twice over the run
    (its wrapped heights jump by L, its images by strain L in x), so a history of total
    velocities, or of heights without their nearest image, would be off by rate L.
    Agreement to 1e-12 (rounding of ~60 steps of O(10) numbers)."""
    box, rate, c, b, dt, steps = np.array([4.0, 4.0, 4.0]), 0.7, 0.9, 0.3, 0.1, 60
    protocol = Steady(rate)

    def velocity(positions, t):
        u = np.zeros((len(positions), 6))
        u[:, 1] = c + b * t
        return u

    integrator = AdamsBashforth4(Motion(1, box, dt, protocol, None, "separate", velocity))
    x0 = np.array([[1.0, 3.5, 2.0]])
    x = x0.copy()
    for k in range(steps):
        x, collisions = integrator.move(Step(k, x, velocity(x, k * dt), np.zeros((1, 6)), None))
        assert collisions.n_overlaps == 0
    t = steps * dt
    exact = x0 + np.array([[rate * (x0[0, 1] * t + c * t ** 2 / 2 + b * t ** 3 / 6), c * t + b * t ** 2 / 2, 0.0]])
    assert exact[0, 1] > 2 * box[1]  # crossed twice
    lattice = Lattice(box, protocol.strain(t))
    assert np.abs(lattice.nearest_image(x - exact)).max() < 1e-12


def test_adams_bashforth_converges_at_fourth_order():
    """Halving dt divides AB4's error at t = 2 by 2^4 = 16 (measured 15.0, 15.2; taken
    between 13 and 19), that of Euler-Maruyama on the same problem by 2 (measured 2.00:
    the problem is not one that every scheme integrates exactly). Reference: AB4 with a
    quarter of the smallest step (its error ~2e-11, 0.4% of the smallest error here,
    4.5e-9). At dt = 0.025 the repulsion's stiffness is outside AB4's stability region
    (explicit multistep: |lambda dt| below ~0.3) and the spheres overlap; Euler-Maruyama's
    region is larger."""
    reference, box = _smooth_run("adams-bashforth-4", 2560)
    lattice = Lattice(box, 2.0)

    def errors(scheme, steps):
        return [np.abs(lattice.nearest_image(_smooth_run(scheme, n)[0] - reference)).max() for n in steps]

    ab4 = errors("adams-bashforth-4", (160, 320, 640))
    assert all(13 < coarse / fine < 19 for coarse, fine in zip(ab4, ab4[1:])), ab4
    euler = errors("euler-maruyama", (160, 320))
    assert 1.9 < euler[0] / euler[1] < 2.1, euler
    assert ab4[0] < 1e-3 * euler[0]


def test_adams_bashforth_converges_at_fourth_order_in_oscillatory_shear():
    """The same spheres in oscillatory shear gamma(t) = 0.5 sin(3 t) over one period (time
    unit t_D, a stronger repulsion, f0 = 2, keeps them apart there): the rate changes
    within a step and the history's rates are those of their own times. Halving dt from
    2 pi / (3 x 640) divides the error by 14.7 and 14.3 (taken: between 12 and 19;
    reference 10240 steps, error ~3e-12 against the smallest here, 7e-10)."""
    sets = ['shear.protocol="oscillatory"', "shear.gamma0=0.5", "shear.omega=[3.0]", "interparticle.f0=2.0",
            "integration.periods=1", "integration.discard_periods=0", 'integration.scheme="adams-bashforth-4"']
    common = [item for item in SMOOTH if not item.startswith(("shear.", "integration.", "interparticle.f0"))]

    def end(steps):
        job = sdmpi.load_job(DEMO, [*common, *sets, f"integration.steps_per_period={steps}"])
        real = Realisation(job, sdmpi.tasks(job)[0])
        assert not real.advance(real.n_steps)["n_overlaps"].any()
        return real.positions, real.box

    reference, box = end(10240)
    lattice = Lattice(box, 0.0)
    errors = [np.abs(lattice.nearest_image(end(n)[0] - reference)).max() for n in (640, 1280, 2560)]
    assert all(12 < coarse / fine < 19 for coarse, fine in zip(errors, errors[1:])), errors


@pytest.mark.parametrize("stop", [2, 7])
def test_adams_bashforth_history_is_state(stop):
    """A realisation restored from the state after ``stop`` steps (2: inside the Runge-Kutta
    start-up, 7: with a full AB4 history) steps on bit for bit; the state holds the history."""
    job = sdmpi.load_job(DEMO, [*SMOOTH, 'integration.scheme="adams-bashforth-4"', "integration.dt=0.02",
                                "integration.n_steps=12"])
    task = sdmpi.tasks(job)[0]
    straight = Realisation(job, task)
    straight.advance(stop)
    state = straight.get_state()
    assert set(straight.state_fields()) == set(state) >= {"ab4_velocities", "ab4_heights"}
    for name, (shape, dtype) in straight.state_fields().items():
        assert state[name].shape == tuple(shape) and state[name].dtype == np.dtype(dtype), name
    rest = straight.advance(12 - stop)
    resumed = Realisation(job, task)
    resumed.advance(1)  # a different history, overwritten by the state
    resumed.set_state(state)
    again = resumed.advance(12 - stop)
    for key in rest:
        assert np.array_equal(rest[key], again[key]), key
    assert np.array_equal(straight.positions, resumed.positions)


def test_killed_adams_bashforth_run_resumes_bit_for_bit(tmp_path):
    """`sdmpi run` killed (SIGKILL) after step 9 of a 16-step AB4 task with checkpoints every
    4 steps resumes from step 8 and ends with the file of an uninterrupted run."""
    job = tmp_path / "job.toml"
    job.write_text(open(DEMO).read())
    sets = [a for s in [*SMOOTH, 'integration.scheme="adams-bashforth-4"', "integration.dt=0.02",
                        "integration.n_steps=16", "output.checkpoint_every=4"] for a in ("--set", s)]

    def run(out, env=None):
        return subprocess.run([sys.executable, "-m", "sdmpi", "run", str(job), "-o", str(out), *sets],
                              capture_output=True, text=True, env=child_env(env), timeout=300)

    assert run(tmp_path / "straight.h5").returncode == 0
    killed = run(tmp_path / "resumed.h5", {"SDMPI_TEST_KILL": "step:9"})
    assert killed.returncode != 0
    res = run(tmp_path / "resumed.h5")
    assert res.returncode == 0, res.stderr
    with h5py.File(tmp_path / "straight.h5", "r") as a, h5py.File(tmp_path / "resumed.h5", "r") as b:
        for name, data in a["tasks/000000/samples"].items():
            assert np.array_equal(data[()], b["tasks/000000/samples"][name][()], equal_nan=True), name


@pytest.mark.parametrize("sets,words", [
    (["brownian.enabled=true"], ["integration.scheme", "adams-bashforth-4", "not Brownian motion",
                                 '"euler-maruyama", or brownian.enabled = false']),
    (['interparticle.kind="frictional"', "brownian.enabled=false", 'shear.protocol="steady"'],
     ["integration.scheme", "frictional contacts", 'allowed: "euler-maruyama"']),
])
def test_what_adams_bashforth_cannot_integrate_is_refused(sets, words):
    """`sdmpi validate` names the key, why and what is allowed, exit 2, nothing written."""
    cmd = [sys.executable, "-m", "sdmpi", "validate", DEMO, "--set", 'integration.scheme="adams-bashforth-4"']
    for s in sets:
        cmd += ["--set", s]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=120)
    assert res.returncode == 2, res.stderr
    for word in words:
        assert word in res.stderr, (word, res.stderr)
    assert "Traceback" not in res.stderr


def test_unknown_integrator_gets_a_did_you_mean():
    with pytest.raises(sdmpi.config.JobError, match=r'integration.scheme = "adams-bashforth": .*'
                                                    r'"euler-maruyama", "adams-bashforth-4"'):
        sdmpi.load_job(DEMO, ['integration.scheme="adams-bashforth"'])


def test_euler_maruyama_has_no_state():
    """The explicit step keeps nothing between steps: the realisation's state is that of
    before the integrators were declared (positions, step, random stream)."""
    job = sdmpi.load_job(DEMO, ["system.n_particles=2"])
    fresh_lubrication_tables()
    real = Realisation(job, sdmpi.tasks(job)[0])
    assert isinstance(real.integrator, EulerMaruyama)
    assert set(real.state_fields()) == {"positions", "step", "rng"}
