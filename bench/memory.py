"""Benchmark: resident memory per rank of a realisation on the petsc-krylov backend, part
by part, and the arrays and PETSc objects that hold it.

One realisation (the first task) of a job file, with --set overrides, built and stepped
as ``sdmpi run`` steps it (`Realisation.advance`), on one rank or, under ``mpirun -n P``,
on the P ranks of ``ensemble.ranks_per_task = P``. Every rank records its resident set
(VmRSS) and its peak (VmHWM, reset through /proc/self/clear_refs where the kernel allows
it) around each part:

* the interpreter with sdmpi, numpy, numba, PETSc and h5py loaded;
* the start (`Realisation`: the lattice start and its hard-sphere Monte Carlo);
* --steps steps, and within them the calls of PARTS (entry resident set, peak within the
  call, resident set at its return; a call inside another counts for both).

At the Brownian midpoint's GMRES solve (the start's evaluation and the midpoint's alive)
it sums the bytes of what the live solvers hold (`holdings`): the
spectral far field's real-space pair blocks, pair lists, window stencils, grids; the
lubrication matrix rows and pair factors of the split resistance; the preconditioner's G
pattern, its PETSc BAIJ matrix and incomplete factor (PETSc's count of their values); the
shared work arrays. Prints a JSON row; --out FILE merges it into FILE under --label.

    mpirun -n 2 python bench/memory.py jobs/large_n_krylov.toml --set system.n_particles=4096 \\
        --set 'shear.protocol="none"' --set integration.n_steps=4 --set integration.discard_steps=0 \\
        --set ensemble.realisations=1 --steps 2 --label n4096_rest --out bench/memory.json
"""

import resource

import h5py  # noqa: F401  (loaded as by sdmpi run: part of the baseline)
import sdmpi  # noqa: F401  (before numpy: it chooses OpenBLAS's kernels as `sdmpi run` does)
import numpy as np
from mpi4py import MPI

from workers import job_benchmark  # bench/ is on sys.path when run as a script

from sdmpi.config import enumerate_tasks
from sdmpi.dynamics import Realisation, drift
from sdmpi.dynamics.checks import load_job
from sdmpi.hydro import krylov, resistance, solvers, spectral, workspace

GIB = 2.0 ** 30

#: part -> the (owner, method) calls it owns
PARTS = {
    "split resistance (pairs, lubrication, far-field operator)": (solvers, "split_resistance"),
    "lubrication rows and pair factors (each rank its own)": (resistance, "_rank_lubrication"),
    "far-field operator (real-space blocks, stencils, grids)": (krylov, "far_field_operator"),
    "solver set-up (L_uu, G blocks)": (krylov.KrylovSolver, "__init__"),
    "preconditioner's incomplete factor": (krylov.KrylovSolver, "schur_solver"),
    "Brownian far-field forces (Lanczos)": (krylov.KrylovSolver, "brownian_forces"),
    "GMRES solves": (krylov.KrylovSolver, "velocities"),
    "collision relative mobilities": (krylov.KrylovSolver, "mobility_forms"),
    "midpoint (its set-up and solves)": (drift.Midpoint, "brownian"),
}


def _status(key):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(key):
                return int(line.split()[1]) * 1024 / GIB
    raise KeyError(key)


def rss():
    """Resident set now (GiB)."""
    return _status("VmRSS:")


class Peaks:
    """Entry resident set, peak and return resident set (GiB) of wrapped calls, the
    largest over all their calls; nested calls fold their peaks into the open ones."""

    def __init__(self):
        self.resettable = self._reset()
        self.open, self.parts = [], {}

    @staticmethod
    def _reset():
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")  # resets VmHWM to the current resident set
            return True
        except OSError:
            return False

    def _fold(self):
        peak = _status("VmHWM:")
        for frame in self.open:
            frame["peak_gib"] = max(frame["peak_gib"], peak)

    def enter(self, part):
        self._fold()
        self._reset()
        now = rss()
        path = [*self.open[-1]["path"][1:], part] if self.open else [part]  # below the outermost
        self.open.append({"path": [*self.open[-1]["path"], part] if self.open else [part],
                          "part": " > ".join(path), "entry_gib": now, "peak_gib": now})

    def leave(self):
        self._fold()
        frame = self.open.pop()
        frame["return_gib"] = rss()
        best = self.parts.get(frame["part"])
        if best is None or frame["peak_gib"] - frame["entry_gib"] > best["peak_gib"] - best["entry_gib"]:
            self.parts[frame["part"]] = {k: v for k, v in frame.items() if k.endswith("_gib")}

    def wrap(self, part, function):
        def call(*args, **kwargs):
            self.enter(part)
            try:
                return function(*args, **kwargs)
            finally:
                self.leave()
        return call

    def install(self, parts=PARTS):
        for part, (owner, name) in parts.items():
            setattr(owner, name, self.wrap(part, getattr(owner, name)))


