"""Sheared monolayers (seed 001; sdmpi.dynamics.monolayer): job keys, the 2D start, the
mirror symmetry that keeps motion in the plane, the seed's viscosity normalisation (dilute
limit), overlap counting and the overlap stop, the reducer's handling of a stopped
realisation, the job files, and one of them under mpirun -n 2."""

import csv
import logging
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sdmpi.analysis.reduce import reduce_runs
from sdmpi.config import JobError, enumerate_tasks, load_job, parse_job
from sdmpi.dynamics import Realisation
from sdmpi.dynamics.initial import hard_disk_monolayer, square_side
from sdmpi.dynamics.shear import rate_of_strain
from sdmpi.hydro.basis import to_five
from sdmpi.hydro.resistance import grand_resistance
from sdmpi.hydro.solvers import make_solver
from .synthetic_run import write_run
from .runs import child_env

ROOT = Path(__file__).resolve().parents[1]
MPIRUN = shutil.which("mpirun")


def monolayer_job(n=25, phi="[0.3]", extra=""):
    return (f'[system]\ngeometry = "monolayer"\nn_particles = {n}\nphi = {phi}\n'
            '[shear]\nprotocol = "steady"\n[brownian]\nenabled = false\n'
            f'[integration]\ndt = 0.002\nn_steps = 20\ndiscard_steps = 5\n{extra}'
            '[ensemble]\nrealisations = 1\n')


def problems(text):
    with pytest.raises(JobError) as err:
        parse_job(text)
    return str(err.value)


# ----------------------------------------------------------------------------- job keys


def test_monolayer_keys_defaults_and_bulk_unchanged():
    job = parse_job(monolayer_job())
    assert job.system.geometry == "monolayer" and job.system.layer_spacing == 2.0
    assert job.integration.overlap_stop == 0.02 and job.system.box is None
    bulk = parse_job("")
    assert bulk.system.geometry == "bulk" and bulk.system.box == "cubic"
    assert bulk.system.layer_spacing is None and bulk.integration.overlap_stop is None


@pytest.mark.parametrize("text, expected", [
    (monolayer_job().replace('"steady"', '"oscillatory"').replace(
        "dt = 0.002\nn_steps = 20\ndiscard_steps = 5\n", ""), ["shear.protocol", '"steady"']),
    (monolayer_job().replace("enabled = false", "enabled = true"),
     ["brownian.enabled = true", "non-Brownian steady shear"]),
    (monolayer_job(extra='[interparticle]\nkind = "vdw"\nhamaker = 1.0\ncap_gap = 0.01\n'),
     ["interparticle.kind", '"none" or "repulsion"']),
    (monolayer_job(phi="[0.5]", n=2), ["system.phi[0] = 0.5", "2 x 2", "0 < phi < 0.3926"]),
    (monolayer_job(n=1, phi="[0.6]").replace("[shear]", "layer_spacing = 1.0\n[shear]"),
     ["system.layer_spacing = 1.0", "lubrication cut-off", "layer_spacing >= 1.748"]),
    (monolayer_job().replace("[shear]", "layer_spacing = 0.5\n[shear]"),
     ["system.layer_spacing = 0.5", "1 <= layer_spacing <= 1000"]),
    (monolayer_job(extra="overlap_stop = 0.0\n"), ["integration.overlap_stop = 0.0", "0 < overlap_stop <= 1"]),
    (monolayer_job().replace("[shear]", 'box = "cubic"\n[shear]'),
     ["system.box", 'used only when system.geometry is "bulk"']),
    ("[integration]\noverlap_stop = 0.02\n", ["integration.overlap_stop", 'system.geometry is "monolayer"']),
    ('[system]\ngeometry = "flat"\n', ["system.geometry", '"bulk", "monolayer"']),
])
def test_bad_monolayer_keys_are_named_with_what_is_allowed(text, expected):
    message = problems(text)
    for part in expected:
        assert part in message, message


# ----------------------------------------------------------------------------- start, symmetry


