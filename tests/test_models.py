"""Viscosity laws of sdmpi.analysis.models: dilute limits, O(phi^2) coefficients, the
divergence at phi_max, relations between the laws."""

import numpy as np
import pytest

from sdmpi.analysis.models import (batchelor_green, eilers, einstein, krieger_dougherty,
                                   maron_pierce)

SMALL = np.array([1e-6, 1e-5, 1e-4])


@pytest.mark.parametrize("law", [krieger_dougherty, eilers, batchelor_green])
@pytest.mark.parametrize("phi_max", [0.58, 0.64, 0.71])
def test_dilute_limit_is_einstein(law, phi_max):
    value = law(SMALL) if law is batchelor_green else law(SMALL, phi_max=phi_max)
    slope = (value - 1.0) / SMALL
    # (eta - 1)/phi = 2.5 + c2 phi + ..., with |c2| < 10 for these laws
    assert np.all(np.abs(slope - 2.5) < 10 * SMALL)
    assert np.all(np.abs(value - einstein(SMALL)) < 10 * SMALL ** 2)


def test_maron_pierce_dilute_slope_is_two_over_phi_max_einstein_at_0_8():
    for phi_max in (0.58, 0.64, 0.8):
        slope = (maron_pierce(SMALL, phi_max) - 1.0) / SMALL
        assert np.allclose(slope, 2.0 / phi_max, rtol=1e-3)
    assert np.all(np.abs(maron_pierce(SMALL, 0.8) - einstein(SMALL)) < 10 * SMALL ** 2)
    # Krieger-Dougherty with [eta] phi_max = 2
    phi = np.linspace(0, 0.6, 13)
    assert np.allclose(maron_pierce(phi, 0.63), krieger_dougherty(phi, 0.63, intrinsic=2 / 0.63))


def test_eilers_second_order_coefficient():
    phi_max = 0.64
    phi = 1e-3
    c2 = (eilers(phi, phi_max) - 1 - 2.5 * phi) / phi ** 2
    assert c2 == pytest.approx(1.5625 + 2.5 / phi_max, rel=1e-2)
    assert 5.0 < c2 < 6.0        # near Batchelor-Green's 5.2


@pytest.mark.parametrize("law,prefactor", [(maron_pierce, lambda m: 1.0),
                                           (eilers, lambda m: (1.25 * m) ** 2)])
def test_divergence_at_phi_max(law, prefactor):
    m = 0.62
    for eps in (1e-4, 1e-5):
        phi = m * (1 - eps)
        assert law(phi, m) * eps ** 2 == pytest.approx(prefactor(m), rel=1e-3)


@pytest.mark.parametrize("law", [maron_pierce, eilers, krieger_dougherty])
def test_monotone_and_range_checked(law):
    phi = np.linspace(0, 0.6, 61)
    v = law(phi, 0.64)
    assert v[0] == 1.0 and np.all(np.diff(v) > 0)
    with pytest.raises(ValueError):
        law(0.64, 0.64)
    with pytest.raises(ValueError):
        law(-0.1, 0.64)
