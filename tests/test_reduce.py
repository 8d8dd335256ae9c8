"""Gather and reduce (issue 5): run files -> moduli.csv / moduli.h5 / figures.

Run files are synthetic (tests/synthetic_run.py): the layout of docs/store.md written
serially with h5py, with xy stresses of known moduli plus correlated (AR(1)) noise. Fixed
seeds; "within errors" means a deviation that a correct reduction exceeds with
probability 1e-4 (Student t with the ensemble's degrees of freedom); test_projection.py
checks the coverage of the error bars themselves."""

import csv
import math
import warnings

import h5py
import numpy as np
import pytest
from scipy.stats import t as student_t

from sdmpi.analysis.analytic import maxwell_moduli, maxwell_viscosity
from sdmpi.analysis.reduce import (TABLE_COMPONENTS, MODULI_COLUMNS, PartialRunWarning, ReduceError,
                                   reduce_runs)
from sdmpi.analysis.report import write_all
from sdmpi.cli import main
from sdmpi.config import enumerate_tasks, parse_job
from .synthetic_run import write_run

W1, W2 = 2 * math.pi, 8 * math.pi


def job_text(seed=1, realisations=3, phi="[0.3, 0.45]", medium='kind = "newtonian"',
             protocol="oscillatory", periods=24, discard=4, spp=16, extra=""):
    shear = (f'protocol = "oscillatory"\ngamma0 = 0.02\nomega = [{W1!r}, {W2!r}]'
             if protocol == "oscillatory" else
             'protocol = "steady"\nrate = 2.0' if protocol == "steady" else 'protocol = "none"')
    integ = (f"steps_per_period = {spp}\nperiods = {periods}\ndiscard_periods = {discard}\n"
             f"dt_max = 0.02" if protocol == "oscillatory" else
             "dt = 0.001\nn_steps = 400\ndiscard_steps = 100")
    return f"""
[job]
name = "synthetic"
seed = {seed}
[system]
n_particles = 8
phi = {phi}
[medium]
{medium}
[shear]
{shear}
[brownian]
enabled = true
[integration]
{integ}
[ensemble]
realisations = {realisations}
{extra}"""


def z_bound(dof):
    """|mean - truth|/err stays below this with probability 1 - 1e-4 (t, dof d.o.f.)."""
    return student_t.ppf(1 - 0.5e-4, dof)


MAXWELL = 'kind = "maxwell"\nmodes = [{eta = 0.7, lambda = 0.5}, {eta = 0.3, lambda = 0.05}]'


def truth(task):
    """Known moduli per contribution, depending on (phi, omega)."""
    s = task.omega / W1
    return {"hydrodynamic": (0.1 * s, 2.0 * s + task.phi),
            "brownian": (0.6 / s, 0.9 - task.phi),
            "interparticle": (0.05, -0.02)}


MODULI = {c: (lambda c: lambda task: truth(task)[c])(c) for c in ("hydrodynamic", "brownian",
                                                                   "interparticle")}


def rows_of(path):
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        return next(reader), list(reader)


# ----------------------------------------------------------------------------- table


