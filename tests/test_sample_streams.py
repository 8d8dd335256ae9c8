"""Reference sample streams: one task of every example job in jobs/ (shrunk to a few
tens of steps at small N), and variants for the options no example job selects, stepped
and compared bit for bit with the SHA-256 digests stored in
tests/data/sample_streams.json. The guard for changes meant to leave every stream as it
is (refactoring, speed-ups): a single changed bit of any sample fails it.

The digests belong to one floating-point stack (numpy and its BLAS, one BLAS thread, the
CPU's kernels); the file records the one they were made on. On that stack a single changed
bit fails; on another one (other BLAS kernels, library versions or CPU) the bits cannot
agree, and a case is skipped when its summarised values agree with the references' to
rounding (`OTHER_STACK_RTOL`) and fails when they differ beyond it.

Each case starts from the state of a fresh process, as the first task of `sdmpi run` on a
rank does: the lubrication tables of `sdmpi.hydro.lubrication` are emptied first. The
last bits of a stream depend on the tables that earlier realisations in the same process
built (a size ratio with fewer than 16 pairs in a call takes the exact path until some
call has built its table), so without that the streams would depend on the order of the
cases.

Regenerate the references only when a change is meant to alter the streams (a defect
fixed, new physics), from the commit that makes that change, and say so in its message:

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 \\
        python -m tests.test_sample_streams --write     # from the repository's top directory
"""

import ast
import hashlib
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np
import pytest

from sdmpi._blas_kernel import openblas_kernel

from .runs import fresh_lubrication_tables

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = ROOT / "tests" / "data" / "sample_streams.json"
STEPS = 24

#: case -> (job file in jobs/, --set overrides, task index). N shrunk so that every case
#: steps in about a second at most once the kernels are compiled; tasks and time steps
#: chosen so that the streams include collisions (demo_midpoint, demo_far_field,
#: boehmite_epoxy, schaink2000_collisions), frictional contacts, sliding included (task 13
#: of the frictional jobs: phi = 0.56), and the last task of a job (its seed's spawn key)
CASES = {
    "demo": ("demo.toml", [], -1),
    "demo_midpoint": ("demo.toml", ['brownian.scheme="midpoint"'], 0),
    "demo_rfd_split": ("demo.toml", ['brownian.scheme="rfd-split"'], 0),
    "demo_far_field": ("demo.toml", ['hydrodynamics.model="far-field"',
                                     "integration.steps_per_period=40"], 0),
    "demo_per_particle": ("demo.toml", ["output.per_particle=true"], 0),
    "bidisperse_demo": ("bidisperse_demo.toml", ["system.n_particles=8"], 0),
    "boehmite_epoxy": ("boehmite_epoxy.toml", [], 0),
    "dilute_free_draining": ("dilute_free_draining.toml", ["system.n_particles=8"], 0),
    "frictional_mu0.1": ("frictional_mu0.1.toml", [], 13),
    "frictional_mu0.3": ("frictional_mu0.3.toml", [], 13),
    "frictional_mu0.5": ("frictional_mu0.5.toml", [], 13),
    "large_n_krylov": ("large_n_krylov.toml", ["system.n_particles=8", "ensemble.ranks_per_task=1"], 0),
    "large_n_krylov_rfd": ("large_n_krylov.toml", ["system.n_particles=8", "ensemble.ranks_per_task=1",
                                                   'brownian.scheme="rfd"'], 0),
    "dratler1996_hydro": ("dratler1996_hydro.toml", ["system.n_particles=9"], 0),
    "dratler1996_repulsion": ("dratler1996_repulsion.toml", ["system.n_particles=9"], 0),
    "dratler1996_sensitivity": ("dratler1996_sensitivity.toml", ["system.n_particles=9"], 0),
    "dratler1996_size": ("dratler1996_size.toml", ["system.n_particles=9"], 0),
    "monolayer_hydro": ("monolayer_hydro.toml", ["system.n_particles=9"], 0),
    "monolayer_repulsion": ("monolayer_repulsion.toml", ["system.n_particles=9"], 0),
    "schaink2000_fixed_dt": ("schaink2000_fixed_dt.toml", ["system.n_particles=8"], 0),
    "schaink2000_frequency_scan": ("schaink2000_frequency_scan.toml", ["system.n_particles=8"], -1),
    "finite_size_n27": ("finite_size_n27.toml", ["system.n_particles=8"], 0),
    "finite_size_n64": ("finite_size_n64.toml", ["system.n_particles=8"], -1),
    "finite_size_n125": ("finite_size_n125.toml", ["system.n_particles=8"], 0),
    "finite_size_n343": ("finite_size_n343.toml", ["system.n_particles=8"], -1),
    "finite_size_dt_control": ("finite_size_dt_control.toml", ["system.n_particles=8"], 0),
    "schaink2000_maxwell": ("schaink2000_maxwell.toml", ["system.n_particles=8"], 0),
    "schaink2000_newtonian": ("schaink2000_newtonian.toml", ["system.n_particles=8"], 0),
    "schaink2000_collisions": ("schaink2000_newtonian.toml", [
        "system.n_particles=8", "integration.steps_per_period=20", "integration.dt_max=0.01"], 0),
    "schaink2000_phi_scan": ("schaink2000_phi_scan.toml", ["system.n_particles=8"], -1),
    "steady_brownian": ("steady_brownian.toml", ["system.n_particles=8"], 0),
    "steady_repulsion": ("steady_repulsion.toml", ["system.n_particles=8"], 0),
}
#: the cases whose backend needs petsc4py
PETSC_CASES = {"large_n_krylov", "large_n_krylov_rfd"}


