"""What a job needs of the machine, estimated from the job alone, and the checks made
against what is available before any rank starts (``sdmpi validate`` warns, ``sdmpi run``
refuses with exit 2).

Memory per rank, in bytes (estimates, documented in docs/cli.md):

* the solver backend's data (`sdmpi.registry.BackendSpec.memory_per_rank`): the direct
  backends hold about `sdmpi.registry.DENSE_MATRICES` matrices of the 11N x 11N FTS grand
  mobility / resistance problem (6 force/torque and 5 stresslet unknowns per sphere),
  8 bytes per entry, spread over the task's ranks by those that solve on several; a
  matrix-free backend declares its measured bytes per sphere (`petsc-krylov`:
  `sdmpi.registry.KRYLOV_BYTES` on every rank and `KRYLOV_SPREAD_BYTES` shared by the
  task's ranks); a model that solves nothing (free draining) needs none of them;
* the hard-sphere start's cell list: one 8-byte head per cell of side >= the contact
  distance 2 a_max, (L / 2 a_max)^3 cells for a cubic box of side L; a very dilute job
  (phi -> 0) makes L, and this list, explode: more than ``MAX_CELL_BYTES`` is refused on
  any machine;
* ``BASE_BYTES`` for the interpreter, numpy, numba and the compiled kernels.

Only the standard library is used, so that ``sdmpi validate`` stays fast.
"""

from __future__ import annotations

import math
import os
import shutil

from ..registry import HYDRODYNAMIC_MODELS, SOLVER_BACKENDS
from .problems import Problem
from .schema import START_PHI_LIMIT, quoted
from .tasks import enumerate_tasks

BASE_BYTES = 300 * 2 ** 20  # interpreter, libraries, compiled kernels
MEMORY_SHARE = 0.9          # of the available memory that a run may plan to use
MAX_CELL_BYTES = 2 ** 30    # largest start cell list accepted on any machine


def gib(n_bytes: float) -> str:
    """A byte count for people: '1.5 GiB', '300 MiB'."""
    for unit, scale in (("TiB", 2 ** 40), ("GiB", 2 ** 30), ("MiB", 2 ** 20)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 2 ** 10:.3g} KiB"


def dense_bytes(job, backend: str) -> float:
    """Bytes per rank of the resolved ``backend``'s data (`BackendSpec.memory_per_rank`;
    0 for a model that solves nothing)."""
    if not HYDRODYNAMIC_MODELS[job.hydrodynamics.model].solves:
        return 0.0
    return SOLVER_BACKENDS[backend].memory_per_rank(job.system.n_particles, job.ensemble.ranks_per_task)


def start_cells_bytes(job) -> float:
    """Bytes of the start's cell list at the smallest volume (areal) fraction."""
    system = job.system
    classes = list(zip(system.class_radii, system.class_counts))  # not a tuple of N radii
    reach = 2.0 * max(system.class_radii)
    phi = min(system.phi)
    if system.geometry == "monolayer":  # areal fraction of discs in a square cell
        side = math.sqrt(math.fsum(m * math.pi * r * r for r, m in classes) / phi)
        return max(side / reach, 1.0) ** 2 * 8.0
    side = (system.sphere_volume / phi) ** (1.0 / 3.0)
    return max(side / reach, 1.0) ** 3 * 8.0


def memory_per_rank(job, backend: str) -> float:
    """Estimated peak bytes of one rank running ``job`` with the resolved ``backend``."""
    return BASE_BYTES + max(dense_bytes(job, backend), start_cells_bytes(job))


