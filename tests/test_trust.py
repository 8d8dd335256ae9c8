"""The trust report of `sdmpi reduce` (sdmpi.analysis.trust): its numbers equal a direct
count over the run file's samples; warnings above the thresholds; committed samples only."""

import csv
import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from sdmpi.analysis.reduce import reduce_runs
from sdmpi.analysis.trust import FLOOR_RATE, exact_floor_rate, overlap_threshold, trust_rows, warnings_of
from sdmpi.cli import main
from sdmpi.config import enumerate_tasks, parse_job
from .synthetic_run import write_run
from .test_reduce import MODULI, job_text
from .tiny_runs import sdmpi_run

ROOT = Path(__file__).parents[1]


def read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_trust_report_equals_a_direct_count_on_a_small_run(tmp_path, capsys):
    run = sdmpi_run(tmp_path / "run.h5")
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    rows = read_csv(out / "trust.csv")
    assert (out / "trust.png").read_bytes()[:4] == b"\x89PNG"
    with h5py.File(run) as f:
        job = parse_job(f.attrs["job_text"])
        by_omega = {}
        for task in enumerate_tasks(job):
            by_omega.setdefault(task.omega, []).append(task)
        assert len(rows) == len(by_omega) == 2
        for row, (omega, tasks) in zip(rows, sorted(by_omega.items())):
            assert float(row["omega"]) == omega
            s = [f[f"tasks/{t.task_id:06d}/samples"] for t in tasks]
            steps = sum(t.n_steps for t in tasks)
            time = sum(t.n_steps * t.dt for t in tasks)
            starts = sum(int(x["n_overlaps"][:].sum()) for x in s)
            mids = sum(int(x["n_overlaps_midpoint"][:].sum()) for x in s)
            gaps = np.concatenate([x["min_gap"][:] for x in s])
            assert int(row["steps"]) == steps and int(row["n_tasks"]) == len(tasks)
            assert math.isclose(float(row["time"]), time, rel_tol=1e-12)
            assert math.isclose(float(row["steps_per_time"]), 1 / tasks[0].dt, rel_tol=1e-9)
            assert math.isclose(float(row["overlaps_per_time"]), starts / time, rel_tol=1e-12)
            assert math.isclose(float(row["overlaps_per_step"]), starts / steps, rel_tol=1e-12)
            assert math.isclose(float(row["midpoint_overlaps_per_time"]), mids / time,
                                rel_tol=1e-12)
            assert float(row["min_gap_min"]) == gaps.min()
            assert float(row["min_gap_median"]) == pytest.approx(np.median(gaps), rel=1e-12)
            # about a tenth of the steps below the 10% quantile
            assert abs(np.mean(gaps < float(row["min_gap_p10"])) - 0.1) <= 1 / len(gaps) + 0.01
            assert float(row["solver_iterations_per_step"]) == 0.0     # dense backend
            if mids / steps / job.system.n_particles > overlap_threshold(job, float(row["phi"]))[0]:
                assert "docs/reduce.md#trust-report" in err
                assert f"omega = {omega:.6g}: {mids / steps:.3g} overlapping pairs corrected " \
                    "per step at the Brownian midpoint" in err


def test_committed_samples_only_missing_fields_nan_and_warnings(tmp_path):
    run = tmp_path / "run.h5"
    text = job_text(realisations=2, phi="[0.3]")
    job = parse_job(text)
    done = job.discard_steps(6.283185307179586) + 3 * job.steps_per_period(6.283185307179586)
    write_run(run, text, MODULI, noise=0.002, seed=3, progress={0: done})
    with h5py.File(run, "a") as f:
        n = f["tasks/000000/samples/n_overlaps"]
        values = np.zeros(n.shape, dtype=np.int32)
        values[:done] = 1                   # one correction every step
        values[done:] = 1000                # never committed: must not count
        n[...] = values
        g = f["tasks/000000/samples/min_gap"]
        gaps = g[()]
        gaps[5] = -0.2
        gaps[done + 1] = -5.0               # not committed
        g[...] = gaps
    with pytest.warns(UserWarning):
        red = reduce_runs([run])
    rows = trust_rows(red)
    first = rows[0]
    tasks = [t for t in enumerate_tasks(job) if t.omega == rows[0]["omega"]]
    steps = done + tasks[1].n_steps
    assert first["steps"] == steps
    assert first["overlaps_per_step"] == pytest.approx(done / steps, rel=1e-12)
    assert first["min_gap_min"] == -0.2
    assert math.isnan(first["midpoint_overlaps_per_step"])   # not in this file
    text = "\n".join(warnings_of(red, rows))
    assert "overlapping pairs corrected per step at the start" in text
    assert "overlap of 0.2 radii" in text
    assert "phi = 0.3, omega = 25.1327" not in text     # the other group is clean


