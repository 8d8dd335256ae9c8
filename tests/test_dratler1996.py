"""postprocess/dratler1996.py and dratler1996_sensitivity.py, the regeneration paths of
docs/validation/dratler1996/, on tiny real runs of its job files (N = 9 spheres, 40 steps,
2 realisations): the tables agree with `sdmpi reduce`, the neighbour count with a direct
count from the stored positions, the paired sensitivity with the realisations' own means,
the tables are byte-identical when regenerated, and bad input exits 2."""

import csv
import math

import h5py
import numpy as np
import pytest

from sdmpi.analysis.reduce import open_run
from sdmpi.cli import main as sdmpi_main
from sdmpi.ensemble.store import task_key
from .tiny_runs import postprocess_script, sdmpi_run

TINY = ["--set", "system.n_particles=9", "--set", "system.phi=[0.5]",
        "--set", "ensemble.realisations=2", "--set", "integration.n_steps=40",
        "--set", "integration.discard_steps=10", "--set", "output.trajectory_every=10",
        "--set", "output.checkpoint_every=20"]
#: postprocess/dratler1996.py as a module
SCRIPT = postprocess_script("dratler1996")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("dratler")
    hydro = sdmpi_run(d / "hydro.h5", job="dratler1996_hydro.toml", shrink=TINY)
    # a shorter range keeps pairs inside it in so few steps (the paper's tau = 1.25e6 acts
    # only below gaps of ~1e-5 a)
    rep = sdmpi_run(d / "repulsion.h5", "--set", "interparticle.tau=200.0", "--set",
                    "interparticle.f0=0.05", job="dratler1996_repulsion.toml", shrink=TINY)
    return hydro, rep


def rows(path):
    return list(csv.DictReader(open(path)))


def regenerate(runs, out):
    hydro, rep = runs
    return SCRIPT.main(["--hydro", str(hydro), "--repulsion", str(rep), "-o", str(out),
                          "--window", "0.05", "--no-plots"])


def test_tables_agree_with_sdmpi_reduce(runs, tmp_path):
    out = tmp_path / "d96"
    assert regenerate(runs, out) == 0
    table = {r["model"]: r for r in rows(out / "monolayer.csv")}
    assert set(table) == {"hydro", "repulsion"}
    for model, run in zip(("hydro", "repulsion"), runs):
        assert sdmpi_main(["reduce", str(run), "-o", str(tmp_path / model), "--no-plots"]) == 0
        assert ((out / model / "viscosity.csv").read_bytes()
                == (tmp_path / model / "viscosity.csv").read_bytes())
        total = {r["component"]: r for r in rows(tmp_path / model / "viscosity.csv")}
        assert float(table[model]["eta"]) == float(total["total"]["eta"])
        assert float(table[model]["eta_h"]) == float(total["hydrodynamic"]["eta"])
        assert float(table[model]["eta_p"]) == float(total["interparticle"]["eta"])
        assert table[model]["realisations"] == "2" and float(table[model]["strain"]) == 0.2
    assert float(table["hydro"]["eta_p"]) == 0.0
    assert float(table["repulsion"]["eta_p"]) > 0.0   # the repulsion acted
    # strain windows of 10 steps: those after the start-up (discard_steps = 10) average to
    # the table's eta, and the parts add up
    for model in ("hydro", "repulsion"):
        win = [r for r in rows(out / "windows.csv") if r["model"] == model]
        assert np.allclose([float(r["strain_from"]) for r in win], [0.0, 0.05, 0.1, 0.15])
        assert all(r["realisations"] == "2" for r in win)
        assert math.isclose(np.mean([float(r["eta"]) for r in win[1:]]),
                            float(table[model]["eta"]), rel_tol=1e-12)
        for r in win:
            assert math.isclose(float(r["eta"]), 1 + float(r["eta_h"]) + float(r["eta_p"]),
                                rel_tol=1e-12)
    # per realisation: the windows average to windows.csv's, and the overlaps per window are
    # those of the samples themselves
    for model, run in zip(("hydro", "repulsion"), runs):
        per = [r for r in rows(out / "realisation_windows.csv") if r["model"] == model]
        assert sorted({r["realisation"] for r in per}) == ["0", "1"] and len(per) == 8
        assert {r["seed"] for r in per} == {str(open_run(run).job.job.seed)}
        win = [r for r in rows(out / "windows.csv") if r["model"] == model]
        for w in win:
            both = [float(r["eta"]) for r in per if float(r["strain_from"]) == float(w["strain_from"])]
            assert math.isclose(np.mean(both), float(w["eta"]), rel_tol=1e-12)
        with h5py.File(run, "r") as f:
            for r in per:
                task = int(r["realisation"])   # one phi_a: task id = realisation
                k = round(float(r["strain_from"]) / 0.05)
                n = f[f"tasks/{task_key(task)}/samples"]["n_overlaps"][10 * k:10 * (k + 1)]
                assert float(r["overlaps_mean"]) == float(n.mean())
                assert int(r["overlaps_max"]) == int(n.max())
    ratio = rows(out / "ratio.csv")[0]
    eta_h, eta_r = float(table["hydro"]["eta"]), float(table["repulsion"]["eta"])
    assert math.isclose(float(ratio["ratio"]), eta_r / eta_h, rel_tol=1e-14)


