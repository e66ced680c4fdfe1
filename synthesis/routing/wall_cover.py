"""The routing problem of method.md §5/§7 over the cut groups alone: the ``"cover"`` backend.

The cut binaries ``d_g`` (one per cut group with a binary, as in
:func:`synthesis.routing.model.build_model`) are the only variables of a small 0-1
*master* problem ``min sum_g weight_g d_g`` (MILP-agent: plus its ``d_state`` columns at
the priority cost of :func:`synthesis.routing.milp`). Every other condition of the model
is a family of rows over the binaries, generated lazily from the checks a master answer
``C`` fails (:mod:`synthesis.routing.cover_rows`):

(a) **bypass cover** -- a ``Src -> Tgt`` path over the c5 edges (avoiding I) that is
    open under ``C`` gives ``sum d_g >= 1`` over the distinct groups with a binary on
    it. Over binary ``d`` these rows say exactly what c4-c5 say (no open bypass);
(b) **flow** -- for the flow level ``F``: when the maximum flow over the open model
    edges is below ``F``, its minimum cut ``K`` (every model edge from the source side
    ``S`` out of it, cut or not) gives
    ``sum_g min(n_g(K), F) (1 - d_g) + #(edges of K without a binary) >= F``, which
    every cut set of flow at least ``F`` satisfies (max-flow min-cut) and ``C`` violates;
(c) **traps** (reactive, mixed and agent problems: c6-c8) -- an entry node of history
    ``q`` with no way to ``Tgt_sys`` under ``C``'s restrictions of ``q`` reaches some
    set ``R`` of ``G_sys``; every edge leaving ``R`` is closed, so at least one of the
    distinct groups closing them must open: ``sum d_g <= |groups| - 1``. The searches
    are :mod:`synthesis.routing.traps`' (the same as the flow MILP's lazy rows), with
    ``closed_loop`` as there;
(d) **exclusions** (agent counterexamples) -- ``sum_{g in C'} d_g <= |C'| - 1`` as in
    the flow MILP, and MILP-agent's ``d_state(p) >= d_g`` rows, up front.

Every row is valid for every cut set that meets the condition it stands for, so the
master is a relaxation and its optimum a lower bound; a master optimum that passes
(a)-(c) is therefore optimal for its flow level. The lexicographic objective of
method.md §5 (largest flow, then fewest cuts) is solved level by level: from one above
the heuristic's flow (:func:`synthesis.routing.heuristic.guess_routing`, a checked test)
up to the flow upper bound, each level's master is solved to its proven optimum; the
first infeasible level proves the maximum flow, and the last feasible level's optimum
(or, when no level above the heuristic's is feasible, that level's, started from the
heuristic's answer) is the answer. Rows (a), (c), (d) carry over between levels; the
minimum cuts ``K`` of (b) are kept and re-instantiated for each new level.

The master is a HiGHS MILP on the binaries only, grown in place (``addRows``) and
re-solved each round with the best known answer of the level as its start. Budgets:
``node_limit`` bounds each master solve's branch-and-bound nodes and
:attr:`CoverOptions.max_rounds` the rounds (both deterministic); ``time_limit`` /
``after_first`` as for the flow MILP (wall clock, not deterministic). A stop request
(Ctrl-C) ends a master solve within a second (:func:`~.solver_control.run_highs`) and
is honoured between rounds.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import highspy
import numpy as np

from ..graphs.consistency import check_consistency
from ..graphs.products import Products
from ..model.errors import InconsistentProblem
from .cover_rows import CoverSeparator, FlowCut, Row
from .model import MilpOptions, cut_groups, group_reductions, model_cut_bound, model_edges, model_flow_bound, static_moves_of
from .result import RoutingResult, required_entries
from .solver_control import Clock, SolveStatus, quiet_highs, run_highs

#: Master rounds per solve (each: one master MILP, then the separation): a deterministic
#: budget far above what the built-ins need.
MAX_ROUNDS = 20_000


@dataclass
class _Level:
    """The best answer known at one flow level, and what the master proved about it."""

    flow: int
    cut: np.ndarray | None = None  # bool per group of the best checked answer
    cost: float = float("inf")
    bound: float = 0.0
    proven: bool = False
    infeasible: bool = False


@dataclass
class _Stats:
    rounds: int = 0
    master_solves: int = 0
    master_nodes: int = 0
    rows: dict[str, int] = field(default_factory=lambda: {"cover": 0, "flow": 0, "trap": 0, "exclusion": 0, "place": 0, "cap": 0})
    separation_seconds: float = 0.0
    master_seconds: float = 0.0


class _Master:
    """The 0-1 master: a HiGHS MILP over the binaries, grown row by row."""

    def __init__(self, n_col: int, cost: np.ndarray, options: MilpOptions) -> None:
        h = quiet_highs(options.threads, options.random_seed)
        h.setOptionValue("mip_rel_gap", 0.0)
        h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)  # integral objective
        if options.node_limit is not None:
            h.setOptionValue("mip_max_nodes", int(options.node_limit))
        h.addVars(n_col, np.zeros(n_col), np.ones(n_col))
        idx = np.arange(n_col, dtype=np.int32)
        h.changeColsCost(n_col, idx, cost.astype(float))
        h.changeColsIntegrality(n_col, idx, np.full(n_col, highspy.HighsVarType.kInteger))
        h.changeObjectiveSense(highspy.ObjSense.kMinimize)
        self.h = h
        self.n_col = n_col
        self.cost = cost.astype(float)
        self.n_row = 0

    def add(self, rows: list[Row]) -> None:
        if not rows:
            return
        lo = np.array([r.lo for r in rows], dtype=float)
        hi = np.array([r.hi for r in rows], dtype=float)
        starts = np.cumsum([0] + [r.cols.size for r in rows[:-1]]).astype(np.int32)
        idx = np.concatenate([r.cols for r in rows]).astype(np.int32)
        val = np.concatenate([r.vals for r in rows]).astype(float)
        self.h.addRows(len(rows), lo, hi, idx.size, starts, idx, val)
        self.n_row += len(rows)

    def solve(self, start: np.ndarray | None, deadline: float | None, options: MilpOptions, flow: int) -> tuple[str, np.ndarray | None, float, str | None]:
        """(status, solution, proven lower bound, stopped_by); status ``"optimal"``,
        ``"infeasible"`` or ``"stopped"`` (a budget ended it; the solution, if any, is the
        master's best)."""
        h = self.h
        h.clearSolver()
        if start is not None:  # the best known answer of the level: it satisfies every row
            sol = highspy.HighsSolution()
            sol.col_value = list(start.astype(float))
            sol.value_valid = True
            h.setSolution(sol)
        run_highs(h, deadline, control=options.control, phase=f"wall-cover master at flow {flow}", flow=flow)
        ms = h.getModelStatus()
        info = h.getInfo()
        if ms == highspy.HighsModelStatus.kModelEmpty:  # no columns: every row is a constant
            lp = h.getLp()
            ok = bool(np.all(np.asarray(lp.row_lower_) <= 1e-9) and np.all(np.asarray(lp.row_upper_) >= -1e-9))
            return ("optimal", np.zeros(0), 0.0, None) if ok else ("infeasible", None, float("inf"), None)
        if ms == highspy.HighsModelStatus.kInfeasible:
            return "infeasible", None, float("inf"), None
        has = info.primal_solution_status == highspy.SolutionStatus.kSolutionStatusFeasible
        x = np.asarray(h.getSolution().col_value, dtype=float) if has else None
        bound = float(info.mip_dual_bound)
        if not np.isfinite(bound):
            bound = 0.0
        if ms == highspy.HighsModelStatus.kOptimal and x is not None:
            return "optimal", x, float(self.cost @ np.round(x)), None
        stopped = "time_limit" if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kInterrupt) else "node_limit"
        return "stopped", x, bound, stopped

    @property
    def nodes(self) -> int:
        return int(self.h.getInfo().mip_node_count)


