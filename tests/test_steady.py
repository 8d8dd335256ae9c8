"""Steady shear through the store and the reducer (issue 7, part 1): viscosity.csv with
the relative viscosity split, N1, N2, Pi and 95% confidence intervals, running-average
figures. Synthetic run files (tests/synthetic_run.py) with known stresses plus AR(1)
noise; one short real job end to end under mpirun -n 2."""

import csv
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.stats import t as student_t

from sdmpi.analysis.errors import SOURCES
from sdmpi.analysis.reduce import (TABLE_COMPONENTS, STEADY_QUANTITIES, VISCOSITY_COLUMNS,
                                   confidence_half_width, reduce_runs, steady_quantities)
from sdmpi.analysis.report import format_table, write_all
from sdmpi.config import enumerate_tasks, load_job, parse_job
from .synthetic_run import ar1, write_run

ROOT = Path(__file__).parents[1]
RATE = 2.0

JOB = f"""
[job]
name = "steady-synthetic"
seed = 3
[system]
n_particles = 8
phi = [0.3]
[shear]
protocol = "steady"
rate = {RATE}
[brownian]
enabled = true
[integration]
dt = 0.001
n_steps = 600
discard_steps = 100
[ensemble]
realisations = 5
"""

#: particle stress 6-vectors (xx yy zz xy xz yz) per contribution, in eta_m/t_D
STRESS = {"hydrodynamic": np.array([-0.3, 0.5, 0.1, 1.5 * RATE, 0.0, 0.0]),
          "brownian": np.array([0.4, -0.1, 0.2, 0.4 * RATE, 0.0, 0.0]),
          "interparticle": np.array([1.0, 1.6, 0.7, 0.2 * RATE, 0.0, 0.0])}


def expected(vec):
    """eta, N1, N2, Pi of a stress 6-vector, in eta_m gamma_dot (hand-written)."""
    xx, yy, zz, xy = vec[:4]
    return np.array([xy, xx - yy, yy - zz, -(xx + yy + zz) / 3]) / RATE


def write_known(path, noise=0.05, seed=0):
    """A synthetic steady run whose stored 6-vectors are STRESS + AR(1) noise."""
    write_run(path, JOB, {}, seed=seed)
    rng = np.random.default_rng(seed + 100)
    with h5py.File(path, "r+") as f:
        for key in f["tasks"]:
            s = f[f"tasks/{key}/samples"]
            for comp, vec in STRESS.items():
                n = s["stress_" + comp].shape[0]
                data = vec + noise * np.stack([ar1(rng, n, 5.0) for _ in range(6)], axis=1)
                s["stress_" + comp][...] = data


def rows_of(path):
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return reader.fieldnames, list(reader)


def test_steady_quantities_sign_conventions():
    vec = np.array([1.0, 2.0, 4.0, 3.0, 9.0, 9.0])
    q = steady_quantities(vec[None, :], rate=0.5)[:, 0]
    assert np.allclose(q, [6.0, -2.0, -4.0, -14.0 / 3.0])   # eta, N1, N2, Pi


def test_confidence_half_width_is_student_t():
    assert confidence_half_width(0.1, 4) == pytest.approx(0.1 * 2.7764451, rel=1e-6)
    assert confidence_half_width(0.0, 4) == 0.0
    assert math.isnan(confidence_half_width(0.1, 0))


