"""Green-Kubo at rest (sdmpi.analysis.green_kubo, sdmpi.analysis.at_rest): the estimator on
toys with an exact G(t), and `sdmpi reduce` of runs at rest."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import lfilter

from sdmpi.analysis import green_kubo as gk
from sdmpi.analysis.at_rest import RELAXATION_COLUMNS, reduce_at_rest
from sdmpi.analysis.reduce import TABLE_COMPONENTS, MODULI_COLUMNS
from sdmpi.cli import main
from .runs import ROOT, child_env

KT = 6 * math.pi


def ou(rng, shape, n, dt, tau, var):
    """Stationary Ornstein-Uhlenbeck samples (exact AR(1) discretisation), <x(t) x(0)> =
    var exp(-t/tau), independent along the leading axes."""
    a = math.exp(-dt / tau)
    start = rng.standard_normal(shape) * math.sqrt(var)
    drive = rng.standard_normal(shape + (n,)) * math.sqrt(var * (1 - a * a))
    return lfilter([1.0], [1.0, -a], drive, axis=-1, zi=(a * start)[..., None])[0]


def six(c5):
    """(5, ..., n) values of the five deviatoric components -> (..., n, 6) stress 6-vectors
    (xx yy zz xy xz yz) with those components and zero trace."""
    xy, xz, yz, u, v = c5
    r3 = math.sqrt(3.0)
    return np.stack([u + v / r3, -u + v / r3, -2 * v / r3, xy, xz, yz], axis=-1)


def maxwell(omega, g0, tau):
    """G', G'' of G(t) = g0 exp(-t/tau)."""
    wt = np.asarray(omega) * tau
    return g0 * wt ** 2 / (1 + wt ** 2), g0 * wt / (1 + wt ** 2)


