"""The job-file schema: one frozen dataclass per TOML section, one field per key.

Each field carries its TOML spelling, kind, allowed values, unit and a one-line doc in
``dataclasses.field(metadata=...)``; the loader, the canonical writer and the key
reference (:mod:`.reference`) all read the schema from there, so a key is declared exactly
once.

Units are the reduced units of Schaink et al. (2000): sphere radius a = 1 (with size classes: the largest
radius; kT, D0 and t_D are then those of the largest spheres), medium zero-shear viscosity
eta_m = 1, time in t_D = a^2/D0 with D0 = kT/(6 pi eta_m a). The one exception is
non-Brownian steady shear, whose time unit is 1/gamma_dot (so ``shear.rate`` is 1 there).
Non-Brownian oscillatory jobs keep t_D as the time unit, so omega and the Maxwell
relaxation times mean the same with and without Brownian motion.

Jobs are made by :func:`sdmpi.config.load_job` / :func:`sdmpi.config.parse_job`, which
validate everything; building the dataclasses by hand skips all checks. Keys that do not
apply (for example ``shear.omega`` under steady shear) hold ``None``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from ..registry import (DRIFT_SCHEMES, FORCES, HYDRODYNAMIC_MODELS, INTEGRATORS, SOLVER_BACKENDS, Registry,
                        default_drift_scheme, several_rank_choices)

TWO_PI = 2.0 * math.pi
#: volume fractions of the initial configurations: below the lattice limit a lattice
#: start, above it a compressed one (sdmpi.dynamics.initial), up to this
START_PHI_LIMIT = 0.6
#: Monte Carlo sweeps of a generated start: enough to melt the simple cubic lattice start
#: (its Bragg peak decays to the fluid's structure factor) up to phi = 0.5 with margin
START_SWEEPS = 5000
#: hydrodynamics.ewald_tolerance when absent: Brownian jobs of equal spheres in a box of side
#: >= LOOSE_EWALD_MIN_SIDE, whose operators change by less than 1e-3 of themselves
#: between 1e-6 and 1e-3 (R_FU^-1, drift, Brownian stresslets, eta_H on 20 equilibrium
#: configurations, largest single value 8e-4; docs/performance.md), far below any stress
#: average's sampling error; ...
BROWNIAN_EWALD_TOLERANCE = 1e-3
#: ... other Brownian jobs (size classes, smaller boxes), where sums to 1e-3 can
#: leave the far-field mobility indefinite (one or two spheres in a box of side 2.1-2.7,
#: spheres of radius 0.2 among spheres of radius 1; bench/ewald_definiteness.py); ...
BROWNIAN_EWALD_TOLERANCE_TIGHT = 1e-4
#: ... and deterministic jobs, compared with exact and published numbers
EWALD_TOLERANCE = 1e-6
#: the most realisations per (phi, omega): the task list is built before any work (one
#: entry per task), and a study of 100 000 independent runs is far beyond any allocation
MAX_REALISATIONS = 100_000
#: the smallest box side (radii) at which Brownian jobs default to BROWNIAN_EWALD_TOLERANCE
#: (M_inf at 1e-3 indefinite up to side 2.65, positive from 3.03 with ~4e-3 to spare:
#: bench/ewald_definiteness.json)
LOOSE_EWALD_MIN_SIDE = 4.0


def lattice_sites_per_axis(n: int) -> int:
    """m, the sites per axis of the smallest simple cubic lattice with at least n sites
    (m^3 >= n > (m - 1)^3): the lattice of the initial configuration."""
    m = round(n ** (1 / 3))
    while m ** 3 < n:
        m += 1
    while m > 1 and (m - 1) ** 3 >= n:
        m -= 1
    return m


# --------------------------------------------------------------------------- allowed values


@dataclass(frozen=True)
class Range:
    """A numeric interval; ``None`` ends are unbounded. Infinity only if ``allow_inf``."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    allow_inf: bool = False

    def contains(self, x) -> bool:
        if math.isinf(x):
            return self.allow_inf and x > 0 and self.hi is None
        if self.lo is not None and (x < self.lo or (self.lo_open and x == self.lo)):
            return False
        if self.hi is not None and (x > self.hi or (self.hi_open and x == self.hi)):
            return False
        return True

    def describe(self, name: str) -> str:
        lo = "" if self.lo is None else f"{_num(self.lo)} {'<' if self.lo_open else '<='} "
        hi = "" if self.hi is None else f" {'<' if self.hi_open else '<='} {_num(self.hi)}"
        if self.lo is not None and self.hi is None:
            text = f"{name} {'>' if self.lo_open else '>='} {_num(self.lo)}"
        else:
            text = f"{lo}{name}{hi}"
        return text + (" (inf allowed)" if self.allow_inf else "")


def _num(x) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"


def quoted(names) -> str:
    """'"a", "b" or "c"' of the names (messages, docs)."""
    names = [f'"{n}"' for n in names]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


@dataclass(frozen=True)
class Choice:
    """One of a fixed set of strings, or of the choices of a registry (`sdmpi.registry`,
    read at every check, so that implementations registered after this module is imported
    count)."""

    options: tuple[str, ...] | Registry

    @property
    def values(self) -> tuple[str, ...]:
        options = self.options
        return options.choices() if isinstance(options, Registry) else options

    def contains(self, x) -> bool:
        return x in self.values

    def describe(self, name: str) -> str:
        return "one of " + ", ".join(f'"{v}"' for v in self.values)


