"""Job file (TOML) + ``--set`` overrides -> validated :class:`Job`, or every problem at once.

Order of work: read and parse the file, parse the overrides, merge them (an override
wins), then check each section and key against the schema (unknown keys with a
did-you-mean, types, ranges, keys that do not apply), then the checks that involve
several keys (:mod:`.checks`). A cross-key check is skipped when one of its keys already
failed, so each mistake is reported once.
"""

from __future__ import annotations

import copy
import dataclasses
import datetime
import difflib
import math
import os
import re
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from . import units
from .canonical import toml_literal
from .checks import CROSS_CHECKS, CrossCheck
from .problems import JobError, Problem
from .schema import SECTIONS, Choice, Job, Physical, Text, toml_name


# --------------------------------------------------------------------------- entry points


def load_job(source: str | os.PathLike | Mapping, overrides: Iterable[str] = (), *,
             checks: Sequence[CrossCheck] = ()) -> Job:
    """The validated, frozen :class:`Job` of a job file's path (TOML) or of a mapping of
    section name -> table (as ``tomllib.load`` returns it; not modified), with the
    ``--set`` ``overrides`` ("SECTION.KEY=LITERAL") applied in order; raises
    :class:`JobError` listing every problem. ``checks``: more cross-key checks (keys read,
    check), run with :data:`.checks.CROSS_CHECKS` in the same pass: those of
    `sdmpi.dynamics.checks`, whose ``load_job`` (``sdmpi.load_job``) adds them."""
    if isinstance(source, Mapping):
        return _validated(copy.deepcopy(dict(source)), overrides, "job", checks)
    name = str(source)
    try:
        data = Path(source).read_bytes()
    except OSError as err:
        reason = err.strerror or str(err)
        raise JobError([Problem(name, f"cannot read the job file: {reason}")], name) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        why = f"not UTF-8 text (bad byte at offset {err.start}); TOML files are UTF-8"
        raise JobError([Problem(name, why)], name) from None
    if not text.strip():
        why = ("the job file is empty; write at least a [job] table with name = \"...\" "
               "(every other key has a default: docs/job_keys.md)")
        raise JobError([Problem(name, why)], name)
    return parse_job(text, overrides, source=name, checks=checks)


def parse_job(text: str, overrides=(), *, source: str = "job", checks: Sequence[CrossCheck] = ()) -> Job:
    """Validate the TOML ``text`` with ``overrides`` (strings 'section.key=LITERAL') and
    the extra cross-key ``checks`` (:func:`load_job`)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        problems = [_syntax_problem(err, text, source)]
        parse_overrides(overrides, problems)
        raise JobError(problems, source) from None
    return _validated(raw, overrides, source, checks)


def _validated(raw: dict, overrides, source: str, checks) -> Job:
    """The Job of the parsed TOML ``raw`` (changed in place) with ``overrides``."""
    problems = []
    settings = parse_overrides(overrides, problems)
    for section, name, value in settings:
        table = raw.setdefault(section, {})
        if isinstance(table, dict):
            table[name] = value
        else:
            problems.append(Problem(section, "is not a table in the file, so "
                                    f"{section}.{name} cannot be set", table, origin="--set"))
    set_paths = frozenset(f"{s}.{k}" for s, k, _ in settings)
    job = _resolve(raw, problems, set_paths, checks)
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


def _resolve(raw: dict, problems: list, set_paths=frozenset(), checks=()) -> Job:
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
    job = _with_derived_defaults(Job(**{s: cls(**st.context[s]) for s, cls in SECTIONS}))
    for deps, check in (*CROSS_CHECKS, *checks):
        if not any(d in st.invalid or d.split(".")[0] in st.invalid for d in deps):
            problems.extend(check(job))
    problems[:] = [_mark_derived(p, st.derived) for p in problems]
    return job


def _with_derived_defaults(job: Job) -> Job:
    """The job with the keys whose default depends on other keys filled in, so that its
    canonical text states the value used: hydrodynamics.ewald_tolerance
    (`Job.ewald_tolerance`: Brownian or not)."""
    hyd = job.hydrodynamics
    if hyd.ewald_tolerance is not None:
        return job
    return dataclasses.replace(job, hydrodynamics=dataclasses.replace(hyd, ewald_tolerance=job.ewald_tolerance))


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
    problems = _physical_requirements(phys, brownian, protocol)
    if problems:
        st.problems.extend(problems)
        st.invalid.update(p.path for p in problems)
        _unconverted(st, targets)
        return
    physical = Physical(**phys)
    try:
        reduced = units.reduced_values(physical, units.make_scales(physical, brownian, protocol))
    except (OverflowError, ZeroDivisionError) as err:  # e.g. radius = 1e-300 nm
        what = "a value overflows" if isinstance(err, OverflowError) else "a scale underflows to zero"
        st.problems.append(Problem("physical", "these values cannot be converted to reduced units "
                                   f"in floating point ({what}): " + ", ".join(
                                       f"{k} = {toml_literal(phys[k])}" for k in given),
                                   allowed="the magnitudes of colloids and their media, e.g. radius "
                                   "= 37.5 nm, viscosity = 0.1 Pa s, temperature = 298.15 K, "
                                   "surface_potential = 30 mV"))
        st.invalid.add("physical")
        _unconverted(st, targets)
        return
    _write_reduced(raw, st, phys, reduced)


def _physical_requirements(phys: dict, brownian: bool, protocol: str) -> list[Problem]:
    """The [physical] keys missing or in conflict for the keys given: radius and
    viscosity always; temperature (t_D) or, in non-Brownian steady shear, shear_rate;
    all or none of the optical keys of Finke et al. (2020) eq. 6 (and not hamaker
    beside them); medium_permittivity with surface_potential."""
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
                    "constant of Finke et al. (2020) eq. 6 needs all of "
                    + ", ".join(units.OPTICAL_KEYS), example)
        require("temperature", "for the Hamaker constant of Finke et al. (2020) eq. 6 "
                "(its kT term)", 298.15)
        if phys["hamaker"] is not None:
            problems.append(Problem("physical.hamaker", "conflicts with physical."
                                    f"{optical[0]} (the Hamaker constant from eq. 6)",
                                    phys["hamaker"], allowed="one of physical.hamaker or the "
                                    "eq.-6 keys " + ", ".join(units.OPTICAL_KEYS)))
    if phys["surface_potential"] is not None:
        require("medium_permittivity", "with physical.surface_potential (the double layer's "
                "strength 4 pi eps_r eps_0 a psi0^2)", 80.0)
    return problems


def _write_reduced(raw: dict, st: _Pass, phys: dict, reduced: dict) -> None:
    """Write the reduced values of the [physical] keys into ``raw`` (recording their
    origin), or a problem where the reduced key is given with another value."""
    for name, (target, value) in reduced.items():
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