def test_viscosity_csv_split_normal_stresses_pressure_and_ci(tmp_path):
    run = tmp_path / "run.h5"
    write_known(run)
    red = reduce_runs([run])
    paths, notes = write_all(red, tmp_path / "out")
    header, rows = rows_of(tmp_path / "out" / "viscosity.csv")
    assert tuple(header) == VISCOSITY_COLUMNS
    assert header[:6] == ["phi", "rate", "component", "n_realisations", "eta", "eta_err"]
    by = {r["component"]: r for r in rows}
    medium = by["medium"]
    assert [float(medium[q]) for q in STEADY_QUANTITIES] == [1.0, 0.0, 0.0, 0.0]
    assert float(medium["eta_ci95"]) == 0.0
    total = np.array([1.0, 0, 0, 0]) + sum(expected(v) for v in STRESS.values())
    q975 = student_t.ppf(0.975, 4)
    bound = student_t.ppf(1 - 0.5e-4, 4)
    e = red.ensemble
    for comp, want in [(c, expected(v)) for c, v in STRESS.items()] + [("total", total)]:
        r = by[comp]
        c = TABLE_COMPONENTS.index(comp)
        assert int(r["n_realisations"]) == 5
        assert int(r["dof"]) == (4 if e.source[0, c, 0] == SOURCES.index("between")
                                 else e.dof_within[0, c, 0])
        for k, (q, w) in enumerate(zip(STEADY_QUANTITIES, want)):
            m, err, ci = float(r[q]), float(r[f"{q}_err"]), float(r[f"{q}_ci95"])
            # the wider of the between (t_4) and within (t_dof_within) intervals
            within = student_t.ppf(0.975, e.dof_within[0, c, k]) * e.err_within[0, c, k]
            between = q975 * e.err_between[0, c, k]
            assert ci == pytest.approx(max(between, within), rel=1e-12)
            assert ci >= between and err >= e.err_between[0, c, k]
            assert abs(m - w) < bound * err, (comp, q, m, w, err)
    # the total is the sum of the parts, value by value
    for q in STEADY_QUANTITIES:
        parts = sum(float(by[c][q]) for c in TABLE_COMPONENTS[:-1])
        assert float(by["total"][q]) == pytest.approx(parts, abs=1e-12)
    # running averages end at the mean over all samples (start-up included)
    run_vals = red.running["values"]
    assert run_vals.shape[:4] == (1, len(TABLE_COMPONENTS), 4, 5)
    assert np.all(np.isfinite(run_vals))
    assert "95% confidence interval" in format_table(red)
    png = tmp_path / "out" / "running_phi0.3.png"
    assert png in paths and png.read_bytes()[:4] == b"\x89PNG"
    with h5py.File(tmp_path / "out" / "viscosity.h5") as f:
        assert f["running/values"].shape == run_vals.shape
        assert f.attrs["quantities"] == "eta N1 N2 Pi"


def test_running_average_matches_direct_mean(tmp_path):
    run = tmp_path / "run.h5"
    write_known(run, noise=0.2, seed=5)
    red = reduce_runs([run])
    job = parse_job(JOB)
    task = enumerate_tasks(job)[2]
    with h5py.File(run) as f:
        xy = f[f"tasks/{task.task_id:06d}/samples/stress_hydrodynamic"][:, 3]
    k = -1
    idx = int(round(red.running["time"][k] / job.integration.dt))
    assert red.running["values"][0, 1, 0, 2, k] == pytest.approx(xy[:idx + 1].mean() / RATE)


def test_partial_steady_run_pads_running_averages_with_nan(tmp_path):
    run = tmp_path / "run.h5"
    job = parse_job(JOB)
    write_run(run, JOB, {"hydrodynamic": 1.0}, noise=0.05, progress={0: 300})
    with pytest.warns(UserWarning):
        red = reduce_runs([run])
    vals = red.running["values"][0, 1, 0]
    t = red.running["time"]
    assert np.all(np.isnan(vals[0, t >= 300 * job.integration.dt]))
    assert np.all(np.isfinite(vals[1]))


@pytest.mark.parametrize("name", ["steady_brownian.toml", "steady_repulsion.toml"])
def test_steady_job_files_validate(name):
    job = load_job(ROOT / "jobs" / name)
    assert job.shear.protocol == "steady"


def test_steady_job_end_to_end_under_mpirun(tmp_path):
    """jobs/steady_repulsion.toml, shortened, on 2 ranks, then sdmpi reduce."""
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        pytest.skip("no mpirun")
    exe = Path(sys.executable).parent / "sdmpi"
    run = tmp_path / "steady.h5"
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    sets = ["--set", "integration.n_steps=60", "--set", "integration.discard_steps=20",
            "--set", "ensemble.realisations=2", "--set", "output.checkpoint_every=30"]
    subprocess.run([mpirun, "-n", "2", str(exe), "run", str(ROOT / "jobs" / "steady_repulsion.toml"),
                    "-o", str(run), *sets], check=True, env=env, timeout=300,
                   capture_output=True)
    out = tmp_path / "out"
    res = subprocess.run([str(exe), "reduce", str(run), "-o", str(out)], env=env,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    header, rows = rows_of(out / "viscosity.csv")
    by = {r["component"]: r for r in rows}
    assert float(by["medium"]["eta"]) == 1.0
    eta_h = float(by["hydrodynamic"]["eta"])
    assert 0.3 < eta_h < 3.0                  # phi = 0.3: eta_H ~ 1 (seed 000 eq. 38: 1.04)
    assert float(by["interparticle"]["eta"]) != 0.0
    assert float(by["total"]["eta"]) == pytest.approx(
        sum(float(by[c]["eta"]) for c in ("medium", "hydrodynamic", "brownian", "interparticle")))
    assert (out / "running_phi0.3.png").exists()
