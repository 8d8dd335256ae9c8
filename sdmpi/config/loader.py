"""Job file (TOML) + ``--set`` overrides -> validated :class:`Job`, or every problem at once.

Order of work: read and parse the file, parse the overrides, merge them (an override
wins), then check each section and key against the schema (unknown keys with a
did-you-mean, types, ranges, keys that do not apply), then the checks that involve
several keys. A cross-key check is skipped when one of its keys already failed, so each
mistake is reported once.
"""

from __future__ import annotations

import dataclasses
import datetime
import difflib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from . import units
from .canonical import toml_literal
from .schema import SECTIONS, START_PHI_LIMIT, TWO_PI, Choice, Job, Physical, Text, toml_name

_MISSING = object()


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a job: where (``section.key``, ``medium.modes[0].lambda``, or
    the file name), the offending value, why, and what is allowed."""

    path: str
    why: str
    value: object = _MISSING
    allowed: str = ""
    origin: str = ""  # "--set" when the offending key came from an override

    def __str__(self) -> str:
        head = self.path
        if self.value is not _MISSING:
            shown = toml_literal(self.value)
            head += f" = {shown if len(shown) <= 60 else shown[:57] + '...'}"
        text = f"{head}: {self.why}"
        if self.allowed:
            text += f"; allowed: {self.allowed}"
        return text + (f" [from {self.origin}]" if self.origin else "")


class JobError(ValueError):
    """A job that cannot be used; ``problems`` lists everything that is wrong with it."""

    def __init__(self, problems, source: str = "job"):
        self.problems = tuple(problems)
        self.source = source
        n = len(self.problems)
        lines = [f"{source}: {n} problem{'s' if n != 1 else ''}"]
        lines += [f"  - {p}" for p in self.problems]
        super().__init__("\n".join(lines))


# --------------------------------------------------------------------------- entry points


def load_job(path, overrides=()) -> Job:
    """Read, override and validate the job file at ``path``; raise :class:`JobError`."""
    source = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        reason = err.strerror or str(err)
        raise JobError([Problem(source, f"cannot read the job file: {reason}")], source) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        why = f"not UTF-8 text (bad byte at offset {err.start}); TOML files are UTF-8"
        raise JobError([Problem(source, why)], source) from None
    return parse_job(text, overrides, source=source)


def parse_job(text: str, overrides=(), *, source: str = "job") -> Job:
    """Validate the TOML ``text`` with ``overrides`` (strings 'section.key=LITERAL')."""
    problems = []
    settings = parse_overrides(overrides, problems)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        problems.insert(0, _syntax_problem(err, text, source))
        raise JobError(problems, source) from None
    for section, name, value in settings:
        table = raw.setdefault(section, {})
        if isinstance(table, dict):
            table[name] = value
        else:
            problems.append(Problem(section, "is not a table in the file, so "
                                    f"{section}.{name} cannot be set", table, origin="--set"))
    set_paths = frozenset(f"{s}.{k}" for s, k, _ in settings)
    job = _resolve(raw, problems, set_paths)
    if problems:
        problems = [_mark_origin(p, set_paths) for p in problems]
        raise JobError(problems, source)
    return job


def parse_overrides(items, problems: list) -> list[tuple[str, str, object]]:
    """``['shear.gamma0=0.05', ...]`` -> [(section, key, value)]; bad items go to problems."""
    out = []
    for item in items:
        path, sep, literal = item.partition("=")
        path = path.strip()
        parts = path.split(".")
        if not sep or len(parts) != 2 or not all(parts):
            problems.append(Problem(item, "not an override", allowed="SECTION.KEY=VALUE, "
                                    "e.g. shear.gamma0=0.05", origin="--set"))
            continue
        try:
            parsed = tomllib.loads(f"value = {literal}")
            if set(parsed) != {"value"}:
                raise tomllib.TOMLDecodeError("more than one value")
        except tomllib.TOMLDecodeError:
            hint = ""
            if re.fullmatch(r"\s*[A-Za-z][\w.+-]*\s*", literal):
                hint = f"; strings need quotes: --set '{path}=\"{literal.strip()}\"'"
            problems.append(Problem(path, f"{literal!r} is not a TOML literal{hint}",
                                    allowed='a TOML value such as 0.3, 7, true, "text", '
                                    "[1.0, 2.0]", origin="--set"))
            continue
        out.append((parts[0], parts[1], parsed["value"]))
    return out


# --------------------------------------------------------------------------- per key


@dataclass
class _Pass:
    """State of one validation pass."""

    problems: list                   # every problem found so far
    set_paths: frozenset             # "section.key" given by --set
    invalid: set = field(default_factory=set)      # keys / sections that failed
    context: dict = field(default_factory=dict)    # section -> {attribute: value} so far
    derived: dict = field(default_factory=dict)    # reduced key -> [physical] key(s) it came from
    supplied: set = field(default_factory=set)     # reduced keys whose [physical] source failed


def _resolve(raw: dict, problems: list, set_paths=frozenset()) -> Job:
    """Check every section and key of ``raw``; return a provisional Job (failed keys at
    their defaults) after running the cross-key checks."""
    st = _Pass(problems, set_paths)
    sections = dict(SECTIONS)
    for name, value in raw.items():
        if name not in sections:
            problems.append(_unknown(name, value, sections, None))
    # [physical] first: it sets reduced keys of the other sections (_apply_physical)
    for section, cls in sorted(SECTIONS, key=lambda item: item[0] != "physical"):
        table = raw.get(section, {})
        if not isinstance(table, dict):
            problems.append(Problem(section, "must be a table", table,
                                    allowed=f"a [{section}] section"))
            st.invalid.add(section)
            table = {}
        st.context[section] = {}  # filled key by key: later keys may depend on earlier ones
        _resolve_table(table, cls, section, st, st.context[section])
        if section == "physical":
            _apply_physical(raw, st)
    job = Job(**{s: cls(**st.context[s]) for s, cls in SECTIONS})
    for deps, check in CROSS_CHECKS:
        if not any(d in st.invalid or d.split(".")[0] in st.invalid for d in deps):
            problems.extend(check(job))
    problems[:] = [_mark_derived(p, st.derived) for p in problems]
    return job


def _resolve_table(table, cls, prefix, st: _Pass, out: dict) -> dict:
    """Validated values of one table (a section or a mode) into ``out``, {attribute: value}.

    A key that does not apply (shear.omega under steady shear, say) is an error, unless
    its controlling key came from --set and it did not: switching the protocol or the
    medium on the command line drops the file's keys for the other protocol or medium.
    """
    fields = dataclasses.fields(cls)
    names = [toml_name(f) for f in fields]
    misspelt = set()  # known keys that an unknown key probably meant
    for name, value in table.items():
        if name not in names:
            st.problems.append(_unknown(f"{prefix}.{name}", value, names, prefix))
            misspelt.update(_close(name, names))
    table = _alternatives(table, fields, prefix, st)
    for f in fields:
        name, meta = toml_name(f), f.metadata
        path = f"{prefix}.{name}"
        applies, controller, condition, fix = _applies(meta["only_if"], st)
        if applies and (rule := _given(f, fields, table, prefix)):
            applies, controller, condition, fix = rule
        if applies is False:
            switched = controller in st.set_paths and path not in st.set_paths
            if name in table and not switched:
                st.problems.append(Problem(path, f"does not apply: used only when "
                                           f"{condition}", table[name],
                                           allowed=f"remove it, or {fix}"))
            out[f.name] = None
        elif name not in table:
            if meta["default"] is None and applies and not meta["optional"] \
                    and name not in misspelt and path not in st.supplied:
                when = f" when {condition}" if condition else ""
                example = toml_literal(meta["example"])
                st.problems.append(Problem(path, f"is required{when}",
                                           allowed=f"e.g. {name} = {example}"))
                st.invalid.add(path)
            out[f.name] = meta["default"]
        else:
            before = len(st.problems)
            value = _convert(table[name], f, path, st)
            if len(st.problems) > before:
                st.invalid.add(path)
                value = meta["default"]
            out[f.name] = value
    return out


def _alternatives(table: dict, fields, prefix, st: _Pass) -> dict:
    """``table`` without the keys an override switched away from: a key given by --set
    wins over its alternative given in the file (``instead_of`` in the schema), and a key
    given only with a dropped one (``given_with``) goes with it."""
    dropped = set()
    for f in fields:
        name, others = toml_name(f), f.metadata["instead_of"]
        given = [o for o in others if o in table]
        if name not in table or not given:
            continue
        if f"{prefix}.{name}" in st.set_paths:
            dropped.update(o for o in given if f"{prefix}.{o}" not in st.set_paths)
        elif any(f"{prefix}.{o}" in st.set_paths for o in given):
            dropped.add(name)
    dropped.update(toml_name(f) for f in fields if f.metadata["given_with"] in dropped)
    return {k: v for k, v in table.items() if k not in dropped}


def _given(f, fields, table: dict, prefix: str):
    """Like :func:`_applies` for the schema's ``instead_of`` / ``given_with``: a key does
    not apply when an alternative to it is given, or when the key it goes with is not
    (None: neither rule concerns the key)."""
    for other in fields:
        if toml_name(f) in other.metadata["instead_of"] and toml_name(other) in table:
            path = f"{prefix}.{toml_name(other)}"
            return False, path, f"{path} is not given", f"remove {path}"
    partner = f.metadata["given_with"]
    if partner is None:
        return None
    path = f"{prefix}.{partner}"
    return partner in table, path, f"{path} is given", f"give {path}"


def _applies(only_if, st: _Pass):
    """Whether a key applies (None when its controlling key is itself invalid), the
    controlling key, the condition in words, and the setting that makes the key apply."""
    if only_if is None:
        return True, "", "", ""
    section, name, values = only_if
    controller = f"{section}.{name}"
    condition = f"{controller} is " + " or ".join(f'"{v}"' for v in values)
    fix = f'set {controller} = "{values[0]}"'
    if controller in st.invalid or section in st.invalid:
        return None, controller, condition, fix
    return st.context[section][name] in values, controller, condition, fix


def _convert(value, f, path, st: _Pass):
    """The checked value of one key (tuples for arrays); problems appended on failure."""
    meta, problems = f.metadata, st.problems
    kind, name = meta["kind"], toml_name(f)
    if kind in ("floats", "tables"):
        if kind == "floats" and _is_number(value):
            value = [value]
        if not isinstance(value, list):
            what = "numbers" if kind == "floats" else "tables {...}"
            problems.append(Problem(path, f"expected an array of {what}, got {_type(value)}",
                                    value, allowed=_allowed(meta, name)))
            return None
        if not value:
            problems.append(Problem(path, "must not be empty", value,
                                    allowed=_allowed(meta, name)))
            return None
        if kind == "floats":
            each = _allowed(meta, name, element=True)
            items = [_scalar(v, "float", meta, f"{path}[{i}]", each, problems)
                     for i, v in enumerate(value)]
            for i, v in enumerate(items):
                if v is not None and v in items[:i]:
                    problems.append(Problem(f"{path}[{i}]", "appears twice", v,
                                            allowed="distinct values"))
            return tuple(items)
        cls, items = meta["table"], []
        for i, v in enumerate(value):
            if isinstance(v, dict):
                items.append(cls(**_resolve_table(v, cls, f"{path}[{i}]", st, {})))
            else:
                problems.append(Problem(f"{path}[{i}]", f"expected a table, got {_type(v)}",
                                        v, allowed=f"e.g. {toml_literal(meta['example'][0])}"))
        return tuple(items)
    return _scalar(value, kind, meta, path, _allowed(meta, name), problems)


def _scalar(value, kind, meta, path, allowed_text, problems):
    """One int / float / bool / str value, type- and range-checked."""
    allowed = meta["allowed"]
    if kind == "int":
        ok = isinstance(value, int) and not isinstance(value, bool)
        expected = "an integer" + (f" (write {int(value)}, not {value!r})"
                                   if isinstance(value, float) and value.is_integer() else "")
    elif kind == "float":
        ok = _is_number(value)
        expected = "a number"
    elif kind == "bool":
        ok = isinstance(value, bool)
        expected = "true or false"
    else:
        ok = isinstance(value, str)
        expected = "a string"
    if not ok:
        problems.append(Problem(path, f"expected {expected}, got {_type(value)}", value,
                                allowed=allowed_text))
        return None
    if kind == "float":
        value = float(value)
        if math.isnan(value):
            problems.append(Problem(path, "is not a number (nan)", value,
                                    allowed=allowed_text))
            return None
    if allowed is not None and not allowed.contains(value):
        why = "out of range"
        if isinstance(allowed, Choice):
            close = difflib.get_close_matches(value, allowed.values, n=1, cutoff=0.5)
            why = "not a valid choice" + (f'; did you mean "{close[0]}"?' if close else "")
        elif not isinstance(value, (int, float)):
            why = "not allowed"  # Text
        problems.append(Problem(path, why, value, allowed=allowed_text))
        return None
    return value


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _allowed(meta, name, element=False) -> str:
    """What a key (or, with ``element``, one element of an array key) may hold."""
    allowed = meta["allowed"]
    text = allowed.describe(name) if allowed is not None else ""
    text += f" [{meta['unit']}]" if meta["unit"] else ""
    if meta["kind"] == "floats":
        return text if element else f"a non-empty array of distinct numbers, each {text}"
    if meta["kind"] == "tables":
        return f"a non-empty array such as {toml_literal(meta['example'])}"
    if isinstance(allowed, (Choice, Text)):
        return text
    kind = {"int": "an integer", "float": "a number", "bool": "true or false",
            "str": "a string"}[meta["kind"]]
    return f"{kind}, {text}" if text else kind


def _type(value) -> str:
    for types, name in ((bool, "a boolean"), (int, "an integer"), (float, "a float"),
                        (str, "a string"), (list, "an array"), (dict, "a table"),
                        ((datetime.date, datetime.time), "a date/time")):
        if isinstance(value, types):
            return name
    return type(value).__name__


def _unknown(path, value, candidates, section) -> Problem:
    """Problem for an unknown key (``section`` given) or section (``section`` None)."""
    name = path.rsplit(".", 1)[-1] if section else path
    hints = [f'"{c}"' for c in _close(name, candidates)]
    hints += [f"{s}.{name}" for s, cls in SECTIONS if s != section
              and name in (toml_name(f) for f in dataclasses.fields(cls))]
    what = f"unknown key in [{section}]" if section else "unknown section"
    if section and "[" in section:  # inside an inline table such as medium.modes[0]
        what = "unknown key"
    why = what + (f"; did you mean {' or '.join(hints)}?" if hints else "")
    kinds = "keys" if section else "sections"
    return Problem(path, why, value, allowed=f"{kinds}: " + ", ".join(candidates))


def _close(name, candidates) -> list[str]:
    """Candidates that ``name`` may be a misspelling or abbreviation of."""
    close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.6)
    return close + [c for c in candidates if c not in close and len(name) >= 3
                    and (c.startswith(name) or name.startswith(c))]


def _syntax_problem(err, text, source) -> Problem:
    why = f"invalid TOML: {err}"
    match = re.search(r"line (\d+)", str(err))
    lines = text.splitlines()
    if match and 0 < int(match[1]) <= len(lines):
        why += f"\n      line {match[1]}: {lines[int(match[1]) - 1].strip()}"
    return Problem(source, why)


def _mark_origin(problem: Problem, set_paths) -> Problem:
    """Tag problems whose offending key was given by --set."""
    p = problem.path
    if problem.origin or not any(p == s or p.startswith(s + "[") or s.startswith(p + ".")
                                 for s in set_paths):
        return problem
    return dataclasses.replace(problem, origin="--set")


# --------------------------------------------------------------------------- physical units


def _apply_physical(raw: dict, st: _Pass) -> None:
    """Convert the [physical] keys (sdmpi.config.units) into the reduced keys they set,
    written into ``raw`` before those sections are checked, so that the usual checks
    (range, applicability, cross-key) see them; their problems name the [physical] key as
    origin. A reduced key given as well must hold the same value (the canonical text
    lists both), else both keys are named. Needs radius and viscosity, and temperature
    (t_D) or, in non-Brownian steady shear, shear_rate (time unit 1/gamma_dot)."""
    phys = st.context["physical"]
    given = [toml_name(f) for f in dataclasses.fields(Physical) if phys[f.name] is not None]
    failed = [p for p in st.invalid if p == "physical" or p.startswith("physical.")]
    named = set(given) | {p.split(".")[-1] for p in failed}
    targets = {units.CONVERTED.get(k, "interparticle.hamaker") for k in named
               if k in units.CONVERTED or k == "particle_permittivity"}
    if not given or failed:
        _unconverted(st, targets)
        return
    brownian = raw.get("brownian", {}).get("enabled", True) \
        if isinstance(raw.get("brownian", {}), dict) else None
    protocol = raw.get("shear", {}).get("protocol", "oscillatory") \
        if isinstance(raw.get("shear", {}), dict) else None
    if not isinstance(brownian, bool) or protocol not in ("oscillatory", "steady", "none"):
        _unconverted(st, targets)  # reported by their own checks
        return
    problems = []

    def require(name, why, example):
        if phys[name] is None and all(p.path != f"physical.{name}" for p in problems):
            problems.append(Problem(f"physical.{name}", f"is required {why}",
                                    allowed=f"e.g. {name} = {example}"))

    require("radius", "with any other [physical] key: it is the length unit a", 37.5)
    require("viscosity", "with any other [physical] key: it is the viscosity unit eta_m", 0.1)
    if protocol == "steady" and not brownian:
        require("shear_rate", "in non-Brownian steady shear, whose time unit is 1/gamma_dot",
                100.0)
    else:
        require("temperature", "for the time unit t_D = 6 pi eta_m a^3 / kT", 298.15)
    optical = [k for k in units.OPTICAL_KEYS if k != "medium_permittivity" and phys[k] is not None]
    if optical:
        for name, example in zip(units.OPTICAL_KEYS, (2.72, 1.85, 1.65, 1.36, 1.43e15)):
            require(name, f"with {', '.join('physical.' + k for k in optical)}: the Hamaker "
                    "constant of seed 003 eq. 6 needs all of "
                    + ", ".join(units.OPTICAL_KEYS), example)
        require("temperature", "for the Hamaker constant of seed 003 eq. 6 (its kT term)", 298.15)
        if phys["hamaker"] is not None:
            problems.append(Problem("physical.hamaker", "conflicts with physical."
                                    f"{optical[0]} (the Hamaker constant from eq. 6)",
                                    phys["hamaker"], allowed="one of physical.hamaker or the "
                                    "eq.-6 keys " + ", ".join(units.OPTICAL_KEYS)))
    if phys["surface_potential"] is not None:
        require("medium_permittivity", "with physical.surface_potential (the double layer's "
                "strength 4 pi eps_r eps_0 a psi0^2)", 80.0)
    if problems:
        st.problems.extend(problems)
        st.invalid.update(p.path for p in problems)
        _unconverted(st, targets)
        return
    physical = Physical(**phys)
    scales = units.make_scales(physical, brownian, protocol)
    for name, (target, value) in units.reduced_values(physical, scales).items():
        section, key_name = target.split(".")
        table = raw.setdefault(section, {})
        if not isinstance(table, dict):
            continue  # reported when the section is checked
        source = "physical." + name
        if key_name in table:
            if not _same_value(table[key_name], value):
                st.problems.append(Problem(
                    target, f"conflicts with {source} = {toml_literal(phys[name])}, which "
                    f"sets it to {toml_literal(value)}", table[key_name],
                    allowed=f"one of {target} (reduced units) or {source} (physical units)"))
                st.invalid.add(target)
            continue
        table[key_name] = list(value) if isinstance(value, tuple) else value
        st.derived[target] = source


def _unconverted(st: _Pass, targets) -> None:
    """Reduced keys that a failed [physical] key should have set: not reported as
    missing, and the cross-key checks that read them are skipped."""
    st.supplied |= targets
    st.invalid |= targets


def _same_value(given, value) -> bool:
    """A reduced key as given equals the value converted from [physical] (to 1e-9)."""
    given = given if isinstance(given, list) else [given]
    value = value if isinstance(value, tuple) else (value,)
    return len(given) == len(value) and all(
        _is_number(g) and math.isclose(g, v, rel_tol=1e-9) for g, v in zip(given, value))


def _mark_derived(problem: Problem, derived: dict) -> Problem:
    """Name the [physical] key as the origin of a problem with a key it set."""
    source = next((s for t, s in derived.items()
                   if problem.path == t or problem.path.startswith(t + "[")), None)
    if source is None or problem.origin:
        return problem
    return dataclasses.replace(problem, origin=source)


# --------------------------------------------------------------------------- cross-key checks


def _discard_periods(job):
    i = job.integration
    if job.shear.protocol != "oscillatory":
        return []
    if i.duration is None:
        if i.discard_periods >= i.periods:
            return [Problem("integration.discard_periods",
                            f"must be smaller than integration.periods (= {i.periods})",
                            i.discard_periods, allowed=f"0 <= discard_periods < {i.periods}")]
        return []
    if i.discard_duration >= i.duration:
        return [Problem("integration.discard_duration", f"must be smaller than "
                        f"integration.duration (= {i.duration:g})", i.discard_duration,
                        allowed=f"0 <= discard_duration < {i.duration:g}")]
    for omega in job.frequencies:  # both are rounded up to whole periods
        kept, dropped = job.periods(omega), job.discarded_periods(omega)
        if dropped >= kept:
            return [Problem("integration.discard_duration", f"leaves no whole period at "
                            f"omega = {omega:g}: both it and integration.duration round up "
                            f"to {kept} period(s) of {TWO_PI / omega:.4g}", i.discard_duration,
                            allowed=f"discard_duration <= {(kept - 1) * TWO_PI / omega:.4g}, "
                            "or a longer duration")]
    return []


def _discard_steps(job):
    i = job.integration
    if job.shear.protocol != "oscillatory" and i.discard_steps >= i.n_steps:
        return [Problem("integration.discard_steps",
                        f"must be smaller than integration.n_steps (= {i.n_steps})",
                        i.discard_steps, allowed=f"0 <= discard_steps < {i.n_steps}")]
    return []


def _trajectory(job):
    """Trajectory extras need frames, and stresslets come from the per-particle samples."""
    out, problems = job.output, []
    for name in ("trajectory_velocities", "trajectory_stresslets"):
        if getattr(out, name) and out.trajectory_every == 0:
            problems.append(Problem(f"output.{name}", "needs a trajectory", True,
                                    allowed="output.trajectory_every >= 1, or false"))
    if out.trajectory_stresslets and not out.per_particle:
        problems.append(Problem("output.trajectory_stresslets", "needs the per-particle "
                                "stresslets", True, allowed="output.per_particle = true, or false"))
    return problems


def _maxwell_sum(job):
    if job.medium.kind != "maxwell":
        return []
    total = math.fsum(m.eta for m in job.medium.modes)
    if abs(total - 1.0) > 1e-9:
        return [Problem("medium.modes", f"the mode viscosities eta sum to {total:g}, but "
                        "their sum is the medium's zero-shear viscosity eta_m, the unit of "
                        "viscosity", job.medium.modes, allowed="modes whose eta sum to 1")]
    return []


def _gaps(job):
    h = job.hydrodynamics
    if h.min_gap >= h.lubrication_cutoff:
        return [Problem("hydrodynamics.min_gap", "must be smaller than "
                        f"hydrodynamics.lubrication_cutoff (= {h.lubrication_cutoff:g})",
                        h.min_gap, allowed=f"0 < min_gap < {h.lubrication_cutoff:g}")]
    return []


def _ranks(job):
    if job.ensemble.ranks_per_task > 1 and job.solver.backend == "dense":
        return [Problem("ensemble.ranks_per_task", 'the "dense" backend runs a task on '
                        "one rank", job.ensemble.ranks_per_task,
                        allowed='1, or solver.backend = "petsc-dense", "petsc-krylov" or "auto"')]
    return []


def _protocol_units(job):
    shear, brownian = job.shear, job.brownian.enabled
    if shear.protocol == "steady" and not brownian and shear.rate != 1.0:
        return [Problem("shear.rate", "non-Brownian steady shear measures time in "
                        "1/gamma_dot, so the rate is 1 by definition", shear.rate,
                        allowed="1.0, or brownian.enabled = true (rate = Peclet number)")]
    if shear.protocol == "none" and not brownian:
        return [Problem("shear.protocol", "without shear and without Brownian motion "
                        "nothing moves", "none",
                        allowed='"oscillatory" or "steady", or brownian.enabled = true')]
    return []


def _time_step(job):
    """Seed eq. 14a (dt < t_D = 1, Brownian jobs) and dt < lambda (Maxwell media)."""
    limits = []
    if job.brownian.enabled:
        smallest = min(job.system.class_radii)
        if smallest == 1.0:
            limits.append((1.0, "the diffusion time t_D = 1 (seed eq. 14a)"))
        else:  # size classes: t_D is the largest spheres' diffusion time
            limits.append((smallest ** 3, "the diffusion time a^2/D0(a) = a^3 t_D = "
                           f"{smallest ** 3:.4g} of the smallest spheres (radius {smallest:g})"))
    if job.medium.kind == "maxwell":
        lam = min(m.lam for m in job.medium.modes)
        limits.append((lam, f"the shortest Maxwell relaxation time ({lam:g})"))
    problems = []
    for limit, what in limits:
        omega = max(job.frequencies, key=lambda w: job.time_step(w), default=None)
        dt = job.time_step(omega)
        if dt < limit:
            continue
        if omega is None:
            problems.append(Problem("integration.dt", f"must be smaller than {what}", dt,
                                    allowed=f"0 < dt < {limit:g}"))
        else:
            problems.append(Problem(
                "integration.steps_per_period", f"gives dt = {dt:.3g} at omega = {omega:g}, "
                f"not smaller than {what}", job.integration.steps_per_period,
                allowed=f"more steps per period, or integration.dt_max < {limit:g}"))
    return problems


def _initial_configuration(job):
    """The hard-sphere generator starts from a simple cubic lattice (sdmpi.dynamics.initial)
    spaced for the largest diameter, compressed when phi is above the lattice's limit
    (pi/6) sum_i a_i^3 / N: phi < START_PHI_LIMIT. Monolayers start from a square lattice
    instead (:func:`_monolayer_start`)."""
    system = job.system
    if system.geometry == "monolayer":
        return _monolayer_start(job)
    n = system.n_particles
    problems = []
    if round(n ** (1 / 3)) ** 3 != n:
        cubes = ", ".join(str(m ** 3) for m in range(1, 8))
        problems.append(Problem("system.n_particles", "the initial configuration starts from a "
                                "simple cubic lattice, so N must be a perfect cube", n,
                                allowed=f"a cube: {cubes}, ..."))
    for k, phi in enumerate(system.phi):
        if phi >= START_PHI_LIMIT:
            problems.append(Problem(f"system.phi[{k}]", "the initial configuration is a "
                                    "compressed hard-sphere fluid, made up to "
                                    f"phi = {START_PHI_LIMIT} (denser ones jam)", phi,
                                    allowed=f"0 < phi < {START_PHI_LIMIT}"))
    return problems


def _monolayer_start(job):
    """The monolayer start (sdmpi.dynamics.initial.hard_disk_monolayer): m x m square
    lattice sites, m = ceil(sqrt N), spaced L/m > 2, so phi < pi N / (4 m^2)."""
    system = job.system
    m = math.isqrt(system.n_particles - 1) + 1
    limit = math.pi * system.n_particles / (4 * m * m)
    return [Problem(f"system.phi[{k}]", f"the monolayer start fills {m} x {m} square-lattice "
                    f"sites spaced for the diameter, which holds N = {system.n_particles} disks "
                    f"up to the areal fraction pi N / (4 m^2) = {limit:.4f}", phi,
                    allowed=f"0 < phi < {math.floor(limit * 1e4) / 1e4:.4f}, or N = {m * m}")
            for k, phi in enumerate(system.phi) if phi >= limit]


def _monolayer(job):
    """Monolayers are seed 001's case: non-Brownian steady shear of equal spheres in a
    Newtonian medium, hard (with the minimum-gap rule) or with the short-range repulsion;
    the layer's z-images stay outside the lubrication cut-off."""
    system = job.system
    if system.geometry != "monolayer":
        return []
    why = "monolayers are non-Brownian steady shear of equal spheres (seed 001)"
    problems = []
    for path, value, ok, allowed in (
            ("shear.protocol", job.shear.protocol, job.shear.protocol == "steady", '"steady"'),
            ("brownian.enabled", job.brownian.enabled, not job.brownian.enabled, "false"),
            ("medium.kind", job.medium.kind, job.medium.kind == "newtonian", '"newtonian"'),
            ("system.size_classes", system.size_classes, system.size_classes is None,
             "absent (equal spheres)"),
            ("interparticle.kind", job.interparticle.kind,
             job.interparticle.kind in ("none", "repulsion"), '"none" or "repulsion"')):
        if not ok:
            problems.append(Problem(path, why, value, allowed=f'{allowed}, or system.geometry = "bulk"'))
    cutoff = job.hydrodynamics.lubrication_cutoff
    side = math.sqrt(system.n_particles * math.pi / max(system.phi))
    need = (2.0 + cutoff) / side
    if system.layer_spacing * side < 2.0 + cutoff:
        problems.append(Problem("system.layer_spacing", f"the layer's z-images ({system.layer_spacing:g} "
                                f"x L = {system.layer_spacing * side:.3g} a away at phi = "
                                f"{max(system.phi):g}) must lie beyond the lubrication cut-off "
                                f"(centre distance 2 + {cutoff:g})", system.layer_spacing,
                                allowed=f"layer_spacing >= {need:.4g}"))
    return problems


