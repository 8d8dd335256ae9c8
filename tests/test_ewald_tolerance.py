"""A looser Ewald tolerance on an equilibrium configuration (N = 27, phi = 0.45): the
mobility R_FU^-1 and the high-frequency viscosity eta_H stay within 0.2% of their values
at the reference tolerance 1e-6 down to 1e-3, the default of Brownian jobs (the bound a
Brownian run's default must meet; bench/ewald_tolerance.py measures 20 configurations,
with the drift and the Brownian stresslets), and the error shrinks as the tolerance
tightens (the sums converge)."""

import numpy as np

from sdmpi.config.schema import BROWNIAN_EWALD_TOLERANCE
from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro.bulk import hydrodynamic_viscosity
from sdmpi.hydro.resistance import grand_resistance


def test_looser_ewald_tolerance_keeps_mobility_and_viscosity_within_bound():
    pos, side = hard_sphere_fluid(27, 0.45, np.random.default_rng(7), sweeps=50)
    box = np.full(3, side)

    def quantities(tol):
        res = grand_resistance(pos, np.ones(27), box, 0.0, ewald_tol=tol)
        return np.linalg.inv(res.blocks()[0]), hydrodynamic_viscosity(res.positions, box, ewald_tol=tol)

    mob_ref, eta_ref = quantities(1e-6)
    errors = []
    for tol in (1e-5, 1e-4, BROWNIAN_EWALD_TOLERANCE):
        mob, eta = quantities(tol)
        errors.append((np.linalg.norm(mob - mob_ref) / np.linalg.norm(mob_ref), abs(eta / eta_ref - 1)))
    assert max(max(e) for e in errors) < 2e-3
    for tighter, looser in zip(errors, errors[1:]):
        assert tighter[0] < looser[0] and tighter[1] < looser[1]
    assert 1.0 < eta_ref < 10.0  # a dense suspension: eta_H of a few medium viscosities
