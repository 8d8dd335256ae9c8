"""Sub-average (blocking) errors of per-period values and their ensemble combination.

Within one realisation the per-period moduli are correlated over the structural
relaxation time, so the naive error sqrt(var/n) is too small. ``blocking`` applies the
Flyvbjerg-Petersen transformation (J. Chem. Phys. 91, 461 (1989)): average neighbouring
values pairwise, again and again (block size 1, 2, 4, ...; an odd last value is
dropped at that level), and at each level estimate var(mean) = c0/(n_b - 1), c0 the
biased variance of the n_b block means. The level is chosen from the data with
Jonsson's test (Phys. Rev. E 98, 043304 (2018)): the first level j at which
M_j = sum_{k >= j} n_k rho_k^2 < chi2_{0.99}(number of levels >= j), rho_k the lag-1
autocorrelation of the level-k block means, i.e. the first level whose blocks (and all
coarser ones) look uncorrelated at the 1% level. Blocks that pass this test still
correlate with their neighbours (rho ~ tau/B for block size B >> tau), which biases the
plain estimate low (coverage 0.57 instead of 0.68 for AR(1) with tau = 4, n = 1024), so
the chosen level's estimate is corrected for that lag-1 (MA(1)) correlation:
var(mean) = c0/(n_b - 1) * max(1, 1 + 2 rho_j). Measured coverage of +-err is then
within 1-3% of P(|t_(n_b - 1)| < 1) once a run spans >~ 100 correlation times (AR(1),
tau = 1-10 periods); shorter runs still under-cover (n = 128, tau = 4: 0.59), which no
single-run estimate can fix: use several realisations.

Across realisations (independent by construction: each task's random stream and start
come from its own SeedSequence(job seed, spawn_key=(task id,))) ``combine`` forms the
period-weighted mean  mu = sum_r n_r m_r / sum_r n_r  (the mean over all periods; the
plain mean of realisation means when runs are complete) and two estimates of its
standard error:

    between:  err_b^2 = sum_r n_r (m_r - mu)^2 / ((R - 1) sum_r n_r),  dof_b = R - 1  (R >= 2)
    within:   err_w^2 = sum_r n_r^2 e_r^2 / (sum_r n_r)^2,   dof_w = sum_r (n_blocks_r - 1)

err_b is the (Hartung-Knapp) spread of realisation means: for equal n_r it is exactly
s/sqrt(R), unbiased for var(mu) whatever the within-realisation correlations and any
extra spread between realisations (e.g. slowly relaxing structure); for unequal n_r
(partial runs) it is unbiased without extra spread and a few % low with it (measured:
err^2 6% low, coverage 0.663 instead of 0.674 for R = 30). But with R - 1 degrees of
freedom it is itself very uncertain at small R: at R = 2 it comes out below a third of
the true error 26% of the time (P(chi2_1 < 1/9)). err_w, the blocking errors e_r of the
realisations propagated to the mean, has many more degrees of freedom but misses
correlations longer than the blocks and any extra spread between realisations.

The reported error is the larger of the two, ``err = max(err_b, err_w)`` (err_w alone
for R = 1), so that no error is smaller than either estimate supports; ``dof`` is that
of the larger one and ``source`` says which it was (:data:`SOURCES`). Measured on
AR(1)-correlated per-period values (64 periods per run, correlation time 3 periods;
tests/test_error_bars.py, docs/reduce.md), mu +- err covers the truth 0.67, 0.70, 0.69
of the time at R = 2, 3, 7 (nominal 0.68), where the between estimate alone covers 0.50,
0.59, 0.66 and is below a third of the true error 26%, 10%, 0.6% of the time (the
combined error: never). Runs of only ~8 correlation times under-cover (0.63-0.65: the
blocking within them sees too few blocks), as any estimate from so little data does.
err_b >> err_w means correlations longer than a run or structure that differs between
realisations.
"""

from typing import NamedTuple

import numpy as np
from scipy.stats import chi2


class Blocking(NamedTuple):
    """Blocking result, arrays over the leading axes: mean of all n values, its
    standard error err (nan if n < 2), and the chosen block_size and n_blocks."""
    mean: np.ndarray
    err: np.ndarray
    n: np.ndarray
    block_size: np.ndarray
    n_blocks: np.ndarray


#: ``EnsembleEstimate.source`` codes: no data, the medium's exact value, the within-realisation
#: blocking error, the between-realisation spread
SOURCES = ("none", "exact", "within", "between")


class EnsembleEstimate(NamedTuple):
    """Ensemble mean, one standard error and its degrees of freedom, counts, the within
    and between estimates with their degrees of freedom, and which of them is ``err``
    (index into :data:`SOURCES`; see module docstring)."""
    mean: np.ndarray
    err: np.ndarray
    dof: np.ndarray
    n_realisations: np.ndarray
    n_periods: np.ndarray
    err_within: np.ndarray
    err_between: np.ndarray
    dof_within: np.ndarray
    dof_between: np.ndarray
    source: np.ndarray


