"""Any number of particles: the hard-sphere start (sdmpi.dynamics.initial.hard_sphere_fluid)
puts N spheres on N of the m^3 >= N sites of a simple cubic lattice, m = ceil(N^(1/3)),
then equilibrates them by Monte Carlo (compressing above the lattice limit); N = m^3 keeps
the start it had when N had to be a cube, bit for bit."""

import math
from pathlib import Path

import numpy as np
import pytest

from sdmpi.config import enumerate_tasks, load_job, parse_job
from sdmpi.config.schema import lattice_sites_per_axis
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.initial import Jammed, box_side, hard_sphere_fluid, min_gap_ratio

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = Path(__file__).parent / "data" / "initial_bidisperse_4f19575.npz"
BIDISPERSE = "[{radius = 1.0, fraction = 0.5}, {radius = 0.5, fraction = 0.5}]"


def _radii(n, classes=None):
    text = f"[system]\nn_particles = {n}\n" + (f"size_classes = {classes}\n" if classes else "")
    return np.array(parse_job(text).system.radii)


@pytest.mark.parametrize("n, m", [(1, 1), (2, 2), (8, 2), (9, 3), (27, 3), (28, 4), (100, 5),
                                  (1000, 10), (1001, 11), (10 ** 6, 100), (10 ** 6 + 1, 101)])
def test_lattice_sites_per_axis(n, m):
    assert lattice_sites_per_axis(n) == m
    assert m ** 3 >= n > (m - 1) ** 3


def test_lattice_limit_counts_the_empty_sites():
    # the spacing L/m of m^3 sites must exceed the diameter: phi < (pi/6) N / m^3
    assert parse_job("[system]\nn_particles = 27\n").system.lattice_phi_limit == math.pi / 6
    system = parse_job("[system]\nn_particles = 30\n").system
    assert system.lattice_phi_limit == pytest.approx(math.pi / 6 * 30 / 64, rel=1e-15)


@pytest.mark.parametrize("n, phi, strain, classes", [
    (30, 0.3, 0.0, None),          # lattice limit 0.245: compressed
    (100, 0.2, 0.37, None),        # below the limit 0.419: lattice start + MC
    (100, 0.55, -1.2, None),       # above it: compressed
    (10, 0.45, 0.0, None),
    (50, 0.45, 0.3, BIDISPERSE),
])
def test_non_cube_start(n, phi, strain, classes):
    radii = _radii(n, classes)
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(7), strain=strain, radii=radii,
                                  sweeps=60)
    assert pos.shape == (n, 3)
    assert min_gap_ratio(pos, side, radii, strain) >= 1.0              # no overlaps
    assert side == pytest.approx(box_side(radii, phi), rel=1e-12)       # the stated phi
    assert 4 / 3 * math.pi * np.sum(radii ** 3) / side ** 3 == pytest.approx(phi, rel=1e-12)
    # a pure function of the random stream
    again, side_again = hard_sphere_fluid(n, phi, np.random.default_rng(7), strain=strain,
                                          radii=radii, sweeps=60)
    assert np.array_equal(pos, again) and side == side_again
    other, _ = hard_sphere_fluid(n, phi, np.random.default_rng(8), strain=strain, radii=radii,
                                 sweeps=60)
    assert not np.array_equal(pos, other)


def test_non_cube_start_leaves_the_lattice():
    """Below the lattice limit the spheres start on randomly drawn sites and MC moves
    them: the mean distance from the nearest lattice site is a fair share of the free
    space between neighbours (a gap of L/m - 2 per axis)."""
    n, phi = 100, 0.1
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(3))
    spacing = side / lattice_sites_per_axis(n)
    offset = (pos % spacing) - spacing / 2
    assert np.mean(np.linalg.norm(offset, axis=1)) > 0.2 * (spacing - 2.0)


def test_cube_starts_bit_for_bit():
    """Bidisperse starts of cube N as made when N had to be a cube (reference file);
    monodisperse ones: tests/test_polydisperse.py::test_monodisperse_positions_bit_for_bit."""
    ref = np.load(REFERENCE)
    for k, (n, phi, seed, strain) in enumerate(ref["cases"]):
        n = int(n)
        radii = _radii(n, BIDISPERSE)
        assert np.array_equal(radii, ref[f"case{k}_radii"])
        pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(int(seed)), strain=strain,
                                      radii=radii, sweeps=50)
        assert np.array_equal(pos, ref[f"case{k}_positions"]), k
        assert side == ref[f"case{k}_side"]


def test_small_box_that_jams_says_so():
    with pytest.raises(Jammed, match=r"5 times from a lattice of N = 5 spheres; small boxes "
                       r"jam: use more particles or a smaller phi"):
        hard_sphere_fluid(5, 0.59, np.random.default_rng(0), sweeps=20)


def test_non_cube_job_validates_and_steps():
    job = load_job(ROOT / "jobs" / "demo.toml", ["system.n_particles=10", "system.phi=[0.45]"])
    task = enumerate_tasks(job)[0]
    a, b = Realisation(job, task), Realisation(job, task)
    assert a.positions.shape == (10, 3) and np.array_equal(a.positions, b.positions)
    assert min_gap_ratio(a.positions, a.box[0], a.radii, a.protocol.strain(0.0)) >= 1.0
    out = a.advance(3)
    assert np.all(np.isfinite(out["stress_hydrodynamic"]))
    assert np.all(np.isfinite(out["stress_brownian"]))
