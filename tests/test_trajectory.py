"""H5MD trajectories in the run file (output.trajectory_every): the layout's required
groups and attributes, frames consistent with the sample stream, pyh5md reads them, and a
killed and resumed run (one or two ranks) ends with the uninterrupted run's frames."""

import h5py
import numpy as np
import pytest

from sdmpi.config import JobError, parse_job
from sdmpi.ensemble.trajectory import frames_done, n_frames
from sdmpi.hydro.basis import from_five
from sdmpi.hydro.geometry import Lattice
from .runs import JOB, MPIRUN, needs_mpi, sdmpi

EVERY = 5
TRAJ_JOB = JOB.replace("checkpoint_every = 10\n", "checkpoint_every = 10\ntrajectory_every = 5\n"
                       "trajectory_velocities = true\ntrajectory_stresslets = true\n")
N_STEPS, N_TASKS = 48, 8


def trajectory_data(path):
    """Every dataset under /h5md, /particles and /observables as bytes, with attributes."""
    out = {}
    with h5py.File(path, "r") as f:
        for top in ("h5md", "particles", "observables"):
            f[top].visititems(lambda name, obj: out.__setitem__(
                f"{top}/{name}", (obj[()].tobytes() if isinstance(obj, h5py.Dataset) else None,
                                  sorted((k, str(v)) for k, v in obj.attrs.items()))))
    return out


@pytest.fixture(scope="module")
def traj_job(tmp_path_factory):
    path = tmp_path_factory.mktemp("tjob") / "job.toml"
    path.write_text(TRAJ_JOB)
    return path


@pytest.fixture(scope="module")
def traj_ref(traj_job, tmp_path_factory):
    out = tmp_path_factory.mktemp("tref") / "ref.h5"
    res = sdmpi("run", traj_job, "-o", out)
    assert res.returncode == 0, res.stderr
    return out


def test_frame_counts():
    assert [n_frames(n, 5) for n in (1, 5, 6, 48, 50)] == [1, 1, 2, 10, 10]
    assert [frames_done(p, 5) for p in (0, 1, 5, 6, 10)] == [0, 1, 1, 2, 2]


def test_h5md_required_groups_and_attributes(traj_ref):
    with h5py.File(traj_ref, "r") as f:
        h5md = f["h5md"]
        assert list(h5md.attrs["version"]) == [1, 1]
        assert h5md["author"].attrs["name"] and h5md["creator"].attrs["name"] == "sdmpi"
        assert "version" in h5md["creator"].attrs
        assert sorted(f["particles"]) == [f"task_{t:06d}" for t in range(N_TASKS)]
        g = f["particles/task_000005"]
        box = g["box"]
        assert box.attrs["dimension"] == 3
        assert [b.decode() if isinstance(b, bytes) else b for b in box.attrs["boundary"]] \
            == ["periodic"] * 3
        frames = n_frames(N_STEPS, EVERY)
        for element, shape in [("position", (8, 3)), ("velocity", (8, 3)),
                               ("stresslet", (8, 3, 3)), ("box/edges", (3, 3))]:
            assert sorted(g[element]) == ["step", "time", "value"], element
            assert g[element]["value"].shape == (frames, *shape)
            assert g[element]["step"].dtype.kind == "i" and g[element]["time"].shape == (frames,)
        assert g["position/value"].attrs["unit"] == "a"
        assert g["velocity/value"].attrs["unit"] == "a/t_D"
        assert f["observables/task_000005/strain/value"].shape == (frames,)


def test_frames_match_the_sample_stream(traj_ref):
    with h5py.File(traj_ref, "r") as f:
        samples = f["tasks/000005/samples"]
        g = f["particles/task_000005"]
        steps = g["position/step"][()]
        assert list(steps) == list(range(0, N_STEPS, EVERY))
        np.testing.assert_array_equal(g["position/time"][()], samples["time"][()][steps])
        strain = samples["strain"][()][steps]
        np.testing.assert_array_equal(f["observables/task_000005/strain/value"][()], strain)
        box = f["tasks/000005"].attrs["box"]
        for edges, gamma in zip(g["box/edges/value"][()], strain):
            np.testing.assert_array_equal(edges, Lattice(box, gamma).vectors)
        np.testing.assert_array_equal(g["stresslet/value"][()],
                                      from_five(samples["stresslets"][()][steps]))


def test_every_step_velocities_are_the_displacements(traj_job, tmp_path):
    out = tmp_path / "every.h5"
    res = sdmpi("run", traj_job, "-o", out, "--set", "output.trajectory_every=1")
    assert res.returncode == 0, res.stderr
    with h5py.File(out, "r") as f:
        g = f["particles/task_000002"]
        x, v = g["position/value"][()], g["velocity/value"][()]
        dt = f["tasks/000002"].attrs["dt"]
        assert x.shape == (N_STEPS, 8, 3)
        # the double's walk is never wrapped: v_k dt = x_{k+1} - x_k up to round-off
        np.testing.assert_allclose(v[:-1] * dt, x[1:] - x[:-1], rtol=0, atol=1e-13)
        assert 0.05 < np.abs(v * dt).mean() < 0.2  # kicks of 0.1 standard normal per step


