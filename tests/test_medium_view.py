"""`sdmpi reduce --medium`: a Maxwell medium applied after the fact to a Newtonian run's
stored hydrodynamic stress equals a direct Maxwell run of the same job seed (Schaink et
al. 2000 sec. II C: same trajectories, linear filter of the stresslets, eqs. 33-35, 42)."""

import csv
import math

import numpy as np
import pytest

from sdmpi.analysis.medium_view import (MediumError, filtered_stress, label, parse_medium,
                                        view_job)
from sdmpi.analysis.reduce import TABLE_COMPONENTS, ReduceError, reduce_runs
from sdmpi.cli import main
from sdmpi.config import Medium, Mode
from .synthetic_run import write_run
from .test_reduce import MODULI, job_text
from .tiny_runs import MEDIUM_SPEC, maxwell_run, sdmpi_run


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("medium")
    return sdmpi_run(d / "newt.h5"), maxwell_run(d / "maxw.h5")


def table(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_maxwell_view_of_a_newtonian_run_equals_the_direct_maxwell_run(runs, tmp_path):
    newt, maxw = runs
    out = tmp_path / "out"
    assert main(["reduce", str(newt), "-o", str(out), "--no-plots",
                 "--medium", MEDIUM_SPEC]) == 0
    assert main(["reduce", str(maxw), "-o", str(tmp_path / "direct"), "--no-plots"]) == 0
    name = "maxwell_eta0.6_lambda0.5_eta0.4_lambda0.05"
    head_v, view = table(out / name / "moduli.csv")
    head_d, direct = table(tmp_path / "direct" / "moduli.csv")
    assert head_v == head_d and len(view) == len(direct) == 2 * len(TABLE_COMPONENTS)
    compared = 0
    for rv, rd in zip(view, direct):
        assert rv[:4] == rd[:4]
        for a, b in zip(rv[4:], rd[4:]):
            # same trajectories; the filter applied to the bulk instead of per particle:
            # equal to rounding (a few ulp of the largest stress, relative 1e-12)
            assert math.isclose(float(a), float(b), rel_tol=1e-12, abs_tol=1e-12), (rv, rd)
            compared += 1
    assert compared == 2 * len(TABLE_COMPONENTS) * 8
    # the Newtonian tables beside it are the plain Newtonian reduction
    assert (out / "moduli.csv").read_bytes() != (out / name / "moduli.csv").read_bytes()
    red = reduce_runs([newt])
    assert red.job.medium.kind == "newtonian" and not red.viewed


def test_filtered_series_equals_the_stored_maxwell_stress(runs):
    import h5py
    newt, maxw = runs
    medium = parse_medium(MEDIUM_SPEC)
    with h5py.File(newt) as a, h5py.File(maxw) as b:
        for key in a["tasks"]:
            viscous = a[f"tasks/{key}/samples/stress_hydrodynamic"][()]
            same = b[f"tasks/{key}/samples/stress_hydrodynamic"][()]
            np.testing.assert_array_equal(viscous, same)          # the same trajectories
            stored = b[f"tasks/{key}/samples/stress_hydrodynamic_maxwell"][()]
            got = filtered_stress(viscous, medium, a[f"tasks/{key}"].attrs["dt"])
            assert np.abs(got - stored).max() < 1e-14 * np.abs(stored).max()
            assert np.all(got[0] == 0.0)                 # S_k(0) = 0, as the run starts


def test_the_newtonian_view_of_a_maxwell_run_is_the_newtonian_run(runs, tmp_path):
    newt, maxw = runs
    assert main(["reduce", str(maxw), "-o", str(tmp_path), "--no-plots",
                 "--medium", "newtonian"]) == 0
    assert main(["reduce", str(newt), "-o", str(tmp_path / "n"), "--no-plots"]) == 0
    assert ((tmp_path / "newtonian" / "moduli.csv").read_bytes()
            == (tmp_path / "n" / "moduli.csv").read_bytes())


def test_filter_of_one_mode_matches_the_analytic_response():
    """A sinusoidal source S_0 = sin(w t) switched on at t = 0: the mode's exact response
    (lambda dS/dt + S = eta S_0, S(0) = 0) is
    eta [sin(w t) - w lam cos(w t) + w lam exp(-t/lam)] / (1 + (w lam)^2); the
    linear-source update is exact to O(dt^2) for a smooth source."""
    w, lam, eta, dt = 2 * math.pi, 0.3, 1.0, 1e-4
    t = dt * np.arange(20000)
    got = filtered_stress(np.sin(w * t), Medium("maxwell", (Mode(eta, lam),)), dt)
    exact = eta * (np.sin(w * t) - w * lam * np.cos(w * t) + w * lam * np.exp(-t / lam)) \
        / (1 + (w * lam) ** 2)
    assert np.abs(got - exact).max() < 1e-7


@pytest.mark.parametrize("spec, message", [
    ("maxwell", "unknown medium"), ("viscous", "unknown medium"),
    ("maxwell:eta=1", "needs both eta and lambda"),
    ("maxwell:eta=1,lambda=x", "is not a number"),
    ("maxwell:eta=1,lambda=-2", "must be a finite number > 0"),
    ("maxwell:eta=1,tau=2", "must be eta=E,lambda=L"),
    ("maxwell:eta=0.5,lambda=0.5", "sum to 0.5"),
    ("maxwell:eta=1,lambda=1e-9", "shortest Maxwell relaxation time"),
])
def test_bad_medium_specs_exit_2_and_write_nothing(tmp_path, capsys, spec, message):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002, seed=3)
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out), "--medium", spec]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


def test_medium_from_a_toml_file_and_labels(tmp_path):
    f = tmp_path / "medium.toml"
    f.write_text('[medium]\nkind = "maxwell"\nmodes = [{eta = 1.0, lambda = 0.5}]\n')
    medium = parse_medium(str(f))
    assert medium == parse_medium("maxwell:eta=1,lambda=0.5")
    assert label(medium) == "maxwell_lambda0.5"
    assert label(parse_medium("newtonian")) == "newtonian"
    f.write_text('[medium]\nkind = "maxwell"\nmodes = [{eta = 1.0, lambda = 0.5}]\ncolour = 1\n')
    with pytest.raises(MediumError, match="medium.colour"):
        parse_medium(str(f))
    with pytest.raises(MediumError, match="not a readable TOML"):
        parse_medium(str(tmp_path / "missing.toml"))
    from sdmpi.config import parse_job
    job = view_job(parse_job(job_text()), medium)
    assert job.medium == medium
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002, seed=3)
    with pytest.raises(ReduceError, match="sum to 2"):
        reduce_runs([run], medium=parse_medium("maxwell:eta=1,lambda=1;eta=1,lambda=2"))