def test_the_five_components_of_an_isotropic_tensor_have_equal_variance_and_no_correlation():
    """s = A + A^T - (2/3) tr(A) I, A with iid unit Gaussian entries, is isotropic: each of
    xy, xz, yz, (xx-yy)/2, (xx+yy-2zz)/(2 sqrt3) has variance 2 and they are uncorrelated;
    a pressure p I added to it changes none of them."""
    rng = np.random.default_rng(5)
    a = rng.standard_normal((200000, 3, 3))
    s = a + np.swapaxes(a, 1, 2)
    s -= np.trace(s, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    s += rng.standard_normal(len(s))[:, None, None] * np.eye(3)       # a random pressure
    vec = np.stack([s[:, 0, 0], s[:, 1, 1], s[:, 2, 2], s[:, 0, 1], s[:, 0, 2], s[:, 1, 2]], -1)
    c = np.cov(gk.deviatoric(vec))
    # sampling error of a variance of 2 over 2e5 samples: 2 sqrt(2/2e5) = 0.006
    assert np.diag(c) == pytest.approx(np.full(5, 2.0), abs=0.03)
    assert np.abs(c - np.diag(np.diag(c))).max() < 0.03


def ensemble_of_toys(rng, n_real, n, dt, tau, g0, volume, white=0.0, lag0="keep",
                     omega=(0.5, 2.0, 8.0), max_lag=400):
    """G(t), G* of an Ornstein-Uhlenbeck stress (variance g0 kT/V per component, so
    G(t) = g0 exp(-t/tau)) plus white noise of variance ``white`` per sample, n_real
    realisations of n samples; two streams that split the stress 1/4 : 3/4."""
    lags = gk.report_lags(max_lag)
    values = []
    for _ in range(n_real):
        s = six(ou(rng, (5,), n, dt, tau, g0 * KT / volume))
        if white:
            s = s + six(rng.standard_normal((5, n)) * math.sqrt(white))
        values.append(gk.realisation_values(np.stack([0.25 * s, 0.75 * s]), dt, volume, KT,
                                            max_lag, np.asarray(omega), lags, lag0))
    return lags, gk.ensemble(values)


def test_ornstein_uhlenbeck_stress_gives_its_exponential_relaxation_and_maxwell_moduli():
    """G(t) = g0 exp(-t/tau), G* = g0 i w tau/(1 + i w tau), window 8 tau (truncation
    e^-8, 3e-4 of G'' at most). Over 12 independent ensembles of 4 realisations: every
    reported lag and G', G'' at 3 frequencies within 4.5 standard errors, and the errors
    honest: rms of (mean - exact)/err between 0.6 and 1.5 (a mean off by a factor 2 in
    V/kT, a missing five-component average, or errors 2x too large or small fail). The
    rows per stream are the stress's share of G (1/4, 3/4), and they sum to the total."""
    rng = np.random.default_rng(41)
    dt, tau, g0, volume = 0.01, 0.5, 3.0, 100.0
    omega = np.array([0.5, 2.0, 8.0])
    z_t, z_w = [], []
    for _ in range(12):
        lags, (rel, mod) = ensemble_of_toys(rng, 4, 20000, dt, tau, g0, volume, omega=omega)
        exact_t = g0 * np.exp(-lags * dt / tau)
        z_t.append((rel.mean[-1] - exact_t) / rel.err[-1])
        for q, exact in enumerate(maxwell(omega, g0, tau)):
            z_w.append((mod.mean[-1, q] - exact) / mod.err[-1, q])
        assert rel.mean[0] == pytest.approx(0.25 * rel.mean[-1], rel=1e-12)
        assert rel.mean[0] + rel.mean[1] == pytest.approx(rel.mean[-1], rel=1e-12)
        assert mod.mean[0] + mod.mean[1] == pytest.approx(mod.mean[-1], rel=1e-12)
    z_t, z_w = np.array(z_t), np.array(z_w)
    assert np.abs(z_t).max() < 4.5 and np.abs(z_w).max() < 4.5
    assert 0.6 < math.sqrt(np.mean(z_t[:, 0] ** 2)) < 1.5     # lag 0, one per ensemble
    assert 0.6 < math.sqrt(np.mean(z_w ** 2)) < 1.5


def test_white_estimator_noise_biases_lag_0_only_and_the_lag1_rule_removes_it():
    """The Brownian stress's per-step noise, modelled as white noise of variance q per
    sample on top of the OU stress: it adds (V/kT) q to G(0) only, so with lag 0 kept
    G''(w) gains w (dt/2) (V/kT) q exactly (the trapezoid's weight of lag 0) while G'
    does not change; the "lag1" and "contact" rules remove it, leaving errors O(dt/tau)
    (here a few % of G(0) dt/2, far below the statistical errors)."""
    dt, tau, g0, volume, q = 0.01, 0.5, 3.0, 100.0, 40.0
    omega = np.array([2.0, 8.0, 16.0])
    _, (rel, keep) = ensemble_of_toys(np.random.default_rng(7), 4, 20000, dt, tau, g0,
                                      volume, white=q, omega=omega)
    _, (_, lag1) = ensemble_of_toys(np.random.default_rng(8), 4, 20000, dt, tau, g0,
                                    volume, white=q, lag0="lag1", omega=omega)
    _, (_, contact) = ensemble_of_toys(np.random.default_rng(9), 4, 20000, dt, tau, g0,
                                       volume, white=q, lag0="contact", omega=omega)
    bias = omega * dt / 2 * volume / KT * q
    g1, g2 = maxwell(omega, g0, tau)
    assert rel.mean[-1, 0] - g0 == pytest.approx(volume / KT * q, rel=0.1)  # G(0): the noise
    assert np.all(np.abs(rel.mean[-1, 1:5] - g0 * np.exp(-np.arange(1, 5) * dt / tau))
                  < 4 * rel.err[-1, 1:5])                       # later lags: unbiased
    assert bias[-1] > 5 * keep.err[-1, 1, -1]                   # the noise matters at 16
    assert np.all(np.abs(keep.mean[-1, 1] - g2 - bias) < 4 * keep.err[-1, 1])
    assert np.all(np.abs(keep.mean[-1, 0] - g1) < 4 * keep.err[-1, 0])
    for est in (lag1, contact):
        assert np.all(np.abs(est.mean[-1, 0] - g1) < 4 * est.err[-1, 0])
        assert np.all(np.abs(est.mean[-1, 1] - g2) < 4 * est.err[-1, 1])


def test_linear_rule_for_a_g_finite_at_t_0_and_the_contact_rule_s_bias_there():
    """A G(t) finite and smooth at t = 0 (hard spheres with lubrication): the "linear"
    rule rebuilds lags 0-4 of a straight line exactly whatever lag 0 holds (white noise),
    and on an exponential G = 30 exp(-t/tau), tau = 0.05 (100 steps of 5e-4: the
    full-SD Brownian G(t) falls 17% over its first 20 lags) changes G', G'' at 2 ... 80
    pi by at most its curvature error, (fit span/tau)^2 ~ 3% of G''; "lag1" by less than
    1%; the "contact" rule fits a t^-1/2 term to the same curve and more than doubles G''
    at 80 pi."""
    dt, tau = 5e-4, 0.05
    m = np.arange(4001)
    line = 30.0 - 500.0 * m * dt
    noisy = line.copy()
    noisy[0] += 90.0
    assert gk.apply_lag0(noisy[:40], "linear") == pytest.approx(line[:40], rel=1e-12)
    c = 30.0 * np.exp(-m * dt / tau)
    w = np.array([2, 8, 16, 32, 80]) * math.pi
    e1, e2 = gk.transform(c, dt, w)
    g1, g2 = gk.transform(gk.apply_lag0(c, "linear"), dt, w)
    assert np.all(np.abs(g1 / e1 - 1) < 1e-3) and np.all(np.abs(g2 / e2 - 1) < 0.03)
    assert gk.transform(gk.apply_lag0(c, "contact"), dt, w)[1][-1] > 2 * e2[-1]
    h1, h2 = gk.transform(gk.apply_lag0(c, "lag1"), dt, w)   # G''(80 pi) loses G(0) dt/tau w dt/2
    assert np.all(h1 == e1) and np.all(np.abs(h2 / e2 - 1) < 0.01)


def test_transform_of_the_step_average_of_a_t_to_the_minus_half_singularity():
    """G(t) = t^-1/2 (the short-time form of hard spheres), sampled as its mean over each
    step (the correlation of step averages: G smoothed by a triangle of half-width dt).
    The trapezoid from lag 0 gives int_0^T G cos(w t) dt to O((w dt)^2) and O(dt/T)
    (here 0.2%); the lag1 rule loses (C_0 - C_1) dt/2 = 0.78 dt^1/2 (C_0 = (8/3) dt^-1/2,
    C_1 = 1.10 dt^-1/2), leaving lag 0 out C_0 dt/2 = 1.33 dt^1/2."""
    from scipy.integrate import quad
    dt, m = 1e-3, 2000
    k = np.arange(m + 1)
    # (1/dt) int G(t) tri((t - k dt)/dt) dt with G(t) = |t|^-1/2, in closed form
    def prim(x):              # int_0^x (x - u) u^-1/2 du = (4/3) x^3/2, for x >= 0
        return 4.0 / 3.0 * np.abs(x) ** 1.5
    c = (prim((k + 1) * dt) - 2 * prim(k * dt) + prim((k - 1) * dt)) / dt ** 2
    c[0] = 2 * prim(dt) / dt ** 2
    for w in (5.0, 50.0):
        exact = quad(lambda t: math.cos(w * t), 0, m * dt, weight="alg", wvar=(-0.5, 0))[0]
        keep = gk.transform(c, dt, [w])[1][0] / w
        lag1 = gk.transform(gk.apply_lag0(c, "lag1"), dt, [w])[1][0] / w
        assert keep == pytest.approx(exact, rel=2e-3)
        assert exact - lag1 == pytest.approx(0.78 * math.sqrt(dt), rel=0.01)
        assert c[0] * dt ** 0.5 == pytest.approx(8 / 3) and c[1] * dt ** 0.5 == pytest.approx(1.1046, rel=1e-4)


def test_omega_grid_and_lags():
    grid = gk.omega_grid(2e-3, 3.0)
    assert grid[0] >= 1 / 3.0 and grid[-1] <= 0.2 / 2e-3
    assert grid[0] / 2 ** 0.25 < 1 / 3.0 and grid[-1] * 2 ** 0.25 > 0.2 / 2e-3
    assert np.any(np.isclose(grid, 2 * math.pi)) and np.any(np.isclose(grid, 16 * math.pi))
    lags = gk.report_lags(1500)
    assert list(lags[:33]) == list(range(33)) and lags[-1] == 1500
    assert np.all(np.diff(lags) > 0)


def step_means(g, dt, lags):
    """(1/dt) int G(t) tri((t - m dt)/dt) dt of a G given as a function of t > 0: the
    correlation of step means (G integrable at 0)."""
    from scipy.integrate import quad
    f = lambda t: float(g(t))
    out = []
    for m in lags:
        if m == 0:
            out.append(2 * quad(lambda t: f(t) * (1 - t / dt), 0, dt, limit=200)[0] / dt)
        else:
            out.append((quad(lambda t: f(t) * (t / dt - m + 1), (m - 1) * dt, m * dt)[0]
                        + quad(lambda t: f(t) * (m + 1 - t / dt), m * dt, (m + 1) * dt)[0]) / dt)
    return np.array(out)


@pytest.mark.parametrize("rule", ["keep", "contact"])
def test_exact_dilute_relaxation_transforms_to_the_exact_dilute_moduli(rule):
    """The exact O(phi^2) G(t) of hard spheres without hydrodynamic interactions
    (models.dilute_hard_sphere_relaxation, ~ t^-1/2 at short times), as step means at
    dt = 2e-3 over a window of 6 t_D (at 3 t_D the truncation is still 1% of G'(1)): the trapezoid from lag 0 gives
    the exact G', G'' (models.dilute_hard_sphere_moduli) at omega = 1, 8, 64 to 0.5%
    (the truncation and (w dt)^2/12), and the "contact" rule, which rebuilds lags 0-4
    from lags 5-20, to 1% (its fit of c t^-1/2 + b to a G that curves away from that
    form)."""
    from sdmpi.analysis.analytic import (dilute_hard_sphere_moduli,
                                       dilute_hard_sphere_relaxation)
    dt, m = 2e-3, 3000
    lags = np.arange(m + 1)
    c = dilute_hard_sphere_relaxation(np.maximum(lags, 1) * dt)   # smooth beyond 16 lags
    c[:16] = step_means(dilute_hard_sphere_relaxation, dt, range(16))
    omega = np.array([1.0, 8.0, 64.0])
    g1, g2 = gk.transform(gk.apply_lag0(c, rule), dt, omega)
    e1, e2 = dilute_hard_sphere_moduli(omega)
    tol = 5e-3 if rule == "keep" else 1e-2
    assert g1 == pytest.approx(e1, rel=tol) and g2 == pytest.approx(e2, rel=tol)


# --------------------------------------------------------------------------- sdmpi reduce

OUTPUTS = {"relaxation.csv", "moduli_gk.csv", "green_kubo.json"}

TINY = """
[job]
name = "gk-tiny"
seed = {seed}
[system]
n_particles = 8
phi = [0.2]
[medium]
kind = "newtonian"
[shear]
protocol = "none"
[brownian]
enabled = true
[integration]
dt = 0.002
n_steps = 1200
discard_steps = 100
[ensemble]
realisations = 2
[hydrodynamics]
model = "free-draining"
[output]
checkpoint_every = 400
"""


def sdmpi_run(job, path, *sets):
    cmd = [sys.executable, "-m", "sdmpi.cli", "run", str(job), "-o", str(path)]
    for item in sets:
        cmd += ["--set", item]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=900)
    assert res.returncode == 0, res.stderr
    return path


