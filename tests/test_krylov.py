"""The petsc-krylov backend (matrix-free mixed form, sparse lubrication, Lanczos Brownian
forces) against dense: solves and Brownian terms on one rank and under mpirun -n 2, the
midpoint drift and Brownian stress, a realisation with ranks_per_task = 2 against one
rank, the `auto` choice and the sparse lubrication assembly."""

import subprocess
import sys

import numpy as np
import pytest

from sdmpi.hydro import solve_mobility
from sdmpi.hydro.petsc_dense import PetscUnavailable, load_petsc

try:
    load_petsc()
except PetscUnavailable as err:
    pytest.skip(f"petsc4py not available: {err}", allow_module_level=True)

from .krylov_check import FAR_ERROR, TOL, compare  # noqa: E402
from .runs import child_env  # noqa: E402
from .test_petsc_dense import (MPIRUN, ROOT, SHORT, _run, assert_isolated_sphere, assert_same_stream,  # noqa: E402
                              mobility_problem, needs_mpi, rows_on_two_ranks)

from sdmpi.dynamics.models import ResistanceModel  # noqa: E402
from sdmpi.hydro.krylov import lanczos_inverse_sqrt  # noqa: E402
from sdmpi.hydro.lubrication import close_pairs, lubrication_matrix, lubrication_sparse  # noqa: E402
from sdmpi.hydro.resistance import grand_resistance, split_resistance  # noqa: E402
from sdmpi.hydro.solvers import make_solver, resolve_backend  # noqa: E402

# Agreement with dense: the solves stop at a relative preconditioned residual TOL = 1e-8,
# which bounds the relative error of the solution up to the preconditioner's quality
# (measured 1-10 x TOL at phi = 0.1 and 0.5 with near-contact pairs); 100 x TOL allows
# for that factor and still fails for any error in the equations (those give O(1e-3..1)).
# The spectral far field is accurate to its Ewald tolerance (1e-6; measured errors of the
# solves 1e-7..1e-6): 10 x that.
AGREE = 100 * TOL
# the near-field covariance is a sum of exact pair factors: rounding only
EXACT = 1e-12
# a random finite difference's change (`mobility_change`, along 1e-6 m): dense's reference
# is itself a difference of direct solves good to ~1e-6 of the change (docs/numerics.md,
# "Drift schemes"; measured 5e-8..5e-7 apart with the dense far field, 1e-6..2e-6 with
# the spectral one); a wrong term (the far field's or the lubrication's change, a sign)
# gives O(0.1..1)
CHANGE_AGREE = 10 * AGREE


def _check(out):
    assert out["min_gap"] < 0.01  # near-contact pairs present
    for key in ("velocities", "stresslets", "brownian_far"):
        assert out[key] < AGREE + 10 * FAR_ERROR[out["far_field"]], (key, out)
    for key in ("change_velocities", "change_stresslets"):
        assert out[key] < CHANGE_AGREE + 10 * FAR_ERROR[out["far_field"]], (key, out)
    assert out["near_covariance"] < EXACT and out["long_wave_factor"] < EXACT, out
    assert max(out["takeover_g"], out["takeover_u"], out["takeover_again"]) < EXACT, out
    assert out["lubrication_shared"] == 0.0, out
    # the pairs' relative mobilities within a few times the accuracy asked, some estimated
    # from the preconditioner at phi = 0.5 (there the estimate's error grows with the gap,
    # to 7e-2 at gaps of 0.03-0.046: 3.6 times the 2e-2 asked; what the near-contact
    # correction needs is a small error times c dt / h there, docs/numerics.md)
    assert out["forms"] < 5 and (out["forms_estimated"] > 0) == (out["phi"] > 0.3), out
    # the resistance and the solver hold this rank's block rows of L alone
    assert out["lubrication_blocks_held"] == out["lubrication_blocks_own"], out


@pytest.mark.parametrize("far_field", ["dense", "spectral"])
@pytest.mark.parametrize("phi", [0.1, 0.5])
def test_agrees_with_dense_one_rank(phi, far_field):
    _check(compare(phi, far_field=far_field))


@needs_mpi
@pytest.mark.mpi
def test_agrees_with_dense_two_ranks():
    rows = rows_on_two_ranks("krylov_check", "0.1", "0.5")
    failing = [out for out in rows if out.get("case") == "failing pair"]
    assert len(failing) == 2 and all(out["raised"] for out in failing)  # on both ranks, one message
    rows = [out for out in rows if out not in failing]
    lone = [out for out in rows if out.get("case") == "lone sphere"]
    assert len(rows) - len(lone) == 8 and len(lone) == 2  # 2 ranks x (2 phi x 2 far fields + 1)
    for out in rows:
        if out in lone:  # rank 1 holds no particle: the same as on one rank
            assert out["velocities"] < AGREE + 10 * FAR_ERROR["spectral"] and out["brownian"] < EXACT, out
        else:
            _check(out)


def test_solve_mobility_every_backend():
    """Unbounded and periodic (sheared), a near-contact pair; the isolated sphere exactly."""
    pos, kw = mobility_problem(2.001)
    for box in ([9.0, 8.0, 10.0], None):
        ref = solve_mobility(pos, box, solver="dense", **kw)
        for name in ("petsc-krylov", "auto"):
            for a, b in zip(ref, solve_mobility(pos, box, solver=name, tolerance=TOL, **kw)):
                assert np.abs(a - b).max() < AGREE * np.abs(a).max(), (name, box)
    assert_isolated_sphere("petsc-krylov", kw["rate_of_strain"])
    with pytest.raises(ValueError, match="solver must be one of"):
        solve_mobility(pos, None, solver="krylov")
    with pytest.raises(ValueError, match="tolerance must be in"):
        solve_mobility(pos, None, solver="petsc-krylov", tolerance=2.0)


def test_script_holding_a_solver_exits_cleanly():
    """PETSc finalizes at exit; a solver still alive then had its python contexts reset
    after the interpreter was gone (segmentation fault, exit code -11) until live solvers
    were destroyed by an exit handler."""
    code = ("import numpy as np\n"
            "from sdmpi.hydro.resistance import split_resistance\n"
            "from sdmpi.hydro.solvers import make_solver\n"
            "pos = np.array([[0.0, 0, 0], [2.1, 0, 0], [0, 3, 0]])\n"
            "solver = make_solver('petsc-krylov', split_resistance(pos, np.ones(3)))\n"
            "solver.velocities(np.ones((3, 6)), np.zeros((3, 5)))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=child_env(),
                         timeout=120, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-2000:]