@dataclass(frozen=True)
class Text:
    """A non-empty, printable, single-line string of bounded length."""

    max_len: int = 200

    def contains(self, x) -> bool:
        return 0 < len(x) <= self.max_len and x.isprintable()

    def describe(self, name: str) -> str:
        return f"a non-empty printable one-line string of at most {self.max_len} characters"


# Field kinds: "int", "float", "bool", "str", "floats" (non-empty array of distinct floats;
# a bare number is taken as a one-element array) and "tables" (non-empty array of inline
# tables, each validated against the dataclass in metadata["table"]).
KINDS = ("int", "float", "bool", "str", "floats", "tables")


_CONTROLLER_DEFAULTS: dict[str, str] = {}  # "section.key" -> default of keys named in only_if


def key(default, kind, doc, *, unit="", allowed=None, only_if=None, toml=None, table=None,
        example=None, controls=None, optional=False, instead_of=(), given_with=None):
    """Declare one job-file key.

    default  the value when the key is absent (None together with ``only_if`` means the key
             is required whenever it applies);
    allowed  a Range (for numbers; per element for "floats"), a Choice or a Text;
    only_if  (section, key, values): the key applies only when that other key has one of
             these values; otherwise giving it is an error and it resolves to None;
    toml     the TOML spelling when it differs from the attribute name;
    table    the dataclass of each element of a "tables" key;
    example  a value shown in messages about a required key;
    controls "section.key" of this key when other keys' only_if refer to it;
    optional a key whose default None means "absent" rather than "required" (it is then
             left out of the canonical text);
    instead_of  names of keys of the same table that do not apply when this key is given
             (alternatives: giving both is an error; an override of either wins);
    given_with  name of a key of the same table: this key applies only when that one is
             given (it is then required unless ``optional``).

    The dataclass default is None for a key that does not apply under the defaults of
    its controlling key, so that ``Job()`` equals the job of an empty file.
    """
    assert kind in KINDS
    if controls:
        _CONTROLLER_DEFAULTS[controls] = default
    applies = only_if is None or _CONTROLLER_DEFAULTS[f"{only_if[0]}.{only_if[1]}"] in only_if[2]
    meta = dict(kind=kind, doc=doc, unit=unit, allowed=allowed, only_if=only_if,
                toml=toml, table=table, default=default, example=example, optional=optional,
                instead_of=tuple(instead_of), given_with=given_with)
    applies = applies and given_with is None
    return field(default=default if applies else None, metadata=meta)


def toml_name(f: dataclasses.Field) -> str:
    return f.metadata.get("toml") or f.name


# --------------------------------------------------------------------------- sections

OSCILLATORY = ("shear", "protocol", ("oscillatory",))
STEADY = ("shear", "protocol", ("steady",))
STEADY_OR_NONE = ("shear", "protocol", ("steady", "none"))
MAXWELL = ("medium", "kind", ("maxwell",))


class ForcesReading(Sequence):
    """The interparticle.kind values whose force reads the [interparticle] key ``name``
    (`sdmpi.registry.ForceSpec.keys`), read at every use, so that forces registered after
    this module is imported count."""

    def __init__(self, name: str):
        self.name = name

    def _kinds(self) -> tuple[str, ...]:
        return FORCES.names(lambda force: self.name in force.keys)

    def __getitem__(self, index):
        return self._kinds()[index]

    def __len__(self) -> int:
        return len(self._kinds())


def _force_key(name: str) -> tuple[str, str, ForcesReading]:
    """only_if of an [interparticle] key: the kinds whose force reads it."""
    return ("interparticle", "kind", ForcesReading(name))


BULK = ("system", "geometry", ("bulk",))
MONOLAYER = ("system", "geometry", ("monolayer",))
START_FILE = ("system", "start", ("file",))
GENERATED = ("system", "start", ("generated",))


@dataclass(frozen=True)
class JobSection:
    """[job]: identification and the master random seed."""

    name: str = key("unnamed", "str", "job name, stored with the results",
                    allowed=Text())
    seed: int = key(0, "int", "master seed; task streams are SeedSequence(seed).spawn(...) "
                    "keyed by task id", allowed=Range(0, 2**63 - 1))


@dataclass(frozen=True)
class SizeClass:
    """One size class: sphere radius (in a, the largest radius) and its share of the
    particle volume."""

    radius: float = key(None, "float", "sphere radius; the largest class has radius 1 "
                        "(it is the length unit a)", unit="a",
                        allowed=Range(0.0, 1.0, lo_open=True), example=1.0)
    fraction: float = key(None, "float", "share of the total particle volume (not of the "
                          "number); the classes sum to 1", allowed=Range(0.0, 1.0, lo_open=True),
                          example=0.5)


