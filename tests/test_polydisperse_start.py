"""Dense starts (sdmpi.dynamics.initial.hard_sphere_fluid above the lattice limit: lattice
at 0.9 of it, compression, MC at phi) for size classes, and the validation of
polydisperse jobs: dense phi accepted, and the van der Waals / double-layer cut-off
checked for the worst pair of size classes rather than for radius-1 spheres."""

import math

import numpy as np
import pytest

from sdmpi.config import JobError, enumerate_tasks
from sdmpi.dynamics.checks import parse_job
from sdmpi.config.schema import START_PHI_LIMIT
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.forces import DoubleLayer, VanDerWaals
from sdmpi.dynamics.initial import box_side, hard_sphere_fluid, min_gap_ratio

BIDISPERSE = "[{radius = 1.0, fraction = 0.5}, {radius = 0.5, fraction = 0.5}]"
THREE = ("[{radius = 1.0, fraction = 0.25}, {radius = 0.7, fraction = 0.5}, "
         "{radius = 0.45, fraction = 0.25}]")


def _system(classes, n, phi):
    return parse_job(f"[system]\nn_particles = {n}\nphi = {phi}\nsize_classes = {classes}\n"
                     "[shear]\nprotocol = \"none\"\n[integration]\ndt = 1e-3\n").system


@pytest.mark.parametrize("classes, n, phi, strain, seed", [
    (BIDISPERSE, 27, 0.45, 0.0, 1),     # lattice limit 0.116: 3.9 x above it
    (BIDISPERSE, 27, 0.55, 0.3, 2),
    (THREE, 64, 0.45, -0.7, 3),
    (THREE, 64, 0.5, 0.0, 4),
])
def test_dense_polydisperse_start(classes, n, phi, strain, seed):
    system = _system(classes, n, phi)
    assert phi > system.lattice_phi_limit
    radii = np.array(system.radii)
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(seed), radii=radii,
                                  strain=strain, sweeps=100)
    # no overlaps (Lees-Edwards minimum image at the start's strain)
    assert min_gap_ratio(pos, side, radii, strain) >= 1.0
    # the stated volume fraction: box side within round-off of the exact one
    assert side == pytest.approx(box_side(radii, phi), rel=1e-12)
    assert 4 / 3 * math.pi * np.sum(radii ** 3) / side ** 3 == pytest.approx(phi, rel=1e-12)
    # radii counts and realised volume shares of the classes unchanged
    counts = tuple(int(np.sum(radii == r)) for r in system.class_radii)
    assert counts == system.class_counts
    vols = np.array([c * r ** 3 for c, r in zip(counts, system.class_radii)])
    assert vols / vols.sum() == pytest.approx(system.realised_fractions, rel=1e-12)
    # a fluid, not the compressed lattice: large spheres spread over the box
    big = pos[radii == 1.0] % side
    assert np.ptp(big, axis=0).max() > side / 3


def test_monodisperse_dense_start_and_limit():
    pos, side = hard_sphere_fluid(27, 0.55, np.random.default_rng(0), sweeps=50)
    assert min_gap_ratio(pos, side, np.ones(27)) >= 1.0      # above pi/6 = 0.5236
    with pytest.raises(ValueError, match="compressed"):
        hard_sphere_fluid(27, START_PHI_LIMIT, np.random.default_rng(0))


def test_dense_polydisperse_job_validates_and_starts():
    job = parse_job(f"[system]\nn_particles = 27\nphi = 0.45\nsize_classes = {BIDISPERSE}\n"
                    "[integration]\nsteps_per_period = 200\nperiods = 2\ndiscard_periods = 1\n"
                    "[ensemble]\nrealisations = 1\n")
    r = Realisation(job, enumerate_tasks(job)[0])
    assert min_gap_ratio(r.positions % r.box[0], r.box[0], r.radii) >= 1.0
    with pytest.raises(JobError, match=r"system.phi\[0\] = 0.61.*phi < 0.6"):
        parse_job(f"[system]\nphi = 0.61\nsize_classes = {BIDISPERSE}\n")


DLVO = """
[system]
phi = 0.02
size_classes = {classes}
[shear]
protocol = "steady"
[integration]
dt = 1e-5
[interparticle]
kind = "dlvo"
hamaker = 1.0
cap_gap = 0.01
debye_length = 0.15
surface_potential = 3.0
"""


