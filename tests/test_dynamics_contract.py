"""Contract suite of the Brownian and time-stepping extension points, over the registries:
every registered drift scheme on every solver backend it suits
(`sdmpi.registry.drift_schemes_for`) and every hydrodynamic model that solves, and every
registered integrator.

* Fluctuation-dissipation and drift, exactly: a scheme's Brownian velocities U_B(z) for
  standard normal z are, to O(dt), an odd part linear in z and an even part quadratic in z
  (zero at z = 0), so the symmetric quadrature z = +-e_k over the noise's dimensions gives
  both moments exactly: sum_k a_k a_k^T with a_k the odd part at e_k is the covariance of
  U_B, which must be 2 kT M / dt (M = R_FU^-1, the evaluation's own mobility); the sum of
  the even parts is the mean, which must be kT div M, and that of the Brownian stresslets
  -kT div(R_SU R_FU^-1), both against centred finite differences of the model's resistance.
* Fluctuation-dissipation, statistically: the displacements dt U_B that a model draws
  from its random stream (near-contact correction included) have covariance 2 kT M dt,
  within the sampling error of a whitened covariance.
* Integrators: the order of convergence on a smooth deterministic problem through the
  Lees-Edwards boundary (ORDERS: a new integrator declares its order here).
* Rank-count independence of the backends that solve a task on several ranks is checked
  by their own tests under mpirun -n 2 (RANK_TESTS: a new such backend needs one).

Symmetry and positive definiteness of the mobility are the backends' and models' contracts
(tests/test_backend_contract.py, tests/test_model_contract.py).
"""

import importlib
import math
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

import sdmpi
from sdmpi.dynamics.integrators import Motion, Step
from sdmpi.dynamics.setup import hydrodynamic_model
from sdmpi.dynamics.shear import Oscillatory
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.resistance import grand_resistance, mobility_divergence
from sdmpi.registry import (DRIFT_SCHEMES, HYDRODYNAMIC_MODELS, INTEGRATORS, SOLVER_BACKENDS,
                            drift_schemes_for)

from .test_backend_contract import BOX, POSITIONS, STRAIN, _available

DEMO = Path(__file__).resolve().parents[1] / "jobs" / "demo.toml"
N = len(POSITIONS)
KT = 1.0
#: the time step of the quadrature: the midpoint scheme's mean is kT div M to O(dt) (its
#: half step), and its odd part carries O(dt) cubic terms
DT = 1e-7
#: finite-difference step of the divergences: truncation O(h^2) ~ 1e-10, rounding of
#: the inverses (cond R_FU ~ 1e3 here) over h ~ 1e-8 (relative)
H = 1e-5
#: iterative solves: residual and Lanczos accuracy (the direct backends are exact to
#: rounding); the Ewald sums' accuracy
TOL, EWALD = 1e-11, 1e-10

COMBINATIONS = [(model, backend, scheme) for model in HYDRODYNAMIC_MODELS.names(lambda m: m.solves)
                for backend in SOLVER_BACKENDS.names() for scheme in drift_schemes_for(backend)]


def _job(model, backend, scheme="rfd"):
    return sdmpi.load_job(DEMO, [f'hydrodynamics.model="{model}"', f'solver.backend="{backend}"',
                                 f'brownian.scheme="{scheme}"', f"hydrodynamics.ewald_tolerance={EWALD}",
                                 f"solver.tolerance={TOL}"])


def _evaluation(model, backend, scheme="rfd"):
    return hydrodynamic_model(_job(model, backend, scheme), np.ones(N), BOX).at(POSITIONS, STRAIN)


def _mobility(at):
    """M (6N x 6N) of an evaluation, column by column."""
    zero = np.zeros((N, 5))
    return np.array([at.velocities(f, zero).ravel() for f in np.eye(6 * N).reshape(6 * N, N, 6)]).T


@lru_cache(maxsize=None)
def _divergences(model):
    """kT div M (N, 6) and kT div(R_SU R_FU^-1) (N, 5) of the model's resistance
    (`sdmpi.hydro.resistance.mobility_divergence`: centred differences of step H over the
    3N translations, pair sets frozen)."""
    hydro = _job(model, "dense").hydrodynamics

    def resistance_at(positions, plan=None):
        return grand_resistance(positions, np.ones(N), BOX, STRAIN, HYDRODYNAMIC_MODELS[model].lubrication,
                                EWALD, hydro.lubrication_cutoff, hydro.min_gap, plan=plan)

    div_m, div_a = mobility_divergence(resistance_at, resistance_at(POSITIONS), H)
    return KT * div_m.reshape(N, 6), KT * div_a.reshape(N, 5)


