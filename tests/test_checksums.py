"""Checksums over committed samples and checkpoint state: damage is found (by ``info``,
``reduce`` and on resume), named by task and step range, and repaired by resuming.

Fault injection: single bit flips at random places of the committed data (sample rows
before /progress, the current checkpoint slot's state and its checksums) of a run file
written by the test double; every flip must be reported, naming the flipped task (and the
dataset and block of a sample flip), and a resume must end with the uninterrupted run's
data bit for bit.
"""

import shutil

import h5py
import numpy as np
import pytest

from sdmpi.ensemble.store import read_summary

from . import runs as ens

TRIALS = 40


def committed_regions(path):
    """(task id, kind, name, file offset, bytes, bytes per row) of every committed region:
    the sample rows before /progress, the current slot's state datasets and checksums."""
    regions = []
    with h5py.File(path, "r") as f:
        progress = f["progress"][()]
        for key in f["tasks"]:
            tid, done = int(key), int(progress[int(key)])
            for name, ds in f[f"tasks/{key}/samples"].items():
                row = ds.dtype.itemsize * int(np.prod(ds.shape[1:]))
                regions.append((tid, "samples", name, ds.id.get_offset(), done * row, row))
            ckpt = f[f"checkpoints/{key}"]
            if done == 0:
                continue
            slot = int(np.flatnonzero(ckpt["slot_step"][()] == done)[0])
            for name, ds in ckpt[f"slot{slot}"].items():
                regions.append((tid, "state", name, ds.id.get_offset(), ds.id.get_storage_size(), 0))
            for name in ("sample_crc", "state_crc"):
                ds = ckpt[name]
                size = ds.id.get_storage_size() // 2  # one row per slot
                regions.append((tid, "state", name, ds.id.get_offset() + slot * size, size, 0))
    return regions