def test_hard_disk_start_is_planar_and_non_overlapping():
    pos, side = hard_disk_monolayer(25, 0.6, np.random.default_rng(3), z=7.0)
    assert side == pytest.approx(math.sqrt(25 * math.pi / 0.6))
    assert np.all(pos[:, 2] == 7.0) and np.all((pos[:, :2] >= 0) & (pos[:, :2] < side))
    d = pos[:, None, :2] - pos[None, :, :2]
    d -= side * np.round(d / side)                       # minimum image, square cell
    r = np.linalg.norm(d, axis=-1) + 3 * np.eye(25)
    assert r.min() >= 2.0                                # hard disks of radius 1
    moved = np.abs(pos[:, :2] - np.round(pos[:, :2] / (side / 5) - 0.5) * (side / 5) - side / 10)
    assert moved.max() > 0.1                             # randomised, not the lattice
    with pytest.raises(ValueError, match="phi_a must be below"):
        hard_disk_monolayer(4, 0.8, np.random.default_rng(0))


def test_out_of_plane_motion_vanishes_by_mirror_symmetry():
    """U_z, Omega_x, Omega_y of the full FTS solution are zero for a planar configuration in
    in-plane shear with in-plane forces (reflection z -> Lz - z); 1e-12 of the in-plane
    velocities leaves room for round-off in the Ewald sums and the dense solve."""
    n, phi = 25, 0.5
    side = square_side(n, phi)
    box = np.array([side, side, 2 * side])
    pos, _ = hard_disk_monolayer(n, phi, np.random.default_rng(1), z=side, strain=0.37)
    res = grand_resistance(pos, np.ones(n), box, strain=0.37)
    solver = make_solver("dense", res, None)
    forces = np.zeros((n, 6))
    forces[0, :2], forces[1, :2] = (3.0, -1.0), (-3.0, 1.0)
    e5 = np.broadcast_to(to_five(rate_of_strain(1.0)), (n, 5))
    u = solver.velocities(forces, e5)
    scale = np.abs(u[:, [0, 1, 5]]).max()
    assert np.abs(u[:, [2, 3, 4]]).max() < 1e-12 * scale
    s = solver.stresslets(u, e5)                        # xz and yz stresslets vanish too
    assert np.abs(s[:, [3, 4]]).max() < 1e-12 * np.abs(s).max()


def test_monolayer_steps_stay_in_the_plane():
    job = parse_job(monolayer_job(phi="[0.5]"))
    real = Realisation(job, enumerate_tasks(job)[0])
    z0 = real.positions[0, 2]
    assert z0 == pytest.approx(0.5 * real.box[2]) and real.box[2] == 2 * real.box[0]
    real.advance(3)
    assert np.all(real.positions[:, 2] == z0)


# ----------------------------------------------------------------------------- viscosity


def dilute_eta(phi):
    """The hydrodynamic relative viscosity of one sphere per cell (one step)."""
    job = parse_job(monolayer_job(n=1, phi=f"[{phi}]"))
    real = Realisation(job, enumerate_tasks(job)[0])
    return real.advance(1)["stress_hydrodynamic"][0, 3]


def test_dilute_monolayer_viscosity_is_the_seed_normalisation_of_the_isolated_stresslet():
    """Seed eq. 6 (stress per layer volume 2 a L^2) with S_xy = (10/3) pi: eta - 1 =
    (5/3) phi_a for an isolated sphere. The periodic lattice's stresslet interactions
    decay like (a/L)^3, i.e. ~phi_a^(3/2): measured -2.1e-4 relative at phi_a = 0.005, and
    the correction must scale by 4^(3/2) = 8 from phi_a = 0.002 to 0.008 (within 10%)."""
    eta = {phi: dilute_eta(phi) for phi in (0.002, 0.005, 0.008)}
    assert eta[0.005] / (5 / 3 * 0.005) - 1 == pytest.approx(0.0, abs=1e-3)
    dev = {phi: eta[phi] / (5 / 3 * phi) - 1 for phi in (0.002, 0.008)}
    assert dev[0.008] / dev[0.002] == pytest.approx(8.0, rel=0.1)


# ----------------------------------------------------------------------------- overlaps


def four_spheres(overlap):
    """A monolayer realisation of 4 spheres, spheres 0 and 1 overlapping by ``overlap``."""
    job = parse_job(monolayer_job(n=4, phi="[0.2]"))
    real = Realisation(job, enumerate_tasks(job)[0])
    z, side = real.positions[0, 2], real.box[0]
    pos = np.array([[2.0, 2.0, z], [4.0 - overlap, 2.0, z], [2.0, 0.5 * side + 2, z],
                    [0.5 * side + 2, 0.5 * side + 2, z]])
    state = real.get_state()
    state["positions"] = pos
    real.set_state(state)
    return real