def _size_classes(job):
    """Volume shares summing to 1, the largest radius 1 (the length unit), distinct radii,
    and at least one sphere per class after rounding the counts."""
    system = job.system
    classes = system.size_classes
    if classes is None:
        return []
    problems = []
    total = math.fsum(c.fraction for c in classes)
    if abs(total - 1.0) > 1e-9:
        problems.append(Problem("system.size_classes", f"the volume shares (fraction) sum to "
                                f"{total:g}; they divide the particle volume, so they sum to 1",
                                classes, allowed="fractions > 0 whose sum is 1"))
    largest = max(c.radius for c in classes)
    if largest != 1.0:
        problems.append(Problem("system.size_classes", f"the largest radius is {largest:g}, "
                                "but the largest radius is the length unit a, so it is 1",
                                classes, allowed="radii divided by the largest, e.g. "
                                "[{radius = 1.0, ...}, {radius = 0.5, ...}]"))
    for k, c in enumerate(classes):
        if any(c.radius == d.radius for d in classes[:k]):
            problems.append(Problem(f"system.size_classes[{k}].radius", "appears twice; "
                                    "merge the two classes", c.radius,
                                    allowed="distinct radii"))
    if problems:
        return problems
    for k, (c, m) in enumerate(zip(classes, system.class_counts)):
        if m == 0:
            problems.append(Problem(f"system.size_classes[{k}]", f"gets no sphere among N = "
                                    f"{system.n_particles} (volume share {c.fraction:g} of "
                                    f"radius {c.radius:g} spheres)", c,
                                    allowed="a larger system.n_particles, or a larger fraction"))
    return problems


