#!/usr/bin/env python3
"""Dratler & Schowalter, J. Fluid Mech. 325, 53 (1996), sec. 4.1: the overlaps per sphere
against the number of spheres N, from run files -> size.csv.

    postprocess/dratler1996_size.py RUN.h5 [RUN.h5 ...] [-o docs/validation/dratler1996/size]

Inputs: run files of jobs/dratler1996_size.toml (or of any monolayer job), all of one
model (the same interparticle.kind), one or more per N: files with the same
system.n_particles are reduced together, as ``sdmpi reduce`` reduces several files. Units:
a = 1, eta_m = 1, time (= strain) in 1/gamma_dot.

``size.csv``, one row per N (ascending) and areal fraction phi_a (descending):

* ``n_particles``, ``phi_a``, ``realisations``, ``strain`` (the longest committed);
* ``eta``, ``eta_err``: eta = 1 + eta_h + eta_p (the paper's eq. 6) with one standard error
  (the larger of the spread between the realisations and the blocking error within them);
* ``overlaps_mean``, ``overlaps_err``: the overlapping pairs per configuration, averaged over
  the samples after the start-up and before a stop, with one standard error of the same
  kind;
* ``per_sphere``, ``per_sphere_err``: the same divided by N (the paper's "about one overlap
  per two spheres, nearly independent of N");
* ``overlaps_max``, ``deepest_overlap`` (a, 0 if none) and ``stops`` (the strains at which
  realisations stopped on an overlap deeper than integration.overlap_stop).

The CSV file is byte-identical when the same run files are processed again. Exit status 2
with a message for an unusable run file or arguments.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from dratler1996 import committed_strain, write_csv  # noqa: E402
from monolayer_table import eta_of, overlap_statistics, reduce_model  # noqa: E402

from sdmpi.analysis.reduce import ReduceError, open_run  # noqa: E402

FIELDS = ["n_particles", "phi_a", "realisations", "strain", "eta", "eta_err", "overlaps_mean",
          "overlaps_err", "per_sphere", "per_sphere_err", "overlaps_max", "deepest_overlap",
          "stops"]


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("runs", nargs="+", metavar="RUN.h5", help="run files, one model, any N")
    p.add_argument("-o", "--output", default="docs/validation/dratler1996/size", metavar="OUTDIR")
    return p.parse_args(argv)


def files_by_size(files) -> dict[int, list[str]]:
    """{N: the run files with system.n_particles = N}; ReduceError unless every file is a
    monolayer run of the first file's model."""
    groups, kind = {}, None
    for path in files:
        job = open_run(path).job
        if job.system.geometry != "monolayer":
            raise ReduceError(f"{path}: not a monolayer job (system.geometry = "
                              f"{job.system.geometry!r})")
        kind = job.interparticle.kind if kind is None else kind
        if job.interparticle.kind != kind:
            raise ReduceError(f"{path}: interparticle.kind is {job.interparticle.kind!r}, "
                              f"the first file's is {kind!r}: give the runs of one model")
        groups.setdefault(job.system.n_particles, []).append(str(path))
    return groups


def size_rows(files, n) -> list[dict]:
    """The size.csv rows of the run files of one N."""
    red = reduce_model(files)
    rows = []
    for phi in sorted(set(red.phi.tolist()), reverse=True):
        eta, eta_err = eta_of(red, phi, "total")
        ov = overlap_statistics(files, phi)
        rows.append({"n_particles": n, "phi_a": phi, "realisations": ov["realisations"],
                     "strain": committed_strain(red, phi), "eta": eta, "eta_err": eta_err,
                     "overlaps_mean": ov["mean"], "overlaps_err": ov["err"],
                     "per_sphere": ov["mean"] / n, "per_sphere_err": ov["err"] / n,
                     "overlaps_max": ov["max"], "deepest_overlap": ov["deepest"],
                     "stops": " ".join(f"{s:.6g}" for s in ov["stops"])})
    return rows


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.output)
    try:
        groups = files_by_size(args.runs)
        rows = [row for n in sorted(groups) for row in size_rows(groups[n], n)]
        out.mkdir(parents=True, exist_ok=True)
    except (ReduceError, OSError, ValueError, KeyError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    write_csv(out / "size.csv", rows, FIELDS)
    print(f"wrote {out}/size.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
