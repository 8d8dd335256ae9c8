"""Far-field FTS mobility: exact limits, Hasimoto's lattice, Ewald consistency, symmetry."""

import math

import numpy as np
import pytest

from sdmpi.hydro.basis import BASIS, from_five, to_five
from sdmpi.hydro.farfield import NDOF, RadialFunction, far_field_mobility, radial_table
from sdmpi.hydro.geometry import Lattice

HASIMOTO_C1 = 2.837297  # Hasimoto (1959), as quoted in the issue; exact 2.8372974794...


def _image_shifts(lattice, reach):
    """Lattice translations n . L with |n_i| <= ceil(reach |b_i|) + 1: every image of a
    point of the primary cell that can lie within `reach` of another point of it."""
    counts = np.ceil(reach * lattice.plane_density).astype(int) + 1
    ranges = [np.arange(-c, c + 1) for c in counts]
    n = np.stack(np.meshgrid(*ranges, indexing="ij"), axis=-1).reshape(-1, 3)
    return n @ lattice.vectors


def _random_config(rng, n, box, rmin=0.6, rmax=1.4):
    """Non-overlapping spheres of random radii (random sequential addition)."""
    pos, rad = [], []
    shifts = _image_shifts(Lattice(box), 2 * rmax)
    while len(pos) < n:
        x, a = rng.uniform(0, 1, 3) * box, rng.uniform(rmin, rmax)
        if all(np.min(np.linalg.norm(p + shifts - x, axis=1)) > a + b + 0.05 for p, b in zip(pos, rad)):
            pos.append(x)
            rad.append(a)
    return np.array(pos), np.array(rad)


def test_basis_is_orthonormal_and_round_trips():
    gram = np.einsum("mij,nij->mn", BASIS, BASIS)
    assert np.allclose(gram, np.eye(5), atol=1e-15)
    e = np.array([[0.1, 0.3, -0.2], [0.3, 0.5, 0.4], [-0.2, 0.4, -0.6]])
    assert np.allclose(from_five(to_five(e)), e, atol=1e-15)


def test_isolated_sphere_self_block():
    for a in (0.5, 1.0, 2.0):
        m = far_field_mobility(np.zeros((1, 3)), np.array([a]))
        assert np.allclose(np.diag(m)[:3], 1 / (6 * math.pi * a), rtol=1e-14)
        assert np.allclose(np.diag(m)[3:6], 1 / (8 * math.pi * a ** 3), rtol=1e-14)
        assert np.allclose(np.diag(m)[6:], 3 / (20 * math.pi * a ** 3), rtol=1e-14)


def test_unbounded_pair_is_rotne_prager_with_exact_singularities():
    a1, a2 = 0.7, 1.3
    pos = np.array([[0.0, 0.0, 0.0], [2.5, -1.0, 1.5]])
    m = far_field_mobility(pos, np.array([a1, a2]))
    rvec = pos[0] - pos[1]
    r = np.linalg.norm(rvec)
    e = rvec / r
    rpy = (np.eye(3) + np.outer(e, e)) / (8 * math.pi * r) + (a1 ** 2 + a2 ** 2) * (
        np.eye(3) - 3 * np.outer(e, e)) / (24 * math.pi * r ** 3)
    assert np.allclose(m[0:3, NDOF:NDOF + 3], rpy, rtol=1e-13, atol=1e-16)
    # rotlet: U_1 = L_2 x (x_1 - x_2) / (8 pi r^3); rotlet-rotlet (3ee - I)/(16 pi r^3)
    torque = np.array([0.3, -1.0, 2.0])
    assert np.allclose(m[0:3, NDOF + 3:NDOF + 6] @ torque, np.cross(torque, rvec) / (8 * math.pi * r ** 3), rtol=1e-13)
    assert np.allclose(m[3:6, NDOF + 3:NDOF + 6], (3 * np.outer(e, e) - np.eye(3)) / (16 * math.pi * r ** 3), rtol=1e-13)
    assert np.allclose(m, m.T, atol=1e-16)