def _repulsion_range(job):
    inter, cutoff = job.interparticle, job.hydrodynamics.lubrication_cutoff
    if inter.kind == "repulsion" and 12 * math.log(10) / inter.tau > cutoff:
        need = 12 * math.log(10) / cutoff
        return [Problem("interparticle.tau", "the repulsion must decay (to 1e-12) within the "
                        f"lubrication cut-off (= {cutoff:g}), whose pairs it acts on", inter.tau,
                        allowed=f"tau >= {need:.4g}, or a larger hydrodynamics.lubrication_cutoff")]
    return []


def _force_range(job):
    """vdw / dlvo: the cap inside the cut-off, and the shift that truncates the force at
    the lubrication cut-off negligible (sdmpi.dynamics.forces.TAIL of the contact force)."""
    inter, cutoff = job.interparticle, job.hydrodynamics.lubrication_cutoff
    if inter.kind not in ("vdw", "dlvo"):
        return []
    smallest = min(job.system.class_radii)  # the cut-off gap is cut-off x mean radius
    if inter.cap_gap >= cutoff * smallest:
        of = "" if smallest == 1.0 else f" x the smallest radius {smallest:g}"
        return [Problem("interparticle.cap_gap", "must be smaller than the cut-off gap "
                        f"hydrodynamics.lubrication_cutoff (= {cutoff:g}){of}", inter.cap_gap,
                        allowed=f"0 < cap_gap < {cutoff * smallest:g}")]
    # the formulas live with the force laws: a layering exception (config -> dynamics),
    # imported here only for these kinds, rather than a second copy of the force laws
    from ..dynamics.forces import TAIL, tail_ratios
    problems = []
    for path, (ratio, (a_i, a_j)) in tail_ratios(job).items():
        if ratio > TAIL:
            what = ("the van der Waals force at the cut-off" if path.endswith("cap_gap")
                    else "the double-layer force at the cut-off")
            if job.system.size_classes is not None:
                what += f" (worst pair: radii {a_i:g} and {a_j:g})"
            fix = ("a smaller cap_gap" if path.endswith("cap_gap") else "a shorter debye_length")
            problems.append(Problem(path, f"{what} is {ratio:.2g} of its contact value; "
                                    f"the force is shifted to vanish at the lubrication cut-off "
                                    f"(= {cutoff:g}), which needs <= {TAIL:g}",
                                    getattr(inter, path.split(".")[1]),
                                    allowed=f"{fix}, or a larger hydrodynamics.lubrication_cutoff"))
    return problems


