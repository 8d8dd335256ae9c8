"""Per-period moduli of one stress signal by Fourier projection (Schaink et al. 2000, eqs. 17-19).

Conventions (DESIGN.md): strain gamma(t) = gamma0 sin(w t); the xy stress of one
realisation (or one contribution to it) is written as

    sigma_xy(t) = gamma0 [G'(w) sin(w t) + G''(w) cos(w t)] + (noise, harmonics)   (eq. 17)

and each whole period [t_p, t_p + 2 pi/w) is projected on sin and cos (eq. 18):

    G'  = w/(pi gamma0) int_period sigma_xy sin(w t) dt
    G'' = w/(pi gamma0) int_period sigma_xy cos(w t) dt

Units: reduced (radius 1, eta_m = 1, time in t_D), so stresses and moduli are in
eta_m/t_D and w in 1/t_D; eta' = G''/w, eta'' = G'/w are relative to eta_m (eq. 19).

Quadrature: n = ``samples_per_period`` uniform samples per period at t_k = t0 + k dt,
dt = 2 pi/(w n); period p is the n samples k = p n ... p n + n - 1 (its start, not its
end: no sample counted twice), integrated by the rectangle rule dt sum_k f(t_k), which
for a periodic integrand is the trapezoid rule and returns G', G'' exactly for a constant
plus harmonics of order <= n - 2 (n >= 3). A stream whose sample k represents t_k + c dt
(``sample_offset`` c, `sdmpi.config.stresses`) is projected with t0 = c dt; t0 may
differ from one signal to the next (an array over the leading axes). Projected half a
step off, G' would be off by (pi/n) G'' (docs/physics.md, "Sample times").
"""

import numpy as np


def project_periods(stress, gamma0, omega, samples_per_period, discard_periods=0, t0=0.0):
    """Per-period G'(w), G''(w) of sampled stress signals (Schaink et al. eq. 18, rectangle rule).

    stress: (..., n_samples) sigma_xy at t_k = t0 + k 2 pi/(w n), k = 0, 1, ...
    (leading axes: realisations, contributions, ... are projected independently);
    t0: the time of sample 0, a number or an array broadcast against the leading axes
    (each signal its own sample times).
    gamma0: strain amplitude; omega: angular frequency w (1/t_D);
    samples_per_period: n >= 3 (integer); discard_periods: whole start-up periods
    dropped from the front. A trailing partial period is ignored.

    Returns (G1, G2), each (..., n_periods) with n_periods = n_samples // n -
    discard_periods (0 if negative): G1 = (2/(n gamma0)) sum_k sigma_k sin(w t_k),
    G2 = (2/(n gamma0)) sum_k sigma_k cos(w t_k) over each whole period.
    """
    stress = np.asarray(stress, dtype=float)
    n = int(samples_per_period)
    if n != samples_per_period or n < 3:
        raise ValueError(f"samples_per_period must be an integer >= 3, got {samples_per_period!r}")
    if discard_periods < 0 or int(discard_periods) != discard_periods:
        raise ValueError(f"discard_periods must be an integer >= 0, got {discard_periods!r}")
    if gamma0 == 0 or omega <= 0:
        raise ValueError(f"need gamma0 != 0 and omega > 0, got gamma0={gamma0!r}, omega={omega!r}")
    first = int(discard_periods)
    n_periods = max(stress.shape[-1] // n - first, 0)
    periods = stress[..., first * n:(first + n_periods) * n]
    periods = periods.reshape(stress.shape[:-1] + (n_periods, n))
    # w t_k within any period: w t0 + 2 pi j/n (w T = 2 pi), so one template per signal
    # serves all its periods.
    phase = omega * np.asarray(t0, dtype=float)[..., None] + 2.0 * np.pi * np.arange(n) / n
    scale = 2.0 / (n * gamma0)
    if phase.ndim == 1:
        return scale * (periods @ np.sin(phase)), scale * (periods @ np.cos(phase))
    sin, cos = np.sin(phase)[..., None], np.cos(phase)[..., None]       # (..., n, 1)
    return scale * (periods @ sin)[..., 0], scale * (periods @ cos)[..., 0]


def viscosities(g_prime, g_dprime, omega):
    """(eta', eta'') = (G''/w, G'/w), relative to eta_m (Schaink et al. eq. 19,
    eta* = eta' - i eta''). Linear, so it converts standard errors the same way."""
    return np.asarray(g_dprime) / omega, np.asarray(g_prime) / omega
