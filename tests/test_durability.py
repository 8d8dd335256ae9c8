"""What a SIGKILL leaves committed, on both ways of writing the run file.

Each run is killed by the fault injector (sdmpi.ensemble.faults) at a known point; the
file is then read as it is on disk, before any resume: every checkpoint completed before
the kill must be there (its /progress, its samples bit for bit, its verified state), and
nothing else. Then the resume must end with the data of an uninterrupted run. The serial
path (h5py without MPI: the file opened directly, HDF5's own raw-data buffers in between)
is forced on a machine with parallel h5py, as tests/test_serial_h5py.py does.
"""

import math
import signal
import subprocess
import sys

import h5py
import numpy as np
import pytest

from .runs import DRIVER, JOB, N_STEPS, child_env, sdmpi, task_data

CHECKPOINT_EVERY = 10


def driver(path_kind) -> list[str]:
    """The command of sdmpi with the test double, on the serial or the parallel path."""
    return [sys.executable, str(DRIVER), *(["--serial-h5py"] if path_kind == "serial" else [])]


def run(path_kind, *args, env=None):
    return sdmpi(*(["--serial-h5py"] if path_kind == "serial" else []), *args, env=env)


def commits_before(point: str, k: int) -> int:
    """Checkpoints a one-rank run completes before the fault injector kills it at the
    k-th ``point``: each task (N_STEPS steps, run one after the other) commits at every
    multiple of CHECKPOINT_EVERY and at its end."""
    per_task = [s for s in range(1, N_STEPS + 1) if s % CHECKPOINT_EVERY == 0 or s == N_STEPS]
    if point == "commit":
        return k - 1
    assert point == "step"  # killed after the k-th step, before its sample is buffered
    ends = [j * N_STEPS + s for j in range(8) for s in per_task]
    return sum(1 for c in ends if c < k)


def committed_checkpoints(progress) -> int:
    """Checkpoints behind each task's /progress (commits at multiples of
    CHECKPOINT_EVERY and at the task's end)."""
    return sum(math.ceil(int(p) / CHECKPOINT_EVERY) for p in progress)


@pytest.fixture(scope="module")
def job_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("job") / "job.toml"
    path.write_text(JOB.replace("checkpoint_every = 10",
                                f"checkpoint_every = {CHECKPOINT_EVERY}"))
    return path


