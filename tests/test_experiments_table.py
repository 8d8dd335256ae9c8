"""docs/validation/finite_size/experiments.csv, the comparison with experiments and theory:
its converted columns recomputed from the published ones with the stated conversion, its
sdmpi columns equal to quantities.csv (what postprocess/finite_size.py writes), the values
of published formulas recomputed, and the omega^-1/2 conversion checked against the sum
over the relaxation modes of van der Werff et al.'s spectrum."""

import csv
import math
from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).parents[1] / "docs" / "validation" / "finite_size"
C_HALF = math.pi / (2.0 * math.sqrt(2.0))  # int_0^inf dx / (1 + x^4)

# published -> sdmpi units, and back (sdmpi units: eta_m, t_D = a^2/D0, omega in rad/t_D).
# kT/a^3 = 6 pi eta_m/t_D since D0 = kT/(6 pi eta_m a); van der Werff et al.'s reduced groups
# a^2 G1/(D0 eta_s) and D0 tau1/a^2 are G1 in eta_m/t_D and tau1 in t_D, and their
# spectrum gives eta'' = C_HALF G1 tau1^1/2 omega^-1/2 (test_omega_half_conversion).
CONVERSIONS = {
    "same": (lambda x: x, lambda y: y),
    "minus_one": (lambda x: x - 1.0, lambda y: y + 1.0),
    "kT_per_a3": (lambda x: 6.0 * math.pi * x, lambda y: y / (6.0 * math.pi)),
    "G1_sqrt_tau1": (lambda x: C_HALF * x, lambda y: y / C_HALF),
}

PHI = 0.45
# rows whose published value is a published formula evaluated at phi = 0.45
FORMULAS = {
    "eta'_H (Schaink et al. eq. 38)":
        2.5 * PHI + 5.2 * PHI**2 + 3.01 * PHI**3 + 47.71 * PHI**4,
    "eta'_inf - 1 (exact hydrodynamics)":
        (lambda s: 1.0 + 2.5 * PHI * (1.0 + s) / (1.0 - PHI * (1.0 + s)))(
            PHI * (1.0 + 0.95 * PHI - 2.15 * PHI**2)),
    "eta'_inf - 1 (Verberg et al. approximate theory)": (1.0 - PHI / 2.0) / (1.0 - PHI) ** 3,
}


def read(name):
    with open(HERE / name, newline="") as fh:
        return list(csv.DictReader(fh))


def assert_rounds_to(shown, exact, where):
    """`shown` (text) is `exact` rounded to the digits it shows."""
    half_ulp = 0.5 * 10.0 ** Decimal(shown).as_tuple().exponent
    assert abs(float(shown) - exact) <= half_ulp * (1 + 1e-9), f"{where}: {shown} vs {exact}"


@pytest.fixture(scope="module")
def rows():
    return read("experiments.csv")


def test_converted_values_follow_from_published_ones(rows):
    converted = 0
    for r in rows:
        if r["published_value"]:
            to_sdmpi, _ = CONVERSIONS[r["conversion"]]
            assert_rounds_to(r["converted_value"], to_sdmpi(float(r["published_value"])),
                             r["quantity"])
            converted += 1
        else:
            assert r["converted_value"] == "", r["quantity"]
            assert r["note"].startswith("not read"), r["quantity"]
    assert converted >= 3


def test_sdmpi_columns_are_the_study_tables(rows):
    study = {q["quantity"]: q for q in read("quantities.csv")}
    for r in rows:
        q = study[r["sdmpi_quantity"]]
        for n in ("N125", "N27"):
            assert_rounds_to(r[f"sdmpi_{n}"], float(q[n]), f"{r['quantity']} {n}")
            assert_rounds_to(r[f"sdmpi_{n}_err"], float(q[f"{n}_err"]), f"{r['quantity']} {n} err")
            if r["conversion"]:
                _, to_published = CONVERSIONS[r["conversion"]]
                assert_rounds_to(r[f"sdmpi_{n}_published_units"], to_published(float(q[n])),
                                 f"{r['quantity']} {n} in published units")


def test_published_formulas_recomputed(rows):
    by_name = {r["quantity"]: r for r in rows}
    for name, value in FORMULAS.items():
        assert_rounds_to(by_name[name]["published_value"], value, name)


@pytest.mark.parametrize("omega_tau1", [1e3, 1e4])
def test_omega_half_conversion(omega_tau1):
    """G(t) = G1 sum_p exp(-t p^2/tau1): G'/G1 = sum_p x^2/(x^2 + p^4) and
    (eta' - eta'_inf)/(G1 tau1) = sum_p p^2/(p^4 + x^2), x = omega tau1. For x >> 1 the sums
    are integrals over p/x^1/2 less half their p = 0 term (Euler-Maclaurin):
    eta'' = G'/omega = G1 [C_HALF (tau1/omega)^1/2 - 1/(2 omega)] and
    eta' - eta'_inf = C_HALF G1 (tau1/omega)^1/2, C_HALF = pi/(2 sqrt 2)."""
    x = omega_tau1
    p = np.arange(1, 400_001, dtype=float)
    g_prime = np.sum(x**2 / (x**2 + p**4))  # tail beyond p = P: x^2/(3 P^3), negligible
    eta_prime = np.sum(p**2 / (p**4 + x**2)) + 1.0 / (p[-1] + 0.5)  # tail ~ sum 1/p^2
    assert g_prime == pytest.approx(C_HALF * math.sqrt(x) - 0.5, abs=1e-6 * math.sqrt(x))
    assert eta_prime == pytest.approx(C_HALF / math.sqrt(x), rel=1e-4)
