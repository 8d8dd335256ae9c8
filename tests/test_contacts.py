"""Frictional contacts (sdmpi.dynamics.contacts; Mari et al., J. Rheol. 58, 1693 (2014)):
the repulsion and the springs against their energies, Newton's third law for forces and
torques, the virial, Coulomb's limit, the history (tangent, sign, reset, overflow), the
sliding velocity, the job keys, a two-sphere trajectory against an independent
integration, and checkpoint/resume bit for bit (in process, and under mpirun -n 2)."""

import dataclasses
import importlib.util
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sdmpi.cli import main
from sdmpi.config import JobError, enumerate_tasks
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.checks import load_job, parse_job
from sdmpi.dynamics.contacts import (ContactLaw, CriticalLoadRepulsion, FrictionalContacts, sliding_mobility,
                                     sliding_velocity, tangent)
from sdmpi.dynamics.forces import FORCE_UNIT, PairForce
from sdmpi.dynamics.integrators import EulerMaruyama
from sdmpi.dynamics.setup import forces_of, hydrodynamic_model
from sdmpi.hydro import solve_mobility
from sdmpi.hydro.basis import to_five
from sdmpi.hydro.lubrication import close_pairs
from sdmpi.hydro.resistance import grand_resistance
from sdmpi.hydro.solvers import DenseSolver
from .test_ensemble_real import sdmpi

ROOT = Path(__file__).resolve().parents[1]
MPIRUN = shutil.which("mpirun")
BASE = '[shear]\nprotocol = "steady"\nrate = 1.0\n[brownian]\nenabled = false\n'
FRICTION = ('[interparticle]\nkind = "frictional"\nmu = {mu}\nk_n = {k_n}\nk_t = {k_t}\n'
            'f_r0 = {f_r0}\nrepulsion_length = 0.05\n')


def frictional_job(extra="", mu=0.5, k_n=1000.0, k_t=500.0, f_r0=0.01):
    return parse_job(BASE + FRICTION.format(mu=mu, k_n=k_n, k_t=k_t, f_r0=f_r0)
                     + '[hydrodynamics]\nmin_gap = 1e-3\n' + extra)


def cluster(rng, n=6, overlap=0.02):
    """n spheres of radii in [0.7, 1], each touching (overlapping by up to `overlap`) an
    earlier one: positions, radii."""
    radii = rng.uniform(0.7, 1.0, n)
    pos = np.zeros((n, 3))
    for k in range(1, n):
        while True:
            d = rng.standard_normal(3)
            p = pos[rng.integers(k)]
            q = int(np.argmin(np.linalg.norm(pos[:k] - p, axis=1)))
            cand = pos[q] + d / np.linalg.norm(d) * (radii[q] + radii[k] - rng.uniform(0, overlap))
            gaps = np.linalg.norm(pos[:k] - cand, axis=1) - radii[:k] - radii[k]
            if gaps.min() > -overlap:
                pos[k] = cand
                break
    return pos, radii


def test_repulsion_is_minus_gradient_with_critical_load_at_contact():
    law = CriticalLoadRepulsion(2.0, 0.05)
    h = np.array([-0.01, -1e-3, 1e-3, 0.02, 0.1, 0.3])
    dh = 1e-7
    numeric = -(law.potential(h + dh) - law.potential(h - dh)) / (2 * dh)
    # central differences of a smooth exponential: error ~ dh^2 U''' ~ 1e-11
    assert np.allclose(law.magnitude(h), numeric, rtol=1e-7)
    assert law.magnitude(0.0) == 2.0 and law.magnitude(-0.5) == 2.0   # F_R0 in contact
    assert law.magnitude(0.05) == pytest.approx(2.0 / math.e, rel=1e-15)
    assert law.magnitude(law.reach) == pytest.approx(2e-12, rel=1e-9)
    job = frictional_job(f_r0=0.3)
    repulsion, model = forces_of(job)
    assert repulsion.law == CriticalLoadRepulsion(FORCE_UNIT * 0.3, 0.05)
    assert model.law == ContactLaw(0.5, FORCE_UNIT * 1000.0, FORCE_UNIT * 500.0)
    assert model.partners.shape == (27, 12)