@pytest.fixture(scope="module")
def tiny_runs(tmp_path_factory):
    """Two tiny free-draining runs at rest (N = 8, 2 realisations of 1200 steps each),
    seeds 11 and 12."""
    d = tmp_path_factory.mktemp("rest")
    runs = []
    for seed in (11, 12):
        job = d / f"tiny{seed}.toml"
        job.write_text(TINY.format(seed=seed))
        runs.append(sdmpi_run(job, d / f"tiny{seed}.h5"))
    return runs


def test_rest_run_reduces_to_tables_that_are_byte_identical_on_re_reduction(tiny_runs,
                                                                            tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["reduce", str(tiny_runs[0]), "-o", str(a)]) == 0
    assert main(["reduce", str(tiny_runs[0]), "-o", str(b), "--no-plots"]) == 0
    out = capsys.readouterr()
    assert "Traceback" not in out.err and "NOT validated" not in out.err
    assert {p.name for p in a.iterdir()} == OUTPUTS | {"green_kubo_phi0.2.png"}
    assert {p.name for p in b.iterdir()} == OUTPUTS
    for name in OUTPUTS:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    lines = (a / "moduli_gk.csv").read_text().splitlines()
    assert lines[0].split(",") == list(MODULI_COLUMNS)
    assert (a / "relaxation.csv").read_text().splitlines()[0].split(",") == list(RELAXATION_COLUMNS)
    meta = json.loads((a / "green_kubo.json").read_text())
    assert meta["validated"] is True and meta["lag0_rule"] == "contact" and not meta["warnings"]
    red = reduce_at_rest([tiny_runs[0]])
    g = red.groups[0]
    assert g.max_lag == int(0.125 * 1100) and g.omega[0] >= 1 / (g.max_lag * g.dt)
    for w in g.omega[:3]:   # free draining: 5/2 phi medium, exact; no Brownian stress
        assert red.value(0.2, w, "hydrodynamic", "eta_prime") == pytest.approx(0.5, rel=1e-12)
        assert red.value(0.2, w, "brownian", "G_dprime") == 0.0
        total = sum(red.value(0.2, w, c, "G_dprime") for c in TABLE_COMPONENTS[:-1])
        assert red.value(0.2, w, "total", "G_dprime") == pytest.approx(total, rel=1e-12)