def _le_bytes(array):
    """The bytes of an array in little-endian order (platform-independent digests)."""
    array = np.ascontiguousarray(array)
    return array.astype(array.dtype.newbyteorder("<"), copy=False).tobytes()


def stream(case):
    """The case's sample stream and final positions, summarised: {"samples": {dataset:
    SHA-256}, "positions": SHA-256, "values": {label: repr(float)}}."""
    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation

    fresh_lubrication_tables()

    job_file, overrides, index = CASES[case]
    job = load_job(ROOT / "jobs" / job_file, overrides)
    real = Realisation(job, enumerate_tasks(job)[index])
    samples = real.advance(STEPS)
    values = {f"{k}[-1, xy]": repr(float(v[-1, 3])) for k, v in samples.items()
              if k.startswith("stress_")}
    values["positions[0]"] = repr([float(x) for x in real.positions[0]])
    return {"samples": {k: hashlib.sha256(_le_bytes(v)).hexdigest() for k, v in sorted(samples.items())},
            "positions": hashlib.sha256(_le_bytes(real.positions)).hexdigest(),
            "values": values}


def _stack():
    """The floating-point stack the digests were made on: versions, the BLAS and LAPACK
    libraries loaded (Linux) and OpenBLAS's kernels, the CPU."""
    import numba
    import scipy
    import scipy.linalg  # noqa: F401  (loads LAPACK)
    try:
        with open("/proc/self/maps") as maps:
            libs = sorted({Path(line.split()[-1]).name for line in maps
                           if "/" in line and any(w in line.split()[-1].rsplit("/", 1)[-1]
                                                  for w in ("blas", "lapack", "mkl"))})
    except OSError:
        libs = []
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as info:
            cpu = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), cpu)
    except OSError:
        pass
    return {"numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
            "blas": [lib for lib in libs if not lib.startswith("_") and "cython" not in lib],
            "blas kernels": openblas_kernel(), "machine": platform.machine(), "cpu": cpu,
            "python": platform.python_version()}


def _reference():
    return json.loads(REFERENCE.read_text())


@pytest.fixture(scope="module")
def reference():
    return _reference()


def test_every_example_job_has_a_case():
    """A new example job gets a reference stream (add it to CASES, then --write)."""
    covered = {job for job, _, _ in CASES.values()}
    assert {p.name for p in (ROOT / "jobs").glob("*.toml")} == covered


def test_references_cover_the_cases(reference):
    assert set(reference["cases"]) == set(CASES)
    for case, (job_file, overrides, index) in CASES.items():
        assert reference["cases"][case]["definition"] == [job_file, overrides, index, STEPS], case