def test_pyh5md_reads_the_run_file(traj_ref):
    pyh5md = pytest.importorskip("pyh5md")
    with pyh5md.File(str(traj_ref), "r") as f:
        g = f.particles_group("task_000003")
        position = pyh5md.element(g, "position")
        assert position.element_type == "TimeElement"
        assert position.value.shape == (n_frames(N_STEPS, EVERY), 8, 3)
        assert list(position.step[()]) == list(range(0, N_STEPS, EVERY))
        edges = pyh5md.element(g, "box/edges")
        assert edges.value.shape == (n_frames(N_STEPS, EVERY), 3, 3)


@needs_mpi
@pytest.mark.mpi
@pytest.mark.parametrize("kill, ranks", [("commit:2", 2), ("samples:3", 1), ("step:23", 2)])
def test_killed_and_resumed_trajectory_equals_uninterrupted(traj_ref, traj_job, tmp_path,
                                                            kill, ranks):
    out = tmp_path / "killed.h5"
    res = sdmpi("run", traj_job, "-o", out, ranks=ranks, env={"SDMPI_TEST_KILL": kill})
    assert res.returncode != 0, res.stdout
    res = sdmpi("run", traj_job, "-o", out, ranks=2 if ranks == 1 else None)
    assert res.returncode == 0 and "resuming" in res.stdout, res.stderr
    assert trajectory_data(out) == trajectory_data(traj_ref)


def test_trajectory_extras_are_validated():
    with pytest.raises(JobError) as info:
        parse_job("[output]\ntrajectory_velocities = true\ntrajectory_stresslets = true\n")
    text = str(info.value)
    assert "output.trajectory_velocities = true: needs a trajectory" in text
    assert "output.trajectory_stresslets = true: needs the per-particle stresslets" in text
    assert "output.per_particle = true" in text


@pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")
def test_real_trajectory_starts_at_the_start_and_stays_in_the_cell(tmp_path):
    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation
    from .test_ensemble_real import ROOT, SHORT
    from .test_ensemble_real import sdmpi as real_sdmpi

    job_path = ROOT / "jobs" / "demo.toml"
    sets = [*SHORT, "--set", "ensemble.realisations=1", "--set", "output.trajectory_every=1",
            "--set", "output.trajectory_velocities=true"]
    out = tmp_path / "real.h5"
    res = real_sdmpi("run", job_path, "-o", out, *sets)
    assert res.returncode == 0, res.stderr
    job = load_job(job_path, [s for s in sets if s != "--set"])
    task = enumerate_tasks(job)[0]
    with h5py.File(out, "r") as f:
        g = f["particles/task_000000"]
        x, v = g["position/value"][()], g["velocity/value"][()]
        strain = f["observables/task_000000/strain/value"][()]
        box = f["tasks/000000"].attrs["box"]
    np.testing.assert_array_equal(x[0], Realisation(job, task).get_state()["positions"])
    for xk, gamma in zip(x, strain):  # wrapped into the Lees-Edwards cell of the frame
        np.testing.assert_allclose(Lattice(box, gamma).wrap(xk), xk, rtol=0, atol=1e-12)
    for k in range(len(x) - 1):
        moved = Lattice(box, strain[k + 1]).nearest_image(x[k + 1] - x[k])
        np.testing.assert_allclose(v[k] * task.dt, moved, rtol=0, atol=1e-12)


def test_the_reader_takes_only_committed_frames(traj_ref, traj_job, tmp_path):
    from sdmpi.analysis.trajectories import read

    out = tmp_path / "partial.h5"
    res = sdmpi("run", traj_job, "-o", out, env={"SDMPI_TEST_KILL": "commit:3"})
    assert res.returncode != 0
    with h5py.File(out, "r") as f:
        progress = f["progress"][()]
    assert 0 < progress.sum() < N_TASKS * N_STEPS
    for task, done in enumerate(progress):
        traj = read(out, f"task_{task:06d}")
        assert len(traj.positions) == frames_done(done, EVERY)
        full = read(traj_ref, f"task_{task:06d}")
        np.testing.assert_array_equal(traj.positions, full.positions[:len(traj.positions)])
        np.testing.assert_array_equal(traj.strain, full.strain[:len(traj.positions)])


def test_the_size_estimate_counts_the_frames(traj_ref, traj_job):
    from sdmpi.config import load_job
    from sdmpi.ensemble.store import run_file_bytes
    from sdmpi.ensemble.trajectory import file_bytes

    job = load_job(traj_job)
    plain = load_job(traj_job, ["output.trajectory_every=0", "output.trajectory_velocities=false",
                                "output.trajectory_stresslets=false"])
    # per task 10 frames of 8 positions, velocities (3 each) and stresslets (9 each),
    # a 3x3 cell, the strain and the shared step and time: 8 bytes each; and the headers
    assert file_bytes(job) == N_TASKS * (10 * 8 * (8 * (3 + 3 + 9) + 9 + 1 + 2) + 16384)
    assert run_file_bytes(job) - run_file_bytes(plain) == file_bytes(job)
    assert traj_ref.stat().st_size <= run_file_bytes(job)
