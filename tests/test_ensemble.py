"""The ensemble runner end to end, with the cheap test double as the realisation.

Every run is a subprocess (``tests/ensemble_run.py`` = ``sdmpi`` with the double), one
rank without mpirun or two under ``mpirun -n 2``; data are compared bit for bit with a
one-rank run that was never interrupted.
"""

import fcntl
import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from sdmpi.config import load_job, parse_job

HERE = Path(__file__).resolve().parent
DRIVER = HERE / "ensemble_run.py"
MPIRUN = shutil.which("mpirun")
needs_mpi = pytest.mark.skipif(MPIRUN is None, reason="mpirun not found")

JOB = """\
[job]
name = "ensemble-test"
seed = 7

[system]
n_particles = 8
phi = [0.2, 0.3]

[medium]
kind = "maxwell"
modes = [{eta = 0.6, lambda = 0.5}, {eta = 0.4, lambda = 2.0}]

[shear]
omega = [2.0, 8.0]

[integration]
steps_per_period = 16
periods = 3
discard_periods = 1

[ensemble]
realisations = 2

[output]
per_particle = true
checkpoint_every = 10
"""
N_TASKS, N_STEPS = 8, 48


def sdmpi(*args, ranks=None, env=None, timeout=120):
    """Run ``sdmpi ARGS`` with the double: plain (one rank) or under mpirun -n RANKS."""
    cmd = [sys.executable, str(DRIVER), *map(str, args)]
    if ranks:
        cmd = [MPIRUN, "--oversubscribe", "-n", str(ranks), *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, env=_env(env), timeout=timeout)


def _env(extra=None):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SDMPI_", "OMPI_COMM"))}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    env.update(extra or {})
    return env


def task_data(path):
    """Every dataset under /tasks, and /progress, as bytes."""
    out = {}
    with h5py.File(path, "r") as f:
        f["tasks"].visititems(
            lambda name, obj: out.__setitem__(name, obj[()].tobytes())
            if isinstance(obj, h5py.Dataset) else None)
        out["progress"] = f["progress"][()].tobytes()
    return out


def digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def logs(path):
    return Path(str(path) + ".logs")


@pytest.fixture(scope="module")
def job_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("job") / "job.toml"
    path.write_text(JOB)
    return path


