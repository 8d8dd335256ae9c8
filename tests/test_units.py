"""Physical-unit input ([physical], sdmpi.config.units): conversion to the reduced units
against hand-written formulas, the canonical text, clear errors (missing scales,
conflicts naming both keys, derived values out of range), the SI columns of the steady
reduction, and the boehmite-epoxy job end to end under mpirun -n 2 (conversion factors
in the run file's metadata, physical columns in viscosity.csv)."""

import csv
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from sdmpi.analysis.reduce import PHYSICAL_COLUMNS, VISCOSITY_COLUMNS, reduce_runs
from sdmpi.config import JobError, canonical_text, load_job, parse_job
from sdmpi.config.units import BOLTZMANN, scales
from .synthetic_run import write_run

ROOT = Path(__file__).parents[1]
MPIRUN = shutil.which("mpirun")

A_NM, ETA, T, RATE, HAMAKER = 37.5, 0.1, 300.0, 50.0, 7.5e-21
KT = 1.380649e-23 * T                         # J (k_B exact since 2019)
A = A_NM * 1e-9                               # m
T_D = 6 * math.pi * ETA * A ** 3 / KT         # s, a^2/D0 with D0 = kT/(6 pi eta a)

BROWNIAN = f"""
[physical]
radius = {A_NM}
viscosity = {ETA}
temperature = {T}
shear_rate = {RATE}
hamaker = {HAMAKER}
cap_gap = 0.4
debye_length = 5.0
surface_potential = -25.0
medium_permittivity = 78.5
[shear]
protocol = "steady"
[interparticle]
kind = "dlvo"
[integration]
dt = 1e-4
n_steps = 100
discard_steps = 10
"""


def test_brownian_conversion_by_hand():
    job = parse_job(BROWNIAN)
    inter = job.interparticle
    assert job.time_unit == "t_D"
    # shear rate in 1/t_D: the Peclet number 6 pi eta a^3 gamma_dot / kT (here ~1.6e-3)
    assert job.shear.rate == pytest.approx(RATE * T_D, rel=1e-14)
    assert job.shear.rate == pytest.approx(6 * math.pi * ETA * A ** 3 * RATE / KT, rel=1e-14)
    assert inter.hamaker == pytest.approx(HAMAKER / KT, rel=1e-14)        # energy unit kT
    assert inter.cap_gap == pytest.approx(0.4 / A_NM, rel=1e-14)          # length unit a
    assert inter.debye_length == pytest.approx(5.0 / A_NM, rel=1e-14)
    # psi^2 = (e psi0 / kT)^2 a / l_B with the Bjerrum length l_B = e^2/(4 pi eps eps0 kT)
    # (sdmpi.dynamics.forces), independent of the sign of psi0
    e, eps0 = 1.602176634e-19, 8.8541878128e-12
    bjerrum = e ** 2 / (4 * math.pi * 78.5 * eps0 * KT)
    psi2 = (e * 25e-3 / KT) ** 2 * A / bjerrum
    assert inter.surface_potential == pytest.approx(math.sqrt(psi2), rel=1e-12)
    s = scales(job)
    assert (s.length, s.viscosity, s.time, s.thermal_energy) == pytest.approx((A, ETA, T_D, KT),
                                                                              rel=1e-14)
    assert s.energy == pytest.approx(KT, rel=1e-14)          # Brownian: E = kT
    assert s.stress == pytest.approx(KT / (6 * math.pi * A ** 3), rel=1e-14)
    assert s.peclet(job.shear.rate) == pytest.approx(job.shear.rate, rel=1e-14)
    # the canonical text lists the [physical] keys and the values they set, and reads back
    text = canonical_text(job)
    assert "[physical]" in text and f"hamaker = {HAMAKER!r}" in text
    assert parse_job(text) == job


def test_non_brownian_steady_shear_units():
    """Time unit 1/gamma_dot: shear.rate is exactly 1, energies in 6 pi eta a^3 gamma_dot."""
    for rate in (49.0, 100.0, 3.0):        # 49 * (1/49) != 1 in floating point
        job = parse_job(f"""
[physical]
radius = {A_NM}
viscosity = {ETA}
shear_rate = {rate}
hamaker = {HAMAKER}
cap_gap = 0.4
[shear]
protocol = "steady"
[brownian]
enabled = false
[interparticle]
kind = "vdw"
""")
        assert job.time_unit == "1/gamma_dot" and job.shear.rate == 1.0
        energy = 6 * math.pi * ETA * A ** 3 * rate
        assert job.interparticle.hamaker == pytest.approx(HAMAKER / energy, rel=1e-14)
        s = scales(job)
        assert s.time == pytest.approx(1 / rate, rel=1e-14) and math.isnan(s.peclet(1.0))
        assert s.stress == pytest.approx(ETA * rate, rel=1e-14)