def blocking_levels(x):
    """Flyvbjerg-Petersen levels of x (..., n): a list, one entry per level with >= 2
    blocks, of (block_size, n_blocks, var_of_mean (...), lag1_autocorrelation (...))."""
    x = np.asarray(x, dtype=float)
    levels, size = [], 1
    while x.shape[-1] >= 2:
        nb = x.shape[-1]
        d = x - x.mean(axis=-1, keepdims=True)
        c0 = (d * d).mean(axis=-1)
        c1 = (d[..., :-1] * d[..., 1:]).sum(axis=-1) / nb
        with np.errstate(invalid="ignore", divide="ignore"):
            rho = np.where(c0 > 0, c1 / c0, 0.0)
        levels.append((size, nb, c0 / (nb - 1), rho))
        x = 0.5 * (x[..., 0:nb - 1:2] + x[..., 1:nb:2])
        size *= 2
    return levels


def blocking(x):
    """Mean and blocking standard error of correlated values x (..., n) along the
    last axis, block size chosen per series by Jonsson's M test (module docstring)."""
    x = np.asarray(x, dtype=float)
    lead, n = x.shape[:-1], x.shape[-1]
    mean = x.mean(axis=-1) if n else np.full(lead, np.nan)
    levels = blocking_levels(x)
    if not levels:
        return Blocking(mean, np.full(lead, np.nan), np.full(lead, n), np.ones(lead, int),
                        np.full(lead, n))
    sizes = np.array([lv[0] for lv in levels])
    nbs = np.array([lv[1] for lv in levels])
    var = np.stack([lv[2] for lv in levels])                       # (L, ...)
    rho = np.stack([lv[3] for lv in levels])
    stat = nbs.reshape((-1,) + (1,) * len(lead)) * rho ** 2       # n_k rho_k^2
    m = np.cumsum(stat[::-1], axis=0)[::-1]                        # M_j
    q = chi2.ppf(0.99, len(levels) - np.arange(len(levels)))
    ok = m < q.reshape(stat.shape[:1] + (1,) * len(lead))
    j = np.argmax(ok, axis=0)          # first accepted level (the last always passes)
    pick = lambda a: np.take_along_axis(a, j[None], axis=0)[0]
    err = np.sqrt(pick(var) * np.maximum(1.0, 1.0 + 2.0 * pick(rho)))
    return Blocking(mean, err, np.full(lead, n), sizes[j], nbs[j])


def combine(b):
    """Combine per-realisation Blocking results (fields (..., R); realisations with
    n == 0 are absent) into one EnsembleEstimate per leading index (module docstring)."""
    n = np.asarray(b.n)
    present = n > 0
    w = np.where(present, n, 0).astype(float)
    r = present.sum(axis=-1)
    total = w.sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.where(present, b.mean, 0.0)
        mu = (w * m).sum(axis=-1) / total
        dev = np.where(present, m - mu[..., None], 0.0)
        err_between = np.sqrt((w * dev ** 2).sum(axis=-1) / ((r - 1) * total))
        err_between = np.where(r >= 2, err_between, np.nan)
        e = np.where(present, b.err, 0.0)
        err_within = np.sqrt((w ** 2 * e ** 2).sum(axis=-1)) / total
    dof_within = np.where(present, b.n_blocks - 1, 0).sum(axis=-1)
    dof_between = np.where(r >= 2, r - 1, 0)
    between = (r >= 2) & ~(err_between < err_within)   # NaN within (n < 2): between
    err = np.where(between, err_between, np.where(r >= 1, err_within, np.nan))
    dof = np.where(between, dof_between, np.where(r >= 1, dof_within, 0))
    source = np.where(r == 0, SOURCES.index("none"),
                      np.where(between, SOURCES.index("between"), SOURCES.index("within")))
    return EnsembleEstimate(mu, err, dof, r, n.sum(axis=-1), err_within, err_between, dof_within,
                    dof_between, source.astype(np.int8))

def ensemble_average(values):
    """Ensemble estimate of per-period values: a list of 1-D arrays, one per realisation
    (lengths may differ, e.g. for a partial run; empty ones count as absent), or an
    array (..., R, n_periods). Returns combine(blocking(...)) as an EnsembleEstimate."""
    if isinstance(values, np.ndarray):
        return combine(blocking(values))
    if len(values) == 0:
        raise ValueError("ensemble_average needs at least one realisation")
    parts = [blocking(np.asarray(v, dtype=float)) for v in values]
    return combine(Blocking(*(np.array(f) for f in zip(*parts))))
