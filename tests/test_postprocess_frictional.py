"""postprocess/frictional_phimax.py: phi_max intervals that cover a known phi_max."""

import numpy as np
import pytest

from sdmpi.analysis.reduce import confidence_half_width
from .tiny_runs import postprocess_script

#: the production scans' shape (docs/validation.md#frictional-contacts): volume fractions,
#: realisations
PHI = np.array([0.45, 0.50, 0.53, 0.56])
R = 4


def load_script():
    return postprocess_script("frictional_phimax")


def synthetic_scan(model, phi_max, spread, rng):
    """Per phi, the mean and the standard error s/sqrt(R) of R realisation means scattered
    around model(phi, phi_max) by the relative standard deviations ``spread``."""
    noise = spread[:, None] * rng.standard_normal((len(PHI), R))
    means = model(PHI, phi_max)[:, None] * (1 + noise)
    return means.mean(axis=1), means.std(axis=1, ddof=1) / np.sqrt(R)


@pytest.mark.parametrize("name, phi_max", [("maron-pierce", 0.60), ("krieger-dougherty", 0.58)])
def test_phi_max_intervals_cover_a_known_phi_max(name, phi_max):
    """400 synthetic scans from a known phi_max (4 phi, 4 realisations each, realisation
    scatter 5-20% of eta_r, as in the runs): the 95% interval (t with R - 1 dof) holds the
    true phi_max in 95% of them and +- the 68.3% t half-width in 68%. Bounds: the
    binomial standard error of a coverage from 400 scans is 0.011 at 0.95 and 0.023 at
    0.68, and the t-interval is exact only for the densest point alone (other points add
    information, so the coverage may exceed nominal a little); [0.91, 0.99] and
    [0.58, 0.78] allow ~3.5 standard errors. Intervals without the t factor (+- 2 err)
    cover 0.86-0.87 and fail the first bound (measured: 0.95-0.96 and 0.65-0.66)."""
    script = load_script()
    model = script.MODELS[name]
    rng = np.random.default_rng(2014)
    hits95 = hits68 = 0
    n = 400
    for _ in range(n):
        eta, err = synthetic_scan(model, phi_max, np.array([0.05, 0.10, 0.15, 0.20]), rng)
        fit = script.phi_max_interval(PHI, eta, err, R - 1, model)
        assert fit["ci95_lo"] < fit["phi_max"] < fit["ci95_hi"]
        hits95 += fit["ci95_lo"] <= phi_max <= fit["ci95_hi"]
        hits68 += abs(fit["phi_max"] - phi_max) <= confidence_half_width(
            fit["phi_max_err"], R - 1, level=0.6827)
    assert 0.91 <= hits95 / n <= 0.99
    assert 0.58 <= hits68 / n <= 0.78


def test_phi_scan_fits_resolve_separated_phi_max_and_not_equal_ones():
    """phi_scan_fits on rows of three friction coefficients: phi_max 0.62, 0.58 and 0.58
    (Maron-Pierce, 2% errors) come back within their 95% intervals; the first pair's
    intervals are disjoint and its difference interval holds 0.04 and excludes 0; the
    equal pair's difference interval holds 0."""
    script = load_script()
    rng = np.random.default_rng(3)
    truth = {0.1: 0.62, 0.3: 0.58, 0.5: 0.58}
    rows = []
    for mu, phi_max in truth.items():
        eta = script.maron_pierce(PHI, phi_max) * (1 + 0.02 * rng.standard_normal(len(PHI)))
        rows += [dict(mu=mu, k_n=1e4, k_t=480.0, f_r0=0.01, phi=p, eta=e, eta_err=0.02 * e,
                      dof=R - 1) for p, e in zip(PHI, eta)]
    rows.append(dict(rows[0], phi=0.40))      # skipped below: not fitted
    _, fits, diffs = script.phi_scan_fits(rows, skip_phi=[0.40])
    mp = {f["mu"]: f for f in fits if f["model"] == "maron-pierce"}
    for mu, phi_max in truth.items():
        assert mp[mu]["ci95_lo"] <= phi_max <= mp[mu]["ci95_hi"] and mp[mu]["n_phi"] == len(PHI)
    d = {(x["mu_a"], x["mu_b"]): x for x in diffs if x["model"] == "maron-pierce"}
    assert d[0.1, 0.3]["disjoint"] and d[0.1, 0.3]["diff_ci95_lo"] > 0
    assert d[0.1, 0.3]["diff_ci95_lo"] <= 0.04 <= d[0.1, 0.3]["diff_ci95_hi"]
    assert not d[0.3, 0.5]["disjoint"]
    assert d[0.3, 0.5]["diff_ci95_lo"] <= 0 <= d[0.3, 0.5]["diff_ci95_hi"]


def test_a_partial_run_is_tabulated_without_its_empty_volume_fractions(tmp_path, capsys):
    """A scan stopped before its second volume fraction has data after the start-up
    (killed after the first task's two checkpoints): the script tabulates the first and
    leaves the second out instead of failing."""
    import csv
    import subprocess
    import sys

    from .runs import ROOT, child_env
    run = tmp_path / "partial.h5"
    cmd = [sys.executable, "-m", "sdmpi.cli", "run", str(ROOT / "jobs" / "frictional_mu0.5.toml"),
           "-o", str(run), "--set", "system.phi=[0.45, 0.5]", "--set", "ensemble.realisations=1",
           "--set", "integration.n_steps=20", "--set", "integration.discard_steps=5",
           "--set", "output.checkpoint_every=10"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600,
                         env=child_env({"SDMPI_TEST_KILL": "commit:2"}))
    assert res.returncode != 0 and run.is_file()
    load_script().main([str(run), "-o", str(tmp_path / "out")])
    rows = list(csv.DictReader(open(tmp_path / "out" / "frictional_viscosity.csv")))
    assert [float(r["phi"]) for r in rows] == [0.45]
    assert float(rows[0]["eta"]) > 1.0 and rows[0]["n_real"] == "1"