def _frictional(job):
    """Frictional contacts (sdmpi.dynamics.contacts): non-Brownian, the repulsion decayed
    within the lubrication cut-off, and a time step the explicit contact springs allow."""
    inter, hyd = job.interparticle, job.hydrodynamics
    if inter.kind != "frictional":
        return []
    from ..dynamics.contacts import SQUEEZE, sliding_mobility
    problems = []
    if job.brownian.enabled:
        problems.append(Problem("brownian.enabled", "frictional contacts are a non-Brownian "
                                "model (the Brownian midpoint would cross the contact springs)",
                                True, allowed='false with interparticle.kind = "frictional"'))
    reach = 12 * math.log(10) * inter.repulsion_length
    if reach > hyd.lubrication_cutoff:
        problems.append(Problem("interparticle.repulsion_length", "the repulsion must decay "
                                "(to 1e-12) within the lubrication cut-off (= "
                                f"{hyd.lubrication_cutoff:g}), whose pairs it acts on",
                                inter.repulsion_length, allowed="repulsion_length <= "
                                f"{hyd.lubrication_cutoff / (12 * math.log(10)):.4g}, or a "
                                "larger hydrodynamics.lubrication_cutoff"))
    dt = max(job.time_step(w) for w in job.frequencies)
    for path, limit, why in (
            ("interparticle.k_t", 1 / (sliding_mobility(hyd.min_gap) * dt),
             f"sliding mobility {sliding_mobility(hyd.min_gap):.3g} at hydrodynamics.min_gap"),
            ("interparticle.k_n", 1 / (SQUEEZE * hyd.min_gap * dt),
             f"normal mobility {SQUEEZE:g} x hydrodynamics.min_gap at contact")):
        value = getattr(inter, path.split(".")[1])
        if value > limit:
            problems.append(Problem(path, f"is too stiff for the time step dt = {dt:.3g}: the "
                                    f"explicit step needs dt x stiffness x mobility <= 1 ({why})",
                                    value, allowed=f"{path.split('.')[1]} <= {limit:.4g}, or a "
                                    "smaller integration.dt"))
    return problems


