"""Fault injection for the crash tests (inert unless ``SDMPI_TEST_KILL`` is set).

``SDMPI_TEST_KILL=POINT:N`` makes a process SIGKILL itself the N-th time it reaches
``POINT`` (each rank counts for itself). Points, in the order one checkpoint meets them:

``step``     after a time step, before its sample is buffered (mid-interval);
``samples``  after the first sample dataset of a checkpoint is written (mid-write);
``state``    after the checkpoint slot's state is written, before the slot is marked
             valid (mid-checkpoint);
``commit``   after the slot is marked valid and synced, before ``/progress`` moves;
``extend``   (``sdmpi run --extend``) after the longer file is complete, before it
             replaces the run file.
"""

from __future__ import annotations

import os
import signal

POINTS = ("step", "samples", "state", "commit", "extend")

_spec = os.environ.get("SDMPI_TEST_KILL", "")
_point, _, _n = _spec.partition(":")
_left = int(_n) if _spec else 0
if _spec and _point not in POINTS:
    raise ValueError(f"SDMPI_TEST_KILL={_spec!r}: point must be one of {', '.join(POINTS)}")


def fault(point: str) -> None:
    """Kill this process (SIGKILL) if ``point`` is the armed point, reached for the N-th time."""
    global _left
    if point == _point:
        _left -= 1
        if _left == 0:
            os.kill(os.getpid(), signal.SIGKILL)
