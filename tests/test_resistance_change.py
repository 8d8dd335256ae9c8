"""The first-order resistance change of the random finite difference: the matrix-free
far-field product and the lubrication product against assembled matrices, the resistance change against two
full assemblies, and the rfd drift and Brownian stresslets against the same difference
taken between two full evaluations."""

import math

import numpy as np
import pytest

from sdmpi.dynamics.models import ResistanceModel
from sdmpi.dynamics.realisation import KT_REDUCED
from sdmpi.hydro.farfield import far_field_mobility, far_field_product, plan_far_field
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.lubrication import close_pairs, lubrication_matrix, lubrication_product
from sdmpi.hydro.resistance import grand_resistance, resistance_change

BOX = np.array([7.0, 7.0, 7.0])
# five spheres, unequal, one pair 0.01 radii apart, one 0.3, in a sheared periodic box
CONFIG = np.array([[1.0, 1.2, 0.8], [3.01, 1.2, 0.8], [2.0, 3.9, 3.5], [4.5, 3.0, 5.5], [5.6, 5.5, 2.0]])
RADII = np.array([1.0, 1.0, 0.8, 1.0, 0.7])
STRAIN = 0.15


def _displacement(scale, seed=0):
    return scale * np.random.default_rng(seed).standard_normal(CONFIG.shape)


@pytest.mark.parametrize("strain", [0.0, STRAIN])
@pytest.mark.parametrize("radii", [RADII, np.ones(len(RADII))], ids=["unequal", "equal"])
def test_far_field_product_is_the_assembled_mobility_times_the_vector(strain, radii):
    """M_inf w by the matrix-free sums equals the assembled matrix (same plan) times w, at
    the plan's positions and displaced from them; unequal radii (the Faxen factors
    expanded) and equal ones (folded), a sheared box. Both are sums of the same terms in
    other orders: tolerance 1e-13 of the largest entry."""
    lattice = Lattice(BOX, strain)
    pos = lattice.wrap(CONFIG)
    plan = plan_far_field(pos, radii, lattice, 1e-6)
    w = np.random.default_rng(1).standard_normal((len(pos), 11))
    for x in (pos, pos + _displacement(1e-2)):
        ref = far_field_mobility(x, radii, plan=plan) @ w.ravel()
        got = far_field_product(x, radii, plan, w).ravel()
        assert np.abs(got - ref).max() < 1e-13 * np.abs(ref).max()


def test_far_field_product_unbounded():
    """The same without a box (pair sums over all pairs, no reciprocal part)."""
    plan = plan_far_field(CONFIG, RADII, None)
    w = np.random.default_rng(4).standard_normal((len(CONFIG), 11))
    ref = far_field_mobility(CONFIG, RADII, plan=plan) @ w.ravel()
    assert np.abs(far_field_product(CONFIG, RADII, plan, w).ravel() - ref).max() < 1e-13 * np.abs(ref).max()


def test_lubrication_product_is_the_matrix_times_the_vector():
    lattice = Lattice(BOX, STRAIN)
    pos = lattice.wrap(CONFIG)
    pairs = close_pairs(pos, RADII, lattice)
    assert len(pairs.i) >= 2
    v = np.random.default_rng(2).standard_normal((len(pos), 11))
    ref = lubrication_matrix(pos, RADII, pairs) @ v.ravel()
    got = lubrication_product(RADII, pairs, v).ravel()
    assert np.abs(got - ref).max() < 1e-12 * np.abs(ref).max()


def test_resistance_change_is_first_order_in_the_displacement():
    """Delta R v against R(x') v - R(x) v from two full assemblies (same pair sets), at
    displacements of scale 1e-5 and 1e-6: the difference is the dropped second-order part,
    proportional to the displacement (measured 1.8e-7 and 1.9e-8 relative; the far-field
    change shares the assembly's Ewald terms, so their truncation cancels). Tolerance
    0.1 x the scale."""
    base = grand_resistance(CONFIG, RADII, BOX, STRAIN)
    v = np.random.default_rng(3).standard_normal((len(CONFIG), 11))
    for scale in (1e-5, 1e-6):
        moved = base.positions + _displacement(scale)
        full = grand_resistance(moved, RADII, BOX, STRAIN, plan=base.plan)
        ref = full.product(v).ravel() - base.product(v).ravel()
        got = resistance_change(base, moved, v, 1e-4).ravel()
        assert np.linalg.norm(got - ref) < 0.1 * scale * np.linalg.norm(ref)


def test_rfd_drift_matches_the_difference_of_two_full_evaluations():
    """The rfd Brownian drift and stresslets (first-order change) against the same random
    finite difference taken between two full evaluations, for 8 noise samples: the dropped
    terms are quadratic in the change (relative ~ the closest pair's gap change over its
    gap, ~1e-2 at the floor; measured here at most 1.0e-4 for the drift and 1.1e-4 for the
    stresslets)."""
    model = ResistanceModel(RADII, BOX, lubrication=True, ewald_tol=1e-6, cutoff=4.0, min_gap=1e-4)
    at = model.at(CONFIG, STRAIN)
    n, zero = len(CONFIG), np.zeros((len(CONFIG), 5))
    rng = np.random.default_rng(4)
    step = model.rfd_step * 6 * math.pi
    for _ in range(8):
        z = rng.standard_normal((n, 6))
        unit_force = at.solver.brownian_forces(z)
        m = at.solver.velocities(unit_force, zero)
        moved, _ = model.displaced(at, at.positions + step * m[:, :3], separate=False)
        m_moved = moved.velocities(unit_force, zero)
        ref_drift = (KT_REDUCED / step) * (m_moved - m)
        ref_stress = (KT_REDUCED / step) * (moved.stresslets(m_moved, zero) - at.solver.stresslets(m, zero))
        terms = at.brownian_terms(z, KT_REDUCED, 1.0)
        drift = terms.velocities - math.sqrt(2 * KT_REDUCED) * m
        assert np.linalg.norm(drift - ref_drift) < 2e-3 * np.linalg.norm(ref_drift)
        assert np.linalg.norm(terms.stresslets - ref_stress) < 2e-3 * np.linalg.norm(ref_stress)