@dataclass(frozen=True)
class System:
    """[system]: the particles. Spheres of radius 1, or of several size classes (radii
    relative to the largest), in a cubic periodic box of side L = (sum_i 4 pi a_i^3 / (3 phi))^(1/3); one task group
    per volume fraction. Monolayers (geometry = "monolayer", Dratler & Schowalter 1996): N spheres of
    radius 1 with centres in one plane, in a square L x L cell, L = (N pi / phi)^(1/2) with
    phi the areal fraction, replicated in the plane and every layer_spacing x L in z
    (sdmpi.dynamics.monolayer).

    Size classes: the class counts N_k are N x_k rounded by largest remainder (ties to the
    earlier class), x_k = (f_k/a_k^3) / sum_j (f_j/a_j^3) the number fractions of the
    volume shares f_k; particles 0..N_0-1 have the first class's radius, and so on. phi is
    the total volume fraction and holds exactly (the box is sized from the realised
    particle volume); the realised volume shares are ``realised_fractions``."""

    n_particles: int = key(27, "int", "number of spheres N per realisation",
                           allowed=Range(1, None))
    phi: tuple[float, ...] = key((0.45,), "floats", "volume fractions (monolayer: areal "
                                 "fractions N pi a^2 / L^2), one task group each; the "
                                 f"initial configurations reach phi < {START_PHI_LIMIT} (bulk) "
                                 "and pi N / (4 m^2), m = ceil(sqrt N) (monolayer)",
                                 allowed=Range(0.0, 1.0, lo_open=True, hi_open=True))
    geometry: str = key("bulk", "str", "bulk: spheres in a cubic periodic box; monolayer: "
                        "centres in one plane z = const, in-plane motion, periodic in the "
                        "plane, non-Brownian steady shear only (Dratler & Schowalter 1996)",
                        allowed=Choice(("bulk", "monolayer")), controls="system.geometry")
    box: str | None = key("cubic", "str", "box shape", allowed=Choice(("cubic",)), only_if=BULK)
    start: str | None = key("generated", "str", "starting configuration: generated (an "
                            "equilibrated hard-sphere fluid drawn from the task's stream) or "
                            "file (positions read from start_file; docs/trajectories.md)",
                            allowed=Choice(("generated", "file")), only_if=BULK,
                            controls="system.start")
    start_sweeps: int | None = key(
        START_SWEEPS, "int", "hard-sphere Monte Carlo sweeps (N trial moves each) that "
        "equilibrate the generated start; the default melts the lattice start at every "
        "volume fraction the start reaches (docs/physics.md, Initial configurations)",
        allowed=Range(0, 10 ** 7), only_if=GENERATED)
    start_file: str | None = key(
        None, "str", "HDF5 file (datasets positions (N, 3) or (M, N, 3), box (3,), optional "
        "radii (N,)), extended XYZ file (Lattice in the comment line, optional 5th column "
        "radius; M frames), or an sdmpi run file (the last committed positions of its tasks "
        "at each phi); realisation r starts from configuration r mod M; a relative path is "
        "taken from the directory sdmpi runs in", allowed=Text(1000), only_if=START_FILE,
        example="start.h5")
    start_tolerance: float | None = key(
        1e-4, "float", "deepest overlap a start file may hold (surface gap >= -tolerance); "
        "smaller overlaps are removed by the overlap correction of the first step",
        unit="a", allowed=Range(0.0, 0.1), only_if=START_FILE)
    layer_spacing: float | None = key(
        2.0, "float", "monolayer: distance Lz between the layer and its periodic images "
        "in z (3D fluid around a 2D-periodic layer; Dratler & Schowalter 1996 used 100)", unit="L (in-plane side)",
        allowed=Range(1.0, 1000.0), only_if=MONOLAYER)
    size_classes: tuple[SizeClass, ...] | None = key(
        None, "tables", "discrete size classes [{radius = ..., fraction = ...}, ...]; radii "
        "in units of the largest (= 1, the length unit), fractions = volume shares summing "
        "to 1; absent: monodisperse spheres of radius 1", table=SizeClass, optional=True,
        example=({"radius": 1.0, "fraction": 0.5}, {"radius": 0.5, "fraction": 0.5}))

    # ---- derived quantities (standard library only)

    @property
    def class_counts(self) -> tuple[int, ...]:
        """Spheres per size class (N,) when monodisperse; see the class docstring."""
        n = self.n_particles
        if self.size_classes is None:
            return (n,)
        weights = [c.fraction / c.radius ** 3 for c in self.size_classes]
        total = math.fsum(weights)
        exact = [n * w / total for w in weights]
        counts = [math.floor(x) for x in exact]
        order = sorted(range(len(exact)), key=lambda k: (-(exact[k] - counts[k]), k))
        for k in order[:n - sum(counts)]:
            counts[k] += 1
        return tuple(counts)

    @property
    def class_radii(self) -> tuple[float, ...]:
        """The radius of each size class ((1.0,) when monodisperse)."""
        return (1.0,) if self.size_classes is None else tuple(c.radius for c in self.size_classes)

    @property
    def radii(self) -> tuple[float, ...]:
        """The radius of every particle, class by class in the order listed."""
        return tuple(r for r, m in zip(self.class_radii, self.class_counts) for _ in range(m))

    @property
    def realised_fractions(self) -> tuple[float, ...]:
        """The volume share of each class after rounding the counts."""
        vols = [m * r ** 3 for r, m in zip(self.class_radii, self.class_counts)]
        total = math.fsum(vols)
        return tuple(v / total for v in vols)

    @property
    def sphere_volume(self) -> float:
        """sum_i 4 pi a_i^3 / 3 over the N spheres (from the class counts, without a tuple of N
        radii): the box side at volume fraction phi is (sphere_volume / phi)^(1/3)."""
        return math.fsum(m * 4.0 / 3.0 * math.pi * r ** 3 for r, m in zip(self.class_radii, self.class_counts))

    @property
    def lattice_phi_limit(self) -> float:
        """The largest phi of the simple-cubic lattice start (m^3 >= N sites, m =
        :func:`lattice_sites_per_axis`), whose spacing L/m must exceed the largest diameter
        2: (pi/6) sum_i a_i^3 / m^3 (pi/6 = 0.5236 for N = m^3 equal spheres)."""
        m = lattice_sites_per_axis(self.n_particles)
        return math.pi / 6 * (math.fsum(r ** 3 for r in self.radii) / m ** 3)


