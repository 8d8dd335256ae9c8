"""``sdmpi reduce`` on awkward input and output paths (issue 18 defects 1 and 6): a run
with nothing analysed yet, a first group without data, outputs onto files or unwritable
places, a bad --task; outputs appear whole or not at all."""

import os
import stat

import pytest

from sdmpi.analysis.reduce import TABLE_COMPONENTS
from sdmpi.cli import main
from .synthetic_run import write_run
from .test_reduce import MODULI, job_text

FILES = {"moduli.csv", "moduli.h5", "units.json", "errors.csv", "trust.csv"}


def listing(path):
    return sorted(p.name for p in path.iterdir())


def test_nothing_analysed_exits_0_with_a_table_of_nan_rows_and_a_note(tmp_path, capsys):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, progress=0)
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "Traceback" not in err and "no realisation has data" in err
    assert "no figures for phi = 0.3" in err
    names = listing(out)
    assert FILES <= set(names) and not any(n.endswith(".png") for n in names)
    assert not any(".tmp" in n for n in names)
    lines = (out / "moduli.csv").read_text().splitlines()
    assert len(lines) == 1 + 2 * len(TABLE_COMPONENTS) and "nan" in lines[2]


def test_default_lissajous_task_comes_from_the_first_group_with_data(tmp_path, capsys):
    run = tmp_path / "run.h5"
    # phi = 0.3 only: group 0 = (0.3, 2 pi) holds tasks 0, 1 and gets no data
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002,
              progress={0: 0, 1: 0}, seed=3)
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out)]) == 0
    assert "no Lissajous" not in capsys.readouterr().err
    assert (out / "lissajous.png").is_file()
    from sdmpi.analysis.reduce import lissajous_data, reduce_runs
    with pytest.warns(UserWarning):
        red = reduce_runs([run])
    assert lissajous_data(red)["task_id"] in (2, 3)


def test_bad_task_writes_nothing(tmp_path, capsys):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002, seed=3)
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out), "--task", "99"]) == 2
    assert "no task 99" in capsys.readouterr().err
    assert not out.exists()
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["reduce", str(run), "-o", str(out), "--task", "99"]) == 2
    assert listing(out) == ["keep.txt"]
    # without the plots that use it, a bad --task is refused all the same
    for bad in ("99", "-1"):
        assert main(["reduce", str(run), "-o", str(out), "--task", bad, "--no-plots"]) == 2
        assert f"no task {bad}" in capsys.readouterr().err
    assert listing(out) == ["keep.txt"]


def test_output_onto_a_file_or_an_unwritable_place_is_refused(tmp_path, capsys):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002, seed=3)
    target = tmp_path / "afile"
    target.write_text("precious")
    assert main(["reduce", str(run), "-o", str(target)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "not a directory" in err and str(target) in err
    assert target.read_text() == "precious"
    if os.geteuid() != 0:                   # root writes anywhere
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(stat.S_IRUSR | stat.S_IXUSR)
        try:
            assert main(["reduce", str(run), "-o", str(locked / "out")]) == 2
            assert "cannot write" in capsys.readouterr().err
        finally:
            locked.chmod(stat.S_IRWXU)
    below_file = target / "out"
    assert main(["reduce", str(run), "-o", str(below_file)]) == 2
    assert "not a directory" in capsys.readouterr().err


def test_output_with_a_trailing_slash_is_a_directory(tmp_path):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002, seed=3)
    assert main(["reduce", str(run), "-o", f"{tmp_path / 'newdir'}/", "--no-plots"]) == 0
    assert (tmp_path / "newdir").is_dir()
    assert FILES <= set(listing(tmp_path / "newdir"))


def test_a_failure_while_writing_leaves_earlier_outputs_untouched(tmp_path, monkeypatch):
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2, phi="[0.3]"), MODULI, noise=0.002, seed=3)
    out = tmp_path / "out"
    assert main(["reduce", str(run), "-o", str(out), "--no-plots"]) == 0
    before = {n: (out / n).read_bytes() for n in listing(out)}
    from sdmpi.analysis import report

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(report, "write_h5", broken)
    assert main(["reduce", str(run), "-o", str(out), "--no-plots"]) == 2
    assert {n: (out / n).read_bytes() for n in listing(out)} == before


def test_a_closed_pipe_is_no_error(tmp_path):
    """`sdmpi reduce ... | true` (a reader that is gone before the table is printed, as
    `| head` after its lines): exit 0, no BrokenPipeError traceback, outputs whole."""
    import subprocess
    import sys
    run = tmp_path / "run.h5"
    write_run(run, job_text(realisations=2), MODULI, noise=0.002, seed=3)
    out = tmp_path / "out"
    cmd = (f"{sys.executable} -m sdmpi.cli reduce {run} -o {out} --no-plots | true; "
           f"exit ${{PIPESTATUS[0]}}")
    res = subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr and "BrokenPipe" not in res.stderr
    assert FILES <= set(listing(out))