def test_unbounded_stresslet_field_far_away():
    """U_1 due to stresslet S of sphere 2: -(3/8pi)(x.S.x) x / r^5 + O(r^-4)."""
    s = np.array([[0.0, 1.0, 0.2], [1.0, 0.3, 0.0], [0.2, 0.0, -0.3]])
    for r_scale in (100.0, 1000.0):
        pos = np.array([[0.0, 0.0, 0.0], [r_scale, 0.4 * r_scale, -0.2 * r_scale]])
        m = far_field_mobility(pos, np.ones(2))
        x = pos[0] - pos[1]
        r = np.linalg.norm(x)
        exact = -(3 / (8 * math.pi)) * (x @ s @ x) * x / r ** 5
        got = m[0:3, NDOF + 6:] @ (-to_five(s))
        # relative correction is the Faxen term, O((a/r)^2)
        assert np.abs(got - exact).max() < 5 / r ** 2 * np.abs(exact).max()


@pytest.mark.parametrize("side", [20.0, 40.0, 80.0])
def test_hasimoto_simple_cubic_lattice(side):
    """6 pi U/F = 1 - 2.837297/L + 4.18879/L^3 + O(L^-6) (Hasimoto 1959)."""
    m = far_field_mobility(np.zeros((1, 3)), np.ones(1), box=[side] * 3, tol=1e-12)
    expected = 1 - HASIMOTO_C1 / side + 4.18879 / side ** 3
    # 1e-6: the quoted constants' rounding (4.8e-7/L) and the O(L^-6) term (< 5e-7 at L=20)
    assert 6 * math.pi * m[0, 0] == pytest.approx(expected, abs=1e-6)
    assert np.allclose(np.diag(m)[:3], m[0, 0], rtol=1e-12)  # cubic symmetry


def test_ewald_splitting_parameter_independence():
    rng = np.random.default_rng(7)
    box = np.array([8.0, 9.0, 10.0])
    pos, rad = _random_config(rng, 6, box)
    mats = [far_field_mobility(pos, rad, box=box, strain=0.3, xi=xi, tol=1e-14) for xi in (0.25, 0.4, 0.7)]
    scale = np.abs(mats[0]).max()
    for m in mats[1:]:
        assert np.abs(m - mats[0]).max() < 1e-10 * scale


def test_periodic_invariances():
    rng = np.random.default_rng(11)
    box = np.array([9.0, 8.0, 10.0])
    pos, rad = _random_config(rng, 5, box)
    ref = far_field_mobility(pos, rad, box=box, strain=0.35)
    # moving every particle by a box length (incl. the sheared y-image)
    shifted = pos + np.array([box[0], 0, 0]) + np.array([0.35 * box[1], box[1], -box[2]])
    assert np.allclose(far_field_mobility(shifted, rad, box=box, strain=0.35), ref, atol=1e-12 * np.abs(ref).max())
    # one particle by one sheared lattice vector only
    one = pos.copy()
    one[2] += np.array([0.35 * box[1], box[1], 0.0])
    assert np.allclose(far_field_mobility(one, rad, box=box, strain=0.35), ref, atol=1e-12 * np.abs(ref).max())
    # relabelling
    perm = rng.permutation(len(rad))
    mp = far_field_mobility(pos[perm], rad[perm], box=box, strain=0.35)
    idx = (NDOF * perm[:, None] + np.arange(NDOF)).ravel()
    assert np.allclose(mp, ref[np.ix_(idx, idx)], atol=1e-12 * np.abs(ref).max())
    # Lees-Edwards period: strain -> strain + Lx/Ly, and negative strains
    for strain in (0.35 + box[0] / box[1], 0.35 - 2 * box[0] / box[1]):
        assert np.allclose(far_field_mobility(pos, rad, box=box, strain=strain), ref, atol=1e-12 * np.abs(ref).max())


