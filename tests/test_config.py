"""Job files: schema, defaults, every kind of error, --set overrides, tasks, canonical
text and hash, and the `sdmpi validate` command (exit codes 0 / 2, writes nothing)."""

import dataclasses
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from sdmpi.cli import main
from sdmpi.config import (LAYOUT_KEYS, Job, JobError, canonical_text, enumerate_tasks,
                          job_hash, load_job, parse_job, resume_hash, schema_text)
from sdmpi.config.schema import SECTIONS, toml_name
from sdmpi.registry import SOLVER_BACKENDS

ROOT = Path(__file__).resolve().parents[1]
JOBS = sorted((ROOT / "jobs").glob("*.toml"))
DEMO = ROOT / "jobs" / "demo.toml"


def problems(text, overrides=()):
    """The problems of a job text, as strings (fails if the job is valid)."""
    with pytest.raises(JobError) as info:
        parse_job(text, overrides)
    return [str(p) for p in info.value.problems]


def only_problem(text, overrides=()):
    found = problems(text, overrides)
    assert len(found) == 1, found
    return found[0]


# --------------------------------------------------------------------------- examples, defaults


def test_example_jobs_exist():
    assert {p.name for p in JOBS} >= {"demo.toml", "schaink2000_newtonian.toml",
                                      "schaink2000_maxwell.toml"}


@pytest.mark.parametrize("path", JOBS, ids=lambda p: p.name)
def test_example_job_validates_and_round_trips(path):
    job = load_job(path)
    assert parse_job(canonical_text(job)) == job


@pytest.mark.parametrize("name, kind", [("schaink2000_newtonian.toml", "newtonian"),
                                        ("schaink2000_maxwell.toml", "maxwell")])
def test_schaink_jobs_match_the_seed_study(name, kind):
    job = load_job(ROOT / "jobs" / name)
    assert job.system.n_particles == 27 and job.system.phi == (0.45,)
    assert job.ensemble.realisations >= 7 and job.brownian.enabled
    assert job.shear.protocol == "oscillatory" and job.shear.gamma0 == 0.02
    assert min(job.shear.omega) <= 2 * math.pi + 1e-9 and max(job.shear.omega) >= 25
    assert all(job.steps_per_period(w) >= 500 for w in job.shear.omega)
    assert all(5e-5 - 1e-12 <= job.time_step(w) <= 5e-4 + 1e-12 for w in job.shear.omega)
    assert job.medium.kind == kind
    if kind == "maxwell":
        assert [(m.eta, m.lam) for m in job.medium.modes] == [(1.0, 0.5)]


def test_demo_is_tiny():
    job = load_job(DEMO)
    assert job.system.n_particles == 8 and job.system.phi == (0.3,)
    assert len(job.shear.omega) == 2 and job.ensemble.realisations == 2
    assert job.brownian.enabled and job.medium.kind == "newtonian"
    assert len(enumerate_tasks(job)) == 4


def test_empty_file_gives_the_documented_defaults():
    job = parse_job("")
    # every key at its schema default; the Ewald tolerance, whose default depends on the
    # job, resolved (a Brownian job: 1e-3)
    assert job.hydrodynamics.ewald_tolerance == 1e-3
    assert dataclasses.replace(job, hydrodynamics=dataclasses.replace(job.hydrodynamics, ewald_tolerance=None)) == Job()
    assert job.system.n_particles == 27 and job.system.phi == (0.45,)
    assert job.medium.kind == "newtonian" and job.medium.modes is None
    assert job.shear.protocol == "oscillatory" and job.shear.gamma0 == 0.02
    assert job.shear.omega == (2 * math.pi,) and job.shear.rate is None
    assert (job.integration.steps_per_period, job.integration.periods,
            job.integration.discard_periods) == (500, 20, 5)
    assert job.integration.dt is None and job.integration.dt_max == math.inf
    assert job.ensemble.realisations == 7 and job.ensemble.ranks_per_task == 1
    assert job.solver.backend == "dense"
    h = job.hydrodynamics
    assert (h.lubrication_cutoff, h.min_gap) == (2.0, 1e-4)
    # absent: the Brownian default, written into the job (its canonical text and hash are
    # those of the same job with the value given); 1e-6 for deterministic jobs
    assert h.ewald_tolerance == job.ewald_tolerance == 1e-3
    assert job_hash(job) == job_hash(parse_job("[hydrodynamics]\newald_tolerance = 1e-3\n"))
    assert parse_job("[brownian]\nenabled = false\n").hydrodynamics.ewald_tolerance == 1e-6
    assert job.output.per_particle is False and job.output.checkpoint_every == 1000
    assert job.time_unit == "t_D"


