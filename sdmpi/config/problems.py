"""What is wrong with a job: :class:`Problem` (one mistake, with its key, value and what is
allowed) and :class:`JobError` (every problem of a job at once)."""

from __future__ import annotations

from dataclasses import dataclass

from .canonical import toml_literal

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
