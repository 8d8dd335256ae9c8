"""Resource checks before any rank starts: memory (dense solvers, the start's cell list),
run-file size against free disk; `validate` estimates and warns, `run` refuses (exit 2,
the key named, nothing written)."""

import errno
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sdmpi.cli import main
from sdmpi.config import load_job, parse_job, resources
from sdmpi.ensemble import runner
from sdmpi.ensemble.store import run_file_bytes

from . import runs as ens

DEMO = str(Path(__file__).parents[1] / "jobs" / "demo.toml")
KRYLOV_JOB = Path(__file__).parents[1] / "jobs" / "large_n_krylov.toml"


def test_run_file_size_estimate(ensemble_job, tmp_path):
    """The estimate is within 5% of the file sdmpi writes (the samples are exact)."""
    out = tmp_path / "run.h5"
    assert ens.sdmpi("run", ensemble_job, "-o", out).returncode == 0
    assert run_file_bytes(load_job(ensemble_job)) == pytest.approx(out.stat().st_size, rel=0.05)


def test_dense_job_too_big_for_memory(ensemble_job, tmp_path, capsys):
    big = ["--set", "system.n_particles=125000"]
    assert main(["validate", str(ensemble_job), *big]) == 0  # may run elsewhere: a warning
    out = capsys.readouterr().out
    assert "memory: about 55 TiB per rank" in out  # 4 (11 N)^2 doubles + 300 MiB
    assert "WARNING: system.n_particles = 125000: the job needs about" in out
    res = ens.sdmpi("run", ensemble_job, "-o", tmp_path / "run.h5", *big)
    assert res.returncode == 2 and "system.n_particles = 125000" in res.stderr, res.stderr
    assert "Nothing written" in res.stderr and "Traceback" not in res.stderr
    assert os.listdir(tmp_path) == []  # nothing written


def test_krylov_job_too_big_for_memory(capsys):
    """petsc-krylov's memory grows with N (its bytes per sphere), so a large enough job
    is warned about by validate, the key and the backend's share named."""
    assert main(["validate", DEMO, "--set", 'solver.backend="petsc-krylov"',
                 "--set", "system.n_particles=10000000"]) == 0
    out = capsys.readouterr().out
    assert "WARNING: system.n_particles = 10000000: the job needs about" in out
    assert "petsc-krylov solver: ~39 KiB per sphere on every rank of a task and 68 KiB" in out


def test_krylov_memory_estimate_covers_the_measured_peaks():
    """At every (job, N, ranks) measured, the estimate per rank lies at or above the
    largest peak resident memory of a rank, and within 1.6 x of it: bench/memory.json (the
    peak within the parts of two steps, VmHWM) and bench/krylov_shares.json (the
    process's ru_maxrss). With the 300 MiB base the estimate is 1.06-1.28 x the peaks."""
    root = Path(__file__).parents[1]
    rows = [(r, max(max(p["peak_gib"] for p in rank["parts"].values()) for rank in r["per_rank"]))
            for r in json.loads((root / "bench" / "memory.json").read_text()).values()]
    rows += [(r, max(r["peak_rss_gib_per_rank"]))
             for r in json.loads((root / "bench" / "krylov_shares.json").read_text()).values()
             if "peak_rss_gib_per_rank" in r]
    assert {(r["n"], r["ranks"]) for r, _ in rows} >= {(1000, 1), (1000, 2), (4096, 2), (10000, 2)}
    for row, peak_gib in rows:
        job = load_job(str(root / row["job"]), row["overrides"])
        assert (job.system.n_particles, job.ensemble.ranks_per_task) == (row["n"], row["ranks"])
        need = resources.memory_per_rank(job, "petsc-krylov")
        peak = peak_gib * 2 ** 30
        assert peak <= need <= 1.6 * peak, (row["n"], row["ranks"], need / peak)


def test_free_draining_needs_no_dense_matrices(ensemble_job):
    """Free draining solves nothing: a 125000-sphere job needs the base memory and its
    start's cell list, not the 55 TiB of a dense one."""
    job = load_job(ensemble_job, overrides=["system.n_particles=125000", 'hydrodynamics.model="free-draining"'])
    assert resources.memory_per_rank(job, "dense") < 2 ** 30


def test_absurdly_dilute_job_refused(ensemble_job, tmp_path, capsys):
    dilute = ["--set", "system.phi=[1e-9]"]
    assert main(["validate", str(ensemble_job), *dilute]) == 2
    err = capsys.readouterr().err
    # a box of side (4 pi N / 3 phi)^(1/3) = 3222 in cells of side 2: 31.2 GiB of heads
    assert "system.phi = 1e-09: so dilute a box needs a start cell list of about 31.2 GiB" in err
    assert "allowed: phi >= 3.12e-08 for N = 8" in err
    res = ens.sdmpi("run", ensemble_job, "-o", tmp_path / "run.h5", *dilute)
    assert res.returncode == 2 and "start cell list" in res.stderr
    assert os.listdir(tmp_path) == []  # nothing written
    # the limit itself: a cell list of at most MAX_CELL_BYTES
    job = parse_job(ens.JOB, ["system.phi=[3.13e-8]"])
    assert resources.start_cells_bytes(job) <= resources.MAX_CELL_BYTES
    assert resources.start_problems(job) == []


def test_too_many_spheres_for_any_start_names_n_particles(ensemble_job, capsys):
    """When no volume fraction below the start's limit could bring the start's cell list
    down, the problem is the number of spheres (computed without a tuple of N radii)."""
    assert main(["validate", str(ensemble_job), "--set", "system.n_particles=1000000000000"]) == 2
    err = capsys.readouterr().err
    assert "system.n_particles = 1000000000000: needs a start cell list of about" in err, err
    assert "allowed: N below ~" in err and "system.phi" not in err


