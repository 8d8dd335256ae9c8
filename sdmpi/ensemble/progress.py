"""Aggregate progress over ranks, printed by world rank 0; per-rank logs; the run lock.

Every group leader counts its steps and finished tasks; leaders other than rank 0 send
their running totals to rank 0 (small non-blocking messages, at most one a second, and a
final one when they are done). Rank 0 polls for them between its own steps and prints
tasks done, steps done, steps/s and the ETA: a live line on a terminal (every second),
plain lines otherwise, every 5 s at first, then every elapsed/10 (at most every 5 min).
Under mpirun the ranks' stdout is a pseudo-terminal whatever mpirun's own stdout is, so
there the plain lines are used.
"""

from __future__ import annotations

import fcntl
import logging
import os
import socket
import sys
import time
from collections.abc import Callable
from pathlib import Path

TAG = 0x5D
SEND_EVERY = 1.0            # s, leaders -> rank 0
LIVE_EVERY = 1.0            # s, live line on a terminal
LINES_EVERY = (5.0, 300.0)  # s, plain lines: bounds of elapsed / 10
LAUNCHER_VARS = ("OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK")


class PipeSafe:
    """A text stream whose reader may go away (``sdmpi run ... | head``): once a write
    finds the pipe broken, further output is dropped and the run goes on (the per-rank
    logs keep everything)."""

    def __init__(self, stream):
        self.stream, self.broken = stream, False

    def isatty(self) -> bool:
        """Whether the wrapped stream is a terminal.

        Returns:
            The wrapped stream's isatty().
        """
        return self.stream.isatty()

    def write(self, text: str) -> None:
        """Write text, or drop it once the pipe is broken.

        Args:
            text: the text to write.
        """
        self._guard(self.stream.write, text)

    def flush(self) -> None:
        """Flush the wrapped stream (nothing once the pipe is broken)."""
        self._guard(self.stream.flush)

    def _guard(self, call, *args) -> None:
        if self.broken:
            return
        try:
            call(*args)
        except BrokenPipeError:
            self.broken = True
            try:  # no second error when the interpreter flushes the stream at exit
                os.dup2(os.open(os.devnull, os.O_WRONLY), self.stream.fileno())
            except (OSError, ValueError, AttributeError):
                pass


def logs_dir(output: str | os.PathLike) -> Path:
    """The log directory of a run file: ``RUN.h5.logs`` (per-rank logs and the lock).

    Args:
        output: the run file RUN.h5.

    Returns:
        The path RUN.h5.logs (not created).
    """
    return Path(str(output) + ".logs")


class RunLocked(Exception):
    """Another process holds the run's lock; the message names it (pid on host)."""


