"""Full SD grand resistance and solve_mobility: exact limits, two spheres, SPD, bad input."""

import math

import numpy as np
import pytest

from sdmpi.dynamics.initial import compress, hard_sphere_fluid
from sdmpi.hydro import solve_mobility
from sdmpi.hydro.farfield import NDOF
from sdmpi.hydro.resistance import grand_resistance
from sdmpi.hydro.two_sphere import pair_resistance

SHEAR = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])  # gamma_dot = 1


@pytest.mark.parametrize("a", [0.5, 1.0, 2.0])
def test_isolated_sphere(a):
    f, t = np.array([[1.0, -2.0, 0.5]]), np.array([[0.3, 0.2, -1.0]])
    e = np.array([[0.1, 0.2, -0.3], [0.2, 0.4, 0.05], [-0.3, 0.05, -0.5]])
    u, w, s = solve_mobility(np.zeros((1, 3)), None, radii=[a], forces=f, torques=t, rate_of_strain=e)
    assert np.allclose(u, f / (6 * math.pi * a), rtol=1e-12, atol=0)
    assert np.allclose(w, t / (8 * math.pi * a ** 3), rtol=1e-12, atol=0)
    assert np.allclose(s, 20 / 3 * math.pi * a ** 3 * e, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("lam", [0.25, 1.0, 4.0])
@pytest.mark.parametrize("gap", [1e-4, 1e-2, 0.3, 2.0, 10.0])
def test_two_spheres_equal_exact_pair_resistance(lam, gap):
    """Two spheres alone: SD's R = M^-1 + R_2B - (M_2B)^-1 reduces to R_2B exactly."""
    a1, a2 = 1.0, lam
    mean = 0.5 * (a1 + a2)
    d = np.array([0.3, -0.5, 0.8])
    d /= np.linalg.norm(d)
    r = a1 + a2 + gap * mean
    pos = np.array([[0.1, 0.2, 0.3], [0.1, 0.2, 0.3] + r * d])
    res = grand_resistance(pos, np.array([a1, a2]), cutoff=25.0)
    exact = pair_resistance((pos[1] - pos[0])[None, :], np.array([a1]), np.array([a2]))[0]
    # the only differences are round-off in M^-1 - (M_2B)^-1, relative to R's scale
    assert np.abs(res.matrix - exact).max() < 1e-6 * np.abs(exact).max()
    # and the mobility solve agrees with solving the exact pair resistance
    forces = np.array([[1.0, 0.5, -0.2], [-0.3, 0.2, 0.9]])
    u, w, s = solve_mobility(pos, None, radii=[a1, a2], forces=forces, rate_of_strain=SHEAR)
    assert np.isfinite(u).all() and np.isfinite(s).all()


def _dense_random(n, phi, seed, strain=0.0):
    """Equilibrium hard spheres in a cube with Lees-Edwards images at the given strain."""
    rng = np.random.default_rng(seed)
    pos, side = hard_sphere_fluid(n, min(phi, 0.45), rng, strain=strain)
    if phi > 0.45:
        pos, side = compress(pos, side, phi, rng, strain=strain)
    return pos, side


@pytest.mark.parametrize("phi", [0.3, 0.45, 0.6])
@pytest.mark.parametrize("strain", [0.0, -0.37])
def test_resistance_spd_dense_random(phi, strain):
    pos, side = _dense_random(27, phi, seed=int(phi * 100), strain=strain)
    res = grand_resistance(pos, np.ones(27), [side] * 3, strain)
    m = res.matrix
    assert np.abs(m - m.T).max() < 1e-10 * np.abs(m).max()
    assert np.linalg.eigvalsh(m).min() > 0


def test_touching_and_overlapping_pairs_are_regularised():
    pos = np.array([[0.0, 0, 0], [2.0, 0, 0], [4.0 - 1e-3, 0, 0], [0.0, 2.0, 0]])
    res = grand_resistance(pos, np.ones(4))
    assert res.pairs.n_regularised == 3
    assert res.pairs.min_gap == pytest.approx(-1e-3)
    assert np.linalg.eigvalsh(res.matrix).min() > 0
    u, w, s = solve_mobility(pos, None, forces=np.ones((4, 3)), rate_of_strain=SHEAR)
    assert np.isfinite(u).all()


def test_energy_dissipation_positive():
    """The two dissipations R's definiteness implies: F.U + L.Omega > 0 for loaded
    particles in a quiescent fluid, and S:E_inf > 0 for force- and torque-free particles
    in shear. (With both at once F.U alone may be negative: the flow can carry particles
    against their loads.)"""
    pos, side = _dense_random(27, 0.45, seed=5)
    rng = np.random.default_rng(2)
    f, t = rng.normal(size=(27, 3)), rng.normal(size=(27, 3))
    u, w, _ = solve_mobility(pos, [side] * 3, forces=f, torques=t)
    assert np.sum(f * u) + np.sum(t * w) > 0
    _, _, s = solve_mobility(pos, [side] * 3, rate_of_strain=SHEAR)
    assert np.einsum("nij,ij->", s, SHEAR) > 0


def test_periodic_invariances_with_lubrication():
    """Shifts by lattice vectors, strain -> strain + Lx/Ly, and relabelling leave R as it
    is (the configuration is made at the strain it is evaluated at: a start made at
    another strain may overlap the sheared images)."""
    pos, side = _dense_random(8, 0.4, seed=9, strain=0.2)
    box = [side] * 3
    ref = grand_resistance(pos, np.ones(8), box, 0.2).matrix
    scale = np.abs(ref).max()
    moved = pos + np.array([0.2 * side, side, 0.0]) - np.array([0, 0, side])
    assert np.abs(grand_resistance(moved, np.ones(8), box, 0.2).matrix - ref).max() < 1e-10 * scale
    assert np.abs(grand_resistance(pos, np.ones(8), box, 1.2).matrix - ref).max() < 1e-10 * scale
    perm = np.random.default_rng(0).permutation(8)
    idx = (NDOF * perm[:, None] + np.arange(NDOF)).ravel()
    got = grand_resistance(pos[perm], np.ones(8), box, 0.2).matrix
    assert np.abs(got - ref[np.ix_(idx, idx)]).max() < 1e-10 * scale


def test_particle_with_its_own_image_in_small_box():
    """A sphere in a box of side 2.5 is within lubrication range of its own images: the
    resistance must still be SPD and larger than without lubrication."""
    box = [2.5, 2.5, 2.5]
    with_lub = grand_resistance(np.zeros((1, 3)), np.ones(1), box)
    without = grand_resistance(np.zeros((1, 3)), np.ones(1), box, lubrication=False)
    # images at 2.5 (6 faces) and 2.5 sqrt2 (12 edges) are within a gap of 2; the
    # pair list holds one entry per +-n pair: 3 + 6
    assert len(with_lub.pairs.i) == 9
    assert np.linalg.eigvalsh(with_lub.matrix).min() > 0
    assert with_lub.matrix[0, 0] > without.matrix[0, 0]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(positions=np.zeros((2, 2))), "positions"),
        (dict(positions=np.array([[0, 0, 0], [np.nan, 0, 0]])), "positions"),
        (dict(radii=[1.0, -1.0]), "radii"),
        (dict(radii=[1.0]), "radii"),
        (dict(box=[10.0, 0.0, 10.0]), "box"),
        (dict(box=[10.0, 10.0]), "box"),
        (dict(forces=np.zeros((3, 3))), "forces"),
        (dict(torques=np.full((2, 3), np.inf)), "torques"),
        (dict(rate_of_strain=np.eye(3)), "rate_of_strain"),
        (dict(strain=np.nan), "strain"),
        (dict(positions=np.array([[0, 0, 0], [1.5, 0, 0]])), "overlap"),
        (dict(solver="magic"), "solver"),
    ],
)
def test_bad_input_raises_value_error_naming_argument(kwargs, match):
    args = dict(positions=np.array([[0.0, 0, 0], [3.0, 0, 0]]), box=None)
    args.update(kwargs)
    positions, box = args.pop("positions"), args.pop("box")
    with pytest.raises(ValueError, match=match):
        solve_mobility(positions, box, **args)