def test_near_contact_g_from_trajectories_equals_a_brute_force_count(tmp_path):
    """With trajectories, the trust report's g in the gap shells [0, 1e-3), [1e-3, 1e-2),
    [1e-2, 1e-1) equals a count over every frame of every task, the nearest image found by
    trying all 27 neighbouring Lees-Edwards cells (independent of Lattice.nearest_image),
    divided by the ideal-gas count; without trajectories the columns are NaN."""
    run = sdmpi_run(tmp_path / "run.h5", "--set", "output.trajectory_every=1")
    red = reduce_runs([run])
    rows = trust_rows(red)
    shells = np.array([0.0, 1e-3, 1e-2, 1e-1])
    with h5py.File(run) as f:
        job = parse_job(f.attrs["job_text"])
        for row, omega in zip(rows, sorted({t.omega for t in enumerate_tasks(job)})):
            counts, ideal = np.zeros(3), np.zeros(3)
            for task in (t for t in enumerate_tasks(job) if t.omega == omega):
                group = f[f"particles/task_{task.task_id:06d}"]
                done = int(f["progress"][task.task_id])
                radii = f[f"tasks/{task.task_id:06d}/radii"][()]
                for x, cell in zip(group["position/value"][:done], group["box/edges/value"][:done]):
                    images = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1)
                                       for k in (-1, 0, 1)]) @ cell
                    volume = abs(np.linalg.det(cell))
                    for p in range(len(x)):
                        for q in range(p + 1, len(x)):
                            r = np.linalg.norm(x[q] - x[p] + images, axis=1).min()
                            contact = radii[p] + radii[q]
                            counts += np.histogram([r - contact], shells)[0]
                            ideal += 4 * np.pi / 3 * ((contact + shells[1:]) ** 3
                                                      - (contact + shells[:-1]) ** 3) / volume
            expected = np.where(ideal > 0, counts / ideal, np.nan)
            got = [row["g_gap_1e-3"], row["g_gap_1e-2"], row["g_gap_1e-1"]]
            assert np.allclose(got, expected, rtol=1e-12, equal_nan=True)
            assert counts[2] > 0  # the outer shell is populated: the test compares numbers
    plain = trust_rows(reduce_runs([sdmpi_run(tmp_path / "plain.h5")]))
    assert all(np.isnan(r["g_gap_1e-1"]) for r in plain)


def test_group_labels_name_the_control_variable():
    from types import SimpleNamespace

    from sdmpi.analysis.trust import group_labels

    rows = [{"phi": 0.45, "omega": 25.132741228718345}]
    assert group_labels(SimpleNamespace(columns=("phi", "omega")), rows) == ["φ = 0.45, ω = 25.13"]
    rows = [{"phi": 0.3, "rate": 2.0}]
    assert group_labels(SimpleNamespace(columns=("phi", "rate")), rows) == ["φ = 0.3, γ̇ = 2"]


def reduction_of(n, geometry="bulk", model="stokesian", lubrication=True, min_gap=1e-4, backend="dense",
                 scheme=None):
    """A stand-in for the reduction warnings_of reads: the job's geometry, N,
    hydrodynamics, solver backend and drift scheme (Brownian)."""
    from types import SimpleNamespace

    return SimpleNamespace(columns=("phi", "rate"), job=SimpleNamespace(
        system=SimpleNamespace(geometry=geometry, n_particles=n),
        hydrodynamics=SimpleNamespace(model=model, lubrication=lubrication, min_gap=min_gap),
        solver=SimpleNamespace(backend=backend), ensemble=SimpleNamespace(ranks_per_task=1),
        brownian=SimpleNamespace(enabled=True, scheme=scheme)))


def overlap_row(per_step, phi=0.45):
    return {"phi": phi, "rate": 1.0, "overlaps_per_step": per_step, "midpoint_overlaps_per_step": 0.0,
            "min_gap_min": 0.0}


