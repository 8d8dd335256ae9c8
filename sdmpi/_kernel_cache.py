"""Where numba keeps sdmpi's compiled kernels, and what to do when nowhere is writable.

The kernels are compiled with ``cache=True``: numba stores them in ``NUMBA_CACHE_DIR``
when it is set, else in ``__pycache__`` next to the sources, else in the user's cache
directory (``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``). A read-only installation (a
shared software tree, a container run under another user id, no writable HOME) has none
of these, and numba would refuse to define the kernels at all. Then caching is switched
off for this process: the kernels are compiled in memory (a slower start, every run), and
one notice says so and how to keep them.
"""

from __future__ import annotations

import glob
import os
import sys
import tempfile

PACKAGE = os.path.dirname(os.path.abspath(__file__))
KERNEL_PACKAGES = ("hydro", "dynamics")  # the subpackages with cached numba kernels
RANK_VARS = ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID")


def writable(directory: str) -> bool:
    """Whether a file can be created in ``directory`` (created if missing), tried the
    way numba tries it (permission bits do not tell for root or read-only mounts)."""
    try:
        os.makedirs(directory, exist_ok=True)
        with tempfile.TemporaryFile(dir=directory):
            return True
    except OSError:
        return False


def cache_locations() -> list[list[str]]:
    """The places numba would use, in its order: each a list of directories that must
    all be writable."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return [[os.environ["NUMBA_CACHE_DIR"]]]
    in_tree = [os.path.join(PACKAGE, p, "__pycache__") for p in KERNEL_PACKAGES]
    home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [in_tree, [os.path.join(home, "numba")]]


def ensure_kernels_can_load() -> bool:
    """Switch numba's caching off for this process when no cache location is writable;
    say so once (on the first MPI rank only). Returns True when caching stays on."""
    if any(all(writable(d) for d in dirs) for dirs in cache_locations()):
        return True
    from numba.core.dispatcher import Dispatcher

    Dispatcher.enable_caching = lambda self: None  # keep numba's in-memory NullCache
    if all(os.environ.get(v, "0") == "0" for v in RANK_VARS):
        where = " or ".join(d for dirs in cache_locations() for d in dirs[:1])
        print(f"sdmpi: no writable place for compiled kernels ({where}, ...): compiling "
              "them in memory for this run (a slower start); set NUMBA_CACHE_DIR to a "
              "writable directory to keep them", file=sys.stderr, flush=True)
    return False


def kernels_cached() -> bool:
    """Whether compiled kernels are found where numba will look for them (then a run
    loads them in a second or two instead of compiling them)."""
    for dirs in cache_locations():
        if all(writable(d) for d in dirs):
            top = dirs[0] if len(dirs) == 1 else None
            patterns = ([os.path.join(top, f"{p}_*", "*.nbi") for p in KERNEL_PACKAGES]
                        if top else [os.path.join(d, "*.nbi") for d in dirs])
            return all(glob.glob(pattern) for pattern in patterns)
    return False