def direct_neighbours(path, task, frame, rc):
    """n(rc) of one stored frame by the plain minimum-image rule in the (unsheared at
    frame 0) square cell: every pair's in-plane distance, periodic in x and y."""
    with h5py.File(path, "r") as f:
        x = f[f"particles/task_{task:06d}/position/value"][frame]
        edges = f[f"particles/task_{task:06d}/box/edges"]
        cell = edges["value"][frame] if isinstance(edges, h5py.Group) else edges[()]
    box = np.diag(cell) if np.ndim(cell) == 2 else np.asarray(cell)
    count = 0
    for i in range(len(x)):
        for j in range(i + 1, len(x)):
            d = x[j] - x[i]
            d[:2] -= box[:2] * np.round(d[:2] / box[:2])
            count += np.linalg.norm(d) < rc
    return 2.0 * count / len(x)


def test_neighbour_counts_equal_a_direct_count(runs, tmp_path):
    out = tmp_path / "d96"
    assert regenerate(runs, out) == 0
    table = rows(out / "neighbours.csv")
    first = [r for r in table if r["model"] == "hydro" and float(r["strain"]) == 0.0]
    assert len(first) == 1 and first[0]["realisations"] == "2"
    assert len([r for r in table if r["model"] == "hydro"]) == 4   # frames at strain 0 ... 0.15
    for rc in (2.00, 2.01, 2.05):
        want = np.mean([direct_neighbours(runs[0], t, 0, rc) for t in (0, 1)])
        assert math.isclose(float(first[0][f"n_{rc:.2f}"]), want, abs_tol=1e-12), rc
    # the cut-offs order the counts
    for r in table:
        assert float(r["n_2.00"]) <= float(r["n_2.01"]) <= float(r["n_2.05"])


