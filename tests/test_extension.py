"""Extension is local: a solver backend, a hydrodynamic model, an interparticle force and a
writer defined outside the package (tests/extension_plugin.py, one module that registers them)
run jobs through `sdmpi run`,
and the job loader's choices, checks and estimates follow the registries
(`sdmpi.registry`, docs/extending.md)."""

import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import sdmpi
from sdmpi.cli import main
from sdmpi.config import JobError, parse_job, resources
from sdmpi.config.checks import scheme_problems
from sdmpi.dynamics.drift import BrownianTerms
from sdmpi.registry import (DRIFT_SCHEMES, FORCES, HYDRODYNAMIC_MODELS, INTEGRATORS, SOLVER_BACKENDS,
                            WRITERS, BackendSpec, DriftSpec, ForceSpec, IntegratorSpec, ModelSpec, Spec)

from .runs import child_env, fresh_lubrication_tables

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "jobs" / "demo.toml"
PLUGIN = Path(__file__).with_name("extension_plugin.py")
#: one task of 20 steps
ONE_TASK = ["ensemble.realisations=1", "shear.omega=[25.132741228718345]", "integration.periods=1",
            "integration.discard_periods=0", "integration.steps_per_period=20"]


def _plugin(out, sets, *flags, env=None):
    """`sdmpi run` of demo.toml with ``sets`` into ``out``, with the plugin's registrations."""
    cmd = [sys.executable, str(PLUGIN), "run", str(DEMO), "-o", str(out), *flags]
    for item in sets:
        cmd += ["--set", item]
    return subprocess.run(cmd, capture_output=True, text=True, env=child_env(env), timeout=600)


def _run_with_plugin(tmp_path, sets, state=False):
    """The samples of the one task of demo.toml with ``sets``, run by `sdmpi run` with the
    plugin's registrations (state: and the state of its last checkpoint)."""
    out = tmp_path / "run.h5"
    res = _plugin(out, sets)
    assert res.returncode == 0, res.stderr
    with h5py.File(out, "r") as f:
        samples = {name: data[()] for name, data in f["tasks/000000/samples"].items()}
        if not state:
            return samples
        ckpt = f["checkpoints/000000"]
        slot = int(np.argmax(ckpt["slot_step"][()]))
        return samples, {name: data[()] for name, data in ckpt[f"slot{slot}"].items()}


def _api_samples(sets):
    """The same task's samples with sdmpi's own implementations (the Python API)."""
    job = sdmpi.load_job(DEMO, sets)
    fresh_lubrication_tables()
    real = sdmpi.Realisation(job, sdmpi.tasks(job)[0])
    return real.advance(real.n_steps)


def test_registered_backend_runs_a_job(tmp_path):
    """A Brownian Stokesian job (rfd drift; the near-contact correction, with the generic
    mobility_forms, acts: gaps down to 7e-3) on the plugin's numpy Cholesky backend gives
    the dense backend's samples: the same factor of R_FU, so the same numbers up to
    rounding, which the random finite difference amplifies (it divides a difference of
    solves by a length ~1e-6, `dynamics.models`) and 20 steps carry into the positions:
    agreement to 1e-8 of each sample's largest value (measured: 2e-10)."""
    ours = _run_with_plugin(tmp_path, [*ONE_TASK, 'solver.backend="numpy-cholesky"'])
    dense = _api_samples(ONE_TASK)
    assert set(ours) == set(dense)
    for name in ("stress_hydrodynamic", "stress_brownian", "strain", "min_gap"):
        scale = np.abs(dense[name]).max()
        assert np.abs(ours[name] - dense[name]).max() <= 1e-8 * scale, name
    assert np.abs(dense["stress_brownian"]).max() > 0  # the Brownian terms were exercised