def test_auto_picks_by_size():
    """"auto": dense on one rank below AUTO_KRYLOV_MIN_N_ONE_RANK particles, petsc-dense on
    several below AUTO_KRYLOV_MIN_N, petsc-krylov from there on; a name stands for itself."""
    from sdmpi.registry import AUTO_KRYLOV_MIN_N, AUTO_KRYLOV_MIN_N_ONE_RANK

    class Two:
        size = 2

    one, several = AUTO_KRYLOV_MIN_N_ONE_RANK, AUTO_KRYLOV_MIN_N
    assert resolve_backend("auto", 27) == "dense"
    assert resolve_backend("auto", one - 1) == "dense"
    assert resolve_backend("auto", one) == resolve_backend("auto", 4096) == "petsc-krylov"
    assert resolve_backend("auto", 27, Two()) == resolve_backend("auto", several - 1, Two()) == "petsc-dense"
    assert resolve_backend("auto", several, Two()) == "petsc-krylov"
    assert resolve_backend("petsc-dense", 4096) == "petsc-dense"


def test_sparse_lubrication_equals_dense():
    """Same pair blocks, summed into a BSR matrix: equal to the dense assembly to rounding
    (self-image pairs and repeated (i, j) images included: small periodic box)."""
    from .petsc_check import STRAIN, configuration
    from sdmpi.hydro.geometry import Lattice

    pos, side = configuration(0.5)
    lattice = Lattice(np.full(3, side), STRAIN)
    pos = lattice.wrap(pos)
    pairs = close_pairs(pos, np.ones(len(pos)), lattice, cutoff=6.0)
    assert np.any(pairs.i == pairs.j)
    dense = lubrication_matrix(pos, np.ones(len(pos)), pairs)
    sparse = lubrication_sparse(pos, np.ones(len(pos)), pairs).toarray()
    assert np.abs(dense - sparse).max() <= EXACT * np.abs(dense).max()


@pytest.mark.parametrize("phi, cutoff, sizes", [(0.5, 6.0, "equal"), (0.3, 2.0, "two"), (0.45, 2.0, "spread")])
def test_lubrication_rows_are_the_whole_matrix_rows(phi, cutoff, sizes):
    """Each rank's block rows of L, formed from the pairs touching them
    (`lubrication_rows`), are the whole matrix's rows bit for bit, and so are those pairs'
    factors, in the whole matrix's order, together all of its factors: equal spheres
    (self-image pairs and repeated images: small box, cut-off 6), two sizes (pairs swapped
    big sphere first, tabulated) and spread sizes (every pair on the exact path)."""
    from .petsc_check import STRAIN, configuration
    from sdmpi.hydro.geometry import Lattice
    from sdmpi.hydro.krylov import particle_ranges
    from sdmpi.hydro.lubrication import lubrication_rows

    pos, side = configuration(phi)
    n = len(pos)
    radii = {"equal": np.ones(n), "two": np.where(np.arange(n) % 2, 1.0, 0.7),
             "spread": 0.8 + 0.2 * np.random.default_rng(0).random(n)}[sizes]
    lattice = Lattice(np.full(3, side), STRAIN)
    pos = lattice.wrap(pos)
    pairs = close_pairs(pos, radii, lattice, cutoff=cutoff)
    whole, *factors = lubrication_sparse(pos, radii, pairs, factors=True)
    for ranks in (1, 2, 5):
        bounds = particle_ranges(n, ranks)
        owned = []
        for r0, r1 in zip(bounds[:-1], bounds[1:]):
            rows, own = lubrication_rows(pos, radii, pairs, (r0, r1), factors=True)
            lo, hi = whole.indptr[r0], whole.indptr[r1]
            assert rows.shape == (11 * (r1 - r0), 11 * n)
            assert np.array_equal(rows.indptr, whole.indptr[r0:r1 + 1] - lo)
            assert np.array_equal(rows.indices, whole.indices[lo:hi])
            assert np.array_equal(rows.data, whole.data[lo:hi])
            at = own[0]
            assert np.all(np.diff(at) > 0)  # in the whole matrix's order
            touching = np.isin(factors[0], np.arange(r0, r1)) | np.isin(factors[1], np.arange(r0, r1))
            assert np.array_equal(at, np.flatnonzero(touching))
            for mine, ref in zip(own[1:], factors):
                assert np.array_equal(mine, ref[at])
            owned.append(at)
        assert np.array_equal(np.unique(np.concatenate(owned)), np.arange(len(pairs.i)))


def test_lanczos_inverse_square_root():
    """A^-1/2 z for an SPD matrix (condition number 1e3, eigenvalues log-spaced: a hard
    case) against its eigen-decomposition."""
    rng = np.random.default_rng(0)
    n = 400
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    a = (q * np.logspace(0, 3, n)) @ q.T
    z = rng.standard_normal(n)
    exact = q @ ((q.T @ z) / np.sqrt(np.logspace(0, 3, n)))
    got, its = lanczos_inverse_sqrt(lambda v: a @ v, z, lambda x, y: x @ y, tol=1e-8)
    # the stopping test (change per step) tracks the error: measured 2.7e-8
    assert np.abs(got - exact).max() < 1e-7 * np.abs(exact).max()
    assert its < n // 2  # converged long before the Krylov space is full (measured 172)


def near_contact_start():
    """A split resistance at phi = 0.5 with near-contact pairs (petsc_check.configuration,
    27 spheres, at the strain it was made at) and its box: the start of a Brownian step."""
    from .petsc_check import STRAIN, configuration

    pos, side = configuration(0.5, 1)
    box = np.full(3, side)
    return split_resistance(pos, np.ones(len(pos)), box, STRAIN), box


def test_resistance_for_solves_only():
    """split_resistance(..., brownian=False) (the Brownian midpoint's) leaves out the pairs'
    factors and nothing else: the same lubrication matrix and noise shape, solves and
    stresslets equal bit for bit, and Brownian forces refused with a message."""
    from .petsc_check import STRAIN

    start, box = near_contact_start()
    n = start.n_particles
    solves = split_resistance(start.positions, np.ones(n), box, STRAIN, plan=start.plan, brownian=False)
    assert solves.pair_factors is None and start.pair_factors is not None
    assert np.array_equal(solves.lubrication.data, start.lubrication.data)
    rng = np.random.default_rng(5)
    forces, einf = rng.standard_normal((n, 6)), rng.standard_normal((n, 5))
    full, only = (make_solver("petsc-krylov", r, tolerance=1e-8) for r in (start, solves))
    assert full.noise_shape == only.noise_shape
    u = full.velocities(forces, einf)
    assert np.array_equal(only.velocities(forces, einf), u)
    assert np.array_equal(only.stresslets(u, einf), full.stresslets(u, einf))
    with pytest.raises(ValueError, match="pairs' factors"):
        only.brownian_forces(rng.standard_normal(only.noise_shape))