def test_tables_are_byte_identical_when_regenerated(runs, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert regenerate(runs, a) == 0 and regenerate(runs, b) == 0
    for name in ("monolayer.csv", "ratio.csv", "neighbours.csv", "windows.csv",
                 "realisation_windows.csv", "hydro/viscosity.csv",
                 "repulsion/errors.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_bad_input_exits_2_and_writes_nothing(runs, tmp_path, capsys):
    hydro, rep = runs
    out = tmp_path / "bad"
    assert SCRIPT.main(["--hydro", str(rep), "-o", str(out)]) == 2
    assert "interparticle.kind is 'repulsion'" in capsys.readouterr().err
    assert SCRIPT.main(["--hydro", str(hydro), "--repulsion", str(hydro), "-o", str(out)]) == 2
    assert SCRIPT.main(["--hydro", str(tmp_path / "missing.h5"), "-o", str(out)]) == 2
    assert not out.exists()
    with pytest.raises(SystemExit) as exc:
        SCRIPT.main(["-o", str(out)])
    assert exc.value.code == 2


#: postprocess/dratler1996_sensitivity.py as a module
SENSITIVITY = postprocess_script("dratler1996_sensitivity")
#: the repulsion acts within so few steps only with a longer range (see `runs`)
SHORT_RANGE = ["--set", "interparticle.tau=200.0", "--set", "interparticle.f0=0.05"]


@pytest.fixture(scope="module")
def sensitivity_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("sensitivity")
    job = "dratler1996_sensitivity.toml"
    ref = sdmpi_run(d / "ref.h5", *SHORT_RANGE, job=job, shrink=TINY)
    f0 = sdmpi_run(d / "f0.h5", *SHORT_RANGE, "--set", "interparticle.f0=0.5", job=job, shrink=TINY)
    n12 = sdmpi_run(d / "n12.h5", *SHORT_RANGE, "--set", "system.n_particles=12", job=job, shrink=TINY)
    return ref, f0, n12


def test_sensitivity_table(sensitivity_runs, tmp_path):
    ref, f0, n12 = sensitivity_runs
    out = tmp_path / "s"
    args = ["--reference", str(ref), "--variant", f"gamma*=1={f0}", f"N=12={n12}", "-o", str(out)]
    assert SENSITIVITY.main(args) == 0
    table = {r["label"]: r for r in rows(out / "sensitivity.csv")}
    assert list(table) == ["reference", "gamma*=1", "N=12"]
    assert table["reference"]["changed"] == "" and float(table["reference"]["change"]) == 0.0
    assert table["gamma*=1"]["changed"] == "interparticle.f0=0.5"
    assert table["N=12"]["changed"] == "system.n_particles=12"
    # each realisation's time average (what the paired change is built from) averages to the
    # table's eta, which is sdmpi reduce's
    etas = {}
    for label, path in (("reference", ref), ("gamma*=1", f0)):
        n, eta = SENSITIVITY.task_etas(path)
        assert list(n) == [30, 30]
        etas[label] = np.nanmean(eta, axis=1)
        assert math.isclose(etas[label].mean(), float(table[label]["eta"]), rel_tol=1e-12)
        assert sdmpi_main(["reduce", str(path), "-o", str(tmp_path / label), "--no-plots"]) == 0
        total = {r["component"]: r for r in rows(tmp_path / label / "viscosity.csv")}
        assert float(table[label]["eta"]) == float(total["total"]["eta"])
    # the same starts: the change is paired, realisation by realisation
    per = (etas["gamma*=1"] - etas["reference"]) / etas["reference"]
    assert table["gamma*=1"]["paired"] == "1"
    assert math.isclose(float(table["gamma*=1"]["change"]), per.mean(), rel_tol=1e-12)
    assert math.isclose(float(table["gamma*=1"]["change_err"]), per.std(ddof=1) / math.sqrt(2),
                        rel_tol=1e-12)
    assert float(table["gamma*=1"]["eta_p"]) > float(table["reference"]["eta_p"])  # a 10x stronger force
    # other starts: the ratio of the means
    assert table["N=12"]["paired"] == "0"
    assert math.isclose(float(table["N=12"]["change"]),
                        float(table["N=12"]["eta"]) / float(table["reference"]["eta"]) - 1,
                        rel_tol=1e-12)
    again = tmp_path / "again"
    assert SENSITIVITY.main([*args[:-1], str(again)]) == 0
    assert (again / "sensitivity.csv").read_bytes() == (out / "sensitivity.csv").read_bytes()


def test_sensitivity_bad_input_exits_2(sensitivity_runs, tmp_path, capsys):
    ref, f0, _ = sensitivity_runs
    out = tmp_path / "bad"
    assert SENSITIVITY.main(["--reference", str(ref), "--variant", f"x={tmp_path / 'no.h5'}",
                             "-o", str(out)]) == 2
    assert "no.h5" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(SystemExit) as exc:
        SENSITIVITY.main(["--reference", str(ref), "--variant", str(f0), "-o", str(out)])
    assert exc.value.code == 2
    assert "LABEL=RUN.h5" in capsys.readouterr().err
    assert not out.exists()


def test_sensitivity_pairs_by_strain_when_the_step_changes(sensitivity_runs, tmp_path):
    """A variant with half the step, the same start-up strain and a shorter run is paired
    over the strain both runs committed: 40 of its samples against 20 of the reference's."""
    ref = sensitivity_runs[0]
    half = sdmpi_run(tmp_path / "half.h5", *SHORT_RANGE, "--set", "integration.dt=0.0025",
                     "--set", "integration.n_steps=60", "--set", "integration.discard_steps=20",
                     job="dratler1996_sensitivity.toml", shrink=TINY)
    out = tmp_path / "s"
    assert SENSITIVITY.main(["--reference", str(ref), "--variant", f"dt={half}", "-o", str(out)]) == 0
    row = rows(out / "sensitivity.csv")[1]
    assert row["paired"] == "1" and "integration.dt=0.0025" in row["changed"]
    (n_v, eta_v), (n_r, eta_r) = SENSITIVITY.task_etas(half), SENSITIVITY.task_etas(ref)
    assert list(n_v) == [40, 40] and list(n_r) == [30, 30]
    per = (eta_v[:, :40].mean(axis=1) - eta_r[:, :20].mean(axis=1)) / eta_r[:, :20].mean(axis=1)
    assert math.isclose(float(row["change"]), per.mean(), rel_tol=1e-12)


#: postprocess/dratler1996_size.py as a module
SIZE = postprocess_script("dratler1996_size")
#: a step and a floor so coarse that spheres overlap within 40 steps, and a deep stop
#: that lets some realisations run on with overlaps
OVERLAPPING = ["--set", "system.phi=[0.6]", "--set", "integration.dt=0.05",
               "--set", "hydrodynamics.min_gap=0.05", "--set", "integration.overlap_stop=0.2"]


@pytest.fixture(scope="module")
def size_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("size")
    job = "dratler1996_size.toml"
    n9 = sdmpi_run(d / "n9.h5", *OVERLAPPING, job=job, shrink=TINY)
    n9b = sdmpi_run(d / "n9b.h5", *OVERLAPPING, "--set", "job.seed=7", job=job, shrink=TINY)
    n16 = sdmpi_run(d / "n16.h5", *OVERLAPPING, "--set", "system.n_particles=16", job=job,
                    shrink=TINY)
    return n9, n9b, n16


def overlap_series(path):
    """Per task: (n_overlaps after the start-up and before a stop, the stop strain or None),
    read directly from the run file (a stopped task's later samples hold -1)."""
    out = []
    with h5py.File(path, "r") as f:
        for name in sorted(f["tasks"]):
            n = f[f"tasks/{name}/samples/n_overlaps"][:]
            stop = int(np.flatnonzero(n < 0)[0]) if (n < 0).any() else None
            out.append((n[10:stop], None if stop is None else stop * 0.05))
    return out


def test_size_table(size_runs, tmp_path):
    n9, n9b, n16 = size_runs
    out = tmp_path / "size"
    assert SIZE.main([str(n9), str(n16), str(n9b), "-o", str(out)]) == 0
    table = rows(out / "size.csv")
    assert [(r["n_particles"], r["phi_a"], r["realisations"]) for r in table] == [
        ("9", "0.6", "4"), ("16", "0.6", "2")]
    for row, files, n in ((table[0], (n9, n9b), 9), (table[1], (n16,), 16)):
        series = [s for path in files for s in overlap_series(path)]
        counts = [c for c, _ in series]
        mean = np.concatenate(counts).mean()
        assert mean > 0   # the coarse step overlaps
        assert math.isclose(float(row["overlaps_mean"]), mean, rel_tol=1e-12)
        assert math.isclose(float(row["per_sphere"]), mean / n, rel_tol=1e-12)
        assert math.isclose(float(row["per_sphere_err"]), float(row["overlaps_err"]) / n,
                            rel_tol=1e-12)
        assert int(row["overlaps_max"]) == max(c.max() for c in counts)
        stops = sorted(s for _, s in series if s is not None)
        assert sorted(float(s) for s in row["stops"].split()) == pytest.approx(stops)
        # the error is at least the spread of the realisations' means (sample-weighted)
        w = np.array([len(c) for c in counts], float)
        m = np.array([c.mean() for c in counts])
        spread = math.sqrt((w * (m - mean) ** 2).sum() / ((len(w) - 1) * w.sum()))
        assert float(row["overlaps_err"]) >= spread * (1 - 1e-12) > 0
    # eta is sdmpi reduce's over the files of one N together
    assert sdmpi_main(["reduce", str(n9), str(n9b), "-o", str(tmp_path / "r"), "--no-plots"]) == 0
    total = {r["component"]: r for r in rows(tmp_path / "r" / "viscosity.csv")}
    assert float(table[0]["eta"]) == float(total["total"]["eta"])
    again = tmp_path / "again"
    assert SIZE.main([str(n9), str(n16), str(n9b), "-o", str(again)]) == 0
    assert (again / "size.csv").read_bytes() == (out / "size.csv").read_bytes()


def test_size_bad_input_exits_2(size_runs, runs, tmp_path, capsys):
    out = tmp_path / "bad"
    assert SIZE.main([str(size_runs[0]), str(runs[1]), "-o", str(out)]) == 2
    assert "interparticle.kind is 'repulsion'" in capsys.readouterr().err
    assert SIZE.main([str(size_runs[0]), str(tmp_path / "no.h5"), "-o", str(out)]) == 2
    assert not out.exists()
