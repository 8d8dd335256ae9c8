"""Analytic models for overlays and checks. Viscosities are relative to the medium's.

Relative viscosity laws: Einstein (dilute), Batchelor-Green (O(phi^2)), Schaink et al.'s (2000)
polynomial fit (eq. 38), and the empirical concentrated-suspension laws Krieger-Dougherty,
Maron-Pierce and Eilers (all with a maximum packing fraction phi_max). Einstein is the
dilute limit of all but Maron-Pierce, whose slope is 2/phi_max (Einstein only for
phi_max = 0.8). Maxwell-medium moduli and viscosities (Schaink et al. 2000, eqs. 36, 41-42).
The exact O(phi^2) linear viscoelasticity of Brownian hard spheres without hydrodynamic
interactions (Cichocki & Felderhof 1991).
"""

import numpy as np


def einstein(phi):
    """eta/eta_m = 1 + 2.5 phi (Einstein 1906/1911); dilute limit, phi -> 0."""
    return 1.0 + 2.5 * phi


def batchelor_green(phi):
    """eta/eta_m = 1 + 2.5 phi + 5.2 phi^2 (Batchelor & Green 1972; Schaink et al. 2000, eq. 37):
    hydrodynamic O(phi^2) result without Brownian motion; valid for phi <~ 0.1-0.2."""
    return 1.0 + 2.5 * phi + 5.2 * phi ** 2


def schaink_eta_h(phi):
    """eta_H/eta_m = 2.5 phi + 5.2 phi^2 + 3.01 phi^3 + 47.71 phi^4 (Schaink et al. 2000, eq. 38):
    polynomial fit to SD hydrodynamic viscosities (N = 27, Brownian, omega = 2 pi),
    stated within 1% for 0 <= phi <= 0.45. The high-frequency viscosity is 1 + eta_H."""
    return 2.5 * phi + 5.2 * phi ** 2 + 3.01 * phi ** 3 + 47.71 * phi ** 4


def _modes(eta, lam):
    """Mode arrays (K,) for broadcasting against omega (..., 1)."""
    eta, lam = np.atleast_1d(np.asarray(eta, float)), np.atleast_1d(np.asarray(lam, float))
    if eta.shape != lam.shape or eta.ndim != 1:
        raise ValueError("eta and lam must be matching 1-D sequences, one entry per mode")
    return eta, lam


def maxwell_viscosity(omega, eta, lam):
    """Complex viscosity eta* = eta' - i eta'' of a multi-mode Maxwell medium (Schaink et al. 2000,
    eq. 36, summed over modes; each mode obeys lam_k dS/dt + S = eta_k gamma_dot, eq. 2):
        eta'  = sum_k eta_k / (1 + (lam_k w)^2),
        eta'' = sum_k eta_k lam_k w / (1 + (lam_k w)^2).
    omega: angular frequency (any shape, 1/t_D); eta, lam: per-mode viscosities
    (relative to eta_m; sum_k eta_k is the zero-shear viscosity) and relaxation times
    (t_D). Exact linear viscoelasticity for all w; the medium stress is linear only for
    small Weissenberg numbers (Schaink et al. eq. 20). Returns (eta', eta'') shaped like omega."""
    eta, lam = _modes(eta, lam)
    w = np.asarray(omega, float)[..., None]
    d = 1.0 + (lam * w) ** 2
    return (eta / d).sum(axis=-1), (eta * lam * w / d).sum(axis=-1)


def maxwell_moduli(omega, eta, lam):
    """Storage and loss moduli of a multi-mode Maxwell medium (Schaink et al. 2000, eq. 36 with
    eq. 19, G' = w eta'', G'' = w eta'; standard Maxwell model, e.g. Ferry 1980):
        G'  = sum_k eta_k lam_k w^2 / (1 + (lam_k w)^2),
        G'' = sum_k eta_k w / (1 + (lam_k w)^2).
    Limits: w -> 0: G'' -> w sum eta_k, G' -> w^2 sum eta_k lam_k; w -> inf:
    G' -> sum eta_k/lam_k, G'' -> 0. Units: eta_m/t_D. Returns (G', G'')."""
    eta1, eta2 = maxwell_viscosity(omega, eta, lam)
    w = np.asarray(omega, float)
    return w * eta2, w * eta1


def maxwell_eta_h(omega, eta_h0, eta, lam):
    """Hydrodynamic contribution to eta* of spheres in a multi-mode Maxwell medium
    (Schaink et al. 2000, eqs. 41-42, correspondence principle):
        eta*_H(w) = (eta_H(0)/eta_0m) eta*_m(w),   eta_0m = sum_k eta_k,
    i.e. eta'_H = eta_h0 sum_k eta_k/(1 + (lam_k w)^2) and
    eta''_H = eta_h0 sum_k eta_k lam_k w/(1 + (lam_k w)^2).
    eta_h0 = eta_H(0)/eta_0m: the hydrodynamic viscosity increment of the same spheres
    in a Newtonian medium (e.g. schaink_eta_h(phi), or an SD result), assumed
    independent of w (Schaink et al. Fig. 7). Validity: particle dynamics unaffected by the
    medium's elasticity, t_B << t <= lambda, low Re and Wi (Schaink et al. eqs. 20, 32); the
    Brownian contribution is not included. Returns (eta'_H, eta''_H), units of eta."""
    eta1, eta2 = maxwell_viscosity(omega, eta, lam)
    f = np.asarray(eta_h0, float)
    return f * eta1, f * eta2


