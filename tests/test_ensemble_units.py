"""Pieces of the ensemble runner that need no MPI: LPT assignment, the progress line."""

import io
import types
from pathlib import Path

from sdmpi.config import enumerate_tasks, parse_job
from sdmpi.ensemble.farm import assign, remaining_costs
from sdmpi.ensemble.progress import Progress, hms

JOB = """
[system]
n_particles = 8
phi = [0.2, 0.3]
[shear]
omega = [1.0, 4.0, 16.0]
[integration]
steps_per_period = 8
periods = 3
discard_periods = 1
dt_max = 0.1
[ensemble]
realisations = 3
"""


def test_every_task_once_longest_first():
    tasks = enumerate_tasks(parse_job(JOB))
    costs = remaining_costs(tasks, [0] * len(tasks))
    for n_groups in (1, 2, 3, 7, 40):
        groups = assign(costs, n_groups)
        assert len(groups) == n_groups
        assert sorted(t for g in groups for t in g) == list(range(len(tasks)))
        for g in groups:
            assert [costs[t] for t in g] == sorted((costs[t] for t in g), reverse=True)


def test_lpt_balance_and_determinism():
    costs = {i: c for i, c in enumerate([7, 7, 6, 5, 5, 4, 3, 3, 2, 1])}
    groups = assign(costs, 3)
    assert groups == assign(dict(reversed(list(costs.items()))), 3)  # order-independent
    loads = [sum(costs[t] for t in g) for g in groups]
    # LPT bound: makespan <= (4/3 - 1/(3m)) OPT; here OPT = 43/3 rounded up = 15
    assert max(loads) <= 16 and sum(loads) == 43