def test_solver_frees_its_petsc_objects():
    """A solver its caller drops destroys its PETSc objects (`KrylovSolver.__del__`): the
    shell matrix and preconditioner hold their python contexts from PETSc's side, and
    PETSc would otherwise keep the solver's matrices, factor and Krylov vectors allocated
    until the process ends (two solvers a Brownian step)."""
    start, _ = near_contact_start()
    n = start.n_particles
    solver = make_solver("petsc-krylov", start, tolerance=1e-6)
    solver.velocities(np.ones((n, 6)), np.zeros((n, 5)))
    held = [solver.ksp, solver.saddle, solver.inner, solver.l_uu, solver.schur]
    assert all(obj.handle != 0 for obj in held)
    del solver
    assert all(obj.handle == 0 for obj in held)


def test_midpoint_difference_is_accurate():
    """The Brownian stresslets are a difference of two solves, S_mid - S_start, at
    configurations ~sqrt(dt) apart, much smaller than each (here 1-2%). The midpoint's solve (which
    takes over the start's preconditioner factor) starts from zero like the start's, so
    the two GMRES runs take nearly the same path and their errors nearly cancel: at
    tolerance 1e-5 the difference of the velocities and of the stresslets is accurate to
    1e-3 of itself (measured 4e-5 and 2e-5 at displacements 1e-3 a, 5e-5 and 3e-5 at 1e-2 a),
    although each solve is accurate to ~2e-5 of itself only. Started from the start's
    solution, the midpoint needs fewer iterations (12 vs 19) but its error is independent:
    4e-3 and 3e-2 of the difference."""
    from .petsc_check import STRAIN

    start, box = near_contact_start()
    n = start.n_particles
    rng = np.random.default_rng(7)
    forces, zero = rng.standard_normal((n, 6)), np.zeros((n, 5))
    # the midpoint of a step: displacements ~1e-3 a with the start's pair sets
    mid = split_resistance(start.positions + 1e-3 * rng.standard_normal((n, 3)), np.ones(n), box,
                           STRAIN, plan=start.plan)

    def solved(solver):
        u = solver.velocities(forces, zero)
        return u, solver.stresslets(u, zero)

    (u0, s0), (u1, s1) = (solved(make_solver("petsc-krylov", r, tolerance=1e-13)) for r in (start, mid))
    first = make_solver("petsc-krylov", start, tolerance=1e-5)
    u_first, s_first = solved(first)
    follow = make_solver("petsc-krylov", mid, tolerance=1e-5)
    follow.take_preconditioner(first)
    assert follow.inner is not None and first.inner is None  # taken over
    make_solver("dense", grand_resistance(start.positions, np.ones(n), box, STRAIN)).take_preconditioner(first)  # no-op
    u_follow, s_follow = solved(follow)
    assert np.abs(u_first - u0).max() > 1e-6 * np.abs(u0).max()  # each solve is only ~1e-5 accurate
    for got, exact, whole in ((u_follow - u_first, u1 - u0, u0), (s_follow - s_first, s1 - s0, s0)):
        assert np.abs(exact).max() < 5e-2 * np.abs(whole).max()  # a small difference
        assert np.abs(got - exact).max() < 1e-3 * np.abs(exact).max()


def test_long_waves_cut_the_lanczos_iterations(monkeypatch):
    """The Lanczos square root preconditioned by the far field's longest waves
    (krylov.LongWaveFactor; its exactness: _check's long_wave_factor and brownian_far)
    needs fewer iterations than with the self mobilities alone: N = 125, phi = 0.45,
    Lanczos tolerance 1e-4, measured 22 against 29 (N = 343: 22 against 33)."""
    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro import krylov

    n = 125
    pos, side = hard_sphere_fluid(n, 0.45, np.random.default_rng(3), strain=0.1)
    res = split_resistance(pos, np.ones(n), np.full(3, side), 0.1, far_field="dense")
    iterations = []
    for waves in (krylov.LONG_WAVES, 0):
        monkeypatch.setattr(krylov, "LONG_WAVES", waves)
        solver = make_solver("petsc-krylov", res, tolerance=1e-6, lanczos_tolerance=1e-4)
        solver.brownian_forces(np.random.default_rng(1).standard_normal(solver.noise_shape))
        iterations.append(solver.stats["lanczos"])
    assert iterations[0] < 0.85 * iterations[1], iterations


@pytest.mark.parametrize("n, chunk", [(20, 512), (90, 512), (90, 7)])
def test_long_wave_factor_with_unequal_radii(n, chunk, monkeypatch):
    """P^T C P = I (krylov.LongWaveFactor against C built pair by pair) for radii 0.5-1.5
    in a sheared box, with fewer rows than long-wave columns (n = 20: 60 < 184) and more
    (n = 90), V formed in one block of particles or in blocks of 7 (the last one short);
    P^T is the transpose of P. (Split over two ranks: krylov_check, in
    test_agrees_with_dense_two_ranks.)"""
    from .krylov_check import long_wave_preconditioner

    from sdmpi.hydro.geometry import Lattice
    from sdmpi.hydro.krylov import LongWaveFactor

    monkeypatch.setattr(LongWaveFactor, "CHUNK", chunk)
    rng = np.random.default_rng(n)
    lattice = Lattice(np.array([9.0, 8.0, 10.0]), 0.35)
    pos, radii = rng.uniform(0, 8, (n, 3)), rng.uniform(0.5, 1.5, n)
    factor = LongWaveFactor(pos, radii, lattice, 0, n)
    eye = np.eye(11 * n)
    p, p_t = (np.array([f(e) for e in eye]).T for f in (factor.right, factor.left))
    assert np.abs(p.T - p_t).max() < 1e-14 * np.abs(p).max()
    c = long_wave_preconditioner(pos, radii, lattice)
    assert np.abs(p.T @ c @ p - eye).max() < 1e-12