def test_registered_model_runs_a_job(tmp_path):
    """A model that doubles the medium's viscosity (the plugin's): a non-Brownian free-draining
    job moves the same (no forces, dilute: no collisions) and has twice the hydrodynamic
    stress, exactly (a factor 2 is exact in floating point)."""
    sets = [*ONE_TASK, "brownian.enabled=false", "system.phi=[0.05]"]
    ours = _run_with_plugin(tmp_path, [*sets, 'hydrodynamics.model="viscous-free-draining"'])
    plain = _api_samples([*sets, 'hydrodynamics.model="free-draining"'])
    assert not plain["n_overlaps"].any() and np.abs(plain["stress_hydrodynamic"]).max() > 0
    assert np.array_equal(ours["stress_hydrodynamic"], 2.0 * plain["stress_hydrodynamic"])
    for name in ("strain", "min_gap", "stress_collision", "n_overlaps"):
        assert np.array_equal(ours[name], plain[name]), name


def test_registered_writer_is_committed_resumed_and_extended(tmp_path):
    """The plugin's writer (the time of every step, extra/000000/time) through a run killed
    after its second checkpoint, its resume and an extension to twice the length: every row
    equals the sample stream's time of that step, bit for bit (both are the same value);
    `sdmpi info` shows the writer's line."""
    out = tmp_path / "run.h5"
    sets = [*ONE_TASK, 'hydrodynamics.model="free-draining"', "output.checkpoint_every=5"]
    killed = _plugin(out, sets, env={"SDMPI_TEST_KILL": "commit:2"})
    assert killed.returncode != 0
    with h5py.File(out, "r") as f:
        assert f["progress"][0] == 5  # the first checkpoint alone is committed
    for more, flags in (([], ()), (["integration.periods=2"], ("--extend",))):
        res = _plugin(out, [*sets, *more], *flags)
        assert res.returncode == 0, res.stderr
    with h5py.File(out, "r") as f:
        assert f["progress"][0] == 40
        times, samples = f["extra/000000/time"][()], f["tasks/000000/samples/time"][()]
    assert times.shape == (40,) and np.all(np.diff(times) > 0)
    assert np.array_equal(times, samples)
    # `sdmpi info` reports every registered writer by its own line
    info = subprocess.run([sys.executable, str(PLUGIN), "info", str(out)], capture_output=True,
                          text=True, env=child_env(), timeout=600)
    assert info.returncode == 0, info.stderr
    assert "step times: 40 committed (extra/NNNNNN/time)" in info.stdout, info.stdout


class _Sized:
    """A writer as far as the size estimate sees it."""

    def enabled(self, job):
        return True

    def file_bytes(self, job):
        return 1000.0


def test_the_size_estimate_counts_every_registered_writer():
    """`sdmpi validate`'s run-file size is the sum over the registry: a registered writer
    adds its bytes."""
    from sdmpi.ensemble.store import run_file_bytes

    job = sdmpi.load_job(DEMO, ONE_TASK)
    without = run_file_bytes(job)
    WRITERS.register(Spec("test-sized", "a test writer", _Sized))
    try:
        assert run_file_bytes(job) - without == 1000.0
    finally:
        WRITERS.unregister("test-sized")


def test_registered_force_runs_a_job(tmp_path):
    """A force registered by the plugin (the repulsion as two exact halves, one of which
    samples and checkpoints its own count) gives the samples of interparticle.kind =
    "repulsion" bit for bit, reads the keys f0 and tau like it, and its own sample field
    and state reach the run file."""
    sets = [*ONE_TASK, "interparticle.f0=1.0", "interparticle.tau=300.0"]
    ours, state = _run_with_plugin(tmp_path, [*sets, 'interparticle.kind="split-repulsion"'], state=True)
    plain = _api_samples([*sets, 'interparticle.kind="repulsion"'])
    assert set(ours) == set(plain) | {"pairs_seen"}
    for name, values in plain.items():
        assert np.array_equal(ours[name], values), name
    assert np.abs(plain["stress_interparticle"]).max() > 0  # the force acted
    seen = ours["pairs_seen"]
    assert seen[0] > 0 and np.all(np.diff(seen) >= 0) and state["pairs_seen"][0] == seen[-1]