@dataclass(frozen=True)
class Mode:
    """One Maxwell mode: partial viscosity eta (relative to eta_m) and relaxation time."""

    eta: float = key(None, "float", "partial zero-shear viscosity; the modes sum to 1",
                     unit="eta_m", allowed=Range(0.0, None, lo_open=True), example=1.0)
    lam: float = key(None, "float", "relaxation time", unit="time unit",
                     allowed=Range(0.0, None, lo_open=True), toml="lambda", example=0.5)


@dataclass(frozen=True)
class Medium:
    """[medium]: the suspending fluid, Newtonian or multi-mode Maxwell (Schaink et al. 2000, eqs. 2, 26)."""

    kind: str = key("newtonian", "str", "suspending medium",
                    allowed=Choice(("newtonian", "maxwell")), controls="medium.kind")
    modes: tuple[Mode, ...] | None = key(
        None, "tables", "Maxwell modes [{eta = ..., lambda = ...}, ...]; required for "
        "maxwell, forbidden for newtonian", only_if=MAXWELL, table=Mode,
        example=({"eta": 1.0, "lambda": 0.5},))


@dataclass(frozen=True)
class Shear:
    """[shear]: the imposed flow u = gamma_dot(t) y e_x.

    oscillatory: gamma(t) = gamma0 sin(omega t), one task group per omega;
    steady: gamma_dot = rate; none: quiescent (needs Brownian motion)."""

    protocol: str = key("oscillatory", "str", "shear protocol",
                        allowed=Choice(("oscillatory", "steady", "none")),
                        controls="shear.protocol")
    gamma0: float | None = key(0.02, "float", "strain amplitude (Schaink et al. 2000: linear regime)",
                               allowed=Range(0.0, 1.0, lo_open=True), only_if=OSCILLATORY)
    omega: tuple[float, ...] | None = key(
        (TWO_PI,), "floats", "angular frequencies, one task group each", unit="rad / time unit",
        allowed=Range(0.0, None, lo_open=True), only_if=OSCILLATORY)
    rate: float | None = key(1.0, "float", "shear rate (the Peclet number for Brownian jobs; "
                             "1 for non-Brownian jobs, whose time unit is 1/gamma_dot)",
                             unit="1 / time unit", allowed=Range(0.0, None, lo_open=True),
                             only_if=STEADY)


@dataclass(frozen=True)
class Brownian:
    """[brownian]: thermal motion (Brownian forces and the Brownian stress, Schaink et al. 2000, eq. 16)."""

    enabled: bool = key(True, "bool", "include Brownian motion")
    scheme: str | None = key(None, "str", "how the Brownian drift kT div R_FU^-1 and the Brownian "
                             "stresslets are estimated: " + DRIFT_SCHEMES.summaries() + "; absent: "
                             + "; ".join(f"{default_drift_scheme(b.name)} on {b.name}" for b in SOLVER_BACKENDS)
                             + " (see docs/numerics.md)", allowed=Choice(DRIFT_SCHEMES), optional=True)