def test_several_files_task_and_bad_input(tiny_runs, tmp_path, capsys):
    out = tmp_path / "two"
    assert main(["reduce", *map(str, tiny_runs), "-o", str(out), "--task", "1"]) == 0
    rows = (out / "moduli_gk.csv").read_text().splitlines()[1:]
    assert {r.split(",")[3] for r in rows} == {"4"}              # 2 files x 2 realisations
    view = tmp_path / "view"       # another medium: its own medium and Einstein rows
    assert main(["reduce", str(tiny_runs[0]), "-o", str(view), "--no-plots",
                 "--medium", "maxwell:eta=1,lambda=0.5"]) == 0
    table = [r.split(",") for r in
             (view / "maxwell_lambda0.5" / "moduli_gk.csv").read_text().splitlines()[1:]]
    medium = {r[1]: (float(r[4]), float(r[6])) for r in table if r[2] == "medium"}
    w = float(table[0][1])
    assert medium[table[0][1]] == pytest.approx((0.5 * w * w / (1 + 0.25 * w * w),
                                                 w / (1 + 0.25 * w * w)), rel=1e-12)
    for r in table:
        if r[2] == "hydrodynamic":
            assert (float(r[4]), float(r[6])) == pytest.approx(
                tuple(0.5 * x for x in medium[r[1]]), rel=1e-12)     # 5/2 phi, phi = 0.2
    for args in (["--task", "7"], ["--gk-window", "-1"], ["--gk-window", "100"],
                 ["--gk-lag0", "lag2"]):
        bad = tmp_path / "bad"
        assert main(["reduce", str(tiny_runs[0]), "-o", str(bad), *args]) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and not bad.exists(), args
        if args == ["--gk-window", "100"]:
            assert "needs" in err   # a window longer than the data: what it needs, said
        if args[0] == "--gk-lag0":
            assert "allowed: keep, lag1, contact, linear" in err
    linear = tmp_path / "linear"
    assert main(["reduce", str(tiny_runs[0]), "-o", str(linear), "--no-plots",
                 "--gk-lag0", "linear"]) == 0
    meta = json.loads((linear / "green_kubo.json").read_text())
    assert meta["lag0_rule"] == "linear" and meta["validated"] is False


