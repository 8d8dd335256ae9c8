"""The first-order resistance change of the random finite difference: the matrix-free
far-field product and the lubrication product against assembled matrices, the resistance change against two
full assemblies, and the rfd drift and Brownian stresslets against the same difference
taken between two full evaluations."""

import dataclasses
import math

import numpy as np
import pytest

from sdmpi.dynamics.drift import rfd_length
from sdmpi.dynamics.models import ResistanceModel
from sdmpi.dynamics.realisation import KT_REDUCED
from sdmpi.hydro.farfield import far_field_mobility, far_field_product, plan_far_field
from sdmpi.hydro import lubrication
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.lubrication import (close_pairs, lubrication_matrix, lubrication_partitions, lubrication_product,
                                     pair_corrections)
from sdmpi.hydro.resistance import grand_resistance, resistance_change

BOX = np.array([7.0, 7.0, 7.0])
# five spheres, unequal, one pair 0.01 radii apart, one 0.3, in a sheared periodic box
CONFIG = np.array([[1.0, 1.2, 0.8], [3.01, 1.2, 0.8], [2.0, 3.9, 3.5], [4.5, 3.0, 5.5], [5.6, 5.5, 2.0]])
RADII = np.array([1.0, 1.0, 0.8, 1.0, 0.7])
STRAIN = 0.15
EPS = np.finfo(float).eps


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



@pytest.mark.parametrize("strain", [0.0, 0.3])
def test_real_space_product_is_the_real_space_blocks_times_the_vector(strain):
    """The real-space Ewald product in tensor form (`_real_space_product`) against the
    11x11 image blocks assembled into a matrix (`_real_space_sum`) times w: four spheres of
    three radii (unequal and equal pairs) in a box of side 4.5, small enough that every
    sphere sees its own images (self-images) and pairs have several consecutive images.
    Tolerance 1e-13 of the largest entry."""
    from sdmpi.hydro.farfield import BASIS, NDOF, _real_space_product, _real_space_sum

    lattice = Lattice(np.full(3, 4.5), strain)
    pos = lattice.wrap(np.array([[0.4, 0.6, 0.5], [2.5, 1.2, 2.9], [1.3, 3.4, 2.4], [3.3, 3.9, 4.3]]))
    radii = np.array([1.0, 0.6, 1.3, 1.0])
    plan = plan_far_field(pos, radii, lattice, 1e-6)
    pi, pj, _ = plan.images
    assert np.any(pi == pj) and np.any((pi[1:] == pi[:-1]) & (pj[1:] == pj[:-1]) & (pi[1:] != pj[1:]))
    w = np.random.default_rng(2).standard_normal((len(pos), NDOF))
    args = (*plan.images, plan.table, plan.grid.values, plan.grid.r0, plan.grid.h, plan.params.xi, BASIS)
    for x in (pos, pos + 1e-2 * np.random.default_rng(3).standard_normal(pos.shape)):
        mob = np.zeros((NDOF * len(pos), NDOF * len(pos)))
        _real_space_sum(x, radii, *args, mob, True)
        ref = mob @ w.ravel()
        got = np.zeros_like(w)
        _real_space_product(x, radii, *args, w, got)
        assert np.abs(got.ravel() - ref).max() < 1e-13 * np.abs(ref).max()


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