def _nbytes(*arrays):
    return sum(a.nbytes for a in arrays if isinstance(a, np.ndarray))


def _petsc_bytes(mat):
    """Bytes of this rank's part of a PETSc BAIJ matrix or factor: its allocated values
    (MatGetInfo, local) at 8 bytes and one 4-byte column index per block."""
    if mat is None:
        return 0.0
    info = mat.getInfo(mat.InfoType.LOCAL)
    return info["nz_allocated"] * (8.0 + 4.0 / info["block_size"])


def holdings(solver):
    """Bytes held by one KrylovSolver on this rank, by object."""
    far = solver.far
    out = {}
    if isinstance(far, spectral.SpectralFarField):
        st = far._stencils
        out["far field: real-space pair blocks"] = _nbytes(far._blocks)   # None while released
        out["far field: real-space pair indices, image indices and positions"] = _nbytes(
            far._pi, far._pj, far._images, far._positions)
        out["far field: window stencils"] = _nbytes(*st.arrays())
        out["far field: k-space kernel"] = _nbytes(getattr(far, "_scale", None))
    else:
        out["far field: dense matrix"] = _nbytes(far.matrix)
    lub = solver._lub  # None while released (`KrylovSolver.forces_drawn`; the property would compute it again)
    out["lubrication matrix (11x11 blocks, this rank's rows)"] = (0 if lub is None else
                                                                  _nbytes(lub.data, lub.indices, lub.indptr))
    if solver.lubricated is not None:
        out["lubrication pair list"] = _nbytes(*vars(solver.lubricated).values())
    out["lubrication pair factors (12x12, pairs touching this rank's rows)"] = _nbytes(*(solver.pair_factors or ()))
    out["L_uu (PETSc BAIJ)"] = _petsc_bytes(solver.l_uu)
    out["G pattern (this rank's rows), D^-1"] = _nbytes(solver._g_keep, solver._g_pattern[2], solver.d_inv)
    out["G (PETSc BAIJ, sequential)"] = _petsc_bytes(solver.schur)
    factor = None
    if solver.inner is not None:
        factor = solver.inner.getPC().getFactorMatrix()
    out["G's incomplete factor (PETSc)"] = _petsc_bytes(factor)
    return out


def measure(job_path, overrides, steps):
    """The row of one realisation: resident memory per part and holdings per rank."""
    comm = MPI.COMM_WORLD
    job = load_job(job_path, overrides)
    peaks = Peaks()
    baseline = rss()
    snapshots = []

    velocities = krylov.KrylovSolver.velocities

    def snapshot(self, *args, **kwargs):
        # the midpoint's solve: two evaluations alive (the step's start and the midpoint)
        if len(krylov._LIVE) >= 2 and not snapshots:
            snapshots.append([holdings(s) for s in list(krylov._LIVE)])
        return velocities(self, *args, **kwargs)

    krylov.KrylovSolver.velocities = snapshot
    peaks.install()
    peaks.enter("start (lattice, Monte Carlo, model)")
    real = Realisation(job, enumerate_tasks(job)[0], comm if comm.size > 1 else None)
    peaks.leave()
    peaks.enter(f"{steps} steps")
    real.advance(steps)
    peaks.leave()
    held = {"work arrays (spectral grids, lubrication chunks)": _nbytes(*vars(workspace._LOCAL).values()) / GIB}
    for owner in snapshots[0] if snapshots else []:
        for key, value in owner.items():
            held[key] = held.get(key, 0.0) + value / GIB
    rows = comm.allgather({"baseline_gib": baseline, "parts": peaks.parts, "held_gib": held,
                           "solvers_at_snapshot": len(snapshots[0]) if snapshots else 0,
                           "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20})
    return {"job": job_path, "overrides": overrides, "ranks": comm.size, "n": job.system.n_particles,
            "steps": steps, "hwm_resettable": peaks.resettable, "per_rank": rows,
            "peak_rss_gib_per_rank": [r["peak_rss_gib"] for r in rows]}


if __name__ == "__main__":
    job_benchmark(__doc__, measure, dict(type=int, default=2))
