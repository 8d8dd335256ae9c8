"""Starting configurations from a file (``system.start = "file"``, docs/trajectories.md).

Three kinds of ``system.start_file``, told apart by their content:

* an sdmpi run file: at each phi, the positions of the current checkpoint of every task
  with committed steps (in task-id order), its box and radii;
* any other HDF5 file: datasets ``positions`` (N, 3) or (M, N, 3), ``box`` (3,) (Lx, Ly,
  Lz) and optionally ``radii`` (N,), in units of a;
* an extended XYZ file: M frames of ``N`` / comment / N lines ``name x y z [radius]``,
  the comment holding ``Lattice="Lx 0 0 0 Ly 0 0 0 Lz"``.

At every phi of the job the file must give N particles, the job's cubic box L =
(sum_i 4 pi a_i^3 / (3 phi))^(1/3) (to a relative 1e-6), the job's radii (if it gives
radii, to 1e-9) and no pair overlapping by more than ``system.start_tolerance`` (surface
gap h = r - a_i - a_j >= -tolerance, with periodic images). Realisation r starts from
configuration r mod M; positions inside [0, L)^3 are used bit for bit, others are wrapped
into the box. :func:`load` raises :class:`StartError` naming the problem; it is called
before anything is written.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import h5py
import numpy as np

from ..config import Problem
from ..dynamics.initial import box_side
from ..hydro.geometry import Lattice
from ..hydro.lubrication import close_pairs
from . import store

if TYPE_CHECKING:
    from ..config.schema import Job
    from ..config.tasks import Task
    from ..dynamics.realisation import Realisation

BOX_RTOL = 1e-6
RADII_ATOL = 1e-9


class StartError(Exception):
    """A start file that cannot start this job; the message names the key and the problem."""


@dataclass(frozen=True)
class Start:
    """Validated starting configurations: phi -> (M, N, 3) positions in the job's box."""

    configurations: dict

    def positions(self, task: Task) -> np.ndarray:
        """The starting positions (N, 3) of a task.

        Args:
            task: the task (its phi and realisation index r).

        Returns:
            Configuration r mod M at the task's phi, shape (N, 3), in a.
        """
        confs = self.configurations[task.phi]
        return confs[task.realisation % len(confs)]


def load(job: Job) -> Start | None:
    """The job's validated start configurations, or None for a generated start.

    Args:
        job: the validated job (system.start, system.start_file, phi, radii).

    Returns:
        The configurations at every phi of the job, or None when system.start is not "file".

    Raises:
        StartError: the file cannot be read or does not fit the job.
    """
    system = job.system
    if system.start != "file":
        return None
    path = system.start_file
    sets = _read(path)
    radii = np.array(system.radii, dtype=float)
    configurations = {}
    for phi in system.phi:
        found = sets.get(phi, sets.get(None))
        if found is None:
            _fail(path, f"holds no committed configuration at phi = {phi:g} (it has "
                  f"{', '.join(f'{p:g}' for p in sets)})", "a run file of the same phi")
        configurations[phi] = _checked(path, job, phi, radii, *found)
    return Start(configurations)


def apply(realisation: Realisation, positions: np.ndarray) -> None:
    """Put the starting positions into a realisation's state (at step 0).

    Args:
        realisation: the realisation (anything with get_state and set_state).
        positions: starting positions, shape (N, 3), in a.
    """
    state = realisation.get_state()
    state["positions"] = np.array(positions, dtype=float)
    realisation.set_state(state)


# --------------------------------------------------------------------------- reading


def _fail(path, why, allowed=""):
    raise StartError(str(Problem("system.start_file", why, path, allowed=allowed)))


def _read(path) -> dict:
    """phi (None: any) -> (positions (M, N, 3), box (3,), radii (N,) or None)."""
    file = Path(path)
    if not file.is_file():
        _fail(path, "no such file" if not file.exists() else "not a file")
    try:
        if h5py.is_hdf5(file):
            return _read_hdf5(path)
        return {None: _read_xyz(path, file.read_text())}
    except (OSError, UnicodeDecodeError, KeyError, TypeError, ValueError) as err:
        _fail(path, f"cannot be read ({type(err).__name__}: {err})")


def _read_hdf5(path) -> dict:
    with h5py.File(path, "r") as f:
        is_run = f.attrs.get("format") == store.FORMAT
    if is_run:
        return _read_run(path)
    with h5py.File(path, "r") as f:
        missing = [k for k in ("positions", "box") if k not in f or
                   not isinstance(f[k], h5py.Dataset)]
        if missing:
            _fail(path, f"an HDF5 file without the dataset(s) {', '.join(missing)}",
                  "datasets positions (N, 3) or (M, N, 3), box (3,), optional radii (N,), "
                  "or an sdmpi run file")
        for name in ("positions", "box", "radii"):
            if name in f and isinstance(f[name], h5py.Dataset) and f[name].dtype.kind not in "fiu":
                _fail(path, f"a dataset {name} of type {f[name].dtype} (not real numbers)",
                      f"{name} as floating-point (or integer) numbers")
        positions = np.asarray(f["positions"][()], dtype=float)
        box = np.asarray(f["box"][()], dtype=float)
        radii = np.asarray(f["radii"][()], dtype=float) if "radii" in f else None
    if positions.ndim == 2:
        positions = positions[None]
    return {None: (positions, box, radii)}


