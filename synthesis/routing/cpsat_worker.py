"""The child process that runs OR-Tools CP-SAT on the routing model (backend ``"cpsat"``).

Why a child process: OR-Tools bundles its own ``libhighs.so.1``, and that build and the one
of highspy cannot be loaded into one process (with OR-Tools 9.15 and highspy 1.15.1,
whichever is imported second fails with an undefined symbol). So this module imports
NumPy, SciPy and OR-Tools only, never ``synthesis`` (whose package imports highspy), and
:mod:`synthesis.routing.cpsat` starts it by its file path (``python -P PATH``), not as
``-m synthesis...``, so the package's ``__init__`` never runs here. Importing this module into a process that
holds highspy fails for the same reason: nothing in FlowTest imports it.

The protocol is a pipe each way (the child's standard input and output), each message a
tuple sent with :class:`multiprocessing.connection.Connection` (pickled, behind its length), so
the parent needs nothing of this module, which it must never import. Requests: ``("build", arrays)``,
``("row", idx, val, lo, hi)``, ``("solve", cost, maximize, hint, params)``. Answers:
``("ok", value)`` or ``("error", text)``; during a solve ``("progress", best, bound)``
lines come first. The protocol keeps its own copy of file descriptor 1, and descriptor 1
itself is pointed at standard error, so nothing a library prints can reach the parent's
standard output or corrupt a message. The child ignores SIGINT (the parent ends it on
Ctrl-C) and ends itself when its parent dies.

Every column of the routing model is integral here (CP-SAT has integer variables only);
why that keeps the optimum is said in :mod:`synthesis.routing.cpsat`.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import scipy.sparse as sp
from ortools.sat.python import cp_model

#: Seconds between two looks of the child at whether its parent is still alive.
PARENT_POLL = 0.2


class CpSatModel:
    """(In the child.) The routing model as a CP-SAT model: one integer variable per column,
    one linear constraint per row; the objective and extra rows come per phase."""

    def __init__(self, arrays: dict[str, np.ndarray]) -> None:
        self._cp = cp_model
        self.model = cp_model.CpModel()
        lo = np.ceil(arrays["col_lo"] - 1e-9).astype(np.int64)
        hi = np.floor(arrays["col_hi"] + 1e-9).astype(np.int64)
        self.vars = [self.model.new_int_var(int(a), int(b), f"x{j}") for j, (a, b) in enumerate(zip(lo, hi, strict=True))]
        a = sp.csr_matrix((arrays["data"], arrays["indices"], arrays["indptr"]), shape=tuple(arrays["shape"]))
        for r in range(a.shape[0]):
            s, e = a.indptr[r], a.indptr[r + 1]
            if e > s:
                self.add_row(a.indices[s:e], a.data[s:e], float(arrays["row_lo"][r]), float(arrays["row_hi"][r]))

    def add_row(self, idx: np.ndarray, val: np.ndarray, lo: float, hi: float) -> None:
        """Add ``lo <= val . x[idx] <= hi``; integral coefficients, so the bounds are rounded
        inwards (``ceil(lo)``, ``floor(hi)``); an infinite bound becomes a finite one past
        every value the row can take."""
        coef = np.round(np.asarray(val, dtype=float)).astype(np.int64)
        if not np.allclose(coef, val):
            raise ValueError("the routing model has a non-integral coefficient")
        expr = self._cp.LinearExpr.weighted_sum([self.vars[int(j)] for j in idx], [int(c) for c in coef])
        span = int(np.abs(coef).sum()) * 10**6 + 1
        ilo = -span if not np.isfinite(lo) else int(np.ceil(lo - 1e-9))
        ihi = span if not np.isfinite(hi) else int(np.floor(hi + 1e-9))
        self.model.add_linear_constraint(expr, ilo, ihi)

    def solve(self, cost: np.ndarray, maximize: bool, hint: np.ndarray | None, params: dict[str, Any], out: Connection) -> dict[str, Any]:
        """Optimise ``cost . x`` (integral costs) from ``hint`` under ``params``; progress
        lines go to ``out`` as solutions and bounds come.

        ``params``: ``random_seed``; ``deterministic_time`` (CP-SAT's deterministic
        seconds, ``None``: none); ``seconds`` (wall clock, ``None``: none); with
        ``after_first``, ``seconds`` bounds the time to the first solution of objective
        >= ``first_at`` and the search stops ``after_first`` seconds after it;
        ``rel_gap``.
        """
        cp = self._cp
        nz = np.flatnonzero(cost)
        coef = np.round(cost[nz]).astype(np.int64)
        if not np.allclose(coef, cost[nz]):
            raise ValueError("the routing objective has a non-integral coefficient")
        expr = cp.LinearExpr.weighted_sum([self.vars[int(j)] for j in nz], [int(c) for c in coef])
        if maximize:
            self.model.maximize(expr)
        else:
            self.model.minimize(expr)
        self.model.clear_hints()
        if hint is not None:
            for var, v in zip(self.vars, np.round(hint).astype(np.int64), strict=True):
                self.model.add_hint(var, int(v))
        solver = cp.CpSolver()
        p = solver.parameters
        p.num_workers = 1  # one worker: the same search, and answer, on every run and machine
        p.random_seed = int(params["random_seed"])
        p.log_search_progress = False
        if params.get("deterministic_time") is not None:
            p.max_deterministic_time = float(params["deterministic_time"])
        seconds = params.get("seconds")
        after_first = params.get("after_first")
        if seconds is not None:
            p.max_time_in_seconds = max(float(seconds), 0.01) + (float(after_first) if after_first is not None else 0.0)
        if params.get("rel_gap"):
            p.relative_gap_limit = float(params["rel_gap"])
        first_at = float(params.get("first_at", 1.0))
        watch = _Watch(solver, out, maximize, after_first, first_at, cp.CpSolverSolutionCallback)
        solver.best_bound_callback = watch.on_bound
        timers = watch.start(seconds)
        cpu0 = time.process_time()
        try:
            status = solver.solve(self.model, watch.callback)
        finally:
            for t in timers + watch.timers:
                t.cancel()
        answer: dict[str, Any] = {
            "status": {cp.OPTIMAL: "optimal", cp.FEASIBLE: "feasible", cp.INFEASIBLE: "infeasible"}.get(status, "unknown"),
            "x": None,
            "objective": None,
            "bound": float(solver.best_objective_bound) if status in (cp.OPTIMAL, cp.FEASIBLE) else None,
            "first_age": None if watch.first is None else time.perf_counter() - watch.first,
            "wall_seconds": float(solver.wall_time),
            "cpu_seconds": time.process_time() - cpu0,  # this solve's CPU time (CP-SAT's user_time is a wall time)
            "process_cpu_seconds": time.process_time(),  # this child's CPU seconds so far
            "deterministic_time": float(solver.deterministic_time),
            "conflicts": int(solver.num_conflicts),
            "branches": int(solver.num_branches),
        }
        if status in (cp.OPTIMAL, cp.FEASIBLE):
            answer["x"] = np.array([solver.value(v) for v in self.vars], dtype=float)
            answer["objective"] = float(solver.objective_value)
        return answer


class _Watch:
    """Progress lines for the parent, and the ``after_first`` rule: stop the search
    ``after_first`` seconds after its first solution of objective >= ``first_at``, or at
    ``seconds`` without one."""

    def __init__(self, solver: Any, out: Connection, maximize: bool, after_first: float | None, first_at: float, base: type) -> None:
        self.solver = solver
        self.out = out
        self.maximize = maximize
        self.after_first = after_first
        self.first_at = first_at
        self.first: float | None = None
        self.best: float | None = None
        self.bound: float | None = None
        self.timers: list[threading.Timer] = []
        self._lock = threading.Lock()
        watch = self

        class _Callback(base):  # type: ignore[misc]
            def on_solution_callback(self) -> None:
                watch.on_solution(float(self.objective_value), float(self.best_objective_bound))

        self.callback = _Callback()

    def start(self, seconds: float | None) -> list[threading.Timer]:
        """With ``after_first`` and ``seconds``: stop at ``seconds`` unless a first solution came."""
        if self.after_first is None or seconds is None:
            return []
        t = threading.Timer(max(float(seconds), 0.01), lambda: None if self.first is not None else self.solver.stop_search())
        t.daemon = True
        t.start()
        return [t]

    def on_solution(self, objective: float, bound: float) -> None:
        with self._lock:
            self.best, self.bound = objective, bound
            if self.after_first is not None and self.first is None and objective >= self.first_at - 1e-9:
                self.first = time.perf_counter()
                t = threading.Timer(max(float(self.after_first), 0.0), self.solver.stop_search)
                t.daemon = True
                t.start()
                self.timers.append(t)
            self._report()

    def on_bound(self, bound: float) -> None:
        with self._lock:
            self.bound = float(bound)
            self._report()

    def _report(self) -> None:
        try:
            self.out.send(("progress", self.best, self.bound))
        except (OSError, ValueError):  # the parent went away: the watchdog ends us
            pass


def _watch_parent(parent: int) -> None:
    """End this process when its parent is gone (no orphan keeps solving)."""
    while True:
        time.sleep(PARENT_POLL)
        if os.getppid() != parent:
            os._exit(1)


def serve(inp: Connection, out: Connection) -> None:
    """The child's loop: build the model, then add rows and solve on request, until the
    parent closes the pipe."""
    model: CpSatModel | None = None
    while True:
        try:
            message = inp.recv()
        except (EOFError, OSError):
            return
        try:
            kind = message[0]
            if kind == "build":
                model = CpSatModel(message[1])
                out.send(("ok", time.process_time()))  # this child's CPU seconds so far
            elif kind == "row" and model is not None:
                model.add_row(*message[1:])
                out.send(("ok", time.process_time()))
            elif kind == "solve" and model is not None:
                cost, maximize, hint, params = message[1:]
                out.send(("ok", model.solve(cost, maximize, hint, params, out)))
            else:
                out.send(("error", f"unexpected request {kind!r}"))
        except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
            out.send(("error", f"{type(exc).__name__}: {exc}"))


def main() -> None:
    """Entry point of the child (``python -P cpsat_worker.py PARENT_PID``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    parent = int(sys.argv[1]) if len(sys.argv) > 1 else os.getppid()
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    inp = Connection(os.dup(0), writable=False)
    out = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)  # a library's print goes to stderr, never into the protocol
    sys.stdout = sys.stderr
    serve(inp, out)


if __name__ == "__main__":
    main()