@dataclass(frozen=True)
class Integration:
    """[integration]: time stepping.

    oscillatory: dt = (2 pi / omega) / n with n = max(steps_per_period,
    ceil(2 pi / (omega dt_max))) steps per period. The length of every task is given either
    in periods (``periods``, the first ``discard_periods`` left out of the moduli) or in
    time (``duration``, the first ``discard_duration`` left out); a duration is rounded up
    to whole periods at each frequency, P(omega) = ceil(duration omega / 2 pi), and so is the
    discarded start-up, because the moduli are projections over whole periods (Schaink et al. eq.
    18). A duration gives every frequency the same time in t_D, so that slow structural
    relaxation (diffusion times) is sampled alike at high and low frequency.
    steady / none: ``n_steps`` steps of ``dt``, the first ``discard_steps`` not averaged.
    """

    steps_per_period: int | None = key(500, "int", "minimum time steps per period "
                                       "(Schaink et al. 2000: at least 500)", allowed=Range(8, None),
                                       only_if=OSCILLATORY)
    periods: int | None = key(20, "int", "periods run per task (or give duration instead)",
                              allowed=Range(1, None), only_if=OSCILLATORY)
    discard_periods: int | None = key(5, "int", "leading periods left out of the moduli; "
                                      "< periods", allowed=Range(0, None),
                                      only_if=OSCILLATORY)
    duration: float | None = key(
        None, "float", "length of every task in time, instead of periods (and "
        "discard_periods): rounded up to whole periods at each frequency, ceil(duration "
        "omega / 2 pi) periods, so that the moduli are still projections over whole periods",
        unit="time unit", allowed=Range(0.0, None, lo_open=True), only_if=OSCILLATORY,
        optional=True, instead_of=("periods", "discard_periods"))
    discard_duration: float | None = key(
        None, "float", "with duration: leading time left out of the moduli, rounded up to "
        "whole periods like duration; at every frequency fewer periods than duration gives",
        unit="time unit", allowed=Range(0.0, None), only_if=OSCILLATORY,
        given_with="duration", example=5.0)
    dt_max: float | None = key(math.inf, "float", "largest time step; adds steps per period "
                               "at low frequency (Schaink et al. 2000: 5e-4)", unit="time unit",
                               allowed=Range(0.0, None, lo_open=True, allow_inf=True),
                               only_if=OSCILLATORY)
    dt: float | None = key(1e-3, "float", "time step", unit="time unit",
                           allowed=Range(0.0, None, lo_open=True), only_if=STEADY_OR_NONE)
    n_steps: int | None = key(10000, "int", "time steps per task", allowed=Range(1, None),
                              only_if=STEADY_OR_NONE)
    overlap_stop: float | None = key(
        0.02, "float", "monolayer: a realisation stops (its later samples are NaN) when two "
        "spheres overlap by more than this (Dratler & Schowalter 1996: 2% of a radius)", unit="a",
        allowed=Range(0.0, 1.0, lo_open=True), only_if=MONOLAYER)
    discard_steps: int | None = key(1000, "int", "leading steps left out of averages; "
                                    "< n_steps", allowed=Range(0, None),
                                    only_if=STEADY_OR_NONE)
    scheme: str = key("euler-maruyama", "str", "time integrator: " + INTEGRATORS.summaries()
                      + " (see docs/numerics.md)", allowed=Choice(INTEGRATORS))


@dataclass(frozen=True)
class Interparticle:
    """[interparticle]: forces between sphere surfaces besides hydrodynamics.

    none: hard spheres (lubrication, plus the potential-free overlap correction);
    repulsion: F(h) = f0 tau exp(-tau h)/(1 + exp(-tau h)) along the line of centres
    (Dratler & Schowalter 1996), with h the surface gap; vdw: Hamaker's van der Waals attraction between
    spheres (Finke et al. 2020, eqs. 4-5), constant below cap_gap; dlvo: vdw plus the electrostatic
    double-layer repulsion psi^2 R ln(1 + exp(-h/debye_length)) (Derjaguin, constant low
    potential; R = a_i a_j/(a_i + a_j)). vdw and dlvo forces are shifted to vanish at the
    lubrication cut-off. frictional: contact springs k_n, k_t with Coulomb friction mu and
    the critical-load repulsion f_r0 exp(-h/repulsion_length) (Mari et al., J. Rheol. 58,
    1693 (2014); sdmpi.dynamics.contacts), non-Brownian only. Force unit 6 pi eta_m a^2/(time unit): kT/a (Brownian) or
    6 pi eta_m a^2 gamma_dot (non-Brownian steady shear); energy unit = force unit x a
    (kT, or 6 pi eta_m a^3 gamma_dot). See sdmpi.dynamics.forces."""

    kind: str = key("none", "str", "interparticle force: " + FORCES.summaries(), allowed=Choice(FORCES),
                    controls="interparticle.kind")
    f0: float | None = key(None, "float", "force scale F0 (F(0) = F0 tau / 2); Dratler & Schowalter 1996: "
                           "F0 = 1/(2 gamma*) in non-Brownian jobs",
                           unit="force unit x a", allowed=Range(0.0, None, lo_open=True),
                           only_if=_force_key("f0"), example=1.0)
    tau: float | None = key(None, "float", "inverse range tau of the repulsion; 1/tau must "
                            "be below the lubrication cut-off / 12", unit="1/a",
                            allowed=Range(0.0, None, lo_open=True), only_if=_force_key("tau"), example=1000.0)
    hamaker: float | None = key(None, "float", "Hamaker constant A (Finke et al. 2020, eq. 4; "
                                "e.g. A/kT = 1.8 for 7.5e-21 J at 300 K)", unit="energy unit",
                                allowed=Range(0.0, None, lo_open=True), only_if=_force_key("hamaker"),
                                example=1.0)
    cap_gap: float | None = key(None, "float", "gap below which the van der Waals force is "
                                "held constant (Finke et al. 2020: 0.4 nm); F(cut-off) <= 1e-3 F(cap) "
                                "is required", unit="a",
                                allowed=Range(0.0, 1.0, lo_open=True), only_if=_force_key("cap_gap"),
                                example=0.01)
    debye_length: float | None = key(None, "float", "Debye screening length 1/kappa of the "
                                     "double layer; F(cut-off) <= 1e-3 F(0) is required",
                                     unit="a", allowed=Range(0.0, None, lo_open=True),
                                     only_if=_force_key("debye_length"), example=0.05)
    surface_potential: float | None = key(
        None, "float", "reduced surface potential psi, psi^2 = 4 pi eps eps0 a psi0^2 / "
        "energy unit (= (e psi0/kT)^2 a/l_B in a Brownian job, l_B the Bjerrum length)",
        unit="sqrt(energy unit / a)", allowed=Range(0.0, None, lo_open=True),
        only_if=_force_key("surface_potential"), example=10.0)
    mu: float | None = key(None, "float", "Coulomb friction coefficient of the contacts, "
                           "|F_t| <= mu |F_n| (0: frictionless contacts)",
                           allowed=Range(0.0, None), only_if=_force_key("mu"), example=0.5)
    k_n: float | None = key(None, "float", "normal contact stiffness (overlap ~ contact "
                            "force / k_n; keep it below ~0.02 a)", unit="force unit / a",
                            allowed=Range(0.0, None, lo_open=True), only_if=_force_key("k_n"),
                            example=1000.0)
    k_t: float | None = key(None, "float", "tangential contact stiffness; the explicit step "
                            "needs k_t dt m_t <= 1, m_t ~ 0.7 (sliding mobility at "
                            "min_gap 1e-3)", unit="force unit / a",
                            allowed=Range(0.0, None, lo_open=True), only_if=_force_key("k_t"),
                            example=500.0)
    f_r0: float | None = key(None, "float", "critical load: the repulsion at contact; the "
                             "shear rate in units of f_r0 / (6 pi eta_m a^2) is 1/f_r0",
                             unit="force unit", allowed=Range(0.0, None, lo_open=True),
                             only_if=_force_key("f_r0"), example=1.0)
    repulsion_length: float | None = key(None, "float", "decay length lambda of the "
                                         "repulsion f_r0 exp(-h/lambda); 27.6 lambda must be "
                                         "below the lubrication cut-off", unit="a",
                                         allowed=Range(0.0, None, lo_open=True),
                                         only_if=_force_key("repulsion_length"), example=0.05)
    max_contacts: int | None = key(12, "int", "contacts stored per particle (checkpointed "
                                   "history; a particle's contacts with larger-numbered ones)",
                                   allowed=Range(1, 64), only_if=_force_key("max_contacts"))