def test_disk_problem_names_the_length_key_of_the_protocol(monkeypatch):
    """Steady and quiescent jobs run integration.n_steps, oscillatory ones periods or a
    duration: the disk problem names the key the job sets its length with."""
    monkeypatch.setattr(shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(10 ** 9, 10 ** 9, 0))
    cases = [(ens.JOB, [], "integration.periods = 3"),
             (ens.JOB, ["integration.duration=10.0", "integration.discard_duration=1.0"],
              "integration.duration = 10.0"),
             (ens.JOB, ['shear.protocol="steady"', "shear.rate=1.0", "integration.dt=1e-3",
                        "integration.n_steps=100", "integration.discard_steps=0"], "integration.n_steps = 100")]
    for text, overrides, named in cases:
        job = parse_job(text, overrides)
        found = resources.disk_problems(job, 1e6, ".")
        assert len(found) == 1 and str(found[0]).startswith(named), str(found[0])


def test_run_file_too_big_for_the_disk(ensemble_job, tmp_path, monkeypatch, capsys):
    job = load_job(ensemble_job)
    monkeypatch.setattr(shutil, "disk_usage", lambda path: shutil._ntuple_diskusage(
        10 ** 9, 10 ** 9 - 1000, 1000))
    need = f"{run_file_bytes(job) / 1024:.0f}"  # the estimate is checked against the file elsewhere
    with pytest.raises(runner.BadInput, match=r"integration.periods = 3: the run file needs "
                                              rf"about {need} KiB, but .* has 0.977 KiB free"):
        runner._check_resources(job, "dense", ensemble_job, tmp_path / "run.h5", False, 1)
    assert main(["validate", str(ensemble_job), "-o", str(tmp_path / "run.h5")]) == 0
    assert "WARNING: integration.periods = 3: the run file needs" in capsys.readouterr().out
    assert os.listdir(tmp_path) == []  # nothing written


def test_validate_measures_the_cost(capsys):
    assert main(["validate", DEMO, "--ranks", "2", "--time-steps", "2"]) == 0
    out = capsys.readouterr().out
    assert "run file: about" in out and "memory: about" in out
    line = next(x for x in out.splitlines() if "cost (measured:" in x)
    m = re.search(r"measured: (\S+) s per step of task 0 \(mean of 2 steps, (\S+)-(\S+) s\) on 1 "
                  r"rank\(s\) of this machine\): ", line)
    assert m and "core-hours" in line
    mean, low, high = (float(x) for x in m.groups())
    assert 0 < low <= mean <= high  # the mean of the two steps lies within their range
    assert line.endswith("on 2 rank(s)")
    assert main(["validate", DEMO, "--time-steps", "1"]) == 0
    assert "s per step of task 0 (1 step) on 1 rank(s) of this machine): " in capsys.readouterr().out
    assert main(["validate", DEMO, "--ranks", "3", "--set", "ensemble.ranks_per_task=2"]) == 2


@ens.needs_mpi
def test_validate_times_a_task_on_its_ranks_under_mpirun():
    """A job of two ranks per task: alone, validate times one rank and says how to time the
    task's two (also as the single process of a Slurm batch script); under mpirun -n 2 it
    times the task on both, and rank 0 alone prints;
    under mpirun -n 3 it refuses (exit 2) and names the count."""
    small = ["--set", "system.n_particles=64", "--set", "ensemble.realisations=1"]
    cmd = [sys.executable, "-m", "sdmpi", "validate", str(KRYLOV_JOB), *small, "--time-steps", "2"]
    # a plain process of a Slurm batch script (SLURM_PROCID=0, one rank) times alone too
    alone = subprocess.run(cmd, capture_output=True, text=True, env=ens.child_env({"SLURM_PROCID": "0"}),
                           timeout=600)
    assert alone.returncode == 0, alone.stderr
    line = next(x for x in alone.stdout.splitlines() if "cost (measured:" in x)
    assert "on 1 rank(s) of this machine; a task runs on 2 ranks, whose step takes another" in line
    both = subprocess.run([ens.MPIRUN, "--oversubscribe", "-n", "2", *cmd], capture_output=True,
                          text=True, env=ens.child_env(), timeout=600)
    assert both.returncode == 0, both.stderr
    lines = [x for x in both.stdout.splitlines() if "cost (measured:" in x]
    assert len(lines) == 1
    m = re.search(r"measured: (\S+) s per step of task 0 \(mean of 2 steps, (\S+)-(\S+) s\) on 2 "
                  r"rank\(s\) of this machine\): ", lines[0])
    mean, low, high = (float(x) for x in m.groups())
    assert 0 < low <= mean <= high  # each step's slowest rank, then their mean
    assert both.stdout.count("job 'large-n-krylov': valid") == 1
    three = subprocess.run([ens.MPIRUN, "--oversubscribe", "-n", "3", *cmd], capture_output=True,
                           text=True, env=ens.child_env(), timeout=600)
    assert three.returncode == 2 and "start it with mpirun -n 2 (here 3)" in three.stderr


def test_full_file_system_is_recognised():
    assert runner._file_system_full(OSError(errno.ENOSPC, "No space left on device"))
    assert runner._file_system_full(OSError("Can't write data (file write failed: errno = "
                                            "28, error message = 'No space left on device')"))
    assert not runner._file_system_full(OSError(errno.EACCES, "Permission denied"))
    assert not runner._file_system_full(ValueError("No space left"))