def test_moduli_csv_columns_rows_and_known_moduli(tmp_path):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=16), MODULI, noise=0.003, tau=8.0, seed=3)
    red = reduce_runs([run])
    paths, _ = write_all(red, tmp_path / "out", plots=False)
    header, rows = rows_of(tmp_path / "out" / "moduli.csv")
    assert tuple(header) == MODULI_COLUMNS
    assert len(rows) == 2 * 2 * len(TABLE_COMPONENTS)
    keys = [(float(r[0]), float(r[1]), r[2]) for r in rows]
    assert keys == [(p, w, c) for p in (0.3, 0.45) for w in (W1, W2) for c in TABLE_COMPONENTS]
    job = parse_job(red.job_text)
    for task in enumerate_tasks(job)[::16]:                 # one task per (phi, omega)
        exact = truth(task)
        exact["medium"] = (0.0, task.omega)                 # Newtonian: G' = 0, G'' = w
        exact["total"] = tuple(map(sum, zip(*exact.values())))
        for comp, (g1, g2) in exact.items():
            row = {k: red.value(task.phi, task.omega, comp, k) for k in MODULI_COLUMNS[3:]}
            assert row["n_realisations"] == 16
            for name, value, err in (("G_prime", g1, row["G_prime_err"]),
                                     ("G_dprime", g2, row["G_dprime_err"])):
                if comp == "medium":
                    assert row[name] == value and err == 0.0
                else:
                    assert 0 < err < 0.05
                    assert abs(row[name] - value) < z_bound(15) * err, (comp, name)
            assert row["eta_prime"] == pytest.approx(row["G_dprime"] / task.omega, rel=1e-14)
            assert row["eta_dprime"] == pytest.approx(row["G_prime"] / task.omega, rel=1e-14)
            assert row["eta_prime_err"] == pytest.approx(row["G_dprime_err"] / task.omega,
                                                         rel=1e-14)
    # total = medium + the contributions, in the mean
    mean = red.ensemble.mean
    np.testing.assert_allclose(mean[:, -1], mean[:, :-1].sum(axis=1), rtol=1e-13, atol=1e-15)


def test_maxwell_medium_row_is_seed_eq36_and_hydrodynamic_is_the_filtered_stress(tmp_path):
    run = tmp_path / "run.h5"
    write_run(run, job_text(medium=MAXWELL, phi="[0.45]"), {"hydrodynamic": (0.4, 1.1)},
              viscous=(50.0, 70.0), noise=0.002, seed=5)
    red = reduce_runs([run])
    eta, lam = [0.7, 0.3], [0.5, 0.05]
    for w in (W1, W2):
        g1, g2 = maxwell_moduli(w, eta, lam)
        e1, e2 = maxwell_viscosity(w, eta, lam)
        assert red.value(0.45, w, "medium", "G_prime") == float(g1)
        assert red.value(0.45, w, "medium", "G_dprime") == float(g2)
        assert red.value(0.45, w, "medium", "eta_prime") == pytest.approx(float(e1), rel=1e-15)
        assert red.value(0.45, w, "medium", "eta_dprime") == pytest.approx(float(e2), rel=1e-15)
        assert red.value(0.45, w, "medium", "G_prime_err") == 0.0
        # stress_hydrodynamic_maxwell (0.4, 1.1), not the viscous stress_hydrodynamic
        assert red.value(0.45, w, "hydrodynamic", "G_prime") == pytest.approx(0.4, abs=0.02)
        assert red.value(0.45, w, "hydrodynamic", "G_dprime") == pytest.approx(1.1, abs=0.02)
        total = red.value(0.45, w, "total", "G_dprime")
        parts = sum(red.value(0.45, w, c, "G_dprime") for c in TABLE_COMPONENTS[:-1])
        assert total == pytest.approx(parts, rel=1e-13)


def test_results_do_not_depend_on_how_realisations_are_spread_over_files(tmp_path):
    """The same 4 realisation signals in one file (seed 1), or 3 + 1 in two files of
    seeds 2 and 3 (any order), give the same ensemble numbers."""
    one = tmp_path / "one.h5"
    data = write_run(one, job_text(realisations=4), MODULI, noise=0.004, tau=6.0, seed=7)
    n_groups = 4

    def part(path, seed, reals):
        mapping = {g * len(reals) + i: data[g * 4 + r]
                   for g in range(n_groups) for i, r in enumerate(reals)}
        write_run(path, job_text(seed=seed, realisations=len(reals)), {}, tasks=mapping)

    part(tmp_path / "a.h5", 2, [0, 1, 2])
    part(tmp_path / "b.h5", 3, [3])
    ref = reduce_runs([one])
    for files in (["a.h5", "b.h5"], ["b.h5", "a.h5"]):
        red = reduce_runs([tmp_path / f for f in files])
        for field in ("mean", "err", "dof", "n_realisations", "n_periods"):
            np.testing.assert_allclose(getattr(red.ensemble, field),
                                       getattr(ref.ensemble, field), rtol=1e-12, atol=1e-15)
        assert red.rows()[7]["component"] == ref.rows()[7]["component"]