@pytest.mark.parametrize("lubrication", [False, True])
def test_block_form_equals_the_inverse_of_the_whole_far_field(lubrication):
    """R in block form (Schur complement of the strain block) against R = inv(M_inf) + L
    with the whole 11N x 11N M_inf inverted by numpy, for 8 spheres at phi = 0.3 in a sheared
    box, with products (`apply`) and matrices (`blocks`): both are the same inverse, rounded
    differently (cond(M_inf) ~ 1e2: tolerance 1e-10 of the largest entry)."""
    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro.farfield import far_field_mobility
    from sdmpi.hydro.geometry import Lattice
    from sdmpi.hydro.lubrication import close_pairs, lubrication_matrix

    pos, side = hard_sphere_fluid(8, 0.3, np.random.default_rng(5), strain=0.2)
    box = np.full(3, side)
    res = grand_resistance(pos, np.ones(8), box, 0.2, lubrication=lubrication)
    lattice = Lattice(box, 0.2)
    ref = np.linalg.inv(far_field_mobility(res.positions, np.ones(8), box, 0.2))
    if lubrication:
        ref += lubrication_matrix(res.positions, np.ones(8), close_pairs(res.positions, np.ones(8), lattice))
    scale = np.abs(ref).max()
    assert np.abs(res.matrix - ref).max() < 1e-10 * scale
    v = np.random.default_rng(6).standard_normal((8, 11))
    rigid, strain = res.apply(v[:, :6], v[:, 6:])
    full = (ref @ v.ravel()).reshape(8, 11)
    assert np.abs(rigid - full[:, :6]).max() < 1e-10 * np.abs(full).max()
    assert np.abs(strain - full[:, 6:]).max() < 1e-10 * np.abs(full).max()


