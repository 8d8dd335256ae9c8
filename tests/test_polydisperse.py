"""Polydisperse suspensions of discrete size classes (``system.size_classes``): job-file
validation, class counts, the hard-sphere initial configuration for unequal spheres, the
monodisperse generator unchanged bit for bit, a bidisperse Brownian realisation and its
checkpointable state, and a bidisperse job end to end under mpirun -n 2."""

import math
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from sdmpi.analysis.reduce import TABLE_COMPONENTS
from sdmpi.config import JobError, canonical_text, enumerate_tasks, load_job, parse_job
from sdmpi.config.schema import START_PHI_LIMIT
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.initial import box_side, compress, hard_sphere_fluid, min_gap_ratio

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "jobs" / "bidisperse_demo.toml"
REFERENCE = Path(__file__).parent / "data" / "initial_monodisperse_230e876.npz"
MPIRUN = shutil.which("mpirun")
BIDISPERSE = "[{radius = 1.0, fraction = 0.5}, {radius = 0.5, fraction = 0.5}]"


def _system(classes, n=27, phi="[0.1]"):
    return parse_job(f"[system]\nn_particles = {n}\nphi = {phi}\nsize_classes = {classes}\n")


# --------------------------------------------------------------------------- job keys


def test_monodisperse_default_unchanged():
    job = parse_job("")
    assert job.system.size_classes is None
    assert job.system.class_counts == (27,) and job.system.radii == (1.0,) * 27
    assert job.system.lattice_phi_limit == math.pi / 6
    assert "size_classes" not in canonical_text(job)  # old job hashes stay valid


def test_counts_radii_and_realised_fractions():
    system = _system(BIDISPERSE).system
    # number fractions (0.5/1) : (0.5/0.125) = 1 : 8 of 27
    assert system.class_counts == (3, 24)
    assert system.radii == (1.0,) * 3 + (0.5,) * 24
    assert system.realised_fractions == (0.5, 0.5)
    assert system.lattice_phi_limit == pytest.approx(math.pi / 6 * 6 / 27)
    # rounding by largest remainder: 64 x (0.2/1, 0.3/0.343, 0.5/0.125)/4.9746 ...
    system = _system("[{radius = 1.0, fraction = 0.2}, {radius = 0.7, fraction = 0.3}, "
                     "{radius = 0.5, fraction = 0.5}]", n=64, phi="[0.05]").system
    weights = np.array([0.2, 0.3 / 0.7 ** 3, 0.5 / 0.5 ** 3])
    exact = 64 * weights / weights.sum()
    assert sum(system.class_counts) == 64
    assert np.all(np.abs(np.array(system.class_counts) - exact) < 1)
    vols = np.array(system.class_counts) * np.array([1.0, 0.7, 0.5]) ** 3
    assert np.allclose(system.realised_fractions, vols / vols.sum())


def test_canonical_text_round_trip():
    job = _system(BIDISPERSE)
    assert "size_classes = [{radius = 1.0, fraction = 0.5}" in canonical_text(job)
    assert parse_job(canonical_text(job)) == job