def take_lock(output: str | os.PathLike) -> int:
    """Create the log directory and take the run's lock (``RUN.h5.logs/lock``, flock;
    released when the returned descriptor is closed or the process dies).

    Args:
        output: the run file RUN.h5.

    Returns:
        The lock file's descriptor, holding the lock.

    Raises:
        RunLocked: another process holds the lock.
    """
    logs = logs_dir(output)
    logs.mkdir(exist_ok=True)
    fd = os.open(logs / "lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 200).decode(errors="replace").strip()
        os.close(fd)
        raise RunLocked(holder or "unknown") from None
    os.ftruncate(fd, 0)
    os.write(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode())
    return fd


def lock_holder(output: str | os.PathLike) -> str | None:
    """Who is running (writing) the run file now ("pid P on HOST"), or None. Read-only.

    Args:
        output: the run file RUN.h5.

    Returns:
        "pid P on HOST" ("unknown" if unreadable) while the lock is held, else None.
    """
    try:
        fd = os.open(logs_dir(output) / "lock", os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return None
    except BlockingIOError:
        return os.read(fd, 200).decode(errors="replace").strip() or "unknown"
    finally:
        os.close(fd)


def rank_logger(logs_dir: Path, rank: int) -> logging.Logger:
    """A logger writing to ``logs_dir/rank-N.log`` (appended across resumes).

    Args:
        logs_dir: the run's log directory (existing).
        rank: the world rank N.

    Returns:
        The logger (level INFO, not propagating), its earlier handlers replaced.
    """
    logger = logging.getLogger(f"sdmpi.ensemble.rank{rank}")
    logger.setLevel(logging.INFO)
    logger.propagate = False
    for h in list(logger.handlers):
        logger.removeHandler(h)
        h.close()
    handler = logging.FileHandler(logs_dir / f"rank-{rank}.log")
    handler.setFormatter(logging.Formatter("%(asctime)s %(message)s"))
    logger.addHandler(handler)
    return logger


def hms(seconds: float) -> str:
    """A duration as H:MM:SS.

    Args:
        seconds: the duration (s), >= 0.

    Returns:
        The text H:MM:SS, rounded to whole seconds.
    """
    s = int(round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


class Progress:
    """Progress of a run: ``tasks`` = (complete at the start, total), ``steps`` =
    (committed at the start, total); rates and ETA count this session only.
    ``leaders``: world ranks of the group leaders (rank 0 first)."""

    def __init__(self, comm, leaders, tasks, steps, stream=None):
        self.comm, self.rank = comm, comm.rank
        self.others = [r for r in leaders if r != 0]
        self.is_leader = self.rank in leaders
        (self.tasks_before, self.tasks_total), (self.steps_before, self.steps_total) = tasks, steps
        self.stream = stream or sys.stdout
        self.tty = self.stream.isatty() and not any(v in os.environ for v in LAUNCHER_VARS)
        self.steps = self.tasks = 0          # this rank's counts
        self.remote = {r: (0, 0) for r in self.others}  # rank 0: (steps, tasks) per leader
        self.finished: set[int] = set()
        self.start = self._last_print = self._last_send = time.monotonic()
        self._first = None  # (time, session steps) when steps were first seen
        self._request = None

    def add(self, steps: int = 0, tasks: int = 0) -> None:
        """Count steps / finished tasks of this rank; report if it is time.

        Args:
            steps: steps just done.
            tasks: tasks just finished.
        """
        self.steps += steps
        self.tasks += tasks
        now = time.monotonic()
        if self.rank == 0:
            self._poll()
            self._start_clock(now)
            if self._due(now):
                self._print(now)
        elif self.is_leader and now - self._last_send >= SEND_EVERY:
            self._send(final=False)

    def finish(self, idle: Callable[[], object] | None = None) -> None:
        """Leaders: send the final count; rank 0: wait for every leader's final count,
        printing (and calling ``idle()``) meanwhile, then print the last line.

        Args:
            idle: called repeatedly on rank 0 while it waits, or None.
        """
        if self.rank == 0:
            while len(self.finished) < len(self.others):
                self._poll()
                if idle is not None:
                    idle()
                now = time.monotonic()
                self._start_clock(now)
                if self._due(now):
                    self._print(now)
                time.sleep(0.05)
            self._print(time.monotonic(), last=True)
        elif self.is_leader:
            self._send(final=True)
            self._request.wait()

    # ---- internals

    def _due(self, now: float) -> bool:
        lo, hi = LINES_EVERY
        every = LIVE_EVERY if self.tty else min(max(lo, (now - self.start) / 10), hi)
        return now - self._last_print >= every

    def _send(self, final: bool) -> None:
        if self._request is not None:
            self._request.wait()
        self._request = self.comm.isend((self.steps, self.tasks, final), dest=0, tag=TAG)
        self._last_send = time.monotonic()

    def _poll(self) -> None:
        from mpi4py import MPI

        status = MPI.Status()
        while self.comm.iprobe(source=MPI.ANY_SOURCE, tag=TAG, status=status):
            source = status.Get_source()
            steps, tasks, final = self.comm.recv(source=source, tag=TAG)
            self.remote[source] = (steps, tasks)
            if final:
                self.finished.add(source)

    def _session(self) -> int:
        """Steps done this session, on every rank as far as rank 0 knows."""
        return self.steps + sum(s for s, _ in self.remote.values())

    def _start_clock(self, now: float) -> None:
        """Start the rate clock when the first steps are seen, so that start-up (imports,
        kernel compilation, initial configurations, the first step) does not skew it."""
        if self._first is None and self._session() > 0:
            self._first = (now, self._session())

    def line(self, now: float) -> str:
        """The progress line: tasks done, steps done, steps/s, ETA.

        Args:
            now: time.monotonic() of the line (s).

        Returns:
            The line, without a newline.
        """
        session = self._session()
        steps = self.steps_before + session
        tasks = self.tasks_before + self.tasks + sum(t for _, t in self.remote.values())
        elapsed = max(now - self.start, 1e-9)
        self._start_clock(now)
        rate, eta = "?", "?"  # until steps were seen at two times (a very short run: "?")
        if self._first is not None and now > self._first[0] and session > self._first[1]:
            per_second = (session - self._first[1]) / (now - self._first[0])
            rate, eta = f"{per_second:.3g}", hms((self.steps_total - steps) / per_second)
        pct = 100.0 * steps / self.steps_total
        return (f"tasks {tasks}/{self.tasks_total} done | steps {steps}/{self.steps_total} "
                f"({pct:.1f}%) | {rate} steps/s | elapsed {hms(elapsed)} | ETA {eta}")

    def _print(self, now: float, last: bool = False) -> None:
        text = self.line(now)
        if self.tty:
            self.stream.write("\r" + text.ljust(100) + ("\n" if last else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self._last_print = now
