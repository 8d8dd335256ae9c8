"""Provenance across library stacks: every session that writes a run file (creation,
resume, extension) records its sdmpi and library stack in /sessions; a resume under
another stack warns once and is recorded; `sdmpi info` lists the history."""

from .runs import JOB, sdmpi


def other_stack(*args, env=None):
    """``sdmpi ARGS`` with the test double, reporting numpy's version as "0.0-other"."""
    return sdmpi("--stack", "numpy=0.0-other", *args, env=env)


def test_resume_under_another_stack_warns_and_is_recorded(tmp_path):
    from sdmpi.ensemble.runner import versions
    from sdmpi.ensemble.store import read_summary

    job = tmp_path / "job.toml"
    job.write_text(JOB)
    out = tmp_path / "run.h5"
    assert sdmpi("run", job, "-o", out, env={"SDMPI_TEST_KILL": "step:100"}).returncode != 0
    first = read_summary(out).sessions
    assert [s["mode"] for s in first] == ["new"] and first[0]["versions"] == versions()
    for key in ("python", "numpy", "scipy", "numba", "h5py", "hdf5", "mpi4py", "MPI",
                "petsc4py", "sdmpi source", "BLAS kernels"):
        assert key in first[0]["versions"]

    res = other_stack("run", job, "-o", out, env={"SDMPI_TEST_KILL": "step:100"})
    assert res.returncode != 0
    assert res.stdout.count("WARNING") == 1
    assert f"numpy {versions()['numpy']} -> 0.0-other" in res.stdout
    assert "not bit for bit" in res.stdout

    res = sdmpi("run", job, "-o", out)  # back on this stack: warned again, then complete
    assert res.returncode == 0 and f"numpy 0.0-other -> {versions()['numpy']}" in res.stdout
    sessions = read_summary(out).sessions
    assert [s["mode"] for s in sessions] == ["new", "resume", "resume"]
    assert sessions[1]["versions"]["numpy"] == "0.0-other"

    info = sdmpi("info", out)
    assert info.returncode == 0, info.stderr
    assert "sessions: 3" in info.stdout and "as created" in info.stdout
    assert f"resume  numpy {versions()['numpy']} -> 0.0-other" in info.stdout


def test_resume_on_the_same_stack_says_nothing(tmp_path):
    job = tmp_path / "job.toml"
    job.write_text(JOB)
    out = tmp_path / "run.h5"
    assert sdmpi("run", job, "-o", out, env={"SDMPI_TEST_KILL": "step:100"}).returncode != 0
    res = sdmpi("run", job, "-o", out)
    assert res.returncode == 0 and "WARNING" not in res.stdout
    assert "resume  same stack" in sdmpi("info", out).stdout