def test_partial_run_reduces_what_is_committed_and_says_so(tmp_path, capsys):
    run = tmp_path / "run.h5"
    text = job_text(realisations=3, phi="[0.3]")
    job = parse_job(text)
    spp, start = job.steps_per_period(W1), job.discard_steps(W1)   # 50 and 200 at 2 pi
    progress = {0: 0, 1: start + spp - 1, 2: start + 3 * spp + 5}
    write_run(run, text, MODULI, noise=0.002, progress=progress, seed=11)
    with pytest.warns(PartialRunWarning, match="3 of 6 tasks unfinished"):
        red = reduce_runs([run])
    assert not red.complete
    notes = "\n".join(red.notes)
    for tid in (0, 1):
        assert f"task {tid} " in notes
    assert notes.count("contributes nothing") == 2              # tasks 0 and 1
    assert "task 2 " in notes and "3 of 20 periods used" in notes
    # group (0.3, 2 pi) keeps one realisation with 3 periods; never reads past progress
    # (the synthetic file holds 1e30 there)
    assert red.value(0.3, W1, "hydrodynamic", "n_realisations") == 1
    assert red.per_realisation.n[0, 1, 0].tolist() == [0, 0, 3]
    assert abs(red.value(0.3, W1, "total", "G_dprime")) < 100
    assert "single realisation" in notes
    assert main(["reduce", str(run), "-o", str(tmp_path / "out"), "--no-plots"]) == 0
    err = capsys.readouterr().err
    assert "PARTIAL RUN" in err and "contributes nothing" in err


def test_nothing_committed_gives_nan_rows_but_exact_medium(tmp_path):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, progress=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        red = reduce_runs([run])
    assert math.isnan(red.value(0.3, W2, "total", "G_prime"))
    assert red.value(0.3, W2, "medium", "G_dprime") == W2
    assert "no realisation has data" in "\n".join(red.notes)


# ----------------------------------------------------------------------------- bad input


def test_non_run_files_give_a_clear_error_and_exit_2(tmp_path, capsys):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["data"] = np.arange(3)
    text = tmp_path / "text.h5"
    text.write_text("not hdf5\n")
    damaged = tmp_path / "damaged.h5"
    write_run(damaged, job_text(realisations=1), MODULI)
    with h5py.File(damaged, "a") as f:
        del f["tasks/000001/samples/stress_brownian"]
    cases = {foreign: "not an sdmpi run file", text: "not a readable HDF5 file",
             tmp_path / "missing.h5": "no such file", damaged: "stress_brownian"}
    for path, message in cases.items():
        with pytest.raises(ReduceError, match=message):
            reduce_runs([path])
        out = tmp_path / f"out-{path.stem}"
        assert main(["reduce", str(path), "-o", str(out)]) == 2
        assert message in capsys.readouterr().err
        assert not out.exists()                                 # nothing written


def test_refuses_other_systems_and_shared_seeds(tmp_path):
    a, b, c = tmp_path / "a.h5", tmp_path / "b.h5", tmp_path / "c.h5"
    write_run(a, job_text(seed=1), MODULI)
    write_run(b, job_text(seed=2, phi="[0.3, 0.4]"), MODULI)
    write_run(c, job_text(seed=1, realisations=2, extra="ranks_per_task = 1"), MODULI)
    with pytest.raises(ReduceError, match=r"not the same system(.|\n)*system.phi"):
        reduce_runs([a, b])
    with pytest.raises(ReduceError, match="same job.seed = 1"):
        reduce_runs([a, c])
    with pytest.raises(ReduceError, match="given twice"):
        reduce_runs([a, a])


def test_quiescent_jobs_have_no_projected_moduli_and_reduce_by_green_kubo(tmp_path):
    run = tmp_path / "run.h5"
    write_run(run, job_text(protocol="none", realisations=1), {})
    with pytest.raises(ReduceError, match="Green-Kubo"):
        reduce_runs([run])
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out), "--no-plots"]) == 0
    assert (out / "moduli_gk.csv").exists() and not (out / "moduli.csv").exists()


