"""Progress on standard error: :class:`StageProgress`, the stage lines every command shows,
:func:`synthesis_progress`, a synthesis's (its stages and its solver's status), and :func:`say`,
one line.

The library (:mod:`experiments.evaluation`, :mod:`experiments.benchmark`,
:mod:`experiments.training`) and the command line share these: a long piece of work says what
it does on stderr, whoever called it. Nothing here writes to standard output, which stays clean
for a command's result (its ``--json`` document above all).
"""

from __future__ import annotations

import io
import os
import shutil
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

from synthesis.routing.solve_status import SolveControl

PROG = "flowtest"
"""The program name every message starts with."""


def say(line: str) -> None:
    """One line on stderr, best effort (stderr may be closed)."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass


PROGRESS_EVERY = 5.0
"""Seconds between two status lines of ``--progress`` when stderr is not a terminal."""


class StageProgress:
    """Stage messages on standard error, with a live elapsed-time indicator on a TTY.

    Called with a message, it starts a new stage. On a terminal the stage is one line
    that a small background thread rewrites (``\\r``) with the seconds since the command
    began (one clock for every line, which solver status lines share) once
    the stage has run longer than ``delay`` seconds, so a long MILP solve visibly
    progresses; elsewhere (a file, a pipe, a CI log) each stage is printed once as a
    plain line, because carriage returns make logs unreadable. Nothing is ever written
    to standard output.

    ``status`` (e.g. :func:`synthesis.routing.solver_control.status_line`) says how a running
    solve stands: its best test so far, the bound and the gap. On a terminal it is shown on
    the live line; elsewhere it is printed as a plain line every ``every`` seconds when
    ``every`` is given (``flowtest synthesize --progress``), else not at all.

    Use it as a context manager so the indicator thread always stops and the last line
    is terminated, even when synthesis raises.
    """

    PREFIX = f"{PROG}: "

    def __init__(
        self,
        stream: TextIO | None = None,
        *,
        enabled: bool = True,
        live: bool | None = None,
        delay: float = 1.0,
        interval: float = 0.2,
        status: Callable[[], str | None] | None = None,
        every: float | None = None,
    ) -> None:
        self.stream: TextIO = stream if stream is not None else sys.stderr
        self.enabled = enabled
        if live is None:
            isatty = getattr(self.stream, "isatty", None)
            live = bool(isatty and isatty())
        self.live = enabled and live
        self.delay = delay
        self.interval = interval
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._message: str | None = None  # the stage whose line is still open (live mode)
        self._width = 0  # characters on the open line
        self._started = 0.0
        self._t0 = time.perf_counter()
        self.clock_start = self._t0  # perf_counter time of the one clock (a solve's status lines share it)
        self.status = status
        self.every = every if enabled and not self.live else None
        self._last_status = time.perf_counter()

    # -- context manager
    def __enter__(self) -> StageProgress:
        if self.live or (self.every is not None and self.status is not None):
            self._thread = threading.Thread(target=self._tick, name="flowtest-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- stages
    def __call__(self, message: str) -> None:
        """Start the stage ``message`` (the ``progress`` callback of synthesis)."""
        if not self.enabled:
            return
        with self._lock:
            self._end_line()
            self._started = time.perf_counter()
            if self.live:
                self._message = message
                self._rewrite(self.PREFIX + message)
            else:
                self._write(self.PREFIX + message + "\n")

    def done(self, message: str) -> None:
        """A final line (e.g. the total time), printed in every mode."""
        if not self.enabled:
            return
        with self._lock:
            self._end_line()
            self._write(self.PREFIX + message + "\n")

    def elapsed(self) -> float:
        """Seconds since this reporter was created."""
        return time.perf_counter() - self._t0

    def close(self) -> None:
        """Stop the indicator thread and terminate the open line."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        with self._lock:
            self._end_line()

    # -- internals (call with the lock held)
    def _end_line(self) -> None:
        if self._message is not None:
            self._rewrite(f"{self.PREFIX}{self._message} (to {self.elapsed():.1f} s)")
            self._write("\n")
            self._message = None
            self._width = 0

    def _rewrite(self, line: str) -> None:
        """Replace the open line: fit it to the terminal, blank out what it no longer covers."""
        columns = self._columns() - 1
        if len(line) > columns:
            line = line[: max(columns - 3, 0)] + "..."
        self._write("\r" + line.ljust(self._width))
        self._width = len(line)

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # closed or broken stderr: progress is best effort
            self.enabled = False

    def _columns(self) -> int:
        """The width of the terminal behind the stream (stdout may be redirected)."""
        try:
            return os.get_terminal_size(self.stream.fileno()).columns
        except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
            return shutil.get_terminal_size((100, 24)).columns

    def _status(self) -> str | None:
        try:
            return self.status() if self.status is not None else None
        except Exception:  # noqa: BLE001 - a progress line must never end a solve
            return None

    def _tick(self) -> None:
        while not self._stop.wait(self.interval):
            with self._lock:
                if not self.enabled:
                    continue
                if not self.live:  # plain status lines every `every` seconds (--progress)
                    now = time.perf_counter()
                    if self.every is not None and now - self._last_status >= self.every:
                        self._last_status = now
                        status = self._status()
                        if status is not None:
                            self._write(f"{self.PREFIX}{status}\n")
                    continue
                if self._message is None:
                    continue
                if time.perf_counter() - self._started >= self.delay:
                    status = self._status()
                    tail = f" | {status}" if status else ""
                    # one clock: the seconds since the command began, on every line
                    self._rewrite(f"{self.PREFIX}{self._message} ... {self.elapsed():.1f} s{tail}")


def solver_status(control: SolveControl) -> str | None:
    """How the running solve stands (best test, bound, gap:
    :func:`synthesis.routing.solver_control.status_line`), its module imported only when a
    status is asked for (it loads HiGHS)."""
    from synthesis.routing.solver_control import status_line

    return status_line(control)


@contextmanager
def synthesis_progress(enabled: bool = True, every: float | None = None, stream: TextIO | None = None) -> Iterator[tuple[StageProgress, SolveControl]]:
    """What a synthesis shows on stderr, the same for every command that synthesizes
    (``flowtest synthesize``, and ``flowtest evaluate`` on a problem file without a cached test):
    a :class:`StageProgress` for its stages, whose live line on a terminal carries the solver's
    status (best test, bound, gap), also printed every ``every`` seconds elsewhere
    (``--progress``), and the :class:`SolveControl` the synthesis shares with it (pass both in
    :class:`synthesis.SynthesisOptions`). The solver's status lines count on the progress's one
    clock. Nothing is shown when not ``enabled`` (``--quiet``).

    Example::

        with synthesis_progress() as (progress, control):
            test = synthesize(problem, SynthesisOptions(progress=progress, control=control))
    """
    control = SolveControl()
    with StageProgress(stream, enabled=enabled, status=lambda: solver_status(control), every=every) as progress:
        control.started = progress.clock_start  # solver status lines count on the command's one clock
        yield progress, control