def test_oscillatory_frequencies_and_no_physical_section():
    job = parse_job(f"[physical]\nradius = {A_NM}\nviscosity = {ETA}\ntemperature = {T}\n"
                    "omega = [1.0, 10.0]\n")
    assert job.shear.omega == pytest.approx((T_D, 10 * T_D), rel=1e-14)
    assert scales(parse_job("")) is None


@pytest.mark.parametrize("text, expected", [
    # scales missing
    ("[physical]\nradius = 10.0\n", ["physical.viscosity: is required",
                                     "physical.temperature: is required", "t_D"]),
    ("[physical]\nviscosity = 1.0\ntemperature = 300.0\n", ["physical.radius: is required"]),
    ("[physical]\nradius = 10.0\nviscosity = 1.0\n[shear]\nprotocol = \"steady\"\n"
     "[brownian]\nenabled = false\n", ["physical.shear_rate: is required", "1/gamma_dot"]),
    # a physical key and its reduced key disagree: both named
    ("[physical]\nradius = 10.0\nviscosity = 1.0\ntemperature = 300.0\nshear_rate = 5.0\n"
     "[shear]\nprotocol = \"steady\"\nrate = 2.0\n",
     ["shear.rate = 2.0: conflicts with physical.shear_rate = 5.0", "one of shear.rate "
      "(reduced units) or physical.shear_rate (physical units)"]),
    # a converted value checked like a reduced one, its [physical] key named as origin
    ("[physical]\nradius = 10.0\nviscosity = 1.0\ntemperature = 300.0\ncap_gap = 30.0\n"
     "[interparticle]\nkind = \"vdw\"\nhamaker = 1.0\n",
     ["interparticle.cap_gap = 3.0", "out of range", "[from physical.cap_gap]"]),
    ("[physical]\nradius = 10.0\nviscosity = 1.0\ntemperature = 300.0\nhamaker = 1e-20\n",
     ["interparticle.hamaker", "does not apply", "[from physical.hamaker]"]),
    ("[physical]\nradius = 10.0\nviscosity = 1.0\ntemperature = 300.0\n"
     "surface_potential = 20.0\n[interparticle]\nkind = \"dlvo\"\nhamaker = 1.0\n"
     "cap_gap = 0.01\ndebye_length = 0.05\n",
     ["physical.medium_permittivity: is required with physical.surface_potential"]),
    ("[physical]\nradius = -1.0\nviscosity = 1.0\n",
     ["physical.radius = -1.0: out of range", "radius > 0 [nm]"]),
    # in range, but beyond floating point once converted: the values named, no traceback
    ("[physical]\nradius = 1e-100\nviscosity = 1.0\ntemperature = 300.0\nhamaker = 1e-20\n"
     "[interparticle]\nkind = \"vdw\"\ncap_gap = 0.01\n",
     ["physical: these values cannot be converted to reduced units in floating point (a scale "
      "underflows to zero): radius = 1e-100, viscosity = 1.0, temperature = 300.0, hamaker = 1e-20",
      "e.g. radius = 37.5 nm"]),
    ("[physical]\nradius = 10.0\nviscosity = 1.0\ntemperature = 300.0\nsurface_potential = 1e200\n"
     "medium_permittivity = 80.0\n[interparticle]\nkind = \"dlvo\"\nhamaker = 1.0\ncap_gap = 0.01\n"
     "debye_length = 0.05\n",
     ["physical: these values cannot be converted", "(a value overflows)", "surface_potential = 1e+200"]),
])
def test_errors_name_the_keys(text, expected):
    with pytest.raises(JobError) as err:
        parse_job(text)
    message = str(err.value)
    for part in expected:
        assert part in message, message


def test_failed_physical_key_is_reported_once():
    """A bad [physical] key is one problem: the reduced key it should set is not also
    reported as missing, and the cross-key checks that need it are skipped."""
    with pytest.raises(JobError) as err:
        parse_job("[physical]\nradius = 10.0\nviscosity = 1.0\ntemperature = 300.0\n"
                  "hamaker = -1e-20\ncap_gap = 0.4\n[interparticle]\nkind = \"vdw\"\n")
    assert len(err.value.problems) == 1 and err.value.problems[0].path == "physical.hamaker"


def test_override_converts_too():
    job = load_job(ROOT / "jobs" / "boehmite_epoxy.toml", ["physical.shear_rate=1000.0"])
    pe = 6 * math.pi * 0.13 * (55e-9) ** 3 * 1000.0 / (BOLTZMANN * 353.15)
    assert job.shear.rate == pytest.approx(pe, rel=1e-14)
    assert 80 < pe < 90


