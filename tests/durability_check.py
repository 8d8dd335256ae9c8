"""Durability on an install: SIGKILLs at random instants keep every committed checkpoint.

Run with the Python of the install to check (``make pip-check`` uses a virtual
environment made by pip without system packages: serial h5py from a wheel):

    python tests/durability_check.py [--ranks 1 2] [--kills 5] [--seed S]

For each rank count: an uninterrupted reference run of a short demo job; then one run
killed (SIGKILL to every process) at ``--kills`` random instants, each time resumed. Before
each kill, ``sdmpi info`` reads the live file; after it, the file must hold at least the
steps that read saw committed (never fewer), verify, and the final data and
``sdmpi reduce`` tables must equal the reference's bit for bit. Prints what it saw; exit
status 0 when everything holds, 1 otherwise.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "jobs" / "demo.toml"
SETS = ["--set", "integration.periods=40", "--set", "output.checkpoint_every=40"]
SDMPI = [sys.executable, "-m", "sdmpi"]


def env() -> dict:
    out = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_rmaps_base_oversubscribe="1")
    return {k: v for k, v in out.items() if not k.startswith(("SDMPI_TEST", "OMPI_COMM"))}


def command(ranks: int, *args) -> list[str]:
    cmd = [*SDMPI, *map(str, args)]
    return ["mpirun", "--oversubscribe", "-n", str(ranks), *cmd] if ranks > 1 else cmd


def committed(path: Path) -> int | None:
    """Steps committed in all, as ``sdmpi info`` reads them (None: info failed)."""
    res = subprocess.run([*SDMPI, "info", str(path)], capture_output=True, text=True, env=env())
    match = re.search(r"tasks complete, (\d+)/\d+ steps", res.stdout)
    if res.returncode != 0 or match is None:
        print(f"    info failed (exit {res.returncode}): {res.stderr.strip()[:300]}")
        return None
    return int(match.group(1))


def task_data(path: Path) -> dict:
    out = {}
    with h5py.File(path, "r") as f:
        f["tasks"].visititems(lambda name, obj: out.__setitem__(name, obj[()].tobytes())
                              if isinstance(obj, h5py.Dataset) else None)
    return out


def reduce_table(run: Path, where: Path) -> Path:
    subprocess.run([*SDMPI, "reduce", str(run), "-o", str(where), "--no-plots"], check=True,
                   capture_output=True, env=env())
    return where / "moduli.csv"


def killed_run(ranks: int, out: Path, kills: int, rng: random.Random) -> bool:
    """Kill a run ``kills`` times at random instants, resuming each time; then finish it.
    Returns True when every kill kept what info had seen committed."""
    ok = True
    for k in range(kills):
        proc = subprocess.Popen(command(ranks, "run", JOB, "-o", out, *SETS),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env=env(), start_new_session=True)
        deadline = time.monotonic() + 300
        while not out.exists() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
        time.sleep(rng.uniform(1.0, 3.0))
        seen = committed(out)
        if proc.poll() is not None:
            print(f"  kill {k + 1}: the run ended before the kill (exit {proc.returncode}); "
                  "no more kills")
            break
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        after = committed(out)
        good = seen is not None and after is not None and after >= seen
        ok &= good
        print(f"  kill {k + 1}: committed {seen} steps before the kill, {after} after it: "
              f"{'kept' if good else 'LOST'}")
    res = subprocess.run(command(ranks, "run", JOB, "-o", out, *SETS), capture_output=True,
                         text=True, env=env())
    if res.returncode != 0:
        print(f"  resume failed (exit {res.returncode}): {res.stderr[-500:]}")
        return False
    return ok


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--seed", type=int, default=None)
    args = parser.parse_args(argv)
    seed = random.SystemRandom().randrange(2 ** 32) if args.seed is None else args.seed
    import h5py as _h5py
    print(f"durability check: h5py {_h5py.version.version} (HDF5 "
          f"{_h5py.version.hdf5_version}, MPI {bool(_h5py.get_config().mpi)}), seed {seed}")
    rng = random.Random(seed)
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        ref = tmp / "reference.h5"
        subprocess.run([*SDMPI, "run", str(JOB), "-o", str(ref), *SETS], check=True,
                       capture_output=True, env=env())
        ref_table = reduce_table(ref, tmp / "reference")
        for ranks in args.ranks:
            if ranks > 1 and shutil.which("mpirun") is None:
                print(f"{ranks} ranks: mpirun not found, skipped")
                continue
            print(f"{ranks} rank(s), {args.kills} SIGKILLs at random instants:")
            out = tmp / f"killed{ranks}.h5"
            good = killed_run(ranks, out, args.kills, rng)
            same = task_data(out) == task_data(ref)
            table = filecmp.cmp(reduce_table(out, tmp / f"killed{ranks}"), ref_table,
                                shallow=False)
            print(f"  final data equal to the uninterrupted run's: {same}; moduli.csv "
                  f"identical: {table}")
            ok &= good and same and table
    print("durability check:", "passed" if ok else "FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
