"""The petsc-krylov vs dense comparison used by tests/test_krylov.py, in process (one rank)
and as a script under ``mpirun -n P`` (rank 0 prints one JSON line per rank).

Configurations: those of petsc_check (N = 27, sheared periodic box, near-contact pairs,
phi = 0.1 and 0.5); the far field dense or spectral (the script runs both). Brownian forces: the near-field part is checked exactly through its
covariance (the sum of the pair factors' squares must equal the dense lubrication's FU
block), the far-field part against the dense P (P^T M P)^-1/2 z for one noise vector, P the
Lanczos preconditioner's factor (krylov.LongWaveFactor) as a matrix, checked to give
P^T C P = I for C = D + M_long built here from its definition. And a lone sphere, so that
with two ranks one holds no particle (`lone_sphere`), and a pair factor failing on one
rank only (`failing_pair`)."""

import hashlib
import sys

import numpy as np

from sdmpi.dynamics.drift import unit_pair_forces
from sdmpi.hydro.backend import FORM_ACCURACY
from sdmpi.hydro.farfield import NDOF, far_field_mobility, self_mobility
from sdmpi.hydro.geometry import Lattice
from sdmpi.hydro.krylov import (CALIBRATION_PAIRS, ESTIMATE_ACCURACY, FAR_FIELDS, DenseFarField, LongWaveFactor,
                                long_waves)
from sdmpi.hydro.lubrication import lubrication_matrix, lubrication_sparse
from sdmpi.hydro.resistance import (DEFAULT_EWALD_TOL, DEFAULT_MIN_GAP, grand_resistance, mobility_change,
                                    split_resistance)
from sdmpi.hydro.solvers import make_solver

from .petsc_check import N, STRAIN, configuration, print_per_rank

TOL = 1e-8  # requested relative (preconditioned) residual
#: relative error of the far-field product: rounding (dense), the Ewald tolerance (spectral)
FAR_ERROR = {"dense": 0.0, "spectral": DEFAULT_EWALD_TOL}


def rel(a, b):
    return float(np.abs(a - b).max() / np.abs(a).max())


def rigid_block(matrix, n):
    idx = (NDOF * np.arange(n)[:, None] + np.arange(6)).ravel()
    return matrix[np.ix_(idx, idx)]


def inverse_root(matrix):
    """matrix^-1/2 of a symmetric positive definite matrix (eigendecomposition)."""
    w, v = np.linalg.eigh(matrix)
    return (v / np.sqrt(w)) @ v.T


def long_wave_preconditioner(positions, radii, lattice):
    """C = D + M_long (11N x 11N) of the Lanczos preconditioner, pair by pair from its
    definition: D the self mobilities, M_long,ij = (2/V) sum_k j0(k a_i) j0(k a_j)/k^2
    cos(k.(x_i - x_j)) (I - k k/k^2) on the translational entries."""
    n = len(positions)
    c = np.zeros((n, NDOF, n, NDOF))
    for i in range(n):
        c[i, :, i, :] = self_mobility(radii[i])
    for k in long_waves(lattice):
        k2 = k @ k
        j0 = np.sinc(np.sqrt(k2) * radii / np.pi)
        coupling = 2 / (lattice.volume * k2) * np.outer(j0, j0) * np.cos((positions @ k)[:, None]
                                                                         - (positions @ k)[None, :])
        c[:, :3, :, :3] += coupling[:, None, :, None] * (np.eye(3) - np.outer(k, k) / k2)[None, :, None, :]
    return c.reshape(NDOF * n, NDOF * n)