def _forces_need_pairs(job):
    if job.interparticle.kind != "none" and not job.hydrodynamics.lubrication:
        return [Problem("hydrodynamics.lubrication", "interparticle forces act on the "
                        "lubrication pair list; without lubrication only overlapping pairs "
                        "would feel them", False,
                        allowed='true, or interparticle.kind = "none"')]
    return []


#: backends implemented in this version (the others are named by the job schema)
IMPLEMENTED_BACKENDS = ("dense", "petsc-dense", "petsc-krylov", "auto")


def _maxwell_forces(job):
    """Seed 000 covers hard spheres in a Maxwell medium: the viscoelastic response of the
    force-induced stresslets is not modelled, so the combination is refused."""
    if job.medium.kind == "maxwell" and job.interparticle.kind != "none":
        return [Problem("interparticle.kind", "interparticle forces in a Maxwell medium are not "
                        "modelled (their stresslets would need the medium's memory too)",
                        job.interparticle.kind, allowed='"none" with medium.kind = "maxwell"')]
    return []


def _backend(job):
    if job.solver.backend not in IMPLEMENTED_BACKENDS:
        return [Problem("solver.backend", "is not implemented yet in this version",
                        job.solver.backend, allowed=", ".join(f'"{b}"' for b in IMPLEMENTED_BACKENDS))]
    return []