def test_normal_springs_are_minus_gradient_of_the_contact_energy():
    rng = np.random.default_rng(1)
    pos, radii = cluster(rng)
    law = ContactLaw(0.0, 7.0, 3.0)

    def energy(p):
        pairs = close_pairs(p, radii, None, cutoff=0.1)
        return 0.5 * law.k_n * np.sum(np.minimum(pairs.gap, 0.0) ** 2)

    pairs = close_pairs(pos, radii, None, cutoff=0.1)
    got = FrictionalContacts(law, radii, 12).forces(pairs)
    assert got.n_contacts >= len(pos) - 1
    num = np.zeros_like(pos)
    for k in range(len(pos)):
        for c in range(3):
            d = np.zeros_like(pos)
            d[k, c] = 1e-7
            num[k, c] = -(energy(pos + d) - energy(pos - d)) / 2e-7
    # quadratic energy: central differences exact up to round-off ~ 1e-16 U / dh
    assert np.allclose(got.forces, num, atol=1e-6)
    assert np.all(got.torques == 0.0)


def test_third_law_torque_balance_virial_and_coulomb_limit():
    rng = np.random.default_rng(2)
    pos, radii = cluster(rng, n=7)
    law = ContactLaw(0.4, 50.0, 20.0)
    pairs = close_pairs(pos, radii, None, cutoff=0.1)
    model = FrictionalContacts(law, radii, 12)
    touching = pairs.gap < 0
    lo = np.minimum(pairs.i, pairs.j)[touching]
    hi = np.maximum(pairs.i, pairs.j)[touching]
    for k, (a, b) in enumerate(zip(lo, hi)):   # random stored stretches, some beyond Coulomb
        slot = np.count_nonzero(model.partners[a] >= 0)
        model.partners[a, slot] = b
        model.stretch[a, slot] = rng.normal(0, 1e-5 if k % 2 else 0.05, 3)
    got = model.forces(pairs)
    assert 0 < got.n_sliding < got.n_contacts
    assert np.allclose(got.forces.sum(axis=0), 0.0, atol=1e-12)
    # angular momentum: sum (x x F + T) = 0 (tangential forces act at the contact points)
    assert np.allclose(np.cross(pos, got.forces).sum(axis=0) + got.torques.sum(axis=0), 0.0, atol=1e-12)
    # no periodic images: the pair virial equals sum over particles of x F
    assert np.allclose(got.virial, pos.T @ got.forces, atol=1e-12)
    # per contact: |F_t| <= mu F_n, equality when sliding; F_t tangent
    n = pairs.dx[touching] / np.linalg.norm(pairs.dx[touching], axis=1)[:, None]
    xi = model._contacts[-1]
    f_n = law.k_n * -pairs.gap[touching]
    f_t = law.k_t * np.linalg.norm(xi, axis=1)
    assert np.all(f_t <= law.mu * f_n * (1 + 1e-12))
    assert np.sum(np.isclose(f_t, law.mu * f_n, rtol=1e-12)) == got.n_sliding
    assert np.allclose(np.sum(xi * n, axis=1), 0.0, atol=1e-15)


