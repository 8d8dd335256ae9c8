"""The ensemble runner end to end, with the cheap test double as the realisation.

Every run is a subprocess (``tests/ensemble_run.py`` = ``sdmpi`` with the double), one
rank without mpirun or two under ``mpirun -n 2``; data are compared bit for bit with a
one-rank run that was never interrupted.
"""

import fcntl
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

from .runs import DRIVER, JOB, MPIRUN, N_STEPS, N_TASKS, child_env, digest, needs_mpi, sdmpi, task_data


def logs(path):
    return Path(str(path) + ".logs")


def test_reference_layout(ensemble_reference, ensemble_job):
    with h5py.File(ensemble_reference, "r") as f:
        assert f.attrs["format"] == "sdmpi-run" and f.attrs["format_version"] == 1
        assert parse_job(f.attrs["job_text"]) == load_job(ensemble_job)
        assert list(f["progress"][()]) == [N_STEPS] * N_TASKS
        samples = f["tasks/000005/samples"]
        assert samples["stresslets"].shape == (N_STEPS, 8, 5)
        assert samples["stress_hydrodynamic_maxwell"].shape == (N_STEPS, 6)
        assert samples["time"].attrs["unit"] == "t_D"
        assert f["tasks/000005"].attrs["realisation"] == 1
        assert sorted(f["checkpoints/000005"]) == ["sample_crc", "slot0", "slot1", "slot_step",
                                                   "state_crc"]
    assert (logs(ensemble_reference) / "rank-0.log").read_text().count("complete") == N_TASKS


@needs_mpi
@pytest.mark.mpi
def test_two_ranks_bit_identical(ensemble_reference, ensemble_job, tmp_path):
    out = tmp_path / "two.h5"
    res = sdmpi("run", ensemble_job, "-o", out, ranks=2)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(ensemble_reference)
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
def test_sigkill_then_resume_bit_identical(ensemble_reference, ensemble_job, tmp_path, kills, ranks,
                                           overrides):
    out = tmp_path / "killed.h5"
    for spec, kill_ranks in kills:
        res = sdmpi("run", ensemble_job, "-o", out, ranks=kill_ranks,
                    env={"SDMPI_TEST_KILL": spec})
        assert res.returncode != 0, f"{spec}: not killed\n{res.stdout}"
        info = sdmpi("info", out)
        assert info.returncode == 0, info.stderr  # intact after the kill
        assert "resumable" in info.stdout
    sets = [a for o in overrides for a in ("--set", o)]
    res = sdmpi("run", ensemble_job, "-o", out, *sets, ranks=ranks)
    assert res.returncode == 0, res.stderr
    assert "resuming" in res.stdout
    assert task_data(out) == task_data(ensemble_reference)
    assert current_checksums(out) == current_checksums(ensemble_reference)


def current_checksums(path):
    """Per task, the sample and state checksums of the current checkpoint slot; asserts
    that the file verifies."""
    from sdmpi.ensemble.store import read_summary

    summary = read_summary(path)
    assert summary.checksummed and summary.damage == ()
    with h5py.File(path, "r") as f:
        return {t.task_id: (f[f"checkpoints/{t.task_id:06d}/sample_crc"][s].tobytes(),
                            f[f"checkpoints/{t.task_id:06d}/state_crc"][s].tobytes())
                for t, s in zip(summary.tasks, summary.slots)}


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_checkpoints_and_resumes(ensemble_reference, ensemble_job, tmp_path, sig):
    out = tmp_path / "stopped.h5"
    _stop_midway(sig, [sys.executable, str(DRIVER), "run", ensemble_job, "-o", out], out)
    info = sdmpi("info", out)
    assert info.returncode == 0 and "resumable" in info.stdout
    with h5py.File(out, "r") as f:
        assert 0 < f["progress"][()].sum() < N_TASKS * N_STEPS
    res = sdmpi("run", ensemble_job, "-o", out, ranks=2 if MPIRUN else None)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(ensemble_reference)


@needs_mpi
@pytest.mark.mpi
def test_sigusr1_to_mpirun_stops_cleanly(ensemble_reference, ensemble_job, tmp_path):
    out = tmp_path / "stopped.h5"
    cmd = [MPIRUN, "--oversubscribe", "-n", "2", sys.executable, str(DRIVER), "run",
           ensemble_job, "-o", out]
    _stop_midway(signal.SIGUSR1, cmd, out)
    res = sdmpi("run", ensemble_job, "-o", out)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(ensemble_reference)


