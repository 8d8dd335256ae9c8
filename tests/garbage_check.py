"""PETSc objects left behind by the parallel backends, used by tests/test_petsc_dense.py as a
script under ``mpirun -n P`` (rank 0 prints one JSON line per rank).

A run builds new solvers every step and drops the old ones. On a communicator of several
ranks petsc4py defers the (collective) destroy of an object whose Python wrapper is
collected to ``PETSc.garbage_cleanup``, so without it every dropped solver's matrices and
every solve's work vectors would stay allocated for the whole run. For each backend this
builds a solver three times at the configuration of petsc_check, with velocities,
stresslets and Brownian forces each time, drops it, builds a fourth, and counts the
objects PETSc still holds as garbage on the communicator (PETSc.garbage_view, whose table
is printed by C code: read back from file descriptor 1)."""

import ctypes
import hashlib
import os
import re
import sys
import tempfile

import numpy as np

from sdmpi.hydro.petsc_dense import load_petsc
from sdmpi.hydro.resistance import grand_resistance, split_resistance
from sdmpi.hydro.solvers import make_solver

from .petsc_check import N, STRAIN, configuration, print_per_rank


def garbage_entries(PETSc, comm):
    """The number of objects in PETSc's garbage on comm, on each rank (rank 0: the list;
    the others: None). Collective."""
    sys.stdout.flush()
    saved = os.dup(1)
    with tempfile.TemporaryFile(mode="w+") as table:
        os.dup2(table.fileno(), 1)
        try:
            PETSc.garbage_view(comm)
            ctypes.CDLL(None).fflush(None)
        finally:
            os.dup2(saved, 1)
            os.close(saved)
        table.seek(0)
        text = table.read()
    return [int(n) for n in re.findall(r"Total entries:\s*(\d+)", text)] if comm.rank == 0 else None


def solver(backend, pos, side, comm):
    if backend == "petsc-dense":
        return make_solver(backend, grand_resistance(pos, np.ones(N), np.full(3, side), STRAIN), comm)
    split = split_resistance(pos, np.ones(N), np.full(3, side), STRAIN, far_field="spectral", comm=comm)
    return make_solver(backend, split, comm, tolerance=1e-8)


def left_behind(backend, comm):
    PETSc = load_petsc()
    pos, side = configuration(0.5)
    rng = np.random.default_rng(3)
    for _ in range(3):
        s = solver(backend, pos, side, comm)
        forces, einf = rng.standard_normal((N, 6)), rng.standard_normal((N, 5))
        u = s.velocities(forces, einf)
        s.stresslets(u, einf)
        s.brownian_forces(rng.standard_normal(s.noise_shape))
        del s
    last = solver(backend, pos, side, comm)  # its build frees what the three dropped left
    entries = comm.bcast(garbage_entries(PETSc, comm), root=0)
    del last  # (held through the count: its own objects are not garbage yet)
    return {"backend": backend, "entries": entries,
            "digest": hashlib.sha256(np.asarray(entries).tobytes()).hexdigest()}


if __name__ == "__main__":
    from mpi4py import MPI

    print_per_rank([left_behind(b, MPI.COMM_WORLD) for b in sys.argv[1:]], MPI.COMM_WORLD)