@pytest.fixture(scope="module")
def reference(job_file, tmp_path_factory):
    """An uninterrupted one-rank run."""
    out = tmp_path_factory.mktemp("ref") / "ref.h5"
    res = sdmpi("run", job_file, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "complete (8 tasks)" in res.stdout
    return out


def test_reference_layout(reference, job_file):
    with h5py.File(reference, "r") as f:
        assert f.attrs["format"] == "sdmpi-run" and f.attrs["format_version"] == 1
        assert parse_job(f.attrs["job_text"]) == load_job(job_file)
        assert list(f["progress"][()]) == [N_STEPS] * N_TASKS
        samples = f["tasks/000005/samples"]
        assert samples["stresslets"].shape == (N_STEPS, 8, 5)
        assert samples["stress_hydrodynamic_maxwell"].shape == (N_STEPS, 6)
        assert samples["time"].attrs["unit"] == "t_D"
        assert f["tasks/000005"].attrs["realisation"] == 1
        assert sorted(f["checkpoints/000005"]) == ["sample_crc", "slot0", "slot1", "slot_step",
                                                   "state_crc"]
    assert (logs(reference) / "rank-0.log").read_text().count("complete") == N_TASKS


@needs_mpi
@pytest.mark.mpi
def test_two_ranks_bit_identical(reference, job_file, tmp_path):
    out = tmp_path / "two.h5"
    res = sdmpi("run", job_file, "-o", out, ranks=2)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(reference)
    assert {p.name for p in logs(out).glob("rank-*.log")} == {"rank-0.log", "rank-1.log"}


# (SDMPI_TEST_KILL, ranks) of each killed run, then the ranks and --set of the resume
KILLS = [
    ([("step:25", 1)], 2, []),
    ([("samples:3", 2)], 1, []),
    ([("state:4", 1)], 1, ["output.checkpoint_every=7"]),
    ([("commit:5", 2)], 2, []),
    ([("commit:2", 1), ("samples:2", 2), ("state:3", 1)], 2, []),
]


@needs_mpi
@pytest.mark.mpi
@pytest.mark.parametrize("kills, ranks, overrides", KILLS,
                         ids=["step", "samples", "state", "commit", "three-kills"])
def test_sigkill_then_resume_bit_identical(reference, job_file, tmp_path, kills, ranks,
                                           overrides):
    out = tmp_path / "killed.h5"
    for spec, kill_ranks in kills:
        res = sdmpi("run", job_file, "-o", out, ranks=kill_ranks,
                    env={"SDMPI_TEST_KILL": spec})
        assert res.returncode != 0, f"{spec}: not killed\n{res.stdout}"
        info = sdmpi("info", out)
        assert info.returncode == 0, info.stderr  # intact after the kill
        assert "resumable" in info.stdout
    sets = [a for o in overrides for a in ("--set", o)]
    res = sdmpi("run", job_file, "-o", out, *sets, ranks=ranks)
    assert res.returncode == 0, res.stderr
    assert "resuming" in res.stdout
    assert task_data(out) == task_data(reference)
    assert current_checksums(out) == current_checksums(reference)


def current_checksums(path):
    """Per task, the sample and state checksums of the current checkpoint slot; asserts
    that the file verifies."""
    from sdmpi.ensemble.store import inspect

    summary = inspect(path)
    assert summary.checksummed and summary.damage == ()
    with h5py.File(path, "r") as f:
        return {t.task_id: (f[f"checkpoints/{t.task_id:06d}/sample_crc"][s].tobytes(),
                            f[f"checkpoints/{t.task_id:06d}/state_crc"][s].tobytes())
                for t, s in zip(summary.tasks, summary.slots)}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_checkpoints_and_resumes(reference, job_file, tmp_path, sig):
    out = tmp_path / "stopped.h5"
    _stop_midway(sig, [sys.executable, str(DRIVER), "run", job_file, "-o", out], out)
    info = sdmpi("info", out)
    assert info.returncode == 0 and "resumable" in info.stdout
    with h5py.File(out, "r") as f:
        assert 0 < f["progress"][()].sum() < N_TASKS * N_STEPS
    res = sdmpi("run", job_file, "-o", out, ranks=2 if MPIRUN else None)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(reference)


@needs_mpi
@pytest.mark.mpi
def test_sigusr1_to_mpirun_stops_cleanly(reference, job_file, tmp_path):
    out = tmp_path / "stopped.h5"
    cmd = [MPIRUN, "--oversubscribe", "-n", "2", sys.executable, str(DRIVER), "run",
           job_file, "-o", out]
    _stop_midway(signal.SIGUSR1, cmd, out)
    res = sdmpi("run", job_file, "-o", out)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(reference)


def _stop_midway(sig, cmd, out):
    """Start a slowed-down run, signal it once it is stepping, expect exit 3."""
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env=_env({"SDMPI_DOUBLE_SLEEP": "0.01"}))
    deadline = time.monotonic() + 30
    while not out.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 3, stderr
    assert f"stopped by {signal.Signals(sig).name}" in stdout


# --------------------------------------------------------------------------- bad input

BAD_JOBS = {
    "unknown key": JOB.replace("n_particles", "n_particle"),
    "wrong type": JOB.replace("n_particles = 8", 'n_particles = "eight"'),
    "out of range": JOB.replace("phi = [0.2, 0.3]", "phi = [0.2, 0.9]"),
    "bad TOML": JOB.replace("[system]", "[system"),
}


@pytest.mark.parametrize("name", BAD_JOBS)
def test_bad_job_file(tmp_path, name):
    job = tmp_path / "bad.toml"
    job.write_text(BAD_JOBS[name])
    out = tmp_path / "run.h5"
    res = sdmpi("run", job, "-o", out)
    assert res.returncode == 2
    assert "problem" in res.stderr
    assert sorted(os.listdir(tmp_path)) == ["bad.toml"]  # nothing written


def test_bad_override(job_file, tmp_path):
    res = sdmpi("run", job_file, "-o", tmp_path / "run.h5", "--set", "system.phi=2.0")
    assert res.returncode == 2 and "system.phi" in res.stderr and "--set" in res.stderr
    assert os.listdir(tmp_path) == []


def test_bad_output_paths(job_file, tmp_path):
    res = sdmpi("run", job_file, "-o", tmp_path / "missing" / "run.h5")
    assert res.returncode == 2 and "does not exist" in res.stderr
    res = sdmpi("run", job_file, "-o", tmp_path)
    assert res.returncode == 2 and "is a directory" in res.stderr
    res = sdmpi("run", tmp_path / "nope.toml", "-o", tmp_path / "run.h5")
    assert res.returncode == 2 and "cannot read" in res.stderr
    assert os.listdir(tmp_path) == []


def _foreign(path, ref):
    with h5py.File(path, "w") as f:
        f["data"] = [1, 2, 3]


def _text(path, ref):
    path.write_text("not HDF5\n" * 100)


