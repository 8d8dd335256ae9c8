"""postprocess/schaink2000.py, the regeneration path of docs/validation/schaink2000/, on
tiny real runs (N = 8, a few periods): every table and figure, the Maxwell tables equal
to `sdmpi reduce --medium`, and byte-identical tables when run again."""

import math

import numpy as np
import pytest

from sdmpi.cli import main as sdmpi_main
from .tiny_runs import postprocess_script, sdmpi_run

TABLES = ["moduli.csv", "errors.csv", "units.json"]
FIGURES = ["moduli.png", "omega_half.png", "eta_components.png", "maxwell.png",
           "phi_scan.png", "fixed_dt.png"]


def script():
    return postprocess_script("schaink2000")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("schaink")
    newt = sdmpi_run(d / "newt.h5")
    phi = sdmpi_run(d / "phi.h5", "--set", "shear.omega=[25.132741228718345]",
                    "--set", "system.phi=[0.3, 0.45]")
    fixed = sdmpi_run(d / "fixed.h5", "--set", "shear.omega=[25.132741228718345]",
                      "--set", "integration.dt_max=0.005", "--set",
                      "integration.steps_per_period=8")
    return newt, phi, fixed


def regenerate(runs, out):
    newt, phi, fixed = runs
    return script().main(["--newtonian", str(newt), "--phi-scan", str(phi),
                          "--fixed-dt", str(fixed), "-o", str(out)])


def test_regeneration_writes_every_table_and_figure(runs, tmp_path, capsys):
    out = tmp_path / "schaink2000"
    assert regenerate(runs, out) == 0
    for sub in ("newtonian", "maxwell", "phi_scan", "fixed_dt"):
        for name in TABLES + ["moduli.h5"]:
            assert (out / sub / name).is_file(), (sub, name)
    for name in FIGURES:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000, name
    # the tables are those of `sdmpi reduce`, the Maxwell ones of --medium
    newt = runs[0]
    assert sdmpi_main(["reduce", str(newt), "-o", str(tmp_path / "cli"), "--no-plots",
                       "--medium", "maxwell:eta=1,lambda=0.5"]) == 0
    for name in TABLES:
        assert (out / "newtonian" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes()
        assert ((out / "maxwell" / name).read_bytes()
                == (tmp_path / "cli" / "maxwell_lambda0.5" / name).read_bytes())
    text = (out / "comparison.md").read_text()
    table = [line for line in text.splitlines() if line.startswith("| ")][1:]
    assert len(table) == 10                   # every statement of issue 16, and the control
    verdicts = {row.split(" | ")[0][2:]: row.rsplit(" | ", 1)[1] for row in table}
    assert verdicts["medium rows exact (eq. 36)"].startswith("reproduced")
    # the eta'_H statement's weighted mean is that of the table's hydrodynamic rows
    import csv
    rows = [r for r in csv.DictReader(open(out / "newtonian" / "moduli.csv"))
            if r["component"] == "hydrodynamic"]
    h = np.array([float(r["eta_prime"]) for r in rows])
    e = np.array([float(r["eta_prime_err"]) for r in rows])
    mean = np.sum(h / e ** 2) / np.sum(e ** -2)
    from sdmpi.analysis.report import plus_minus
    assert f"weighted mean {plus_minus(mean, np.sum(e ** -2) ** -0.5)}" in text
    assert "newt.h5" in text and "20000803" in text


def test_tables_are_byte_identical_when_regenerated(runs, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert regenerate(runs, a) == 0
    assert regenerate(runs, b) == 0
    for sub in ("newtonian", "maxwell", "phi_scan", "fixed_dt"):
        for name in TABLES:
            assert (a / sub / name).read_bytes() == (b / sub / name).read_bytes(), (sub, name)
    assert (a / "comparison.md").read_bytes() == (b / "comparison.md").read_bytes()


def test_bad_input_exits_2(tmp_path, capsys):
    assert script().main(["--newtonian", str(tmp_path / "missing.h5"), "-o",
                          str(tmp_path / "out")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_trend_verdicts():
    trend = script().trend
    assert trend(0.01, 0.02, False, "flat") == "reproduced"
    assert trend(0.5, 0.1, False, "flat").startswith("NOT reproduced (still grows")
    assert trend(0.1, 0.2, False, "flat").startswith("not resolved")
    assert trend(-1.0, 0.1, False, "falls") == "reproduced"
    assert trend(1.0, 0.1, False, "falls").startswith("NOT reproduced (rises")
    assert trend(math.nan, math.nan, True, "falls") == "undetermined"