def test_cutoff_check_uses_the_worst_pair():
    """The double layer decays over debye_length = 0.15: at the cut-off gap of radius-1
    pairs (2 x 1) F/F(0) = 2 e^(-13.3)/(1 + e^(-13.3)) = 3e-6 is negligible, but for two
    spheres of radius 0.3 (cut-off gap 0.6) it is 2 e^(-4)/(1 + e^(-4)) = 0.036 > 1e-3."""
    law = DoubleLayer(1.0, 0.15)
    assert law.magnitude(2.0, 1.0, 1.0) / law.magnitude(0.0, 1.0, 1.0) < 1e-5
    assert law.magnitude(0.6, 0.3, 0.3) / law.magnitude(0.0, 0.3, 0.3) == pytest.approx(
        2 * math.exp(-4) / (1 + math.exp(-4)), rel=1e-12)
    parse_job(DLVO.format(classes="[{radius = 1.0, fraction = 1.0}]"))
    with pytest.raises(JobError) as err:
        parse_job(DLVO.format(classes="[{radius = 1.0, fraction = 0.5}, "
                                      "{radius = 0.3, fraction = 0.5}]"))
    text = str(err.value)
    assert "interparticle.debye_length = 0.15" in text and "worst pair: radii 0.3 and 0.3" \
        in text and "0.036 of its contact value" in text
    # the van der Waals cap must lie inside the smallest pair's cut-off gap (2 x 0.3)
    with pytest.raises(JobError, match=r"cap_gap = 0.7.*smallest radius 0.3.*cap_gap < 0.6"):
        parse_job(DLVO.format(classes="[{radius = 1.0, fraction = 0.5}, "
                                      "{radius = 0.3, fraction = 0.5}]")
                  .replace("cap_gap = 0.01", "cap_gap = 0.7").replace("0.15", "0.01"))


def test_van_der_waals_tail_grows_for_small_pairs():
    """The fixed cap against a cut-off gap that shrinks with the pair: the van der Waals
    tail ratio of a 0.3-0.3 pair is larger than that of a 1-1 pair (what the loader's
    check now takes the maximum of)."""
    law = VanDerWaals(1.0, 0.01)
    big = law.magnitude(2.0, 1.0, 1.0) / law.magnitude(0.01, 1.0, 1.0)
    small = law.magnitude(0.6, 0.3, 0.3) / law.magnitude(0.01, 0.3, 0.3)
    assert small > 3 * big


@pytest.mark.parametrize("side, strain", [(10.0, 0.0), (10.0, 0.45), (13.0, -0.9), (5.5, 0.2)])
def test_mc_cell_list_finds_every_sphere_within_contact(side, strain):
    """The MC overlap check looks only at the spheres in the 27 cells around a trial
    position (lattice coordinates of the sheared box): for random spheres and trial
    points anywhere (unwrapped), every sphere within the largest contact distance 2 by
    the brute-force Lees-Edwards minimum image is among them (at side 5.5 the cells
    collapse to one: all spheres)."""
    from sdmpi.dynamics.initial import _cell_counts, _cell_index, _cells, _min_image, _neighbours

    rng = np.random.default_rng(0)
    pos = rng.uniform(-side, 2 * side, (300, 3))
    cells = _cell_counts(side, strain, 2.0)
    assert (cells.min() >= 3) == (side > 6.0)
    head, nxt, _ = _cells(pos, side, strain, cells)
    near = np.empty(len(pos), dtype=np.int64)
    missed = 0
    for trial in rng.uniform(-side, 2 * side, (300, 3)):
        found = set(near[:_neighbours(_cell_index(trial, side, strain, cells), cells, head, nxt, near)])
        for j in range(len(pos)):
            dx = trial - pos[j]
            _min_image(dx, side, strain)
            missed += bool(dx @ dx < 4.0 and j not in found)
    assert missed == 0


@pytest.mark.parametrize("spread, strain", [(1.0, 0.0), (1.0, 0.4), (4.0, -0.3)])
def test_compression_closest_pair_matches_the_full_scan(spread, strain):
    """compress's closest contact ratio from the near pairs (cell list) is the full
    O(N^2) scan's number bit for bit; with no pair within 1.5 contacts (spread 4) it
    falls back to that scan."""
    from sdmpi.dynamics.initial import _closest_ratio, _contact_ratio

    rng = np.random.default_rng(4)
    n, side = 200, 30.0
    pos = rng.uniform(-side, 2 * side, (n, 3))
    radii = rng.uniform(0.5, 1.0, n) / spread
    assert _closest_ratio(pos, side, strain, radii) == _contact_ratio(pos, side, strain, radii)