def flip(path, offset, bit):
    with open(path, "r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)[0]
        fh.seek(offset)
        fh.write(bytes([byte ^ (1 << bit)]))


def test_random_bit_flips_are_all_detected(ensemble_reference, tmp_path):
    regions = committed_regions(ensemble_reference)
    with h5py.File(ensemble_reference, "r") as f:
        block = int(f["checkpoints/000000/sample_crc"].attrs["block"])
    rng = np.random.default_rng(18)
    injected = detected = 0
    for trial in range(TRIALS):
        kinds = [r for r in regions if r[1] == ("samples", "state")[trial % 2]]
        tid, kind, name, offset, size, row = kinds[rng.integers(len(kinds))]
        at = int(rng.integers(size))
        damaged = tmp_path / f"flip{trial}.h5"
        shutil.copy(ensemble_reference, damaged)
        flip(damaged, offset + at, int(rng.integers(8)))
        injected += 1
        found = read_summary(damaged).damage
        assert all(d.task_id == tid for d in found), (name, [str(d) for d in found])
        if kind == "samples":
            step = at // row
            lo = step // block * block
            want = f"samples/{name} of steps {lo}..{min(lo + block, ens.N_STEPS) - 1} fail"
            assert [str(d) for d in found] == [f"task {tid}: {want} their checksum"]
        else:
            assert found and found[0].what == "state", (name, [str(d) for d in found])
        detected += bool(found)
        damaged.unlink()
    assert (injected, detected) == (TRIALS, TRIALS)


@pytest.mark.parametrize("kind, ranks", [("samples", None),
                                         pytest.param("state", 2, marks=pytest.mark.mpi)])
def test_damage_reported_then_repaired_by_resume(ensemble_reference, ensemble_job, tmp_path, kind, ranks):
    if ranks and ens.MPIRUN is None:
        pytest.skip("mpirun not found")
    regions = [r for r in committed_regions(ensemble_reference) if r[0] == 5 and r[1] == kind
               and r[2] in ("stress_brownian", "positions")]
    _, _, name, offset, size, _ = regions[0]
    out = tmp_path / "run.h5"
    shutil.copy(ensemble_reference, out)
    flip(out, offset + size // 2, 3)
    info = ens.sdmpi("info", out)
    assert info.returncode == 2 and "DAMAGED" in info.stderr and "task 5: " in info.stderr
    reduced = ens.sdmpi("reduce", out, "-o", tmp_path / "red", "--no-plots")
    assert reduced.returncode == 2, reduced.stderr  # with the task and the range
    if kind == "samples":
        assert "task 5: samples/stress_brownian of steps 20..29 fail" in reduced.stderr
    else:  # the checksums of the last interval were in the damaged checkpoint
        assert "task 5: samples of steps 40..47 cannot be verified" in reduced.stderr
    res = ens.sdmpi("run", ensemble_job, "-o", out, ranks=ranks)
    assert res.returncode == 0, res.stderr
    assert "WARNING: damaged: task 5" in res.stdout
    restart = 0 if kind == "samples" else 40  # samples: before the damage; state: older slot
    assert f"task 5: recomputing from step {restart} (committed up to 48)" in res.stdout
    assert ens.task_data(out) == ens.task_data(ensemble_reference)  # nothing lost
    info = ens.sdmpi("info", out)
    assert info.returncode == 0 and "checksums: every committed sample" in info.stdout


def test_damaged_state_of_a_stopped_run_falls_back(ensemble_reference, ensemble_job, tmp_path):
    """A run stopped mid-way, its current checkpoint's random-generator state damaged:
    the resume falls back to the other slot and still ends bit for bit."""
    out = tmp_path / "run.h5"
    res = ens.sdmpi("run", ensemble_job, "-o", out, env={"SDMPI_TEST_KILL": "step:25"})
    assert res.returncode != 0
    summary = read_summary(out)
    tid = next(t for t, p in enumerate(summary.progress) if 0 < p < ens.N_STEPS)
    region = next(r for r in committed_regions(out) if r[0] == tid and r[2] == "rng")
    flip(out, region[3] + 5, 0)
    summary = read_summary(out)
    assert [d.what for d in summary.damage] == ["state", "samples"]
    done = int(summary.progress[tid])
    assert summary.resume[tid][0] == done - 10  # the other slot, one checkpoint earlier
    res = ens.sdmpi("run", ensemble_job, "-o", out)
    assert res.returncode == 0, res.stderr
    assert ens.task_data(out) == ens.task_data(ensemble_reference)


def test_files_without_checksums_are_read_unverified(ensemble_reference, tmp_path):
    out = tmp_path / "old.h5"
    shutil.copy(ensemble_reference, out)
    with h5py.File(out, "r+") as f:
        for key in f["checkpoints"]:
            del f[f"checkpoints/{key}/sample_crc"], f[f"checkpoints/{key}/state_crc"]
    summary = read_summary(out)
    assert not summary.checksummed and summary.damage == ()
    info = ens.sdmpi("info", out)
    assert info.returncode == 0 and "checksums: none" in info.stdout


def test_damaged_unused_slot_of_a_complete_run_is_discarded(ensemble_reference, ensemble_job, tmp_path):
    """The older checkpoint slot of a complete task, damaged: nothing to recompute, the
    run marks the slot as never written and the file verifies again, data untouched."""
    out = tmp_path / "run.h5"
    shutil.copy(ensemble_reference, out)
    with h5py.File(out, "r") as f:
        ckpt = f["checkpoints/000003"]
        older = int(np.argmin(ckpt["slot_step"][()]))
        offset = ckpt[f"slot{older}/positions"].id.get_offset()
    flip(out, offset + 7, 6)
    assert [str(d) for d in read_summary(out).damage] == [
        f"task 3: checkpoint slot {older} (state at step 40) fails its checksum"]
    res = ens.sdmpi("run", ensemble_job, "-o", out)
    assert res.returncode == 0 and "already complete" in res.stdout, res.stderr
    assert "WARNING: damaged: task 3: checkpoint slot" in res.stdout
    assert read_summary(out).damage == ()
    assert ens.task_data(out) == ens.task_data(ensemble_reference)
