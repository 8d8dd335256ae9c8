"""Configurations and the petsc-dense vs dense comparison used by tests/test_petsc_dense.py,
in process (one rank) and as a script under ``mpirun -n P`` (rank 0 prints one JSON line per rank)."""

import hashlib
import json
import sys

import numpy as np

from sdmpi.dynamics.initial import compress, hard_sphere_fluid
from sdmpi.hydro.resistance import grand_resistance
from sdmpi.hydro.solvers import make_solver

STRAIN = 0.3
N = 27


def configuration(phi, seed=1):
    """N hard spheres at volume fraction phi in a sheared periodic box (strain 0.3), with
    spheres 0 and 1 put 1e-3 radii apart (near contact) when phi is dilute."""
    rng = np.random.default_rng(seed)
    pos, side = hard_sphere_fluid(N, min(phi, 0.45), rng, strain=STRAIN)
    if phi > 0.45:
        pos, side = compress(pos, side, phi, rng, strain=STRAIN)
    else:
        pos[1] = pos[0] + np.array([2.001, 0.0, 0.0])
    return pos, side


def compare(phi, comm=None, seed=1):
    """Max relative differences (velocities, stresslets, Brownian forces) between
    petsc-dense on comm and dense, and the smallest gap of the configuration."""
    pos, side = configuration(phi, seed)
    res = grand_resistance(pos, np.ones(N), np.full(3, side), STRAIN)
    dense = make_solver("dense", res)
    petsc = make_solver("petsc-dense", res, comm)
    rng = np.random.default_rng(seed + 100)
    forces, einf, z = rng.standard_normal((N, 6)), rng.standard_normal((N, 5)), rng.standard_normal((N, 6))

    def rel(a, b):
        return float(np.abs(a - b).max() / np.abs(a).max())

    u_d, u_p = dense.velocities(forces, einf), petsc.velocities(forces, einf)
    out = {"phi": phi, "min_gap": float(res.pairs.min_gap),
           "velocities": rel(u_d, u_p),
           "stresslets": rel(dense.stresslets(u_d, einf), petsc.stresslets(u_p, einf)),
           "brownian": rel(dense.brownian_forces(z), petsc.brownian_forces(z))}
    # every rank of comm must hold the same answer
    out["digest"] = hashlib.sha256(np.concatenate([u_p.ravel(), petsc.brownian_forces(z).ravel()]).tobytes()).hexdigest()
    return out


def print_per_rank(rows, comm):
    """Marks whether every rank's rows have the same digests, then prints (rank 0) one
    JSON line of rows per rank."""
    digests = comm.allgather([r.pop("digest") for r in rows])
    for r in rows:
        r["same_on_all_ranks"] = all(d == digests[0] for d in digests)
        r["ranks"] = comm.size
    every = comm.gather(rows)
    if comm.rank == 0:  # one writer: ranks' lines would interleave
        for rank_rows in every:
            print(json.dumps(rank_rows), flush=True)


if __name__ == "__main__":
    from mpi4py import MPI

    print_per_rank([compare(float(phi), MPI.COMM_WORLD) for phi in sys.argv[1:]], MPI.COMM_WORLD)
