"""Structure and self-diffusion from H5MD trajectories (docs/trajectories.md).

Reads one particles group of an H5MD file (de Buyl et al., Comput. Phys. Commun. 185, 1546
(2014)): ``position`` (step, time, value (F, N, 3)) and the box ``edges`` (3,) or (3, 3),
fixed or per frame (rows = cell vectors). An sdmpi run file is H5MD; only its committed
frames are read, and its ``observables/<group>/strain`` gives the Lees-Edwards strain.

* :func:`pair_distribution`: the radial distribution function

      g(r) = V / (N (N - 1) / 2) < n(r, r + dr) > / (4 pi (r_2^3 - r_1^3) / 3),

  n the pairs with nearest-image distance in the shell, averaged over frames; exact for
  r_max up to half the smallest distance between opposite cell faces (the nearest image
  is then unique, :meth:`sdmpi.hydro.geometry.Lattice.nearest_image`).
* :func:`unwrap`: continuous positions u_j from positions wrapped into the (sheared) cell:
  u_{j+1} = u_j + nearest image of (x_{j+1} - u_j) in the cell of frame j + 1, correct
  while no particle moves more than half a cell width between frames. Under shear the
  cell's images move with the flow, so u is the motion in the unbounded sheared fluid.
* :func:`mean_squared_displacement`: per Cartesian component, averaged over particles and
  time origins, of the displacements in the frame convected by the imposed shear,
  s = u - gamma(t) y e_x (the affine part gamma y of the motion removed). For free
  diffusion with diffusion coefficient D, <ds_y^2> = <ds_z^2> = 2 D t, and
  ds_x = dW_x - gamma dy gives <ds_x^2> = 2 D int (1 + gamma^2) dt (a relative
  gamma0^2/2 more at small strain amplitude). The short-time self-diffusion coefficient
  is D_s = <ds_y^2 + ds_z^2> / (4 t) at lags t << t_D.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import h5py
import numpy as np

from ..config import parse_job
from ..ensemble.h5 import open_read
from ..hydro.geometry import Lattice


@dataclass(frozen=True)
class Trajectory:
    """One particles group's frames: step (F,), time (F,), positions (F, N, 3), cells
    (F, 3, 3) (rows L1, L2, L3), strain (F,) (the Lees-Edwards strain, NaN if unknown)."""

    step: np.ndarray
    time: np.ndarray
    positions: np.ndarray
    cells: np.ndarray
    strain: np.ndarray

    def lattice(self, frame: int) -> Lattice:
        """The periodic lattice of a frame (a Lees-Edwards cell when L2 has an x part)."""
        cell = self.cells[frame]
        box = np.array([cell[0, 0], cell[1, 1], cell[2, 2]])
        if np.any(cell[[0, 0, 1, 2, 2], [1, 2, 2, 0, 1]] != 0):
            raise ValueError("only cells with L1 along x, L2 in the x-y plane and L3 along z "
                             "(Lees-Edwards cells) are supported")
        return Lattice(box, cell[1, 0] / cell[1, 1])


    def largest_r(self) -> float:
        """Half the smallest distance between opposite cell faces over all frames: the
        largest r_max of :func:`pair_distribution`."""
        return min(0.5 / np.linalg.norm(self.lattice(k).reciprocal, axis=1).max()
                   for k in range(len(self.cells)))


def groups(path) -> list[str]:
    """The particles groups of an H5MD file."""
    with open_read(path) as f:
        return sorted(f["particles"]) if "particles" in f else []


def read(path, group: str | None = None) -> Trajectory:
    """The frames of ``group`` (default: the only particles group) of the H5MD file at
    ``path``; for an sdmpi run file only the committed ones. ValueError if unusable."""
    names = groups(path)
    if group is None:
        if len(names) != 1:
            raise ValueError(f"{path}: holds {len(names)} particles groups "
                             f"({', '.join(names[:5])}{'...' if len(names) > 5 else ''}); "
                             "name one")
        group = names[0]
    if group not in names:
        raise ValueError(f"{path}: no particles group {group!r} (it has "
                         f"{', '.join(names[:5]) or 'none'})")
    with open_read(path) as f:
        g = f[f"particles/{group}"]
        position = g["position"]
        frames = _committed_frames(f, group, len(position["value"]))
        step = position["step"][:frames]
        time = position["time"][:frames] if "time" in position else step.astype(float)
        positions = position["value"][:frames]
        edges = g["box/edges"]
        if isinstance(edges, h5py.Group):
            cells = edges["value"][:frames]
        else:
            cells = np.broadcast_to(edges[()], (frames, *edges.shape))
        if cells.ndim == 2:  # rectangular box: edge lengths
            cells = np.stack([np.diag(c) for c in cells])
        strain_path = f"observables/{group}/strain/value"
        if strain_path in f:
            strain = f[strain_path][:frames]
        else:
            strain = np.full(frames, np.nan)
    return Trajectory(step, time, positions, np.asarray(cells, dtype=float), strain)


def _committed_frames(f, group: str, stored: int) -> int:
    """Frames that hold data: those below /progress in an sdmpi run file, else all."""
    if f.attrs.get("format") != "sdmpi-run" or not group.startswith("task_"):
        return stored
    every = parse_job(f.attrs["job_text"]).output.trajectory_every
    done = int(f["progress"][int(group[5:])])
    return min(-(-done // every), stored)


# --------------------------------------------------------------------------- g(r)


def pair_distribution(traj: Trajectory, r_max: float, bins: int = 100):
    """(r (bins,) shell centres, g (bins,)): g(r) for 0 < r < r_max averaged over frames
    (module docstring). ValueError if r_max exceeds half the smallest cell width."""
    largest = traj.largest_r()
    if r_max > largest * (1 + 1e-12):
        raise ValueError(f"r_max = {r_max:g} exceeds half the smallest cell width "
                         f"({largest:.4g}, over all frames)")
    edges = np.linspace(0.0, r_max, bins + 1)
    counts, ideal = np.zeros(bins), np.zeros(bins)
    n = traj.positions.shape[1]
    for frame, x in enumerate(traj.positions):
        lattice = traj.lattice(frame)
        counts += pair_counts(x, lattice, edges)
        ideal += ideal_pair_counts(n, lattice.volume, edges)
    return 0.5 * (edges[1:] + edges[:-1]), counts / ideal


def pair_counts(positions, lattice, edges):
    """Pairs of one configuration (N, 3) per centre-separation shell [edges[k], edges[k+1]),
    nearest images in the lattice (`hydro.geometry.Lattice`)."""
    i, j = np.triu_indices(len(positions), k=1)
    r = np.linalg.norm(lattice.nearest_image(positions[j] - positions[i]), axis=1)
    return np.histogram(r, edges)[0]


def ideal_pair_counts(n, volume, edges):
    """Pairs per shell of `pair_counts` of n uncorrelated particles (g = 1) in a volume:
    n (n - 1)/2 (4 pi/3)(r_(k+1)^3 - r_k^3) / V; pair_counts over this is g."""
    edges = np.asarray(edges, dtype=float)
    return n * (n - 1) / 2 * 4.0 * math.pi / 3.0 * (edges[1:] ** 3 - edges[:-1] ** 3) / volume


# --------------------------------------------------------------------------- MSD


def unwrap(traj: Trajectory) -> np.ndarray:
    """Continuous positions u (F, N, 3) from the wrapped ones (module docstring)."""
    u = np.empty_like(traj.positions)
    u[0] = traj.positions[0]
    for frame in range(1, len(u)):
        moved = traj.positions[frame] - u[frame - 1]
        u[frame] = u[frame - 1] + traj.lattice(frame).nearest_image(moved)
    return u


def convected(traj: Trajectory) -> np.ndarray:
    """Positions s = u - gamma(t) y e_x in the frame convected by the shear (F, N, 3);
    the strain comes from the file, or from the cells when it holds none (then it is the
    reduced strain, |gamma| <= Lx/(2 Ly), which is the strain itself only below that)."""
    strain = traj.strain
    if np.any(np.isnan(strain)):
        strain = traj.cells[:, 1, 0] / traj.cells[:, 1, 1]
    s = unwrap(traj)
    s[..., 0] -= strain[:, None] * s[..., 1]
    return s


def mean_squared_displacement(traj: Trajectory, max_lag: int | None = None):
    """(lags (L,) in frames, lag times (L,), msd (L, 3) per component): the mean over
    particles and all time origins of the convected displacements at lags 1..max_lag
    frames (default: all). Frames must be equally spaced in time."""
    s = convected(traj)
    frames = len(s)
    if frames < 2:
        raise ValueError("a mean-squared displacement needs at least two frames")
    spacing = np.diff(traj.time)
    if not np.allclose(spacing, spacing[0], rtol=1e-9, atol=0):
        raise ValueError("frames are not equally spaced in time")
    lags = np.arange(1, (max_lag or frames - 1) + 1)
    msd = np.array([((s[lag:] - s[:-lag]) ** 2).mean(axis=(0, 1)) for lag in lags])
    return lags, lags * spacing[0], msd


def self_diffusion(lag_times, msd) -> np.ndarray:
    """D(t) = (<ds_y^2> + <ds_z^2>) / (4 t) per lag: the components the flow leaves alone."""
    return (msd[:, 1] + msd[:, 2]) / (4.0 * lag_times)
