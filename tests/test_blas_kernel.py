"""OpenBLAS's kernel choice (`sdmpi._blas_kernel`): from the CPU's flags, never over the
user's, never after numpy is loaded, and recorded as the loaded library reports it."""

import os
import subprocess
import sys

from sdmpi._blas_kernel import choose_openblas_kernel, cpu_flags, kernel_for, openblas_kernel

AVX512 = "fpu sse2 avx avx2 fma avx512f avx512cd avx512bw avx512dq avx512vl"


def _cpuinfo(tmp_path, flags):
    path = tmp_path / "cpuinfo"
    path.write_text(f"processor\t: 0\nmodel name\t: Intel(R) Xeon(R) Processor\nflags\t\t: {flags}\n")
    return str(path)


def test_kernel_from_the_instruction_sets():
    assert kernel_for(frozenset(AVX512.split())) == "SkylakeX"
    assert kernel_for(frozenset("sse2 avx avx2 fma avx512f".split())) == "Haswell"  # AVX-512 F alone
    assert kernel_for(frozenset("sse2 avx avx2".split())) is None  # no FMA
    assert kernel_for(frozenset()) is None


def test_flags_read_from_cpuinfo(tmp_path):
    assert cpu_flags(_cpuinfo(tmp_path, AVX512)) == frozenset(AVX512.split())
    assert cpu_flags(str(tmp_path / "missing")) == frozenset()


def test_the_users_choice_stands(tmp_path):
    environ = {"OPENBLAS_CORETYPE": "Prescott"}
    assert choose_openblas_kernel(environ, _cpuinfo(tmp_path, AVX512)) == "Prescott"
    assert environ == {"OPENBLAS_CORETYPE": "Prescott"}


def test_nothing_set_once_numpy_is_loaded(tmp_path):
    assert "numpy" in sys.modules  # the test session has loaded it
    environ = {}
    assert choose_openblas_kernel(environ, _cpuinfo(tmp_path, AVX512)) is None
    assert environ == {}


def test_a_fresh_process_loads_the_chosen_kernels():
    """In a fresh process ``import sdmpi`` chooses before numpy loads OpenBLAS, and the
    loaded library reports the choice (where numpy's BLAS is OpenBLAS and the CPU has AVX2
    or better)."""
    code = ("import os; os.environ.pop('OPENBLAS_CORETYPE', None); import sdmpi; "
            "chosen = os.environ.get('OPENBLAS_CORETYPE'); import numpy, scipy.linalg; "
            "from sdmpi._blas_kernel import openblas_kernel; print(chosen, openblas_kernel(), sep='|')")
    chosen, loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                                    check=True).stdout.strip().split("|")
    assert chosen == str(kernel_for(cpu_flags()))
    if loaded != "not OpenBLAS" and chosen != "None":
        assert loaded == chosen


def test_this_process_runs_the_kernels_it_records():
    """tests/conftest.py chose before numpy was loaded, as `sdmpi run` does."""
    loaded = openblas_kernel()
    if loaded != "not OpenBLAS" and os.environ.get("OPENBLAS_CORETYPE"):
        assert loaded == os.environ["OPENBLAS_CORETYPE"]
