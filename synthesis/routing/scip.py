"""The wall-cover master solved in one SCIP branch-and-bound tree per flow level: the
``"scip"`` backend (the optional extra ``flowtest[scip]``: PySCIPOpt, MIT, whose wheel
bundles SCIP 10 and SoPlex 8, both Apache-2.0).

The master is :mod:`synthesis.routing.wall_cover`'s: a 0-1 column per cut group with a
binary (MILP-agent: plus its ``d_state`` columns), ``min sum weight d``, and every other
condition of the routing problem as rows that :class:`~.cover_rows.CoverSeparator` finds
from the checks a cut set fails (bypass cover over distinct groups, minimum-cut flow rows
for the level, trap rows; exclusions and place rows up front). Where the ``cover`` backend
re-solves a HiGHS master from scratch after every round of rows, here one SCIP tree runs per
flow level, and a constraint handler adds the rows inside it:

* at every integral LP or pseudo solution (``consenfolp`` / ``consenfops``; enforcement
  priority below integrality's, so it sees only integral points) the separation runs on its
  cut set, and the rows it gives go in as global linear constraints (``CONSADDED``);
* a solution from elsewhere (the start) that fails a check is rejected (``conscheck``); its
  rows wait for the next enforcement;
* every column is locked both ways (rows of both signs may come), so SCIP makes no dual
  reduction that a later row would contradict.

A master answer SCIP accepts has passed every check, so a level's proven optimum is the
routing optimum at that flow, as with the ``cover`` backend, and the lexicographic
objective (largest flow, then fewest cuts) is solved level by level exactly as there
(:func:`synthesis.routing.wall_cover.solve_cover` with :func:`solve_level_scip`). SCIP's own
cutting planes and primal heuristics are off: measured on refueling they cost 6x the CPU
time (heuristics mostly propose cut sets the handler rejects) for fewer nodes
(docs/benchmarks.md, "SCIP one-tree branch and cut").

Determinism: one thread, SCIP's fixed default seed, deterministic callbacks, and as budget
``MilpOptions.node_limit`` (SCIP's ``limits/nodes``, per level); a wall-clock limit only when
the user asks for one (``time_limit`` / ``after_first``). SCIP runs in a daemon thread
(``optimizeNogil``) while the calling thread waits in short steps, so Ctrl-C (or a stop
request through :class:`~.solver_control.SolveControl`) interrupts SCIP and is raised as
``KeyboardInterrupt`` within a second. PySCIPOpt 6.3 shares a process with highspy 1.15
and OR-Tools 9.15 (checked: both import orders, a model solved with each), so no child
process is needed.
"""

from __future__ import annotations

import importlib
import time
from typing import Any

import numpy as np

from .cover_rows import Row
from .solver_control import OptionalSolver, SolveStatus, run_in_solver_thread, stdout_guard
from .wall_cover import _Level, _Search

MISSING = "the scip backend needs PySCIPOpt, which is not installed: pip install 'flowtest[scip]' (see docs/install.md)"
"""The one-line error when ``--backend scip`` is asked for without the extra."""


_PYSCIPOPT = OptionalSolver("pyscipopt", MISSING)
available = _PYSCIPOPT.available
require = _PYSCIPOPT.require
scip_version = _PYSCIPOPT.version  # each PySCIPOpt wheel bundles one SCIP release


def _pyscipopt() -> Any:
    """The PySCIPOpt module, imported when the backend first runs (importing it costs about
    0.1 s, which no other command should pay)."""
    return importlib.import_module("pyscipopt")


def _handler_class() -> Any:
    """The constraint handler class."""
    pyscipopt = _pyscipopt()
    result = pyscipopt.SCIP_RESULT
    base: Any = pyscipopt.Conshdlr

    class WallCoverHandler(base):  # type: ignore[misc]
        """Enforces the wall-cover checks at SCIP's integral points (see the module docstring)."""

        def __init__(self, tree: _LevelTree) -> None:
            super().__init__()
            self.tree = tree

        def conscheck(self, constraints: Any, solution: Any, checkintegrality: bool, checklprows: bool, printreason: bool, completely: bool) -> dict[str, Any]:
            rows = self.tree.violated(solution)
            if rows:
                self.tree.pending += rows
                return {"result": result.INFEASIBLE}
            return {"result": result.FEASIBLE}

        def _enforce(self) -> dict[str, Any]:
            rows = self.tree.violated(None) + self.tree.take_pending()
            if rows:
                self.tree.add_rows(rows)
                return {"result": result.CONSADDED}
            return {"result": result.FEASIBLE}

        def consenfolp(self, constraints: Any, nusefulconss: int, solinfeasible: bool) -> dict[str, Any]:
            return self._enforce()

        def consenfops(self, constraints: Any, nusefulconss: int, solinfeasible: bool, objinfeasible: bool) -> dict[str, Any]:
            return self._enforce()

        def conslock(self, constraint: Any, locktype: Any, nlockspos: int, nlocksneg: int) -> None:
            n = nlockspos + nlocksneg
            for var in self.tree.vars:
                self.model.addVarLocks(var, n, n)

    return WallCoverHandler


