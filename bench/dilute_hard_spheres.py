"""Dilute hard spheres without hydrodynamic interactions: the collision moduli of sdmpi
against the exact O(phi^2) result (sdmpi.analysis.analytic.dilute_hard_sphere_moduli;
Cichocki & Felderhof 1991, Brady 1993). Runs jobs/dilute_free_draining.toml (N = 1000,
phi = 0.05, free draining) once per frequency with `sdmpi run` (the frequencies side by side), reduces it, and writes
bench/dilute_hard_spheres.json: per frequency, G'/phi^2 and G''/phi^2 of the `collision`
row of moduli.csv with one standard error, the exact values, and the contact value
g(2) = Pi_c/(4 phi n kT) of the same run (the trace of the collision stress; Carnahan-
Starling 1.137 at phi = 0.05) for the time step's bias. docs/physics.md tabulates it.

    nice -n 10 python bench/dilute_hard_spheres.py [--scale 1.0] [--runs DIR]
    python bench/dilute_hard_spheres.py --reduce DIR/dilute_w*.h5    # compare existing runs

--scale multiplies every run's duration; --runs keeps the run files; --reduce compares
run files of the job (partial ones too: their committed periods) without running.
tests/test_dilute_hard_spheres.py runs one short frequency through `start` and `compare`.
"""

import argparse
import json
import math
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import h5py
import numpy as np

from sdmpi.analysis.analytic import dilute_hard_sphere_moduli
from sdmpi.analysis.reduce import PartialRunWarning, reduce_runs
from sdmpi.dynamics.realisation import KT_REDUCED

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "jobs" / "dilute_free_draining.toml"
#: (omega, gamma0, dt_max, duration): gamma0 sqrt(2 omega) ~ 0.5, the strain of the contact
#: layer (thickness (2/omega)^1/2 a) relative to its thickness, and gamma0 omega <= 1.
#: The highest frequency takes the smaller step: its layer is 0.5 a thick.
FREQUENCIES = ((1.0, 0.35, 2e-3, 40.0), (3.0, 0.2, 2e-3, 60.0), (8.0, 0.125, 1e-3, 30.0))


def start(omega, gamma0, dt_max, duration, workdir, extra=()):
    """Start `sdmpi run` of the job at one frequency into workdir (extra: more --set items);
    returns (process, run file)."""
    run = Path(workdir) / f"dilute_w{omega:g}.h5"
    sets = [f"shear.omega=[{omega!r}]", f"shear.gamma0={gamma0!r}", f"integration.dt_max={dt_max!r}",
            f"integration.duration={duration!r}", *extra]
    cmd = [sys.executable, "-m", "sdmpi.cli", "run", str(JOB), "-o", str(run)]
    for item in sets:
        cmd += ["--set", item]
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True), run


def finish(process):
    """Wait for a run of `start`; RuntimeError with its messages if it failed."""
    _, err = process.communicate()
    if process.returncode != 0:
        raise RuntimeError(err)


def compare(run):
    """The collision moduli of one run file of the job (complete, or partial: its committed
    periods) against the exact O(phi^2) result. Returns a dict of the numbers."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PartialRunWarning)
        red = reduce_runs([run])
    phi, omega, gamma0 = float(red.phi[0]), float(red.control[0]), red.job.shear.gamma0
    row = {"omega": omega, "gamma0": gamma0, "phi": phi, "n_particles": red.job.system.n_particles}
    for col in ("G_prime", "G_prime_err", "G_dprime", "G_dprime_err"):
        row[col + "_over_phi2"] = red.value(phi, omega, "collision", col) / phi ** 2
    row["hydrodynamic_eta_prime"] = red.value(phi, omega, "hydrodynamic", "eta_prime")
    row["brownian_G_dprime"] = red.value(phi, omega, "brownian", "G_dprime")
    exact = dilute_hard_sphere_moduli(omega)
    row["exact_G_prime_over_phi2"], row["exact_G_dprime_over_phi2"] = float(exact[0]), float(exact[1])
    with h5py.File(run, "r") as f:
        task = f["tasks"][sorted(f["tasks"])[0]]
        committed = int(red.committed[0, 0])
        stress = task["samples/stress_collision"][:committed, :3]
        time = task["samples/time"][:committed]
        dt = float(time[1] - time[0])
    keep = time >= red.job.integration.discard_duration
    n = row["n_particles"]
    volume = n * (4 * math.pi / 3) / phi
    contact = -stress[keep].sum(axis=1) / 3 / (n / volume * KT_REDUCED * 4 * phi)
    blocks = contact[: len(contact) // 20 * 20].reshape(20, -1).mean(axis=1)
    row.update(dt=dt, steps=committed, contact_g2=float(contact.mean()),
               contact_g2_err=float(blocks.std(ddof=1) / math.sqrt(20)))
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", type=float, default=1.0)
    parser.add_argument("--runs", default=None, help="keep the run files in this directory")
    parser.add_argument("--reduce", nargs="+", metavar="RUN.h5", help="only compare these run files")
    parser.add_argument("--out", default=str(Path(__file__).with_name("dilute_hard_spheres.json")))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        if args.reduce:
            paths = args.reduce
        else:
            workdir = args.runs or tmp
            runs = [start(omega, gamma0, dt_max, duration * args.scale, workdir)
                    for omega, gamma0, dt_max, duration in FREQUENCIES]  # side by side, one process each
            for process, _ in runs:
                finish(process)
            paths = [run for _, run in runs]
        rows = [compare(path) for path in paths]
        for row in rows:
            print(f"omega = {row['omega']:g} (gamma0 {row['gamma0']:g}, dt {row['dt']:.3g}): "
                  f"G'/phi^2 = {row['G_prime_over_phi2']:.3f} +- {row['G_prime_err_over_phi2']:.3f} "
                  f"(exact {row['exact_G_prime_over_phi2']:.3f}), "
                  f"G''/phi^2 = {row['G_dprime_over_phi2']:.3f} +- {row['G_dprime_err_over_phi2']:.3f} "
                  f"(exact {row['exact_G_dprime_over_phi2']:.3f}); contact g(2) = {row['contact_g2']:.3f} "
                  f"+- {row['contact_g2_err']:.3f} ({row['steps']} steps)", flush=True)
    Path(args.out).write_text(json.dumps({"command": "nice -n 10 python bench/dilute_hard_spheres.py",
                                          "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