def krieger_dougherty(phi, phi_max=0.64, intrinsic=2.5):
    """eta/eta_m = (1 - phi/phi_max)^(-[eta] phi_max) (Krieger & Dougherty, Trans. Soc.
    Rheol. 3, 137 (1959)); [eta] = 2.5 for spheres gives Einstein's 1 + 2.5 phi as
    phi -> 0. Empirical, 0 <= phi < phi_max; phi_max is a fit parameter (about 0.64,
    random close packing, for the high-frequency/hydrodynamic viscosity; about
    0.58-0.63 for the zero-shear viscosity of Brownian hard spheres)."""
    phi = np.asarray(phi, float)
    phi = _check_below_max(phi, phi_max)
    return (1.0 - phi / phi_max) ** (-intrinsic * phi_max)


def _check_below_max(phi, phi_max):
    phi = np.asarray(phi, float)
    if np.any((phi < 0) | (phi >= phi_max)):
        raise ValueError(f"need 0 <= phi < phi_max = {phi_max}")
    return phi


def maron_pierce(phi, phi_max=0.64):
    """eta/eta_m = (1 - phi/phi_max)^(-2) (Maron & Pierce, J. Colloid Sci. 11, 80 (1956);
    the form used by Finke et al. 2020 and, with phi_max fitted, for non-Brownian suspensions by
    e.g. Zarraga, Hill & Leighton, J. Rheol. 44, 185 (2000), Mari et al., J. Rheol. 58
    (2014)). Krieger-Dougherty with the exponent [eta] phi_max fixed at 2. Empirical,
    0 <= phi < phi_max. Dilute limit 1 + (2/phi_max) phi: Einstein's 2.5 phi only for
    phi_max = 0.8 (for phi_max = 0.64 the slope is 3.1); it is a concentrated-suspension
    fit, not a dilute theory. Diverges as (1 - phi/phi_max)^-2."""
    phi = _check_below_max(phi, phi_max)
    return (1.0 - phi / phi_max) ** -2


def eilers(phi, phi_max=0.64):
    """eta/eta_m = [1 + 1.25 phi / (1 - phi/phi_max)]^2 (Eilers, Kolloid-Z. 97, 313
    (1941); reviewed by Stickel & Powell, Annu. Rev. Fluid Mech. 37, 129 (2005);
    phi_max ~ 0.58-0.64 from fits to non-Brownian data, e.g. Zarraga et al. 2000: 0.62).
    Empirical, 0 <= phi < phi_max. Dilute limit: 1 + 2.5 phi + (1.5625 + 2.5/phi_max)
    phi^2 + ..., Einstein for every phi_max (O(phi^2) coefficient 5.47 at phi_max = 0.64,
    near Batchelor-Green's 5.2); near phi_max: (1.25 phi_max)^2 (1 - phi/phi_max)^-2, the
    same divergence as Maron-Pierce."""
    phi = _check_below_max(phi, phi_max)
    return (1.0 + 1.25 * phi / (1.0 - phi / phi_max)) ** 2