@pytest.fixture(scope="module")
def reference(job_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "ref.h5"
    res = run("parallel", "run", job_file, "-o", out)
    assert res.returncode == 0, res.stderr
    return out


@pytest.mark.parametrize("path_kind", ["serial", "parallel"])
@pytest.mark.parametrize("kill", ["step:25", "commit:7", "step:203", "commit:33"])
def test_kill_keeps_every_completed_checkpoint(reference, job_file, tmp_path, path_kind,
                                               kill):
    from sdmpi.ensemble.store import read_summary

    out = tmp_path / "killed.h5"
    res = run(path_kind, "run", job_file, "-o", out, env={"SDMPI_TEST_KILL": kill})
    assert res.returncode != 0, f"not killed:\n{res.stdout}"
    point, k = kill.split(":")
    summary = read_summary(out)  # as the kill left it on disk
    assert summary.damage == ()
    assert committed_checkpoints(summary.progress) == commits_before(point, int(k))
    with h5py.File(out, "r") as f, h5py.File(reference, "r") as ref:
        for task, done in zip(summary.tasks, summary.progress):
            key = f"tasks/{task.task_id:06d}/samples"
            for name in ref[key]:
                np.testing.assert_array_equal(f[key][name][:done], ref[key][name][:done],
                                              err_msg=f"{name} of task {task.task_id}")
    res = run(path_kind, "run", job_file, "-o", out)
    assert res.returncode == 0, res.stderr
    assert task_data(out) == task_data(reference)


def test_serial_path_allocates_every_dataset_at_creation(job_file, tmp_path):
    """Writing values while stepping must change no HDF5 metadata: every dataset of a
    new run file has its storage (contiguous) before the first step."""
    out = tmp_path / "new.h5"
    res = run("serial", "run", job_file, "-o", out, env={"SDMPI_TEST_KILL": "step:1"})
    assert res.returncode != 0
    unallocated = []
    with h5py.File(out, "r") as f:
        f.visititems(lambda name, obj: unallocated.append(name)
                     if isinstance(obj, h5py.Dataset) and obj.size and obj.id.get_offset() is None
                     else None)
    assert unallocated == []


@pytest.mark.parametrize("path_kind", ["serial", "parallel"])
def test_live_file_is_read_while_it_is_written(job_file, tmp_path, path_kind):
    """While a run steps (then stopped by SIGTERM), `info` reads its file (exit 0, progress counted up to the last
    checkpoints, "running"), `reduce` reads what is committed, and a second `run` is
    refused as "in use" without suggesting --new; nothing is reported damaged."""
    import time

    out = tmp_path / "live.h5"
    proc = subprocess.Popen([*driver(path_kind), "run", str(job_file), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=child_env({"SDMPI_DOUBLE_SLEEP": "0.2"}))  # 77 s, stopped sooner
    try:
        seen = []
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline and len(seen) < 3:
            time.sleep(1.0)
            if not out.exists():
                continue
            res = run(path_kind, "info", out)
            assert res.returncode == 0, res.stderr
            assert "running (pid" in res.stdout and "verified" in res.stdout
            progress = next(line for line in res.stdout.splitlines()
                            if line.startswith("progress:"))
            seen.append(int(progress.split(" steps (")[0].rsplit(" ", 1)[1].split("/")[0]))
        again = run(path_kind, "run", job_file, "-o", out)
        reduced = run(path_kind, "reduce", out, "-o", tmp_path / "red", "--no-plots")
        assert proc.poll() is None, "the run ended before the reads: slow it down"
        assert len(seen) == 3 and seen == sorted(seen) and seen[-1] > 0, seen
        assert again.returncode == 2 and "in use by another sdmpi run (pid" in again.stderr
        assert "--new" not in again.stderr
        assert reduced.returncode == 0, reduced.stderr
    finally:
        proc.send_signal(signal.SIGTERM)  # a clean stop: checkpoint, exit 3
        stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 3, stderr


#: in a child process: a serial run file of the ensemble job, three commits of task 0
#: (steps 10, 20, 30; slots 0, 1, 0) made and applied as one batch, as the writer rank of
#: a serial h5py applies what it has received (SDMPI_TEST_KILL kills it on the way)
BATCH = """
import sys
from mpi4py import MPI
from sdmpi.config import canonical_text, enumerate_tasks, load_job
from sdmpi.ensemble.store import RunFile, TaskLayout, create
from tests.ensemble_double import DoubleRealisation

job = load_job(sys.argv[1])
tasks = enumerate_tasks(job)
layouts = {t.task_id: TaskLayout.of(DoubleRealisation(job, t)) for t in tasks}
create(sys.argv[2], job, canonical_text(job), layouts, MPI.COMM_SELF, "{}", "now")
collected = []
handle = RunFile(sys.argv[2], MPI.COMM_SELF)
handle._submit = collected.append
real = DoubleRealisation(job, tasks[0])
handle.begin(0, -1)
for k, stop in enumerate((10, 20, 30)):
    samples = real.advance(10)
    handle.commit(0, handle.samples(0), stop - 10, stop, samples, real.get_state(), k % 2)
handle._apply(collected)
handle.close()
"""


@pytest.mark.parametrize("kill", ["commit:1", "commit:2", "commit:3", "state:3", None])
def test_a_batch_of_one_tasks_commits_keeps_the_file_consistent(job_file, tmp_path, kill):
    """The writer rank may receive several commits of one task at once; a kill anywhere
    in applying them leaves /progress at a step some intact slot holds."""
    from sdmpi.ensemble.store import read_summary

    out = tmp_path / "batch.h5"
    res = subprocess.run([sys.executable, "-c", BATCH, str(job_file), str(out)],
                         capture_output=True, text=True, cwd=str(DRIVER.parents[1]),
                         env=child_env({"SDMPI_TEST_KILL": kill} if kill else {}), timeout=120)
    assert (res.returncode != 0) == (kill is not None), res.stderr
    summary = read_summary(out)
    assert summary.damage == ()
    committed = {None: 30, "commit:1": 0, "commit:2": 10, "commit:3": 20, "state:3": 20}[kill]
    assert int(summary.progress[0]) == committed