def test_frequencies_given_instead_of_the_grid(tiny_runs):
    """reduce_at_rest(omega=...) reports exactly those frequencies, with the same values
    the grid gives where they coincide; frequencies beyond MAX_OMEGA_DT/dt are refused."""
    from sdmpi.analysis.reduce import ReduceError
    grid = reduce_at_rest([tiny_runs[0]])
    w = grid.groups[0].omega
    chosen = reduce_at_rest([tiny_runs[0]], omega=[w[2], 30.0])
    assert list(chosen.groups[0].omega) == [w[2], 30.0]
    for col in ("G_prime", "G_dprime_err"):
        assert chosen.value(0.2, w[2], "collision", col) == grid.value(0.2, w[2], "collision", col)
    assert math.isfinite(chosen.value(0.2, 30.0, "collision", "G_dprime"))
    with pytest.raises(ReduceError, match="omega"):
        reduce_at_rest([tiny_runs[0]], omega=[0.21 / 0.002])


def test_partial_run_and_an_unvalidated_model_are_said(tmp_path, capsys):
    """A run at rest with hydrodynamic interactions (synthetic samples) reduces with the
    warning that it is not validated, in the output and on the terminal; unfinished
    tasks are reduced as far as committed and named."""
    from .synthetic_run import write_run
    from .test_reduce import job_text
    text = job_text(realisations=4, phi="[0.3]", protocol="none",
                    extra='[hydrodynamics]\nmodel = "stokesian"\n').replace(
                        "n_steps = 400", "n_steps = 2000")
    run = tmp_path / "sd.h5"
    write_run(run, text, {"brownian": 0.0}, noise=1.0, tau=20.0, progress={1: 1500})
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out), "--no-plots"]) == 0
    err = capsys.readouterr().err
    assert "NOT validated" in err and "PARTIAL RUN" in err and "task 1" in err
    meta = json.loads((out / "green_kubo.json").read_text())
    assert meta["validated"] is False and "NOT validated" in meta["warnings"][0]
    rows = [r.split(",") for r in (out / "moduli_gk.csv").read_text().splitlines()[1:]]
    assert all(r[4] == "nan" for r in rows if r[2] in ("hydrodynamic", "total"))
    assert "no trajectory frames" in meta["groups"][0]["eta_h_how"]
    assert any("hydrodynamic and total rows NaN" in n for n in meta["notes"])
    sheared = tmp_path / "osc.h5"          # the Green-Kubo options on an oscillatory run
    write_run(sheared, job_text(realisations=2, phi="[0.3]"), {"brownian": (1.0, 2.0)})
    for option in (["--gk-lag0", "lag1"], ["--gk-window", "1"]):
        assert main(["reduce", str(sheared), "-o", str(tmp_path / "o"), *option]) == 2
        assert "apply only to runs at rest" in capsys.readouterr().err


