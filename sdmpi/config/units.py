"""Physical units: the optional ``[physical]`` section -> sdmpi's reduced units, and back.

Reduced units (see :mod:`.schema`): length a = the largest sphere radius, viscosity
eta_m = the medium's zero-shear viscosity, time t_D = a^2/D0 = 6 pi eta_m a^3 / kT (or
1/gamma_dot in non-Brownian steady shear), hence

    energy E = 6 pi eta_m a^3 / (time unit)  (= kT, or 6 pi eta_m a^3 gamma_dot),
    force  E/a,    stress eta_m / (time unit)  (= kT/(6 pi a^3), or eta_m gamma_dot).

``[physical]`` gives the scales (``radius`` in nm, ``viscosity`` in Pa s, ``temperature``
in K) and, instead of the reduced keys, physical values that the loader converts once:
shear rate (1/s), frequencies (rad/s), Hamaker constant (J, or eq. 6 of Finke et al. 2020 from
dielectric constants and refractive indices), cap gap and Debye length (nm), surface
potential (mV). :data:`CONVERTED` says which reduced key each one sets.

The Peclet number is Pe = 6 pi eta_m a^3 gamma_dot / kT = gamma_dot t_D, the shear rate
of a Brownian job in its reduced units (Finke et al. 2020, eq. 14 defines Pe with 3 pi, half this).

Constants: SI 2019 exact values of k_B and h, CODATA 2018 vacuum permittivity.
This module uses the standard library only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

BOLTZMANN = 1.380649e-23          # J/K (exact)
PLANCK = 6.62607015e-34           # J s (exact)
VACUUM_PERMITTIVITY = 8.8541878128e-12  # F/m (CODATA 2018)
NANOMETRE = 1e-9
MILLIVOLT = 1e-3

#: the eq.-6 inputs of the Hamaker constant ([physical] keys), all needed together
OPTICAL_KEYS = ("particle_permittivity", "medium_permittivity", "particle_refractive_index",
                "medium_refractive_index", "absorption_frequency")

#: [physical] key -> the reduced key it sets (the Hamaker constant from OPTICAL_KEYS too)
CONVERTED = {
    "shear_rate": "shear.rate",
    "omega": "shear.omega",
    "hamaker": "interparticle.hamaker",
    "cap_gap": "interparticle.cap_gap",
    "debye_length": "interparticle.debye_length",
    "surface_potential": "interparticle.surface_potential",
}


def hamaker_lifshitz(particle_permittivity, medium_permittivity, particle_refractive_index,
                     medium_refractive_index, absorption_frequency, temperature):
    """Hamaker constant A (J) of two identical bodies 1 across a medium 3 (Finke et al. 2020
    eq. 6; Israelachvili, Intermolecular and Surface Forces, 3rd ed. (2011), eq. 13.16,
    the Tabor-Winterton approximation of Lifshitz theory):

        A = (3/4) kT ((e1 - e3)/(e1 + e3))^2
            + 3 h nu_e/(16 sqrt 2) (n1^2 - n3^2)^2 / (n1^2 + n3^2)^(3/2),

    e static dielectric constants, n refractive indices (visible), nu_e the main
    electronic (UV) absorption frequency in 1/s (Hz, not rad/s), T in K. The first term
    is the zero-frequency (Keesom + Debye) part, the second the dispersion part."""
    args = dict(particle_permittivity=particle_permittivity,
                medium_permittivity=medium_permittivity,
                particle_refractive_index=particle_refractive_index,
                medium_refractive_index=medium_refractive_index)
    for name, value in args.items():
        if not value >= 1.0:
            raise ValueError(f"{name} must be >= 1 (relative to vacuum), got {value}")
    for name, value in (("absorption_frequency", absorption_frequency),
                        ("temperature", temperature)):
        if not 0.0 < value < math.inf:
            raise ValueError(f"{name} must be > 0 and finite, got {value}")
    e1, e3 = particle_permittivity, medium_permittivity
    n1, n3 = particle_refractive_index ** 2, medium_refractive_index ** 2
    zero = 0.75 * BOLTZMANN * temperature * ((e1 - e3) / (e1 + e3)) ** 2
    dispersion = (3.0 * PLANCK * absorption_frequency / (16.0 * math.sqrt(2.0))
                  * (n1 - n3) ** 2 / (n1 + n3) ** 1.5)
    return zero + dispersion


@dataclass(frozen=True)
class Scales:
    """SI values of the reduced units of one job (module docstring).

    length (m) = a; viscosity (Pa s) = eta_m; time (s) = t_D or 1/gamma_dot, as
    time_unit says (Job.time_unit); thermal_energy (J) = kT, None when no temperature is
    given (non-Brownian steady shear only)."""

    length: float
    viscosity: float
    time: float
    time_unit: str
    thermal_energy: float | None

    @property
    def energy(self) -> float:
        """J: 6 pi eta_m a^3 / time unit (kT in a Brownian job)."""
        return 6.0 * math.pi * self.viscosity * self.length ** 3 / self.time

    @property
    def force(self) -> float:
        """N: energy / a."""
        return self.energy / self.length

    @property
    def stress(self) -> float:
        """Pa: eta_m / time unit."""
        return self.viscosity / self.time

    def peclet(self, rate_reduced) -> float:
        """Pe = 6 pi eta_m a^3 gamma_dot / kT of a reduced shear rate (NaN without kT)."""
        if self.thermal_energy is None:
            return math.nan
        gamma_dot = rate_reduced / self.time
        return 6.0 * math.pi * self.viscosity * self.length ** 3 * gamma_dot / self.thermal_energy

    def as_dict(self) -> dict:
        """The conversion factors (SI) for the run file's metadata."""
        return {"length_m": self.length, "viscosity_Pa_s": self.viscosity,
                "time_s": self.time, "time_unit": self.time_unit, "energy_J": self.energy, "force_N": self.force,
                "stress_Pa": self.stress,
                "thermal_energy_J": math.nan if self.thermal_energy is None
                else self.thermal_energy}


