"""Trajectories inside the run file, in the H5MD layout (de Buyl, Colberg & Hoefling,
Comput. Phys. Commun. 185, 1546 (2014); H5MD 1.1). Layout and conventions: docs/store.md
and docs/trajectories.md.

With ``output.trajectory_every = K`` a task keeps a frame at every step k = 0, K, 2K, ...
below its n_steps: the positions at the start of step k (the realisation's state, wrapped
into the Lees-Edwards cell of strain gamma(t_k)), optionally the mean velocity over step k,
v_k = (x_{k+1} - x_k)/dt (nearest image at strain gamma(t_{k+1})), and the hydrodynamic
stresslets of step k. Frames are created with the rest of the file (preallocated, one
H5MD particles group per task) and written by the task's owner just before each
checkpoint commit, so ``/progress`` = p also commits the frames below step p:
``frames_done(p, K) = ceil(p / K)``, and a killed and resumed run ends with the same
frames as an uninterrupted one. :class:`TrajectoryWriter` is their
`sdmpi.ensemble.writers.Writer`.
"""

from __future__ import annotations

import getpass
import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import h5py
import numpy as np

from .. import __version__
from ..config import enumerate_tasks
from ..hydro.basis import from_five
from ..hydro.geometry import Lattice
from .h5 import new_dataset

if TYPE_CHECKING:
    from ..config.schema import Job
    from ..config.tasks import Task
    from ..dynamics.realisation import Realisation

H5MD_VERSION = (1, 1)
#: the optional elements: output key -> (element name, value shape per particle, unit)
EXTRAS = {"trajectory_velocities": ("velocity", (3,), "a/time unit"),
          "trajectory_stresslets": ("stresslet", (3, 3), "eta_m a^3/time unit")}


def group_name(task_id: int) -> str:
    """The H5MD particles (and observables) group of a task.

    Args:
        task_id: the task's id.

    Returns:
        The group name, task_NNNNNN.
    """
    return f"task_{task_id:06d}"


