"""Canonical text of a resolved job, and its hash.

The canonical text is TOML: every non-empty section in schema order, every applicable key in
schema order with its resolved value (defaults included, keys that do not apply left
out), floats written with ``repr`` (shortest round-trip form). Parsing it gives back the
same :class:`Job`, so it is what the run file stores, and two jobs are the same job
exactly when their canonical texts (or hashes) are equal.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math

from .schema import SECTIONS, Job, toml_name

FORMAT = "sdmpi job, canonical form 1"

# Keys that change how a job is run but never its results (principle: results do not
# depend on rank count, assignment, stops or resumes); a run may resume with them changed.
LAYOUT_KEYS = frozenset({"ensemble.ranks_per_task", "output.checkpoint_every"})
# Keys that set how long tasks run (and how much of the start the averages leave out): a
# finished run may be extended (``sdmpi run --extend``) by a job differing only in these.
LENGTH_KEYS = frozenset({"integration.periods", "integration.discard_periods",
                         "integration.duration", "integration.discard_duration",
                         "integration.n_steps", "integration.discard_steps"})


def toml_literal(value) -> str:
    """One value as a TOML literal (bool, int, float incl. inf, str, array, dataclass)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(toml_literal(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {toml_literal(v)}"
                               for k, v in value.items()) + "}"
    if dataclasses.is_dataclass(value):
        return "{" + ", ".join(f"{toml_name(f)} = {toml_literal(getattr(value, f.name))}"
                               for f in dataclasses.fields(value)) + "}"
    return repr(value)  # other TOML types (dates) only ever appear in error messages


def _toml_string(s: str) -> str:
    out = []
    for ch in s:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_key(k: str) -> str:
    bare = k and all(c.isascii() and (c.isalnum() or c in "_-") for c in k)
    return k if bare else _toml_string(k)


def canonical_text(job: Job, *, exclude: frozenset[str] = frozenset()) -> str:
    """The canonical TOML text of ``job``, without the keys named in ``exclude``."""
    lines = [f"# {FORMAT}"]
    for section, _ in SECTIONS:
        values = getattr(job, section)
        keys = [f"{toml_name(f)} = {toml_literal(getattr(values, f.name))}"
                for f in dataclasses.fields(values)
                if getattr(values, f.name) is not None and f"{section}.{toml_name(f)}" not in exclude]
        if keys:  # sections without applicable keys (e.g. an unused [physical]) are left out
            lines += [f"\n[{section}]"] + keys
    return "\n".join(lines) + "\n"


def job_hash(job: Job) -> str:
    """SHA-256 (hex) of the canonical text: equal exactly for equal jobs."""
    return hashlib.sha256(canonical_text(job).encode()).hexdigest()


def resume_hash(job: Job) -> str:
    """SHA-256 (hex) of the canonical text without :data:`LAYOUT_KEYS`: a run may be
    resumed by any job with the same resume hash."""
    return hashlib.sha256(canonical_text(job, exclude=LAYOUT_KEYS).encode()).hexdigest()


def extension_hash(job: Job) -> str:
    """SHA-256 (hex) of the canonical text without :data:`LAYOUT_KEYS` and
    :data:`LENGTH_KEYS`: a run may be extended by any longer job with the same hash."""
    return hashlib.sha256(canonical_text(job, exclude=LAYOUT_KEYS | LENGTH_KEYS)
                          .encode()).hexdigest()