def test_hydrodynamic_row_at_rest_is_eta_h_of_the_trajectory_frames(tmp_path, capsys):
    """Full SD at rest (N = 8, phi = 0.3, 2 realisations of 400 steps, a frame every 50):
    the hydrodynamic row is eta_H times the medium's moduli, eta_H the ensemble average of
    (1/V) sum S_xy per unit shear rate over the frames from discard_steps on, recomputed
    here from the frames with solve_mobility (to 1e-12); G'_H = 0; the total is the sum
    of the rows; the tables are byte-identical on re-reduction. Fails for frames of the
    start-up counted, a wrong box or rate (E_xy = 1/2 per unit rate), a medium factor
    missing, or the row left NaN. Lubrication settings solve_mobility cannot reproduce
    give NaN with the reason."""
    import h5py
    from sdmpi import load_job
    from sdmpi.analysis.at_rest import hydrodynamic_settings
    from sdmpi.hydro import solve_mobility
    job = tmp_path / "sd.toml"
    job.write_text(TINY.format(seed=41).replace('"free-draining"', '"stokesian"')
                   .replace("phi = [0.2]", "phi = [0.3]").replace("n_steps = 1200", "n_steps = 400")
                   .replace("checkpoint_every = 400", "checkpoint_every = 200\ntrajectory_every = 50"))
    run = sdmpi_run(job, tmp_path / "sd.h5")
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        assert main(["reduce", str(run), "-o", str(out), "--no-plots"]) == 0
    assert "NOT validated" in capsys.readouterr().err
    for name in OUTPUTS:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    per_realisation, tol = [], load_job(str(job)).ewald_tolerance
    unit_rate = np.array([[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]])
    with h5py.File(run, "r") as f:
        for t in (0, 1):
            box = f[f"tasks/{t:06d}"].attrs["box"]
            frames = f[f"particles/task_{t:06d}/position/value"][2:]       # steps 100 .. 350
            s = [solve_mobility(x, box, rate_of_strain=unit_rate, ewald_tol=tol)[2] for x in frames]
            per_realisation.append(np.mean([si[:, 0, 1].sum() / np.prod(box) for si in s]))
    eta_h = np.mean(per_realisation)
    assert 0.5 < eta_h < 2.0          # 2.5 phi = 0.75 raised by the hydrodynamic interactions
    red = reduce_at_rest([run])
    g = red.groups[0]
    assert g.hydro.frames == 12 and g.hydro.eta_h == pytest.approx(eta_h, rel=1e-12)
    meta = json.loads((a / "green_kubo.json").read_text())
    assert meta["groups"][0]["eta_h"] == pytest.approx(eta_h, rel=1e-12)
    for w in g.omega[:3]:
        assert red.value(0.3, w, "hydrodynamic", "G_dprime") == pytest.approx(eta_h * w, rel=1e-12)
        assert red.value(0.3, w, "hydrodynamic", "G_prime") == 0.0
        assert red.value(0.3, w, "hydrodynamic", "G_dprime_err") > 0
        total = sum(red.value(0.3, w, c, "G_dprime") for c in TABLE_COMPONENTS[:-1])
        assert red.value(0.3, w, "total", "G_dprime") == pytest.approx(total, rel=1e-12)
    other = load_job(str(job), ["hydrodynamics.min_gap=0.001"])
    assert "min_gap" in hydrodynamic_settings(other)
    assert hydrodynamic_settings(load_job(str(job)))["lubrication"] is True