def test_overlaps_are_counted_and_kept_below_the_stop():
    real = four_spheres(0.01)
    sample = real.advance(1)
    assert sample["n_overlaps"][0] == 1 and sample["min_gap"][0] == pytest.approx(-0.01)
    assert np.isfinite(sample["stress_hydrodynamic"]).all()
    # not separated: the pair on the flow axis (y equal) moves with the flow, still overlapping
    gap = np.linalg.norm(real.positions[1] - real.positions[0]) - 2.0
    assert -0.011 < gap < -0.009 and real.geometry.stopped_at == -1


def test_an_overlap_past_the_threshold_stops_the_realisation(caplog):
    real = four_spheres(0.03)
    before = real.positions.copy()
    with caplog.at_level(logging.WARNING):
        sample = real.advance(2)
    assert "overlap by 0.03 a > integration.overlap_stop = 0.02" in caplog.text
    assert np.isnan(sample["stress_hydrodynamic"]).all() and np.all(sample["n_overlaps"] == -1)
    assert np.array_equal(sample["time"], [0.0, 0.002]) and real.step == 2
    assert np.array_equal(real.positions, before) and real.geometry.stopped_at == 0
    again = four_spheres(0.0)
    again.set_state(real.get_state())           # the stop is part of the state
    assert again.geometry.stopped_at == 0 and np.isnan(again.advance(1)["min_gap"][0])


def test_reduce_uses_a_stopped_realisation_up_to_its_stop(tmp_path):
    """Realisation 0 stops at step 60 (NaN from there); its mean is over steps 5..59."""
    text = monolayer_job(phi="[0.3]").replace("n_steps = 20", "n_steps = 100") \
        .replace("realisations = 1", "realisations = 2")
    hydro = np.where(np.arange(100) < 30, 1.0, 3.0)
    hydro[60:] = np.nan
    write_run(tmp_path / "run.h5", text, {"hydrodynamic": 2.0},
              tasks={0: {"stress_hydrodynamic": hydro}})
    red = reduce_runs([tmp_path / "run.h5"])
    per = red.per_realisation.mean[0, 1, 0]           # hydrodynamic eta per realisation
    assert per[0] == pytest.approx((25 * 1.0 + 30 * 3.0) / 55) and per[1] == pytest.approx(2.0)
    assert any("stopped on an overlap" in n and "step 60" in n and "55 samples" in n
               for n in red.notes), red.notes


# ----------------------------------------------------------------------------- mpirun


@pytest.mark.parametrize("name, kind", [("monolayer_hydro", "none"),
                                        ("monolayer_repulsion", "repulsion")])
def test_monolayer_job_files_are_the_seed_cases(name, kind):
    job = load_job(ROOT / "jobs" / f"{name}.toml")
    assert job.system.geometry == "monolayer" and job.system.n_particles == 25
    assert job.system.phi == (0.2, 0.3, 0.4, 0.5, 0.6) and job.interparticle.kind == kind
    assert job.integration.overlap_stop == 0.02


@pytest.mark.mpi
@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_monolayer_job_runs_under_mpirun_and_reduces(tmp_path):
    out = tmp_path / "run.h5"
    short = ["--set", "integration.n_steps=12", "--set", "integration.discard_steps=2",
             "--set", "system.phi=[0.4]"]
    cmd = [MPIRUN, "--oversubscribe", "-n", "2", sys.executable, "-m", "sdmpi.cli", "run",
           str(ROOT / "jobs" / "monolayer_repulsion.toml"), "-o", str(out), *short]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=300)
    assert res.returncode == 0, res.stderr
    res = subprocess.run([sys.executable, "-m", "sdmpi.cli", "reduce", str(out), "-o",
                          str(tmp_path / "red")], capture_output=True, text=True, env=child_env(),
                         timeout=300)
    assert res.returncode == 0, res.stderr
    rows = {r["component"]: r for r in csv.DictReader(open(tmp_path / "red" / "viscosity.csv"))}
    assert float(rows["total"]["phi"]) == 0.4 and rows["total"]["n_realisations"] == "2"
    # eta > 1 + (5/3) phi_a: a dense layer is more viscous than the dilute limit
    assert float(rows["total"]["eta"]) > 1 + 5 / 3 * 0.4
