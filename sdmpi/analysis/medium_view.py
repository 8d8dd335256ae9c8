"""Another suspending medium applied after the fact (``sdmpi reduce --medium``).

Schaink et al. (2000) sec. II C: a Maxwell medium leaves every particle trajectory as in
the viscous medium of the same zero-shear viscosity eta_m (their eq. 32) and filters only
the hydrodynamic stresslets, mode by mode (eqs. 33-35, 42):

    lambda_k dS_k/dt + S_k = (eta_k / eta_m) S_0(t),    S_H = sum_k S_k.

The filter is linear and the same for every particle, so applied to the stored bulk
hydrodynamic stress of a run in the viscous medium (``samples/stress_hydrodynamic``) it
gives the bulk stress a run in the Maxwell medium stores (``stress_hydrodynamic_maxwell``)
to rounding. It is :class:`sdmpi.dynamics.media.MaxwellFilter`'s step update (exact for a
source linear over each step, S_k = 0 at t = 0) applied to a whole committed series as
the first-order recursive filter it is:

    S_k(t_j) = decay S_k(t_{j-1}) + w_old S_0(t_{j-1}) + w_new S_0(t_j),   S_k(t_0) = 0,

with (decay, w_old, w_new) = ``MaxwellFilter.coefficients()``.

Medium specifications (``--medium SPEC``; :func:`parse_medium`): ``newtonian``;
``maxwell:eta=E,lambda=L`` with modes separated by ``;`` (eta relative to eta_m, the
modes summing to 1; lambda in t_D); or the path of a TOML file holding a ``[medium]``
table as in a job file. The medium is checked as part of the whole job (sdmpi.config).
The manual: docs/reduce.md, "Another medium after the fact".
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np

from ..config import JobError, Medium, Mode, canonical_text, parse_job

#: the forms of a medium specification, for messages
SPEC_FORMS = ('"newtonian", "maxwell:eta=E,lambda=L[;eta=E,lambda=L...]", or a TOML file '
              'with a [medium] table (kind = "maxwell", modes = [{eta = 1.0, lambda = 0.5}])')


class MediumError(ValueError):
    """A medium specification that cannot be used; the message names it and the forms."""


def parse_medium(spec: str) -> Medium:
    """The :class:`sdmpi.config.Medium` of a specification (module docstring); raises
    :class:`MediumError`. Not yet checked against a job (see :func:`view_job`)."""
    text = spec.strip()
    if text.endswith(".toml") or Path(text).is_file():
        return _from_toml(text)
    kind, _, modes = text.partition(":")
    if kind == "newtonian" and not modes:
        return Medium(kind="newtonian", modes=None)
    if kind != "maxwell" or not modes.strip():
        raise MediumError(f"--medium {spec!r}: unknown medium; allowed: {SPEC_FORMS}")
    return Medium(kind="maxwell", modes=tuple(_mode(spec, m) for m in modes.split(";")))


def _mode(spec: str, text: str) -> Mode:
    values = {}
    for item in text.split(","):
        key, eq, value = (x.strip() for x in item.partition("="))
        if not eq or key not in ("eta", "lambda") or key in values:
            raise MediumError(f"--medium {spec!r}: mode {text.strip()!r} must be "
                              f"eta=E,lambda=L (each once); allowed: {SPEC_FORMS}")
        try:
            values[key] = float(value)
        except ValueError:
            raise MediumError(f"--medium {spec!r}: {key} = {value!r} is not a number") from None
        if not (math.isfinite(values[key]) and values[key] > 0):
            raise MediumError(f"--medium {spec!r}: {key} = {value} must be a finite number > 0")
    if len(values) != 2:
        raise MediumError(f"--medium {spec!r}: mode {text.strip()!r} needs both eta and lambda")
    return Mode(eta=values["eta"], lam=values["lambda"])


def _from_toml(path: str) -> Medium:
    try:
        raw = tomllib.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise MediumError(f"--medium {path}: not a readable TOML file ({err})") from None
    table = raw.get("medium")
    if not isinstance(table, dict) or set(raw) != {"medium"}:
        raise MediumError(f"--medium {path}: the file must hold exactly one [medium] table "
                          f"(kind = \"maxwell\", modes = [{{eta = 1.0, lambda = 0.5}}])")
    extra = set(table) - {"kind", "modes"}
    if extra:
        names = ", ".join(f"medium.{k}" for k in sorted(extra))
        raise MediumError(f"--medium {path}: unknown key(s) {names}; allowed: medium.kind, "
                          f"medium.modes")
    kind = table.get("kind")
    if kind == "newtonian" and "modes" not in table:
        return Medium(kind="newtonian", modes=None)
    modes = table.get("modes")
    if kind != "maxwell" or not isinstance(modes, list) or not modes:
        raise MediumError(f"--medium {path}: medium.kind must be \"newtonian\" (no modes) or "
                          f"\"maxwell\" with a non-empty medium.modes list")
    spec = ";".join(",".join(f"{k}={v}" for k, v in m.items()) if isinstance(m, dict)
                    else repr(m) for m in modes)
    return parse_medium(f"maxwell:{spec}")


def label(medium: Medium) -> str:
    """A directory name for a medium: ``newtonian``, ``maxwell_lambda0.5`` for one mode,
    ``maxwell_eta0.7_lambda0.5_eta0.3_lambda0.05`` for several."""
    if medium.kind != "maxwell":
        return medium.kind
    if len(medium.modes) == 1:
        return f"maxwell_lambda{medium.modes[0].lam:g}"
    return "maxwell_" + "_".join(f"eta{m.eta:g}_lambda{m.lam:g}" for m in medium.modes)


def view_job(job, medium: Medium, source: str = "run file"):
    """The job ``job`` with its medium replaced, validated as a whole (sdmpi.config);
    :class:`MediumError` lists the problems."""
    text = canonical_text(dataclasses.replace(job, medium=medium))
    try:
        return parse_job(text, source=f"{source} with --medium")
    except JobError as err:
        raise MediumError(str(err)) from None


def filtered_stress(viscous, medium: Medium, dt: float):
    """The hydrodynamic stress series in ``medium`` from the viscous medium's one,
    ``viscous`` (n, ...) at t_j = j dt from t_0 = 0 (any trailing shape: one component or
    the 6-vectors), by the Maxwell modes' filter (module docstring); a copy for a
    Newtonian medium."""
    viscous = np.asarray(viscous, float)
    if medium.kind != "maxwell" or viscous.shape[0] == 0:
        return viscous.copy()
    from scipy.signal import lfilter

    from ..dynamics.media import MaxwellFilter
    coefficients = MaxwellFilter(tuple(m.eta for m in medium.modes),
                                 tuple(m.lam for m in medium.modes), dt).coefficients()
    out = np.zeros_like(viscous)
    for decay, w_old, w_new in coefficients:
        # initial condition chosen so that the mode's output at t_0 is 0
        out += lfilter([w_new, w_old], [1.0, -decay], viscous, axis=0,
                       zi=-w_new * viscous[:1])[0]
    return out