class _Search:
    """The state of one cover solve: the rows found so far (level-independent ones, and the
    minimum cuts of (b)), the answers per flow level, the budgets and the counters."""

    def __init__(self, sep: CoverSeparator, options: MilpOptions, clock: Clock, max_rounds: int) -> None:
        self.sep, self.options, self.clock, self.max_rounds = sep, options, clock, max_rounds
        self.rows: list[Row] = sep.exclusion_rows() + sep.place_rows()
        self.flow_cuts: list[FlowCut] = []
        self.stats = _Stats()
        self.stats.rows["exclusion"] = len(sep.exclusion_rows())
        self.stats.rows["place"] = len(self.rows) - self.stats.rows["exclusion"]
        self.started = time.perf_counter()

    def solve_level(self, level: _Level) -> str | None:
        """Solve the master at ``level.flow`` to its proven optimum, from the level's best
        known answer; returns what stopped it (``None``: done, ``level`` says the outcome)."""
        sep, options, clock, stats = self.sep, self.options, self.clock, self.stats
        flow = level.flow
        master = _Master(sep.n_col, sep.cost, options)
        master.add(self.rows)
        master.add([fc.row(flow) for fc in self.flow_cuts])
        while True:
            if options.control is not None and options.control.stop_requested:
                raise KeyboardInterrupt
            if stats.rounds >= self.max_rounds:
                return "node_limit"
            if clock.deadline is not None and time.perf_counter() > clock.deadline:
                return "time_limit"
            stats.rounds += 1
            start = sep.master_point(level.cut) if level.cut is not None else None
            t = time.perf_counter()
            status, x, bound, stopped = master.solve(start, clock.latest(), options, flow)
            stats.master_seconds += time.perf_counter() - t
            stats.master_solves += 1
            stats.master_nodes += master.nodes
            if status == "infeasible":
                level.infeasible = level.cut is None
                level.proven = True
                level.bound = level.cost
                return None
            if x is None:  # a budget stopped the master before any solution
                return stopped
            level.bound = max(level.bound, float(np.ceil(bound - 1e-6)))
            cut = sep.cut_of_point(x)
            t = time.perf_counter()
            rows, flow_cuts = sep.separate(cut, flow)
            stats.separation_seconds += time.perf_counter() - t
            self.flow_cuts += flow_cuts
            rows += [("flow", fc.row(flow)) for fc in flow_cuts]
            if options.control is not None:
                options.control.report(
                    SolveStatus("wall cover", "min", level.cost if np.isfinite(level.cost) else None, level.bound, self.started, flow)
                )
            if not rows:  # the master's answer passes every check: a test
                cost = sep.cost_of(cut)
                if cost < level.cost:
                    level.cut, level.cost = cut, cost
                    clock.first_test()
                if status == "optimal":
                    level.proven = True
                    level.bound = level.cost
                    return None
                return stopped
            if options.progress is not None and stats.rounds % 25 == 0:
                options.progress(
                    f"wall cover: flow {flow}, round {stats.rounds}, master {sep.cost_of(cut):.0f} ({status}), "
                    f"best {level.cost:.0f}, rows {stats.rows}, master {stats.master_seconds:.1f} s, "
                    f"separation {stats.separation_seconds:.1f} s"
                )
            for kind, row in rows:
                stats.rows[kind] += 1
                if kind != "flow":
                    self.rows.append(row)
            master.add([r for _, r in rows])
            if status == "optimal" and level.cut is not None and level.bound >= level.cost - 0.5:
                level.proven = True  # the relaxation's optimum equals the best known answer
                return None
            if status != "optimal":
                return stopped