@pytest.fixture
def registered():
    """A backend that solves on several ranks without dense matrices, and a model with
    lubrication, registered for one test."""
    backend = SOLVER_BACKENDS.register(BackendSpec("test-gpu", "a test backend", "nowhere:Solver",
                                                   several_ranks=True, matrix_free=True))
    model = HYDRODYNAMIC_MODELS.register(ModelSpec("test-model", "a test model", "nowhere:Model",
                                                   lubrication=True))
    yield backend, model
    SOLVER_BACKENDS.unregister(backend.name)
    HYDRODYNAMIC_MODELS.unregister(model.name)


def test_loader_follows_the_registries(registered, capsys):
    """Registered names become choices; the checks, the memory estimate and `sdmpi validate`
    read the specs (which never import the implementation: it is nowhere)."""
    assert main(["validate", str(DEMO), "--set", 'solver.backend="test-gpu"']) == 0
    assert "backend test-gpu, dense far field, 1 rank(s) per task" in capsys.readouterr().out  # matrix-free
    job = parse_job('[solver]\nbackend = "test-gpu"\n[hydrodynamics]\nmodel = "test-model"\n',
                    ["ensemble.ranks_per_task=2"])
    assert resources.dense_bytes(job, "test-gpu") == 0.0  # no dense matrices
    with pytest.raises(JobError, match='"midpoint" .or absent. with solver.backend = "test-gpu"'):
        parse_job('[solver]\nbackend = "test-gpu"\n[brownian]\nscheme = "rfd"\n')  # matrix-free
    with pytest.raises(JobError, match='allowed: 1, or solver.backend = "petsc-dense", "petsc-krylov", '
                                       '"test-gpu" or "auto"'):
        parse_job("", ["ensemble.ranks_per_task=2"])
    with pytest.raises(JobError, match='applies to the stokesian and test-model model only'):
        parse_job('[hydrodynamics]\nmodel = "far-field"\nlubrication = false\n')


@pytest.fixture
def registered_force():
    """A non-Brownian force with contacts that reads interparticle.mu and may act in
    monolayers, registered for one test."""
    force = FORCES.register(ForceSpec("test-force", "a test force", "nowhere:build", keys=("mu",),
                                      brownian=False, monolayer=True, contacts=True))
    yield force
    FORCES.unregister(force.name)


def test_loader_follows_the_force_registry(registered_force):
    """A registered force is an interparticle.kind choice whose keys apply, and the checks read
    its spec (never its builder, which is nowhere): Brownian jobs refused, monolayers
    allowed, contacts need lubrication and an integrator that integrates them."""
    steady = '[brownian]\nenabled = false\n[shear]\nprotocol = "steady"\nrate = 1.0\n'
    job = parse_job(steady + '[interparticle]\nkind = "test-force"\nmu = 0.5\n')
    assert job.interparticle.mu == 0.5
    with pytest.raises(JobError, match="interparticle.mu.* required"):
        parse_job(steady + '[interparticle]\nkind = "test-force"\n')
    with pytest.raises(JobError, match='brownian.enabled = true: the test-force force is a non-Brownian model'):
        parse_job('[interparticle]\nkind = "test-force"\nmu = 0.5\n')
    monolayer = ('[system]\ngeometry = "monolayer"\nn_particles = 25\nphi = [0.4]\n'
                 '[integration]\ndt = 0.01\nn_steps = 10\ndiscard_steps = 0\n')
    with pytest.raises(JobError) as err:
        parse_job(steady + monolayer + '[interparticle]\nkind = "vdw"\nhamaker = 1.0\ncap_gap = 0.01\n')
    assert '"none", "repulsion" or "test-force"' in str(err.value)
    with pytest.raises(JobError, match="test-force contacts need the lubrication"):
        parse_job(steady + '[hydrodynamics]\nmodel = "far-field"\n[interparticle]\nkind = "test-force"\nmu = 0.5\n')
    with pytest.raises(JobError, match="does not integrate the history of the test-force contacts"):
        parse_job(steady + '[integration]\nscheme = "adams-bashforth-4"\ndt = 0.01\nn_steps = 10\n'
                  'discard_steps = 0\n[interparticle]\nkind = "test-force"\nmu = 0.5\n')


