"""Moduli by per-period projection, blocking errors and their ensemble combination,
and the Maxwell-medium models (issue 5; seed 000 eqs. 17-19, 36, 41-42).

Statistical tests use fixed seeds (deterministic), but their tolerances are set so a
correct implementation would fail with any seed at most ~1e-4 of the time: coverage
within 4 binomial standard deviations of the expected rate, means within 4 standard
errors of the truth."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import lfilter
from scipy.stats import t as student_t

from sdmpi.analysis.errors import Blocking, blocking, combine, ensemble_average
from sdmpi.analysis.analytic import (einstein, krieger_dougherty, maxwell_eta_h,
                                   maxwell_moduli, maxwell_viscosity)
from sdmpi.analysis.projection import project_periods, viscosities

Z = 4.0  # false-alarm bound: two-sided 4 sigma, p ~ 6e-5 per check


def ar1(rng, shape, tau):
    """Stationary unit-variance AR(1) along the last axis, correlation time tau samples."""
    a = np.exp(-1.0 / tau)
    start = a * rng.standard_normal(shape[:-1] + (1,))
    return lfilter([np.sqrt(1 - a * a)], [1.0, -a], rng.standard_normal(shape), axis=-1,
                   zi=start)[0]


def t_coverage(dof):
    """P(|t_dof| < 1): coverage of a +-1 standard error interval with dof d.o.f."""
    return 2.0 * student_t.cdf(1.0, dof) - 1.0


# ---------------------------------------------------------------- projection

def test_projection_exact_for_resolved_harmonics():
    n, gamma0, omega, g1, g2 = 8, 0.02, 2.7, 0.8, 1.9
    dt = 2 * np.pi / (omega * n)
    t0 = 0.37 * dt
    discard, kept, tail = 3, 5, 5                       # tail: a partial period
    t = t0 + dt * np.arange((discard + kept) * n + tail)
    sigma = gamma0 * (g1 * np.sin(omega * t) + g2 * np.cos(omega * t)) + 0.3
    for m in range(2, n - 1):                           # all harmonics <= n - 2
        sigma += 0.1 * np.sin(m * omega * t + m)
    sigma[:discard * n] += 1e3 * np.exp(-t[:discard * n])  # start-up transient
    sigma[-tail:] = 1e6                                 # garbage in the partial period
    G1, G2 = project_periods(sigma, gamma0, omega, n, discard, t0=t0)
    assert G1.shape == G2.shape == (kept,)
    np.testing.assert_allclose(G1, g1, rtol=1e-12)
    np.testing.assert_allclose(G2, g2, rtol=1e-12)


def test_end_of_step_sampling_and_batches():
    """Samples at step ends (t0 = dt) and leading batch axes."""
    n, gamma0, omega = 5, 0.05, 0.4
    dt = 2 * np.pi / (omega * n)
    t = dt * (1 + np.arange(4 * n))
    g = np.array([[1.0, 2.0], [-0.5, 3.0], [0.0, 0.1]])          # (3 signals, G'/G'')
    sigma = gamma0 * (g[:, :1] * np.sin(omega * t) + g[:, 1:] * np.cos(omega * t))
    G1, G2 = project_periods(sigma, gamma0, omega, n, discard_periods=1, t0=dt)
    assert G1.shape == (3, 3)
    np.testing.assert_allclose(G1, np.repeat(g[:, :1], 3, 1), atol=1e-13)
    np.testing.assert_allclose(G2, np.repeat(g[:, 1:], 3, 1), atol=1e-13)


def test_partial_periods_ignored_and_counts():
    rng = np.random.default_rng(0)
    n = 10
    sigma = rng.standard_normal(7 * n)
    full = project_periods(sigma, 0.02, 3.0, n, 2)
    for extra in (1, n - 1):
        more = project_periods(np.r_[sigma, rng.standard_normal(extra)], 0.02, 3.0, n, 2)
        np.testing.assert_array_equal(full, more)
    assert full[0].shape == (5,)
    assert project_periods(sigma[:2 * n + 3], 0.02, 3.0, n, 2)[0].shape == (0,)
    assert project_periods(sigma[:n], 0.02, 3.0, n, 2)[0].shape == (0,)


@pytest.mark.parametrize("bad", [dict(samples_per_period=2), dict(samples_per_period=7.5),
                                 dict(discard_periods=-1), dict(gamma0=0.0),
                                 dict(omega=0.0)])
def test_projection_rejects_bad_arguments(bad):
    args = dict(stress=np.zeros(100), gamma0=0.02, omega=1.0, samples_per_period=10)
    with pytest.raises(ValueError):
        project_periods(**(args | bad))


def test_viscosities_are_moduli_over_omega():
    g1, g2, w = np.array([0.3, 1.2]), np.array([2.0, 0.7]), 6.0
    eta1, eta2 = viscosities(g1, g2, w)
    np.testing.assert_allclose(eta1, g2 / w)          # eta'  = G''/w
    np.testing.assert_allclose(eta2, g1 / w)          # eta'' = G'/w


# ---------------------------------------------------------------- errors

def test_ensemble_of_synthetic_signals_unbiased_and_covers():
    """M ensembles of R = 7 realisations: sigma = gamma0 [(G' + a_r + a(t)) sin wt +
    (G'' + b_r + b(t)) cos wt] + e(t), with slow AR(1) amplitude noise a, b (correlation
    time 3 periods), per-realisation offsets a_r, b_r (structure differing between
    realisations), fast AR(1) additive noise e and a start-up transient in the discarded
    periods. Equal-length Gaussian realisations: the between estimate +-err_between covers
    with P(|t_6| < 1) = 0.644; the reported err = max(err_between, err_within) covers more."""
    rng = np.random.default_rng(20000803)
    M, R, n, discard, kept, tail = 2000, 7, 16, 3, 24, 5
    gamma0, omega, g1, g2 = 0.02, 6.283, 0.7, 2.3
    t = 2 * np.pi / (omega * n) * np.arange((discard + kept) * n + tail)
    shape = (M, R, t.size)
    amp1 = g1 + 0.3 * rng.standard_normal((M, R, 1)) + 0.5 * ar1(rng, shape, 3 * n)
    amp2 = g2 + 0.3 * rng.standard_normal((M, R, 1)) + 0.5 * ar1(rng, shape, 3 * n)
    sigma = gamma0 * (amp1 * np.sin(omega * t) + amp2 * np.cos(omega * t))
    sigma += 0.02 * ar1(rng, shape, 4)
    sigma[..., :discard * n] += 5.0 * np.exp(-t[:discard * n] * omega)
    G1, G2 = project_periods(sigma, gamma0, omega, n, discard)
    assert G1.shape == (M, R, kept)
    for values, truth in ((G1, g1), (G2, g2)):
        ens = ensemble_average(values)
        assert np.all(ens.n_realisations == R) and np.all(ens.n_periods == R * kept)
        assert np.all(ens.dof_between == R - 1)
        bias = ens.mean.mean() - truth
        assert abs(bias) < Z * ens.mean.std() / np.sqrt(M), bias
        expected = t_coverage(R - 1)
        covered = np.mean(np.abs(ens.mean - truth) < ens.err_between)
        assert abs(covered - expected) < Z * np.sqrt(expected * (1 - expected) / M), covered
        # the error is the size of the scatter: E[err^2] = var(mean) (chi2 / dof),
        # checked to 4 sigma of that ratio's sampling error (~3.5%)
        ratio = np.mean(ens.err_between ** 2) / ens.mean.var()
        assert abs(ratio - 1) < Z * np.sqrt(2 / M + 2 / (M * (R - 1))), ratio
        # per-realisation offsets: the blocking errors alone miss the between spread
        assert np.median(ens.err_between / ens.err_within) > 1.2
        assert np.all(ens.err >= ens.err_between) and np.all(ens.err >= ens.err_within)
        assert np.mean(np.abs(ens.mean - truth) < ens.err) >= covered


@pytest.mark.parametrize("tau", [0.01, 4.0])
def test_blocking_single_run_coverage(tau):
    """One long run (1024 periods) of AR(1)-correlated per-period values: the blocking
    error covers at P(|t_(n_blocks - 1)| < 1) (0.68 here) within 4 binomial sigma plus
    a 1% allowance for the residual block correlation (measured: 0.665 vs 0.680 for
    tau = 4; white noise: 0.685 vs 0.682)."""
    rng = np.random.default_rng(7)
    M, n = 4000, 1024
    x = 1.5 + ar1(rng, (M, n), tau)
    b = blocking(x)
    expected = np.mean(t_coverage(b.n_blocks - 1))
    covered = np.mean(np.abs(b.mean - 1.5) < b.err)
    assert abs(covered - expected) < Z * np.sqrt(expected * (1 - expected) / M) + 0.01, (
        covered, expected)
    naive = x.std(axis=-1, ddof=1) / np.sqrt(n)
    if tau > 1:   # correlated periods must not shrink the error
        assert np.median(b.block_size) >= 8 and np.median(b.err / naive) > 2.5
    else:
        assert np.median(b.block_size) == 1
        np.testing.assert_allclose(np.median(b.err / naive), 1.0, atol=0.05)


def test_combine_coverage_many_partial_realisations():
    """R = 30 realisations of unequal length (8-40 periods, as in a partial run) of
    AR(1) per-period values (correlation time 3 periods) plus per-realisation offsets:
    +-err_between covers at P(|t_29| < 1) = 0.674 within 4 binomial sigma plus a 1.5% allowance
    (period weights are not inverse-variance weights when realisations differ:
    measured 0.663, err^2 about 6% low)."""
    rng = np.random.default_rng(11)
    M, R, P = 4000, 30, 40
    x = 0.3 * rng.standard_normal((M, R, 1)) + ar1(rng, (M, R, P), 3.0)
    lengths = rng.integers(8, P + 1, size=R)
    parts = [blocking(x[:, r, :lengths[r]]) for r in range(R)]
    ens = combine(Blocking(*(np.stack(f, axis=-1) for f in zip(*parts))))
    assert np.all(ens.n_periods == lengths.sum()) and np.all(ens.dof_between == R - 1)
    expected = t_coverage(R - 1)
    covered = np.mean(np.abs(ens.mean) < ens.err_between)
    assert abs(covered - expected) < Z * np.sqrt(expected * (1 - expected) / M) + 0.015, (
        covered, expected)


def test_combine_estimators_and_counts():
    rng = np.random.default_rng(3)
    runs = [rng.standard_normal(n) + 2.0 for n in (40, 40, 40)]
    ens = ensemble_average(runs)
    means = np.array([r.mean() for r in runs])
    np.testing.assert_allclose(ens.mean, means.mean())
    np.testing.assert_allclose(ens.err_between, means.std(ddof=1) / np.sqrt(3))
    np.testing.assert_allclose(ens.err, max(ens.err_between, ens.err_within))
    assert (ens.n_realisations, ens.n_periods, ens.dof_between) == (3, 120, 2)
    assert ens.dof == (2 if ens.err_between >= ens.err_within else ens.dof_within)

    # a partial run (fewer periods) and an empty one (not past the discarded periods)
    ragged = runs[:2] + [runs[2][:10], np.array([])]
    ens = ensemble_average(ragged)
    allp = np.concatenate(ragged)
    np.testing.assert_allclose(ens.mean, allp.mean())    # weights = periods per run
    assert (ens.n_realisations, ens.n_periods, ens.dof_between) == (3, 90, 2)
    w = np.array([40, 40, 10])
    m = np.array([r.mean() for r in ragged[:3]])
    between = np.sqrt(np.sum(w * (m - allp.mean()) ** 2) / (2 * w.sum()))
    np.testing.assert_allclose(ens.err_between, between)
    within = np.sqrt(sum((len(r) * blocking(r).err) ** 2 for r in ragged[:3])) / 90
    np.testing.assert_allclose(ens.err_within, within)
    np.testing.assert_allclose(ens.err, max(between, within))
    assert ens.dof_within == sum(blocking(r).n_blocks - 1 for r in ragged[:3])

    # one realisation: the blocking error, dof = n_blocks - 1
    one = ensemble_average([runs[0]])
    b = blocking(runs[0])
    np.testing.assert_allclose(one.err, b.err, rtol=1e-14)
    assert one.dof == b.n_blocks - 1 and np.isnan(one.err_between)
    # vectorised over leading axes gives the same as the ragged path
    batch = combine(blocking(np.stack([np.stack(runs), np.stack(runs) * 2])))
    np.testing.assert_allclose(batch.err, [ensemble_average(runs).err,
                                           2 * ensemble_average(runs).err])
    with pytest.raises(ValueError):
        ensemble_average([])


# ---------------------------------------------------------------- models

ETA, LAM = np.array([0.6, 0.3, 0.1]), np.array([0.5, 0.05, 2.0])


@pytest.mark.parametrize("omega", [0.3, 2 * np.pi, 50.0])
def test_maxwell_moduli_match_constitutive_ode(omega):
    """Integrate lam_k dS_k/dt + S_k = eta_k gamma0 w cos(w t) from rest, drop the
    transient (> 40 t_D = 20 lam_max), project: equals seed eq. 36 (summed) to 1e-4."""
    gamma0, n = 0.02, 64
    period = 2 * np.pi / omega
    discard, kept = int(np.ceil(40.0 / period)), 4
    t = period / n * np.arange((discard + kept) * n)
    rhs = lambda s, S: (ETA * gamma0 * omega * np.cos(omega * s) - S) / LAM
    sol = solve_ivp(rhs, (0.0, t[-1]), np.zeros(3), t_eval=t, method="DOP853",
                    rtol=1e-11, atol=1e-14)
    assert sol.success
    G1, G2 = project_periods(sol.y.sum(axis=0), gamma0, omega, n, discard)
    g1, g2 = maxwell_moduli(omega, ETA, LAM)
    np.testing.assert_allclose(G1, g1, rtol=1e-4)
    np.testing.assert_allclose(G2, g2, rtol=1e-4)


def test_maxwell_limits_and_shapes():
    eta0 = ETA.sum()
    g1, g2 = maxwell_moduli(1e-5, ETA, LAM)
    np.testing.assert_allclose(g2, eta0 * 1e-5, rtol=1e-8)                # G'' -> eta w
    np.testing.assert_allclose(g1, 1e-10 * np.sum(ETA * LAM), rtol=1e-8)
    g1, g2 = maxwell_moduli(1e7, ETA, LAM)
    np.testing.assert_allclose(g1, np.sum(ETA / LAM), rtol=1e-8)          # G' -> eta/lam
    np.testing.assert_allclose(g2, 1e-7 * np.sum(ETA / LAM ** 2), rtol=1e-8)  # -> 0
    w = np.logspace(-2, 2, 7).reshape(7, 1)
    assert maxwell_moduli(w, ETA, LAM)[0].shape == (7, 1)
    # single mode, seed eq. 36 written out; eta' = G''/w, eta'' = G'/w
    e1, e2 = maxwell_viscosity(w, 1.0, 0.5)
    np.testing.assert_allclose(e1, 1 / (1 + 0.25 * w ** 2))
    np.testing.assert_allclose(e2, 0.5 * w / (1 + 0.25 * w ** 2))
    np.testing.assert_allclose(viscosities(*maxwell_moduli(w, 1.0, 0.5), w), (e1, e2))
    with pytest.raises(ValueError):
        maxwell_moduli(1.0, [1.0, 2.0], [0.5])


def test_maxwell_eta_h_seed_eqs_41_42():
    w, eta_h0 = np.array([0.1, 2 * np.pi, 30.0]), 1.84
    h1, h2 = maxwell_eta_h(w, eta_h0, 1.0, 0.5)                           # eq. 41
    np.testing.assert_allclose(h1, eta_h0 / (1 + 0.25 * w ** 2))
    np.testing.assert_allclose(h2, eta_h0 * 0.5 * w / (1 + 0.25 * w ** 2))
    h1, h2 = maxwell_eta_h(w, eta_h0, ETA, LAM)                           # eq. 42
    d = 1 + (LAM * w[:, None]) ** 2
    np.testing.assert_allclose(h1, eta_h0 * np.sum(ETA / d, axis=1))
    np.testing.assert_allclose(h2, eta_h0 * np.sum(ETA * LAM * w[:, None] / d, axis=1))
    np.testing.assert_allclose(maxwell_eta_h(1e-9, eta_h0, ETA, LAM)[0], eta_h0 * ETA.sum())


def test_krieger_dougherty():
    np.testing.assert_allclose(krieger_dougherty(1e-6), einstein(1e-6), rtol=1e-10)
    np.testing.assert_allclose(krieger_dougherty(0.32, 0.64), 0.5 ** -1.6)
    with pytest.raises(ValueError):
        krieger_dougherty(0.64, 0.64)