@dataclass(frozen=True)
class Ensemble:
    """[ensemble]: independent realisations and how many MPI ranks share one task."""

    realisations: int = key(7, "int", "independent realisations per (phi, omega) "
                            "(Schaink et al. 2000: at least 7)", allowed=Range(1, MAX_REALISATIONS))
    ranks_per_task: int = key(1, "int", "MPI ranks per task (> 1 needs solver.backend = "
                              f"{quoted(several_rank_choices())})",
                              allowed=Range(1, None))


@dataclass(frozen=True)
class Solver:
    """[solver]: the linear-algebra backend for the resistance problem."""

    backend: str = key("dense", "str", SOLVER_BACKENDS.summaries(), allowed=Choice(SOLVER_BACKENDS))
    tolerance: float = key(1e-8, "float", "relative residual of iterative solves "
                           "(petsc-krylov; direct backends ignore it); for dynamics 1e-4 to "
                           "1e-6 with lanczos_tolerance = 1e-4 and hydrodynamics."
                           "ewald_tolerance = 1e-4 suffice "
                           "(docs/performance.md#krylov-backend-benchbench_krylovpy)",
                           allowed=Range(0.0, 1.0, lo_open=True, hi_open=True))
    lanczos_tolerance: float | None = key(None, "float", "relative accuracy of the Lanczos "
                                          "square root M^-1/2 z in the Brownian forces "
                                          "(petsc-krylov); absent: solver.tolerance",
                                          allowed=Range(0.0, 1.0, lo_open=True, hi_open=True),
                                          optional=True)
    far_field: str | None = key(None, "str", "petsc-krylov's far-field mobility: spectral = "
                                "particle-mesh Ewald products, O(N log N); dense = the Ewald "
                                "matrix, 11N x 11N on every rank (small N, the exact reference); "
                                "absent: dense below 200 particles, else spectral; the direct "
                                "backends ignore it", allowed=Choice(("dense", "spectral")),
                                optional=True)