def test_lanczos_tolerance():
    """A looser Lanczos tolerance gives the Brownian force to about that tolerance in
    fewer iterations."""
    start, box = near_contact_start()
    n = start.n_particles
    tight = make_solver("petsc-krylov", start, tolerance=1e-8)
    loose = make_solver("petsc-krylov", start, tolerance=1e-8, lanczos_tolerance=1e-3)
    z = np.random.default_rng(7).standard_normal(tight.noise_shape)
    tight_force, loose_force = tight.brownian_forces(z), loose.brownian_forces(z)
    # the stopping test tracks the error (test_lanczos_inverse_square_root; measured
    # 6.2e-4 here, 15 vs 46 iterations): 10 x tol
    assert np.abs(tight_force - loose_force).max() < 1e-2 * np.abs(tight_force).max()
    assert loose.stats["lanczos"] < tight.stats["lanczos"]


BOX = np.array([7.0, 7.0, 7.0])
CONFIG = np.array([[1.0, 1.2, 0.8], [3.05, 1.2, 0.8], [2.0, 3.9, 3.5]])  # as test_dynamics


def test_midpoint_drift_and_brownian_stress_agree_with_dense():
    """The expectation over the noise of the midpoint estimates is a quadratic form in it;
    the quadrature noise = +-e_k (weights 1/2) gives it exactly up to O(dt^2) and to the
    Lanczos tolerance. petsc-krylov (noise 11N + 12 per pair) and dense (6N) must give the
    same drift kT div R_FU^-1 and Brownian stresslet -kT div(R_SU R_FU^-1): agreement to
    1e-4 relative (dt = 1e-7: O(dt) terms ~1e-6; solver errors ~1e-7)."""
    kt, dt, n = 1.0, 1e-7, len(CONFIG)
    means = {}
    for name in ("dense", "petsc-krylov"):
        model = ResistanceModel(np.ones(n), BOX, lubrication=True, ewald_tol=1e-6, cutoff=2.0, min_gap=1e-4,
                                backend=name, tolerance=1e-10, scheme="midpoint")
        at = model.at(CONFIG, 0.1)
        shape = at.solver.noise_shape
        m = int(np.prod(shape))
        drift, stress = np.zeros((n, 6)), np.zeros((n, 5))
        for k in range(m):
            for sign in (1.0, -1.0):
                z = np.zeros(m)
                z[k] = sign
                terms = at.brownian_terms(z.reshape(shape), kt, dt)
                drift += 0.5 * terms.velocities
                stress += 0.5 * terms.stresslets
        means[name] = drift, stress
    for a, b in zip(means["dense"], means["petsc-krylov"]):
        assert np.abs(a - b).max() < 1e-4 * np.abs(a).max()


def test_midpoint_brownian_stress_reuses_the_start_solve():
    """A sample of the midpoint Brownian stresslet is S_mid - S_start of two solves whose
    errors cancel when S_start comes from the start's own velocity solve (the one the
    midpoint displacement used): at tolerance 1e-5 each sample agrees with a 1e-12 solve
    to 1.4e-5 ... 4.2e-5 of itself (a fresh solve for S_start, with an independent error:
    4.4e-4 ... 5.4e-4), so 1.5e-4 separates the two."""
    kt, dt, n = 6 * np.pi, 5e-4, len(CONFIG)
    samples = {}
    for tol in (1e-5, 1e-12):
        model = ResistanceModel(np.ones(n), BOX, lubrication=True, ewald_tol=1e-6, cutoff=2.0, min_gap=1e-4,
                                backend="petsc-krylov", tolerance=tol, scheme="midpoint")
        at = model.at(CONFIG, 0.1)
        rng = np.random.default_rng(3)
        samples[tol] = [at.brownian_terms(rng.standard_normal(at.solver.noise_shape), kt, dt).stresslets
                        for _ in range(3)]
    for loose, tight in zip(samples[1e-5], samples[1e-12]):
        assert np.abs(loose - tight).max() < 1.5e-4 * np.abs(tight).max()


def test_single_precision_spectral_far_field_keeps_the_brownian_step(monkeypatch):
    """The spectral far field in single precision (blocks and grids, from
    spectral.SINGLE_PRECISION_TOL: here Ewald tolerance 1e-5) against the same operator
    in double, on a stored configuration (27 spheres, phi = 0.5, near-contact pairs), the
    solves at 1e-10: the velocities and stresslets of the imposed flow and the midpoint
    drift and Brownian stresslets of 4 noise samples agree to 1e-5 relative, a tenth of
    the Ewald tolerance (measured: velocities 1.5e-7, stresslets 5e-8, Brownian velocities
    2e-7, Brownian stresslets, a difference of two solves, 1.4-2.7e-6)."""
    from .petsc_check import STRAIN, configuration

    from sdmpi.hydro import spectral

    pos, side = configuration(0.5, 1)
    n, kt, dt = len(pos), 6 * np.pi, 5e-4
    einf = np.tile([1.0, 0.0, 0.0, 0.0, 0.0], (n, 1))
    results = []
    for single_from in (1e-5, 1.0):   # single, double precision
        monkeypatch.setattr(spectral, "SINGLE_PRECISION_TOL", single_from)
        model = ResistanceModel(np.ones(n), np.full(3, side), lubrication=True, ewald_tol=1e-5, cutoff=2.0,
                                min_gap=1e-4, backend="petsc-krylov", tolerance=1e-10, scheme="midpoint",
                                far_field="spectral")
        rng = np.random.default_rng(12)
        out = []
        for _ in range(4):
            at = model.at(pos, STRAIN)
            assert at.solver.far._precision == (np.float32 if single_from < 1 else np.float64)
            u = at.velocities(np.zeros((n, 6)), einf)
            out += [u, at.stresslets(u, einf)]
            terms = at.brownian(rng, kt, dt)
            out += [terms.velocities, terms.stresslets]
        results.append(out)
    for single, double in zip(*results):
        assert np.linalg.norm(single - double) < 1e-5 * np.linalg.norm(double)


