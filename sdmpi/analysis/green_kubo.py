"""Relaxation modulus G(t) and complex modulus G*(w) by Green-Kubo from a run at rest.

Linear response at rest (Brady, J. Chem. Phys. 99, 567 (1993); Nägele & Bergenholtz,
J. Chem. Phys. 108, 9893 (1998); Foss & Brady, J. Rheol. 44, 629 (2000)): for the
configurational stress C (Brownian + interparticle + collision) and each contribution A,

    G_A(t) = (V/kT) <sigma_A(t) sigma_C(0)>,     sum_A G_A = G,

averaged over the five deviatoric components that an isotropic fluid correlates equally
and not with each other (:func:`deviatoric`: xy, xz, yz, u = (s_xx - s_yy)/2,
v = (s_xx + s_yy - 2 s_zz)/(2 sqrt 3); Daivis & Evans, J. Chem. Phys. 100, 541 (1994)),
with no mean subtracted (isotropy).

Estimator: per realisation, over the time origins k = 0 .. n - M - 1 (every origin sees
every lag m = 0 .. M),

    G_A(m dt) = (V/kT) (1/5) sum_c  mean_k  a_c(k + m) b_c(k);

the origins cut into :data:`BASE_BLOCKS` blocks, each with its own G(t) and G*, whose
blocking (:func:`.errors.blocking`) and combination over realisations
(:func:`.errors.combine`) give the errors.

Transform: G*(w) = G' + i G'' = i w int_0^t_M G(t) e^(-i w t) dt by the trapezoid rule
from t = 0,

    G'(w)  = w dt sum_m w_m G(m dt) sin(w m dt),
    G''(w) = w dt sum_m w_m G(m dt) cos(w m dt),      w_0 = w_M = 1/2, else 1,

on the grid of :func:`omega_grid` (1/t_M to w dt = :data:`MAX_OMEGA_DT`), the window
t_M = M dt a fraction :data:`WINDOW_FRACTION` of the longest realisation unless given;
:func:`tail_check` says when G has not decayed within it.

Short times (``lag0``): ``"contact"`` replaces lags 0-4 (:data:`CONTACT_REPLACED`) by the
step means of c t^-1/2 + b fitted to lags 5-20 (:data:`CONTACT_FIT_LAGS`; the contact
boundary layer of hard spheres, :func:`.analytic.dilute_hard_sphere_relaxation`);
``"linear"`` by a + b t fitted to the same lags (a G finite at t = 0, as with
lubrication: Lionberger & Russel, J. Rheol. 38, 1885 (1994)); ``"lag1"`` replaces lag 0
by lag 1; ``"keep"`` keeps the sampled lags. Why the sampled short lags differ from the
physical ones, the accuracy of the transform and the measurements: docs/reduce.md, "Runs
at rest: Green-Kubo".

Units: reduced, a = 1, eta_m = 1, t in t_D, kT = 6 pi eta_m a^3/t_D, stresses and moduli
in eta_m/t_D, omega in 1/t_D.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .errors import Blocking, blocking, combine

#: the five deviatoric components averaged over (module docstring)
DEVIATORIC = ("xy", "xz", "yz", "(xx-yy)/2", "(xx+yy-2zz)/(2 sqrt3)")
#: time origins per realisation are cut into this many blocks for the errors
BASE_BLOCKS = 64
#: default window t_M: this fraction of the longest analysed realisation
WINDOW_FRACTION = 0.125
#: highest omega of the grid: w dt = MAX_OMEGA_DT
MAX_OMEGA_DT = 0.2
#: the omega grid: 2 pi 2^(j/POINTS_PER_OCTAVE), j integer
POINTS_PER_OCTAVE = 4
#: the short-time rules (module docstring; the reducer's default: at_rest.default_lag0)
LAG0_RULES = ("keep", "lag1", "contact", "linear")
#: the lags fitted by the "contact" and "linear" rules, and the lags they replace
CONTACT_FIT_LAGS = tuple(range(5, 21))
CONTACT_REPLACED = 5
#: lags reported in relaxation tables: every lag up to this, then ~LAGS_PER_DECADE per decade
ALL_LAGS_UP_TO = 32
LAGS_PER_DECADE = 24


def deviatoric(stress):
    """(..., n, 6) stress 6-vectors (xx yy zz xy xz yz) -> (..., 5, n): s_xy, s_xz, s_yz,
    (s_xx - s_yy)/2 and (s_xx + s_yy - 2 s_zz)/(2 sqrt 3), the components of equal
    variance and no mutual correlation in an isotropic fluid (module docstring)."""
    s = np.moveaxis(np.asarray(stress, float), -1, -2)
    xx, yy, zz = s[..., 0, :], s[..., 1, :], s[..., 2, :]
    return np.stack([s[..., 3, :], s[..., 4, :], s[..., 5, :], 0.5 * (xx - yy),
                     (xx + yy - 2.0 * zz) / (2.0 * math.sqrt(3.0))], axis=-2)


def block_correlations(series, conjugate, max_lag, n_blocks=BASE_BLOCKS):
    """Per block of time origins, the correlation (1/5) sum_c mean_k a_c(k + m) b_c(k) for
    m = 0 .. max_lag.

    series (S, 5, n): the deviatoric components of S streams; conjugate (5, n): those of
    the stress they are correlated with. The origins k = 0 .. n - max_lag - 1 are cut into
    ``n_blocks`` blocks of equal length L (the last few origins beyond n_blocks L are
    dropped). Returns (values (n_blocks, S, max_lag + 1), origins used = n_blocks L);
    ValueError when fewer than n_blocks origins exist."""
    a, b = np.asarray(series, float), np.asarray(conjugate, float)
    n, m = a.shape[-1], int(max_lag)
    length = (n - m) // n_blocks
    if length < 1:
        raise ValueError(f"{n} samples give fewer than {n_blocks} time origins at lag {m}")
    size = 1 << int(math.ceil(math.log2(length + m)))      # no wrap-around for lags <= m
    starts = np.arange(n_blocks) * length
    idx_a = starts[:, None] + np.arange(length + m)        # (B, L + M)
    idx_b = starts[:, None] + np.arange(length)            # (B, L)
    out = np.zeros((n_blocks, a.shape[0], m + 1))
    for c in range(a.shape[1]):
        fb = np.conj(np.fft.rfft(b[c][idx_b], size))       # (B, F)
        for s in range(a.shape[0]):
            fa = np.fft.rfft(a[s, c][idx_a], size)
            out[:, s] += np.fft.irfft(fa * fb, size)[:, :m + 1]
    return out / (5.0 * length), n_blocks * length


def step_averaged_inverse_sqrt(lags):
    """The correlation at lag m dt of step means of a stress whose G(t) = |t|^-1/2, in units
    of dt^-1/2: (1/dt) int |t|^-1/2 tri((t - m dt)/dt) dt, tri the unit triangle, =
    (4/3) [(m + 1)^3/2 - 2 m^3/2 + |m - 1|^3/2] (8/3 at m = 0)."""
    m = np.asarray(lags, float)
    return 4.0 / 3.0 * ((m + 1) ** 1.5 - 2 * m ** 1.5 + np.abs(m - 1) ** 1.5)


#: the short-time forms fitted by a rule: lags -> (lags, 2) basis functions
SHORT_TIME_FORMS = {
    "contact": lambda m: np.stack([step_averaged_inverse_sqrt(m), np.ones(m.size)], axis=1),
    "linear": lambda m: np.stack([m.astype(float), np.ones(m.size)], axis=1)}


def apply_lag0(g, rule):
    """G(t) on lags 0 .. M along the last axis with the short-time rule applied (module
    docstring): "keep" returns it unchanged, "lag1" with G(0) := G(dt), "contact" and
    "linear" with the lags below CONTACT_REPLACED replaced by their form
    (:data:`SHORT_TIME_FORMS`: the step means of c t^-1/2 + b, or a + b t) fitted (least
    squares) to the lags CONTACT_FIT_LAGS. Every rule is linear in g."""
    if rule not in LAG0_RULES:
        raise ValueError(f"lag0 = {rule!r}; allowed: {', '.join(LAG0_RULES)}")
    g = np.array(g, float)
    if rule == "lag1":
        g[..., 0] = g[..., 1]
    elif rule in SHORT_TIME_FORMS:
        form = SHORT_TIME_FORMS[rule]
        fit = np.array(CONTACT_FIT_LAGS)
        coef = g[..., fit] @ np.linalg.pinv(form(fit)).T                # (..., 2)
        g[..., :CONTACT_REPLACED] = coef @ form(np.arange(CONTACT_REPLACED)).T
    return g


def transform(g, dt, omega):
    """(G', G'') of G(t) given on lags m dt, m = 0 .. M, along the last axis: the
    trapezoid rule from t = 0 to t_M of G*(w) = i w int G(t) e^(-i w t) dt (module
    docstring). Returns two arrays (..., len(omega))."""
    g = np.asarray(g, float)
    w = np.atleast_1d(np.asarray(omega, float))
    t = np.arange(g.shape[-1]) * dt
    weight = np.ones(g.shape[-1])
    weight[[0, -1]] = 0.5
    phase = w[:, None] * t[None, :]                            # (W, M + 1)
    kernel = w[:, None] * dt * weight[None, :]
    return g @ (kernel * np.sin(phase)).T, g @ (kernel * np.cos(phase)).T


def omega_grid(dt, window):
    """The frequencies the data support: 2 pi 2^(j/POINTS_PER_OCTAVE) from 1/window (one
    radian over the window) to MAX_OMEGA_DT/dt (module docstring)."""
    lo, hi = 1.0 / window, MAX_OMEGA_DT / dt
    j = np.arange(math.ceil(POINTS_PER_OCTAVE * math.log2(lo / (2 * math.pi)) - 1e-9),
                  math.floor(POINTS_PER_OCTAVE * math.log2(hi / (2 * math.pi)) + 1e-9) + 1)
    return 2.0 * math.pi * 2.0 ** (j / POINTS_PER_OCTAVE)


def report_lags(max_lag):
    """The lags of a relaxation table: every lag up to ALL_LAGS_UP_TO, then about
    LAGS_PER_DECADE per decade up to max_lag (always included)."""
    top = max(int(max_lag), 0)
    geo = np.geomspace(1, max(top, 1), max(int(LAGS_PER_DECADE * math.log10(max(top, 1))), 1) + 1)
    lags = np.concatenate([np.arange(min(ALL_LAGS_UP_TO, top) + 1), np.rint(geo), [top]])
    return np.unique(lags.astype(int))


class Realisation(NamedTuple):
    """One realisation's Green-Kubo values per stream (the rows of ``series`` and, last,
    their sum): ``relaxation`` Blocking with fields (S + 1, lags) of G(t) on ``lags``,
    ``moduli`` Blocking with fields (S + 1, 2, W) of (G', G'') on ``omega``; ``n`` is the
    number of time origins (the realisation's weight in the ensemble)."""
    relaxation: Blocking
    moduli: Blocking


def realisation_values(series, dt, volume, kT, max_lag, omega, lags, lag0="keep"):
    """G(t) and G*(w) of one realisation (module docstring).

    series (S, n, 6): each contribution's stress 6-vectors at rest (eta_m/t_D); the
    configurational stress is their sum. dt (t_D), volume (a^3), kT (6 pi in reduced
    units), max_lag M (the window t_M = M dt), omega (W,), lags: the lags to report.
    Returns :class:`Realisation`: rows 0 .. S - 1 are the contributions (their
    cross-correlation with the sum), row S the sum (its autocorrelation)."""
    dev = deviatoric(series)                                    # (S, 5, n)
    blocks, origins = block_correlations(dev, dev.sum(axis=0), max_lag)
    blocks = np.concatenate([blocks, blocks.sum(axis=1, keepdims=True)], axis=1)
    blocks = apply_lag0(blocks * (volume / kT), lag0)           # (B, S + 1, M + 1)
    g1, g2 = transform(blocks, dt, omega)                       # (B, S + 1, W) each
    relax = blocking(np.moveaxis(blocks[..., lags], 0, -1))
    mod = blocking(np.moveaxis(np.stack([g1, g2], axis=2), 0, -1))
    return Realisation(*(b._replace(n=np.full_like(b.n, origins)) for b in (relax, mod)))


def ensemble(values):
    """Combine :class:`Realisation` values (a list, None for a realisation without data)
    into (relaxation, moduli) :class:`.errors.EnsembleEstimate` over the realisations, each
    weighted by its number of time origins (:func:`.errors.combine`)."""
    present = [v for v in values if v is not None]
    out = []
    for field in Realisation._fields:
        ref = getattr(present[0], field)
        parts = [getattr(v, field) if v is not None else
                 Blocking(*(np.full_like(np.asarray(x), np.nan if k < 2 else 0, dtype=float)
                            for k, x in enumerate(ref))) for v in values]
        stacked = Blocking(*(np.stack([np.asarray(p[k], float) for p in parts], axis=-1)
                             for k in range(len(Blocking._fields))))
        out.append(combine(stacked))
    return tuple(out)


def tail_check(mean, err, fraction=0.1, sigmas=3.0):
    """Whether G(t) has decayed within the window: the mean of G over the last
    ``fraction`` of the reported lags, against ``sigmas`` times its error (errors of
    neighbouring lags treated as fully correlated, so the error is their mean). Returns
    (decayed: bool, mean, error)."""
    mean, err = np.asarray(mean, float), np.asarray(err, float)
    k = max(int(round(fraction * mean.size)), 1)
    m, e = float(np.mean(mean[-k:])), float(np.mean(err[-k:]))
    return bool(abs(m) <= sigmas * e), m, e