@dataclass(frozen=True)
class Hydrodynamics:
    """[hydrodynamics]: accuracy knobs of the hydrodynamic interactions. Gaps are
    surface-to-surface distances in units of the pair's mean radius."""

    model: str = key("stokesian", "str", "hydrodynamic interactions: " + HYDRODYNAMIC_MODELS.summaries(),
                     allowed=Choice(HYDRODYNAMIC_MODELS))
    ewald_tolerance: float | None = key(None, "float", "relative accuracy of the Ewald sums; "
                                        f"absent: {_num(BROWNIAN_EWALD_TOLERANCE)} for Brownian "
                                        "jobs of equal spheres in a box of side >= "
                                        f"{_num(LOOSE_EWALD_MIN_SIDE)} (their operators change by "
                                        "< 1e-3 of themselves, docs/performance.md), "
                                        f"{_num(BROWNIAN_EWALD_TOLERANCE_TIGHT)} for other "
                                        f"Brownian jobs, else {_num(EWALD_TOLERANCE)}; from 1e-05 "
                                        "on, dense and petsc-dense invert M_inf in single "
                                        "precision for 64 spheres or more and petsc-krylov stores "
                                        "its real-space blocks and wave-space grids in single "
                                        "precision "
                                        "(docs/numerics.md)",
                                        allowed=Range(0.0, 1e-2, lo_open=True), optional=True)
    lubrication: bool = key(True, "bool", "add pairwise lubrication (near-field) terms; false leaves "
                            "the far-field mobility alone (prefer model = \"far-field\")")
    lubrication_cutoff: float = key(2.0, "float", "gap below which lubrication is added",
                                    unit="mean radii", allowed=Range(0.0, 10.0, lo_open=True))
    min_gap: float = key(1e-4, "float", "gaps are clamped to at least this in lubrication; "
                         "< lubrication_cutoff", unit="mean radii",
                         allowed=Range(0.0, 0.1, lo_open=True))
    collisions: str | None = key(None, "str", "how pairs in contact (gap below min_gap) after a "
                                 "step are corrected: separate = moved apart to 2 min_gap; "
                                 "reflect = the Brownian part of the step reflected at the gap "
                                 "min_gap (the deterministic part separated), both by contact "
                                 "impulses acting through the mobility; absent: separate "
                                 "for the models with lubrication ("
                                 + ", ".join(HYDRODYNAMIC_MODELS.names(lambda m: m.lubrication))
                                 + "), reflect for the others (see docs/physics.md)",
                                 allowed=Choice(("separate", "reflect")), optional=True)
    far_field_refresh: float = key(0.0, "float", "time between recomputations of the far-field "
                                   "mobility M_inf (lubrication every step): the far field of the "
                                   "last refresh is used in between (Dratler & Schowalter 1996: "
                                   "0.1); rounded to whole time steps; 0: every step; "
                                   "non-Brownian jobs on a direct backend only", unit="time unit",
                                   allowed=Range(0.0, None))


@dataclass(frozen=True)
class Output:
    """[output]: what is stored and how often the run state is committed."""

    per_particle: bool = key(False, "bool", "also store per-particle stresslets")
    checkpoint_every: int = key(1000, "int", "time steps between checkpoints",
                                allowed=Range(1, None))
    trajectory_every: int = key(0, "int", "write the positions every K time steps into the "
                                "run file as an H5MD trajectory (docs/trajectories.md); 0: "
                                "no trajectory", allowed=Range(0, None))
    trajectory_velocities: bool = key(False, "bool", "trajectory frames also hold each "
                                      "particle's mean velocity over the frame's time step")
    trajectory_stresslets: bool = key(False, "bool", "trajectory frames also hold the "
                                      "hydrodynamic stresslets (needs per_particle = true)")


@dataclass(frozen=True)
class Physical:
    """[physical]: optional physical-unit input (sdmpi.config.units). The scales radius,
    viscosity and temperature fix the reduced units (a, eta_m, t_D = 6 pi eta_m a^3/kT;
    1/gamma_dot in non-Brownian steady shear, which needs shear_rate instead of
    temperature); the other keys are converted once, by the loader, into the reduced key
    named in their doc, which must then be absent (or equal, as in the canonical text).
    Outputs gain SI columns (sdmpi reduce) and the run file the conversion factors."""

    radius: float | None = key(None, "float", "radius a of the largest spheres (the length "
                               "unit); needed with any other [physical] key", unit="nm",
                               allowed=Range(0.0, None, lo_open=True), optional=True)
    viscosity: float | None = key(None, "float", "medium zero-shear viscosity eta_m; "
                                  "needed with any other [physical] key", unit="Pa s",
                                  allowed=Range(0.0, None, lo_open=True), optional=True)
    temperature: float | None = key(None, "float", "temperature T (kT, t_D, the Peclet number, "
                                    "eq. 6)", unit="K", allowed=Range(0.0, None, lo_open=True),
                                    optional=True)
    shear_rate: float | None = key(None, "float", "shear rate; sets shear.rate (= Pe = "
                                   "gamma_dot t_D, or 1 in non-Brownian jobs)", unit="1/s",
                                   allowed=Range(0.0, None, lo_open=True), optional=True)
    omega: tuple[float, ...] | None = key(None, "floats", "angular frequencies; set shear.omega",
                                          unit="rad/s", allowed=Range(0.0, None, lo_open=True),
                                          optional=True)
    hamaker: float | None = key(None, "float", "Hamaker constant (Finke et al. 2020: 7.5e-21); sets "
                                "interparticle.hamaker", unit="J",
                                allowed=Range(0.0, None, lo_open=True), optional=True)
    cap_gap: float | None = key(None, "float", "van der Waals cap gap (Finke et al. 2020: 0.4); sets "
                                "interparticle.cap_gap", unit="nm",
                                allowed=Range(0.0, None, lo_open=True), optional=True)
    debye_length: float | None = key(None, "float", "Debye length; sets "
                                     "interparticle.debye_length", unit="nm",
                                     allowed=Range(0.0, None, lo_open=True), optional=True)
    surface_potential: float | None = key(
        None, "float", "surface potential psi0 (needs medium_permittivity); sets "
        "interparticle.surface_potential = sqrt(4 pi eps_r eps_0 a psi0^2 / kT)", unit="mV",
        allowed=Range(None, None), optional=True)
    particle_permittivity: float | None = key(
        None, "float", "static dielectric constant e1 of the particles: with the next four "
        "keys and temperature, the Hamaker constant of Finke et al. 2020, eq. 6 (Israelachvili eq. "
        "13.16) sets interparticle.hamaker", allowed=Range(1.0, None), optional=True)
    medium_permittivity: float | None = key(None, "float", "static dielectric constant e3 of "
                                            "the medium (eq. 6; double layer)",
                                            allowed=Range(1.0, None), optional=True)
    particle_refractive_index: float | None = key(None, "float", "refractive index n1 of the "
                                                  "particles (eq. 6)", allowed=Range(1.0, None),
                                                  optional=True)
    medium_refractive_index: float | None = key(None, "float", "refractive index n3 of the "
                                                "medium (eq. 6)", allowed=Range(1.0, None),
                                                optional=True)
    absorption_frequency: float | None = key(None, "float", "main UV absorption frequency "
                                             "nu_e (eq. 6; ~3e15 for many materials)",
                                             unit="1/s", allowed=Range(0.0, None, lo_open=True),
                                             optional=True)