@pytest.mark.parametrize("far_field", ["dense", "spectral"])
def test_step_draw_frees_the_pair_factors_before_the_midpoint(far_field, monkeypatch):
    """The step's draw (`ResistanceEvaluation.brownian`, the evaluation's last) frees the
    start's pair factors, in its solver and its resistance, its rows of the lubrication
    matrix and their PETSc copy L_uu, and a spectral far field's real-space blocks, once
    the midpoint scheme has drawn the forces and before it builds the midpoint; its terms
    equal bit for bit those of a sample of the same noise drawn without freeing
    (`brownian_terms`), which keeps them for more draws, and so do the start's later
    solves and stresslets (what was freed computed again). (L is freed from
    RELEASE_MIN_BYTES on: here from any size.)"""
    from sdmpi.hydro import workspace

    monkeypatch.setattr(workspace, "RELEASE_MIN_BYTES", 0)
    kt, dt, n = 6 * np.pi, 5e-4, len(CONFIG)
    model = ResistanceModel(np.ones(n), BOX, lubrication=True, ewald_tol=1e-6, cutoff=2.0, min_gap=1e-4,
                            backend="petsc-krylov", tolerance=1e-8, scheme="midpoint", far_field=far_field)
    step, sample = model.at(CONFIG, 0.1), model.at(CONFIG, 0.1)
    held = []
    displaced = model.displaced

    def record(evaluation, positions, separate):
        solver = evaluation.solver
        held.append((solver.pair_factors, evaluation.resistance.pair_factors,
                     getattr(solver.far, "_blocks", "dense"), solver._lub, evaluation.resistance.lubrication,
                     solver.l_uu))
        return displaced(evaluation, positions, separate)

    monkeypatch.setattr(model, "displaced", record)
    terms = step.brownian(np.random.default_rng(4), kt, dt)
    assert held == [(None, None, None if far_field == "spectral" else "dense", None, None, None)]
    with pytest.raises(ValueError, match="pairs' factors"):
        step.solver.brownian_forces(np.zeros(step.solver.noise_shape))
    z = np.random.default_rng(4).standard_normal(sample.solver.noise_shape)
    kept = sample.brownian_terms(z, kt, dt)
    assert all(item is not None for item in held[1])
    assert np.array_equal(terms.velocities, kept.velocities)
    assert np.array_equal(terms.stresslets, kept.stresslets)
    forces = np.random.default_rng(5).standard_normal((n, 6))
    einf = np.random.default_rng(6).standard_normal((n, 5))
    assert np.array_equal(step.solver.stresslets(forces, einf), sample.solver.stresslets(forces, einf))
    assert np.array_equal(step.velocities(forces, einf), sample.velocities(forces, einf))
    sample.brownian_terms(z, kt, dt)  # drawn again


# ---------------------------------------------------------------- ranks_per_task = 2

# on top of test_petsc_dense's short run (N = 27, phi = 0.45, one period)
KRYLOV = ["--set", "integration.steps_per_period=20", "--set", "shear.omega=[50.26548245743669]",
          "--set", "output.checkpoint_every=20", "--set", 'solver.backend="petsc-krylov"',
          "--set", "solver.tolerance=1e-10"]


@needs_mpi
@pytest.mark.mpi
@pytest.mark.parametrize("scheme", ["midpoint", "rfd"])
def test_two_ranks_per_task_same_stream(tmp_path, scheme):
    """A Brownian realisation (N = 27, phi = 0.45, 20 steps of 0.00625 t_D) with petsc-krylov
    (spectral far field) on a 2-rank
    sub-communicator against one rank, with either drift scheme (rfd: its change solved for
    on the two ranks, the near-contact correction's forms and solves): the same noise,
    solves agreeing to ~1e-9 (tolerance
    1e-10), so the streams agree sample by sample to 1e-6 of their scale (the trajectories
    separate slowly), and so do their means and spreads; the solver statistics are
    recorded (iterations > 0, residual below the tolerance)."""
    job = [*KRYLOV, "--set", f'brownian.scheme="{scheme}"']
    one = _run(tmp_path / "one.h5", *job)
    two = _run(tmp_path / "two.h5", *job, "--set", "ensemble.ranks_per_task=2", ranks=2)
    assert_same_stream(one, two, rtol=1e-6, mean_tol=1e-4)
    for run in (one, two):
        assert np.all(run["solver_iterations"] > 0) and np.all(run["lanczos_iterations"] > 0)
        assert np.all(run["solver_residual"] < 1e-10)


@needs_mpi
@pytest.mark.mpi
def test_two_ranks_per_task_killed_and_resumed_is_bit_identical(tmp_path):
    """The realisation of test_two_ranks_per_task_same_stream on 2 ranks per task, with a
    checkpoint every 5 steps, SIGKILLed after its second commit and resumed: its run file's
    task data equal an uninterrupted 2-rank run's bit for bit (the collective solves and
    the far field's rank split are deterministic for a given rank count)."""
    from .runs import task_data

    run = [sys.executable, "-m", "sdmpi.cli", "run", str(ROOT / "jobs" / "demo.toml"), *SHORT, *KRYLOV,
           "--set", "ensemble.ranks_per_task=2", "--set", "output.checkpoint_every=5"]
    mpirun = [MPIRUN, "--oversubscribe", "-n", "2"]
    ref, killed = tmp_path / "ref.h5", tmp_path / "killed.h5"
    for out, env, ok in ((ref, None, True), (killed, {"SDMPI_TEST_KILL": "commit:2"}, False), (killed, None, True)):
        res = subprocess.run([*mpirun, *run, "-o", str(out)], capture_output=True, text=True, env=child_env(env),
                             timeout=300, cwd=ROOT)
        assert (res.returncode == 0) == ok, res.stderr
    assert "resuming" in res.stdout
    assert task_data(killed) == task_data(ref)


@pytest.mark.parametrize("fast, bounds", [((1e-6, 1e-4, 1e-4), (1e-3, 1e-3)),
                                          ((1e-5, 1e-4, 1e-4), (1e-3, 1e-3)),
                                          ((1e-4, 1e-4, 1e-4), (3e-3, 3e-3))])
def test_fast_tolerances_change_the_stream_only_at_their_level(fast, bounds):
    """The benchmark's fast settings (solver tolerance 1e-6, 1e-5 or 1e-4, Lanczos 1e-4,
    Ewald 1e-4) against tight ones (1e-10, 1e-10, 1e-8) on the same realisation (N = 27,
    phi = 0.45, the same noise): each sample's stresses agree to `bounds` (hydrodynamic,
    Brownian) of their scale (measured 7e-5 and 2e-4 at 1e-6; 5e-5 and 3e-4 at 1e-5;
    2.5e-4 to 1.2e-3 and 3.4e-4 at 1e-4, depending on the start's closest pairs (N = 125:
    5e-4 and 2e-4); the solver's relative residual bounds the error only up to the
    condition number of the resistance near contact): far below the sampling noise of a
    stress average; the Brownian stress, a difference of two solves ~sqrt(dt) apart, keeps
    its accuracy because the two solves' errors cancel, test_midpoint_difference_is_accurate;
    with the midpoint started from the start's solution it was 8e-3 at 1e-5), positions to
    3e-5 a after 4 steps (Lanczos error 1e-4 x the Brownian displacement, ~0.09 a: ~1e-5;
    measured 6e-6, 6e-6 and 1.5e-5; N = 125: 7e-6, 7e-6, 2e-5)."""
    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation

    streams = {}
    for name, (tol, lanczos, ewald) in {"tight": (1e-10, 1e-10, 1e-8), "fast": fast}.items():
        job = load_job(str(ROOT / "jobs" / "demo.toml"), [
            "system.n_particles=27", "system.phi=[0.45]", 'solver.backend="petsc-krylov"',
            f"solver.tolerance={tol}", f"solver.lanczos_tolerance={lanczos}",
            f"hydrodynamics.ewald_tolerance={ewald}", "integration.steps_per_period=2000"])
        real = Realisation(job, enumerate_tasks(job)[0])
        streams[name] = real.advance(4), real.positions
    (tight, x_tight), (fast, x_fast) = streams["tight"], streams["fast"]
    for key, bound in zip(("stress_hydrodynamic", "stress_brownian"), bounds):
        scale = np.abs(tight[key]).max()
        assert np.abs(tight[key] - fast[key]).max() < bound * scale, key
    assert np.abs(x_tight - x_fast).max() < 3e-5
    assert fast["solver_iterations"].sum() < tight["solver_iterations"].sum()