@pytest.mark.parametrize("case", sorted(CASES))
def test_sample_stream_unchanged(case, reference):
    assert os.environ.get("OPENBLAS_NUM_THREADS") == "1", "the references need one BLAS thread"
    if case in PETSC_CASES:
        from sdmpi.hydro.petsc_dense import PetscUnavailable, load_petsc
        try:
            load_petsc()
        except PetscUnavailable as err:
            pytest.skip(f"petsc4py not available: {err}")
    ref = reference["cases"][case]
    got = stream(case)
    changed = [k for k in sorted(set(ref["samples"]) | set(got["samples"]))
               if ref["samples"].get(k) != got["samples"].get(k)]
    if got["positions"] != ref["positions"]:
        changed.append("final positions")
    if not changed:
        return
    values = "\n".join(f"  {k}: reference {ref['values'].get(k)}, now {v}"
                       for k, v in got["values"].items())
    if not _same_stack(_stack(), reference["stack"]) and _agree_to_rounding(ref["values"], got["values"]):
        pytest.skip(f"{case}: another floating-point stack than the references' ({_stack()}); "
                    f"the stream agrees with them to {OTHER_STACK_RTOL} relative, not bit for bit")
    pytest.fail(f"{case}: the sample stream changed ({', '.join(changed)}); made on "
                f"{reference['stack']}, now {_stack()}\n{values}")


#: how far the summarised values may move on another floating-point stack (other BLAS
#: kernels or versions reorder operations): 24 steps of the example jobs amplify rounding to
#: at most 1.3e-8 relative (generic against AVX-512 OpenBLAS kernels), a defect or a change
#: of the physics moves them by 1e-4 or more
OTHER_STACK_RTOL = 1e-6


def _same_stack(stack, other):
    """Whether two `_stack` records name the same floating-point stack. ScaLAPACK, which
    only the PETSc cases load, is left out of the libraries: whether it is loaded yet
    depends on the order of the cases, not on the stack."""
    def key(record):
        return {**record, "blas": [lib for lib in record.get("blas", []) if "scalapack" not in lib]}
    return key(stack) == key(other)


def _agree_to_rounding(reference_values, values):
    """Whether every summarised value agrees with the reference's to OTHER_STACK_RTOL of
    its own scale."""
    if set(reference_values) != set(values):
        return False
    for key, text in values.items():
        got, ref = np.atleast_1d(ast.literal_eval(text)), np.atleast_1d(ast.literal_eval(reference_values[key]))
        if not np.allclose(got, ref, rtol=OTHER_STACK_RTOL, atol=OTHER_STACK_RTOL * np.max(np.abs(ref))):
            return False
    return True


def test_rounding_agreement_tells_rounding_from_change():
    ref = {"stress[-1, xy]": "0.12462060674643835", "positions[0]": "[0.41, 3.44, 3.31]"}
    rounded = {"stress[-1, xy]": "0.12462060674643901", "positions[0]": "[0.41, 3.4400000001, 3.31]"}
    assert _agree_to_rounding(ref, rounded)
    assert not _agree_to_rounding(ref, {**rounded, "stress[-1, xy]": "0.1246306"})
    assert not _agree_to_rounding(ref, {**rounded, "positions[0]": "[0.41, 3.4401, 3.31]"})
    assert not _agree_to_rounding(ref, {"stress[-1, xy]": ref["stress[-1, xy]"]})


def test_the_references_stack_is_recognised_whatever_the_case_order(reference):
    """On the references' own stack every changed bit fails, also before a PETSc case has
    loaded ScaLAPACK (which the references' record lists)."""
    stack = reference["stack"]
    without = {**stack, "blas": [lib for lib in stack["blas"] if "scalapack" not in lib]}
    assert _same_stack(without, stack)
    assert not _same_stack({**stack, "blas kernels": "Prescott" if stack.get("blas kernels") != "Prescott"
                            else "Haswell"}, stack)


def write():
    """Recompute every case and rewrite tests/data/sample_streams.json."""
    cases = {}
    for case, (job_file, overrides, index) in CASES.items():
        cases[case] = {"definition": [job_file, overrides, index, STEPS], **stream(case)}
        print(case, file=sys.stderr)
    REFERENCE.write_text(json.dumps({"stack": _stack(), "cases": cases}, indent=1) + "\n")


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit(__doc__)
    if any(os.environ.get(v) != "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")):
        sys.exit("set OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 first")
    write()