class _LevelTree:
    """One SCIP model: the master at one flow level, the rows known so far, the handler."""

    def __init__(self, search: _Search, flow: int) -> None:
        pyscipopt = _pyscipopt()
        self.search, self.sep, self.flow = search, search.sep, flow
        with stdout_guard():
            m = pyscipopt.Model()
        m.hideOutput()
        m.setParam("misc/catchctrlc", False)  # the calling thread handles Ctrl-C
        m.setParam("parallel/maxnthreads", 1)
        m.setSeparating(pyscipopt.SCIP_PARAMSETTING.OFF)
        m.setHeuristics(pyscipopt.SCIP_PARAMSETTING.OFF)
        if search.options.node_limit is not None:
            m.setParam("limits/nodes", int(search.options.node_limit))
        self.m = m
        self.vars = [m.addVar(f"d{i}", vtype="B", obj=float(c)) for i, c in enumerate(self.sep.cost)]
        self.pending: list[tuple[str, Row]] = []
        self.n_rows = 0
        for row in search.rows:
            self._add(row)
        for fc in search.flow_cuts:
            self._add(fc.row(flow))
        handler = _handler_class()(self)
        m.includeConshdlr(
            handler,
            "wallcover",
            "wall-cover checks of FlowTest's routing problem",
            sepapriority=-1,
            enfopriority=-1,
            chckpriority=-1,
            sepafreq=-1,
            propfreq=-1,
            eagerfreq=-1,
            maxprerounds=0,
            needscons=True,
        )
        cons = m.createCons(handler, "wallcover", initial=False, separate=False, enforce=True, check=True, propagate=False, local=False, removable=False)
        m.addPyCons(cons)

    def _add(self, row: Row) -> None:
        expr = _pyscipopt().quicksum(float(v) * self.vars[int(c)] for c, v in zip(row.cols.tolist(), row.vals.tolist(), strict=True))
        if np.isfinite(row.lo):
            self.m.addCons(expr >= float(row.lo), name=f"r{self.n_rows}")
        if np.isfinite(row.hi):
            self.m.addCons(expr <= float(row.hi), name=f"r{self.n_rows}u")
        self.n_rows += 1

    def add_rows(self, rows: list[tuple[str, Row]]) -> None:
        """Add rows to the tree (once each) and to the search's rows for the next levels."""
        seen: set[tuple[bytes, bytes, float, float]] = set()
        for kind, row in rows:
            key = (row.cols.tobytes(), row.vals.tobytes(), row.lo, row.hi)
            if key in seen:
                continue
            seen.add(key)
            self._add(row)
            self.search.stats.rows[kind] += 1
            if kind != "flow":  # flow rows are kept as their cuts (search.flow_cuts)
                self.search.rows.append(row)

    def take_pending(self) -> list[tuple[str, Row]]:
        out, self.pending = self.pending, []
        return out

    def point(self, sol: Any) -> np.ndarray:
        """The master columns at SCIP's solution ``sol`` (``None``: the current LP / pseudo solution)."""
        return np.array([self.m.getSolVal(sol, v) for v in self.vars])

    def violated(self, sol: Any) -> list[tuple[str, Row]]:
        """The ``(kind, row)`` pairs the cut set at ``sol`` violates at this level."""
        control = self.search.options.control
        if control is not None and control.stop_requested:
            self.m.interruptSolve()
        cut = self.sep.cut_of_point(self.point(sol))
        t = time.perf_counter()
        rows, flow_cuts = self.sep.separate(cut, self.flow)
        self.search.stats.separation_seconds += time.perf_counter() - t
        self.search.stats.rounds += 1
        self.search.flow_cuts += flow_cuts
        return rows + [("flow", fc.row(self.flow)) for fc in flow_cuts]


def solve_level_scip(search: _Search, level: _Level) -> str | None:
    """Solve the master at ``level.flow`` to its proven optimum in one SCIP tree (started
    from the level's best known answer); returns what stopped it (``None``: done, ``level``
    says the outcome). A :data:`~synthesis.routing.wall_cover.LevelSolver`."""
    options, clock, stats = search.options, search.clock, search.stats
    if options.control is not None and options.control.stop_requested:
        raise KeyboardInterrupt
    tree = _LevelTree(search, level.flow)
    m = tree.m
    if level.cut is not None:  # a checked answer: it satisfies every row
        sol = m.createSol()
        for v, val in zip(tree.vars, search.sep.master_point(level.cut).tolist(), strict=True):
            m.setSolVal(sol, v, val)
        m.addSol(sol, free=True)
    deadline = clock.latest()
    if deadline is not None:
        m.setParam("limits/time", max(deadline - time.perf_counter(), 0.01))
    t = time.perf_counter()
    _run(m, search, level)
    stats.master_seconds += time.perf_counter() - t
    stats.master_solves += 1
    stats.master_nodes += int(m.getNNodes())
    status = m.getStatus()
    if status == "userinterrupt":
        raise KeyboardInterrupt
    if status == "infeasible":
        level.infeasible = level.cut is None
        level.proven = True
        level.bound = level.cost
        return None
    if m.getNSols() > 0:
        cut = search.sep.cut_of_point(tree.point(m.getBestSol()))
        if search.sep.checks_pass(cut, level.flow):  # accepted by the handler; checked again
            cost = search.sep.cost_of(cut)
            if cost < level.cost:
                level.cut, level.cost = cut, cost
                clock.first_test()
    bound = float(m.getDualbound())
    if np.isfinite(bound):
        level.bound = max(level.bound, float(np.ceil(bound - 1e-6)))
    if status == "optimal" and level.cut is not None:
        level.proven = True
        level.bound = level.cost
        return None
    return "time_limit" if status == "timelimit" else "node_limit"


def _run(m: Any, search: _Search, level: _Level) -> None:
    """``m.optimizeNogil()`` in a solver thread; a ``KeyboardInterrupt`` or stop request
    interrupts SCIP and is raised within :data:`~.solver_control.STOP_GRACE` seconds."""
    status = SolveStatus("wall cover (SCIP)", "min", None, None, time.perf_counter(), level.flow)
    run_in_solver_thread(m.optimizeNogil, m.interruptSolve, search.options.control, status)