def test_row_products_equal_the_matrix_rows():
    """GrandResistance.product for each choice of rows, and with a vector that is zero on
    the rigid-body dofs (strain_only), against the rows of the whole R (the lubrication's
    dense partitions and the far field's block form both enter)."""
    from sdmpi.dynamics.initial import hard_sphere_fluid

    pos, side = hard_sphere_fluid(8, 0.4, np.random.default_rng(9), strain=0.3)
    res = grand_resistance(pos, np.ones(8), np.full(3, side), 0.3)
    assert res.lubrication_dense is not None
    matrix = res.matrix
    v = np.random.default_rng(10).standard_normal((8, 11))
    strain_v = v.copy()
    strain_v[:, :6] = 0.0
    for vec, strain_only in ((v, False), (strain_v, True)):
        full = (matrix @ vec.ravel()).reshape(8, 11)
        scale = np.abs(full).max()
        for rows, cols in ((None, slice(0, 11)), ("rigid", slice(0, 6)), ("strain", slice(6, 11))):
            got = res.product(vec, rows, strain_only)
            assert np.abs(got - full[:, cols]).max() < 1e-10 * scale, (rows, strain_only)


def test_single_precision_inversion_stays_far_below_the_ewald_tolerance(monkeypatch):
    """From ewald_tol = SINGLE_PRECISION_TOL and SINGLE_PRECISION_MIN_N spheres on, M_inf's
    Schur complement is factorised and inverted in single precision (here from 27 spheres
    on): at the Brownian default 1e-3 (27 spheres, phi = 0.45, shear) the velocities of
    random forces and of the imposed flow and the stresslets differ from the
    double-precision inversion of the same M_inf by < 1e-2 of the tolerance (measured
    1.6e-7 and 7e-8 relative); below the tolerance or the size the inversion is in double
    precision, bit for bit."""
    from scipy.linalg import cho_factor, cho_solve

    from sdmpi.hydro import resistance
    from sdmpi.hydro.farfield import far_field_mobility
    from sdmpi.hydro.resistance import SINGLE_PRECISION_TOL, far_field_blocks

    pos, side = _dense_random(27, 0.45, seed=11)
    box, radii = np.full(3, side), np.ones(27)
    tol = 1e-3
    assert tol >= SINGLE_PRECISION_TOL > 1e-6
    monkeypatch.setattr(resistance, "SINGLE_PRECISION_MIN_N", 27)
    mobilities = {}
    for ewald_tol, single in ((tol, True), (1e-6, False)):
        res = grand_resistance(pos, radii, box, 0.0, ewald_tol=ewald_tol)
        assert res.exact_inverse is not single
        mob = far_field_mobility(res.positions, radii, plan=res.plan.far)
        same = grand_resistance(pos, radii, box, 0.0, ewald_tol=ewald_tol, far=far_field_blocks(mob, single))
        assert np.array_equal(res.r_fu, same.r_fu)   # the tolerance chose the precision
        assert not same.exact_inverse                # blocks passed in: not taken as exact
        mobilities[ewald_tol] = mob
    with pytest.raises(ValueError, match="double precision"):   # finite differences refused
        resistance.mobility_divergence(lambda x, plan: None, grand_resistance(pos, radii, box, 0.0, ewald_tol=tol))
    monkeypatch.setattr(resistance, "SINGLE_PRECISION_MIN_N", 28)
    assert grand_resistance(pos, radii, box, 0.0, ewald_tol=tol).exact_inverse   # and the size
    forces = np.random.default_rng(12).standard_normal(6 * 27)
    einf = np.zeros((27, 5))
    einf[:, 1] = 1.0   # a shear rate of strain
    out = []
    for single in (False, True):
        res = grand_resistance(pos, radii, box, 0.0, ewald_tol=tol, far=far_field_blocks(mobilities[tol], single))
        u = cho_solve(cho_factor(res.r_fu), forces + res.strain_forces(einf)).reshape(27, 6)
        out.append((u, res.stresslets(u, einf)))
    for a, b in zip(*out):
        assert np.abs(a - b).max() < 1e-2 * tol * np.abs(a).max()