def _no_near(m):
    return 0.0


@pytest.mark.parametrize("model,backend,scheme", COMBINATIONS)
def test_drift_scheme_keeps_fluctuation_dissipation_and_the_drift(model, backend, scheme):
    """Covariance of U_B = 2 kT M / dt to 1e-7 of M's largest entry (the midpoint's odd
    terms are O(dt) = 1e-7; the rest is rounding and, on petsc-krylov, Lanczos and solves at
    1e-11: measured at most 3.4e-9). Mean of U_B = kT div M and mean Brownian stresslets =
    -kT div A, rotations included, to 1e-6 of the largest entry (the midpoint's O(dt) bias,
    the differences' O(h^2) truncation: measured at most 7.9e-9); a missing drift, or one of
    the wrong sign or scale, is off by O(1)."""
    if not _available(SOLVER_BACKENDS[backend]):
        pytest.skip(f"{backend} needs petsc4py")
    at = _evaluation(model, backend, scheme)
    drift = DRIFT_SCHEMES[scheme].load()()
    stress_draw = DRIFT_SCHEMES[scheme].stress_draw  # its own draw: the same quadrature
    size = math.prod(at.solver.noise_shape)
    odd, mean, stress = [], np.zeros((N, 6)), np.zeros((N, 5))
    for k in range(size):
        unit = np.zeros(size)
        unit[k] = 1.0
        plus, minus = (drift.brownian(at, z, KT, DT, _no_near, z if stress_draw else None)
                       for z in (sign * unit.reshape(at.solver.noise_shape) for sign in (1.0, -1.0)))
        odd.append(0.5 * (plus.velocities - minus.velocities).ravel())
        mean += 0.5 * (plus.velocities + minus.velocities)
        stress += 0.5 * (plus.stresslets + minus.stresslets)
    odd = np.array(odd)
    mobility = _mobility(at)
    covariance = odd.T @ odd * DT / (2 * KT)
    assert np.abs(covariance - mobility).max() < 1e-7 * np.abs(mobility).max()
    div_m, div_a = _divergences(model)
    assert np.abs(mean - div_m).max() < 1e-6 * np.abs(div_m).max()
    assert np.abs(stress + div_a).max() < 1e-6 * np.abs(div_a).max()


def test_split_rfd_takes_the_drift_from_z_and_the_stress_from_its_own_draw():
    """rfd-split: the velocities are a function of the step's z alone, equal to rfd's bit
    for bit, and the stresslets a function of z_stress alone, equal to rfd's for z = z_stress:
    the stress estimator's noise is independent of the displacement by construction (its
    mean is tested with every scheme above)."""
    rng = np.random.default_rng(7)
    rfd, split = (_evaluation("stokesian", "dense", scheme) for scheme in ("rfd", "rfd-split"))
    z, z_stress, other = (rng.standard_normal((N, 6)) for _ in range(3))
    both = split.brownian_terms(z, KT, 5e-4, None, z_stress)
    assert np.array_equal(both.velocities, rfd.brownian_terms(z, KT, 5e-4).velocities)
    assert np.array_equal(both.stresslets, rfd.brownian_terms(z_stress, KT, 5e-4).stresslets)
    assert np.array_equal(both.velocities, split.brownian_terms(z, KT, 5e-4, None, other).velocities)
    assert np.array_equal(both.stresslets, split.brownian_terms(other, KT, 5e-4, None, z_stress).stresslets)
    assert not np.allclose(both.stresslets, split.brownian_terms(z, KT, 5e-4, None, other).stresslets)
    with pytest.raises(ValueError, match="z_stress"):
        split.brownian_terms(z, KT, 5e-4)


#: draws of the statistical test
SAMPLES = 1000