def n_frames(n_steps: int, every: int) -> int:
    """Frames of a task of n_steps steps, one every ``every`` steps from step 0.

    Args:
        n_steps: the task's steps.
        every: output.trajectory_every, >= 1.

    Returns:
        ceil(n_steps / every).
    """
    return -(-n_steps // every)


def frames_done(progress: int, every: int) -> int:
    """Frames committed when ``progress`` steps are: those at steps below it.

    Args:
        progress: committed steps of the task.
        every: output.trajectory_every, >= 1.

    Returns:
        ceil(progress / every).
    """
    return n_frames(progress, every)


def elements(job: Job) -> dict[str, tuple[tuple[int, ...], str]]:
    """element name -> (value shape per particle, unit) of the job's frames.

    Args:
        job: the validated job (output.trajectory_* keys, time unit).

    Returns:
        "position" and the optional elements the job asks for, in that order.
    """
    out = {"position": ((3,), "a")}
    for key, (name, shape, unit) in EXTRAS.items():
        if getattr(job.output, key):
            out[name] = (shape, unit.replace("time unit", job.time_unit))
    return out


#: bytes per task for the trajectory's groups, attributes and dataset headers (measured:
#: about 11 KiB)
TASK_OVERHEAD = 16 * 2 ** 10


def file_bytes(job: Job) -> int:
    """Bytes of every task's trajectory (0 without one): per frame the elements' values,
    the cell (3, 3), the strain, and one step and time shared by all, preallocated; plus
    TASK_OVERHEAD.

    Args:
        job: the validated job.

    Returns:
        The estimate, in bytes.
    """
    every = job.output.trajectory_every
    if not every:
        return 0
    n = job.system.n_particles
    per_frame = 8 * (sum(n * math.prod(shape) for shape, _ in elements(job).values()) + 9 + 1 + 2)
    return sum(n_frames(t.n_steps, every) * per_frame + TASK_OVERHEAD
               for t in enumerate_tasks(job))


class TrajectoryWriter:
    """The writer of the H5MD trajectories (`sdmpi.ensemble.writers.Writer`): enabled by
    output.trajectory_every >= 1."""

    def enabled(self, job: Job) -> bool:
        """Whether the job keeps a trajectory (output.trajectory_every >= 1)."""
        return bool(job.output.trajectory_every)

    def describe(self, job: Job, done: list[int]) -> str:
        """The frames committed in all (`frames_done` of each task) and where they are."""
        every = job.output.trajectory_every
        frames = sum(frames_done(p, every) for p in done)
        return (f"trajectory: H5MD, a frame every {every} steps, {frames} frames committed "
                "(particles/task_NNNNNN; docs/trajectories.md)")

    def create(self, f: h5py.File, job: Job, tasks: Iterable[Task], layouts: dict[int, Any]) -> None:
        """The /h5md group, then one H5MD particles group (and observables group) per task,
        ``n_frames(n_steps, trajectory_every)`` frames preallocated."""
        every = job.output.trajectory_every
        h5md = f.create_group("h5md")
        h5md.attrs["version"] = np.array(H5MD_VERSION, dtype="i4")
        h5md.create_group("author").attrs["name"] = _user()
        creator = h5md.create_group("creator")
        creator.attrs.update({"name": "sdmpi", "version": __version__})
        for task in tasks:
            _create_task(f, job, task, layouts[task.task_id], n_frames(task.n_steps, every))

    def recorder(self, job: Job, task: Task, realisation: Realisation, run_file: Any,
                 start: int) -> "Recorder":
        """Frames of the task, written through ``run_file.write``."""
        return Recorder(job, task, realisation.box, run_file.write)

    def carry_over(self, old: h5py.File, new: h5py.File, job: Job, task_id: int, done: int) -> None:
        """Copy the frames below step ``done`` (``frames_done(done, trajectory_every)``)."""
        frames = frames_done(done, job.output.trajectory_every)
        if not frames:
            return
        name = group_name(task_id)
        for top in ("particles", "observables"):
            def copy(path, obj):
                if isinstance(obj, h5py.Dataset) and path.split("/")[-1] in ("step", "time", "value"):
                    new[f"{top}/{name}/{path}"][:frames] = obj[:frames]

            old[f"{top}/{name}"].visititems(copy)

    def file_bytes(self, job: Job) -> float:
        """`file_bytes` of the job."""
        return float(file_bytes(job))


def _user() -> str:
    """The H5MD author: the login name of the user running sdmpi."""
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return "unknown"


def _create_task(f, job, task, layout, frames: int) -> None:
    n = layout.n_particles
    name = group_name(task.task_id)
    particles = f.create_group(f"particles/{name}")
    box = particles.create_group("box")
    box.attrs.update({"dimension": 3, "boundary": np.array([b"periodic"] * 3)})
    edges = _time_element(box, "edges", frames, (3, 3), "a")
    edges["value"].attrs["description"] = (
        "rows: the Lees-Edwards cell vectors L1 = (Lx, 0, 0), L2 = (g Ly, Ly, 0), "
        "L3 = (0, 0, Lz), g = the strain reduced to |g| <= Lx/(2 Ly)")
    step, time = edges["step"], edges["time"]
    for element, (shape, unit) in elements(job).items():
        _time_element(particles, element, frames, (n, *shape), unit, step, time)
    radius = new_dataset(particles, "radius", data=np.array(layout.radii or (1.0,) * n,
                                                            dtype="f8"))
    radius.attrs["unit"] = "a"
    strain = _time_element(f.require_group("observables").create_group(name), "strain",
                           frames, (), "1", step, time)
    strain["value"].attrs["description"] = (
        "Lees-Edwards strain gamma(t), not reduced: the image at +Ly is shifted in x by "
        "gamma Ly")


def _time_element(parent, name, frames, shape, unit, step=None, time=None):
    """An H5MD time-dependent element: step (frames,), time (frames,), value (frames,
    *shape), preallocated; step and time hard-linked from another element when given."""
    group = parent.create_group(name)
    if step is None:
        step = new_dataset(group, "step", (frames,), "i8")
        time = new_dataset(group, "time", (frames,), "f8")
    else:
        group["step"], group["time"] = step, time
    value = new_dataset(group, "value", (frames, *shape), "f8")
    value.attrs["unit"] = unit
    return group


class Recorder:
    """Collects one task's frames while it steps and writes them into the run file.

    Call :meth:`before` ahead of each step and :meth:`after` with the step's sample;
    :meth:`flush` puts the frames collected since the last call into the file (before
    the checkpoint commit that makes them valid)."""

    def __init__(self, job, task, box, write):
        """``write(path, rows, values)`` puts values into rows of the run file's dataset
        at ``path`` (sdmpi.ensemble.store.RunFile.write)."""
        from ..dynamics.setup import protocol_of

        self.every = job.output.trajectory_every
        self.dt, self.box = task.dt, np.asarray(box, dtype=float)
        self.protocol = protocol_of(job, task)
        self.elements = elements(job)
        self.sink = write
        self.group = f"particles/{group_name(task.task_id)}"
        self.strain = f"observables/{group_name(task.task_id)}/strain/value"
        self.pending = []   # frames (dicts) not yet written
        self._frame = None  # the frame of the current step, until after()

    def before(self, step: int, realisation: Realisation) -> None:
        """Start a frame when ``step`` is a frame step: the positions of the state.

        Args:
            step: the step about to be taken.
            realisation: the task's realisation, at the start of that step.
        """
        if step % self.every == 0:
            self._frame = {"step": step, "position": realisation.get_state()["positions"]}

    def after(self, step: int, sample: dict[str, np.ndarray], realisation: Realisation) -> None:
        """Complete the current frame with the step's sample (and velocity).

        Args:
            step: the step just taken.
            sample: the step's sample, name -> array with a leading axis of length 1.
            realisation: the task's realisation, after the step (velocity: positions in a,
                divided by dt in the time unit).
        """
        frame, self._frame = self._frame, None
        if frame is None:
            return
        frame["time"], frame["strain"] = float(sample["time"][0]), float(sample["strain"][0])
        if "velocity" in self.elements:
            moved = realisation.get_state()["positions"] - frame["position"]
            lattice = Lattice(self.box, self.protocol.strain((frame["step"] + 1) * self.dt))
            frame["velocity"] = lattice.nearest_image(moved) / self.dt
        if "stresslet" in self.elements:
            frame["stresslet"] = from_five(sample["stresslets"][0])
        self.pending.append(frame)

    def flush(self, stop: int) -> None:
        """Write the pending frames (consecutive frame indices, the frames below step
        ``stop``) into the file."""
        if not self.pending:
            return
        first = self.pending[0]["step"] // self.every
        stop = first + len(self.pending)
        frames, rows, edges = self.pending, slice(first, stop), f"{self.group}/box/edges"
        self.sink(f"{edges}/step", rows, np.array([fr["step"] for fr in frames]))
        self.sink(f"{edges}/time", rows, np.array([fr["time"] for fr in frames]))
        self.sink(f"{edges}/value", rows,
                  np.stack([Lattice(self.box, fr["strain"]).vectors for fr in frames]))
        self.sink(self.strain, rows, np.array([fr["strain"] for fr in frames]))
        for element in self.elements:
            self.sink(f"{self.group}/{element}/value", rows,
                      np.stack([fr[element] for fr in frames]))
        self.pending = []
