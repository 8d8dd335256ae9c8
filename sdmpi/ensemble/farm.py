"""The task farm: which rank group runs which task.

Static assignment by the cost model (``Task.cost`` = steps x N^3, scaled by the fraction of
steps still to run): longest processing time first (LPT), each task to the least-loaded
group, ties broken by task id and group index. The assignment is a pure function of the
remaining costs and the group count, so every rank computes the same one without
communication; results never depend on it (a task is a pure function of job and id).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mpi4py import MPI

    from ..config.tasks import Task


def assign(costs: dict[int, float], n_groups: int) -> list[list[int]]:
    """LPT assignment of tasks (task id -> remaining cost) to ``n_groups`` groups.

    Returns one list of task ids per group, in the order the group runs them (longest
    first). Tasks with zero cost (finished) are left out.

    Args:
        costs: task id -> remaining cost (steps x N^3, arbitrary scale).
        n_groups: number of rank groups, >= 1.

    Returns:
        n_groups lists of task ids.

    Raises:
        ValueError: n_groups < 1.
    """
    if n_groups < 1:
        raise ValueError("need at least one group")
    order = sorted((tid for tid, c in costs.items() if c > 0), key=lambda t: (-costs[t], t))
    loads = [(0.0, g) for g in range(n_groups)]  # a heap of (load, group)
    groups: list[list[int]] = [[] for _ in range(n_groups)]
    for tid in order:
        load, g = heapq.heappop(loads)
        groups[g].append(tid)
        heapq.heappush(loads, (load + costs[tid], g))
    return groups


def remaining_costs(tasks: Iterable[Task], progress: Sequence[int]) -> dict[int, float]:
    """Task id -> cost of the steps still to run (``progress[task_id]`` steps are done).

    Args:
        tasks: the job's tasks.
        progress: steps done, indexed by task id.

    Returns:
        Task id -> remaining cost (the cost model's units, steps x N^3).
    """
    return {t.task_id: t.cost * (t.n_steps - int(progress[t.task_id])) / t.n_steps
            for t in tasks}


def split_groups(comm: MPI.Intracomm, ranks_per_task: int) -> tuple[MPI.Intracomm, int, int]:
    """Split ``comm`` into groups of ``ranks_per_task`` consecutive ranks.

    Returns (group communicator, group index, number of groups). The caller has checked
    that ``ranks_per_task`` divides ``comm.size``. Rank 0 of each group is its leader: the
    only one that writes the group's tasks to the store.

    Args:
        comm: the communicator of all ranks (collective).
        ranks_per_task: ranks per group, dividing comm.size.

    Returns:
        (group communicator, group index, number of groups).
    """
    group = comm.rank // ranks_per_task
    sub = comm.Split(color=group, key=comm.rank)
    return sub, group, comm.size // ranks_per_task
