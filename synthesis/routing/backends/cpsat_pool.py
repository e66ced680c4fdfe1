"""The CP-SAT child processes: starting one, keeping one idle for the next solve, ending them.

:mod:`synthesis.routing.backends.cpsat` solves on a child running
:mod:`synthesis.routing.backends.cpsat_worker` (OR-Tools cannot share a process with highspy). A
child is started before it is needed when that pays: :func:`prestart` lets it load
OR-Tools while this process does other work, and ``flowtest synthesize`` calls it first
thing, before its own imports (:mod:`experiments.cli.prestart`). Whoever may have started one
ends it with :func:`close_idle_workers` when it is not (or no longer) needed.

This module imports the standard library only, so that starting a child costs the caller
no more than the ``fork``/``exec`` (the ``synthesis`` package loads its modules lazily).
"""

from __future__ import annotations

import atexit
import os
import signal
import subprocess
import sys
import tempfile
import threading
from multiprocessing.connection import Connection
from pathlib import Path

WORKER = Path(__file__).resolve().with_name("cpsat_worker.py")
"""The child's program, started by its path so the ``synthesis`` package (and highspy) never loads there."""


class Worker:
    """One child process running :mod:`synthesis.routing.backends.cpsat_worker`, and the two ends
    of the pipes to it (:class:`multiprocessing.connection.Connection`)."""

    def __init__(self) -> None:
        self.stderr = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            [sys.executable, "-P", str(WORKER), str(os.getpid())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.stderr,
        )
        if self.proc.stdin is None or self.proc.stdout is None:
            raise RuntimeError("the CP-SAT worker has no pipes")
        self.to_child = Connection(os.dup(self.proc.stdin.fileno()), readable=False)
        self.from_child = Connection(os.dup(self.proc.stdout.fileno()), writable=False)
        self.proc.stdin.close()
        self.proc.stdout.close()
        self.cpu = 0.0  # the child's CPU seconds at its last answer

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    @property
    def pid(self) -> int:
        """The child's process id."""
        return int(self.proc.pid)

    def stderr_tail(self) -> str:
        """The last line the child wrote to its standard error (``""``: none)."""
        try:
            self.stderr.seek(0)
            lines = self.stderr.read().decode(errors="replace").strip().splitlines()
        except (OSError, ValueError):
            return ""
        return f": {lines[-1]}" if lines else ""

    def close(self) -> None:
        """End the child (killed if it still runs), reap it and free its pipes."""
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        for conn in (self.to_child, self.from_child):
            conn.close()
        self.stderr.close()


_idle: list[Worker] = []
_idle_lock = threading.Lock()


def _forget_idle_in_fork_child() -> None:
    """A forked process must not talk to its parent's idle child (the pipes are shared): it
    forgets it, without ending it, and starts its own when it needs one."""
    global _idle_lock
    _idle.clear()
    _idle_lock = threading.Lock()


os.register_at_fork(after_in_child=_forget_idle_in_fork_child)


def prestart() -> None:
    """Start an idle child now, if none waits, so importing OR-Tools there overlaps with
    the caller's work (its imports, the product graphs, the model) instead of following it."""
    with _idle_lock:
        if any(w.alive for w in _idle):
            return
    give_back(Worker())


def idle_pids() -> list[int]:
    """The process ids of the idle children (tests)."""
    with _idle_lock:
        return [w.pid for w in _idle]


def take_worker() -> tuple[Worker, bool]:
    """An idle child (prestarted, or from an earlier solve of this process), else a new one
    (and whether it is new): a fresh child's start-up, which the counterexample loop of an
    agent problem, with its many solves, would pay each time. A child holds no state
    between models (each solve builds its own CP-SAT model)."""
    with _idle_lock:
        while _idle:
            worker = _idle.pop()
            if worker.alive:
                return worker, False
            worker.close()
    return Worker(), True


def give_back(worker: Worker) -> None:
    """Keep ``worker`` as the idle child if it runs and none is kept; else end it."""
    with _idle_lock:
        if worker.alive and not _idle:
            _idle.append(worker)
            return
    worker.close()


def close_idle_workers() -> None:
    """End and reap the idle child (a command's end, tests, this process's exit)."""
    with _idle_lock:
        workers = list(_idle)
        _idle.clear()
    for worker in workers:
        worker.close()


atexit.register(close_idle_workers)  # no child outlives this process unreaped


def kill_idle_now() -> None:
    """Kill the idle children without waiting or locking: for a signal handler that is about
    to end this process (whoever reaps an orphan reaps them)."""
    for worker in list(_idle):
        try:
            os.kill(worker.pid, signal.SIGKILL)
        except OSError:
            pass


__all__ = ["WORKER", "Worker", "close_idle_workers", "give_back", "idle_pids", "kill_idle_now", "prestart", "take_worker"]