def test_symmetric_positive_definite_sheared():
    rng = np.random.default_rng(3)
    box = np.array([9.0, 9.0, 9.0])
    pos, rad = _random_config(rng, 8, box)
    for strain in (-0.45, 0.0, 0.2):
        m = far_field_mobility(pos, rad, box=box, strain=strain)
        assert np.abs(m - m.T).max() < 1e-15 * np.abs(m).max()
        assert np.linalg.eigvalsh(m).min() > 0


def test_radial_machinery_matches_closed_forms():
    """lap chi_r = erfc(xi r)/(4 pi r) - G/4xi^2 + lap G/8xi^4 with G the normalised
    Gaussian (the Hasimoto splitting, derived independently in Fourier space)."""
    xi = 0.8
    table = radial_table(xi)
    phi1 = RadialFunction(xi, table[1, 0, 0], table[1, 0, 1])
    r = np.linspace(0.5, 6.0, 12)
    gauss = (xi / math.sqrt(math.pi)) ** 3 * np.exp(-((xi * r) ** 2))
    lap_gauss = gauss * (4 * xi ** 4 * r ** 2 - 6 * xi ** 2)
    erfc = np.array([math.erfc(xi * x) for x in r])
    closed = erfc / (4 * math.pi * r) - gauss / (4 * xi ** 2) + lap_gauss / (8 * xi ** 4)
    assert np.allclose(phi1(r), closed, rtol=1e-12, atol=1e-15)
    # derivative chain vs finite differences
    phi0 = RadialFunction(xi, table[0, 0, 0], table[0, 0, 1])
    d1 = RadialFunction(xi, table[0, 1, 0], table[0, 1, 1])
    h = 1e-6
    assert np.allclose(d1(r), (phi0(r + h) - phi0(r - h)) / (2 * h), rtol=1e-7)


@pytest.mark.parametrize("box, count, reach_abs, cells", [
    ([5.0, 4.0, 6.0], 7, 2.0, False),   # reach > box: many images, pair by pair
    ([16.0, 14.0, 15.0], 60, 1.0, True),  # >= 3 cells of the reach per axis: cell list
])
def test_pair_search_finds_exactly_the_images_within_reach(box, count, reach_abs, cells):
    """find_pairs (direct enumeration of lattice translations in small boxes, a cell list
    in large ones) against a brute-force scan of every translation |n_i| <= 4, for
    unwrapped positions and positive and negative strain (the x-extent of a sheared box
    makes the enumeration order matter); pairs ordered by i, then j."""
    from sdmpi.hydro.geometry import _cell_counts, find_pairs

    rng = np.random.default_rng(5)
    box = np.array(box)
    for strain in (0.0, 0.45, -0.3):
        lat = Lattice(box, strain)
        pos = rng.uniform(-3, 9, (count, 3)) * box / 6  # not wrapped on purpose
        radii = rng.uniform(0.5, 1.0, count)
        assert (_cell_counts(lat, reach_abs + 3.0 * radii.max()) is not None) == cells
        i, j, shift = find_pairs(pos, radii, lat, reach_abs, 1.5)
        got = {(a, b, tuple(np.round(s, 9))) for a, b, s in zip(i, j, shift)}
        n = np.stack(np.meshgrid(*[np.arange(-4, 5)] * 3, indexing="ij"), -1).reshape(-1, 3)
        shifts = n @ lat.vectors
        want = set()
        for a in range(count):
            for b in range(a, count):
                d = np.linalg.norm(pos[b] + shifts - pos[a], axis=1)
                for k in np.nonzero(d < reach_abs + 1.5 * (radii[a] + radii[b]))[0]:
                    if a == b and tuple(n[k][::-1]) <= (0, 0, 0):  # one of each +-n
                        continue
                    want.add((a, b, tuple(np.round(shifts[k], 9))))
        assert got == want and len(got) == len(i) and len(got) > count // 4
        assert np.all(np.diff(i * count + j) >= 0)


