"""The child process that runs OR-Tools CP-SAT on the routing model (backend ``"cpsat"``).

Why a child process: OR-Tools bundles its own ``libhighs.so.1``, and that build and the one
of highspy cannot be loaded into one process (whichever is imported second fails with an
undefined symbol). So this module imports
OR-Tools' compiled CP-SAT helper and the standard library only, never ``synthesis`` (whose
package imports highspy), nor NumPy, SciPy or OR-Tools' ``cp_model`` (which imports
pandas): with them a fresh child starts several times slower than with the helper alone
(docs/benchmarks/solvers.md, "The default command"). The parent starts it by its file
path (``python -P PATH``), not as
``-m synthesis...``, so the package's ``__init__`` never runs here. Importing this module into a process that
holds highspy fails for the same reason: nothing in FlowTest imports it.

The protocol is a pipe each way (the child's standard input and output), each message a
tuple sent with :class:`multiprocessing.connection.Connection` (pickled, behind its length), so
the parent needs nothing of this module, which it must never import. Requests: ``("build", arrays)``,
``("row", idx, val, lo, hi)``, ``("rows", [(idx, val, lo, hi), ...])``,
``("solve", cost, maximize, hint, params)``, every array
as ``(typecode, bytes)`` of :mod:`array` (``"q"`` int64, ``"d"`` float64), so nothing
here needs NumPy to receive it. Answers:
``("ok", value)`` or ``("error", text)``; during a solve ``("progress", best, bound)``
lines come first. The protocol keeps its own copy of file descriptor 1, and descriptor 1
itself is pointed at standard error, so nothing a library prints can reach the parent's
standard output or corrupt a message. The child ignores SIGINT (the parent ends it on
Ctrl-C) and ends itself when its parent dies.

Every column of the routing model is integral here (CP-SAT has integer variables only);
why that keeps the optimum is said in :mod:`synthesis.routing.backends.cpsat`.
"""

from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
from array import array
from multiprocessing.connection import Connection
from typing import Any

from ortools.sat.python import cp_model_helper as cmh

#: Seconds between two looks of the child at whether its parent is still alive.
PARENT_POLL = 0.2

INF = float("inf")

_STATUS = {cmh.CpSolverStatus.OPTIMAL: "optimal", cmh.CpSolverStatus.FEASIBLE: "feasible", cmh.CpSolverStatus.INFEASIBLE: "infeasible"}


def _ceil(v: float) -> int:
    """``ceil(v - 1e-9)``: a bound a rounding error above an integer is that integer."""
    return math.ceil(v - 1e-9)


def _floor(v: float) -> int:
    """``floor(v + 1e-9)``."""
    return math.floor(v + 1e-9)


def unpack(packed: tuple[str, bytes]) -> array[Any]:
    """An array sent by the parent as ``(typecode, bytes)`` (``"q"``: int64, ``"d"``: float64):
    plain bytes, so that receiving it needs no NumPy here."""
    code, raw = packed
    out: array[Any] = array(code)
    out.frombytes(raw)
    return out


def _integral(values: array[Any] | list[float], what: str) -> list[int]:
    """``values`` rounded to integers; raises ``ValueError`` if one is not integral (the
    tolerance of ``numpy.allclose``)."""
    out = [round(v) for v in values]
    for c, v in zip(out, values, strict=True):
        if abs(v - c) > 1e-8 + 1e-5 * abs(c):
            raise ValueError(f"the routing model has a non-integral {what}")
    return out


def _merged(idx: array[Any] | list[int], coef: list[int]) -> tuple[list[int], list[int]]:
    """A linear expression as CP-SAT stores it: terms by variable index, duplicates summed,
    zero coefficients dropped."""
    terms: dict[int, int] = {}
    for j, c in zip(idx, coef, strict=True):
        terms[int(j)] = terms.get(int(j), 0) + c
    keys = sorted(j for j, c in terms.items() if c != 0)
    return keys, [terms[j] for j in keys]