LevelSolver = Callable[["_Search", _Level], "str | None"]
"""Solves the master at one flow level to its proven optimum (or a budget), updating the
level; returns what stopped it (``None``: done). The default is :meth:`_Search.solve_level`
(a HiGHS master re-solved per round); :mod:`synthesis.routing.scip` passes one SCIP tree."""


def solve_cover(
    products: Products,
    options: MilpOptions,
    max_rounds: int = MAX_ROUNDS,
    solve_level: LevelSolver | None = None,
    backend: str = "cover",
) -> RoutingResult:
    """Solve the routing problem with the wall-cover master (see the module docstring);
    ``solve_level`` solves each flow level's master (default: the HiGHS master re-solved
    per round), ``backend`` names it in the stats.

    Returns the same :class:`RoutingResult` as the flow MILP: ``"optimal"`` only when the
    maximum flow and the fewest cuts at it are both proven.

    Raises
    ------
    InconsistentProblem
        ``unreachable`` or ``unroutable`` (no cut set separates, or every one traps
        the system / has flow 0).
    TimeoutError
        A budget ended the solve before any test was found.
    KeyboardInterrupt
        On Ctrl-C or a stop request through ``options.control``.
    """
    t0 = time.perf_counter()
    note = options.progress or (lambda msg: None)
    clock = Clock(options.time_limit, options.after_first)
    keep = check_consistency(products)
    groups = cut_groups(products, options)
    me = model_edges(products, groups, keep)
    required = required_entries(products, options)
    # the reductions' fixed-open groups are never cut: they get no binary here
    fixed_open = group_reductions(products, options, groups, me, bool(required)).fixed_open
    me = replace(me, has_var=me.has_var & ~fixed_open)
    sep = CoverSeparator(products, options, groups, me, required)
    if sep.bypass_with_all_cut():
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed: an unrestrictable route leads from the start "
            "to the goal around the test objective",
        )
    guess = sep.guess()
    graph_seconds = time.perf_counter() - t0
    t_solve = time.perf_counter()
    search = _Search(sep, options, clock, max_rounds)
    walls_bound = model_flow_bound(products, options, me)  # MILP-static: the walls' flow bound, a proof
    upper = guess.upper_bound if walls_bound is None else min(guess.upper_bound, walls_bound)
    levels: dict[int, _Level] = {}
    best = 0
    if guess.flow >= 1:
        cut = sep.guess_cut(guess)
        if cut is not None and sep.checks_pass(cut, guess.flow):
            levels[guess.flow] = _Level(guess.flow, cut, sep.cost_of(cut))
            best = guess.flow
            clock.first_test()
    stopped_by: str | None = None
    try:
        # top down: the first level with an answer is the maximum flow (every level above
        # it was proven infeasible), and its proven optimum is the answer
        flow = upper
        while flow >= max(best, 1):
            note(f"wall cover: flow {flow} (upper bound {upper}, heuristic {guess.flow})")
            level = levels.setdefault(flow, _Level(flow))
            _apply_cut_bound(products, options, sep, level)
            if not level.proven:
                stopped_by = (solve_level or _Search.solve_level)(search, level)
            if stopped_by is not None or level.cut is not None:
                break
            flow -= 1
    except TimeoutError:  # run_highs found the clock spent before a master could start
        stopped_by = "time_limit"
    best = max((f for f, lv in levels.items() if lv.cut is not None), default=0)
    if best < 1:
        if stopped_by is not None:
            raise TimeoutError(f"no test with flow >= 1 was found within the {_LIMIT_TEXT[stopped_by]}")
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed without trapping the system: no cut set "
            "routes every successful execution through it while leaving a way to the goal",
        )
    level = levels[best]
    if level.cut is None:  # every level with an answer has its cut set
        raise RuntimeError("the wall-cover search lost its answer")
    flow_proven = all(levels[f].infeasible for f in range(best + 1, upper + 1) if f in levels) and all(
        f in levels for f in range(best + 1, upper + 1)
    )
    optimal = level.proven and flow_proven and stopped_by is None
    gap = 0.0 if optimal else _gap(level)
    return _result(
        products, options, sep, level.cut, best, optimal, gap, stopped_by, search.stats, graph_seconds, time.perf_counter() - t_solve, backend
    )