def test_far_field_key_picks_the_operator_and_both_agree():
    """solver.far_field = "spectral" at N = 27 (where the by-N default is the dense Ewald
    matrix) builds the particle-mesh operator, and a Brownian realisation (3 steps, the same
    noise, Ewald tolerance 1e-8, solver 1e-10) follows the dense one: stresses to 1e-6 of
    their scale, positions to 1e-8 a (both far fields are accurate to ~1e-8; measured
    1.2e-8, 3.4e-8 and 3e-10 a)."""
    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation
    from sdmpi.hydro.krylov import DenseFarField
    from sdmpi.hydro.spectral import SpectralFarField

    runs = {}
    for far in (None, "spectral"):
        job = load_job(str(ROOT / "jobs" / "demo.toml"), [
            "system.n_particles=27", "system.phi=[0.45]", 'solver.backend="petsc-krylov"',
            "solver.tolerance=1e-10", "hydrodynamics.ewald_tolerance=1e-8",
            "integration.steps_per_period=2000", *([f'solver.far_field="{far}"'] if far else [])])
        real = Realisation(job, enumerate_tasks(job)[0])
        kind = type(real.model.at(real.positions, 0.0).resistance.far)
        runs[far] = kind, real.advance(3), real.positions
    (dense_kind, dense, x_dense), (spectral_kind, spectral, x_spectral) = runs.values()
    assert dense_kind is DenseFarField and spectral_kind is SpectralFarField
    for key in ("stress_hydrodynamic", "stress_brownian"):
        assert np.abs(dense[key] - spectral[key]).max() < 1e-6 * np.abs(dense[key]).max(), key
    assert np.abs(x_dense - x_spectral).max() < 1e-8


def test_monolayer_agrees_with_dense():
    """A sheared monolayer (jobs/monolayer_repulsion.toml, areal fraction 0.4: z-replicated
    layers, in-plane motion, repulsion) stepped with petsc-krylov at tolerance 1e-10
    follows the dense run: stresses to 1e-7 relative (measured 5e-11 hydrodynamic, 9e-9
    interparticle), positions to 1e-9 a after 5 steps."""
    from sdmpi.config import enumerate_tasks, load_job
    from sdmpi.dynamics import Realisation

    runs = {}
    for backend in ("dense", "petsc-krylov"):
        job = load_job(str(ROOT / "jobs" / "monolayer_repulsion.toml"),
                       [f'solver.backend="{backend}"', "solver.tolerance=1e-10", "system.phi=[0.4]"])
        real = Realisation(job, enumerate_tasks(job)[0])
        runs[backend] = real.advance(5), real.positions
    (dense, x_dense), (krylov, x_krylov) = runs["dense"], runs["petsc-krylov"]
    for key in ("stress_hydrodynamic", "stress_interparticle"):
        assert np.abs(dense[key] - krylov[key]).max() < 1e-7 * np.abs(dense[key]).max(), key
    assert np.abs(x_dense - x_krylov).max() < 1e-9


@pytest.mark.parametrize("phi", [0.5, 0.55])
def test_preconditioner_keeps_iterations_low_near_contact(phi, monkeypatch):
    """The preconditioner (incomplete Cholesky of G on its full 6x6-block pattern, the
    lubrication coupling of pairs closer than krylov.PRECONDITIONER_MAX_GAP, the far-field
    self resistance scaled by krylov.self_resistance_scale and weighted by
    krylov.self_resistance_weights) keeps the iterations of a solve at N = 125 with pairs
    at the minimum gap (strain 0.3, tolerance 1e-8) low: measured 52 / 41 at phi = 0.5 /
    0.55 (unweighted: 55 / 47; the isolated-sphere D, scale 1, unweighted: 59 / 62; all
    pairs' coupling, scaled D: 49 / 47; all pairs, scale 1, ICC(0): 65 / 63); an
    incomplete factor on the pattern of the nonzero entries alone needs hundreds.
    Bound: 100, and fewer than unweighted, which needs fewer than the isolated D."""
    from sdmpi.dynamics.initial import hard_sphere_fluid
    from sdmpi.hydro import krylov

    n = 125
    # a compressed start with few sweeps keeps pairs below the minimum gap
    pos, side = hard_sphere_fluid(n, phi, np.random.default_rng(2), strain=0.3, sweeps=200)
    res = split_resistance(pos, np.ones(n), np.full(3, side), 0.3)
    assert res.pairs.n_regularised > 0  # pairs closer than the minimum gap
    rng = np.random.default_rng(1)
    rhs = rng.standard_normal((n, 6)), rng.standard_normal((n, 5))
    iterations = []
    for exponent, weights in ((krylov.SELF_RESISTANCE_EXPONENT, krylov.SELF_RESISTANCE_WEIGHTS),
                              (krylov.SELF_RESISTANCE_EXPONENT, (1, 1, 1)), (0.0, (1, 1, 1))):
        monkeypatch.setattr(krylov, "SELF_RESISTANCE_EXPONENT", exponent)
        monkeypatch.setattr(krylov, "SELF_RESISTANCE_WEIGHTS", weights)
        solver = make_solver("petsc-krylov", res, tolerance=1e-8)
        solver.velocities(*rhs)
        kept = solver._g_keep.sum()  # full blocks: of the near pairs, and the diagonal ones
        assert solver.schur.getInfo()["nz_used"] == 36 * kept < 36 * len(res.lubrication.data)
        iterations.append(solver.stats["iterations"])
    weighted, unweighted, isolated = iterations
    assert 0 < weighted < unweighted < isolated < 100, iterations