@pytest.mark.parametrize("text, expected", [
    ("", 1e-3),  # 27 equal spheres at phi = 0.45: box side 6.3
    ("[system]\nn_particles = 8\n", 1e-3),  # side 4.2
    ("[system]\nn_particles = 2\n", 1e-4),  # side 2.65: sums to 1e-3 leave M_inf indefinite
    ("[system]\nn_particles = 8\nphi = [0.1, 0.45]\n", 1e-3),  # the densest phi decides
    ("[system]\nn_particles = 6\nphi = [0.1, 0.45]\n", 1e-4),  # side 3.8 at phi = 0.45
    ("[system]\nsize_classes = [{radius = 1.0, fraction = 0.9}, {radius = 0.2, fraction = 0.1}]\n", 1e-4),
    ("[brownian]\nenabled = false\n", 1e-6),
    ("[system]\nn_particles = 2\n[hydrodynamics]\newald_tolerance = 1e-3\n", 1e-3),  # given: kept
])
def test_ewald_tolerance_default_by_kind_of_job(text, expected):
    """Brownian jobs default to 1e-3 only where it was measured to hold (equal spheres in a
    box of side >= 4 radii at every phi); other Brownian jobs to 1e-4; deterministic jobs
    (monolayers among them) to 1e-6. The resolved value is written into the job."""
    job = parse_job(text)
    assert job.ewald_tolerance == job.hydrodynamics.ewald_tolerance == expected


def test_default_job_round_trips_through_its_canonical_text():
    job = parse_job("")
    assert parse_job(canonical_text(job)) == job


def test_job_is_frozen():
    job = parse_job("")
    with pytest.raises(dataclasses.FrozenInstanceError):
        job.system.n_particles = 3


def test_steady_and_none_protocols_use_dt_and_n_steps():
    job = parse_job('[shear]\nprotocol = "steady"\nrate = 1\n[brownian]\nenabled = false\n'
                    "[integration]\ndt = 0.01\nn_steps = 200\ndiscard_steps = 20\n")
    assert job.shear.omega is None and job.integration.periods is None
    assert job.shear.rate == 1.0 and isinstance(job.shear.rate, float)
    assert job.time_unit == "1/gamma_dot" and job.frequencies == (None,)
    assert (job.time_step(None), job.n_steps(None), job.discard_steps(None)) == (0.01, 200, 20)
    quiet = parse_job('[shear]\nprotocol = "none"\n')
    assert quiet.integration.n_steps == 10000 and quiet.shear.gamma0 is None


def test_ints_are_accepted_for_floats_and_scalars_for_arrays():
    job = parse_job("[shear]\ngamma0 = 1\nomega = 3\n[system]\nphi = 0.3\n")
    assert job.shear.gamma0 == 1.0 and isinstance(job.shear.gamma0, float)
    assert job.shear.omega == (3.0,) and job.system.phi == (0.3,)