@pytest.mark.parametrize("box, count", [([5.0, 4.0, 6.0], 7), ([16.0, 14.0, 15.0], 60)])
def test_pairs_within_a_longer_search_are_the_shorter_search(box, count):
    """pairs_within (a longer pair list filtered) gives exactly find_pairs' list at the
    shorter reach, in its order, on both search paths (by translations, by cell list):
    one search serves the Ewald sums and the lubrication."""
    from sdmpi.hydro.geometry import find_pairs, pairs_within

    rng = np.random.default_rng(8)
    box = np.array(box)
    for strain in (0.0, 0.45, -0.3):
        lat = Lattice(box, strain)
        pos = lat.wrap(rng.uniform(0, 1, (count, 3)) * box)
        radii = rng.uniform(0.5, 1.0, count)
        long = find_pairs(pos, radii, lat, 4.5, 0.0)
        for reach_abs, reach_rel in ((3.0, 0.0), (0.0, 2.0)):
            want = find_pairs(pos, radii, lat, reach_abs, reach_rel)
            got = pairs_within(long, pos, radii, reach_abs, reach_rel)
            assert len(want[0]) > count // 2
            for a, b in zip(got, want):
                assert np.array_equal(a, b)


def test_wave_phases_are_the_cosines_and_sines_of_k_x():
    """wave_phases (products of per-axis phases) against cos and sin of k.x directly, on
    sheared lattices of unequal sides: equal to rounding (|k.x| up to ~50, so ~1e-14)."""
    from sdmpi.hydro.farfield import plan_far_field, wave_phases

    rng = np.random.default_rng(4)
    box = np.array([6.0, 5.0, 7.0])
    for strain in (0.0, 0.37, -0.5):
        lat = Lattice(box, strain)
        pos = lat.wrap(rng.uniform(0, 1, (20, 3)) * box)
        plan = plan_far_field(pos, np.ones(20), lat, 1e-6)
        assert np.allclose(plan.wave_index @ plan.wave_basis, plan.kvec, rtol=0, atol=1e-13)
        cos, sin = wave_phases(pos, plan)
        phase = pos @ plan.kvec.T
        assert np.abs(cos - np.cos(phase)).max() < 1e-13 and np.abs(sin - np.sin(phase)).max() < 1e-13


@pytest.mark.parametrize("phi", [0.1, 0.45])
def test_pair_room_covers_a_suspension(phi):
    """find_pairs sizes its outputs by the mean count of pair images within reach
    (geometry._expected_pairs, + 10%): enough for one scan of a hard-sphere suspension at
    the reaches of lubrication (4) and of the spectral real space (6.45), and not much
    more than needed (room - 16 N < 1.5 x the count: excluded volume only lowers it)."""
    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro.geometry import _expected_pairs, find_pairs

    n = 343
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(2), sweeps=3, strain=0.3)
    lat = Lattice(np.full(3, side), 0.3)
    for reach in (4.0, 6.45):
        count = len(find_pairs(pos, np.ones(n), lat, reach, 0.0)[0])
        room = _expected_pairs(n, lat, reach)
        assert count <= room and room - 16 * n < 1.5 * count, (reach, count, room)


@pytest.mark.parametrize("tol", [1e-4, 1e-6, 1e-8])
def test_requested_accuracy_is_met(tol):
    """The whole periodic M_inf at accuracy tol (interpolated real-space radial values,
    truncated sums) against a tol = 1e-13 sum (exact radial values): the largest error,
    relative to the largest entry, is below tol (measured 0.1-0.3 tol)."""
    rng = np.random.default_rng(11)
    box = np.array([7.0, 7.0, 7.0])
    pos, rad = _random_config(rng, 12, box, rmin=0.9, rmax=1.0)
    ref = far_field_mobility(pos, rad, box=box, strain=-0.4, tol=1e-13)
    got = far_field_mobility(pos, rad, box=box, strain=-0.4, tol=tol)
    assert np.abs(got - ref).max() < tol * np.abs(ref).max()