_INTEGRATION = tuple(f"integration.{f.name}" for f in dataclasses.fields(Job().integration))

# (keys a check reads, check): skipped when one of those keys failed its own checks.
CROSS_CHECKS = (
    (("shear.protocol", "shear.omega") + _INTEGRATION, _discard_periods),
    (("shear.protocol", "integration.n_steps", "integration.discard_steps"), _discard_steps),
    (("medium.kind", "medium.modes"), _maxwell_sum),
    (("output.trajectory_every", "output.trajectory_velocities", "output.trajectory_stresslets",
      "output.per_particle"), _trajectory),
    (("hydrodynamics.min_gap", "hydrodynamics.lubrication_cutoff"), _gaps),
    (("ensemble.ranks_per_task", "solver.backend"), _ranks),
    (("shear.protocol", "shear.rate", "brownian.enabled"), _protocol_units),
    (("shear.protocol", "shear.omega", "brownian.enabled", "medium.kind", "medium.modes",
      "system.size_classes") + _INTEGRATION, _time_step),
    (("system.n_particles", "system.size_classes"), _size_classes),
    (("system.n_particles", "system.phi", "system.size_classes", "system.geometry"),
     _initial_configuration),
    (("system.geometry", "system.n_particles", "system.phi", "system.layer_spacing",
      "system.size_classes", "shear.protocol", "brownian.enabled", "medium.kind",
      "interparticle.kind", "hydrodynamics.lubrication_cutoff"), _monolayer),
    (("interparticle.kind", "interparticle.tau", "hydrodynamics.lubrication_cutoff"), _repulsion_range),
    (("interparticle.kind", "interparticle.cap_gap", "interparticle.debye_length",
      "hydrodynamics.lubrication_cutoff", "system.size_classes"), _force_range),
    (("interparticle.kind", "hydrodynamics.lubrication"), _forces_need_pairs),
    (("interparticle.kind", "interparticle.mu", "interparticle.k_n", "interparticle.k_t",
      "interparticle.f_r0", "interparticle.repulsion_length", "brownian.enabled",
      "hydrodynamics.lubrication_cutoff", "hydrodynamics.min_gap", "shear.protocol",
      "shear.omega") + _INTEGRATION, _frictional),
    (("solver.backend",), _backend),
    (("medium.kind", "interparticle.kind"), _maxwell_forces),
)
