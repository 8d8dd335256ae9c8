"""Honest error bars at small ensembles (sdmpi.analysis.errors): realisations are
independent by construction, and err = max(between-realisation spread, propagated
within-realisation blocking error) never reports an error much smaller than the truth,
at R = 2, 3, 7 realisations, where the spread alone often does."""

import itertools
import math

import numpy as np
import pytest
from scipy.stats import chi2

from sdmpi.analysis.errors import SOURCES, blocking, combine
from sdmpi.config import enumerate_tasks, parse_job
from .test_projection import ar1
from .test_reduce import job_text

#: ensembles per case; binomial sigma of a coverage near 0.68: 0.0074
M = 4000
#: a coverage or fraction is "within noise" when within Z binomial sigmas
Z = 4.0
NOMINAL = math.erf(1 / math.sqrt(2))          # 0.6827: +-1 sigma of a Gaussian mean


def binomial_sigma(p, m=M):
    return math.sqrt(p * (1 - p) / m)


@pytest.mark.parametrize("R", [2, 3, 7])
def test_coverage_of_the_combined_error_on_correlated_ensembles(R):
    """M ensembles of R realisations of 64 per-period values each, AR(1)-correlated
    (correlation time 3 periods: each run spans ~20 correlation times, as a run of
    ~60 periods at the seed's frequencies does), true mean 0.

    * The reported err covers the true mean at least as often as a +-1 sigma interval
      should (0.6827, less Z binomial sigmas; measured 0.67-0.70), and is not vacuous
      (coverage below 0.80, rms err within 25% of the true standard deviation of the
      mean; measured 1.04-1.14).
    * An error below a third of the truth happens in at most 0.5% of the ensembles,
      whereas the between spread alone does so with probability
      P(chi2_{R-1}/(R-1) < 1/9) (0.25, 0.11, 0.005 at R = 2, 3, 7), also checked."""
    rng = np.random.default_rng(16 + R)
    x = ar1(rng, (M, R, 64), 3.0)
    ens = combine(blocking(x))
    truth = ens.mean.std()                      # of the M ensemble means
    covered = np.mean(np.abs(ens.mean) < ens.err)
    assert covered > NOMINAL - Z * binomial_sigma(NOMINAL), covered
    assert covered < 0.80, covered
    assert 0.95 < np.sqrt(np.mean(ens.err ** 2)) / truth < 1.25
    too_small = np.mean(ens.err < truth / 3)
    expected = chi2.cdf((R - 1) / 9, R - 1)
    small_between = np.mean(ens.err_between < truth / 3)
    print(f"R = {R}: coverage {covered:.3f} (between alone "
          f"{np.mean(np.abs(ens.mean) < ens.err_between):.3f}, within alone "
          f"{np.mean(np.abs(ens.mean) < ens.err_within):.3f}); err < truth/3: "
          f"{too_small:.4f} (between alone {small_between:.3f}); rms err/truth "
          f"{np.sqrt(np.mean(ens.err ** 2)) / truth:.3f}; between dominates "
          f"{np.mean(ens.source == SOURCES.index('between')):.2f}")
    assert too_small <= 0.005, too_small
    assert abs(small_between - expected) < Z * binomial_sigma(expected) + 0.01, small_between
    # the larger of the two is reported, with its source and degrees of freedom
    between = ens.source == SOURCES.index("between")
    np.testing.assert_array_equal(ens.err, np.maximum(ens.err_between, ens.err_within))
    assert np.all(ens.dof[between] == R - 1)
    assert np.all(ens.dof[~between] == ens.dof_within[~between])
    assert 0.05 < between.mean() < 0.95          # both sources occur


def test_between_dominates_when_realisations_differ_in_structure():
    """Per-realisation offsets (structure relaxing slower than a run) that the blocking
    within runs cannot see: the spread takes over (R = 7), and coverage stays nominal
    for P(|t_6| < 1) = 0.644 or above."""
    rng = np.random.default_rng(5)
    R = 7
    x = ar1(rng, (M, R, 64), 3.0) + 0.6 * rng.standard_normal((M, R, 1))
    ens = combine(blocking(x))
    assert np.mean(ens.source == SOURCES.index("between")) > 0.95
    covered = np.mean(np.abs(ens.mean) < ens.err)
    print(f"R = 7 with offsets: coverage {covered:.3f}")
    assert covered > 0.644 - Z * binomial_sigma(0.644), covered


def test_realisations_have_distinct_streams_and_starts():
    """Every task's random stream is SeedSequence(job seed, spawn_key=(task id,)) and its
    start is drawn from it: no two tasks of a job (or of two jobs with different seeds)
    share a start or a stream; their normal deviates are uncorrelated."""
    from sdmpi.dynamics import Realisation
    starts, draws = {}, {}
    for seed in (1, 2):
        job = parse_job(job_text(seed=seed, realisations=3, phi="[0.3]"))
        for task in enumerate_tasks(job):
            r = Realisation(job, task)
            starts[seed, task.task_id] = r.positions.copy()
            draws[seed, task.task_id] = r.rng.standard_normal(20000)
    assert len(starts) == 12
    limit = Z / math.sqrt(20000)                 # |Pearson r| of independent normals
    for a, b in itertools.combinations(starts, 2):
        assert np.abs(starts[a] - starts[b]).max() > 0.5, (a, b)
        assert abs(np.corrcoef(draws[a], draws[b])[0, 1]) < limit, (a, b)
