"""Control of a running solver: its time budget, Ctrl-C, live status, and standard output.

One small module that every solve shares (the routing MILP today; any later solver can use
the same pieces):

* :class:`Clock` -- the time budget of one routing solve (an overall deadline, or the
  paper's rule: a deadline to the first test, then ``after_first`` seconds more).
* :class:`SolveControl` -- what a caller (the command line) shares with a running solve: a
  stop request (Ctrl-C) and the latest :class:`SolveStatus` (best answer, bound, gap), which
  a progress line reads (both defined in :mod:`synthesis.routing.solve_status`, which imports
  no solver, so the options that name them load none).
* :func:`run_highs` -- runs HiGHS in a worker thread with one interrupt callback, so the
  main thread stays responsive: Ctrl-C (``KeyboardInterrupt``) asks HiGHS to stop through
  its interrupt callbacks (MIP, simplex, IPM) and is raised again within about a second,
  whether or not HiGHS has returned by then.
* :func:`stdout_guard` -- points the process's file descriptor 1 at ``/dev/null`` while
  libraries run, so nothing they print (HiGHS's banner, a C-level ``printf``) lands in
  output that must hold only our JSON.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from importlib.util import find_spec
from typing import Any

import highspy
import numpy as np

from ..model.errors import ProblemError
from .solve_status import SolveControl as SolveControl  # re-exported: the status and control live in solve_status
from .solve_status import SolveStatus as SolveStatus

#: Seconds the main thread waits for HiGHS to honour a stop request before it gives up
#: on it and raises ``KeyboardInterrupt`` anyway (the solve thread is a daemon).
STOP_GRACE = 0.25

#: Seconds between two looks of the main thread at a running solve.
POLL = 0.05

#: The name of the threads that run an in-process solver, HiGHS or SCIP (see :func:`solves_running`).
SOLVER_THREAD = "flowtest-solver"


class SolverAbandoned(TimeoutError):
    """A solver still busy past the hard deadline of its run was left behind in its daemon
    thread (see :func:`run_in_solver_thread`): the time limit holds, and the solver's model
    must not be touched again (it is still in use)."""


class Clock:
    """The time budget of one routing solve: an overall deadline, or (``after_first``)
    a deadline to the first test that moves to ``after_first`` seconds after it."""

    def __init__(self, time_limit: float | None, after_first: float | None) -> None:
        now = time.perf_counter()
        self.deadline = None if time_limit is None else now + time_limit
        self.after_first = after_first
        self.found = False

    def first_test(self, at: float | None = None) -> None:
        """A first test is in hand (since ``perf_counter()`` time ``at``, default now): from
        then on, only ``after_first`` seconds more."""
        if self.found:
            return
        self.found = True
        if self.after_first is not None:
            self.deadline = (time.perf_counter() if at is None else at) + self.after_first

    def watching_first(self) -> bool:
        """Whether a run must watch for its first test with flow >= 1 (and then move the
        deadline): no first test yet, and an ``after_first`` budget."""
        return not self.found and self.after_first is not None

    def latest(self) -> float | None:
        """The latest a run may end: the deadline, or while watching for a first test,
        ``after_first`` seconds past it (the callback stops the run earlier)."""
        if self.deadline is None or not self.watching_first():
            return self.deadline
        return self.deadline + float(self.after_first or 0.0)


_CALLBACKS = ("kCallbackMipInterrupt", "kCallbackSimplexInterrupt", "kCallbackIpmInterrupt")


def run_highs(
    h: highspy.Highs,
    deadline: float | None,
    *,
    clock: Clock | None = None,
    control: SolveControl | None = None,
    phase: str = "",
    flow: int | None = None,
    watch_first: bool = False,
    abandon_at: float | None = None,
) -> None:
    """Run HiGHS on its current model until it is done, the deadline passes, or a stop
    (past ``abandon_at``: :class:`SolverAbandoned`, see :func:`run_in_solver_thread`).

    The run happens in a daemon thread while the calling thread waits in short steps, so a
    ``KeyboardInterrupt`` reaches the caller at once: it sets the stop request, which the
    interrupt callbacks pass to HiGHS, waits up to :data:`STOP_GRACE` seconds for HiGHS to
    return, and is raised again. A stop requested through ``control`` by another thread
    is raised as ``KeyboardInterrupt`` as well.

    With ``watch_first`` (a maximum-flow run of an ``after_first`` budget), the first
    incumbent with flow >= 1 starts ``clock``'s ``after_first`` seconds and the callback
    stops HiGHS at the moved deadline. ``phase`` and ``flow`` label the status published
    to ``control`` from the MIP callback.
    """
    sense_max = h.getLp().sense_ == highspy.ObjSense.kMaximize
    t0 = time.perf_counter()
    limit = highspy.kHighsInf if deadline is None else max(deadline - t0, 0.01)
    h.setOptionValue("time_limit", float(limit))
    stop = threading.Event()
    if control is not None and control.stop_requested:
        raise KeyboardInterrupt

    mip_kind = int(highspy.cb.HighsCallbackType.kCallbackMipInterrupt)

    def on_interrupt(kind: Any, message: str, data_out: Any, data_in: Any, user_data: Any) -> None:
        if int(kind) == mip_kind:  # some versions pass the type as a plain int
            primal = float(data_out.mip_primal_bound)
            if watch_first and clock is not None and np.isfinite(primal) and primal >= 1.0 - 1e-6:
                clock.first_test()
            if control is not None:
                dual = float(data_out.mip_dual_bound)
                control.report(
                    SolveStatus(
                        phase,
                        "max" if sense_max else "min",
                        primal if np.isfinite(primal) else None,
                        dual if np.isfinite(dual) else None,
                        t0,
                        flow,
                    )
                )
            if watch_first and clock is not None and clock.deadline is not None and time.perf_counter() > clock.deadline:
                data_in.user_interrupt = True
        if stop.is_set() or (control is not None and control.stop_requested):
            data_in.user_interrupt = True

    h.setCallback(on_interrupt, None)
    kinds = [getattr(highspy.cb.HighsCallbackType, k) for k in _CALLBACKS]
    for k in kinds:
        h.startCallback(k)

    def stop_callbacks() -> None:
        for k in kinds:
            h.stopCallback(k)

    status = SolveStatus(phase, "max" if sense_max else "min", None, None, t0, flow)
    run_in_solver_thread(h.run, stop.set, control, status, finished=stop_callbacks, deadline=deadline, abandon_at=abandon_at)


def run_in_solver_thread(
    run: Callable[[], object],
    interrupt: Callable[[], None],
    control: SolveControl | None,
    status: SolveStatus,
    *,
    finished: Callable[[], None] | None = None,
    deadline: float | None = None,
    abandon_at: float | None = None,
) -> None:
    """Call the blocking solver entry ``run`` in a daemon thread while the calling thread
    waits in short steps, so Ctrl-C reaches the caller at once.

    Past ``deadline`` (a ``perf_counter`` time), ``interrupt`` is called once: the solver's
    own time limit is the same deadline, but a solver checks its clock only now and then
    (HiGHS inside a long simplex run), and the time limit must hold for the whole command.
    Past ``abandon_at`` the solver is left running in its daemon thread and
    :class:`SolverAbandoned` is raised (``finished`` is not called): HiGHS's presolve looks
    at no clock for seconds on a large model.

    A ``KeyboardInterrupt``, or a stop requested through ``control`` by another thread,
    calls ``interrupt`` (which must make the solver return), sets the stop request, waits
    up to :data:`STOP_GRACE` seconds for the solver, and is raised. ``status`` is published
    to ``control`` for the run; ``finished`` runs once the solver has returned (not if it
    is still inside after the grace); an exception of ``run`` is raised here. Shared by
    HiGHS (:func:`run_highs`) and the other in-process solvers, so each stops alike.
    """
    failure: list[BaseException] = []
    done = threading.Event()

    def work() -> None:
        try:
            run()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller below
            failure.append(exc)
        finally:
            done.set()

    if control is not None:
        control.report(status)
    thread = threading.Thread(target=work, name=SOLVER_THREAD, daemon=True)
    try:
        thread.start()
        late = False
        while not done.wait(POLL):
            if control is not None and control.stop_requested:
                raise KeyboardInterrupt
            now = time.perf_counter()
            if deadline is not None and not late and now > deadline:
                late = True
                interrupt()
            if abandon_at is not None and now > abandon_at:
                interrupt()
                _left_behind(thread)
                raise SolverAbandoned("no solution was found within the time limit (the solver, still busy, was stopped)")
        if control is not None and control.stop_requested:  # the solver saw the stop first
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        interrupt()
        if control is not None:
            control.request_stop()
        done.wait(STOP_GRACE)
        raise
    finally:
        if done.is_set() and finished is not None:
            finished()
        if control is not None:
            control.report(None)
    if failure:
        raise failure[0]


_ABANDONED: list[threading.Thread] = []

ABANDONED_JOIN_SECONDS = 300.0
"""At interpreter exit, the longest wait for a solver left behind (it stops at its own time
limit, seconds later): a C++ solver torn down while it runs aborts the process."""


def _left_behind(thread: threading.Thread) -> None:
    """Keep a solver thread left behind, to be waited for at exit (:func:`_join_left_behind`)."""
    if not _ABANDONED:
        atexit.register(_join_left_behind)
    _ABANDONED.append(thread)


def _join_left_behind() -> None:
    """At exit: wait for the solvers left behind (a process that must not wait ends with
    ``os._exit`` once :func:`solves_running` is false or it does not care)."""
    for thread in _ABANDONED:
        thread.join(ABANDONED_JOIN_SECONDS)


@dataclass(frozen=True)
class OptionalSolver:
    """A solver package a backend needs (OR-Tools for ``cpsat``): whether it is installed, a
    one-line error when it is asked for and missing, its version. Checked without importing
    the package (OR-Tools cannot share a process with highspy)."""

    package: str
    missing: str  # the error message when the backend is asked for without the package

    def available(self) -> bool:
        """Whether the package is installed."""
        return find_spec(self.package) is not None

    def require(self) -> None:
        """Raise :class:`~synthesis.model.errors.ProblemError` (:attr:`missing`) when the
        package is not installed."""
        if not self.available():
            raise ProblemError(self.missing)

    def version(self) -> str | None:
        """The installed version (``None``: not installed); part of the cache key."""
        try:
            return version(self.package)
        except PackageNotFoundError:
            return None


def solver_version() -> str:
    """The version of the solver package answers depend on (``highspy``, e.g. ``"1.15.1"``):
    recorded with shipped artifacts, and part of every cache key."""
    try:
        return version("highspy")
    except PackageNotFoundError:  # an unpackaged build: ask HiGHS itself
        with stdout_guard():  # the banner of HiGHS >= 1.16
            return str(highspy.Highs().version())


def solves_running() -> bool:
    """Whether a solver thread started by :func:`run_in_solver_thread` is still running (one
    that was asked to stop but has not reached a point where its solver notices yet)."""
    return any(t.name == SOLVER_THREAD and t.is_alive() for t in threading.enumerate())


# --------------------------------------------------------------------------- stdout


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers (a library's ``printf`` waits there)."""
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no C library handle here: nothing to flush
        pass


