"""system.start = "file": runs start from the positions of an HDF5, XYZ or run file
(frame 0 of the trajectory is the file's configuration, bit for bit, on one or two ranks
and with the real realisation); bad files are refused with the problem named, exit 2,
nothing written."""

import math

import h5py
import numpy as np
import pytest

from sdmpi.cli import main
from .runs import JOB, needs_mpi, sdmpi
from .test_ensemble_real import ROOT, SHORT
from .test_ensemble_real import sdmpi as real_sdmpi

N, PHI = 8, 0.3
SIDE = (N * 4 * math.pi / (3 * PHI)) ** (1 / 3)
START_JOB = JOB.replace("phi = [0.2, 0.3]", f"phi = [{PHI}]").replace(
    "checkpoint_every = 10\n", "checkpoint_every = 10\ntrajectory_every = 4\n")


def lattice_configurations(m, seed=1):
    """m configurations: a 2x2x2 lattice of spacing L/2 (gaps ~0.4) jiggled by 0.1."""
    grid = (np.arange(2) + 0.25) * SIDE / 2
    base = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), -1).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    return base + rng.uniform(-0.1, 0.1, (m, N, 3))


def write_h5(path, positions, box=(SIDE,) * 3, radii=None):
    with h5py.File(path, "w") as f:
        f["positions"], f["box"] = positions, np.array(box)
        if radii is not None:
            f["radii"] = radii
    return path


def write_xyz(path, frames, lattice=f'Lattice="{SIDE!r} 0 0 0 {SIDE!r} 0 0 0 {SIDE!r}"'):
    lines = []
    for frame in frames:
        lines += [str(len(frame)), lattice]
        lines += [f"S {float(x)!r} {float(y)!r} {float(z)!r} 1.0" for x, y, z in frame]
    path.write_text("\n".join(lines) + "\n")
    return path


def text_file(path, text):
    path.write_text(text)
    return path


def job_with_start(tmp_path, start, extra=""):
    path = tmp_path / "job.toml"
    path.write_text(START_JOB.replace("[system]\n", f'[system]\nstart = "file"\n'
                                      f'start_file = "{start}"\n{extra}'))
    return path


def first_frames(path):
    with h5py.File(path, "r") as f:
        return {name: g["position/value"][0] for name, g in f["particles"].items()}


@pytest.mark.parametrize("ranks", [None, pytest.param(2, marks=[needs_mpi, pytest.mark.mpi])])
def test_runs_start_from_the_file_bit_for_bit(tmp_path, ranks):
    confs = lattice_configurations(2)
    job = job_with_start(tmp_path, write_h5(tmp_path / "start.h5", confs))
    out = tmp_path / "run.h5"
    res = sdmpi("run", job, "-o", out, ranks=ranks)
    assert res.returncode == 0, res.stderr
    frames = first_frames(out)
    assert len(frames) == 4  # 2 omega x 2 realisations; realisation r starts from conf r
    for task, x0 in frames.items():
        realisation = int(task[-6:]) % 2
        np.testing.assert_array_equal(x0, confs[realisation])


def test_xyz_and_hdf5_starts_agree(tmp_path):
    confs = lattice_configurations(2)
    job_h5 = job_with_start(tmp_path, write_h5(tmp_path / "start.h5", confs))
    (tmp_path / "x").mkdir()
    job_xyz = job_with_start(tmp_path / "x", write_xyz(tmp_path / "s.xyz", confs))
    runs = []
    for job in (job_h5, job_xyz):
        out = job.parent / "run.h5"
        assert sdmpi("run", job, "-o", out).returncode == 0
        runs.append(first_frames(out))
    assert runs[0].keys() == runs[1].keys()
    for key in runs[0]:
        np.testing.assert_array_equal(runs[0][key], runs[1][key])


