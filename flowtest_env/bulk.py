"""Bulk work on many tests: the cyclic garbage collector paused while it builds, and whether a
forked helper process may share it.

Loading a standard pool (:mod:`flowtest_env.standard_pools`) and compiling a vector env
(:mod:`flowtest_env.compiled`) build millions of small objects that stay alive, and split
their work with one forked helper where the machine has two cores for it.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["can_fork", "free_cores", "gc_paused"]


@contextmanager
def gc_paused() -> Iterator[None]:
    """The cyclic garbage collector paused (as it was before, after): a bulk build of
    many small objects that stay alive otherwise triggers collection after collection,
    each walking every object built so far (about a third of the time of a large pool).

    Example::

        with gc_paused():
            games = [TestGame(a) for a in artifacts]
    """
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def can_fork() -> bool:
    """Whether a helper can be forked safely: on Linux (macOS's system libraries are not
    safe to fork), where this process runs no other Python thread (a fork copies no
    thread, and a lock one of them held would stay held in the helper) and may have
    children (a multiprocessing pool's worker, one of a trainer's runs, is daemonic and
    may not)."""
    return sys.platform.startswith("linux") and threading.active_count() == 1 and not multiprocessing.current_process().daemon


def free_cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def helper_signals() -> None:
    """In a forked helper, first thing: Ctrl-C (sent to the whole process group) is left to
    the parent, which stops its helpers, and the parent's ``terminate()`` ends the helper at
    once. Without it, the parent's handlers, inherited by the fork, turned either signal into
    a ``KeyboardInterrupt`` in the helper, whose traceback the user then read."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    except ValueError:  # not the main thread of the helper: the handlers stay as they are
        pass