def test_tangent_keeps_length_and_rigid_motion_does_not_slide():
    rng = np.random.default_rng(3)
    n = rng.standard_normal((5, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    xi = rng.standard_normal((5, 3))
    t = tangent(xi, n)
    assert np.allclose(np.linalg.norm(t, axis=1), np.linalg.norm(xi, axis=1), rtol=1e-14)
    assert np.allclose(np.sum(t * n, axis=1), 0.0, atol=1e-14)
    # a rigid rotation w and translation of the pair: contact points move together (the
    # arms l_i + l_j = r, here for overlapping spheres)
    arm_i, arm_j = rng.uniform(0.5, 1, 5), rng.uniform(0.5, 1, 5)
    x_i = rng.standard_normal((5, 3))
    dx = (arm_i + arm_j)[:, None] * n
    w, u0 = rng.standard_normal(3), rng.standard_normal(3)
    v_i = np.hstack([u0 + np.cross(w, x_i), np.tile(w, (5, 1))])
    v_j = np.hstack([u0 + np.cross(w, x_i + dx), np.tile(w, (5, 1))])
    assert np.allclose(sliding_velocity(n, arm_i, arm_j, v_i, v_j), 0.0, atol=1e-14)
    # i rolling on a fixed j does not slide either: its contact point is at rest,
    # U_i + Omega_i x (l_i n) = 0
    om = rng.standard_normal((5, 3))
    v_i = np.hstack([-np.cross(om, arm_i[:, None] * n), om])
    assert np.allclose(sliding_velocity(n, arm_i, arm_j, v_i, np.zeros((5, 6))), 0.0, atol=1e-14)
    # and a pure relative translation slides by its tangential part
    v_j = np.hstack([np.tile(u0, (5, 1)), np.zeros((5, 3))])
    slide = sliding_velocity(n, arm_i, arm_j, np.zeros((5, 6)), v_j)
    assert np.allclose(slide, u0 - (n @ u0)[:, None] * n, atol=1e-14)


def test_history_sign_reset_and_overflow():
    law = ContactLaw(1.0, 100.0, 10.0)
    radii = np.ones(3)
    pos = np.array([[0.0, 0.0, 0.0], [1.99, 0.0, 0.0], [0.0, 1.99, 0.0]])
    model = FrictionalContacts(law, radii, 2)
    pairs = close_pairs(pos, radii, None, cutoff=0.1)
    model.forces(pairs)
    vel = np.zeros((3, 6))
    vel[1, 2] = 1.0   # particle 1 moves along z: slides on 0
    model.advance(vel, 0.0, 0.01)
    assert set(model.partners[0]) == {1, 2}
    slot = list(model.partners[0]).index(1)
    assert np.allclose(model.stretch[0, slot], [0, 0, 0.01])
    # the same contact seen with i and j swapped gets the reversed stretch, so the force
    # on particle 1 is still -k_t xi
    swapped = close_pairs(pos, radii, None, cutoff=0.1)
    swapped.i, swapped.j, swapped.dx = swapped.j.copy(), swapped.i.copy(), -swapped.dx
    got = model.forces(swapped)
    assert got.forces[1, 2] == pytest.approx(-law.k_t * 0.01, rel=1e-12)
    # separation resets: particle 2 leaves
    pos[2, 1] = 2.5
    model.forces(close_pairs(pos, radii, None, cutoff=0.1))
    model.advance(np.zeros((3, 6)), 0.0, 0.01)
    assert list(model.partners[0]).count(2) == 0 and list(model.partners[0]).count(1) == 1
    small = FrictionalContacts(law, radii, 1)
    pos[2, 1] = 1.99
    small.forces(close_pairs(pos, radii, None, cutoff=0.1))
    with pytest.raises(RuntimeError, match="interparticle.max_contacts = 1"):
        small.advance(np.zeros((3, 6)), 0.0, 0.01)


def test_sliding_mobility_fit_against_solve_mobility():
    n = np.array([0.0, 0.0, 1.0])
    for h in (1e-4, 1e-3, 1e-2):
        f = FORCE_UNIT * np.array([1.0, 0.0, 0.0])   # tangential force on sphere 1 (job units 1)
        u, om, _ = solve_mobility(np.array([[0.0, 0, 0], [0, 0, 2 + h]]), None,
                                  forces=np.array([f, -f]), torques=np.array([np.cross(n, f)] * 2))
        slide = -(u[1] - u[0] - np.cross(om[0] + om[1], n))[0]
        # the docstring's fit claims 1% in this range
        assert sliding_mobility(h) == pytest.approx(slide, rel=0.01)


@pytest.mark.parametrize("extra,fragments", [
    ('[interparticle]\nkind = "frictional"\n',
     ["interparticle.mu: is required", "interparticle.k_n: is required",
      "interparticle.f_r0: is required", "interparticle.repulsion_length: is required"]),
    (FRICTION.format(mu=-0.1, k_n=1.0, k_t=1.0, f_r0=1.0), ["interparticle.mu", "out of range"]),
    (FRICTION.format(mu=0.1, k_n=1.0, k_t=1.0, f_r0=1.0) + "max_contacts = 0\n",
     ["interparticle.max_contacts", "1 <= max_contacts <= 64"]),
    (FRICTION.format(mu=0.1, k_n=1.0, k_t=1.0, f_r0=1.0).replace("0.05", "0.1"),
     ["interparticle.repulsion_length", "repulsion_length <= 0.07238"]),
    (FRICTION.format(mu=0.1, k_n=1.0, k_t=5000.0, f_r0=1.0) + "[integration]\ndt = 0.001\n",
     ["interparticle.k_t", "too stiff", "k_t <= 1385", "sliding mobility 0.722"]),
    (FRICTION.format(mu=0.1, k_n=1e6, k_t=1.0, f_r0=1.0) + "[integration]\ndt = 0.001\n",
     ["interparticle.k_n", "too stiff", "k_n <= 2.5e+05"]),
    (FRICTION.format(mu=0.1, k_n=1.0, k_t=1.0, f_r0=1.0) + "f0 = 1.0\n",
     ["interparticle.f0", "does not apply"]),
    ('[interparticle]\nkind = "none"\nmu = 0.5\n', ["interparticle.mu", "does not apply"]),
])
def test_frictional_keys_are_validated(extra, fragments):
    with pytest.raises(JobError) as info:
        parse_job(BASE + extra + "[hydrodynamics]\nmin_gap = 1e-3\n")
    text = str(info.value)
    for fragment in fragments:
        assert fragment in text, text


def test_physics_problems_are_reported_with_the_others(tmp_path, capsys):
    """The contact springs' check (`sdmpi.dynamics.checks`) runs in the loader's single
    pass: `sdmpi validate` and `sdmpi run` list it with a problem of another key, exit 2,
    and run writes nothing."""
    job = tmp_path / "job.toml"
    job.write_text(BASE + FRICTION.format(mu=0.1, k_n=1.0, k_t=5000.0, f_r0=1.0)
                   + "[integration]\ndt = 0.001\n[hydrodynamics]\nmin_gap = 1e-3\n")
    bad = ["--set", "system.n_particles=0"]
    assert main(["validate", str(job), *bad]) == 2
    err = capsys.readouterr().err
    assert "2 problems" in err and "system.n_particles = 0" in err and "interparticle.k_t" in err \
        and "too stiff" in err, err
    res = sdmpi("run", job, "-o", tmp_path / "run.h5", *bad)
    assert res.returncode == 2 and "too stiff" in res.stderr and "system.n_particles" in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.toml"]


def test_brownian_frictional_job_is_refused():
    with pytest.raises(JobError, match="brownian.enabled.*non-Brownian model"):
        parse_job('[shear]\nprotocol = "steady"\n' + FRICTION.format(mu=0.1, k_n=1.0, k_t=1.0, f_r0=1.0))


# ----------------------------------------------------------------------------- trajectory

BOX = 60.0   # periodic images change the pair mobility by O((2/BOX)^3) ~ 4e-5
MU, K_N, K_T, F_R0, H0, XI0 = 1.0, 100.0, 20.0, 0.5, -0.01, 0.01


def sd_contact(dt, t_end):
    """Two unit spheres touching along the vorticity axis z (overlap -H0), with a stored
    tangential stretch XI0 e_x, stepped by sdmpi (Realisation._one_step) in steady shear:
    times, stretches (x component, as stored after each step) and gaps."""
    n = int(round(t_end / dt))
    job = frictional_job('[system]\nn_particles = 8\nphi = [0.01]\n[integration]\n'
                         f'dt = {dt}\nn_steps = {n}\ndiscard_steps = 0\n[ensemble]\nrealisations = 1\n',
                         mu=MU, k_n=K_N, k_t=K_T, f_r0=F_R0)
    real = Realisation(job, enumerate_tasks(job)[0])
    real.n_particles, real.radii = 2, np.ones(2)
    real.box, real.volume = np.full(3, BOX), BOX ** 3
    real.model = hydrodynamic_model(job, real.radii, real.box)
    real.integrator = EulerMaruyama(dataclasses.replace(real.integrator.motion, n_particles=2, box=real.box))
    repulsion, contacts = real.forces
    contacts = FrictionalContacts(contacts.law, real.radii, 4)
    real.forces = [PairForce(repulsion.law, real.radii), contacts]
    contacts.partners[0, 0] = 1
    contacts.stretch[0, 0] = [XI0, 0.0, 0.0]
    c = BOX / 2
    real.positions = np.array([[c, c, c - 1 - H0 / 2], [c, c, c + 1 + H0 / 2]])
    xi, gaps = [XI0], [H0]
    for _ in range(n):
        out = real.advance(1)
        assert out["n_contacts"][0] == 1 and out["n_sliding"][0] == 0   # sticks throughout
        xi.append(contacts.stretch[0, 0, 0])
        d = real.positions[1] - real.positions[0]
        gaps.append(np.linalg.norm(d - BOX * np.round(d / BOX)) - 2.0)
    return dt * np.arange(n + 1), np.array(xi), np.array(gaps)


def ode_contact(t_eval):
    """The same pair integrated independently: state (x1, x2, xi), forces written out here
    (normal spring + critical load, tangential spring, torques at the contact point, which
    lies half way between the centres),
    velocities from the resistance of the true positions (unbounded fluid; lubrication at
    the job's minimum gap 1e-3, as sdmpi regularises touching pairs),
    d xi/dt the tangential sliding velocity, xi turned tangent where used."""
    gamma = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    e_inf = 0.5 * (gamma + gamma.T)
    w_inf = np.array([0.0, 0.0, -0.5])

    def rhs(t, y):
        x, xi = y[:6].reshape(2, 3), y[6:]
        d = x[1] - x[0]
        n = d / np.linalg.norm(d)
        h = np.linalg.norm(d) - 2.0
        xt = xi - (xi @ n) * n
        xt *= np.linalg.norm(xi) / np.linalg.norm(xt)
        f_on_2 = (K_N * -h + F_R0) * n - K_T * xt
        arm = 0.5 * np.linalg.norm(d)   # lever arms r a_i / (a_i + a_j)
        torque = arm * np.cross(n, K_T * xt)
        solver = DenseSolver(grand_resistance(x, np.ones(2), None, min_gap=1e-3))
        f6 = FORCE_UNIT * np.array([np.concatenate([-f_on_2, torque]), np.concatenate([f_on_2, torque])])
        u = solver.velocities(f6, np.tile(to_five(e_inf), (2, 1)))
        v = u[:, :3] + x @ gamma.T
        om = u[:, 3:] + w_inf
        rel = v[1] - v[0] - arm * np.cross(om[0] + om[1], n)
        return np.concatenate([v.ravel(), rel - (rel @ n) * n])

    y0 = np.array([0, 0, -1 - H0 / 2, 0, 0, 1 + H0 / 2, XI0, 0, 0])
    sol = solve_ivp(rhs, (0, t_eval[-1]), y0, t_eval=t_eval, rtol=1e-9, atol=1e-12)
    x = sol.y[:6].T.reshape(-1, 2, 3)
    return sol.y[6], np.linalg.norm(x[:, 1] - x[:, 0], axis=1) - 2.0


def test_two_sphere_contact_trajectory_matches_independent_integration():
    t, xi_c, gap_c = sd_contact(0.01, 0.3)
    _, xi_f, gap_f = sd_contact(0.005, 0.3)
    xi_f, gap_f = xi_f[::2], gap_f[::2]
    xi_ode, gap_ode = ode_contact(t)
    assert xi_ode[-1] < 0.3 * XI0                  # the tangential spring really relaxed
    assert gap_ode[-1] - H0 > 5e-4                 # and the overlap shrank
    # explicit Euler: errors halve with dt (measured 2.06; 2.03 at dt/4); the Richardson
    # value 2 f(dt/2) - f(dt) leaves O(dt^2): measured 1.0e-5 = 1e-3 XI0 for the stretch,
    # 2e-8 for the gap (which changes by 1.7e-3); bounds twice and five times that
    err_c, err_f = np.abs(xi_c - xi_ode).max(), np.abs(xi_f - xi_ode).max()
    assert err_c == pytest.approx(2 * err_f, rel=0.1)
    assert np.abs(2 * xi_f - xi_c - xi_ode).max() < 2e-3 * XI0
    assert np.abs(2 * gap_f - gap_c - gap_ode).max() < 1e-7


# ----------------------------------------------------------------------------- checkpoints

TINY = ('[system]\nn_particles = 8\nphi = [0.5]\n[integration]\ndt = 0.002\nn_steps = 600\n'
        'discard_steps = 0\n[ensemble]\nrealisations = 1\n')


def test_resume_from_state_is_bit_identical():
    job = frictional_job(TINY)
    task = enumerate_tasks(job)[0]
    whole = Realisation(job, task).advance(600)
    first = Realisation(job, task)
    head = first.advance(300)
    state = first.get_state()
    assert np.any(state["contact_partners"] >= 0) and np.any(state["contact_stretch"] != 0)
    assert set(state) == set(first.state_fields())
    second = Realisation(job, task)
    second.set_state({k: v.copy() for k, v in state.items()})
    tail = second.advance(300)
    for key in whole:
        assert np.array_equal(np.concatenate([head[key], tail[key]]), whole[key]), key
    assert whole["n_contacts"].max() > 0 and whole["stress_contact"][:, 3].max() > 0


@pytest.mark.mpi
@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_frictional_job_file_killed_then_resumed_on_two_ranks(tmp_path):
    """jobs/frictional_mu0.5.toml, tiny (N = 8 in one size class: the job's two classes
    would touch through two images in so small a box; a wide minimum gap so that contacts
    form within 150 steps), SIGKILLed after its third checkpoint (step 150, with a contact
    in its history), resumed under mpirun -n 2: the samples equal an uninterrupted
    in-process run."""
    path = ROOT / "jobs" / "frictional_mu0.5.toml"
    short = ["system.n_particles=8", "system.phi=[0.5]", "ensemble.realisations=1",
             "integration.n_steps=200", "integration.discard_steps=20", "job.seed=2",
             "output.checkpoint_every=50", "hydrodynamics.min_gap=0.02", "interparticle.k_t=300.0",
             "interparticle.k_n=2000.0", "system.size_classes=[{radius = 1.0, fraction = 1.0}]"]
    sets = [a for item in short for a in ("--set", item)]
    out = tmp_path / "run.h5"
    res = sdmpi("run", path, "-o", out, *sets, env={"SDMPI_TEST_KILL": "commit:3"})
    assert res.returncode != 0
    res = sdmpi("run", path, "-o", out, *sets, ranks=2)
    assert res.returncode == 0 and "resuming" in res.stdout, res.stderr
    job = load_job(path, short)
    whole = Realisation(job, enumerate_tasks(job)[0]).advance(200)
    assert whole["n_contacts"][149] > 0
    with h5py.File(out, "r") as f:
        for key, value in whole.items():
            assert np.array_equal(f[f"tasks/000000/samples/{key}"][()], value), key


def test_phimax_fit_recovers_known_krieger_dougherty_and_maron_pierce():
    """postprocess/frictional_phimax.py's fit on exact model values (errors 5%)."""
    spec = importlib.util.spec_from_file_location("frictional_phimax",
                                                  ROOT / "postprocess" / "frictional_phimax.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    phi = np.array([0.40, 0.45, 0.50, 0.52])
    for name, model in script.MODELS.items():
        eta = model(phi, 0.58)
        best, _ = script.fit_phi_max(phi, eta, 0.05 * eta, model)
        # exact data: the least-squares optimum is the true value (to the solver's tolerance)
        assert best == pytest.approx(0.58, abs=1e-6), name