def compare(phi, comm=None, seed=1, far_field="dense"):
    """Max relative differences between petsc-krylov (far field `far_field`, "dense" or
    "spectral") on comm and dense: velocities and
    stresslets (imposed forces and strain), the near-field covariance, the far-field
    Brownian force; the smallest gap; the iterations; and the preconditioner takeover's
    three differences (`takeover`)."""
    pos, side = configuration(phi, seed)
    box = np.full(3, side)
    res = grand_resistance(pos, np.ones(N), box, STRAIN)
    split = split_resistance(pos, np.ones(N), box, STRAIN, far_field=far_field, comm=comm)
    dense = make_solver("dense", res)
    krylov = make_solver("petsc-krylov", split, comm, TOL)
    rng = np.random.default_rng(seed + 100)
    forces, einf = rng.standard_normal((N, 6)), rng.standard_normal((N, 5))
    u_d, u_k = dense.velocities(forces, einf), krylov.velocities(forces, einf)
    out = {"phi": phi, "far_field": far_field, "min_gap": float(res.pairs.min_gap),
           "velocities": rel(u_d, u_k),
           "stresslets": rel(dense.stresslets(u_d, einf), krylov.stresslets(u_k, einf))}
    # Brownian: near field exactly (covariance), far field on the z_1 part of one noise
    # (every rank's pair factors: those of the pairs touching its spheres, gathered)
    at, pair_i, pair_j, chol = (np.concatenate(krylov.comm.allgather(a)) for a in split.pair_factors)
    at, first = np.unique(at, return_index=True)
    pair_i, pair_j, chol = pair_i[first], pair_j[first], chol[first]
    c = np.einsum("pij,pkj->pik", chol, chol)
    near = np.zeros((N, 6, N, 6))
    for u, pu in enumerate((pair_i, pair_j)):
        for v, pv in enumerate((pair_i, pair_j)):
            np.add.at(near, (pu, slice(None), pv), c[:, 6 * u:6 * u + 6, 6 * v:6 * v + 6])
    lub_fu = rigid_block(lubrication_matrix(res.positions, np.ones(N), res.pairs), N)
    out["near_covariance"] = rel(lub_fu, near.reshape(6 * N, 6 * N))
    # the lubrication of the split resistance (each rank's rows and the factors of the pairs
    # touching them, computed by that rank) is the whole matrix's rows here, no more
    own, _, _, own_chol = lubrication_sparse(split.positions, np.ones(N), split.pairs, factors=True)
    lo, hi = own.indptr[krylov.p0], own.indptr[krylov.p1]
    out["lubrication_shared"] = max(rel(own.data[lo:hi], split.lubrication.data), rel(own_chol, chol),
                                    float(len(at) != len(own_chol)))
    out["lubrication_blocks_held"] = largest_lubrication(split, krylov)
    out["lubrication_blocks_own"] = int(hi - lo)
    z = np.zeros(krylov.noise_shape)
    z[:NDOF * N] = rng.standard_normal(NDOF * N)
    lattice = Lattice(box, STRAIN)
    # the factor on this rank's rows, as the solver has it; P as a matrix, column by column
    factor = LongWaveFactor(res.positions, np.ones(N), lattice, krylov.p0, krylov.p1, comm)
    rows = slice(NDOF * krylov.p0, NDOF * krylov.p1)
    p, p_t = (np.array([krylov._gather(apply(e[rows]), krylov.counts11) for e in np.eye(NDOF * N)]).T
              for apply in (factor.right, factor.left))
    out["long_wave_factor"] = max(rel(p.T, p_t), float(np.abs(
        p.T @ long_wave_preconditioner(res.positions, np.ones(N), lattice) @ p - np.eye(NDOF * N)).max()))
    m = far_field_mobility(res.positions, np.ones(N), plan=res.plan.far)
    far = (p @ inverse_root(p.T @ m @ p) @ z[:NDOF * N]).reshape(N, NDOF)[:, :6]
    f_b = krylov.brownian_forces(z)
    out["brownian_far"] = rel(far, f_b)
    # a random finite difference's first-order change along m (the rfd scheme), from the
    # same forces without strain: krylov's one solve of the change against dense's
    zero = np.zeros((N, 5))
    m_d, m_k = dense.velocities(forces, zero), krylov.velocities(forces, zero)
    moved = res.positions + 1e-6 * m_d[:, :3]
    change_d = mobility_change(res, dense, moved, m_d, DEFAULT_MIN_GAP)
    change_k = krylov.mobility_change(moved, m_k, DEFAULT_MIN_GAP)
    out["change_velocities"], out["change_stresslets"] = (rel(d, k) for d, k in zip(change_d, change_k))
    out["iterations"] = krylov.stats["iterations"]
    out["takeover_g"], out["takeover_u"], out["takeover_again"] = takeover(krylov, split, box, forces,
                                                                           einf, u_k, comm)
    out["lanczos"] = krylov.stats["lanczos"]
    # the relative mobilities of the pairs below a gap of 0.05 (mobility_forms): the
    # closest CALIBRATION_PAIRS asked to FORM_ACCURACY, the others to ESTIMATE_ACCURACY
    # (estimated from the preconditioner where the closest suffice to calibrate it: phi =
    # 0.5; phi = 0.1 has fewer pairs, all solved); the error in units of the accuracy asked
    lub = split.lubricated
    near = np.flatnonzero(lub.gap < 0.05)
    near = near[np.argsort(lub.gap[near])]
    pair_forces = unit_pair_forces(lub.i[near], lub.j[near],
                                   lub.dx[near] / np.linalg.norm(lub.dx[near], axis=1)[:, None], N)
    accuracy = np.full(len(near), ESTIMATE_ACCURACY)
    accuracy[:CALIBRATION_PAIRS] = FORM_ACCURACY
    forms = krylov.mobility_forms(pair_forces, accuracy)
    out["forms"] = float(np.max(np.abs(forms / dense.mobility_forms(pair_forces) - 1) / accuracy))
    out["forms_estimated"] = max(len(near) - CALIBRATION_PAIRS, 0)
    out["digest"] = hashlib.sha256(np.concatenate([u_k.ravel(), f_b.ravel()]).tobytes()).hexdigest()
    return out


