"""The solver backend a run's tasks solve on is recorded in the run file (root attribute
``solver_backend``, "auto" resolved at creation) and a resume keeps it, whatever rank
count it runs on; files without the record resume as before (the rule at the job's N and
ranks_per_task). The runs use the cheap test double (`tests/ensemble_run.py`)."""

import io
import shutil

import h5py
import pytest
from mpi4py import MPI

from sdmpi.ensemble import runner
from sdmpi.hydro.petsc_dense import PetscUnavailable, import_petsc4py

from .ensemble_double import DoubleRealisation
from .runs import JOB, sdmpi, task_data

AUTO_JOB = JOB + '\n[solver]\nbackend = "auto"\n'  # 8 particles: dense on one rank per task


@pytest.fixture(scope="module")
def killed_auto_run(tmp_path_factory):
    """A one-rank run of AUTO_JOB killed (SIGKILL) at its 25th step: resumable, with
    committed checkpoints. Returns (job path, run file); copy the file before changing it."""
    where = tmp_path_factory.mktemp("auto")
    job, out = where / "auto.toml", where / "killed.h5"
    job.write_text(AUTO_JOB)
    res = sdmpi("run", job, "-o", out, env={"SDMPI_TEST_KILL": "step:25"})
    assert res.returncode != 0, res.stdout
    return job, out


def _copy(killed, tmp_path, backend="keep"):
    """The killed run file copied into tmp_path, its recorded backend set to ``backend``
    (None: the attribute removed, as in files written before it was recorded)."""
    out = tmp_path / "run.h5"
    shutil.copy(killed, out)
    if backend != "keep":
        with h5py.File(out, "r+") as f:
            if backend is None:
                del f.attrs["solver_backend"]
            else:
                f.attrs["solver_backend"] = backend
    return out


def _plan(job, out, ranks_per_task=1):
    return runner._plan(str(job), [f"ensemble.ranks_per_task={ranks_per_task}"], out,
                        new=False, extend=False, size=ranks_per_task)


def test_the_resolved_backend_is_recorded_at_creation(killed_auto_run):
    job, out = killed_auto_run
    with h5py.File(out, "r") as f:
        assert f.attrs["solver_backend"] == "dense"  # "auto" at N = 8 on one rank per task
    info = sdmpi("info", out)
    assert info.returncode == 0 and "solver backend: dense (recorded at creation" in info.stdout


def test_a_resume_keeps_the_recorded_backend_on_any_rank_count(killed_auto_run, tmp_path):
    """"auto" at N = 8 is petsc-dense on 2 ranks per task and dense on one; a file that
    recorded petsc-dense resumes on it on one rank, and one that recorded dense on it."""
    try:
        import_petsc4py()
    except PetscUnavailable as err:
        pytest.skip(f"petsc4py not available: {err}")
    job, killed = killed_auto_run
    plan = _plan(job, _copy(killed, tmp_path, "petsc-dense"))
    assert (plan.mode, plan.backend) == ("resume", "petsc-dense")
    assert _plan(job, _copy(killed, tmp_path, "dense")).backend == "dense"


def test_a_recorded_one_rank_backend_refuses_several_ranks_per_task(killed_auto_run, tmp_path):
    job, killed = killed_auto_run
    with pytest.raises(runner.BadInput) as err:
        _plan(job, _copy(killed, tmp_path), ranks_per_task=2)
    text = str(err.value)
    assert 'the "dense" backend (what solver.backend = "auto" stood for' in text
    assert "ensemble.ranks_per_task = 2; allowed: 1" in text and "Nothing written" in text


def test_an_unknown_recorded_backend_is_refused(killed_auto_run, tmp_path):
    job, killed = killed_auto_run
    with pytest.raises(runner.BadInput, match='"warp-drive" backend .* this sdmpi does not have'):
        _plan(job, _copy(killed, tmp_path, "warp-drive"))


def test_a_file_without_the_record_resolves_auto_as_before(killed_auto_run, tmp_path):
    try:
        import_petsc4py()
        two = [2]
    except PetscUnavailable:
        two = []
    job, killed = killed_auto_run
    out = _copy(killed, tmp_path, None)
    for rpt, backend in [(1, "dense"), *((n, "petsc-dense") for n in two)]:
        assert _plan(job, out, rpt).backend == backend


@pytest.mark.parametrize("recorded", ["keep", None], ids=["recorded", "older-file"])
def test_resumed_realisations_get_the_backend_and_finish_bit_identical(
        killed_auto_run, ensemble_reference, tmp_path, recorded):
    """In process: the realisations of the resume are built from the job with the plan's
    backend (not "auto"), and the finished file holds the uninterrupted run's data."""
    job, killed = killed_auto_run
    out, seen = _copy(killed, tmp_path, recorded), []

    def factory(job, task, **kwargs):
        seen.append(job.solver.backend)
        return DoubleRealisation(job, task, **kwargs)

    assert runner.run(str(job), [], out, realisation_factory=factory, comm=MPI.COMM_SELF,
                      stream=io.StringIO())
    assert seen and set(seen) == {"dense"}
    assert task_data(out) == task_data(ensemble_reference)
    assert _plan(job, out, ranks_per_task=2).mode == "complete"  # nothing to run: not refused


def test_an_extension_keeps_the_recorded_backend(killed_auto_run, tmp_path):
    job, killed = killed_auto_run
    out, longer = _copy(killed, tmp_path, "petsc-dense"), tmp_path / "longer.toml"
    longer.write_text(AUTO_JOB.replace("periods = 3", "periods = 4"))
    try:
        import_petsc4py()
    except PetscUnavailable as err:
        pytest.skip(f"petsc4py not available: {err}")
    plan = runner._plan(str(longer), [], out, new=False, extend=True, size=1)
    assert (plan.mode, plan.backend) == ("extend", "petsc-dense")
    from sdmpi.ensemble import extension

    extension.extend(out, runner.parse_job(plan.job_text), plan.job_text, plan.versions)
    with h5py.File(out, "r") as f:
        assert f.attrs["solver_backend"] == "petsc-dense" and "extended" in f.attrs


def test_pinning_the_resolved_backend_keeps_the_stream():
    """A realisation built from the job with "auto" replaced by what it stands for
    (`runner._pinned`, as sdmpi run builds them) steps bit for bit as one built from the
    job itself (demo job, N = 8: dense)."""
    from pathlib import Path

    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation

    job = load_job(str(Path(__file__).parents[1] / "jobs" / "demo.toml"), ['solver.backend="auto"'])
    pinned = runner._pinned(job, runner.job_backend(job))
    assert pinned.solver.backend == "dense" and pinned.system == job.system
    task = enumerate_tasks(job)[0]
    a, b = Realisation(job, task).advance(12), Realisation(pinned, task).advance(12)
    assert a.keys() == b.keys() and all(a[k].tobytes() == b[k].tobytes() for k in a)
