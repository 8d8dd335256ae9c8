"""Tiny real runs of the Schaink et al. (2000) job files (N = 8, a few periods at 8 pi
and 16 pi, 2 realisations) for the reducer's end-to-end tests: `sdmpi run` as a user
runs it, one process each."""

import importlib.util
import subprocess
import sys
from pathlib import Path

from .runs import child_env

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--set", "system.n_particles=8",
        "--set", "shear.omega=[25.132741228718345, 50.26548245743669]",
        "--set", "integration.periods=3", "--set", "integration.discard_periods=1",
        "--set", "integration.steps_per_period=20", "--set", "integration.dt_max=0.01",
        "--set", "ensemble.realisations=2", "--set", "output.checkpoint_every=20"]
#: the Maxwell medium of the direct run (two modes, to test the sum over modes)
MODES = "[{eta = 0.6, lambda = 0.5}, {eta = 0.4, lambda = 0.05}]"
MEDIUM_SPEC = "maxwell:eta=0.6,lambda=0.5;eta=0.4,lambda=0.05"


def sdmpi_run(path, *extra, job="schaink2000_newtonian.toml", shrink=TINY):
    """Run jobs/<job> shrunk by ``shrink`` (default TINY, for the Schaink et al. jobs; and
    ``extra`` --set items) into ``path``."""
    cmd = [sys.executable, "-m", "sdmpi.cli", "run", str(ROOT / "jobs" / job), "-o",
           str(path), *shrink, *extra]
    res = subprocess.run(cmd, capture_output=True, text=True, env=child_env(), timeout=600)
    assert res.returncode == 0, res.stderr
    return path


def maxwell_run(path):
    """The same job in the Maxwell medium MODES, same job seed."""
    return sdmpi_run(path, "--set", 'medium.kind="maxwell"', "--set", f"medium.modes={MODES}")


def postprocess_script(name):
    """postprocess/<name>.py imported as a module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "postprocess" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