def test_self_resistance_scale():
    """1 in dilute suspensions and unbounded fluid, growing with phi (its docstring's
    measurements), bounded near close packing."""
    from sdmpi.hydro.krylov import self_resistance_scale

    assert self_resistance_scale(0.0) == 1.0
    values = [self_resistance_scale(phi) for phi in (0.1, 0.3, 0.45, 0.55, 0.64, 0.9)]
    assert np.all(np.diff(values[:5]) > 0) and values[-1] == self_resistance_scale(0.7)
    assert 4 < self_resistance_scale(0.45) < 6  # the measured optimum at 0.45: 4-6



def _near_contact_suspension():
    """125 spheres at phi = 0.45 (hard-sphere fluid compressed), 7 pairs at gaps below
    0.005 a: (n, positions, box, split resistance at rest)."""
    from sdmpi.dynamics.initial import compress, hard_sphere_fluid

    n, rng = 125, np.random.default_rng(3)
    pos, side = hard_sphere_fluid(n, 0.2, rng)
    pos, side = compress(pos, side, 0.45, rng)
    box = np.full(3, side)
    return n, pos, box, split_resistance(pos, np.ones(n), box, 0.0)


def test_mobility_forms_share_solves_between_distant_near_contact_pairs():
    """The relative mobilities G_p = f_p.R_FU^-1.f_p of pairs near contact (the collision
    stress), several to a solve: 125 spheres at phi = 0.45 with 7 pairs at gaps below
    0.005 a take 3 solves instead of 7, each form within 5e-3 of the exact one (the dense
    backend; the cross terms f_p.R_FU^-1.f_q of the pairs sharing a solve measure up to
    2.3e-3 of G_p here, below 1e-3 at the collisions of runs at N = 343-1000, with fewer
    such pairs and smaller gaps). With all 7 in one solve, neighbours included, the error
    is several times larger. A single-sphere force and a pair farther from contact are
    solved alone, exact to the solver tolerance."""
    from sdmpi.dynamics.drift import unit_pair_forces
    from sdmpi.hydro.backend import SolverBackend
    from sdmpi.hydro.geometry import Lattice
    from sdmpi.hydro.krylov import FORMS_MAX_GAP, FORMS_SEPARATION

    n, pos, box, res = _near_contact_suspension()
    pairs = res.pairs
    near = np.flatnonzero(pairs.gap < FORMS_MAX_GAP)
    wide = np.flatnonzero(pairs.gap > 0.5)[:1]
    chosen = np.concatenate([near, wide])
    e = pairs.dx[chosen] / np.linalg.norm(pairs.dx[chosen], axis=1)[:, None]
    forces = unit_pair_forces(pairs.i[chosen], pairs.j[chosen], e, n)
    single = np.zeros((1, n, 6))
    single[0, 5, 1] = 1.0
    forces = np.concatenate([forces, single])
    solver = make_solver("petsc-krylov", res, tolerance=1e-10)
    groups = solver.form_groups(forces)
    assert len(near) == 7 and len(groups) == 5 and [len(chosen)] in groups and [len(chosen) - 1] in groups
    for group in groups:  # no two pairs of a solve within FORMS_SEPARATION (nearest images)
        spheres = [np.concatenate([pairs.i[chosen[[p]]], pairs.j[chosen[[p]]]]) for p in group if p < len(near)]
        for a in range(len(spheres)):
            for b in range(a):
                d = Lattice(box, 0.0).nearest_image(pos[spheres[a]][:, None] - pos[spheres[b]][None])
                assert np.linalg.norm(d, axis=-1).min() >= 2 * FORMS_SEPARATION
    twice = solver.form_groups(np.concatenate([forces[:1], forces[:1]]))  # the same pair twice: apart
    assert twice == [[0], [1]]
    exact = make_solver("dense", grand_resistance(res.positions, np.ones(n), box, 0.0)).mobility_forms(forces)
    shared = solver.mobility_forms(forces)
    error = np.abs(shared / exact - 1)
    assert error[:len(near)].max() < 5e-3 and error[len(near):].max() < 1e-8, error
    assert np.abs(SolverBackend.mobility_forms(solver, forces) / exact - 1).max() < 1e-8  # one solve each
    pair_forces = forces[:len(near)]  # all near pairs in one solve:
    together = np.einsum("pkc,kc->p", pair_forces, solver.velocities(pair_forces.sum(axis=0), np.zeros((n, 5))))
    assert np.abs(together / exact[:len(near)] - 1).max() > 2 * error.max()


def test_colouring_separates_neighbours_with_few_colours():
    """The solves of `mobility_forms` are the colours of the graph of pairs too close to
    share one (`_dsatur`): never two neighbours alike, on random graphs; two colours on a
    crown graph (u_i adjacent to v_j for i != j, 6 + 6 vertices) listed u_1, v_1, u_2, v_2,
    ..., where taking the vertices in order with the lowest free colour needs 6; and on
    the near-contact pairs of a suspension no more groups than in order."""
    from sdmpi.dynamics.drift import NEAR_CONTACT_GAP, unit_pair_forces
    from sdmpi.hydro.krylov import _dsatur

    rng = np.random.default_rng(5)
    for density in (0.05, 0.2, 0.5):
        upper = np.triu(rng.random((40, 40)) < density, 1)
        adjacent = upper | upper.T
        colour = _dsatur(adjacent)
        assert colour.min() == 0 and not np.any(adjacent & (colour[:, None] == colour[None, :]))
    m = 6
    crown = np.zeros((2 * m, 2 * m), dtype=bool)
    for i in range(m):
        for j in range(m):
            if i != j:
                crown[2 * i, 2 * j + 1] = crown[2 * j + 1, 2 * i] = True
    in_order = np.full(2 * m, -1)
    for v in range(2 * m):
        in_order[v] = min(set(range(2 * m)) - set(in_order[crown[v]]))
    assert in_order.max() + 1 == m and _dsatur(crown).max() + 1 == 2

    n, pos, box, res = _near_contact_suspension()
    pairs = res.pairs
    chosen = np.flatnonzero(pairs.gap < NEAR_CONTACT_GAP)
    forces = unit_pair_forces(pairs.i[chosen], pairs.j[chosen],
                              pairs.dx[chosen] / np.linalg.norm(pairs.dx[chosen], axis=1)[:, None], n)
    solver = make_solver("petsc-krylov", res, tolerance=1e-4)
    groups = solver.form_groups(forces)
    too_close = solver._too_close(np.stack([pairs.i[chosen], pairs.j[chosen]], axis=1), pairs.gap[chosen],
                                  np.full(len(chosen), 1e-3))
    assert sorted(sum(groups, [])) == list(range(len(chosen)))
    assert all(not too_close[np.ix_(g, g)][~np.eye(len(g), dtype=bool)].any() for g in groups)
    in_order = []
    for p in range(len(chosen)):
        for group in in_order:
            if not too_close[p, group].any():
                group.append(p)
                break
        else:
            in_order.append([p])
    assert len(groups) <= len(in_order)


