"""Sedimentation, K = 6 pi <U>/F for the same force F on every sphere: the collective part
of the hydrodynamics. Simple cubic arrays (one sphere per periodic cell) against the
Faxen-corrected point-force lattice (Hasimoto 1959) and exact array drags (Zick & Homsy
1982; Sangani & Acrivos 1982); random hard-sphere suspensions: the dependence on the box."""

import math

import numpy as np
import pytest

from sdmpi.dynamics.initial import hard_sphere_fluid
from sdmpi.hydro import solve_mobility
from sdmpi.hydro.bulk import hydrodynamic_viscosity

#: Hasimoto's constant, 6 pi U/F = 1 - HASIMOTO a/L for point forces on a cubic lattice
HASIMOTO = 2.8372975
#: Zick & Homsy, J. Fluid Mech. 115, 13 (1982), table 2, simple cubic: (phi, F/(6 pi a U))
ZICK_HOMSY = ((0.027, 2.008), (0.064, 2.810), (0.125, 4.292), (0.216, 7.442), (0.343, 15.4), (0.45, 28.1))


def array_k(phi, lubrication):
    """6 pi U_z of a unit sphere under a unit force along z, one sphere per cubic cell."""
    side = (4 * math.pi / (3 * phi)) ** (1 / 3)
    u, omega, _ = solve_mobility(np.zeros((1, 3)), np.full(3, side), forces=np.array([[0.0, 0.0, 1.0]]),
                                 lubrication=lubrication, ewald_tol=1e-10)
    assert np.abs(u[0, :2]).max() < 1e-12 and np.abs(omega).max() < 1e-12
    return 6 * math.pi * u[0, 2]


@pytest.mark.parametrize("phi", [0.01, 0.125, 0.216, 0.343, 0.45, 0.5])
def test_array_far_field_is_the_faxen_corrected_point_lattice(phi):
    """One sphere per cell: by inversion symmetry of the lattice the U-S and Omega-F
    image sums vanish, so the FTS far field gives U = M_UF F, the self Ewald sum of the
    Rotne-Prager tensor (1 + a^2/6 lap)^2 J. With J's k = 0 term omitted (zero-volume-flux
    frame), its regular part at r = 0 is -HASIMOTO/(6 pi L) (Hasimoto 1959); (a^2/3) lap J
    adds (a^2/3)(2/3V) I, i.e. +phi in K (near 0 the periodic lap chi is
    1/(4 pi r) + r^2/(6V) + h, h harmonic with cubic symmetry, so its Hessian at 0
    vanishes); (a^4/36) lap^2 J = -(a^4/36)(I lap - grad grad)(delta_periodic - 1/V) adds
    nothing at r = 0.
    So K = 1 - HASIMOTO a/L + phi exactly, at any phi; a velocity relative to the mean fluid
    velocity instead would be K/(1 - phi) (2 phi at first order). Tolerance 3e-8: HASIMOTO's
    rounding (2e-8 a/L) and the Ewald tolerance 1e-10 (measured: < 6e-9)."""
    a_over_l = (3 * phi / (4 * math.pi)) ** (1 / 3)
    assert array_k(phi, lubrication=False) == pytest.approx(1 - HASIMOTO * a_over_l + phi, abs=3e-8)


