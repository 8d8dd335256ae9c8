"""Viscosity laws of sdmpi.analysis.analytic: dilute limits, O(phi^2) coefficients, the
divergence at phi_max, relations between the laws."""

import math

import numpy as np
import pytest

from sdmpi.analysis.analytic import (batchelor_green, eilers, einstein, krieger_dougherty,
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


def _contact_coefficient(omega, outer=40.0):
    """c* of dilute hard spheres without hydrodynamic interactions computed independently of
    the closed form: the radial equation i w f = 2 (f'' + 2 f'/r - 6 f/r^2) (a = D0 = 1)
    solved numerically on [2, 2 + outer/Re kappa] with f'(2) = 1 and f = 0 at the far end,
    then the contact stress -(n^2 kT (2a)^3/2) oint r^_x r^_y g dOmega under simple shear
    (E_xy = 1/2 per unit rate) integrated over the sphere, kT = 6 pi, n = 3 phi/(4 pi)."""
    from scipy import integrate
    w = float(omega)
    r_end = 2.0 + outer / math.sqrt(w / 4.0)

    def rhs(r, y):  # y = (Re f, Im f, Re f', Im f')
        f, df = y[0] + 1j * y[1], y[2] + 1j * y[3]
        d2 = 0.5j * w * f - 2 * df / r + 6 * f / r ** 2
        return np.vstack([y[2], y[3], d2.real, d2.imag])

    def bc(ya, yb):
        return np.array([ya[2] - 1.0, ya[3], yb[0], yb[1]])

    r = np.geomspace(2.0, r_end, 400)
    sol = integrate.solve_bvp(rhs, bc, r, np.zeros((4, r.size)), tol=1e-8, max_nodes=100000)
    assert sol.success
    f_contact = sol.sol(2.0)[0] + 1j * sol.sol(2.0)[1]

    def integrand(theta, phi_angle, part):
        e = np.array([np.sin(theta) * np.cos(phi_angle), np.sin(theta) * np.sin(phi_angle), np.cos(theta)])
        g = 1 + f_contact * e[0] * e[1]  # r^.E.r^ with E_xy = E_yx = 1/2
        return (e[0] * e[1] * g).real * np.sin(theta) if part == 0 else (e[0] * e[1] * g).imag * np.sin(theta)

    oint = [integrate.dblquad(integrand, 0, 2 * np.pi, 0, np.pi, args=(k,), epsabs=1e-12)[0] for k in (0, 1)]
    n_over_phi = 3 / (4 * np.pi)
    # sigma_xy / (gamma_dot phi^2) = eta*: -(n^2 kT 8/2) oint e_x e_y g
    return -(n_over_phi ** 2 * 6 * np.pi * 8 / 2) * (oint[0] + 1j * oint[1])


def test_dilute_hard_sphere_viscosity_limits():
    """Zero frequency: 12/5 phi^2 (Brady 1993, Bergenholtz et al. 2002); low frequency
    G' ~ (8/15) w^2; high frequency eta' ~ (18/5) w^-1/2, eta'' ~ (18/5)(w^-1/2 - w^-1), the
    next terms being O(w^-3/2); eta' decreases monotonically."""
    from sdmpi.analysis.analytic import dilute_hard_sphere_moduli, dilute_hard_sphere_viscosity
    c1, c2 = dilute_hard_sphere_viscosity(np.array([0.0, 1e-8]))
    assert c1 == pytest.approx([2.4, 2.4], rel=1e-6) and c2[0] == 0
    w = 1e-5
    g1, g2 = dilute_hard_sphere_moduli(w)
    assert g1 / w ** 2 == pytest.approx(8 / 15, rel=1e-2) and g2 / w == pytest.approx(2.4, rel=1e-6)
    w = np.array([1e6, 1e8])
    c1, c2 = dilute_hard_sphere_viscosity(w)
    assert np.allclose(c1, 3.6 / np.sqrt(w), rtol=1e-5)
    assert np.allclose(c2, 3.6 * (1 / np.sqrt(w) - 1 / w), rtol=1e-5)
    g1, g2 = dilute_hard_sphere_moduli(w)
    assert np.allclose(g1, 3.6 * (np.sqrt(w) - 1), rtol=0, atol=0.01)  # + O(w^-1/2)
    assert np.all(np.diff(dilute_hard_sphere_viscosity(np.geomspace(1e-3, 1e3, 50))[0]) < 0)


@pytest.mark.parametrize("omega", [0.5, 2.0, 8.0])
def test_dilute_hard_sphere_viscosity_solves_the_pair_smoluchowski_equation(omega):
    """The closed form against a numerical solution of its boundary-value problem and a
    numerical angular integral of the contact stress (all prefactors included): to 1e-5
    (the boundary-value solver's tolerance)."""
    from sdmpi.analysis.analytic import dilute_hard_sphere_viscosity
    c1, c2 = dilute_hard_sphere_viscosity(omega)
    numeric = _contact_coefficient(omega)
    assert numeric.real == pytest.approx(c1, rel=1e-5)
    assert -numeric.imag == pytest.approx(c2, rel=1e-5)


def test_dilute_hard_sphere_viscosity_obeys_kramers_kronig():
    """Causality: eta'(0) - eta'(inf) = (2/pi) int_0^inf eta''(x)/x dx, with eta'(inf) = 0
    (no instantaneous interparticle stress without hydrodynamic interactions)."""
    from scipy import integrate
    from sdmpi.analysis.analytic import dilute_hard_sphere_viscosity
    total = 0.0
    for lo, hi in ((0, 1), (1, 100), (100, np.inf)):
        total += integrate.quad(lambda x: dilute_hard_sphere_viscosity(x)[1] / x, lo, hi, epsabs=1e-12,
                                limit=200)[0]
    assert 2 / np.pi * total == pytest.approx(2.4, rel=1e-6)
