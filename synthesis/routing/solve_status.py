"""What a caller shares with a running solve: its latest status and a stop request.

:class:`SolveStatus` is a running solve as a progress line shows it; :class:`SolveControl`
carries a stop request (Ctrl-C) to the solve and its latest status back. Both are plain
Python: the options name :class:`SolveControl` (:mod:`synthesis.routing.options`), and what
only reads options or a test loads no solver. Running a solver under them is
:mod:`synthesis.routing.solver_control`'s job.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SolveStatus:
    """A running solve as a progress line shows it.

    ``phase`` names what runs (e.g. ``"maximum flow"``), ``sense`` is ``"max"`` or
    ``"min"``, ``best`` the objective of the best solution so far (``None``: none yet),
    ``bound`` the proven bound on the optimum, ``started`` the ``perf_counter`` time the
    run began (the line shows the time since), ``flow`` the flow held fixed (phase 2).
    """

    phase: str
    sense: str
    best: float | None
    bound: float | None
    started: float
    flow: int | None = None

    @property
    def elapsed(self) -> float:
        """Seconds since the run began."""
        return time.perf_counter() - self.started

    @property
    def valid_bound(self) -> float | None:
        """The bound where it says something: ``None`` when there is none or it lies on the
        wrong side of the best answer (a solver's placeholder, not a proof); a minimised
        objective (cuts, walls, doors: never below 0) is bounded by 0 at worst."""
        b = self.bound
        if b is None or not np.isfinite(b):
            return None
        if self.sense == "min":
            b = max(b, 0.0)
            if self.best is not None and b > self.best + 1e-6:
                return None
        elif self.best is not None and b < self.best - 1e-6:
            return None
        return b

    @property
    def gap(self) -> float | None:
        """Relative gap ``|best - bound| / max(|best|, 1)`` (``None`` without both, or with a
        bound that proves nothing: see :attr:`valid_bound`)."""
        bound = self.valid_bound
        if self.best is None or bound is None:
            return None
        return abs(self.best - bound) / max(abs(self.best), 1.0)

    def text(self, since: float | None = None) -> str:
        """One short line: the best test so far (flow, cuts), the bound and the gap (a
        number, or ``no bound yet``), and the seconds since ``since`` (a ``perf_counter``
        time: the command's one clock; default: since this run began)."""

        def num(v: float | None) -> str:
            if v is None:
                return "-"
            if abs(v - round(v)) < 1e-6:
                return f"{round(v) + 0:d}"  # never "-0"
            return f"{v:.2f}"

        if self.flow is None:  # maximum flow
            best = f"best flow {num(self.best)}"
        else:
            best = f"flow {self.flow}, best cuts {num(self.best)}"
        bound = self.valid_bound
        gap = self.gap
        if bound is None:
            tail = "no bound yet"
        else:
            tail = f"bound {num(bound)}, gap {'-' if gap is None else f'{100 * gap:.1f}%'}"
        elapsed = self.elapsed if since is None else time.perf_counter() - since
        return f"{self.phase}: {best}, {tail}, {elapsed:.0f} s"


class SolveControl:
    """What a caller shares with a running solve: a stop request and the latest status.

    Thread-safe: the solve thread writes the status, the caller's progress thread reads it,
    the main thread requests the stop.
    """

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._status: SolveStatus | None = None
        self.started = time.perf_counter()  # the one clock progress lines show

    def request_stop(self) -> None:
        """Ask every running and later solve to stop as soon as it can."""
        self._stop.set()

    @property
    def stop_requested(self) -> bool:
        return self._stop.is_set()

    def report(self, status: SolveStatus | None) -> None:
        """Publish the status of the running solve (``None``: no solve runs).

        Once a stop is requested only ``None`` is kept: a HiGHS thread still winding down
        after its caller gave up (:data:`~synthesis.routing.solver_control.STOP_GRACE`) cannot publish a status again."""
        with self._lock:
            if status is not None and self._stop.is_set():
                return
            self._status = status

    @property
    def status(self) -> SolveStatus | None:
        with self._lock:
            return self._status