def _stop_midway(sig, cmd, out):
    """Start a slowed-down run, signal it once it is stepping, expect exit 3."""
    proc = subprocess.Popen([str(c) for c in cmd], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            env=child_env({"SDMPI_DOUBLE_SLEEP": "0.01"}))
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


def test_bad_override(ensemble_job, tmp_path):
    res = sdmpi("run", ensemble_job, "-o", tmp_path / "run.h5", "--set", "system.phi=2.0")
    assert res.returncode == 2 and "system.phi" in res.stderr and "--set" in res.stderr
    assert os.listdir(tmp_path) == []


def test_bad_output_paths(ensemble_job, tmp_path):
    res = sdmpi("run", ensemble_job, "-o", tmp_path / "missing" / "run.h5")
    assert res.returncode == 2 and "does not exist" in res.stderr
    res = sdmpi("run", ensemble_job, "-o", tmp_path)
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
def test_bad_run_file_refused_untouched(ensemble_reference, ensemble_job, tmp_path, name):
    make, message = BAD_FILES[name]
    out = tmp_path / "run.h5"
    make(out, ensemble_reference)
    before = digest(out)
    info = sdmpi("info", out)
    assert info.returncode == 2 and message in info.stderr, info.stderr
    res = sdmpi("run", ensemble_job, "-o", out)
    assert res.returncode == 2 and message in res.stderr, res.stderr
    # --new is offered only for what is (or was, before damage) an sdmpi run file
    assert ("--new" in res.stderr) == (name not in ("foreign HDF5", "text")), res.stderr
    assert digest(out) == before
    assert os.listdir(tmp_path) == ["run.h5"]


def test_other_job_refused_then_new(ensemble_reference, ensemble_job, tmp_path):
    out = tmp_path / "run.h5"
    shutil.copy(ensemble_reference, out)
    before = digest(out)
    res = sdmpi("run", ensemble_job, "-o", out, "--set", "job.seed=8")
    assert res.returncode == 2
    assert "different job" in res.stderr and "job.seed: file has 7, this job has 8" in res.stderr
    assert digest(out) == before
    res = sdmpi("run", ensemble_job, "-o", out, "--set", "job.seed=8", "--new")
    assert res.returncode == 0, res.stderr
    assert "seed = 8" in sdmpi("info", out, "--job").stdout


def test_complete_run_is_left_alone(ensemble_reference, ensemble_job):
    before = digest(ensemble_reference)
    res = sdmpi("run", ensemble_job, "-o", ensemble_reference, "--set", "output.checkpoint_every=3")
    assert res.returncode == 0 and "already complete" in res.stdout
    assert digest(ensemble_reference) == before


def test_locked_run_refused(ensemble_reference, ensemble_job, tmp_path):
    out = tmp_path / "run.h5"
    logs(out).mkdir()
    with open(logs(out) / "lock", "w") as held:
        held.write("pid 1 on elsewhere\n")
        held.flush()
        fcntl.flock(held, fcntl.LOCK_EX)
        res = sdmpi("run", ensemble_job, "-o", out)
    assert res.returncode == 2 and "in use by another sdmpi run (pid 1 on elsewhere)" in res.stderr
    assert not out.exists()


# --------------------------------------------------------------------------- info


def test_info(ensemble_reference, ensemble_job):
    res = sdmpi("info", ensemble_reference)
    assert res.returncode == 0, res.stderr
    text = res.stdout
    assert "sdmpi run file, format 1" in text and "job 'ensemble-test'" in text
    assert "progress: 8/8 tasks complete, 384/384 steps (100.0%); complete" in text
    assert text.count(" done\n") == N_TASKS
    assert "versions: sdmpi 0.1.0, sdmpi source " in text and "hdf5" in text and "MPI" in text
    assert "units: time t_D, stress eta_m/t_D" in text
    res = sdmpi("info", ensemble_reference, "--job")
    assert parse_job(res.stdout) == load_job(ensemble_job)
    assert sdmpi("info", ensemble_reference.parent / "missing.h5").returncode == 2


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