#: the validation's dilute job (docs/validation/green_kubo/), shortened to 16 t_D
DILUTE = ROOT / "docs" / "validation" / "green_kubo" / "dilute_rest.toml"
DILUTE_SETS = ("integration.n_steps=8200", "integration.discard_steps=200",
               "ensemble.realisations=1", "job.seed=19930701", "output.checkpoint_every=4100")
#: O(phi^3) and time-step systematics allowed around the exact O(phi^2) result, as a
#: ratio measured/exact (test docstring)
DILUTE_BAND = (0.94, 1.29)


def test_dilute_free_draining_at_rest_gives_the_exact_dilute_relaxation_and_moduli(tmp_path):
    """Free draining, N = 1000, phi = 0.05, dt = 2e-3, 16 t_D at rest (8200 steps): the
    collision stress's G(t) and G', G'' against the exact O(phi^2) result of hard spheres
    without hydrodynamic interactions (models.dilute_hard_sphere_relaxation, _moduli).

    Systematics allowed (DILUTE_BAND, ratio measured/exact): O(phi^3), a factor between the
    contact value g(2) = 1.137 and g(2)^2 = 1.29 at phi = 0.05 (docs/physics.md), and the
    time step's 6% deficit of the contact value at dt = 2e-3: 0.94 .. 1.29, widened by 3
    standard errors. (1) G(t) averaged over lags 5-32 (t = 0.01-0.064 t_D, where G ~ t^-1/2;
    lags 0-4 carry the overlap correction's artefacts) against the exact step means, with
    its blocking error over 64 blocks of time origins (~10%). (2) G'' at omega = pi/2, 2 pi, 8 pi and G' at
    2 pi, 8 pi (G' at pi/2 is too small to resolve: +-60%) with a window of 1 t_D, against
    the exact G(t) put through the same window, quadrature and contact rule (errors
    15-35%). Fails for a wrong V/kT (a factor 2 or 6 pi), a missing or doubled
    five-component average, G' and G'' exchanged, or a wrong sign."""
    from sdmpi.analysis.analytic import dilute_hard_sphere_relaxation
    run = sdmpi_run(DILUTE, tmp_path / "dilute.h5", *DILUTE_SETS)
    red = reduce_at_rest([run], window=1.0)
    g = red.groups[0]
    phi2 = g.phi ** 2
    w3 = [math.pi / 2, 2 * math.pi, 8 * math.pi]
    assert red.value(g.phi, w3[0], "hydrodynamic", "eta_prime") == pytest.approx(0.125, rel=1e-12)
    assert red.value(g.phi, w3[0], "brownian", "G_dprime") == 0.0
    lo, hi = DILUTE_BAND
    # (1) short-time G(t)
    import h5py
    from sdmpi.analysis.errors import blocking
    with h5py.File(run, "r") as f:
        stress = f["tasks/000000/samples/stress_collision"][200:8200]
    blocks, _ = gk.block_correlations(gk.deviatoric(stress)[None], gk.deviatoric(stress), 32)
    short = blocks[:, 0, 5:33].mean(axis=1) * g.volume / KT / phi2      # per block of origins
    b = blocking(short)
    exact = step_means(dilute_hard_sphere_relaxation, g.dt, range(5, 33)).mean()
    ratio, err = float(b.mean) / exact, float(b.err) / exact
    assert err < 0.15
    assert lo - 3 * err < ratio < hi + 3 * err, (ratio, err)
    # (2) moduli through the same window and rule
    lags = np.arange(g.max_lag + 1)
    c = dilute_hard_sphere_relaxation(np.maximum(lags, 1) * g.dt)
    c[:16] = step_means(dilute_hard_sphere_relaxation, g.dt, range(16))
    e1, e2 = gk.transform(gk.apply_lag0(c, red.lag0), g.dt, w3)
    checks = [(w, "G_dprime", e2[k]) for k, w in enumerate(w3)]
    checks += [(w, "G_prime", e1[k]) for k, w in enumerate(w3) if k]   # G'(pi/2): +-60%
    for w, col, ex in checks:
        r = red.value(g.phi, w, "collision", col) / phi2 / ex
        s = red.value(g.phi, w, "collision", col + "_err") / phi2 / ex
        assert s < 0.5 and lo - 3 * s < r < hi + 3 * s, (w, col, r, s)


def test_default_short_time_rule_follows_the_lubrication():
    """Without lubrication G(t) rises as t^-1/2 at short times (rule "contact"); with it
    G(t) is finite at t = 0 (rule "lag1", docs/reduce.md)."""
    from sdmpi.analysis.at_rest import default_lag0
    from sdmpi.config import parse_job

    def rule(text):
        return default_lag0(parse_job("[shear]\nprotocol = \"none\"\n" + text))

    assert rule('[hydrodynamics]\nmodel = "free-draining"\n') == "contact"
    assert rule('[hydrodynamics]\nmodel = "far-field"\n') == "contact"
    assert rule('[hydrodynamics]\nmodel = "stokesian"\n') == "lag1"
    assert rule('[hydrodynamics]\nmodel = "stokesian"\nlubrication = false\n') == "contact"
