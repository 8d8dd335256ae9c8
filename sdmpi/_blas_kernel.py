"""Which compute kernels OpenBLAS uses, and a better choice where it cannot tell.

OpenBLAS built for many CPUs (``DYNAMIC_ARCH``: Debian's package, the wheels on PyPI) picks
its kernels when it is loaded, from the CPU's identity. A virtual machine that reports a
generic Intel model is not recognised, and OpenBLAS falls back to its oldest x86-64 kernels
("Prescott", SSE3): on such a machine a dense product or Cholesky factorisation runs 2-5
times slower than with the kernels the CPU supports (measured: docs/performance.md, "BLAS
kernels"). The choice can be made by the variable ``OPENBLAS_CORETYPE``, read once when
the library is loaded. ``choose_openblas_kernel`` sets it from the CPU's instruction sets
(``/proc/cpuinfo`` flags) unless the user set it: "SkylakeX" where AVX-512 (F, CD, BW, DQ,
VL) is present, "Haswell" where AVX2 and FMA are, nothing otherwise. The double-precision
kernels of newer CPU types are those two, so a CPU OpenBLAS recognises loses nothing.

Kernels differ in the order of floating-point operations, so the last bits of a run's
numbers depend on them: the run file records the kernel with the library versions
(`openblas_kernel`). ``OPENBLAS_CORETYPE=Prescott`` reproduces a run made with the
generic kernels.
"""

from __future__ import annotations

import ctypes
import os
import sys

#: OpenBLAS core type -> the CPU flags its kernels need, best first
KERNELS = (
    ("SkylakeX", frozenset({"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"})),
    ("Haswell", frozenset({"avx2", "fma"})),
)


def cpu_flags(cpuinfo: str = "/proc/cpuinfo") -> frozenset[str]:
    """The instruction-set flags of the first CPU in ``cpuinfo`` (empty where there is no
    such file, e.g. not Linux)."""
    try:
        with open(cpuinfo) as info:
            for line in info:
                if line.startswith("flags"):
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return frozenset()


def kernel_for(flags: frozenset[str]) -> str | None:
    """The OpenBLAS core type for a CPU with these flags (`KERNELS`), None if none fits."""
    return next((name for name, needs in KERNELS if needs <= flags), None)


def choose_openblas_kernel(environ=os.environ, cpuinfo: str = "/proc/cpuinfo") -> str | None:
    """Set ``OPENBLAS_CORETYPE`` in ``environ`` from the CPU's flags unless it is set, and
    only while numpy (and so OpenBLAS) is not loaded yet: the variable is read once, when
    the library is loaded. Returns the value in force afterwards, None if none."""
    if environ.get("OPENBLAS_CORETYPE"):
        return environ["OPENBLAS_CORETYPE"]
    if "numpy" in sys.modules:
        return None
    kernel = kernel_for(cpu_flags(cpuinfo))
    if kernel is not None:
        environ["OPENBLAS_CORETYPE"] = kernel
    return kernel


def openblas_kernel(maps: str = "/proc/self/maps") -> str:
    """The kernels of the OpenBLAS this process has loaded (its ``openblas_get_corename``;
    the 64-bit-integer builds of PyPI's wheels carry a suffix), or "not OpenBLAS" where no
    OpenBLAS is loaded or it cannot be asked (not Linux)."""
    try:
        with open(maps) as lines:
            paths = sorted({line.split()[-1] for line in lines
                            if "openblas" in line.rsplit("/", 1)[-1].lower()})
    except OSError:
        return "not OpenBLAS"
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("openblas_get_corename", "openblas_get_corename64_", "scipy_openblas_get_corename64_"):
            function = getattr(lib, name, None)
            if function is not None:
                function.restype = ctypes.c_char_p
                return function().decode()
    return "not OpenBLAS"