def test_resistance_change_of_a_rounded_inverse():
    """Delta R v with M_inf^-1 rounded: S^-1 (of the block inversion) times (1 + 1e-7 P) for
    a random symmetric P, as a single-precision inversion rounds it, at a displacement of
    1e-6 (a change of 2.7e-6 of R v). Marked inexact (`GrandResistance.exact_inverse`
    False), the far-field change is the difference of two products with the same plan,
    [M_inf(x') - M_inf(x)] w, and carries the rounding only relatively (measured 1.8e-9 of
    the change; tolerance 1e-5). Marked exact, M_inf(x) w is taken as v, which the rounding
    breaks by ~1e-7 |v|, against a change of ~1e-6 |v| (measured 6e-3 of the change; the
    test asks > 1e-3): why single-precision blocks must say so."""
    base = grand_resistance(CONFIG, RADII, BOX, STRAIN)
    assert base.exact_inverse
    rng = np.random.default_rng(6)
    noise = rng.standard_normal(base.s_inverse.shape)
    s_rounded = base.s_inverse * (1 + 1e-7 * (noise + noise.T) / 2)
    v = rng.standard_normal((len(CONFIG), 11))
    moved = base.positions + _displacement(1e-6)
    ref = resistance_change(base, moved, v, 1e-4)
    for exact, bound in ((False, lambda err: err < 1e-5), (True, lambda err: err > 1e-3)):
        rounded = dataclasses.replace(base, s_inverse=s_rounded, exact_inverse=exact)
        got = resistance_change(rounded, moved, v, 1e-4)
        assert bound(np.linalg.norm(got - ref) / np.linalg.norm(ref)), exact


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
    step = rfd_length(model.min_gap)
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


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("small", [1.0, 0.6173])
def test_lubrication_change_round_off_near_contact(small):
    """The lubrication part of the change, L(moved) v pair by pair minus L(base) v by the
    dense partitions, against the same pair blocks' differences applied in extended
    precision, for a chain of seven spheres at gaps 1e-4 (the floor) to 0.1 mean radii
    (entries of L up to ~1e5) and displacements of 1e-7 to 1e-5 (the rfd's ~1e-6). The
    difference of the two products carries a round-off of ~eps max|L v| (measured up to
    2.4 eps, 8.8e-13 of the change at displacements of 1e-7); tolerance 8 eps max|L v| and
    1e-10 of the change. small: the radius of sphere 4 (0.6173: size ratios on the exact path)."""
    radii = np.array([1.0, 1.0, 1.0, 1.0, small, 1.0, 1.0])
    chain = [(0, 1, [1, 0.3, 0.1], 1.5e-4), (1, 2, [0.2, 1, -0.3], 3e-4), (0, 3, [-0.4, 0.2, 1], 1e-3),
             (2, 4, [0.3, 0.4, 1], 1e-2), (3, 5, [-1, 0.5, 0.2], 1e-4), (5, 6, [0.1, -1, 0.4], 0.1)]
    pos = np.zeros((7, 3))
    pos[0] = 4.0
    for i, j, d, gap in chain:
        pos[j] = pos[i] + _unit(d) * (1.0 + 0.5 * gap) * (radii[i] + radii[j])
    n = len(pos)
    lattice = Lattice(np.full(3, 12.0), STRAIN)
    pos = lattice.wrap(pos)
    pairs = close_pairs(pos, radii, lattice, min_gap=1e-4)
    assert (pairs.gap / (0.5 * pairs.radii_sum)).min() < 1.1e-4
    if small == 1.0:  # the equal spheres' table: built for a few pairs only once it exists
        count = lubrication._MIN_PAIRS_FOR_TABLE
        lubrication._STORE.lookup(np.ones(count), np.full(count, 0.01))
    dense, setup = lubrication_partitions(radii, pairs, n)
    assert (setup is None) == (small != 1.0)
    l_fu, l_fe, _ = dense
    images = (pairs.i, pairs.j, pairs.shift)
    a1, a2 = radii[pairs.i], radii[pairs.j]
    base_blocks = pair_corrections(pairs.dx, a1, a2).astype(np.longdouble)
    rng = np.random.default_rng(0)
    for scale in (1e-7, 1e-6, 1e-5, 1e-6):
        v = np.zeros((n, 11))
        v[:, :6] = rng.standard_normal((n, 6))
        moved = close_pairs(pos + scale * rng.standard_normal((n, 3)), radii, None, min_gap=1e-4, images=images)
        base_product = np.hstack([(l_fu @ v[:, :6].ravel()).reshape(n, 6),
                                  (l_fe.T @ v[:, :6].ravel()).reshape(n, 5)])
        got = lubrication_product(radii, moved, v, setup) - base_product
        diff = pair_corrections(moved.dx, a1, a2).astype(np.longdouble) - base_blocks
        ref = np.zeros((n, 11), dtype=np.longdouble)
        for p, (i, j) in enumerate(zip(pairs.i, pairs.j)):
            y = diff[p] @ np.concatenate([v[i], v[j]]).astype(np.longdouble)
            ref[i] += y[:11]
            ref[j] += y[11:]
        err = float(np.abs(got - ref).max())
        assert err < 8 * EPS * np.abs(base_product).max()
        assert err < 1e-10 * float(np.abs(ref).max())
