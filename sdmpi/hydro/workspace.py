"""Reusable work arrays for the large temporaries of the hydrodynamic sums.

A fresh array of a few hundred kB is mapped by the allocator on every call and each of
its pages faults on first touch; at N = 27 that costs as much as the arithmetic that
fills it. `work_array` hands out views of one growing buffer per name and thread: the
caller must be done with a view before asking for the same name again.
"""

from __future__ import annotations

import threading

import numpy as np

_LOCAL = threading.local()


def work_array(name: str, shape: tuple[int, ...], dtype: type = np.float64) -> np.ndarray:
    """An uninitialised C-contiguous array of `shape` and `dtype`, a view of this thread's
    buffer `name` of that dtype (valid until the next call with that name and dtype).

    Args:
        name: key of the per-thread buffer.
        shape: shape of the array wanted.
        dtype: its element type (each dtype its own buffer).

    Returns:
        Uninitialised array of `shape` (a view into the buffer `name`).
    """
    size = 1
    for s in shape:
        size *= s
    buffers = _LOCAL.__dict__
    key = (name, np.dtype(dtype).str)
    buf = buffers.get(key)
    if buf is None or buf.size < size:
        buf = buffers[key] = np.empty(size, dtype=dtype)
    return buf[:size].reshape(shape)
