"""Colloidal forces (issue 7, part 2; seed 003): van der Waals between unequal spheres
(Hamaker 1937 = seed eqs. 4-5), capped below a minimum gap; the DLVO double layer; the
shifted-force truncation at the lubrication cut-off; job keys and cross-key checks; and
two-sphere trajectories of sdmpi's stepping against an independent ODE integration."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sdmpi.config import JobError, enumerate_tasks
from sdmpi.dynamics.checks import parse_job
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.integrators import EulerMaruyama
from sdmpi.dynamics.forces import FORCE_UNIT, Combined, DoubleLayer, PairForce, Repulsion, VanDerWaals, pair_forces
from sdmpi.dynamics.setup import forces_of, hydrodynamic_model
from sdmpi.hydro.lubrication import close_pairs
from sdmpi.hydro.two_sphere import resistance_scalars


def hamaker_1937(r, a1, a2, A):
    """Hamaker's sphere-sphere energy in the centre distance r (Physica 4, 1058 (1937),
    eq. 22 as quoted by Israelachvili, Intermolecular and Surface Forces, 3rd ed. 13.4)."""
    p, m = r * r - (a1 + a2) ** 2, r * r - (a1 - a2) ** 2
    return -A / 6 * (2 * a1 * a2 / p + 2 * a1 * a2 / m + np.log(p / m))


def minus_gradient(law, h, a1, a2, dh=1e-7):
    return -(law.potential(h + dh, a1, a2) - law.potential(h - dh, a1, a2)) / (2 * dh)


RADII = [(1.0, 1.0), (1.0, 0.4), (2.5, 1.0)]


@pytest.mark.parametrize("a1,a2", RADII)
def test_vdw_energy_is_hamaker_1937_and_force_is_minus_gradient(a1, a2):
    law = VanDerWaals(hamaker=1.3, cap_gap=1e-3)
    h = np.geomspace(2e-3, 3.0, 40)
    assert np.allclose(law.potential(h, a1, a2), hamaker_1937(a1 + a2 + h, a1, a2, 1.3),
                       rtol=1e-10)
    # seed eq. 5 is -dW/db of eq. 4 (here signed: < 0 is attraction)
    num = minus_gradient(law, h, a1, a2, dh=1e-6 * h)
    assert np.allclose(law.magnitude(h, a1, a2), num, rtol=1e-6)
    assert np.all(law.magnitude(h, a1, a2) < 0)


@pytest.mark.parametrize("a1,a2", RADII)
def test_vdw_limits(a1, a2):
    A = 2.0
    law = VanDerWaals(hamaker=A, cap_gap=1e-9)
    reff = a1 * a2 / (a1 + a2)
    for h in (1e-5, 1e-4):       # Derjaguin: F = -A R/(6 h^2) (1 + O(h/a))
        assert law.magnitude(h, a1, a2) == pytest.approx(-A * reff / (6 * h * h), rel=20 * h)
    r = 400.0                    # London: F = -(32/3) A a1^3 a2^3 / r^7 (1 + O(a^2/r^2))
    far = law.magnitude(r - a1 - a2, a1, a2)
    assert far == pytest.approx(-(32 / 3) * A * (a1 * a2) ** 3 / r ** 7, rel=1e-4)


def test_vdw_cap_holds_force_constant_and_energy_linear():
    law = VanDerWaals(hamaker=1.0, cap_gap=0.01)
    f_cap = law.magnitude(0.01)
    h = np.array([-0.02, 0.0, 0.004, 0.0099999])
    assert np.allclose(law.magnitude(h), f_cap, rtol=1e-12)
    assert np.allclose(minus_gradient(law, h, 1.0, 1.0), f_cap, rtol=1e-6)
    assert np.isfinite(law.potential(-0.02))
    assert abs(law.magnitude(0.0100001)) < abs(f_cap)   # falls off above the cap


def test_double_layer_equal_spheres_is_seed_001_repulsion_and_far_field_is_lsa():
    psi, lam = 7.0, 0.05
    dl = DoubleLayer(strength=psi ** 2, debye_length=lam)
    rep = Repulsion(f0=psi ** 2 / 2, tau=1 / lam)
    h = np.linspace(0, 1, 41)
    assert np.allclose(dl.magnitude(h), rep.magnitude(h), rtol=1e-12)
    assert np.allclose(dl.potential(h), rep.potential(h), rtol=1e-12)
    a1, a2 = 1.0, 0.3
    reff = a1 * a2 / (a1 + a2)
    assert np.allclose(dl.magnitude(h, a1, a2), minus_gradient(dl, h, a1, a2), rtol=1e-6)
    # contact value and the linear-superposition (weak overlap) far field
    assert dl.magnitude(0.0, a1, a2) == pytest.approx(psi ** 2 * reff / (2 * lam))
    assert dl.magnitude(1.0, a1, a2) == pytest.approx(psi ** 2 * reff / lam * math.exp(-20),
                                                      rel=1e-8)
    assert dl.magnitude(-0.01, a1, a2) == dl.magnitude(0.0, a1, a2)   # overlaps: contact force


@pytest.mark.parametrize("law", [VanDerWaals(1.0, 0.01, cutoff=2.0),
                                 DoubleLayer(50.0, 0.2, cutoff=2.0),
                                 Combined((VanDerWaals(1.0, 0.01, 2.0), DoubleLayer(50.0, 0.2, 2.0)))])
def test_shifted_force_truncation_is_continuous_and_conservative(law):
    a1, a2 = 1.0, 0.5                  # cut-off at 2 mean radii = gap 1.5
    hc = 1.5
    h = np.linspace(0.02, 1.45, 30)
    assert np.allclose(law.magnitude(h, a1, a2), minus_gradient(law, h, a1, a2), rtol=1e-6,
                       atol=1e-9)
    assert abs(law.magnitude(hc - 1e-9, a1, a2)) < 1e-8
    assert abs(law.potential(hc - 1e-9, a1, a2)) < 1e-12
    assert law.magnitude(hc + 1e-3, a1, a2) == 0.0 and law.potential(hc + 0.2, a1, a2) == 0.0


def test_pair_forces_newtons_third_law_and_virial_unequal_radii():
    pos = np.array([[0.0, 0, 0], [1.45, 0.1, 0], [0.3, 1.2, 0.9], [-1.0, -1.6, 0.5]])
    radii = np.array([1.0, 0.5, 0.7, 1.2])
    pairs = close_pairs(pos, radii)
    law = Combined((VanDerWaals(2.0, 0.01, cutoff=2.0), DoubleLayer(80.0, 0.1, cutoff=2.0)))
    forces, virial = pair_forces(law, pairs, 4, radii)
    assert len(pairs.i) >= 3
    assert np.allclose(forces.sum(axis=0), 0, atol=1e-12)
    assert np.allclose(virial, np.einsum("ni,nj->ij", pos, forces), atol=1e-12)
    # each pair's force uses its own radii (not the mean radius)
    f_own = law.magnitude(pairs.gap, radii[pairs.i], radii[pairs.j])
    f_mean = law.magnitude(pairs.gap, pairs.radii_sum / 2, pairs.radii_sum / 2)
    assert not np.allclose(f_own, f_mean)


# ----------------------------------------------------------------------------- job keys

BASE = '[shear]\nprotocol = "steady"\nrate = 1.0\n[brownian]\nenabled = false\n'


def test_force_law_from_job_in_force_units():
    job = parse_job(BASE + '[interparticle]\nkind = "dlvo"\nhamaker = 0.5\ncap_gap = 0.01\n'
                    'debye_length = 0.05\nsurface_potential = 4.0\n')
    (force,) = forces_of(job)
    vdw, dl = force.law.parts
    assert vdw == VanDerWaals(FORCE_UNIT * 0.5, 0.01, 2.0)
    assert dl == DoubleLayer(FORCE_UNIT * 16.0, 0.05, 2.0)
    (rep,) = forces_of(parse_job(BASE + '[interparticle]\nkind = "repulsion"\nf0 = 0.5\ntau = 100.0\n'))
    assert rep.law == Repulsion(FORCE_UNIT * 0.5, 100.0)
    assert forces_of(parse_job(BASE)) == []


@pytest.mark.parametrize("extra,fragments", [
    ('kind = "vdw"\n', ["interparticle.hamaker: is required", "interparticle.cap_gap: is required"]),
    ('kind = "dlvo"\nhamaker = 1.0\ncap_gap = 0.01\n',
     ["interparticle.debye_length: is required", "interparticle.surface_potential: is required"]),
    ('kind = "vdw"\nhamaker = 1.0\ncap_gap = 0.01\ndebye_length = 0.1\n',
     ["interparticle.debye_length", "does not apply"]),
    ('kind = "none"\nhamaker = 1.0\n', ["interparticle.hamaker", "does not apply"]),
    ('kind = "vdw"\nhamaker = -1.0\ncap_gap = 0.01\n', ["interparticle.hamaker", "out of range"]),
    ('kind = "vdw"\nhamaker = 1.0\ncap_gap = 0.3\n',
     ["interparticle.cap_gap", "of its contact value", "smaller cap_gap"]),
    ('kind = "dlvo"\nhamaker = 1.0\ncap_gap = 0.01\ndebye_length = 0.5\nsurface_potential = 3.0\n',
     ["interparticle.debye_length", "double-layer force", "shorter debye_length"]),
    ('kind = "vdw"\nhamaker = 1.0\ncap_gap = 0.01\n[hydrodynamics]\nlubrication_cutoff = 0.005\n',
     ["interparticle.cap_gap", "lubrication_cutoff (= 0.005)"]),
    ('kind = "vdw"\nhamaker = 1.0\ncap_gap = 0.01\n[hydrodynamics]\nmodel = "free-draining"\n'
     'lubrication = false\n', ["hydrodynamics.lubrication", "stokesian model only"]),
    ('kind = "van der waals"\n', ["interparticle.kind", "not a valid choice"]),
])
def test_colloidal_keys_are_validated(extra, fragments):
    with pytest.raises(JobError) as info:
        parse_job(BASE + "[interparticle]\n" + extra)
    text = str(info.value)
    for fragment in fragments:
        assert fragment in text, text


def test_dlvo_job_runs_a_few_steps():
    job = parse_job(BASE + '[system]\nn_particles = 8\nphi = [0.3]\n[integration]\ndt = 0.001\n'
                    'n_steps = 3\ndiscard_steps = 0\n[ensemble]\nrealisations = 1\n'
                    '[interparticle]\nkind = "dlvo"\nhamaker = 0.02\ncap_gap = 0.01\n'
                    'debye_length = 0.05\nsurface_potential = 1.0\n')
    out = Realisation(job, enumerate_tasks(job)[0]).advance(3)
    assert np.all(np.isfinite(out["stress_interparticle"]))
    assert np.any(out["stress_interparticle"] != 0)


# ----------------------------------------------------------------------------- trajectories

BOX = 60.0   # periodic images change the pair's relative mobility by O((2/BOX)^3) ~ 1e-5


def squeeze_mobility(h):
    """G(h) of two unit spheres at gap h: with forces -F d on sphere 1 and +F d on
    sphere 2 (d from 1 to 2, F > 0 repulsive), dh/dt = 2 F G(h). From the exact axial
    resistance (sdmpi.hydro.two_sphere, XA in the Jeffrey-Onishi normalisation: block
    (a, b) is 3 pi (a_a + a_b) XA_ab = 6 pi XA_ab here), R_A = 6 pi [[XA11, XA12],
    [XA21, XA22]]; velocities M F with M = R_A^-1, so dh/dt = (M22 - M21 - M12 + M11) F."""
    xa = resistance_scalars(np.array([2.0 + h]), 1.0, 1.0)[0, :, 0]      # 11, 12, 21, 22
    m = np.linalg.inv(6 * math.pi * xa.reshape(2, 2))
    return 0.5 * (m[1, 1] - m[1, 0] - m[0, 1] + m[0, 0])


def sd_gaps(inter, h0, dt, t_end):
    """Gaps h(t_k) of two unit spheres stepped by sdmpi (Realisation._one_step: pair
    forces, resistance solve, explicit step), non-Brownian, along the vorticity axis z at
    equal y, where simple shear leaves their separation unchanged, in a periodic box of
    side BOX standing in for unbounded fluid."""
    n = int(round(t_end / dt))
    job = parse_job(BASE + f'[system]\nn_particles = 8\nphi = [0.01]\n[integration]\ndt = {dt}\n'
                    f'n_steps = {n}\ndiscard_steps = 0\n[ensemble]\nrealisations = 1\n'
                    f'[interparticle]\n{inter}\n')
    real = Realisation(job, enumerate_tasks(job)[0])
    real.n_particles, real.radii = 2, np.ones(2)
    real.box, real.volume = np.full(3, BOX), BOX ** 3
    real.model = hydrodynamic_model(job, real.radii, real.box)
    (force,) = real.forces
    real.forces = [PairForce(force.law, real.radii)]
    real.integrator = EulerMaruyama(dataclasses.replace(real.integrator.motion, n_particles=2, box=real.box))
    c = BOX / 2
    real.positions = np.array([[c, c, c - 1 - h0 / 2], [c, c, c + 1 + h0 / 2]])
    gaps = [h0]
    for _ in range(n):
        real.advance(1)
        d = real.positions[1] - real.positions[0]
        d -= BOX * np.round(d / BOX)
        assert abs(d[0]) < 1e-12 and abs(d[1]) < 1e-12
        gaps.append(np.linalg.norm(d) - 2.0)
    return np.array(gaps), force.law


@pytest.mark.parametrize("inter,h0,t_end", [
    ('kind = "repulsion"\nf0 = 0.05\ntau = 20.0', 0.02, 2.0),           # separates
    ('kind = "vdw"\nhamaker = 0.1\ncap_gap = 0.01', 0.2, 1.0),          # approaches
])
def test_two_sphere_trajectory_matches_ode(inter, h0, t_end):
    coarse, law = sd_gaps(inter, h0, 0.01, t_end)
    fine, _ = sd_gaps(inter, h0, 0.005, t_end)
    t = 0.01 * np.arange(coarse.size)

    def rhs(_, y):
        return [2.0 * law.magnitude(np.array([y[0]]))[0] * squeeze_mobility(y[0])]

    ode = solve_ivp(rhs, (0.0, t[-1]), [h0], t_eval=t, method="DOP853", rtol=1e-10,
                    atol=1e-13, max_step=0.01).y[0]
    assert abs(ode[-1] - h0) > 0.05                       # the spheres really moved
    fine = fine[::2]
    # explicit (first-order) stepping: the error halves with dt, and the Richardson
    # extrapolation 2 h(dt/2) - h(dt) removes it
    err_fine = np.abs(fine - ode) / ode
    err_rich = np.abs(2 * fine - coarse - ode) / ode
    assert np.max(err_fine) < 5e-3
    assert np.max(np.abs(coarse - ode) / ode) == pytest.approx(2 * np.max(err_fine), rel=0.1)
    assert np.max(err_rich) < 1e-3
