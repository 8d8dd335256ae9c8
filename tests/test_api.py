"""The Python API (docs/api.md): the same samples as `sdmpi run` bit for bit, its
accessors consistent with the samples, jobs from dicts, start files, and the example
script of docs/examples."""

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import h5py
import numpy as np
import pytest

import sdmpi
from .runs import child_env, fresh_lubrication_tables

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "jobs" / "demo.toml"
#: two tasks of 30 steps in a two-mode Maxwell medium with per-particle stresslets
RUN = ["system.n_particles=8", "shear.omega=[25.132741228718345]", "integration.periods=1",
       "integration.discard_periods=0", "integration.steps_per_period=30",
       'medium.kind="maxwell"', "medium.modes=[{eta = 0.6, lambda = 0.5}, {eta = 0.4, lambda = 0.05}]",
       "output.per_particle=true", "output.checkpoint_every=10"]


def test_same_samples_as_sdmpi_run(tmp_path):
    """Every sample dataset of both tasks of a run file equals the API's, bit for bit.
    One rank runs the (equal-cost) tasks in task-id order in one fresh process; the API
    steps them in that order from fresh lubrication tables, in uneven chunks."""
    out = tmp_path / "run.h5"
    cmd = [sys.executable, "-m", "sdmpi.cli", "run", str(DEMO), "-o", str(out)]
    for item in RUN:
        cmd += ["--set", item]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    job = sdmpi.load_job(DEMO, RUN)
    tasks = sdmpi.tasks(job)
    assert len(tasks) == 2
    fresh_lubrication_tables()
    with h5py.File(out, "r") as f:
        for task in tasks:
            r = sdmpi.Realisation(job, task)
            parts = [r.advance(7), r.advance(100)]
            assert r.step == task.n_steps == 30
            stored = f[f"tasks/{task.task_id:06d}/samples"]
            assert set(stored) == set(parts[0]) == set(r.fields)
            for name in stored:
                got = np.concatenate([p[name] for p in parts])
                assert got.dtype == stored[name].dtype and got.tobytes() == stored[name][()].tobytes(), name


def test_accessors_match_the_samples():
    """time, strain and rate are those of the next sample, positions those it starts from;
    samples by contribution are the datasets the reducer reads."""
    job = sdmpi.load_job(DEMO, RUN)
    r = sdmpi.Realisation(job, 1)
    assert r.task == sdmpi.tasks(job)[1] and r.job is job
    assert (r.time, r.step) == (0.0, 0)
    first = r.advance(3)
    assert set(first.stress) == {"hydrodynamic", "brownian", "interparticle", "collision"}
    assert first.stress["hydrodynamic"] is first["stress_hydrodynamic_maxwell"]
    assert first.stress["brownian"] is first["stress_brownian"]
    time, strain, rate, positions = r.time, r.strain, r.rate, r.positions
    nxt = r.advance(1)
    assert (nxt["time"][0], nxt["strain"][0], nxt["rate"][0]) == (time, strain, rate)
    assert time == 3 * r.dt and strain != 0.0
    assert positions.shape == (8, 3) and r.radii.shape == (8,) and r.box.shape == (3,)
    assert np.all((positions >= 0) & (positions < r.box))
    assert not np.array_equal(positions, r.positions)  # a copy of the state of its time
    rest = r.advance(1000)
    assert len(rest["time"]) == r.n_steps - 4 and len(r.advance(5)["time"]) == 0
    with pytest.raises(ValueError, match="n must be an integer >= 0"):
        r.advance(-1)


def test_newtonian_hydrodynamic_contribution():
    job = sdmpi.load_job(DEMO, ["system.n_particles=8"])
    samples = sdmpi.Realisation(job, 0).advance(1)
    assert samples.stress["hydrodynamic"] is samples["stress_hydrodynamic"]


def test_job_from_a_dict_is_the_job_from_its_file():
    raw = tomllib.loads(DEMO.read_text())
    kept = repr(raw)
    assert sdmpi.load_job(raw, RUN) == sdmpi.load_job(DEMO, RUN)
    assert repr(raw) == kept  # not modified
    with pytest.raises(sdmpi.config.JobError, match="system.n_particles"):
        sdmpi.load_job({"job": {"name": "x"}, "system": {"n_particles": 0}})


def test_start_file(tmp_path):
    """A job started from a file starts every realisation from the file's configuration
    (task 0 from the first, task 1 from the second), bit for bit."""
    job = sdmpi.load_job(DEMO, ["system.n_particles=8"])
    starts = [sdmpi.Realisation(job, task) for task in sdmpi.tasks(job)[2:4]]
    path = tmp_path / "start.h5"
    with h5py.File(path, "w") as f:
        f["positions"] = np.stack([r.positions for r in starts])
        f["box"] = starts[0].box
    filed = sdmpi.load_job(DEMO, ["system.n_particles=8", 'system.start="file"',
                                  f'system.start_file="{path}"'])
    for k in (0, 1):
        assert sdmpi.Realisation(filed, k).positions.tobytes() == starts[k].positions.tobytes()


def test_import_sdmpi_leaves_numpy_unloaded():
    """The command line sets one BLAS thread before numpy is imported: `import sdmpi`
    must not import it (the API is imported on first use)."""
    code = "import sys, sdmpi; assert 'numpy' not in sys.modules; sdmpi.tasks; assert 'numpy' in sys.modules"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert res.returncode == 0, res.stderr


def test_solve_mobility_is_public():
    """An isolated sphere (contract 1): U = F/(6 pi), Omega = T/(8 pi), S = (20/3) pi E."""
    e = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    u, w, s = sdmpi.hydro.solve_mobility(np.zeros((1, 3)), None, forces=[[1.0, 2.0, 3.0]],
                                         torques=[[0.0, 0.0, 1.0]], rate_of_strain=e)
    assert np.allclose(u, np.array([[1.0, 2.0, 3.0]]) / (6 * np.pi), rtol=1e-12, atol=0)
    assert np.allclose(w, [[0.0, 0.0, 1.0 / (8 * np.pi)]], rtol=1e-12, atol=1e-300)
    assert np.allclose(s[0], 20 / 3 * np.pi * e, rtol=1e-12, atol=1e-300)


def test_example_script_steps_and_plots(tmp_path):
    """docs/examples/step_and_plot.py runs as documented and writes its figure."""
    out = tmp_path / "stress.png"
    res = subprocess.run([sys.executable, str(ROOT / "docs" / "examples" / "step_and_plot.py"), str(out)],
                         capture_output=True, text=True, env=child_env(), cwd=tmp_path, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "100 steps to t = 1.000 t_D" in res.stdout
    assert out.read_bytes().startswith(b"\x89PNG") and out.stat().st_size > 10_000
