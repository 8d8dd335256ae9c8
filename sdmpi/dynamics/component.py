"""What every component of a realisation (a force, a geometry, a stress recorder) shares:
its own state, saved with every checkpoint and restored on resume, and the shapes of its
sample and state fields."""

from __future__ import annotations

from typing import Protocol

import numpy as np

#: name -> (shape per sample, dtype, unit, description) of sample fields
SampleFields = dict[str, tuple[tuple[int, ...], str, str, str]]
#: name -> (shape, dtype) of state fields
StateFields = dict[str, tuple[tuple[int, ...], str]]


class Stateful(Protocol):
    """A component's state as named arrays of fixed shape (names unique within a realisation)."""

    def state_fields(self) -> StateFields:
        """name -> (shape, dtype) of its state (empty: none)."""
        raise NotImplementedError

    def get_state(self) -> dict[str, np.ndarray]:
        """Its state as arrays (copies), those of state_fields."""
        raise NotImplementedError

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore its state from get_state (extra names ignored)."""
        raise NotImplementedError


class NoState(Stateful):
    """A component without state."""

    def state_fields(self) -> StateFields:
        return {}

    def get_state(self) -> dict[str, np.ndarray]:
        return {}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        pass