_LIMIT_TEXT = {"time_limit": "time limit", "node_limit": "node limit"}


def _apply_cut_bound(products: Products, options: MilpOptions, sep: CoverSeparator, level: _Level) -> None:
    """MILP-static: the walls' cut bound at the level (:mod:`synthesis.routing.cut_bound`, a
    proof) raises the level's bound, and its minimum cuts' wall sets, grown by the routing
    heuristic and passing every check, become the level's answer where cheaper; an answer that
    meets the bound is proven without a master, and a level the bound proves empty (infinite)
    needs no master either."""
    cb = model_cut_bound(products, options, sep.groups, sep.me, level.flow)
    if cb is None:
        return
    if not np.isfinite(cb.value):  # no cut set has this flow: the level is empty, no master needed
        if level.cut is not None:
            raise RuntimeError(f"the walls' cut bound says no cut set has flow {level.flow}, which a checked test has: a FlowTest bug")
        level.infeasible = level.proven = True
        return
    level.bound = max(level.bound, cb.value)
    for walls in cb.candidates:
        guess = replace(sep.me, has_var=sep.me.has_var & walls).guess(products, route_seed=False)
        cut = sep.guess_cut(guess) if guess.flow >= level.flow else None
        if cut is not None and sep.checks_pass(cut, level.flow) and sep.cost_of(cut) < level.cost:
            level.cut, level.cost = cut, sep.cost_of(cut)
    if level.cut is not None and level.cost <= level.bound + 0.5:
        level.proven = True


def _gap(level: _Level) -> float:
    if not np.isfinite(level.cost):
        return float("inf")
    return float(max(level.cost - level.bound, 0.0) / max(abs(level.cost), 1.0))


def _result(
    products: Products,
    options: MilpOptions,
    sep: CoverSeparator,
    cut: np.ndarray,
    flow: int,
    optimal: bool,
    gap: float,
    stopped_by: str | None,
    stats: _Stats,
    graph_seconds: float,
    solve_seconds: float,
    backend: str,
) -> RoutingResult:
    groups = sep.groups
    static_moves_cut = np.isin(groups.move_key, groups.keys[cut & groups.static]) & static_moves_of(products, options)
    out: dict[str, Any] = {
        "backend": backend,
        "binary_vars": int(sep.n_col),
        "continuous_vars": 0,
        "constraints": int(sum(stats.rows.values())),
        "feasibility_vars": 0,
        "model_edges": int(sep.me.edges.size),
        "graph_seconds": graph_seconds,
        "solve_seconds": solve_seconds,
        "mip_gap": gap,
        "stopped_by": stopped_by if not optimal else None,
        "deterministic": options.deterministic,
        "rounds": stats.rounds,
        "master_solves": stats.master_solves,
        "master_nodes": stats.master_nodes,
        "rows": dict(stats.rows),
        "master_seconds": stats.master_seconds,
        "separation_seconds": stats.separation_seconds,
    }
    return RoutingResult(
        status="optimal" if optimal else "feasible",
        flow=flow,
        cut_edges=np.flatnonzero(cut[groups.of_edge]),
        cut_group_keys=[int(k) for k in groups.keys[cut]],
        static_moves_cut=static_moves_cut,
        blocked_places=sep.blocked_places(cut),
        mip_gap=gap,
        stats=out,
    )