def available_memory() -> float | None:
    """Bytes of memory available on this machine (MemAvailable of /proc/meminfo), or None
    where that is not known."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return None


def ranks_on_this_node(world_size: int) -> int:
    """Ranks sharing this machine's memory: the launcher's local size if it says
    (Open MPI, MPICH/Hydra, Slurm), else all ``world_size`` ranks."""
    for var in ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS", "SLURM_NTASKS_PER_NODE"):
        value = os.environ.get(var, "")
        if value.isdigit() and int(value) > 0:
            return int(value)
    return world_size


def start_problems(job) -> list[Problem]:
    """Problems of a job too dilute to start on any machine: a start cell list larger
    than MAX_CELL_BYTES."""
    cells = start_cells_bytes(job)
    if cells <= MAX_CELL_BYTES:
        return []
    system, need = job.system, min_phi(job, MAX_CELL_BYTES)
    # the densest start: START_PHI_LIMIT in bulk, the square lattice's pi/4 in a monolayer
    limit = START_PHI_LIMIT if system.geometry == "bulk" else math.pi / 4
    if need >= limit:  # no volume fraction helps: too many spheres
        fewer = int(system.n_particles * MAX_CELL_BYTES / cells * limit / min(system.phi))
        return [Problem("system.n_particles", f"needs a start cell list of about {gib(cells)} "
                        f"(at most {gib(MAX_CELL_BYTES)}), more than any volume fraction "
                        "can bring down", system.n_particles,
                        allowed=f"N below ~{fewer:.3g} (at phi near {limit:.3g})")]
    return [Problem("system.phi", f"so dilute a box needs a start cell list of about "
                    f"{gib(cells)} (at most {gib(MAX_CELL_BYTES)})", min(system.phi),
                    allowed=f"phi >= {need:.3g} for N = {system.n_particles}")]


def memory_problems(job, backend: str, ranks: int, available: float | None) -> list[Problem]:
    """Problems when ``ranks`` ranks of ``job`` on one machine would need more than
    MEMORY_SHARE of the ``available`` bytes (none when that is unknown)."""
    if available is None:
        return []
    need, allowed = memory_per_rank(job, backend), MEMORY_SHARE * available / ranks
    if need <= allowed:
        return []
    spec, lean = SOLVER_BACKENDS[backend], SOLVER_BACKENDS.names(lambda b: not b.dense_matrices)
    other = "" if backend in lean else f", or solver.backend = {quoted(lean)} (O(N) memory)"
    return [Problem("system.n_particles", f"the job needs about {gib(need)} per rank "
                    f"({backend} solver: {spec.memory_text()}; "
                    f"start cell list {gib(start_cells_bytes(job))}), more than the "
                    f"{gib(allowed)} available to each of {ranks} rank(s) here",
                    job.system.n_particles,
                    allowed=f"fewer particles, fewer ranks per machine{other}")]


def min_phi(job, cell_bytes: float) -> float:
    """The smallest volume (areal) fraction whose start cell list fits in ``cell_bytes``
    (the number of cells, (side / reach)^d, is proportional to 1 / phi)."""
    return min(job.system.phi) * start_cells_bytes(job) / max(cell_bytes, 8.0)


def disk_problems(job, run_file_bytes: float, directory) -> list[Problem]:
    """Problems when a run file of ``run_file_bytes`` will not fit in ``directory``."""
    free = shutil.disk_usage(directory).free
    if run_file_bytes <= free:
        return []
    integ = job.integration
    if job.shear.protocol != "oscillatory":
        key, value, fewer = "integration.n_steps", integ.n_steps, "fewer steps"
    elif integ.duration is not None:
        key, value, fewer = "integration.duration", integ.duration, "a shorter duration, fewer steps per period"
    else:
        key, value, fewer = "integration.periods", integ.periods, "fewer periods, steps per period"
    return [Problem(key, f"the run file needs about {gib(run_file_bytes)}, but {directory} has "
                    f"{gib(free)} free", value,
                    allowed=f"{fewer}, realisations, volume fractions or frequencies, "
                            "output.per_particle = false, or a file system with more room")]


def problems(job, backend: str, ranks: int, directory=None,
             run_file_bytes: float = 0.0) -> list[Problem]:
    """Every resource problem of ``job`` run by ``ranks`` ranks on this machine with the
    resolved ``backend``: too dilute to start, out of memory, and, given the
    ``directory`` of a run file still to be written, out of disk."""
    found = start_problems(job)
    if not found:
        busy = min(ranks, len(enumerate_tasks(job)) * job.ensemble.ranks_per_task)
        found = memory_problems(job, backend, busy, available_memory())
    if directory is not None:
        found += disk_problems(job, run_file_bytes, directory)
    return found