@contextmanager
def stdout_guard() -> Iterator[None]:
    """While the body runs, file descriptor 1 points at ``/dev/null``; restored after.

    Whatever a library prints to standard output meanwhile -- from Python (``sys.stdout``
    is pointed at ``/dev/null`` too), from C through ``printf``, or with ``write(1, ...)`` --
    is dropped, so a caller whose standard output must hold only its own document
    (``flowtest ... --json``) writes it after the body. Python's and C's buffers are
    flushed on both sides of the switch so nothing printed inside reaches the real
    standard output later. Not for use from several threads.
    """
    try:
        sys.stdout.flush()
    except (OSError, ValueError, AttributeError):
        pass
    _flush_c_stdio()
    python_stdout = sys.stdout
    try:
        saved = os.dup(1)
    except OSError:  # no file descriptor 1: guard Python's stdout only
        saved = -1
    if saved >= 0:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, 1)
        finally:
            os.close(null)
    # Python-level prints too, even where sys.stdout is not file descriptor 1
    sys.stdout = open(os.devnull, "w")  # noqa: SIM115 - closed below
    try:
        yield
    finally:
        devnull, sys.stdout = sys.stdout, python_stdout
        try:
            devnull.close()
        except (OSError, ValueError, AttributeError):
            pass
        _flush_c_stdio()
        if saved >= 0:
            os.dup2(saved, 1)
            os.close(saved)


def status_line(control: SolveControl | None) -> str | None:
    """The running solve's status as one line, or ``None`` when no solve runs."""
    status = None if control is None else control.status
    return None if status is None or control is None else status.text(since=control.started)


__all__ = [
    "Clock",
    "OptionalSolver",
    "SolveControl",
    "SolveStatus",
    "SolverAbandoned",
    "run_highs",
    "solver_version",
    "solves_running",
    "status_line",
    "stdout_guard",
]


def quiet_highs(threads: int | None, random_seed: int) -> highspy.Highs:
    """A HiGHS instance that prints nothing (its banner included), on ``threads`` threads
    (``None``: HiGHS decides) with a fixed ``random_seed``: what every HiGHS solve of the
    routing backends starts from."""
    with stdout_guard():  # HiGHS >= 1.16 prints its banner on construction, before any option
        h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("log_to_console", False)
    if threads is not None:
        highspy.Highs.resetGlobalScheduler(True)
        h.setOptionValue("threads", int(threads))
    h.setOptionValue("random_seed", int(random_seed))
    return h
