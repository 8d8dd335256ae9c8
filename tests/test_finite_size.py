"""postprocess/finite_size.py, the regeneration path of docs/validation/finite_size/, on
tiny real runs (N = 8 and 16 of jobs/finite_size_n64.toml, shrunk; the time-step control at
80 pi): every table and figure, the per-N tables equal to `sdmpi reduce`'s, the fits in 1/L
and 1/N against an independent least-squares solution, byte-identical tables when run again."""

import csv
import math

import numpy as np
import pytest

from sdmpi.cli import main as sdmpi_main
from .tiny_runs import postprocess_script, sdmpi_run

FIGURES = ["moduli.png", "viscosities.png", "size.png", "N8/maxwell.png"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("finite_size")
    small = sdmpi_run(d / "n8.h5", job="finite_size_n64.toml")
    large = sdmpi_run(d / "n16.h5", "--set", "system.n_particles=16", job="finite_size_n64.toml")
    control = sdmpi_run(d / "control.h5", "--set", "shear.omega=[251.32741228718345]",
                        job="finite_size_dt_control.toml")
    return small, large, control


def regenerate(runs, out):
    small, large, control = runs
    return postprocess_script("finite_size").main(
        ["--runs", str(small), str(large), "--control", str(control), "-o", str(out)])


def read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_regeneration_writes_every_table_and_figure(runs, tmp_path):
    out = tmp_path / "fs"
    assert regenerate(runs, out) == 0
    for name in FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    assert sdmpi_main(["reduce", str(runs[0]), "-o", str(tmp_path / "cli"), "--no-plots",
                       "--medium", "maxwell:eta=1,lambda=0.5"]) == 0
    for name in ("moduli.csv", "errors.csv"):
        assert (out / "N8" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
        assert ((out / "N8" / "maxwell" / name).read_bytes()
                == (tmp_path / "cli" / "maxwell_lambda0.5" / name).read_bytes())
    text = (out / "summary.md").read_text()
    assert "| eta_H | " in text and "## Time step: the control" in text
    control = text.split("## Time step: the control")[1]
    assert "| 80 pi | 5e-4, 5e-05 |" in control and "nan" not in control

    # the fits in 1/L and 1/N, independently: weighted least squares by numpy
    quantities = {r["quantity"]: r for r in read(out / "quantities.csv")}
    fits = {(r["quantity"], r["in"]): r for r in read(out / "extrapolation.csv")}
    sizes = np.array([8, 16, 27])
    side = (4 * math.pi * sizes / (3 * 0.45)) ** (1 / 3)
    y = np.array([float(quantities["eta_H"][f"N{n}"]) for n in sizes])
    e = np.array([float(quantities["eta_H"][f"N{n}_err"]) for n in sizes])
    for variable, x in (("1/L", 1 / side), ("1/N", 1 / sizes)):
        fit = fits["eta_H", variable]
        assert fit["sizes"] == "8 16 27"
        design = np.vstack([np.ones(3), x]).T
        cov = np.linalg.inv(design.T @ (design / e[:, None] ** 2))
        coef = cov @ design.T @ (y / e ** 2)
        assert float(fit["Q_inf"]) == pytest.approx(coef[0], rel=1e-9)
        assert float(fit["Q_inf_err"]) == pytest.approx(math.sqrt(cov[0, 0]), rel=1e-9)
        assert float(fit["c"]) == pytest.approx(coef[1], rel=1e-9)
        # the fit's closed form (normal equations through a determinant) rounds a and b
        # differently from numpy's solve: ~1e-9 relative in chi^2
        chi2 = float(np.sum(((y - design @ coef) / e) ** 2))
        assert float(fit["chi2_per_dof"]) == pytest.approx(chi2, rel=1e-7) and fit["dof"] == "1"
        # one degree of freedom: P(chi^2_1 >= chi2) = erfc(sqrt(chi2 / 2))
        assert float(fit["p"]) == pytest.approx(math.erfc(math.sqrt(chi2 / 2)), rel=1e-6)
        # N_within: where the fitted correction |c| x falls to the error of Q_inf
        x_within = math.sqrt(cov[0, 0]) / abs(coef[1])
        n_within = 1 / x_within if variable == "1/N" else 3 * 0.45 / (4 * math.pi * x_within ** 3)
        assert float(fit["N_within"]) == pytest.approx(n_within, rel=1e-9)
    # N = 27 comes from the committed study's table
    study = [r for r in read("docs/validation/schaink2000/newtonian/moduli.csv")
             if r["component"] == "hydrodynamic"]
    w = np.array([float(r["eta_prime_err"]) ** -2 for r in study])
    mean = np.sum(w * [float(r["eta_prime"]) for r in study]) / w.sum()
    assert float(quantities["eta_H"]["N27"]) == pytest.approx(mean, rel=1e-9)


def test_tables_are_byte_identical_when_regenerated(runs, tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    assert regenerate(runs, first) == 0 and regenerate(runs, second) == 0
    for name in ("quantities.csv", "extrapolation.csv", "summary.md", "N16/moduli.csv",
                 "dt_control/moduli.csv"):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name


def test_sizes_from_their_committed_tables_give_the_same_numbers(runs, tmp_path):
    """Run files are not kept: a later session adds a size to the committed tables
    (--tables N=MODULI.csv, --control MODULI.csv) and gets the same quantities and fits."""
    first = tmp_path / "runs"
    assert regenerate(runs, first) == 0
    again = tmp_path / "tables"
    assert postprocess_script("finite_size").main(
        ["--tables", f"8={first / 'N8' / 'moduli.csv'}", f"16={first / 'N16' / 'moduli.csv'}",
         "--control", str(first / "dt_control" / "moduli.csv"), "-o", str(again)]) == 0
    for name in ("quantities.csv", "extrapolation.csv"):
        assert (again / name).read_bytes() == (first / name).read_bytes(), name
    assert (again / "summary.md").read_text().split("\n| quantity")[1] == \
        (first / "summary.md").read_text().split("\n| quantity")[1]