def test_remaining_costs_skip_finished():
    tasks = enumerate_tasks(parse_job(JOB))
    progress = [t.n_steps if t.task_id % 2 else t.n_steps // 2 for t in tasks]
    costs = remaining_costs(tasks, progress)
    groups = assign(costs, 2)
    assigned = sorted(t for g in groups for t in g)
    assert assigned == [t.task_id for t in tasks if t.task_id % 2 == 0]
    assert all(costs[t.task_id] == t.cost / 2 for t in tasks if t.task_id % 2 == 0
               and t.n_steps % 2 == 0)


def test_progress_line():
    comm = types.SimpleNamespace(rank=0)
    p = Progress(comm, [0, 3], (2, 10), (400, 2000), io.StringIO())
    p.steps, p.tasks, p.remote[3] = 100, 0, (100, 1)
    # the first line with steps starts the rate clock (start-up time left out)
    assert p.line(p.start + 10.0).endswith("| ? steps/s | elapsed 0:00:10 | ETA ?")
    p.steps, p.tasks, p.remote[3] = 300, 1, (500, 2)
    line = p.line(p.start + 40.0)
    assert line == ("tasks 5/10 done | steps 1200/2000 (60.0%) | 20 steps/s | "
                    "elapsed 0:00:40 | ETA 0:00:40")
    assert hms(3725.4) == "1:02:05"


def test_progress_rate_on_the_first_line(monkeypatch):
    """The rate clock starts at the first counted step, not at the first printed line, so
    the first line printed after it (5 s later) already shows a rate and an ETA."""
    from sdmpi.ensemble import progress

    clock = [100.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: clock[0])
    stream = io.StringIO()
    comm = types.SimpleNamespace(rank=0, iprobe=lambda **kwargs: False)
    p = Progress(comm, [0], (0, 4), (0, 1000), stream)
    clock[0] = 103.0
    p.add(steps=10)                # the first step (start-up and compilation before it)
    clock[0] = 105.0               # first line due (plain lines: every 5 s at first)
    p.add(steps=90)
    assert stream.getvalue() == ("tasks 0/4 done | steps 100/1000 (10.0%) | 45 steps/s | "
                                 "elapsed 0:00:05 | ETA 0:00:20\n")



def test_petsc_backend_without_petsc4py_is_bad_input(monkeypatch):
    """A job whose backend needs PETSc (named, or "auto" with ranks_per_task > 1), on a
    machine where petsc4py cannot be loaded, is refused by the checks `sdmpi run` makes
    before it writes anything (BadInput: exit 2); dense jobs do not need PETSc."""
    import pytest

    from sdmpi.config import load_job
    from sdmpi.ensemble import runner
    from sdmpi.hydro import petsc_dense

    def unavailable():
        raise petsc_dense.PetscUnavailable("petsc4py cannot be imported (test)")

    monkeypatch.setattr(petsc_dense, "import_petsc4py", unavailable)
    demo = str(Path(__file__).parents[1] / "jobs" / "demo.toml")
    for backend, rpt in (("petsc-krylov", 1), ("petsc-dense", 2), ("auto", 2)):
        job = load_job(demo, [f'solver.backend="{backend}"', f"ensemble.ranks_per_task={rpt}"])
        with pytest.raises(runner.BadInput, match=f"solver.backend = '{backend}' needs PETSc"):
            runner._check_backend(job, runner.job_backend(job), demo)
    runner._check_backend(load_job(demo), "dense", demo)
    auto = load_job(demo, ['solver.backend="auto"'])
    runner._check_backend(auto, runner.job_backend(auto), demo)  # N = 8: dense


def test_validate_summary_shows_what_run_uses(monkeypatch, capsys):
    """`sdmpi validate` says what `run` will do: the backend "auto" resolves to, and that a
    PETSc backend cannot run where petsc4py does not load; areal fractions for monolayers;
    the SI scales and Peclet number of a [physical] job."""
    from sdmpi.cli import main
    from sdmpi.hydro import petsc_dense

    jobs = Path(__file__).parents[1] / "jobs"
    assert main(["validate", str(jobs / "demo.toml"), "--set", 'solver.backend="auto"',
                 "--set", "system.n_particles=1000"]) == 0
    assert "backend auto (here petsc-krylov), spectral far field" in capsys.readouterr().out

    def unavailable():
        raise petsc_dense.PetscUnavailable("petsc4py cannot be imported (test)")

    monkeypatch.setattr(petsc_dense, "import_petsc4py", unavailable)
    assert main(["validate", str(jobs / "demo.toml"), "--set", 'solver.backend="petsc-krylov"']) == 0
    assert "petsc-krylov, dense far field - NOT RUNNABLE HERE, sdmpi run would refuse it" in capsys.readouterr().out
    assert main(["validate", str(jobs / "monolayer_hydro.toml")]) == 0
    out = capsys.readouterr().out
    assert "areal fraction = 0.2, 0.3" in out and "rate = 1 [gamma_dot]" in out
    assert main(["validate", str(jobs / "boehmite_epoxy.toml")]) == 0
    out = capsys.readouterr().out
    # a = 55 nm (the job's radius); Pe = 6 pi eta a^3 gamma_dot / kT = the reduced rate in t_D units
    assert "physical units: a = 5.5e-08 m" in out and "Pe = 8.36" in out


def test_validate_summary_names_the_hydrodynamics_run_uses(capsys):
    """hydrodynamics.lubrication = false turns the stokesian model into its far field
    alone: `sdmpi validate` says so rather than printing the model's name only; the
    integrator, a held far field, and the drift scheme the backend runs (with the
    near-contact correction where it applies) are named too."""
    from sdmpi.cli import main

    demo = str(Path(__file__).parents[1] / "jobs" / "demo.toml")
    assert main(["validate", demo]) == 0
    out = capsys.readouterr().out
    assert "  hydrodynamics: stokesian\n" in out and "Brownian on (drift rfd, near-contact correction);" in out
    assert main(["validate", demo, "--set", "hydrodynamics.lubrication=false"]) == 0
    out = capsys.readouterr().out
    assert "stokesian without lubrication" in out and 'as hydrodynamics.model = "far-field"' in out
    assert "Brownian on (drift rfd);" in out
    assert main(["validate", demo, "--set", 'solver.backend="petsc-krylov"']) == 0
    assert "Brownian on (drift midpoint);" in capsys.readouterr().out
    monolayer = str(Path(__file__).parents[1] / "jobs" / "dratler1996_hydro.toml")
    assert main(["validate", monolayer, "--set", 'integration.scheme="adams-bashforth-4"',
                 "--set", "hydrodynamics.far_field_refresh=0.1"]) == 0
    assert ("  integrator: adams-bashforth-4; far-field mobility held 0.1 [1/gamma_dot] between "
            "refreshes\n") in capsys.readouterr().out