def test_single_precision_inversion_changes_a_brownian_step_only_at_its_rounding(monkeypatch):
    """A Brownian realisation (demo job: 27 spheres, phi = 0.45, oscillatory shear, the
    default Ewald tolerance 1e-3, random-finite-difference drift and Brownian stress), 3
    steps with the same noise, single- against double-precision inversion: every sample's
    hydrodynamic and Brownian stress agree to 1e-4 of its scale, positions to 1e-6 a
    (measured 3.5e-8, 5e-7 and 1.2e-7 a: the inversion's rounding, amplified near
    contact; had the random finite difference's far-field change relied on M_inf M^-1 v =
    v, 6e-4, 1.3e-2 and 2.5e-3 a)."""
    from pathlib import Path

    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation
    from sdmpi.hydro import resistance

    job = load_job(str(Path(__file__).parents[1] / "jobs" / "demo.toml"),
                   ["system.n_particles=27", "system.phi=[0.45]"])
    assert job.hydrodynamics.ewald_tolerance >= resistance.SINGLE_PRECISION_TOL
    runs = []
    for min_n in (27, 28):   # single, double precision
        monkeypatch.setattr(resistance, "SINGLE_PRECISION_MIN_N", min_n)
        real = Realisation(job, enumerate_tasks(job)[0])
        runs.append((real.advance(3), real.positions))
    (single, x_single), (double, x_double) = runs
    for key in ("stress_hydrodynamic", "stress_brownian"):
        assert np.abs(single[key] - double[key]).max() < 1e-4 * np.abs(double[key]).max(), key
    assert np.abs(x_single - x_double).max() < 1e-6