def make_scales(physical, brownian: bool, protocol: str) -> Scales:
    """The scales of a ``[physical]`` section (schema.Physical; radius and viscosity
    given) for a job with these brownian.enabled and shear.protocol: time t_D =
    6 pi eta a^3/kT, or 1/gamma_dot for non-Brownian steady shear (then
    ``physical.shear_rate`` is needed; otherwise ``physical.temperature``)."""
    a = physical.radius * NANOMETRE
    eta = physical.viscosity
    kt = None if physical.temperature is None else BOLTZMANN * physical.temperature
    if protocol == "steady" and not brownian:
        return Scales(a, eta, 1.0 / physical.shear_rate, "1/gamma_dot", kt)
    return Scales(a, eta, 6.0 * math.pi * eta * a ** 3 / kt, "t_D", kt)


def scales(job) -> Scales | None:
    """The scales of a resolved job, or None when it has no ``[physical]`` radius."""
    physical = job.physical
    if physical.radius is None:
        return None
    return make_scales(physical, job.brownian.enabled, job.shear.protocol)


def reduced_values(physical, s: Scales) -> dict:
    """{[physical] key: (reduced key, value in reduced units)} of the converted keys
    given in ``physical`` (the Hamaker constant from eq. 6 under the key
    "particle_permittivity" when the optical data are given). Needs the scales ``s``;
    the surface potential needs ``medium_permittivity``, eq. 6 the temperature."""
    out = {}
    if physical.shear_rate is not None:  # 1 by definition when it is the time unit
        rate = 1.0 if s.time_unit == "1/gamma_dot" else physical.shear_rate * s.time
        out["shear_rate"] = (CONVERTED["shear_rate"], rate)
    if physical.omega is not None:
        out["omega"] = (CONVERTED["omega"], tuple(w * s.time for w in physical.omega))
    if physical.hamaker is not None:
        out["hamaker"] = (CONVERTED["hamaker"], physical.hamaker / s.energy)
    if physical.particle_permittivity is not None:
        a = hamaker_lifshitz(*(getattr(physical, k) for k in OPTICAL_KEYS),
                             physical.temperature)
        out["particle_permittivity"] = (CONVERTED["hamaker"], a / s.energy)
    for key in ("cap_gap", "debye_length"):
        if getattr(physical, key) is not None:
            out[key] = (CONVERTED[key], getattr(physical, key) * NANOMETRE / s.length)
    if physical.surface_potential is not None:
        # psi^2 = 4 pi eps_r eps_0 a psi0^2 / E (sdmpi.dynamics.forces.DoubleLayer)
        psi0 = physical.surface_potential * MILLIVOLT
        psi2 = (4.0 * math.pi * physical.medium_permittivity * VACUUM_PERMITTIVITY
                * s.length * psi0 ** 2 / s.energy)
        out["surface_potential"] = (CONVERTED["surface_potential"], math.sqrt(psi2))
    return out