def test_unregistered_names_are_refused():
    with pytest.raises(JobError, match='solver.backend = "test-gpu": not a valid choice.*'
                                       'one of "dense", "petsc-dense", "petsc-krylov", "auto"'):
        parse_job('[solver]\nbackend = "test-gpu"\n')
    with pytest.raises(JobError, match='interparticle.kind = "test-force": not a valid choice.*'
                                       'one of "repulsion", "vdw", "dlvo", "frictional", "none"'):
        parse_job('[interparticle]\nkind = "test-force"\n')
    with pytest.raises(ValueError, match="registered already"):
        SOLVER_BACKENDS.register(BackendSpec("dense", "again", "nowhere:Solver"))


class NoDrift:
    """Brownian velocities without drift or Brownian stress (the example of
    docs/extending.md)."""

    def brownian(self, evaluation, z, kT, dt, near, z_stress=None):
        m = evaluation.solver.brownian_velocities(z)
        return BrownianTerms(np.sqrt(2 * kT / dt) * m + near(m), np.zeros((evaluation.n_particles, 5)))


@pytest.fixture
def no_drift():
    """NoDrift registered as brownian.scheme = "no-drift" (direct backends only), and an
    integrator of deterministic motion, for one test."""
    drift = DRIFT_SCHEMES.register(DriftSpec("no-drift", "no drift", NoDrift, matrix_free=False,
                                             why_not="a test of the direct backends"))
    integrator = INTEGRATORS.register(IntegratorSpec("test-deterministic", "a test integrator", "nowhere:Cls",
                                                     brownian=False))
    yield drift
    DRIFT_SCHEMES.unregister(drift.name)
    INTEGRATORS.unregister(integrator.name)


def test_registered_drift_scheme_and_integrator_are_choices_and_checked(no_drift):
    """A registered drift scheme runs a Brownian job (its zero Brownian stress is in the
    samples; the same noise as rfd, so the first step's start is the same) and is refused
    on a matrix-free backend with its own reason; a registered integrator's spec drives
    the Brownian check without importing it."""
    sets = ["system.n_particles=4", "ensemble.realisations=1"]
    fresh_lubrication_tables()
    ours = sdmpi.Realisation(sdmpi.load_job(DEMO, [*sets, 'brownian.scheme="no-drift"']), 0).advance(3)
    fresh_lubrication_tables()
    rfd = sdmpi.Realisation(sdmpi.load_job(DEMO, [*sets, 'brownian.scheme="rfd"']), 0).advance(3)
    assert not np.asarray(ours["stress_brownian"]).any() and np.asarray(rfd["stress_brownian"]).any()
    assert np.array_equal(ours["stress_hydrodynamic"][0], rfd["stress_hydrodynamic"][0])
    assert not np.array_equal(ours["stress_hydrodynamic"][1:], rfd["stress_hydrodynamic"][1:])
    # it suits the direct backends and petsc-krylov (which has mobility_change), not a
    # matrix-free backend without it; solver.backend = "auto" is judged by what it stands
    # for (`sdmpi run` and `validate` resolve it, the loader cannot)
    assert parse_job('[solver]\nbackend = "petsc-krylov"\n[brownian]\nscheme = "no-drift"\n')
    iterative = SOLVER_BACKENDS.register(BackendSpec("test-iterative", "a test", "nowhere:Cls", matrix_free=True))
    try:
        with pytest.raises(JobError, match=r'brownian.scheme = "no-drift": a test of the direct backends; '
                                           r'allowed: "midpoint" \(or absent\) with solver.backend = "test-iterative"'):
            parse_job('[solver]\nbackend = "test-iterative"\n[brownian]\nscheme = "no-drift"\n')
        job = sdmpi.load_job(DEMO, ['solver.backend="auto"', 'brownian.scheme="no-drift"'])
        assert 'with solver.backend = "test-iterative" (what "auto" stands for with' in str(
            scheme_problems(job, "test-iterative")[0])
    finally:
        SOLVER_BACKENDS.unregister(iterative.name)
    with pytest.raises(JobError, match=r'integration.scheme = "test-deterministic": .* allowed: '
                                       r'"euler-maruyama", or brownian.enabled = false'):
        parse_job('[integration]\nscheme = "test-deterministic"\n')
