"""Reusable work arrays for the large temporaries of the hydrodynamic sums.

A fresh array of a few hundred kB is mapped by the allocator on every call and each of
its pages faults on first touch; at N = 27 that costs as much as the arithmetic that
fills it. `work_array` hands out views of one growing buffer per name and thread: the
caller must be done with a view before asking for the same name again.
`release_free_memory` hands the C heap's free pages back to the system after large
set-ups have gone.
"""

from __future__ import annotations

import ctypes
import threading
from typing import Any

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


class _MallocInfo(ctypes.Structure):
    """glibc's struct mallinfo2 (all size_t)."""

    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                     "fsmblks", "uordblks", "fordblks", "keepcost")]


def _glibc() -> Any:
    """The C library's malloc_trim and mallinfo2 (glibc >= 2.33), or None elsewhere (an
    older glibc, macOS, musl: `release_free_memory` then does nothing)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = _MallocInfo
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
        return libc
    except (OSError, AttributeError):
        return None


_LIBC = _glibc()

#: free bytes in the C heap from which `release_free_memory` hands them back
RELEASE_MIN_BYTES = 64 << 20


def release_free_memory() -> int:
    """Hands the C heap's free pages back to the system (glibc's malloc_trim) when more
    than RELEASE_MIN_BYTES of it are free, and returns how many bytes were free (0 without
    glibc). The allocator keeps what large set-ups free (the lubrication, far-field and
    preconditioner arrays of a solver that has gone) for later allocations, so the
    resident set would otherwise stay at the largest set-up's level while the next one is
    built beside it. Costs ~10-20 ms per 0.4 GB returned, plus the page faults of later
    allocations (a step of petsc-krylov calls it 5-6 times; at N = 1000 the free heap, 35-50
    MiB, stays below the threshold and nothing is handed back).

    Returns:
        The free bytes found in the heap.
    """
    if _LIBC is None:
        return 0
    free = _LIBC.mallinfo2().fordblks
    if free > RELEASE_MIN_BYTES:
        _LIBC.malloc_trim(0)
    return free
