"""The key reference: every job-file key with its default, allowed values, unit and
meaning, as plain text read from the schema (docs/job_keys.md is this text)."""

from __future__ import annotations

import dataclasses

from .canonical import toml_literal
from .schema import SECTIONS, toml_name


def schema_text() -> str:
    """A plain-text table of every key: default, allowed values, unit and meaning."""
    lines = []
    for section, cls in SECTIONS:
        lines.append(" ".join(cls.__doc__.split("\n\n")[0].split()))
        for f in dataclasses.fields(cls):
            lines.extend(_key_line(f, "  "))
            if f.metadata["table"] is not None:
                for g in dataclasses.fields(f.metadata["table"]):
                    lines.extend(_key_line(g, "    ", f"{toml_name(f)}[]."))
        lines.append("")
    return "\n".join(lines)


def _key_line(f, indent, prefix=""):
    m = f.metadata
    name = prefix + toml_name(f)
    default = toml_literal(m["default"])
    if m["default"] is None:
        default = "absent" if m["optional"] else "required"
    allowed = m["allowed"].describe(name) if m["allowed"] else m["kind"]
    extra = f"; unit {m['unit']}" if m["unit"] else ""
    if m["only_if"]:
        s, k, vals = m["only_if"]
        extra += f"; only when {s}.{k} is " + " or ".join(f'"{v}"' for v in vals)
    if m["instead_of"]:
        extra += "; given instead of " + " and ".join(m["instead_of"])
    if m["given_with"]:
        extra += f"; only with {m['given_with']}"
    return [f"{indent}{name} = {default}   ({allowed}{extra})", f"{indent}    {m['doc']}"]