@pytest.mark.parametrize("classes, n, phi, expected", [
    ("[{radius = 1.0, fraction = 0.5}, {radius = 0.5, fraction = 0.6}]", 27, "[0.1]",
     ["system.size_classes", "sum to 1.1", "sum is 1"]),
    ("[{radius = 0.8, fraction = 0.5}, {radius = 0.5, fraction = 0.5}]", 27, "[0.1]",
     ["largest radius is 0.8", "length unit a, so it is 1"]),
    ("[{radius = 1.0, fraction = 0.5}, {radius = 1.0, fraction = 0.5}]", 27, "[0.1]",
     ["system.size_classes[1].radius = 1.0", "appears twice"]),
    ("[{radius = 1.0, fraction = 0.5}, {radius = -0.5, fraction = 0.5}]", 27, "[0.1]",
     ["system.size_classes[1].radius = -0.5", "out of range", "0 < radius <= 1"]),
    ("[{radius = 1.0, fraction = 0.5}, {radius = 0.5, fraction = 0.0}]", 27, "[0.1]",
     ["system.size_classes[1].fraction = 0.0", "out of range", "0 < fraction <= 1"]),
    ("[{radius = 1.0, fraction = 1.0}, {radius = 0.5}]", 27, "[0.1]",
     ["system.size_classes[1].fraction", "is required"]),
    ("[{radius = 1.0, fraction = 1.0, size = 3}]", 27, "[0.1]",
     ["system.size_classes[0].size", "unknown key"]),
    ("[]", 27, "[0.1]", ["system.size_classes", "must not be empty"]),
    ("[{radius = 1.0, fraction = 0.999}, {radius = 0.5, fraction = 0.001}]", 8, "[0.1]",
     ["system.size_classes[1]", "gets no sphere among N = 8"]),
    (BIDISPERSE, 27, "[0.05, 0.62]",
     ["system.phi[1] = 0.62", "compressed hard-sphere fluid", "0 < phi < 0.6"]),
])
def test_validation_errors(classes, n, phi, expected):
    with pytest.raises(JobError) as err:
        _system(classes, n, phi)
    text = str(err.value)
    for part in expected:
        assert part in text, text


def test_time_step_below_the_small_spheres_diffusion_time():
    text = f"[system]\nsize_classes = {BIDISPERSE}\nphi = 0.1\n"
    with pytest.raises(JobError, match=r"integration.dt = 0.2: must be smaller than the "
                       r"diffusion time .* 0.125 of the smallest spheres"):
        parse_job(text + '[shear]\nprotocol = "none"\n[integration]\ndt = 0.2\n')
    parse_job(text + '[shear]\nprotocol = "none"\n[integration]\ndt = 0.1\n')


def test_size_classes_by_override():
    job = load_job(ROOT / "jobs" / "demo.toml",
                   overrides=[f"system.size_classes={BIDISPERSE}", "system.n_particles=27",
                              "system.phi=0.1"])
    assert job.system.class_counts == (3, 24)


# --------------------------------------------------------------------------- configurations


@pytest.mark.parametrize("strain", [0.0, 0.37, -1.2])
def test_bidisperse_configuration(strain):
    system = _system(BIDISPERSE, n=64, phi="[0.11]").system
    radii = np.array(system.radii)
    pos, side = hard_sphere_fluid(64, 0.11, np.random.default_rng(5), radii=radii, strain=strain)
    assert min_gap_ratio(pos, side, radii, strain) >= 1.0          # no overlaps
    phi = 4.0 / 3.0 * math.pi * np.sum(radii ** 3) / side ** 3
    assert phi == pytest.approx(0.11, rel=1e-12)                     # the stated phi
    assert side == box_side(radii, 0.11)
    counts = [int(np.sum(radii == r)) for r in system.class_radii]
    assert tuple(counts) == system.class_counts
    # the large spheres are spread over the box, not left on one corner of the lattice
    big = pos[radii == 1.0] % side
    assert np.ptp(big, axis=0).max() > side / 3


def test_bidisperse_compression_has_no_overlaps():
    radii = np.array(_system(BIDISPERSE).system.radii)
    rng = np.random.default_rng(3)
    pos, side = hard_sphere_fluid(27, 0.1, rng, radii=radii, sweeps=50)
    pos, side = compress(pos, side, 0.3, rng, radii=radii)
    assert min_gap_ratio(pos, side, radii) >= 1.0
    assert side == pytest.approx(box_side(radii, 0.3), rel=1e-12)


def test_start_limit_enforced_by_generator():
    # above the lattice limit the start is compressed (tests/test_polydisperse_start.py),
    # up to START_PHI_LIMIT
    radii = np.array([1.0] + [0.5] * 7)
    with pytest.raises(ValueError, match="compressed"):
        hard_sphere_fluid(8, START_PHI_LIMIT, np.random.default_rng(0), radii=radii)