def dilute_hard_sphere_viscosity(omega):
    """O(phi^2) complex viscosity of Brownian hard spheres without hydrodynamic interactions,
    eta*(w) - eta_m (1 + 5/2 phi) = phi^2 eta_m c*(w), exact as phi -> 0 (Cichocki &
    Felderhof, Phys. Rev. A 43, 5405 (1991); Brady, J. Chem. Phys. 99, 567 (1993);
    Lionberger & Russel, J. Rheol. 38, 1885 (1994)). Returns (c', c''), eta* = eta' - i eta''
    (Schaink et al. 2000, eq. 19), for w in 1/t_D (t_D = a^2/D0, any shape).

    Derivation. The pair distribution of two spheres, g(r, t), obeys the pair Smoluchowski
    equation with the relative diffusivity 2 D0 (free draining) and the relative velocity
    Gamma.r of the imposed flow u = Gamma.x, with no flux through contact r = 2a:
    dg/dt + div(g Gamma.r - 2 D0 grad g) = 0, r.(g Gamma.r - 2 D0 grad g) = 0 at r = 2a,
    g -> 1 far away. For E(t) = Re[E0 e^(i w t)] (traceless, symmetric) the linear
    response is g = 1 + Re[f(r) (r^.E0.r^) e^(i w t)]: div(Gamma.r) = 0 and grad 1 = 0 leave
    i w f = 2 D0 (f'' + 2 f'/r - 6 f/r^2) outside contact (an l = 2 harmonic), forced through
    the boundary, f'(2a) = a/D0 (the convective flux 2a r^.E.r^ balanced by diffusion). The
    decaying solution is the modified spherical Bessel function k_2(kappa r), kappa =
    (i w/(2 D0))^(1/2) with Re kappa > 0, k_2(x) ~ e^-x (x^2 + 3x + 3)/x^3, so with
    z = 2a kappa = (2 i w a^2/D0)^(1/2):

        f(2a) = (2 a^2/D0) k_2(z)/(z k_2'(z)) = -(2 a^2/D0) (z^2 + 3z + 3)/(z^3 + 4z^2 + 9z + 9).

    The hard-sphere (contact) stress, -(n^2 kT (2a)^3/2) oint r^r^ g(2a, r^) dOmega (Batchelor
    1977; its trace is the contact osmotic pressure n kT 4 phi g(2a)), with
    oint r^r^ (r^.E.r^) dOmega = (8 pi/15) E and n = 3 phi/(4 pi a^3), is 2 eta_m phi^2 c* E:

        c*(w) = (36/5) (z^2 + 3z + 3)/(z^3 + 4z^2 + 9z + 9)
              = (12/5) (1 + z + z^2/3)/(1 + z + 4z^2/9 + z^3/9)

    in eta_m, using kT/D0 = 6 pi eta_m a. Limits: w -> 0, c* -> 12/5 (the zero-shear O(phi^2)
    Brownian viscosity without hydrodynamic interactions; Bergenholtz, Brady & Vicic, J.
    Fluid Mech. 456, 239 (2002)); w -> inf, c* ~ (36/5)(1/z - 1/z^2), i.e.
    c' ~ (18/5)(w t_D)^(-1/2) and c'' ~ (18/5)[(w t_D)^(-1/2) - (w t_D)^-1].

    The 5/2 phi is the single spheres' stresslet (20/3) pi a^3 E (Einstein), which sdmpi's
    free-draining model puts in the hydrodynamic stress; c* is the whole interparticle part,
    which sdmpi records as the collision stress (`dynamics.collisions`). Free draining has no
    O(phi^2) hydrodynamic term."""
    w = np.asarray(omega, float)
    z = np.sqrt(2j * w)
    c = 7.2 * (z * z + 3 * z + 3) / (z ** 3 + 4 * z * z + 9 * z + 9)
    return c.real, -c.imag


def dilute_hard_sphere_moduli(omega):
    """G'/phi^2 and G''/phi^2 of dilute_hard_sphere_viscosity (G' = w eta'', G'' = w eta'),
    in eta_m/t_D: the O(phi^2) moduli of hard spheres without hydrodynamic interactions,
    G* = i w eta*. Limits: w -> 0, G'' ~ (12/5) w and G' ~ (8/15) w^2 (c* = (12/5)(1 - z^2/9
    + O(z^3)): a mean relaxation time of 2/9 t_D); w -> inf, G' ~ (18/5)(w^(1/2) - 1), G'' ~ (18/5) w^(1/2)."""
    c1, c2 = dilute_hard_sphere_viscosity(omega)
    w = np.asarray(omega, float)
    return w * c2, w * c1



def dilute_hard_sphere_relaxation(t):
    """G(t)/phi^2 of dilute_hard_sphere_moduli at t > 0 (t_D), in eta_m/t_D: the O(phi^2)
    relaxation modulus of hard spheres without hydrodynamic interactions, whose Laplace
    transform is eta*(s) = c*(z), z = (2 s t_D)^1/2 (dilute_hard_sphere_viscosity with
    s = i w). In partial fractions over the roots z_j of z^3 + 4z^2 + 9z + 9,

        c* = (36/5) sum_j A_j/(z - z_j),   A_j = (z_j^2 + 3 z_j + 3)/(3 z_j^2 + 8 z_j + 9),

    and L^-1[1/(s^1/2 + a)] = (pi t)^-1/2 - a exp(a^2 t) erfc(a t^1/2) (a = -z_j/2^1/2,
    Re a > 0; exp(x^2) erfc(x) = w(i x), the Faddeeva function) give

        G(t)/phi^2 = (36/5) 2^-1/2 sum_j A_j [(pi t)^-1/2 - a_j w(i a_j t^1/2)].

    sum_j A_j = 1, so G ~ (18/5) (2/(pi t))^1/2 as t -> 0; int_0^inf G dt = c*(0) = 12/5."""
    from scipy.special import wofz
    t = np.asarray(t, float)
    roots = np.roots([1.0, 4.0, 9.0, 9.0])
    amp = (roots ** 2 + 3 * roots + 3) / (3 * roots ** 2 + 8 * roots + 9)
    a = -roots / np.sqrt(2.0)
    x = np.sqrt(t)[..., None]
    terms = amp * (1.0 / np.sqrt(np.pi * t)[..., None] - a * wofz(1j * a * x))
    return (7.2 / np.sqrt(2.0) * terms.sum(axis=-1)).real
