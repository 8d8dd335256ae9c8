#!/usr/bin/env python3
"""g(r) and the mean-squared displacement of one H5MD trajectory.

    postprocess/trajectory_analysis.py FILE.h5 [--task ID | --group NAME] -o OUTDIR
        [--r-max R] [--bins B] [--max-lag L]

FILE.h5 is an sdmpi run file written with output.trajectory_every > 0 (one particles group
per task, task_NNNNNN; only committed frames are used) or any H5MD file with one
particles group (position and box/edges). sdmpi.analysis.trajectories does the work:

* g(r) for 0 < r < R (default: half the smallest cell width, the largest r for which the
  nearest image is unique), B shells, averaged over the frames: OUTDIR/gr.csv (r, g) and
  gr.png;
* the mean-squared displacement per component in the frame convected by the shear
  (s = u - gamma y e_x, u the unwrapped positions), at lags 1..L frames (default: up to
  100), and D(t) = (<ds_y^2> + <ds_z^2>)/(4 t), whose short-lag value is the short-time
  self-diffusion coefficient in units of D0 (time in t_D = a^2/D0, length in a):
  OUTDIR/msd.csv (lag_frames, lag_time, msd_x, msd_y, msd_z, D_yz) and msd.png.
  Unwrapping needs frames close enough that no particle moves half a cell width between
  them (trajectory_every x dt << L^2 / D0).

Exit status 2 with a message for an unusable file or arguments.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from sdmpi.analysis.trajectories import (mean_squared_displacement, pair_distribution, read,
                                         self_diffusion)


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("file", type=Path, help="H5MD file or sdmpi run file")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--task", type=int, help="task id (sdmpi run files)")
    which.add_argument("--group", help="particles group name")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUTDIR")
    parser.add_argument("--r-max", type=float, help="largest r of g(r), in a")
    parser.add_argument("--bins", type=int, default=100, help="shells of g(r)")
    parser.add_argument("--max-lag", type=int, default=100, help="largest lag in frames")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    group = f"task_{args.task:06d}" if args.task is not None else args.group
    try:
        traj = read(args.file, group)
        r_max = traj.largest_r() if args.r_max is None else args.r_max
        r, g = pair_distribution(traj, r_max, args.bins)
        max_lag = min(args.max_lag, len(traj.positions) - 1)
        lags, t, msd = mean_squared_displacement(traj, max_lag)
    except (OSError, KeyError, ValueError) as err:
        print(f"{args.file}: {err}", file=sys.stderr)
        return 2
    diffusion = self_diffusion(t, msd)
    args.output.mkdir(parents=True, exist_ok=True)
    np.savetxt(args.output / "gr.csv", np.column_stack([r, g]), delimiter=",",
               header="r,g", comments="", fmt="%.10g")
    np.savetxt(args.output / "msd.csv", np.column_stack([lags, t, msd, diffusion]),
               delimiter=",", header="lag_frames,lag_time,msd_x,msd_y,msd_z,D_yz",
               comments="", fmt="%.10g")
    plot(args.output, r, g, t, msd, diffusion, f"{args.file.name} {group or ''}".strip())
    print(f"{args.file} {group or ''}: {len(traj.positions)} frames of "
          f"{traj.positions.shape[1]} particles; g(r) up to r = {r_max:.4g} a; "
          f"D_s(t = {t[0]:.4g}) = {diffusion[0]:.4g} D0 -> {args.output}")
    return 0


def plot(outdir, r, g, t, msd, diffusion, title: str) -> None:
    """gr.png and msd.png in ``outdir``, titled with the run file and task."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(r, g)
    ax.axhline(1.0, color="0.6", lw=0.8)
    ax.set(xlabel="r / a", ylabel="g(r)", title=f"{title}: pair distribution")
    fig.tight_layout()
    fig.savefig(outdir / "gr.png", dpi=120)
    plt.close(fig)
    fig, (left, right) = plt.subplots(1, 2, figsize=(9, 3.5))
    for c, name in enumerate("xyz"):
        left.loglog(t, msd[:, c], label=f"<ds_{name}^2>")
    left.set(xlabel="t / t_D", ylabel="MSD / a^2")
    left.legend()
    right.semilogx(t, diffusion)
    right.set(xlabel="t / t_D", ylabel="D(t) / D0 (y, z)")
    fig.suptitle(f"{title}: mean-squared displacement")
    fig.tight_layout()
    fig.savefig(outdir / "msd.png", dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
