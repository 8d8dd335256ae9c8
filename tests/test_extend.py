"""sdmpi run --extend: a run lengthened afterwards equals a run created at the longer
length (samples, checkpoints, trajectory frames, bit for bit, on one or two ranks); a kill
during the extension leaves the run file as it was; refusals write nothing."""

import h5py
import pytest

from .runs import JOB, digest, needs_mpi, sdmpi, task_data
from .test_trajectory import trajectory_data

SHORT_JOB = JOB.replace("periods = 3\n", "periods = 2\n").replace(
    "checkpoint_every = 10\n", "checkpoint_every = 10\ntrajectory_every = 5\n"
    "trajectory_velocities = true\n")
LONGER = ["--set", "integration.periods=3"]


def final_states(path):
    """The current checkpoint state of every task (the slot holding its /progress step;
    the other slot depends on where earlier runs stopped)."""
    out = {}
    with h5py.File(path, "r") as f:
        for task, done in enumerate(f["progress"][()]):
            ckpt = f[f"checkpoints/{task:06d}"]
            slot = list(ckpt["slot_step"][()]).index(done)
            out[task] = {k: v[()].tobytes() for k, v in ckpt[f"slot{slot}"].items()}
    return out


@pytest.fixture(scope="module")
def job_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("xjob") / "job.toml"
    path.write_text(SHORT_JOB)
    return path


@pytest.fixture(scope="module")
def longer(job_file, tmp_path_factory):
    """The run created at the longer length from the start."""
    out = tmp_path_factory.mktemp("long") / "long.h5"
    res = sdmpi("run", job_file, "-o", out, *LONGER)
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture
def short(job_file, tmp_path):
    out = tmp_path / "run.h5"
    res = sdmpi("run", job_file, "-o", out)
    assert res.returncode == 0, res.stderr
    return out


def same_run(a, b):
    assert task_data(a) == task_data(b)
    assert final_states(a) == final_states(b)
    assert trajectory_data(a) == trajectory_data(b)


@pytest.mark.parametrize("ranks", [None, pytest.param(2, marks=[needs_mpi, pytest.mark.mpi])])
def test_extended_run_equals_the_longer_run(job_file, short, longer, ranks):
    before = task_data(short)
    res = sdmpi("run", job_file, "-o", short, *LONGER, "--extend", ranks=ranks)
    assert res.returncode == 0, res.stderr
    assert "extended" in res.stdout and "resuming" in res.stdout
    same_run(short, longer)
    with h5py.File(short, "r") as f:  # what was committed is kept, bit for bit
        for name, data in before.items():
            if name.endswith("/time"):
                n = len(data) // 8
                assert f[f"tasks/{name}"][:n].tobytes() == data
        assert '"job_hash"' in f.attrs["extended"]
    info = sdmpi("info", short)
    assert "extended 1 time(s)" in info.stdout and "80 frames committed" in info.stdout
    assert "every committed sample and checkpoint verified" in info.stdout


def test_stopped_run_extends_and_resumes(job_file, longer, tmp_path):
    out = tmp_path / "part.h5"
    res = sdmpi("run", job_file, "-o", out, env={"SDMPI_TEST_KILL": "commit:3"})
    assert res.returncode != 0
    res = sdmpi("run", job_file, "-o", out, *LONGER, "--extend")
    assert res.returncode == 0, res.stderr
    same_run(out, longer)


@needs_mpi
@pytest.mark.mpi
def test_kill_during_extension_leaves_the_run_file_as_it_was(job_file, short, longer):
    before = digest(short)
    res = sdmpi("run", job_file, "-o", short, *LONGER, "--extend", ranks=2,
                env={"SDMPI_TEST_KILL": "extend:1"})
    assert res.returncode != 0
    assert digest(short) == before
    assert short.with_name(short.name + ".part").exists()
    res = sdmpi("run", job_file, "-o", short, *LONGER, "--extend", ranks=2)
    assert res.returncode == 0, res.stderr
    same_run(short, longer)
    assert not short.with_name(short.name + ".part").exists()


@pytest.mark.parametrize("sets, extend, message", [
    (["--set", "integration.periods=1", "--set", "integration.discard_periods=0"], True,
     "omega = 2: 16 steps per task, shorter than the run's 32"),
    (["--set", "integration.periods=3", "--set", "shear.gamma0=0.05"], True,
     "--extend allows only the length keys"),
    (LONGER, False, "add --extend to lengthen"),
])
def test_refusals_write_nothing(job_file, short, sets, extend, message):
    before = digest(short)
    res = sdmpi("run", job_file, "-o", short, *sets, *(["--extend"] if extend else []))
    assert res.returncode == 2, res.stdout
    assert message in res.stderr and "Traceback" not in res.stderr
    assert digest(short) == before


def test_extend_needs_an_existing_run(job_file, tmp_path):
    res = sdmpi("run", job_file, "-o", tmp_path / "none.h5", "--extend")
    assert res.returncode == 2 and "--extend lengthens an existing run" in res.stderr
    assert not (tmp_path / "none.h5").exists()
    res = sdmpi("run", job_file, "-o", tmp_path / "none.h5", "--extend", "--new")
    assert res.returncode == 2 and "not allowed with" in res.stderr


def test_a_damaged_run_is_not_extended(job_file, short):
    with h5py.File(short, "r+") as f:  # a committed sample changed behind the checksums
        f["tasks/000003/samples/stress_brownian"][5, 0] += 1.0
    before = digest(short)
    res = sdmpi("run", job_file, "-o", short, *LONGER, "--extend")
    assert res.returncode == 2 and "holds damaged data" in res.stderr, res.stderr
    assert "run it once without --extend" in res.stderr and digest(short) == before


def test_extension_needs_room_for_the_whole_longer_file(job_file, short, monkeypatch):
    import shutil

    from sdmpi.config import load_job
    from sdmpi.ensemble import runner, store

    job = load_job(job_file, ["integration.periods=3"])
    needed = store.run_file_bytes(job)
    free = needed - 1  # enough for the growth, not for the copy beside the run file
    assert free > needed - short.stat().st_size
    monkeypatch.setattr(shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(
        10 ** 9, 10 ** 9 - free, free))
    runner._check_resources(job, "dense", job_file, short, False, 1)  # a resume: nothing to create
    with pytest.raises(runner.BadInput, match="the run file needs about"):
        runner._check_resources(job, "dense", job_file, short, False, 1, extend=True)