# ----------------------------------------------------------------------------- outputs


def test_steady_shear_gives_viscosity_csv(tmp_path):
    run = tmp_path / "run.h5"
    write_run(run, job_text(protocol="steady", realisations=4, phi="[0.3]"),
              {"hydrodynamic": 1.5, "brownian": 0.4}, noise=0.05, seed=2)
    red = reduce_runs([run])
    paths, _ = write_all(red, tmp_path / "out")
    header, rows = rows_of(tmp_path / "out" / "viscosity.csv")
    # issue 7 appended N1, N2, Pi and 95% intervals (tests/test_steady.py); eta first
    assert header[:6] == ["phi", "rate", "component", "n_realisations", "eta", "eta_err"]
    eta = {r[2]: (float(r[4]), float(r[5])) for r in rows}
    assert eta["medium"] == (1.0, 0.0)
    for comp, value in (("hydrodynamic", 1.5), ("brownian", 0.4), ("total", 2.9)):
        assert abs(eta[comp][0] - value) < z_bound(3) * eta[comp][1]


def test_cli_writes_table_archive_and_figures(tmp_path, capsys):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, medium=MAXWELL), MODULI, noise=0.002, seed=4)
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out), "--task", "5"]) == 0
    stdout = capsys.readouterr().out
    assert "hydrodynamic" in stdout and "one standard error" in stdout
    figures = ["moduli_phi0.3.png", "viscosity_phi0.3.png", "moduli_phi0.45.png",
               "viscosity_phi0.45.png", "lissajous.png"]
    for name in figures:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
        assert f"wrote {out / name}" in stdout
    with h5py.File(out / "moduli.h5") as f:
        assert f.attrs["format"] == "sdmpi-moduli"
        assert parse_job(f.attrs["job_text"]) == parse_job(job_text(realisations=2,
                                                                    medium=MAXWELL))
        assert str(run) in f.attrs["input_files"]
        assert f["realisations/mean"].shape == (4, len(TABLE_COMPONENTS), 2, 2)
        assert f["realisations/block_size"].shape == (4, len(TABLE_COMPONENTS), 2, 2)
        assert f["ensemble/dof"].shape == (4, len(TABLE_COMPONENTS), 2)
        assert list(f["table/component"].asstr()[:len(TABLE_COMPONENTS)]) == list(TABLE_COMPONENTS)
        np.testing.assert_array_equal(f["table/G_prime"][:], [r["G_prime"] for r in
                                                              reduce_runs([run]).rows()])
    assert main(["reduce", str(run), "-o", str(out), "--task", "999"]) == 2


def test_postprocess_scripts_rebuild_the_seed_figures_from_partial_runs(tmp_path, capsys):
    """postprocess/fig*.py on small synthetic runs of both media, one of them partial,
    with two volume fractions (Fig. 2 needs several)."""
    import importlib.util
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent / "postprocess"
    newt, maxw = tmp_path / "newt.h5", tmp_path / "maxw.h5"
    write_run(newt, job_text(realisations=2), MODULI, noise=0.002, progress={3: 10}, seed=1)
    write_run(maxw, job_text(realisations=2, medium=MAXWELL, phi="[0.45]"), MODULI,
              noise=0.002, seed=2)
    runs = {"fig2_viscosity_vs_phi": [newt], "fig4_moduli": [newt], "fig5_omega_half": [newt],
            "fig7_newtonian_viscosity": [newt],
            "fig8_maxwell_viscosity": [maxw, "--newtonian", newt]}
    for name, args in runs.items():
        spec = importlib.util.spec_from_file_location(name, root / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        out = tmp_path / f"{name}.png"
        assert module.main([str(a) for a in args] + ["-o", str(out)]) == 0
        assert out.read_bytes()[:4] == b"\x89PNG"
        assert f"wrote {out}" in capsys.readouterr().out
