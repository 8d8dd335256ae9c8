"""The Brownian drift near contact, and the hard-sphere collisions: two spheres at gaps
from just above the lubrication floor to 1e-2, at the default time step."""

import math

import numpy as np
import pytest

from sdmpi.dynamics.collisions import SEPARATION, remove_overlaps, separate
from sdmpi.dynamics.models import ResistanceModel
from sdmpi.dynamics.realisation import KT_REDUCED
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.lubrication import close_pairs
from sdmpi.hydro.resistance import grand_resistance

BOX = np.full(3, 10.0)
MIN_GAP = 1e-4  # the default floor: gaps below 1e-4 a are clamped in the lubrication


def _pair(h):
    return np.array([[3.0, 4.0, 5.0], [5.0 + h, 4.1, 5.0]]) * np.array([1, 1, 1])


def _exact_divergence(pos, eps):
    """kT div R_FU^-1 by centred differences of step eps over the 6 translations (the
    pair sets of pos kept)."""
    base = grand_resistance(pos, np.ones(2), BOX, 0.0, min_gap=MIN_GAP)
    div = np.zeros(12)
    for p in range(2):
        for c in range(3):
            inv = []
            for sign in (1, -1):
                moved = base.positions.copy()
                moved[p, c] += sign * eps
                r_fu = grand_resistance(moved, np.ones(2), BOX, 0.0, min_gap=MIN_GAP, plan=base.plan).blocks()[0]
                inv.append(np.linalg.inv(r_fu)[:, 6 * p + c])
            div += (inv[0] - inv[1]) / (2 * eps)
    return KT_REDUCED * div.reshape(2, 6)


@pytest.mark.parametrize("gap", [1.1e-4, 2e-4, 1e-3, 4e-3, 1e-2])
def test_rfd_drift_exact_near_contact_at_default_time_step(gap):
    """Mean over the noise of the rfd Brownian velocity (dt = 5e-4, the largest default
    step): a linear (mean 0) plus a quadratic form in z to O(epsilon^2), so z = +-e_k
    (weights 1/2) give it exactly. It equals the exact divergence within 1e-4 relative at
    every gap (centred-difference truncation and the rounding of a difference over epsilon,
    ~1e-6 of the drift at cond R_FU ~ 1e4), far inside the 2% near-contact accuracy asked
    of the drift; the relative radial drift, which keeps pairs from piling up at contact,
    is checked alone too."""
    pos = _pair(gap)
    model = ResistanceModel(np.ones(2), BOX, lubrication=True, ewald_tol=1e-6, cutoff=2.0, min_gap=MIN_GAP,
                            scheme="rfd")
    at = model.at(pos, 0.0)
    mean = np.zeros((2, 6))
    for k in range(12):
        for sign in (1.0, -1.0):
            z = np.zeros(12)
            z[k] = sign
            mean += 0.5 * at.brownian_terms(z.reshape(2, 6), KT_REDUCED, 5e-4).velocities
    exact = _exact_divergence(at.positions, eps=min(1e-6, (gap - MIN_GAP) / 20))
    assert np.abs(mean - exact).max() < 1e-4 * np.abs(exact).max()
    e = at.positions[1] - at.positions[0]
    e /= np.linalg.norm(e)
    radial, radial_exact = e @ (mean[1, :3] - mean[0, :3]), e @ (exact[1, :3] - exact[0, :3])
    assert radial > 0  # the drift pushes the pair apart
    assert radial == pytest.approx(radial_exact, rel=1e-4)


def test_overlap_correction_leaves_pairs_above_the_lubrication_floor():
    """Three spheres in a row, two overlaps: corrected until no pair is closer than the
    floor, the last one moved to SEPARATION x min_gap (mean radii), symmetric pushes (the
    centre of mass kept), the separation changes reported per pair."""
    pos = np.array([[0.0, 0, 0], [1.9, 0, 0], [3.85, 0, 0]])
    radii = np.ones(3)
    pairs = close_pairs(pos, radii)
    fixed, moved = remove_overlaps(pos, radii, pairs, min_gap=MIN_GAP)
    after = close_pairs(fixed, radii)
    assert after.gap.min() > MIN_GAP  # no pair left below the floor
    assert np.isclose(after.gap, SEPARATION * MIN_GAP, rtol=1e-6).any()
    assert np.allclose(fixed.mean(axis=0), pos.mean(axis=0))
    assert moved.sum() > 0.1 + 0.15  # at least the two initial overlaps were undone


def test_collision_force_is_the_free_draining_impulse():
    """One overlapping pair in free draining: the collision force f = s/(G dt) with
    G = 2/(6 pi) moves each sphere, in dt, by exactly its correction; the virial is
    r f e e^T (trace r f)."""
    pos = np.array([[2.0, 2.0, 2.0], [3.95, 2.0, 2.0]])
    radii = np.ones(2)
    lattice = Lattice(BOX, 0.0)
    fixed, coll = separate(pos, radii, lattice, MIN_GAP)
    assert coll.n_overlaps == 1 and coll.deepest == pytest.approx(-0.05)
    dt = 1e-3
    forces, virial = coll.forces(lambda i, j, e: np.full(len(i), 2 / (6 * math.pi)), dt, 2)
    displacement = dt * forces[:, :3] / (6 * math.pi)
    assert np.allclose(displacement, fixed - pos, atol=1e-14)
    assert np.allclose(forces.sum(axis=0), 0)
    assert np.trace(virial) == pytest.approx(coll.r[0] * coll.s[0] / (2 / (6 * math.pi) * dt))