def test_monodisperse_positions_bit_for_bit():
    """The reference file holds configurations from sdmpi before size classes (commit
    230e876): the same seeds give the same positions, with and without radii = ones."""
    ref = np.load(REFERENCE)
    for k, (n, phi, seed, strain, sweeps) in enumerate(ref["cases"]):
        n = int(n)
        for radii in (None, np.ones(n)):
            pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(int(seed)),
                                          sweeps=int(sweeps), strain=strain, radii=radii)
            assert np.array_equal(pos, ref[f"case{k}_positions"]), k
            assert side == ref[f"case{k}_side"]
    rng = np.random.default_rng(11)
    pos, side = hard_sphere_fluid(27, 0.4, rng, sweeps=50)
    pos, side = compress(pos, side, 0.5, rng)
    assert np.array_equal(pos, ref["compress_positions"]) and side == ref["compress_side"]
    # the reference realisations were made with 200 sweeps (the default of that commit)
    job = load_job(ROOT / "jobs" / "demo.toml", ["system.start_sweeps=200"])
    for task in enumerate_tasks(job)[:2]:
        r = Realisation(job, task)
        assert np.array_equal(r.positions, ref[f"realisation{task.task_id}_positions"])
        assert np.array_equal(r.box, ref[f"realisation{task.task_id}_box"])
        assert np.array_equal(r.radii, np.ones(job.system.n_particles))


# --------------------------------------------------------------------------- dynamics


def test_bidisperse_realisation_steps_and_round_trips():
    job = load_job(JOB)
    task = enumerate_tasks(job)[0]
    a = Realisation(job, task)
    assert np.array_equal(a.radii, np.array(job.system.radii))
    assert min_gap_ratio(a.positions, a.box[0], a.radii, a.protocol.strain(0.0)) >= 1.0
    first = a.advance(3)
    assert np.all(np.isfinite(first["stress_hydrodynamic"]))
    assert np.all(np.isfinite(first["stress_brownian"]))
    state = a.get_state()
    b = Realisation(job, task)
    b.set_state(state)
    out_a, out_b = a.advance(3), b.advance(3)
    for name in out_a:
        assert out_a[name].tobytes() == out_b[name].tobytes(), name
    for name, value in a.get_state().items():
        assert np.asarray(value).tobytes() == np.asarray(b.get_state()[name]).tobytes(), name


@pytest.mark.mpi
@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_bidisperse_job_two_ranks_run_and_reduce(tmp_path):
    from .runs import child_env

    run, out = tmp_path / "bidisperse.h5", tmp_path / "reduced"
    short = ["--set", "integration.steps_per_period=40", "--set", "integration.periods=2",
             "--set", "output.checkpoint_every=30"]
    cmd = [MPIRUN, "--oversubscribe", "-n", "2", sys.executable, "-m", "sdmpi.cli", "run",
           str(JOB), "-o", str(run), *short]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=300)
    assert res.returncode == 0, res.stderr
    job = load_job(JOB, overrides=short[1::2])
    with h5py.File(run, "r") as f:
        for task in enumerate_tasks(job):
            group = f[f"tasks/{task.task_id:06d}"]
            assert np.array_equal(group["radii"][()], np.array(job.system.radii))
            assert group["radii"].attrs["unit"] == "a"
            volume = 4 / 3 * math.pi * np.sum(group["radii"][()] ** 3)
            assert volume / np.prod(group.attrs["box"]) == pytest.approx(0.1, rel=1e-12)
    res = subprocess.run([sys.executable, "-m", "sdmpi.cli", "reduce", str(run), "-o", str(out)],
                         capture_output=True, text=True, env=child_env(), timeout=300)
    assert res.returncode == 0, res.stderr
    lines = (out / "moduli.csv").read_text().splitlines()
    assert lines[0].startswith("phi,omega,component") and len(lines) == 1 + len(TABLE_COMPONENTS)


def test_validate_summary_lists_size_classes():
    from sdmpi.cli import main
    import contextlib
    import io
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["validate", "jobs/bidisperse_demo.toml"]) == 0
    assert "size classes: 3 x radius 1" in out.getvalue()
