"""Work arrays and the allocator's free memory (sdmpi/hydro/workspace.py)."""

import numpy as np
import pytest

from sdmpi.hydro import workspace


def _resident_mib():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise KeyError("VmRSS")


def test_work_arrays_are_views_of_one_buffer_per_name_and_dtype():
    """A name hands out views of one buffer (grown when a larger shape is asked for), and
    each dtype has its own: a float32 array of a name does not overwrite its float64 one."""
    a = workspace.work_array("test_buffer", (4, 5))
    b = workspace.work_array("test_buffer", (2, 3))
    assert a.dtype == np.float64 and np.shares_memory(a, b)
    a[...] = 1.0
    single = workspace.work_array("test_buffer", (4, 5), np.float32)
    single[...] = 2.0
    assert single.dtype == np.float32 and not np.shares_memory(a, single)
    assert np.all(workspace.work_array("test_buffer", (4, 5)) == 1.0)


@pytest.mark.skipif(workspace._LIBC is None, reason="not glibc: nothing to release")
def test_release_free_memory_hands_the_heap_back():
    """~300 MB freed in blocks below glibc's mmap threshold, between blocks still in use,
    stay in the heap (the resident set does not fall); release_free_memory finds them free
    and hands them back: the resident set falls by most of them (they stay free heap
    space, whose pages the next allocations fault in again)."""
    blocks = [bytearray(100_000) for _ in range(6000)]  # touched: zero-filled
    kept = blocks[1::2]
    del blocks  # every other block freed: holes the heap's top cannot trim
    before = _resident_mib()
    free = workspace.release_free_memory()
    after = _resident_mib()
    assert free > 250 * 2 ** 20
    assert before - after > 200, (before, after)
    assert len(kept) == 3000


def test_release_free_memory_leaves_a_small_heap_alone(monkeypatch):
    """Below RELEASE_MIN_BYTES of free heap (the small jobs, whose steps take milliseconds)
    it only looks: malloc_trim is not called."""
    calls = []

    class Libc:
        def mallinfo2(self):
            return type("Info", (), {"fordblks": free})()

        def malloc_trim(self, pad):
            calls.append(pad)

    monkeypatch.setattr(workspace, "_LIBC", Libc())
    free = workspace.RELEASE_MIN_BYTES - 1
    assert workspace.release_free_memory() == free and calls == []
    free = workspace.RELEASE_MIN_BYTES + 1
    assert workspace.release_free_memory() == free and calls == [0]