class CpSatModel:
    """(In the child.) The routing model as a CP-SAT model (its ``CpModelProto``, written
    directly): one integer variable per column, one linear constraint per row; the
    objective and extra rows come per phase. Only OR-Tools' compiled helper is loaded:
    its Python layer (``cp_model``) imports pandas and NumPy, most of a fresh child's
    start-up."""

    def __init__(self, arrays: dict[str, tuple[str, bytes]]) -> None:
        self.proto = cmh.CpModelProto()
        col_lo, col_hi = unpack(arrays["col_lo"]), unpack(arrays["col_hi"])
        variables = self.proto.variables
        for j, (lo, hi) in enumerate(zip(col_lo, col_hi, strict=True)):
            var = variables.add()
            var.name = f"x{j}"
            var.domain.extend([_ceil(lo), _floor(hi)])
        self.n_cols = len(col_lo)
        indptr, indices, data = unpack(arrays["indptr"]), unpack(arrays["indices"]), unpack(arrays["data"])
        row_lo, row_hi = unpack(arrays["row_lo"]), unpack(arrays["row_hi"])
        for r in range(len(indptr) - 1):
            s, e = indptr[r], indptr[r + 1]
            if e > s:
                self.add_row(indices[s:e], data[s:e], row_lo[r], row_hi[r])

    def add_row(self, idx: array[Any] | list[int], val: array[Any] | list[float], lo: float, hi: float) -> None:
        """Add ``lo <= val . x[idx] <= hi``; integral coefficients, so the bounds are rounded
        inwards (``ceil(lo)``, ``floor(hi)``); an infinite bound becomes a finite one past
        every value the row can take."""
        coef = _integral(val, "coefficient")
        span = sum(abs(c) for c in coef) * 10**6 + 1
        ilo = -span if lo == -INF else _ceil(lo)
        ihi = span if hi == INF else _floor(hi)
        linear = self.proto.constraints.add().linear
        keys, coeffs = _merged(idx, coef)
        linear.vars.extend(keys)
        linear.coeffs.extend(coeffs)
        if ilo <= ihi:  # an empty domain (an infeasible row) is stored as no interval
            linear.domain.extend([ilo, ihi])

    def _set_objective(self, cost: array[Any], maximize: bool) -> None:
        """``cost . x`` as the objective (CP-SAT minimises: a maximum is stored negated,
        with scaling factor -1)."""
        nz = [j for j, c in enumerate(cost) if c != 0]
        keys, coeffs = _merged(nz, _integral([cost[j] for j in nz], "objective coefficient"))
        self.proto.clear_objective()
        self.proto.clear_floating_point_objective()
        objective = self.proto.objective
        objective.vars.extend(keys)
        if maximize:
            objective.scaling_factor = -1.0
            objective.offset = 0
            objective.coeffs.extend([-c for c in coeffs])
        else:
            objective.scaling_factor = 1.0
            objective.offset = 0
            objective.coeffs.extend(coeffs)

    def _set_hint(self, hint: array[Any] | None) -> None:
        self.proto.clear_solution_hint()
        if hint is not None:
            self.proto.solution_hint.vars.extend(range(self.n_cols))
            self.proto.solution_hint.values.extend([round(v) for v in hint])

    def solve(self, cost: array[Any], maximize: bool, hint: array[Any] | None, params: dict[str, Any], out: Connection) -> dict[str, Any]:
        """Optimise ``cost . x`` (integral costs) from ``hint`` under ``params``; progress
        lines go to ``out`` as solutions and bounds come.

        ``params``: ``random_seed``; ``deterministic_time`` (CP-SAT's deterministic
        seconds, ``None``: none); ``seconds`` (wall clock, ``None``: none); with
        ``after_first``, ``seconds`` bounds the time to the first solution of objective
        >= ``first_at`` and the search stops ``after_first`` seconds after it;
        ``rel_gap``; ``search`` (CP-SAT parameters by name, an enum's value by its name);
        ``reach`` (not ``None``: a feasibility solve on a copy of the model, for a solution
        of objective at least ``reach``, at most when minimising; the copy's extra row and
        missing objective do not touch the kept model); ``stop_at`` (minimising: stop at the
        first solution of objective at most this, a proven lower bound).
        """
        self._set_objective(cost, maximize)
        self._set_hint(hint)
        reach = params.get("reach")
        proto = self.proto if reach is None else self._reaching(cost, maximize, float(reach))
        p = cmh.SatParameters()
        p.num_workers = 1  # one worker: the same search, and answer, on every run and machine
        p.random_seed = int(params["random_seed"])
        p.log_search_progress = False
        for name, value in (params.get("search") or {}).items():
            _set_parameter(p, name, value)
        if params.get("deterministic_time") is not None:
            p.max_deterministic_time = float(params["deterministic_time"])
        seconds = params.get("seconds")
        after_first = params.get("after_first")
        if seconds is not None:
            p.max_time_in_seconds = max(float(seconds), 0.01) + (float(after_first) if after_first is not None else 0.0)
        if params.get("rel_gap"):
            p.relative_gap_limit = float(params["rel_gap"])
        first_at = float(params.get("first_at", 1.0))
        solver = cmh.SolveWrapper()
        solver.set_parameters(p)
        watch = _Watch(solver, out, maximize, after_first, first_at, None if reach is None else float(reach))
        stop_at = params.get("stop_at")
        if stop_at is not None and not maximize:
            watch.stop_at = float(stop_at)
        watch.keep, watch.n_cols = int(params.get("keep") or 0), self.n_cols
        solver.add_solution_callback(watch.callback)
        solver.add_best_bound_callback(watch.on_bound)
        timers = watch.start(seconds)
        cpu0 = time.process_time()
        try:
            response = solver.solve(proto)
        finally:
            for t in timers + watch.timers:
                t.cancel()
            solver.clear_solution_callback(watch.callback)
        status = response.status
        found = status in (cmh.CpSolverStatus.OPTIMAL, cmh.CpSolverStatus.FEASIBLE)
        answer: dict[str, Any] = {
            "status": _STATUS.get(status, "unknown"),
            "x": None,
            "objective": None,
            "bound": float(response.best_objective_bound) if found else None,
            "first_age": None if watch.first is None else time.perf_counter() - watch.first,
            "wall_seconds": float(response.wall_time),
            "cpu_seconds": time.process_time() - cpu0,  # this solve's CPU time (CP-SAT's user_time is a wall time)
            "process_cpu_seconds": time.process_time(),  # this child's CPU seconds so far
            "deterministic_time": float(response.deterministic_time),
            "conflicts": int(response.num_conflicts),
            "branches": int(response.num_branches),
            "solutions": watch.solutions,
        }
        if found:
            answer["x"] = [int(v) for v in response.solution]
            answer["objective"] = float(response.objective_value)
            if reach is not None:  # no objective in a feasibility solve, and no bound on one
                answer["objective"] = float(sum(c * answer["x"][j] for j, c in enumerate(cost) if c != 0))
                answer["bound"] = None
        return answer

    def _reaching(self, cost: array[Any], maximize: bool, reach: float) -> Any:
        """A copy of the model without objective and with the row ``cost . x >= reach``
        (``<=`` when minimising): a feasibility question that leaves the kept model as it is."""
        proto = cmh.CpModelProto()
        proto.copy_from(self.proto)
        proto.clear_objective()
        proto.clear_floating_point_objective()
        nz = [j for j, c in enumerate(cost) if c != 0]
        coef = _integral([cost[j] for j in nz], "objective coefficient")
        span = sum(abs(c) for c in coef) * 10**6 + 1
        keys, coeffs = _merged(nz, coef)
        linear = proto.constraints.add().linear
        linear.vars.extend(keys)
        linear.coeffs.extend(coeffs)
        linear.domain.extend([_ceil(reach), span] if maximize else [-span, _floor(reach)])
        return proto


