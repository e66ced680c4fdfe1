"""OR-Tools CP-SAT as a solver of the routing model (``MilpOptions.backend = "cpsat"``).

OR-Tools is a core dependency (``auto`` picks CP-SAT for mid-sized models). CP-SAT gets exactly the model
:func:`synthesis.routing.model.build_model` builds for HiGHS (both phases, the exclusions,
MILP-agent's places, the feasibility flows) with every column integral. That keeps the
optimum: once the cut binaries are fixed, what is left is a unit-capacity flow (integral
by max-flow integrality), aggregated feasibility flows with integral supplies and
capacities ``K (1 - d)`` (integral for the same reason), MILP-agent's place binaries
(integral already), and the potentials ``mu``, which may be taken as the 0/1
reachability from ``Src`` outside I (the fact the coupling rows of
:mod:`synthesis.routing.model` rest on). Every coefficient is integral, so a row
``lo <= a x <= hi`` is ``ceil(lo) <= a x <= floor(hi)``. The exhaustive-optimality tests
(``tests/synthesis/test_optimality.py``) hold this backend to that claim.

CP-SAT runs in a child process (:mod:`synthesis.routing.backends.cpsat_worker`): OR-Tools bundles
its own ``libhighs.so.1``, which cannot share a process with highspy. The model goes over
as arrays (plain bytes: the child loads no NumPy); the child keeps it between the two phases. Its search is deterministic: one
worker, a fixed ``random_seed``, and as a budget CP-SAT's deterministic time
(``MilpOptions.work_limit``); a wall-clock limit only when the user asks for one
(``time_limit`` / ``after_first``), and then the answer is reported non-deterministic as
with HiGHS. Phase 1 may add feasibility solves level by level, with the default search and at
the top level with another one (:data:`MAX_FLOW_SEARCH`, see
:func:`synthesis.routing.backends.cpsat_phases.phase1_cpsat`). Ctrl-C (or a stop request through :class:`SolveControl`) kills the child at
once and is raised as ``KeyboardInterrupt``. Every solution the child returns is checked
against the model here (bounds, rows, integrality, objective) before it is used.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..solver_control import POLL, OptionalSolver, SolveControl, SolveStatus
from .cpsat_pool import WORKER, close_idle_workers, give_back, prestart, take_worker

MISSING = "the cpsat backend needs OR-Tools, which is not installed: pip install 'ortools>=9.15,<9.16' (see docs/install.md)"
"""The one-line error when ``--backend cpsat`` is asked for without the extra."""

FEASIBILITY_TOLERANCE = 1e-6
"""Largest violation of a bound or row accepted in a CP-SAT solution (they are integral: 0)."""


PROOF_WORK = 1.0
"""Deterministic seconds of CP-SAT's default search (with its LP relaxation) for the maximum
flow before phase 1 turns to :data:`MAX_FLOW_SEARCH` (see
:func:`synthesis.routing.backends.cpsat_phases.phase1_cpsat`): enough for refueling and the random 5x5 grids,
which it proves in a small fraction of it (docs/benchmarks/solvers.md, "CP-SAT's phase 1")."""

LEVEL_WORK = 8.0
"""Deterministic seconds of phase 1's one :data:`MAX_FLOW_SEARCH` turn at the top flow level,
before the default search has what is left (see :func:`synthesis.routing.backends.cpsat_phases.reach_level`):
just enough for mars-exploration's flow-2 test from the heuristic's hint (docs/benchmarks/solvers.md, "CP-SAT's phase 1")."""

MAX_FLOW_SEARCH: dict[str, Any] = {"linearization_level": 0, "search_branching": "PORTFOLIO_WITH_QUICK_RESTART_SEARCH"}
"""CP-SAT's search for phase 1 (maximum flow): no LP relaxation, and quick restarts that
alternate CP-SAT's branching heuristics. Finding a wall set that lets the flow through is a
search for a solution, which the weak LP bound does not guide: on mars-exploration it finds a
flow-2 wall set where CP-SAT's default search finds none in several times the budget
(docs/benchmarks/solvers.md, "CP-SAT's phase 1"). It is bad at proving that no wall set
reaches a flow (far slower there than the default search and the LP bound), so
it only follows the default search, and only at the top flow level, for one turn of
:data:`LEVEL_WORK` before the default search."""


_ORTOOLS = OptionalSolver("ortools", MISSING)
available = _ORTOOLS.available
require = _ORTOOLS.require
ortools_version = _ORTOOLS.version


def _ints(a: Any) -> tuple[str, bytes]:
    """An integer array as the child receives it: ``("q", int64 bytes)`` (no NumPy there)."""
    return "q", np.ascontiguousarray(a, dtype=np.int64).tobytes()


def _floats(a: Any) -> tuple[str, bytes]:
    """A float array as the child receives it: ``("d", float64 bytes)``."""
    return "d", np.ascontiguousarray(a, dtype=np.float64).tobytes()


@dataclass(frozen=True)
class ModelArrays:
    """The routing model as plain arrays: what goes to the child, and what its answers
    are checked against."""

    a: sp.csr_matrix
    row_lo: np.ndarray
    row_hi: np.ndarray
    col_lo: np.ndarray
    col_hi: np.ndarray

    def violation(self, x: np.ndarray) -> float:
        """The largest violation by ``x`` of a column bound, a row or integrality."""
        ax = self.a @ x
        parts = [self.col_lo - x, x - self.col_hi, self.row_lo - ax, ax - self.row_hi, np.abs(x - np.round(x))]
        return float(max((float(np.max(p)) for p in parts if p.size), default=0.0))

    def with_row(self, idx: np.ndarray, val: np.ndarray, lo: float, hi: float) -> ModelArrays:
        """These arrays with one more row."""
        row = sp.csr_matrix((np.asarray(val, dtype=float), (np.zeros(len(idx), dtype=np.int64), np.asarray(idx))), shape=(1, self.a.shape[1]))
        return ModelArrays(
            sp.vstack([self.a, row], format="csr"),
            np.append(self.row_lo, lo),
            np.append(self.row_hi, hi),
            self.col_lo,
            self.col_hi,
        )


@dataclass(frozen=True)
class CpSatAnswer:
    """One CP-SAT run, checked: ``status`` (``optimal``, ``feasible``, ``infeasible``,
    ``unknown``: stopped without a solution), the solution ``x`` (``None`` without one), its
    relative ``gap`` to CP-SAT's bound, what stopped it short of a proof (``stopped_by``:
    ``"time_limit"``, ``"work_limit"`` or ``None``), how many seconds before its end the first
    solution of objective >= 1 came (``first_age``), the child's own figures
    (``stats``: wall, CPU and deterministic seconds, conflicts, branches), and CP-SAT's bound
    on the objective (``bound``; ``None`` without a solution or for a feasibility solve), and
    with ``keep`` the first solutions the search found, in order, each checked (``solutions``)."""

    status: str
    x: np.ndarray | None
    gap: float
    stopped_by: str | None
    first_age: float | None
    stats: dict[str, Any]
    bound: float | None = None
    solutions: tuple[np.ndarray, ...] = ()


class CpSatSession:
    """The routing model on CP-SAT in a child process, kept between the two phases.

    Use as a context manager: on a normal exit the child goes back to an idle pool for
    the next solve of this process; after an error, Ctrl-C or a stop request it is
    killed. ``control`` carries Ctrl-C / stop requests and receives the live status, as
    with HiGHS.
    """

    def __init__(self, arrays: ModelArrays, control: SolveControl | None = None) -> None:
        require()
        self.arrays = arrays
        self.control = control
        self.started = time.perf_counter()
        self._worker, self.fresh = take_worker()
        self._broken = False
        self._closed = False
        self._cpu_before = self._worker.cpu
        a = arrays.a
        self._worker.cpu = self._call(
            (
                "build",
                {
                    "indptr": _ints(a.indptr),
                    "indices": _ints(a.indices),
                    "data": _floats(a.data),
                    "row_lo": _floats(arrays.row_lo),
                    "row_hi": _floats(arrays.row_hi),
                    "col_lo": _floats(arrays.col_lo),
                    "col_hi": _floats(arrays.col_hi),
                },
            ),
        )
        self.spawn_seconds = time.perf_counter() - self.started
        self.spawn_cpu_seconds = self._worker.cpu - self._cpu_before

    @property
    def child_cpu_seconds(self) -> float:
        """CPU seconds the child spent for this session (start-up of a fresh child, the model, the solves)."""
        return self._worker.cpu - self._cpu_before

    def __enter__(self) -> CpSatSession:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def pid(self) -> int:
        """The child's process id."""
        return int(self._worker.proc.pid)

    def add_row(self, idx: np.ndarray, val: np.ndarray, lo: float, hi: float) -> None:
        """Add one row (phase 2's ``F >= F*``), here and in the child."""
        self._worker.cpu = self._call(("row", _ints(idx), _floats(val), float(lo), float(hi)))
        self.arrays = self.arrays.with_row(idx, val, lo, hi)

    def add_rows(self, rows: list[tuple[np.ndarray, np.ndarray, float, float]]) -> None:
        """Add rows ``(idx, val, lo, hi)``, here and in the child, in one message."""
        if not rows:
            return
        self._worker.cpu = self._call(("rows", [(_ints(i), _floats(v), float(lo), float(hi)) for i, v, lo, hi in rows]))
        n = self.arrays.a.shape[1]
        block = sp.csr_matrix(
            (
                np.concatenate([np.asarray(v, dtype=float) for _, v, _, _ in rows]),
                (np.repeat(np.arange(len(rows)), [len(i) for i, _, _, _ in rows]), np.concatenate([np.asarray(i, dtype=np.int64) for i, _, _, _ in rows])),
            ),
            shape=(len(rows), n),
        )
        self.arrays = ModelArrays(
            sp.vstack([self.arrays.a, block], format="csr"),
            np.append(self.arrays.row_lo, [lo for _, _, lo, _ in rows]),
            np.append(self.arrays.row_hi, [hi for _, _, _, hi in rows]),
            self.arrays.col_lo,
            self.arrays.col_hi,
        )

    def solve(
        self,
        cost: np.ndarray,
        maximize: bool,
        hint: np.ndarray | None,
        *,
        seconds: float | None,
        after_first: float | None,
        work_limit: float | None,
        rel_gap: float,
        random_seed: int,
        phase: str,
        flow: int | None = None,
        search: dict[str, Any] | None = None,
        reach: float | None = None,
        stop_at: float | None = None,
        keep: int = 0,
    ) -> CpSatAnswer:
        """Optimise ``cost . x`` (integral) from ``hint`` (used only if it satisfies the
        model), under the budgets (see the module docstring), and check the answer.

        ``search``: CP-SAT parameters by name for this solve (an enum's value by its name),
        such as :data:`MAX_FLOW_SEARCH`. With ``reach``, a feasibility solve instead: some
        solution of objective at least ``reach`` (at most, minimising), its status
        ``"feasible"`` (found), ``"infeasible"`` (proven none) or ``"unknown"``; the row
        is not kept. With ``stop_at`` (minimising), the search stops at its first solution of
        objective at most ``stop_at`` (a proven lower bound: that solution is optimal). With
        ``keep``, the first ``keep`` solutions of the search come back too (``solutions``).

        Raises ``KeyboardInterrupt`` on Ctrl-C or a stop request (the child is killed)."""
        if hint is not None and self.arrays.violation(hint) > FEASIBILITY_TOLERANCE:
            hint = None
        params = {
            "random_seed": int(random_seed),
            "deterministic_time": work_limit,
            "seconds": seconds,
            "after_first": after_first,
            "rel_gap": float(rel_gap),
            "first_at": 1.0,
            "search": dict(search or {}),
            "reach": None if reach is None else float(reach),
            "stop_at": None if stop_at is None else float(stop_at),
            "keep": int(keep),
        }
        sense = "max" if maximize else "min"
        t0 = time.perf_counter()
        if self.control is not None:
            self.control.report(SolveStatus(phase, sense, None, None, t0, flow))
        try:
            packed_hint = None if hint is None else _floats(hint)
            raw = self._call(("solve", _floats(cost), bool(maximize), packed_hint, params), progress=(phase, sense, t0, flow))
        finally:
            if self.control is not None:
                self.control.report(None)
        self._worker.cpu = float(raw["process_cpu_seconds"])
        return self._checked(raw, cost, seconds, work_limit, reach, maximize)

    def _checked(
        self,
        raw: dict[str, Any],
        cost: np.ndarray,
        seconds: float | None,
        work_limit: float | None,
        reach: float | None = None,
        maximize: bool = True,
    ) -> CpSatAnswer:
        """The child's answer as a :class:`CpSatAnswer`, its solution checked against the model."""
        stats = {k: raw[k] for k in ("wall_seconds", "cpu_seconds", "deterministic_time", "conflicts", "branches")}
        status = str(raw["status"])
        stopped_by = None
        if status in ("feasible", "unknown"):
            hit_work = work_limit is not None and raw["deterministic_time"] >= 0.999 * work_limit
            stopped_by = "work_limit" if hit_work or seconds is None else "time_limit"
        x = raw["x"]
        if x is None:
            return CpSatAnswer(status, None, float("inf"), stopped_by, raw["first_age"], stats)
        x = np.asarray(x, dtype=float)
        if x.size != self.arrays.col_lo.size or self.arrays.violation(x) > FEASIBILITY_TOLERANCE:
            raise RuntimeError("CP-SAT returned a solution that violates the routing model")
        kept = tuple(np.asarray(y, dtype=float) for y in raw.get("solutions") or ())
        if any(y.size != x.size or self.arrays.violation(y) > FEASIBILITY_TOLERANCE for y in kept):
            raise RuntimeError("CP-SAT returned a solution that violates the routing model")
        objective = float(np.asarray(cost, dtype=float) @ x)
        if abs(objective - float(raw["objective"])) > 1e-6 * max(1.0, abs(objective)):
            raise RuntimeError("CP-SAT reported another objective than its solution has")
        if reach is not None:
            if (objective < reach - 1e-6) if maximize else (objective > reach + 1e-6):
                raise RuntimeError("CP-SAT's feasibility solve returned a solution short of its target")
            return CpSatAnswer("feasible", x, float("inf"), None, raw["first_age"], stats)
        bound = raw["bound"]
        # integral objective: within less than 1 of the bound is a proof
        proven = bound is not None and np.isfinite(bound) and abs(objective - float(bound)) < 1.0 - 1e-6
        if status == "optimal" and proven:
            return CpSatAnswer("optimal", x, 0.0, None, raw["first_age"], stats, objective, kept)
        finite = bound is not None and np.isfinite(bound)
        gap = abs(objective - float(bound)) / max(abs(objective), 1.0) if finite else float("inf")
        return CpSatAnswer("feasible", x, float(gap), stopped_by, raw["first_age"], stats, float(bound) if finite else None, kept)

    def _call(self, message: tuple[Any, ...], progress: tuple[str, str, float, int | None] | None = None) -> Any:
        """Send a request and wait for its answer, in short steps so Ctrl-C and stop
        requests are seen within :data:`POLL` seconds; progress lines go to ``control``.
        Any failure, Ctrl-C included, kills the child."""
        worker = self._worker
        try:
            worker.to_child.send(message)
            while True:
                while not worker.from_child.poll(POLL):
                    if self.control is not None and self.control.stop_requested:
                        raise KeyboardInterrupt
                kind, *rest = worker.from_child.recv()
                if kind == "progress":
                    if progress is not None and self.control is not None:
                        phase, sense, t0, flow = progress
                        self.control.report(SolveStatus(phase, sense, rest[0], rest[1], t0, flow))
                    continue
                if kind == "error":
                    raise RuntimeError(f"the CP-SAT worker failed: {rest[0]}")
                return rest[0]
        except (EOFError, BrokenPipeError, ConnectionResetError) as exc:
            self._broken = True
            self.close()
            raise RuntimeError(f"the CP-SAT worker ended unexpectedly{worker.stderr_tail()}") from exc
        except KeyboardInterrupt:
            if self.control is not None:
                self.control.request_stop()
            self._broken = True
            self.close()
            raise
        except BaseException:
            self._broken = True
            self.close()
            raise

    def close(self) -> None:
        """Hand the child back for the next solve, or end it after a failure (once)."""
        if self._closed:
            return
        self._closed = True
        if self._broken:
            self._worker.close()
        else:
            give_back(self._worker)


__all__ = ["MISSING", "WORKER", "CpSatAnswer", "CpSatSession", "ModelArrays", "available", "close_idle_workers", "ortools_version", "prestart", "require"]