@pytest.mark.parametrize("phi, drag", ZICK_HOMSY[:4])
def test_array_sd_differs_from_exact_by_the_multipoles_beyond_fts(phi, drag):
    """Full SD (lubrication included, which couples each sphere to its own images where
    L < 4) against the exact array: the excess K_SD - 1/drag is what the series of Sangani
    & Acrivos (1982), K = 1 - 1.7601 chi + chi^3 - 1.5593 chi^6 + 3.9799 chi^8
    - 3.0734 chi^10 (chi = phi^(1/3)), has beyond the FTS closed form 1 - 1.7601 chi + chi^3:
    1.5593 chi^6 - 3.9799 chi^8 + 3.0734 chi^10, from multipoles SD leaves out. Agreement
    within 15% of that excess plus 1.3e-4 (Zick & Homsy's four digits: 1.2e-4 in 1/drag at
    phi = 0.027), covering the series' O(chi^11) remainder and the self-image lubrication
    (-3e-4 at phi = 0.125, -4e-4 at 0.216). SD is thus within 0.2% of exact at phi = 0.027,
    1.2% at 0.064, 5% at 0.125 and 19% at 0.216."""
    chi = phi ** (1 / 3)
    missing = 1.5593 * chi ** 6 - 3.9799 * chi ** 8 + 3.0734 * chi ** 10
    excess = array_k(phi, lubrication=True) - 1 / drag
    assert excess == pytest.approx(missing, abs=0.15 * missing + 1.3e-4)


def test_array_sd_overestimates_dense_arrays_by_the_fts_truncation():
    """Beyond phi ~ 0.2 the truncation dominates: at phi = 0.343 and 0.45 the exact array
    settles at 0.065 and 0.036, SD at 0.111 and 0.101 (1.7 and 2.8 times exact), within
    0.5% of the FTS closed form (the self-image lubrication: -3e-4 and -4e-4)."""
    for phi, drag in ZICK_HOMSY[4:]:
        k = array_k(phi, lubrication=True)
        a_over_l = (3 * phi / (4 * math.pi)) ** (1 / 3)
        assert k == pytest.approx(1 - HASIMOTO * a_over_l + phi, rel=5e-3)
        assert 1.5 < k * drag < 3.0


def _carnahan_starling_s0(phi):
    """S(0) of hard spheres (Carnahan-Starling compressibility)."""
    return (1 - phi) ** 4 / (1 + 4 * phi + 4 * phi ** 2 - 4 * phi ** 3 + phi ** 4)


def _random_k_and_eta(n, phi, configs):
    """Mean K (full SD, the force along x, y, z in turn) and eta'_inf over equilibrium
    hard-sphere configurations (fixed seeds)."""
    ks, etas = [], []
    for k in range(configs):
        pos, side = hard_sphere_fluid(n, phi, np.random.default_rng([39, n, k]))
        box = np.full(3, side)
        for axis in range(3):
            forces = np.zeros((n, 3))
            forces[:, axis] = 1.0
            u, _, _ = solve_mobility(pos, box, forces=forces)
            ks.append(6 * math.pi * u[:, axis].mean())
        etas.append(1 + hydrodynamic_viscosity(pos, box))
    return float(np.mean(ks)), float(np.mean(etas))


def test_random_suspension_size_dependence_is_that_of_a_sphere_and_its_correlation_hole():
    """K of N spheres in a periodic box is below the infinite system's by the images of each
    sphere and of its correlation hole, net weight S(0): HASIMOTO (a/L) S(0)/eta'_inf
    (docs/validation.md, Sedimentation). At phi = 0.45 (S(0) = 0.028) this makes K_64 - K_27
    = 6e-4, where the images of a lone sphere (no S(0)) would give 0.02. Four
    configurations per size: the scatter of K between configurations (0.0025 at N = 27,
    0.0013 at N = 64) gives a standard error of 0.0014 on the difference; tolerance 0.006
    (4 standard errors), a third of the lone-sphere value."""
    phi = 0.45
    (k27, eta27), (k64, eta64) = _random_k_and_eta(27, phi, 4), _random_k_and_eta(64, phi, 4)

    def image_term(n, eta, s0):
        return HASIMOTO * (3 * phi / (4 * math.pi * n)) ** (1 / 3) * s0 / eta

    s0 = _carnahan_starling_s0(phi)
    hole = image_term(27, eta27, s0) - image_term(64, eta64, s0)
    lone = image_term(27, eta27, 1.0) - image_term(64, eta64, 1.0)
    assert lone > 0.018
    assert k64 - k27 == pytest.approx(hole, abs=0.006)