def _set_parameter(p: Any, name: str, value: Any) -> None:
    """Set one CP-SAT parameter by name; an enum parameter's value is given by its name."""
    current = getattr(p, name)
    if isinstance(value, str):
        value = getattr(type(current), value)
    setattr(p, name, value)


class _Watch:
    """Progress lines for the parent, and the ``after_first`` rule: stop the search
    ``after_first`` seconds after its first solution of objective >= ``first_at``, or at
    ``seconds`` without one."""

    def __init__(self, solver: Any, out: Connection, maximize: bool, after_first: float | None, first_at: float, reach: float | None = None) -> None:
        self.solver = solver
        self.out = out
        self.maximize = maximize
        self.after_first = after_first
        self.first_at = first_at
        self.first: float | None = None
        self.best: float | None = None
        self.bound: float | None = None
        self.timers: list[threading.Timer] = []
        self.stop_at: float | None = None  # minimising: stop at a solution this good (a proven bound)
        self.keep = 0  # how many of the search's solutions to keep (``solutions``), in order found
        self.n_cols = 0
        self.solutions: list[list[int]] = []
        self._lock = threading.Lock()
        watch = self

        class _Callback(cmh.SolutionCallback):
            def OnSolutionCallback(self) -> None:  # noqa: N802 - the name CP-SAT calls
                if reach is not None:  # a feasibility solve: its solutions reach the objective asked for
                    watch.on_solution(reach, reach)
                else:
                    watch.on_solution(float(self.ObjectiveValue()), float(self.BestObjectiveBound()))
                if len(watch.solutions) < watch.keep:
                    watch.solutions.append([int(self.SolutionIntegerValue(j)) for j in range(watch.n_cols)])

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
            if self.stop_at is not None and objective <= self.stop_at + 1e-9:
                self.solver.stop_search()
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
                idx, val, lo, hi = message[1:]
                model.add_row(unpack(idx), unpack(val), lo, hi)
                out.send(("ok", time.process_time()))
            elif kind == "rows" and model is not None:
                for idx, val, lo, hi in message[1]:
                    model.add_row(unpack(idx), unpack(val), lo, hi)
                out.send(("ok", time.process_time()))
            elif kind == "solve" and model is not None:
                cost, maximize, hint, params = message[1:]
                out.send(("ok", model.solve(unpack(cost), maximize, None if hint is None else unpack(hint), params, out)))
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
