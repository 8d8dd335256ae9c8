"""High-frequency viscosity of equilibrium hard-sphere suspensions at phi = 0.45 against
seed 000 eq. 38 (Schaink et al. 2000)."""

import math

import numpy as np
import pytest

from sdmpi.analysis.analytic import schaink_eta_h
from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro.bulk import hydrodynamic_viscosity


def test_eta_inf_at_phi_045_matches_seed_eq38_at_its_n():
    """eta'_inf = 1 + n <S_xy>/gamma_dot over independent equilibrium (Monte Carlo)
    configurations of the seed's N = 27, against 5.41 from eq. 38 (the seed's fit to its
    own N = 27 Brownian SD, within 1%). Measured: 5.40 +- 0.05 on 100 configurations; one
    configuration scatters by ~0.5 with a tail up to +1.2 (rare close triplets), so 30
    give +- 0.09 and the tolerance 6% (0.32) is 3.5 standard errors. Starts that keep their lattice's memory (200 sweeps: 4.83) fail, as do
    runs without lubrication (2.9) or the dilute Batchelor-Green value (2.58). Larger N give
    more (5.8 at N = 64 and 125, docs/validation.md): eq. 38 holds for N = 27 only."""
    n, configs = 27, 30
    rng = np.random.default_rng(20000803 + n)
    values = [hydrodynamic_viscosity(*_config(n, rng)) for _ in range(configs)]
    eta_inf = 1 + np.mean(values)
    err = np.std(values, ddof=1) / math.sqrt(configs)
    print(f"N = {n}: eta'_inf = {eta_inf:.3f} +- {err:.3f}; seed eq. 38: {1 + schaink_eta_h(0.45):.3f}")
    assert eta_inf == pytest.approx(1 + schaink_eta_h(0.45), rel=0.06)
    assert err < 0.05 * eta_inf


def _config(n, rng):
    pos, side = hard_sphere_fluid(n, 0.45, rng)
    return pos, [side] * 3