def _truncated(path, ref):
    data = ref.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _overwrite(where):
    """Overwrite 64 bytes at an offset, or where a byte string first occurs."""
    def damage(path, ref):
        data = bytearray(ref.read_bytes())
        offset = where if isinstance(where, int) else data.index(where)
        data[offset:offset + 64] = b"\xff" * 64
        path.write_bytes(bytes(data))
    return damage


BAD_FILES = {"foreign HDF5": (_foreign, "not an sdmpi run file"),
             "text": (_text, "not a readable HDF5 file"),
             "truncated": (_truncated, "truncated"),
             "superblock": (_overwrite(100), "not a readable HDF5 file"),
             "object header": (_overwrite(800), "not a readable HDF5 file"),
             "versions attribute": (_overwrite(b'{"sdmpi"'), "damaged run file"),
             "job text": (_overwrite(b"[shear]"), "damaged run file")}


@pytest.mark.parametrize("name", BAD_FILES)
def test_bad_run_file_refused_untouched(reference, job_file, tmp_path, name):
    make, message = BAD_FILES[name]
    out = tmp_path / "run.h5"
    make(out, reference)
    before = digest(out)
    info = sdmpi("info", out)
    assert info.returncode == 2 and message in info.stderr, info.stderr
    res = sdmpi("run", job_file, "-o", out)
    assert res.returncode == 2 and message in res.stderr, res.stderr
    # --new is offered only for what is (or was, before damage) an sdmpi run file
    assert ("--new" in res.stderr) == (name not in ("foreign HDF5", "text")), res.stderr
    assert digest(out) == before
    assert os.listdir(tmp_path) == ["run.h5"]


def test_other_job_refused_then_new(reference, job_file, tmp_path):
    out = tmp_path / "run.h5"
    shutil.copy(reference, out)
    before = digest(out)
    res = sdmpi("run", job_file, "-o", out, "--set", "job.seed=8")
    assert res.returncode == 2
    assert "different job" in res.stderr and "job.seed: file has 7, this job has 8" in res.stderr
    assert digest(out) == before
    res = sdmpi("run", job_file, "-o", out, "--set", "job.seed=8", "--new")
    assert res.returncode == 0, res.stderr
    assert "seed = 8" in sdmpi("info", out, "--job").stdout


def test_complete_run_is_left_alone(reference, job_file):
    before = digest(reference)
    res = sdmpi("run", job_file, "-o", reference, "--set", "output.checkpoint_every=3")
    assert res.returncode == 0 and "already complete" in res.stdout
    assert digest(reference) == before


def test_locked_run_refused(reference, job_file, tmp_path):
    out = tmp_path / "run.h5"
    logs(out).mkdir()
    with open(logs(out) / "lock", "w") as held:
        held.write("pid 1 on elsewhere\n")
        held.flush()
        fcntl.flock(held, fcntl.LOCK_EX)
        res = sdmpi("run", job_file, "-o", out)
    assert res.returncode == 2 and "in use by another sdmpi run (pid 1 on elsewhere)" in res.stderr
    assert not out.exists()


# --------------------------------------------------------------------------- info


def test_info(reference, job_file):
    res = sdmpi("info", reference)
    assert res.returncode == 0, res.stderr
    text = res.stdout
    assert "sdmpi run file, format 1" in text and "job 'ensemble-test'" in text
    assert "progress: 8/8 tasks complete, 384/384 steps (100.0%); complete" in text
    assert text.count(" done\n") == N_TASKS
    assert "versions: sdmpi 0.1.0, sdmpi source " in text and "hdf5" in text and "MPI" in text
    assert "units: time t_D, stress eta_m/t_D" in text
    res = sdmpi("info", reference, "--job")
    assert parse_job(res.stdout) == load_job(job_file)
    assert sdmpi("info", reference.parent / "missing.h5").returncode == 2


def test_source_digest_tells_code_apart(tmp_path):
    """The run file's source digest (sdmpi.ensemble.runner.source_digest) depends on every
    source file's path and content, and on nothing else."""
    from sdmpi.ensemble.runner import source_digest

    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "a.py").write_text("x = 1\n")
    (tmp_path / "b.py").write_text("y = 2\n")
    (tmp_path / "notes.txt").write_text("not source")
    first = source_digest(tmp_path)
    assert len(first) == 12 and int(first, 16) >= 0
    (tmp_path / "notes.txt").write_text("changed")
    assert source_digest(tmp_path) == first
    (tmp_path / "pkg" / "a.py").write_text("x = 2\n")
    assert source_digest(tmp_path) != first
    (tmp_path / "pkg" / "a.py").write_text("x = 1\n")
    (tmp_path / "pkg" / "a.py").rename(tmp_path / "pkg" / "c.py")
    assert source_digest(tmp_path) != first