def test_schema_text_documents_every_key():
    text = schema_text()
    for section, cls in SECTIONS:
        assert f"[{section}]" in text
        for f in dataclasses.fields(cls):
            assert f"  {toml_name(f)} = " in text
    assert "eta_m" in text and "mean radii" in text


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("text, expected", [
    # unknown keys and sections, with a did-you-mean
    ("[shear]\nomgea = [1.0]\n", ['shear.omgea', 'did you mean "omega"', "protocol, gamma0"]),
    ("[system]\nrealisations = 3\n", ["system.realisations", "ensemble.realisations"]),
    ("[hydro]\nmin_gap = 0.1\n", ["hydro", 'did you mean "hydrodynamics"']),
    ("[sytem]\nn_particles = 8\n", ["sytem", 'did you mean "system"']),
    ('name = "x"\n', ["name", "job.name"]),
    # wrong types
    ("[system]\nn_particles = 8.0\n", ["system.n_particles = 8.0", "expected an integer",
                                       "write 8", "n_particles >= 1"]),
    ("[ensemble]\nrealisations = true\n", ["ensemble.realisations = true",
                                           "got a boolean", "1 <= realisations <= 100000"]),
    ('[shear]\ngamma0 = "0.02"\n', ["shear.gamma0", "expected a number", "0 < gamma0 <= 1"]),
    ("[brownian]\nenabled = 1\n", ["brownian.enabled = 1", "true or false"]),
    ("[system]\nphi = {a = 1}\n", ["system.phi", "expected an array of numbers"]),
    ('[shear]\nomega = [1.0, "x"]\n', ["shear.omega[1]", "expected a number", "omega > 0"]),
    # out of range / bad choice
    ("[system]\nphi = [0.3, 1.2]\n", ["system.phi[1] = 1.2", "out of range", "0 < phi < 1"]),
    ("[system]\nphi = [0.3, 0.7]\n", ["system.phi[1] = 0.7", "compressed hard-sphere fluid",
                                     "0 < phi < 0.6"]),
    ("[system]\nphi = []\n", ["system.phi", "must not be empty"]),
    ("[system]\nphi = [0.3, 0.3]\n", ["system.phi[1]", "appears twice"]),
    ("[shear]\ngamma0 = 0\n", ["shear.gamma0 = 0.0", "out of range", "0 < gamma0 <= 1"]),
    ("[shear]\ngamma0 = nan\n", ["shear.gamma0 = nan", "nan"]),
    ("[integration]\nsteps_per_period = 4\n", ["integration.steps_per_period = 4",
                                               "steps_per_period >= 8"]),
    ("[job]\nseed = -1\n", ["job.seed = -1", "0 <= seed"]),
    ('[solver]\nbackend = "petsc_dense"\n', ["solver.backend", 'did you mean "petsc-dense"',
                                             '"dense", "petsc-dense", "petsc-krylov"']),
    ('[job]\nname = ""\n', ["job.name", "non-empty"]),
    ('[solver]\nfar_field = "fft"\n', ["solver.far_field", '"dense", "spectral"']),
    # keys that are required / forbidden by another key
    ('[medium]\nkind = "maxwell"\n', ["medium.modes", "required", 'medium.kind is "maxwell"',
                                      "lambda = 0.5"]),
    ("[medium]\nmodes = [{eta = 1.0, lambda = 0.5}]\n", ["medium.modes", "does not apply",
                                                         'medium.kind = "maxwell"']),
    ('[medium]\nkind = "maxwell"\nmodes = []\n', ["medium.modes", "must not be empty"]),
    ('[medium]\nkind = "maxwell"\nmodes = [{eta = 1.0, lamda = 0.5}]\n',
     ["medium.modes[0].lamda", 'did you mean "lambda"']),
    ('[medium]\nkind = "maxwell"\nmodes = [{eta = 1.0, lambda = -1}]\n',
     ["medium.modes[0].lambda = -1", "lambda > 0"]),
    ('[shear]\nprotocol = "steady"\nomega = [1.0]\n', ["shear.omega", "does not apply",
                                                       'shear.protocol is "oscillatory"']),
    # checks across keys
    ("[integration]\nperiods = 20\ndiscard_periods = 20\n",
     ["integration.discard_periods = 20", "smaller than integration.periods",
      "0 <= discard_periods < 20"]),
    ('[shear]\nprotocol = "none"\n[integration]\nn_steps = 10\n',
     ["integration.discard_steps = 1000", "0 <= discard_steps < 10"]),
    ('[medium]\nkind = "maxwell"\nmodes = [{eta = 0.5, lambda = 0.5}]\n',
     ["medium.modes", "sum to 0.5", "sum to 1"]),
    ("[ensemble]\nranks_per_task = 2\n", ["ensemble.ranks_per_task = 2", "petsc-dense"]),
    ("[hydrodynamics]\nlubrication_cutoff = 0.05\nmin_gap = 0.06\n",
     ["hydrodynamics.min_gap", "0 < min_gap < 0.05"]),
    ('[shear]\nprotocol = "steady"\nrate = 2.0\n[brownian]\nenabled = false\n',
     ["shear.rate = 2.0", "1/gamma_dot"]),
    ('[shear]\nprotocol = "none"\n[brownian]\nenabled = false\n',
     ["shear.protocol", "nothing moves"]),
    ("[shear]\nomega = [0.001]\n", ["integration.steps_per_period", "t_D",
                                    "integration.dt_max < 1"]),
    ('[medium]\nkind = "maxwell"\nmodes = [{eta = 1.0, lambda = 0.001}]\n',
     ["integration.steps_per_period", "Maxwell relaxation time"]),
    ('[shear]\nprotocol = "steady"\n[integration]\ndt = 2.0\n', ["integration.dt", "dt < 1"]),
    # hydrodynamic models with options they do not support
    ('[hydrodynamics]\nmodel = "magic"\n', ["hydrodynamics.model", '"free-draining"']),
    ('[hydrodynamics]\nmodel = "far-field"\nlubrication = false\n',
     ["hydrodynamics.lubrication", "stokesian model only"]),
    ('[hydrodynamics]\nmodel = "free-draining"\n[interparticle]\nkind = "frictional"\n'
     'mu = 0.1\nk_n = 1e4\nk_t = 1e4\nf_r0 = 1.0\nrepulsion_length = 0.02\n[brownian]\nenabled = false\n'
     '[shear]\nprotocol = "steady"\nrate = 1.0\n[integration]\ndt = 1e-4\nn_steps = 10\ndiscard_steps = 0\n',
     ["hydrodynamics.model", "frictional contacts"]),
    ('[hydrodynamics]\nlubrication = false\n[interparticle]\nkind = "frictional"\n'
     'mu = 0.1\nk_n = 1e4\nk_t = 1e4\nf_r0 = 1.0\nrepulsion_length = 0.02\n[brownian]\nenabled = false\n'
     '[shear]\nprotocol = "steady"\nrate = 1.0\n[integration]\ndt = 1e-4\nn_steps = 10\ndiscard_steps = 0\n',
     ["hydrodynamics.lubrication = false", "frictional contacts", "allowed: true"]),
    ('[system]\ngeometry = "monolayer"\nn_particles = 16\nphi = [0.3]\n[hydrodynamics]\nlubrication = false\n'
     '[brownian]\nenabled = false\n[shear]\nprotocol = "steady"\nrate = 1.0\n[integration]\ndt = 1e-3\n'
     'n_steps = 10\ndiscard_steps = 0\n',
     ["hydrodynamics.lubrication = false", "monolayers", "allowed: true"]),
    ("[ensemble]\nrealisations = 1000000000000\n", ["ensemble.realisations", "realisations <= 100000"]),
    ('[hydrodynamics]\nmodel = "free-draining"\n[ensemble]\nranks_per_task = 2\n[solver]\n'
     'backend = "petsc-dense"\n', ["ensemble.ranks_per_task", "free-draining"]),
    # not TOML at all
    ("[system]\nphi = [0.3\nn_particles = 8\n", ["invalid TOML", "line 3"]),
    ("[shear]\ngamma0 = \n", ["invalid TOML", "line 2", "gamma0 ="]),
    ("[system]\n[system]\n", ["invalid TOML"]),
])
def test_each_kind_of_error_names_key_value_and_what_is_allowed(text, expected):
    message = only_problem(text)
    for part in expected:
        assert part in message, (part, message)


