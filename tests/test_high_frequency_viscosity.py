"""High-frequency viscosity of equilibrium hard-sphere suspensions at phi = 0.45 against
seed 000 eq. 38 (Schaink et al. 2000). The measured values are recorded in the README."""

import math

import numpy as np
import pytest

from sdmpi.analysis.models import schaink_eta_h
from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro.bulk import hydrodynamic_viscosity


@pytest.mark.parametrize("n, configs", [(27, 8), (64, 6)])
def test_eta_inf_at_phi_045_close_to_seed_eq38(n, configs):
    """eta'_inf = 1 + n <S_xy>/gamma_dot over independent equilibrium (Monte Carlo)
    configurations, against 5.41 from eq. 38. Measured (README): 4.9 +- 0.1 here, and
    5.07 +- 0.04 on 120 configurations: 6% low, a gap we have not explained (README lists
    what was checked). Eq. 38 fits the seed's Brownian SD within 1%; the tolerance is 12%
    (the gap plus the scatter of 6-8 configurations); it still fails without
    lubrication (2.9) or with the dilute Batchelor-Green value (2.58)."""
    rng = np.random.default_rng(20000803 + n)
    values = [hydrodynamic_viscosity(*_config(n, rng)) for _ in range(configs)]
    eta_inf = 1 + np.mean(values)
    err = np.std(values, ddof=1) / math.sqrt(configs)
    print(f"N = {n}: eta'_inf = {eta_inf:.3f} +- {err:.3f}; seed eq. 38: {1 + schaink_eta_h(0.45):.3f}")
    assert eta_inf == pytest.approx(1 + schaink_eta_h(0.45), rel=0.12)
    assert err < 0.05 * eta_inf


def _config(n, rng):
    pos, side = hard_sphere_fluid(n, 0.45, rng)
    return pos, [side] * 3