def largest_lubrication(*holders):
    """The most 11 x 11 lubrication blocks that one attribute of the holders (a
    SplitResistance, a KrylovSolver) holds: a BSR matrix or an array of such blocks."""
    most = 0
    for holder in holders:
        for value in vars(holder).values():
            data = getattr(value, "data", value)
            if isinstance(data, np.ndarray) and data.ndim == 3 and data.shape[1:] == (NDOF, NDOF):
                most = max(most, len(data))
    return most


def takeover(krylov, split, box, forces, einf, u_k, comm):
    """A solver at a nearby configuration with the same pair sets (the Brownian midpoint)
    takes over krylov's preconditioner factor (take_preconditioner). Returns the max relative
    differences of (1) its G (the whole sequential matrix, on rank 0 alone) from the G a
    solver of that configuration builds itself, (2) its velocities from that solver's (a
    stale factor, not refactorised, gives ~5e-8 here), and (3) krylov's velocities solved
    again afterwards (krylov rebuilds its own factor) from the first ones: all 0 up to
    rounding; the iterations of (2) must be equal too."""
    rng = np.random.default_rng(5)
    mid = split_resistance(split.positions + 1e-3 * rng.standard_normal((N, 3)), np.ones(N), box,
                           STRAIN, plan=split.plan, far_field=split_far_field(split), comm=comm)
    own, taker = (make_solver("petsc-krylov", mid, comm, TOL) for _ in range(2))
    taker.take_preconditioner(krylov)
    assert taker._g_ready and not krylov._g_ready  # taken over
    assert (taker.inner is not None) == (krylov.comm.rank == 0) and krylov.inner is None
    own.take_preconditioner(krylov)  # nothing left to take over
    assert not own._g_ready and own.inner is None
    own._g_keep = taker._g_keep  # the same kept blocks (a pair may cross the gap filter)
    u_own, u_taker = own.velocities(forces, einf), taker.velocities(forces, einf)
    assert own.stats["iterations"] == taker.stats["iterations"]
    g_diff = 0.0
    if own.schur is not None:  # rank 0 holds G
        (ip_o, j_o, v_o), (ip_t, j_t, v_t) = own.schur.getValuesCSR(), taker.schur.getValuesCSR()
        assert np.array_equal(ip_o, ip_t) and np.array_equal(j_o, j_t)
        g_diff = rel(v_o, v_t)
    else:
        assert own.comm.rank > 0 and taker.schur is None
    return g_diff, rel(u_own, u_taker), rel(u_k, krylov.velocities(forces, einf))


def split_far_field(split):
    """The far-field kind of a SplitResistance."""
    return "dense" if isinstance(split.far, DenseFarField) else "spectral"


def lone_sphere(comm=None):
    """One sphere in a sheared periodic box (spectral far field): on comm with more ranks
    than particles some ranks hold none. Max relative differences of its velocities from
    dense and of its Brownian force from the one-rank solver's (the same noise)."""
    pos, box = np.array([[1.0, 2.0, 3.0]]), np.full(3, 6.0)
    forces, einf = np.array([[1.0, -2.0, 0.5, 0.3, 0.0, -0.4]]), np.array([[0.2, 0.0, -0.1, 0.3, 0.1]])
    dense = make_solver("dense", grand_resistance(pos, np.ones(1), box, STRAIN))
    solvers = [make_solver("petsc-krylov", split_resistance(pos, np.ones(1), box, STRAIN, far_field="spectral",
                                                            comm=c), c, TOL) for c in (comm, None)]
    z = np.random.default_rng(3).standard_normal(solvers[0].noise_shape)
    u_k = solvers[0].velocities(forces, einf)
    f_comm, f_self = (s.brownian_forces(z) for s in solvers)
    return {"case": "lone sphere", "velocities": rel(dense.velocities(forces, einf), u_k),
            "brownian": rel(f_self, f_comm),
            "digest": hashlib.sha256(np.concatenate([u_k.ravel(), f_comm.ravel()]).tobytes()).hexdigest()}


def failing_pair(comm):
    """A pair factor that fails on the last rank of comm alone (its lubrication rows
    raise LinAlgError there): split_resistance raises on every rank, with that rank's
    message, instead of leaving the others waiting in a collective."""
    from sdmpi.hydro import resistance

    pos, side = configuration(0.5, 1)
    rows = resistance.lubrication_rows

    def fail_on_last(*args, **kwargs):
        if comm is None or comm.rank == comm.size - 1:
            raise np.linalg.LinAlgError("the pair (0, 1) fails")
        return rows(*args, **kwargs)

    resistance.lubrication_rows = fail_on_last
    try:
        split_resistance(pos, np.ones(N), np.full(3, side), STRAIN, comm=comm)
        message = ""
    except np.linalg.LinAlgError as err:
        message = str(err)
    finally:
        resistance.lubrication_rows = rows
    return {"case": "failing pair", "raised": message == "the pair (0, 1) fails",
            "digest": hashlib.sha256(message.encode()).hexdigest()}


if __name__ == "__main__":
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    print_per_rank([compare(float(phi), comm, far_field=far) for phi in sys.argv[1:] for far in FAR_FIELDS]
                   + [lone_sphere(comm), failing_pair(comm)], comm)