def test_a_real_run_starts_from_the_last_positions_of_another_run(tmp_path):
    job = ROOT / "jobs" / "demo.toml"
    sets = [*SHORT, "--set", "ensemble.realisations=1", "--set", "output.trajectory_every=10"]
    first = tmp_path / "first.h5"
    assert real_sdmpi("run", job, "-o", first, *sets).returncode == 0
    with h5py.File(first, "r") as f:
        done = f["progress"][0]
        slot = list(f["checkpoints/000000/slot_step"][()]).index(done)
        last = f[f"checkpoints/000000/slot{slot}/positions"][()]
    second = tmp_path / "second.h5"
    res = real_sdmpi("run", job, "-o", second, *sets, "--set", 'system.start="file"',
                     "--set", f'system.start_file="{first}"')
    assert res.returncode == 0, res.stderr
    np.testing.assert_array_equal(first_frames(second)["task_000000"], last)


def overlapping(tmp_path):
    confs = lattice_configurations(1)
    confs[0, 1] = confs[0, 0] + [0.0, 0.0, 1.95]  # gap -0.05 (its lattice neighbour in z)
    return write_h5(tmp_path / "bad.h5", confs)


@pytest.mark.parametrize("make, message", [
    (lambda p: p / "missing.h5", "no such file"),
    (lambda p: write_h5(p / "bad.h5", lattice_configurations(1)[:, :7]),
     "positions of shape (1, 7, 3)"),
    (lambda p: write_h5(p / "bad.h5", lattice_configurations(1), box=(5.0, 5.0, 5.0)),
     "not the job's cubic box at phi = 0.3"),
    (lambda p: write_h5(p / "bad.h5", lattice_configurations(1), radii=np.full(N, 0.9)),
     "radii that differ from the job's"),
    (overlapping, "1 pair(s) overlap by more than system.start_tolerance = 0.0001"),
    (lambda p: write_xyz(p / "bad.xyz", lattice_configurations(1), lattice="no box"),
     "the comment line gives no box"),
    (lambda p: text_file(p / "bad.txt", "hello\n"), "not an XYZ particle count"),
    (lambda p: write_h5(p / "bad.h5", np.array([b"x"] * 3)), "a dataset positions of type |S1 (not real numbers)"),
    (lambda p: write_h5(p / "bad.h5", lattice_configurations(1) * (1 + 0j)),
     "a dataset positions of type complex128 (not real numbers)"),
])
def test_bad_start_files_are_refused_and_nothing_is_written(tmp_path, capsys, make, message):
    job = job_with_start(tmp_path, make(tmp_path))
    out = tmp_path / "run.h5"
    res = sdmpi("run", job, "-o", out)
    assert res.returncode == 2, res.stdout
    assert "system.start_file" in res.stderr and message in res.stderr, res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists() and not (tmp_path / "run.h5.logs").exists()
    assert main(["validate", str(job)]) == 2
    assert message in capsys.readouterr().err


def test_start_tolerance_admits_shallow_overlaps(tmp_path):
    job = job_with_start(tmp_path, overlapping(tmp_path), "start_tolerance = 0.06\n")
    assert main(["validate", str(job)]) == 0


def test_the_start_file_is_needed_only_while_tasks_are_unstarted(tmp_path):
    start = write_h5(tmp_path / "start.h5", lattice_configurations(2))
    job = job_with_start(tmp_path, start)
    out = tmp_path / "run.h5"
    res = sdmpi("run", job, "-o", out, env={"SDMPI_TEST_KILL": "commit:3"})
    assert res.returncode != 0
    reference = tmp_path / "ref.h5"
    assert sdmpi("run", job, "-o", reference).returncode == 0
    with h5py.File(out, "r") as f:
        unstarted = int((f["progress"][()] == 0).sum())
    assert unstarted > 0
    start.unlink()  # tasks still to start need it: refused, named, nothing written
    res = sdmpi("run", job, "-o", out)
    assert res.returncode == 2 and "no such file" in res.stderr
    write_h5(start, lattice_configurations(2))
    assert sdmpi("run", job, "-o", out).returncode == 0
    start.unlink()  # a complete run needs no start file
    res = sdmpi("run", job, "-o", out)
    assert res.returncode == 0 and "already complete" in res.stdout
    assert first_frames(out).keys() == first_frames(reference).keys()
    for key, x0 in first_frames(out).items():
        np.testing.assert_array_equal(x0, first_frames(reference)[key])
