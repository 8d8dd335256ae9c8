"""Analytic models for overlays and checks. Viscosities are relative to the medium's."""


def einstein(phi):
    """eta/eta_m = 1 + 2.5 phi (Einstein 1906/1911); dilute limit, phi -> 0."""
    return 1.0 + 2.5 * phi


def batchelor_green(phi):
    """eta/eta_m = 1 + 2.5 phi + 5.2 phi^2 (Batchelor & Green 1972; seed 000 eq. 37):
    hydrodynamic O(phi^2) result without Brownian motion; valid for phi <~ 0.1-0.2."""
    return 1.0 + 2.5 * phi + 5.2 * phi ** 2


def schaink_eta_h(phi):
    """eta_H/eta_m = 2.5 phi + 5.2 phi^2 + 3.01 phi^3 + 47.71 phi^4 (seed 000 eq. 38):
    polynomial fit to SD hydrodynamic viscosities (N = 27, Brownian, omega = 2 pi),
    stated within 1% for 0 <= phi <= 0.45. The high-frequency viscosity is 1 + eta_H."""
    return 2.5 * phi + 5.2 * phi ** 2 + 3.01 * phi ** 3 + 47.71 * phi ** 4
