"""Brownian hard spheres without hydrodynamic interactions, dilute: the moduli of the
collision stress against the exact O(phi^2) result (sdmpi.analysis.analytic.
dilute_hard_sphere_moduli), through `sdmpi run` and the reducer, as a user runs it."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: allowance for the systematic offsets (docstring below), relative to the exact value
SYSTEMATIC = 0.2


def _bench():
    spec = importlib.util.spec_from_file_location("dilute_hard_spheres", ROOT / "bench" / "dilute_hard_spheres.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_free_draining_collision_moduli_are_the_dilute_hard_sphere_result(tmp_path):
    """jobs/dilute_free_draining.toml (N = 1000, phi = 0.05, dt = 2e-3) at omega = 3 t_D^-1,
    gamma0 = 0.2, 30 t_D (~15 000 steps). Free draining: the hydrodynamic row is the
    Einstein stresslet alone, eta' = 5/2 phi exactly, and the Brownian row is zero.

    The collision row, divided by phi^2, against the exact G'/phi^2 = 2.006, G''/phi^2 =
    5.408: the standard error of this run is ~0.7 for both (the equilibrium stress
    fluctuations, var G = 4 kT eta'/(gamma0^2 T V) by fluctuation-dissipation), and the
    longer runs of bench/dilute_hard_spheres.py (docs/physics.md) agree with exact within
    their own ~9% errors at omega = 1, 3, 8. Unresolved systematics: the O(phi^3) excess
    (a factor between g(2) and g(2)^2, +14% to +29% at phi = 0.05), the time step's deficit
    (the contact value of the same runs is 6% low) and the amplitude's O(gamma0^2).
    Tolerance: SYSTEMATIC = 20% of exact plus 3 standard errors. A missing or doubled impulse, the wrong sign, G' and G'' exchanged
    (a phase error of pi/2), or the collision stress counted per particle instead of per
    pair fails."""
    bench = _bench()
    process, run = bench.start(3.0, 0.2, 2e-3, 30.0, tmp_path)
    bench.finish(process)
    row = bench.compare(run)
    assert row["hydrodynamic_eta_prime"] == pytest.approx(2.5 * 0.05, rel=1e-12)
    assert row["brownian_G_dprime"] == 0.0
    for name in ("G_prime", "G_dprime"):
        measured, err = row[f"{name}_over_phi2"], row[f"{name}_err_over_phi2"]
        exact = row[f"exact_{name}_over_phi2"]
        assert 0.2 < err < 1.5  # the error estimate is itself sane
        assert abs(measured - exact) < SYSTEMATIC * exact + 3 * err, (name, measured, err, exact)
