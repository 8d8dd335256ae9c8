"""Sub-average (blocking) errors of per-period values and their ensemble combination.

``blocking``: the Flyvbjerg-Petersen transformation (J. Chem. Phys. 91, 461 (1989)) of one
realisation's per-period values: average neighbouring values pairwise, again and again
(an odd last value dropped at each level), with var(mean) = c0/(n_b - 1) at each level,
c0 the biased variance of the n_b block means. The level is the first j at which
Jonsson's test (Phys. Rev. E 98, 043304 (2018)) passes,
M_j = sum_{k >= j} n_k rho_k^2 < chi2_{0.99}(number of levels >= j), rho_k the lag-1
autocorrelation of the level-k block means; its estimate is corrected for the remaining
lag-1 correlation of the blocks, var(mean) = c0/(n_b - 1) * max(1, 1 + 2 rho_j).

``combine``: over R independent realisations, the period-weighted mean
mu = sum_r n_r m_r / sum_r n_r and two standard errors,

    between:  err_b^2 = sum_r n_r (m_r - mu)^2 / ((R - 1) sum_r n_r),  dof_b = R - 1  (R >= 2)
    within:   err_w^2 = sum_r n_r^2 e_r^2 / (sum_r n_r)^2,   dof_w = sum_r (n_blocks_r - 1)

(err_b the Hartung-Knapp spread of the realisation means, e_r the realisations' blocking
errors). The reported error is ``err = max(err_b, err_w)`` (err_w alone for R = 1), with
the ``dof`` of the larger one and ``source`` saying which (:data:`SOURCES`); err_b >> err_w
means correlations longer than a run or structure that differs between realisations.
Why the larger of the two, and the coverage measured on synthetic ensembles:
docs/reduce.md, "Error bars".
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