def _read_run(path) -> dict:
    try:
        summary = store.read_summary(path)
    except store.StoreError as err:
        _fail(path, f"an unusable run file: {err}")
    sets = {}
    with h5py.File(path, "r") as f:
        for task, done, slot in zip(summary.tasks, summary.progress, summary.slots):
            if done == 0:
                continue
            key = store.task_key(task.task_id)
            group = f[f"tasks/{key}"]
            positions = f[f"checkpoints/{key}/slot{slot}/positions"][()]
            entry = sets.setdefault(task.phi, ([], group.attrs["box"], group["radii"][()]))
            entry[0].append(positions)
    if not sets:
        _fail(path, "a run file without committed steps", "a run file with progress")
    return {phi: (np.array(confs, dtype=float), np.asarray(box, dtype=float), radii)
            for phi, (confs, box, radii) in sets.items()}


_LATTICE = re.compile(r'Lattice\s*=\s*"([^"]*)"', re.IGNORECASE)


def _read_xyz(path, text: str):
    lines = text.splitlines()
    frames, boxes, radii, at = [], [], [], 0
    while at < len(lines):
        if not lines[at].strip():
            at += 1
            continue
        head = f"line {at + 1}"
        try:
            n = int(lines[at].split()[0])
        except ValueError:
            _fail(path, f"{head}: not an XYZ particle count ({lines[at][:40]!r})",
                  "an XYZ file: N, a comment line with Lattice=\"Lx 0 0 0 Ly 0 0 0 Lz\", "
                  "N lines 'name x y z [radius]'")
        if at + 2 + n > len(lines):
            _fail(path, f"{head}: a frame of {n} particles, but the file ends first")
        lattice = _LATTICE.search(lines[at + 1])
        if lattice is None:
            _fail(path, f"line {at + 2}: the comment line gives no box",
                  'Lattice="Lx 0 0 0 Ly 0 0 0 Lz" (extended XYZ)')
        try:
            cell = np.array(lattice.group(1).split(), dtype=float).reshape(3, 3)
        except ValueError:
            _fail(path, f"line {at + 2}: Lattice needs 9 numbers", 'Lattice="Lx 0 0 0 Ly 0 0 0 Lz"')
        if np.any(cell != np.diag(np.diag(cell))):
            _fail(path, f"line {at + 2}: a non-rectangular Lattice", "a rectangular box "
                  '(Lattice="Lx 0 0 0 Ly 0 0 0 Lz")')
        rows = [line.split() for line in lines[at + 2:at + 2 + n]]
        try:
            values = np.array([[float(v) for v in row[1:5]] for row in rows])
        except ValueError as err:
            _fail(path, f"frame at {head}: a particle line is not 'name x y z [radius]' "
                  f"({err})")
        if values.ndim != 2 or values.shape[1] not in (3, 4):
            _fail(path, f"frame at {head}: particle lines need 3 coordinates (and the same "
                  "number of columns on every line)", "'name x y z' or 'name x y z radius'")
        frames.append(values[:, :3])
        boxes.append(np.diag(cell))
        radii.append(values[:, 3] if values.shape[1] == 4 else None)
        at += 2 + n
    if not frames:
        _fail(path, "an empty XYZ file")
    if len({f.shape for f in frames}) > 1 or any(np.any(b != boxes[0]) for b in boxes):
        _fail(path, "XYZ frames with different particle counts or boxes",
              "every frame with the same N and box")
    if len({r is None for r in radii}) > 1 or (
            radii[0] is not None and any(np.any(r != radii[0]) for r in radii)):
        _fail(path, "XYZ frames with different radii", "the same radius column in every frame")
    return np.array(frames), boxes[0], radii[0]


# --------------------------------------------------------------------------- checks


def _checked(path, job, phi, radii, positions, box, file_radii) -> np.ndarray:
    """The configurations (M, N, 3) in the job's box, or StartError."""
    n = job.system.n_particles
    if positions.ndim != 3 or positions.shape[1:] != (n, 3) or len(positions) == 0:
        _fail(path, f"positions of shape {positions.shape[-3:] if positions.ndim >= 2 else positions.shape}",
              f"(N, 3) or (M, N, 3) with N = system.n_particles = {n}")
    if not np.all(np.isfinite(positions)):
        _fail(path, "positions that are not finite numbers")
    side = box_side(radii, phi)
    if box.shape != (3,) or not np.allclose(box, side, rtol=BOX_RTOL, atol=0):
        _fail(path, f"a box {np.asarray(box).tolist()}, not the job's cubic box at phi = "
              f"{phi:g}", f"box = [{side!r}] * 3 (L = (sum 4 pi a^3 / (3 phi))^(1/3), "
              f"relative tolerance {BOX_RTOL:g})")
    if file_radii is not None and (np.shape(file_radii) != (n,) or not np.allclose(
            file_radii, radii, rtol=0, atol=RADII_ATOL)):
        _fail(path, "radii that differ from the job's (system.size_classes, class by class)",
              f"{n} radii equal to the job's to {RADII_ATOL:g}, or no radii")
    lattice = Lattice(np.full(3, side), 0.0)
    tolerance = job.system.start_tolerance
    out = np.empty_like(positions)
    for m, conf in enumerate(positions):
        inside = np.all((conf >= 0.0) & (conf < side), axis=1)
        out[m] = np.where(inside[:, None], conf, lattice.wrap(conf))
        pairs = close_pairs(out[m], radii, lattice, cutoff=0.0)
        if len(pairs.gap) and pairs.gap.min() < -tolerance:
            worst = int(np.argmin(pairs.gap))
            deep = int(np.sum(pairs.gap < -tolerance))
            _fail(path, f"configuration {m}: {deep} pair(s) overlap by more than "
                  f"system.start_tolerance = {tolerance:g} (deepest: particles "
                  f"{pairs.i[worst]} and {pairs.j[worst]}, gap {pairs.gap[worst]:.4g})",
                  "surface gaps >= -start_tolerance (a raise of start_tolerance, or a "
                  "configuration without overlaps)")
    return out