@dataclass(frozen=True)
class Job:
    """A validated job: one attribute per TOML section (same names as in the file)."""

    job: JobSection = field(default_factory=JobSection)
    system: System = field(default_factory=System)
    medium: Medium = field(default_factory=Medium)
    shear: Shear = field(default_factory=Shear)
    brownian: Brownian = field(default_factory=Brownian)
    integration: Integration = field(default_factory=Integration)
    interparticle: Interparticle = field(default_factory=Interparticle)
    ensemble: Ensemble = field(default_factory=Ensemble)
    solver: Solver = field(default_factory=Solver)
    hydrodynamics: Hydrodynamics = field(default_factory=Hydrodynamics)
    output: Output = field(default_factory=Output)
    physical: Physical = field(default_factory=Physical)

    # ---- derived quantities (one place for the time-step arithmetic)

    @property
    def ewald_tolerance(self) -> float:
        """hydrodynamics.ewald_tolerance, or its default for this job: EWALD_TOLERANCE without
        Brownian motion (monolayers included); with it BROWNIAN_EWALD_TOLERANCE for equal
        spheres in a box of side >= LOOSE_EWALD_MIN_SIDE at every phi, else
        BROWNIAN_EWALD_TOLERANCE_TIGHT."""
        tol = self.hydrodynamics.ewald_tolerance
        if tol is not None:
            return tol
        if not self.brownian.enabled:
            return EWALD_TOLERANCE
        system = self.system
        loose = system.size_classes is None and \
            (system.sphere_volume / max(system.phi)) ** (1 / 3) >= LOOSE_EWALD_MIN_SIDE
        return BROWNIAN_EWALD_TOLERANCE if loose else BROWNIAN_EWALD_TOLERANCE_TIGHT

    @property
    def time_unit(self) -> str:
        """'1/gamma_dot' for non-Brownian steady shear, else 't_D' (= a^2/D0)."""
        steady = self.shear.protocol == "steady"
        return "1/gamma_dot" if steady and not self.brownian.enabled else "t_D"

    @property
    def frequencies(self) -> tuple[float | None, ...]:
        """The omega of each task group; (None,) unless the shear is oscillatory."""
        return self.shear.omega if self.shear.protocol == "oscillatory" else (None,)

    def steps_per_period(self, omega: float) -> int:
        """Time steps per period at this omega (oscillatory jobs), honouring dt_max."""
        integ = self.integration
        needed = TWO_PI / (omega * integ.dt_max)
        return max(integ.steps_per_period, math.ceil(needed * (1.0 - 1e-12)))

    def time_step(self, omega: float | None) -> float:
        """The time step (time unit) of a task at this omega (None: steady / none)."""
        if omega is None:
            return self.integration.dt
        return TWO_PI / omega / self.steps_per_period(omega)

    def periods(self, omega: float) -> int:
        """Whole periods run per task at this omega (oscillatory jobs)."""
        integ = self.integration
        if integ.duration is None:
            return integ.periods
        return max(_whole_periods(integ.duration, omega), 1)

    def discarded_periods(self, omega: float) -> int:
        """Leading whole periods left out of the moduli at this omega (oscillatory jobs)."""
        integ = self.integration
        if integ.duration is None:
            return integ.discard_periods
        return _whole_periods(integ.discard_duration, omega)

    def n_steps(self, omega: float | None) -> int:
        """Total time steps of one task at this omega (None: steady / none)."""
        if omega is None:
            return self.integration.n_steps
        return self.periods(omega) * self.steps_per_period(omega)

    def discard_steps(self, omega: float | None) -> int:
        """Leading time steps left out of averages at this omega."""
        if omega is None:
            return self.integration.discard_steps
        return self.discarded_periods(omega) * self.steps_per_period(omega)


def _whole_periods(duration: float, omega: float) -> int:
    """ceil(duration omega / 2 pi): the whole periods covering ``duration``; a product
    within 1e-9 (relative) of an integer counts as that integer, so that a duration given
    as an exact multiple of the period is not rounded up by round-off."""
    n = duration * omega / TWO_PI
    return max(math.ceil(n - 1e-9 * max(n, 1.0)), 0)


SECTIONS: tuple[tuple[str, type], ...] = tuple(
    (f.name, f.default_factory) for f in dataclasses.fields(Job))