def test_single_precision_inversion_keeps_the_rfd_drift_and_brownian_stress(monkeypatch):
    """The random-finite-difference drift and Brownian stresslets of 8 noise samples (27
    spheres, phi = 0.45, strain 0.1, Ewald tolerance 1e-3) with M_inf inverted in single
    against double precision: equal to 1e-5 relative (measured <= 3.0e-7 for the drift and
    2.6e-7 for the stresslets)."""
    import math

    from sdmpi.dynamics.models import ResistanceModel
    from sdmpi.dynamics.realisation import KT_REDUCED
    from sdmpi.hydro import resistance

    pos, side = _dense_random(27, 0.45, seed=11, strain=0.1)
    zero = np.zeros((27, 5))
    terms = []
    for min_n in (27, 28):   # single, double precision
        monkeypatch.setattr(resistance, "SINGLE_PRECISION_MIN_N", min_n)
        model = ResistanceModel(np.ones(27), np.full(3, side), lubrication=True, ewald_tol=1e-3, cutoff=2.0,
                                min_gap=1e-4)
        at = model.at(pos, 0.1)
        assert at.resistance.exact_inverse is (min_n == 28)
        rng = np.random.default_rng(4)
        samples = []
        for _ in range(8):
            z = rng.standard_normal((27, 6))
            m = at.solver.velocities(at.solver.brownian_forces(z), zero)
            step = at.brownian_terms(z, KT_REDUCED, 1.0)
            samples.append((step.velocities - math.sqrt(2 * KT_REDUCED) * m, step.stresslets))
        terms.append(samples)
    for (drift, stress), (drift_ref, stress_ref) in zip(*terms):
        assert np.linalg.norm(drift - drift_ref) < 1e-5 * np.linalg.norm(drift_ref)
        assert np.linalg.norm(stress - stress_ref) < 1e-5 * np.linalg.norm(stress_ref)


def test_single_precision_inversion_falls_back_to_double_where_it_loses_definiteness():
    """An M_inf whose smallest eigenvalues lie within single precision's rounding of zero
    (here 1e-9 of the largest, of a random orthogonal basis) but are resolved in double
    precision: its single-precision Cholesky finds a non-positive pivot, and the inverse is
    taken in double precision instead (exact), equal to the dense inverse to 1e-6
    relative; the single-precision blocks alone refuse it (FarFieldIndefinite)."""
    from sdmpi.hydro.farfield import FarFieldIndefinite
    from sdmpi.hydro.resistance import _far_field_inverse, far_field_blocks

    n = 4
    rng = np.random.default_rng(3)
    basis, _ = np.linalg.qr(rng.standard_normal((11 * n, 11 * n)))
    eigenvalues = np.geomspace(1e-9, 1.0, 11 * n)
    mob = (basis * eigenvalues) @ basis.T
    mob = (mob + mob.T) / 2
    with pytest.raises(FarFieldIndefinite):
        far_field_blocks(mob, single=True)
    (s_inverse, _, _), exact = _far_field_inverse(mob, single=True)
    assert exact
    rigid = (np.arange(11 * n) % 11) < 6
    reference = np.linalg.inv(mob)[np.ix_(rigid, rigid)]
    assert np.abs(s_inverse - reference).max() < 1e-6 * np.abs(reference).max()


def test_the_ewald_tolerance_key_states_the_single_precision_thresholds():
    """hydrodynamics.ewald_tolerance's help (docs/job_keys.md) names the tolerance and the
    size from which M_inf is inverted in single precision, and the spectral blocks' storage
    threshold is the same tolerance: the text follows the constants."""
    from sdmpi.config import schema_text
    from sdmpi.hydro import resistance, spectral

    text = " ".join(schema_text().split())
    assert f"from {resistance.SINGLE_PRECISION_TOL:g} on" in text
    assert f"{resistance.SINGLE_PRECISION_MIN_N} spheres or more" in text
    assert spectral.SINGLE_PRECISION_TOL == resistance.SINGLE_PRECISION_TOL