def test_every_problem_is_reported_at_once():
    text = """
[job]
seed = 1.5
[system]
n_particles = 0
phi = [1.5]
color = "red"
[medium]
kind = "maxwell"
[shear]
gamma0 = 2.0
[integration]
periods = 5
discard_periods = 7
[solver]
backend = "magic"
[output]
checkpoint_every = 0
[extra]
"""
    found = problems(text)
    paths = [p.split(":")[0].split(" =")[0] for p in found]
    assert paths == ["extra", "job.seed", "system.color", "system.n_particles",
                     "system.phi[0]", "medium.modes", "shear.gamma0", "solver.backend",
                     "output.checkpoint_every", "integration.discard_periods"]


def test_job_error_message_lists_every_problem(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[system]\nn_particles = 0\n[shear]\ngamma0 = -1\n")
    with pytest.raises(JobError) as info:
        load_job(path)
    text = str(info.value)
    assert text.startswith(f"{path}: 2 problems")
    assert "system.n_particles = 0" in text and "shear.gamma0 = -1" in text


def test_a_failed_key_does_not_cause_follow_up_errors():
    # periods is invalid, so discard_periods < periods is not checked against a default
    found = problems("[integration]\nperiods = 0\ndiscard_periods = 30\n")
    assert len(found) == 1 and found[0].startswith("integration.periods = 0")


@pytest.mark.parametrize("content, why", [(None, "No such file"),
                                          (b"\xff\xfe[job]\n", "not UTF-8")])
def test_unreadable_file(tmp_path, content, why):
    path = tmp_path / "job.toml"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(JobError) as info:
        load_job(path)
    assert why in str(info.value)


def test_directory_is_not_a_job_file(tmp_path):
    with pytest.raises(JobError, match="cannot read the job file"):
        load_job(tmp_path)


# --------------------------------------------------------------------------- --set


def test_overrides_replace_file_values_and_add_keys():
    job = load_job(DEMO, ["shear.gamma0=0.05", "system.phi=[0.2, 0.25]",
                          'job.name="other"', "output.per_particle=true",
                          "hydrodynamics.min_gap=1e-3", "shear.omega=1"])
    assert job.shear.gamma0 == 0.05 and job.system.phi == (0.2, 0.25)
    assert job.job.name == "other" and job.output.per_particle is True
    assert job.hydrodynamics.min_gap == 1e-3 and job.shear.omega == (1.0,)
    assert job.system.n_particles == 8  # untouched keys keep the file's value


def test_later_override_wins():
    job = load_job(DEMO, ["ensemble.realisations=3", "ensemble.realisations=5"])
    assert job.ensemble.realisations == 5


def test_override_with_invalid_literal_suggests_quotes():
    message = only_problem("", ["medium.kind=maxwell"])
    assert "medium.kind" in message and "not a TOML literal" in message
    assert "medium.kind=\"maxwell\"" in message and "[from --set]" in message


@pytest.mark.parametrize("item", ["nokey", "shear=1", "a.b.c=1", "shear.gamma0",
                                  "shear.gamma0=", "shear.gamma0=1\nx = 2"])
def test_malformed_override(item):
    message = only_problem("", [item])
    assert "[from --set]" in message


def test_override_unknown_key_gets_did_you_mean():
    message = only_problem("", ["shear.gamm0=0.1"])
    assert message.startswith("shear.gamm0 = 0.1: unknown key")
    assert 'did you mean "gamma0"' in message and message.endswith("[from --set]")
    assert 'did you mean "shear"' in only_problem("", ["sheer.gamma0=0.1"])


def test_override_value_is_validated_like_the_file():
    message = only_problem("", ["shear.gamma0=true"])
    assert "expected a number, got a boolean" in message and "[from --set]" in message


def test_override_switching_protocol_drops_the_files_other_keys():
    job = load_job(DEMO, ['shear.protocol="steady"', "integration.n_steps=50",
                          "integration.discard_steps=5"])
    assert job.shear.omega is None and job.integration.periods is None
    assert job.integration.n_steps == 50
    newtonian = load_job(ROOT / "jobs" / "schaink2000_maxwell.toml",
                         ['medium.kind="newtonian"'])
    assert newtonian.medium.modes is None
    # ...but a key set on the command line that does not apply is still an error
    message = only_problem("", ['shear.protocol="steady"', "shear.omega=[1.0]"])
    assert "shear.omega" in message and "does not apply" in message


# --------------------------------------------------------------------------- tasks


def test_tasks_ids_order_and_cost():
    job = parse_job("[system]\nn_particles = 8\nphi = [0.2, 0.3]\n"
                    "[shear]\nomega = [1.0, 2.0, 4.0]\n[ensemble]\nrealisations = 3\n"
                    "[integration]\nsteps_per_period = 10\nperiods = 4\ndiscard_periods = 1\n")
    tasks = enumerate_tasks(job)
    assert [t.task_id for t in tasks] == list(range(18))
    assert [(t.phi, t.omega, t.realisation) for t in tasks[:4]] == [
        (0.2, 1.0, 0), (0.2, 1.0, 1), (0.2, 1.0, 2), (0.2, 2.0, 0)]
    assert tasks[9].phi == 0.3 and tasks[9].omega == 1.0
    for t in tasks:
        assert t.n_steps == 40 and t.discard_steps == 10
        assert t.cost == 40 * 8 ** 3
        assert t.dt == pytest.approx(2 * math.pi / t.omega / 10)
    assert enumerate_tasks(job) == tasks  # deterministic


def test_dt_max_adds_steps_at_low_frequency():
    job = parse_job("[shear]\nomega = [6.283185307179586, 251.32741228718345]\n"
                    "[integration]\nsteps_per_period = 500\ndt_max = 5e-4\n")
    low, high = job.shear.omega
    assert job.steps_per_period(low) == 2000 and job.time_step(low) == pytest.approx(5e-4)
    assert job.steps_per_period(high) == 500 and job.time_step(high) == pytest.approx(5e-5)


def test_steady_tasks_have_no_omega():
    job = parse_job('[shear]\nprotocol = "steady"\n[ensemble]\nrealisations = 2\n')
    tasks = enumerate_tasks(job)
    assert [(t.omega, t.n_steps, t.dt) for t in tasks] == [(None, 10000, 1e-3)] * 2


# --------------------------------------------------------------------------- canonical form


def test_canonical_text_ignores_layout_comments_and_order():
    a = parse_job('[shear]\ngamma0 = 0.02\nprotocol = "oscillatory"\n[job]\nseed = 3\n')
    b = parse_job("# a comment\n[job]\nseed = 3 # here too\n[shear]\ngamma0 = 2e-2\n")
    assert canonical_text(a) == canonical_text(b) and job_hash(a) == job_hash(b)
    assert len(job_hash(a)) == 64


def test_every_backend_is_implemented():
    """Every choice of solver.backend is a registered backend (or the rule "auto")."""
    assert {"dense", "petsc-dense", "petsc-krylov", "auto"} <= set(SOLVER_BACKENDS.choices())
    for name in SOLVER_BACKENDS.choices():
        assert parse_job(f'[solver]\nbackend = "{name}"\n').solver.backend == name
        assert name == "auto" or SOLVER_BACKENDS[name].load().__name__.endswith("Solver")
    parse_job('[solver]\nbackend = "auto"\n', ["ensemble.ranks_per_task=2"])
    with pytest.raises(JobError, match="ensemble.ranks_per_task"):
        parse_job("", ["ensemble.ranks_per_task=2"])  # dense runs on one rank


def test_hash_changes_with_any_value():
    base = parse_job("")
    for override in ["job.seed=1", "shear.gamma0=0.03", "solver.backend=\"petsc-dense\"",
                     "ensemble.ranks_per_task=2", "output.checkpoint_every=7", 'solver.far_field="dense"']:
        other = parse_job("", [override, 'solver.backend="petsc-krylov"'] if "ranks" in override
                          else [override])
        assert job_hash(other) != job_hash(base), override


def test_resume_hash_ignores_only_layout_keys():
    assert LAYOUT_KEYS == {"ensemble.ranks_per_task", "output.checkpoint_every"}
    base = parse_job('[solver]\nbackend = "petsc-dense"\n')
    layout = parse_job('[solver]\nbackend = "petsc-dense"\n',
                       ["ensemble.ranks_per_task=2", "output.checkpoint_every=10"])
    physics = parse_job('[solver]\nbackend = "petsc-dense"\n', ["ensemble.realisations=8"])
    assert resume_hash(layout) == resume_hash(base) != resume_hash(physics)
    assert job_hash(layout) != job_hash(base)


def test_canonical_text_escapes_strings_and_writes_inf():
    job = parse_job('[job]\nname = "a \\"quoted\\" name \\\\ é"\n')
    text = canonical_text(job)
    assert parse_job(text) == job and "dt_max = inf" in text


# --------------------------------------------------------------------------- CLI


def test_cli_validate_ok(capsys):
    assert main(["validate", str(DEMO)]) == 0
    out = capsys.readouterr().out
    assert "job 'demo': valid" in out and "tasks: 4 = 1 phi x 2 omega x 2 realisations" in out
    steps = sum(t.n_steps for t in enumerate_tasks(load_job(str(DEMO))))
    assert f"; {steps} time steps in all;" in out


def test_cli_validate_checks_the_fewest_ranks_a_job_runs_on(capsys):
    """Without --ranks, validate checks ensemble.ranks_per_task ranks (a job of two
    ranks per task is valid as it stands) and says so; a count it cannot run on is
    refused with exit 2."""
    sets = ["--set", 'solver.backend="petsc-dense"', "--set", "ensemble.ranks_per_task=2"]
    assert main(["validate", str(DEMO), *sets]) == 0
    out = capsys.readouterr().out
    assert "checking for 2 ranks, the fewest this job runs on" in out and "valid" in out
    assert main(["validate", str(DEMO), *sets, "--ranks", "3"]) == 2
    assert "must be a multiple of ensemble.ranks_per_task = 2" in capsys.readouterr().err
    assert main(["validate", str(DEMO)]) == 0
    assert "checking for" not in capsys.readouterr().out


def test_cli_validate_the_large_n_job_as_it_stands(capsys):
    """jobs/large_n_krylov.toml (two ranks per task) validates without options: checked
    for its two ranks, on petsc-krylov with the spectral far field, with the memory that
    backend needs per rank at its N (`resources.memory_per_rank`)."""
    from sdmpi.config import resources

    path = ROOT / "jobs" / "large_n_krylov.toml"
    assert main(["validate", str(path)]) == 0
    out = capsys.readouterr().out
    assert "checking for 2 ranks, the fewest this job runs on" in out
    assert "backend petsc-krylov, spectral far field, 2 rank(s) per task" in out
    need = resources.memory_per_rank(load_job(str(path)), "petsc-krylov")
    assert need > resources.BASE_BYTES + 2 ** 26  # the backend's share at N = 1000: ~72 MiB
    assert f"memory: about {resources.gib(need)} per rank" in out


def test_cli_validate_names_the_krylov_far_field(capsys):
    """For petsc-krylov the summary says which far field runs: by N (dense below
    krylov.DENSE_FAR_FIELD_MAX_N, spectral from there on) or as solver.far_field says."""
    from sdmpi.hydro.krylov import DENSE_FAR_FIELD_MAX_N

    cases = [(27, None, "dense"), (DENSE_FAR_FIELD_MAX_N + 16, None, "spectral"), (27, "spectral", "spectral")]
    for n, far, kind in cases:
        extra = ["--set", f'solver.far_field="{far}"'] if far else []
        assert main(["validate", str(DEMO), "--set", 'solver.backend="petsc-krylov"',
                     "--set", f"system.n_particles={n}", *extra]) == 0
        assert f"backend petsc-krylov, {kind} far field" in capsys.readouterr().out, (n, far)


def test_cli_validate_with_overrides(capsys):
    assert main(["validate", str(DEMO), "--set", "ensemble.realisations=3",
                 "--set", "system.phi=[0.2, 0.3]"]) == 0
    assert "tasks: 12 = 2 phi x 2 omega x 3 realisations" in capsys.readouterr().out


def test_cli_validate_bad_job_lists_every_problem(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text("[system]\nn_partcles = 8\n[shear]\ngamma0 = 5\n")
    assert main(["validate", str(path), "--set", "ensemble.realisations=0"]) == 2
    err = capsys.readouterr().err
    assert "3 problems" in err and 'did you mean "n_particles"' in err
    assert "shear.gamma0 = 5" in err and "ensemble.realisations = 0" in err


@pytest.mark.parametrize("argv", [[], ["validate"], ["frobnicate"],
                                  ["validate", "x.toml", "--bogus"],
                                  ["validate", "does-not-exist.toml"]])
def test_cli_bad_arguments_exit_2(argv, capsys):
    assert main(argv) == 2
    assert capsys.readouterr().err.strip()


@pytest.mark.parametrize("argv", [["--help"], ["validate", "--help"]])
def test_cli_help(argv, capsys):
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "validate" in out and ("--set" in out or "COMMAND" in out)


def _tree(path):
    return sorted((str(p.relative_to(path)), p.stat().st_mtime_ns)
                  for p in path.rglob("*"))


@pytest.mark.parametrize("content, code", [(DEMO.read_text(), 0), ("[system]\nphi = 2\n", 2)])
def test_cli_subprocess_exit_code_and_writes_nothing(tmp_path, content, code):
    (tmp_path / "job.toml").write_text(content)
    before = _tree(tmp_path)
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1",
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    result = subprocess.run([sys.executable, "-m", "sdmpi.cli", "validate", "job.toml"],
                            cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)
    assert result.returncode == code, result.stderr
    assert (result.stdout if code == 0 else result.stderr).strip()
    assert _tree(tmp_path) == before


def test_initial_configuration_and_repulsion_range_checked():
    with pytest.raises(JobError) as err:
        parse_job("[system]\nn_particles = 30\nphi = [0.3, 0.61]\n")
    text = str(err.value)
    assert "system.n_particles" not in text  # any N: the start need not fill a lattice
    assert "system.phi[1] = 0.61" in text and "phi < 0.6" in text
    with pytest.raises(JobError, match=r"interparticle.tau = 5.*tau >= 13.8"):
        parse_job('[interparticle]\nkind = "repulsion"\nf0 = 1.0\ntau = 5.0\n')


def test_maxwell_medium_with_interparticle_forces_is_refused():
    with pytest.raises(JobError, match="interparticle.kind.*Maxwell medium"):
        parse_job('[medium]\nkind = "maxwell"\nmodes = [{eta = 1.0, lambda = 0.5}]\n'
                  '[interparticle]\nkind = "repulsion"\nf0 = 1.0\ntau = 300.0\n')


def test_config_imports_nothing_from_the_physics():
    """`sdmpi.config` sits below `hydro` and `dynamics` (DESIGN.md): none of its modules
    imports them, not even inside a function (physics checks live in `dynamics.checks`)."""
    import ast

    config = Path(__file__).resolve().parents[1] / "sdmpi" / "config"
    for path in sorted(config.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                names = [("." * node.level) + (node.module or "")]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                assert not name.startswith(("..dynamics", "..hydro", "sdmpi.dynamics", "sdmpi.hydro")), \
                    f"{path.name}:{node.lineno} imports {name}"