def test_monolayer_overlaps_are_reported_as_kept():
    """Monolayers keep and count their overlaps (Dratler & Schowalter 1996): the warning
    says so instead of "corrected"."""
    for geometry, word in (("monolayer", "kept"), ("bulk", "corrected")):
        red = reduction_of(27, geometry)
        assert f"2 overlapping pairs {word} per step at the start" in warnings_of(red, [overlap_row(2.0, 0.6)])[0]


def test_overlap_warning_without_lubrication_is_per_sphere():
    """The pairs near contact grow with N, and so the corrections per step of a given dt:
    without lubrication the warning compares the corrections per step and sphere with
    OVERLAPS_PER_SPHERE_WARN. 0.5 corrections per step warn at N = 27 (0.0185 per sphere),
    not at N = 1000 (5e-4); 4 per step at N = 1000 (4e-3) do."""
    def warned(n, per_step):
        return warnings_of(reduction_of(n, model="free-draining", lubrication=False), [overlap_row(per_step)])

    assert warned(27, 0.5) and not warned(1000, 0.5)
    assert "(0.004 per sphere, above 0.00075)" in warned(1000, 4.0)[0]
    assert not warned(27, 0.02)  # at the threshold: no warning


def test_overlap_warning_with_lubrication_against_the_exact_floor_rate():
    """With lubrication the warning compares the corrections with what the exact
    near-contact transition leaves below the floor (bench/floor_hits.json, phi = 0.45,
    min_gap = 1e-4, dt = 5e-4: 1.2-1.4e-3 per step and sphere): rfd with the near-contact
    correction (N = 125: 1.38e-3 on dense, 1.20e-3 on petsc-krylov; petsc-krylov N = 27:
    1.18e-3, 1.33e-3) passes, the midpoint
    (N = 125: dense 2.4e-3, petsc-krylov 2.9e-3; N = 1000: 2.5e-3) and the correction with
    kappa = 1 (N = 27: 3.0-3.4e-3) warn.
    The rate scales with phi g(2a) (Carnahan-Starling) and with the floor."""
    rows = [json.loads(line) for line in (ROOT / "bench" / "floor_hits.json").read_text().splitlines()]
    # the exact rate in the structure of runs whose step reproduces it (observed within 15%)
    exact = [r["exact_per_step"] / r["n_particles"] for r in rows if r["dt"] == 5e-4 and abs(r["ratio"] - 1) < 0.15]
    assert len(exact) >= 4
    assert min(exact) > FLOOR_RATE / 1.15 and max(exact) < FLOOR_RATE * 1.1

    def warned(n, per_step, phi=0.45, min_gap=1e-4):
        return warnings_of(reduction_of(n, min_gap=min_gap), [overlap_row(per_step, phi)])

    # each run at dt = 5e-4 is warned about exactly when it left more than 1.5 x its own exact
    # count below the floor (at dt = 2.5e-4 kappa = 1 is 1.4-1.5 x: under the bar)
    for r in (r for r in rows if r["dt"] == 5e-4):
        assert bool(warned(r["n_particles"], r["observed_per_step"])) is (r["ratio"] > 1.5), r
    assert warned(1000, 2.48)
    assert "above 1.5 x the 0.0013 that exact near-contact dynamics take below the floor" in warned(1000, 2.48)[0]
    # a scheme without the near-contact correction is named (petsc-krylov's default, or named)
    for backend, scheme in (("petsc-krylov", None), ("dense", "midpoint"), ("auto", None)):
        text = warnings_of(reduction_of(1000, backend=backend, scheme=scheme), [overlap_row(2.48)])[0]
        assert "the midpoint scheme takes no near-contact correction" in text, (backend, text)
    for backend, scheme in (("dense", None), ("petsc-krylov", "rfd")):
        text = warnings_of(reduction_of(125, backend=backend, scheme=scheme), [overlap_row(0.4)])[0]
        assert "near-contact correction" not in text, (backend, text)
    assert exact_floor_rate(0.45, 1e-4) == pytest.approx(FLOOR_RATE)
    # phi g(2a): 0.3 * 0.85 / 0.343 against 0.45 * 0.775 / 0.166375
    assert exact_floor_rate(0.3, 1e-4) / FLOOR_RATE == pytest.approx((0.3 * 0.85 / 0.343) / (0.45 * 0.775 / 0.166375))
    assert exact_floor_rate(0.45, 1e-5) == pytest.approx(FLOOR_RATE / 10)
    assert warned(125, 0.172, min_gap=1e-5) and not warned(125, 0.172)
