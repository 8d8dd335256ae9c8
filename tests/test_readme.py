"""README.md's quickstart runs as written: the block after the ``<!-- quickstart``
marker is run by bash from a fresh directory holding the repository's jobs/ and
postprocess/, with the `sdmpi` and `python` of this interpreter on PATH. Only the
Schaink et al. (2000) run is shrunk further (fewer, coarser steps) to keep the test short;
its job, frequencies and realisations stay as the README gives them."""

import csv
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from .runs import child_env

ROOT = Path(__file__).resolve().parents[1]
MARKER = "<!-- quickstart"
#: appended to the README's `sdmpi validate|run jobs/schaink2000_newtonian.toml` commands
SHRINK = ("--set integration.dt_max=0.01 --set integration.steps_per_period=20 "
          "--set integration.periods=3 --set integration.discard_periods=1")


def quickstart() -> list[str]:
    """The quickstart's commands, continuation lines joined."""
    text = (ROOT / "README.md").read_text()
    block = text[text.index(MARKER):].split("```sh\n", 1)[1].split("```", 1)[0]
    return [line.strip() for line in block.replace("\\\n", " ").splitlines() if line.strip()]


def shrunk(command: str) -> str:
    words = command.split()
    if "jobs/schaink2000_newtonian.toml" in words and ({"run", "validate"} & set(words)):
        return f"{command} {SHRINK}"
    return command


def test_quickstart_is_the_documented_workflow():
    commands = quickstart()
    verbs = [c.split()[c.split().index("sdmpi") + 1] if "sdmpi" in c.split() else c.split()[0]
             for c in commands]
    assert verbs == ["mkdir", "validate", "run", "info", "reduce", "validate", "run", "reduce",
                     "python"]
    assert all(c.startswith(("mkdir -p out", "sdmpi ", "mpirun -n 2 sdmpi ", "python postprocess/"))
               for c in commands)


@pytest.mark.mpi
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not found")
def test_quickstart_runs(tmp_path):
    for name in ("jobs", "postprocess"):
        (tmp_path / name).symlink_to(ROOT / name)
    env = child_env({"PATH": str(Path(sys.executable).parent) + os.pathsep + os.environ["PATH"]})
    script = "set -euo pipefail\n" + "\n".join(shrunk(c) for c in quickstart()) + "\n"
    res = subprocess.run(["bash", "-c", script], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=900)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    for table, omegas in (("out/demo/moduli.csv", 2), ("out/schaink/moduli.csv", 2)):
        rows = list(csv.DictReader((tmp_path / table).open()))
        assert len({r["omega"] for r in rows}) == omegas, table
        total = [r for r in rows if r["component"] == "total"]
        assert total and all(float(r["G_dprime"]) > 0 for r in total), table
    assert (tmp_path / "out/schaink/fig4.png").stat().st_size > 0
    assert "complete" in res.stdout