def test_reduction_si_columns(tmp_path):
    """Synthetic steady run of known eta: the SI columns are eta x eta_m, the rate in 1/s,
    Pe, and the shear stress eta eta_m gamma_dot."""
    text = BROWNIAN.replace("[integration]\ndt = 1e-4\nn_steps = 100\ndiscard_steps = 10",
                            "[integration]\ndt = 1e-4\nn_steps = 200\ndiscard_steps = 10\n"
                            "[ensemble]\nrealisations = 3")
    path = tmp_path / "run.h5"
    write_run(path, text, {"hydrodynamic": 2.5, "interparticle": 0.5})
    red = reduce_runs([path])
    assert red.columns == VISCOSITY_COLUMNS + PHYSICAL_COLUMNS["steady"]
    total = next(r for r in red.rows() if r["component"] == "total")
    assert total["eta"] == pytest.approx(4.0, rel=1e-12)       # 1 + 2.5 + 0.5, no noise
    assert total["eta_Pa_s"] == pytest.approx(4.0 * ETA, rel=1e-12)
    assert total["rate_per_s"] == pytest.approx(RATE, rel=1e-12)
    assert total["Pe"] == pytest.approx(6 * math.pi * ETA * A ** 3 * RATE / KT, rel=1e-12)
    assert total["shear_stress_Pa"] == pytest.approx(4.0 * ETA * RATE, rel=1e-12)


def test_reduction_si_columns_oscillatory(tmp_path):
    """Moduli in Pa = reduced x eta_m/t_D, omega in rad/s = omega / t_D, eta' x eta_m."""
    text = (f"[physical]\nradius = {A_NM}\nviscosity = {ETA}\ntemperature = {T}\n"
            "omega = [2.0e3]\n[integration]\nsteps_per_period = 64\nperiods = 3\n"
            "discard_periods = 1\n[ensemble]\nrealisations = 2\n")
    path = tmp_path / "osc.h5"
    write_run(path, text, {"hydrodynamic": (0.4, 3.0)})
    red = reduce_runs([path])
    assert red.columns[-len(PHYSICAL_COLUMNS["oscillatory"]):] == PHYSICAL_COLUMNS["oscillatory"]
    row = next(r for r in red.rows() if r["component"] == "hydrodynamic")
    stress = KT / (6 * math.pi * A ** 3)                   # eta_m / t_D in Pa
    assert row["omega_rad_per_s"] == pytest.approx(2.0e3, rel=1e-12)
    assert row["G_prime_Pa"] == pytest.approx(0.4 * stress, rel=1e-9)
    assert row["G_dprime_Pa"] == pytest.approx(3.0 * stress, rel=1e-9)
    assert row["eta_prime_Pa_s"] == pytest.approx(3.0 / (2.0e3 * T_D) * ETA, rel=1e-9)


@pytest.mark.skipif(MPIRUN is None, reason="needs mpirun")
def test_boehmite_job_end_to_end(tmp_path):
    """The seed-003 job (shortened) under mpirun -n 2: conversion factors in the run
    file's metadata; viscosity_vs_rate.py writes the SI columns."""
    out = tmp_path / "be.h5"
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = [MPIRUN, "--oversubscribe", "-n", "2", sys.executable, "-m", "sdmpi.cli", "run",
           str(ROOT / "jobs" / "boehmite_epoxy.toml"), "-o", str(out),
           "--set", "integration.n_steps=12", "--set", "integration.discard_steps=2",
           "--set", "physical.shear_rate=1000.0"]
    result = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr[-3000:]
    with h5py.File(out, "r") as f:
        factors = json.loads(f.attrs["physical_units"])
    a, eta, kt = 55e-9, 0.13, BOLTZMANN * 353.15
    assert factors["length_m"] == pytest.approx(a, rel=1e-14)
    assert factors["time_s"] == pytest.approx(6 * math.pi * eta * a ** 3 / kt, rel=1e-14)
    assert factors["stress_Pa"] == pytest.approx(kt / (6 * math.pi * a ** 3), rel=1e-14)
    result = subprocess.run([sys.executable, str(ROOT / "postprocess" / "viscosity_vs_rate.py"),
                             str(out), "-o", str(tmp_path / "red")],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-3000:]
    with open(tmp_path / "red" / "viscosity_vs_rate.csv") as fh:
        rows = {r["component"]: r for r in csv.DictReader(fh)}
    total = rows["total"]
    assert float(total["rate_per_s"]) == pytest.approx(1000.0, rel=1e-12)
    assert float(total["eta_Pa_s"]) == pytest.approx(float(total["eta"]) * eta, rel=1e-12)
    assert (tmp_path / "red" / "viscosity_vs_rate.png").is_file()