def test_mobility_forms_to_the_accuracy_asked():
    """The near-contact correction asks each pair's G_p to FORM_ACCURACY only where a step
    can bring the pair to the floor and to NEAR_CONTACT_FAR_ACCURACY farther out
    (`drift.near_contact_velocities`): 125 spheres at phi = 0.45, the 72 pairs below
    NEAR_CONTACT_GAP, the 16 below 0.012 a (2 FLOOR_REACH c dt at dt = 5e-4) asked to 1e-3
    and solved, the others asked to 2e-2 and estimated from the preconditioner calibrated
    on the solved ones (`KrylovSolver._estimated_forms`): 8 times fewer GMRES iterations
    than every form asked to 1e-3 (280 against 2288), the solved forms within 2.3e-3 of
    the dense backend's exact ones and the estimated within 6.5e-2 (median 1.5e-2), each
    within 4 times what was asked of it. With none asked to 1e-3 nothing calibrates the
    estimate: all are solved, grouped for 2e-2 (17 solves instead of 57)."""
    from sdmpi.dynamics.drift import NEAR_CONTACT_FAR_ACCURACY, NEAR_CONTACT_GAP, unit_pair_forces
    from sdmpi.hydro.backend import FORM_ACCURACY

    n, pos, box, res = _near_contact_suspension()
    pairs = res.pairs
    chosen = np.flatnonzero(pairs.gap < NEAR_CONTACT_GAP)
    e = pairs.dx[chosen] / np.linalg.norm(pairs.dx[chosen], axis=1)[:, None]
    forces = unit_pair_forces(pairs.i[chosen], pairs.j[chosen], e, n)
    accuracy = np.where(pairs.gap[chosen] < 0.012, FORM_ACCURACY, NEAR_CONTACT_FAR_ACCURACY)
    solver = make_solver("petsc-krylov", res, tolerance=1e-10)
    exact = make_solver("dense", grand_resistance(res.positions, np.ones(n), box, 0.0)).mobility_forms(forces)

    def forms(asked):  # the forms and the GMRES iterations they took
        before = solver.stats["iterations"]
        out = solver.mobility_forms(forces, asked)
        return np.abs(out / exact - 1), solver.stats["iterations"] - before

    (error, iterations), (_, everywhere) = forms(accuracy), forms(None)
    assert 4 * iterations < everywhere
    assert (error <= 4 * accuracy).all() and np.median(error[accuracy > FORM_ACCURACY]) < NEAR_CONTACT_FAR_ACCURACY
    rough = np.full(len(chosen), NEAR_CONTACT_FAR_ACCURACY)
    error, iterations = forms(rough)
    assert 2 * len(solver.form_groups(forces, rough)) < len(solver.form_groups(forces))
    assert iterations > 0 and (error <= 4 * rough).all()  # (estimated forms take no GMRES iteration)


def test_velocities_of_forms_combined_without_a_solve():
    """After `mobility_forms`, forces that are a combination of the force sums it solved
    (the collision forces sum_p w_p f_p of pairs each solved alone) take that combination
    of their solutions: no GMRES iteration, velocities and stresslets within 10 x the
    solver tolerance of the dense backend's (tolerance 1e-8: measured 0.9e-8 and 1.8e-8 of
    their largest, a fresh solve's 0.9e-8 and 0.3e-8; at tolerance 1e-4 1.8e-4 and 1.8e-4
    against a solve's 1.9e-4 and 0.6e-4). Forces outside the span
    (other weights within a shared group, an unrelated force, an imposed strain) are
    solved."""
    from sdmpi.dynamics.drift import unit_pair_forces
    from sdmpi.hydro.krylov import FORMS_MAX_GAP

    n, pos, box, res = _near_contact_suspension()
    pairs = res.pairs
    near = np.flatnonzero(pairs.gap < FORMS_MAX_GAP)
    chosen = np.concatenate([near[:1], np.flatnonzero(pairs.gap > 0.5)[:2]])  # each solved alone
    e = pairs.dx[chosen] / np.linalg.norm(pairs.dx[chosen], axis=1)[:, None]
    forces = unit_pair_forces(pairs.i[chosen], pairs.j[chosen], e, n)
    solver = make_solver("petsc-krylov", res, tolerance=1e-8)
    dense = make_solver("dense", grand_resistance(res.positions, np.ones(n), box, 0.0))
    zero = np.zeros((n, 5))
    assert len(solver.form_groups(forces)) == 3
    solver.mobility_forms(forces)
    its = solver.stats["iterations"]
    combined = np.einsum("p,pkc->kc", [3.0, -0.7, 1e-3], forces)
    u = solver.velocities(combined, zero)
    assert solver.stats["iterations"] == its
    exact = dense.velocities(combined, zero)
    assert np.abs(u - exact).max() < 1e-7 * np.abs(exact).max()
    s, s_exact = solver.stresslets(u, zero), dense.stresslets(exact, zero)
    assert solver.stats["iterations"] == its  # (the combined lambda: no CG solve either)
    assert np.abs(s - s_exact).max() < 1e-7 * np.abs(s_exact).max()
    other = combined.copy()
    other[7, 2] += 1.0
    strain = np.tile([0.0, 1.0, 0.0, 0.0, 0.0], (n, 1))
    for f, einf in ((other, zero), (combined, strain)):
        before = solver.stats["iterations"]
        u = solver.velocities(f, einf)
        assert solver.stats["iterations"] > before
        exact = dense.velocities(f, einf)
        assert np.abs(u - exact).max() < 1e-7 * np.abs(exact).max()
    shared = unit_pair_forces(pairs.i[near], pairs.j[near], pairs.dx[near] / np.linalg.norm(
        pairs.dx[near], axis=1)[:, None], n)
    groups = solver.form_groups(shared)
    solver.mobility_forms(shared)
    weights = np.linspace(1.0, 2.0, len(near))
    big = max(groups, key=len)
    assert len(big) > 1  # a shared group: other weights within it are not in the span
    before = solver.stats["iterations"]
    solver.velocities(np.einsum("p,pkc->kc", weights, shared), zero)
    assert solver.stats["iterations"] > before