@pytest.mark.parametrize("model", HYDRODYNAMIC_MODELS.names())
def test_drawn_displacements_have_the_covariance_2_kt_m_dt(model):
    """The displacements dx = dt U_B a model draws (its default drift scheme on the dense
    backend, the near-contact correction included) whitened by 2 kT dt M = L L^T are, to
    O(dt) = 1e-7, standard normal in p = 6N = 36 dimensions: over S = 1000 draws their
    sample covariance C has trace p +- sqrt(2p/S) and off-diagonal entries 0 +- 1/sqrt(S).
    Tested at 5 standard deviations: a false alarm has probability ~1e-6 for the trace
    and ~4e-4 for the largest of the 630 off-diagonal entries; covariances off by 4% in
    scale or 0.16 in a correlation fail. The random stream is seeded: the outcome is
    fixed."""
    at = _evaluation(model, "dense")
    lower = np.linalg.cholesky(2 * KT * DT * _mobility(at))
    rng = np.random.default_rng(11)
    dx = np.array([DT * at.brownian(rng, KT, DT).velocities.ravel() for _ in range(SAMPLES)])
    white = np.linalg.solve(lower, dx.T)
    c = white @ white.T / SAMPLES
    p = len(c)
    assert abs(np.trace(c) - p) < 5 * math.sqrt(2 * p / SAMPLES)
    assert np.abs(c - np.diag(np.diag(c))).max() < 5 / math.sqrt(SAMPLES)


#: the global order of each registered integrator on smooth deterministic motion
ORDERS = {"euler-maruyama": 1, "adams-bashforth-4": 4}
#: the smooth problem: four points in a box under oscillatory shear, with disturbance
#: velocities that are periodic functions of the height (so periodic under Lees-Edwards
#: images) and of time, integrated to T
SMOOTH_BOX, SMOOTH_SHEAR, SMOOTH_T = np.array([5.0, 6.0, 7.0]), Oscillatory(0.8, 2.0), 2.0
SMOOTH_X0 = np.random.default_rng(5).uniform(0.0, 1.0, (4, 3)) * SMOOTH_BOX


def _smooth_velocity(x, t):
    q = 2 * np.pi * x[:, 1] / SMOOTH_BOX[1]
    u = np.zeros((len(x), 6))
    u[:, 0], u[:, 1], u[:, 2] = 0.4 * np.cos(q), 0.3 * np.sin(q) + 0.2 * np.cos(1.5 * t), 0.2 * np.sin(q + 0.5)
    return u


def _smooth_end(name, steps):
    dt = SMOOTH_T / steps
    integrator = INTEGRATORS[name].load()(Motion(len(SMOOTH_X0), SMOOTH_BOX, dt, SMOOTH_SHEAR, None, "separate",
                                                 _smooth_velocity))
    x = Lattice(SMOOTH_BOX, 0.0).wrap(SMOOTH_X0)
    for k in range(steps):
        x, _ = integrator.move(Step(k, x, _smooth_velocity(x, k * dt), np.zeros((len(x), 6)), None))
    return x


def test_every_integrator_declares_its_order():
    assert set(ORDERS) == set(INTEGRATORS.names())


@pytest.mark.parametrize("name", INTEGRATORS.names())
def test_integrator_converges_at_its_order(name):
    """The error at T = 2 of 80, 160, 320 steps against fourth-order Adams-Bashforth with
    2560 (its error ~1e-12, 2e-4 of the smallest here): each halving of dt divides it by
    2^p (measured: Euler-Maruyama 2.00, 2.00; Adams-Bashforth-4 16.9, 16.5, approaching 16
    as dt -> 0); the measured orders log2(ratio) are taken within 0.15 of p."""
    reference = _smooth_end("adams-bashforth-4", 2560)
    lattice = Lattice(SMOOTH_BOX, SMOOTH_SHEAR.strain(SMOOTH_T))
    errors = [np.abs(lattice.nearest_image(_smooth_end(name, n) - reference)).max() for n in (80, 160, 320)]
    orders = [math.log2(coarse / fine) for coarse, fine in zip(errors, errors[1:])]
    assert all(abs(order - ORDERS[name]) < 0.15 for order in orders), orders


#: backends that solve a task on several ranks -> their test of the same results on one
#: and two ranks (mpirun -n 2)
RANK_TESTS = {"petsc-dense": "tests.test_petsc_dense:test_agrees_with_dense_two_ranks",
              "petsc-krylov": "tests.test_krylov:test_agrees_with_dense_two_ranks"}


def test_every_several_rank_backend_has_a_rank_count_test():
    assert set(RANK_TESTS) == set(SOLVER_BACKENDS.names(lambda b: b.several_ranks))
    for where in RANK_TESTS.values():
        module, _, name = where.partition(":")
        try:
            assert callable(getattr(importlib.import_module(module), name))
        except ImportError:  # petsc4py missing: that module cannot be imported here
            pytest.skip("petsc4py is not installed")
