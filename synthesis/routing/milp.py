"""The routing optimization of method.md §5 (and the MILP-agent options of §7) on HiGHS.

One builder serves every variant: MILP-static, MILP-reactive, MILP-mixed, with the
bidirectional option (c14), cuts tied across places (fuel levels), the test-agent
state penalties and exclusion of rejected cut sets. The model is assembled in bulk
as one sparse matrix.

Reductions, none of which changes the optimum of method.md §5:

* **Pruning.** Nodes of G with no path to ``Tgt`` carry no flow and lie on no
  ``Src -> Tgt`` path, so they (and their edges) are left out of the model; cut
  counts still refer to the whole G.
* **Cut groups.** Edges that must share a cut value (c9 ties over the same
  transition, c14 pairs, fuel levels) share one binary, weighted by the number of
  edges of G it stands for. A group that touches no constraint c5 is never worth
  cutting (cutting only lowers flow and tightens feasibility) and gets no binary.
* **Groups fixed open** (:mod:`synthesis.routing.bounds.reductions`): cut groups no bypass
  walk crosses, groups on every route through I, and (MILP-static) dominated groups get
  upper bound 0, so the solver branches on fewer binaries.
* **Lexicographic objective in two phases.** ``F - (1/|E|) sum d`` with integral F
  is maximised by first maximising F and then minimising the cuts with ``F`` fixed;
  both objectives are integral, so an absolute gap below 1 proves optimality.
* **Integral reachability and flows in MILP-reactive's phase 2.** The potentials ``mu``
  may be taken 0/1 and the flows integral once the cuts are binary
  (:func:`synthesis.routing.model.phase2_integral_columns` proves it), so phase 2 of
  MILP-reactive declares them integral on HiGHS (models of 200 rows or more): HiGHS then
  branches on which nodes ``Src`` reaches and its heuristics look for integral routes, which
  proves the fewest cuts of mid-size reactive models that branching on the cuts alone does
  not.
* **Closing rows per cut column** (large MILP-reactive models on HiGHS,
  :func:`per_cut_flow_rows`): the feasibility flows' c7 rows written once per history and cut
  over all the flow edges it closes; the same solutions with binary cuts
  (:func:`synthesis.routing.model._add_feasibility` proves it), a smaller model.
* **Aggregated feasibility flows.** For a history ``q`` with ``K`` kept entry nodes,
  the ``K`` unit flows of c6-c8 are replaced by one flow in which every entry node
  supplies one unit, on edges of capacity ``K (1 - d)``. By flow decomposition each
  unit reaches ``Tgt_sys`` over uncut edges, and conversely ``K`` paths give such a
  flow, so the feasible cut sets are the same. Each flow lives on the part of
  G_sys reachable from its entries and co-reachable to ``Tgt_sys``.

Layout of one solve (:func:`_solve_once`): :func:`synthesis.routing.model.build_model`
builds the model as named column and row blocks (:mod:`synthesis.routing.model`); then
:func:`_phase1` (maximum flow), :func:`_phase2` (fewest cuts at that flow) and
:func:`_result`. Which histories need their feasibility flows is found by the MILP's own
trap search (:mod:`synthesis.routing.traps`), never by the checks it is held to.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import highspy
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from ..graphs.consistency import check_consistency
from ..graphs.products import Products
from ..model.errors import InconsistentProblem
from .backends import cpsat, hitting_set
from .backends.separator import CoverSeparator
from .bounds.heuristic import RoutingGuess
from .model import BACKENDS, CutGroups, RoutingModel, build_model, model_cut_bound, phase2_integral_columns, static_moves_of
from .options import MilpOptions
from .result import RoutingResult as RoutingResult
from .result import blocked_by as blocked_by
from .result import blocked_of_edges, required_entries
from .solver_control import Clock, SolverAbandoned, quiet_highs, run_highs, solver_version
from .traps import trapped_configurations, trapped_entries

EAGER_FLOW_LIMIT = 200_000  # histories x G_sys edges up to which all feasibility flows go in at once


def solve_routing(products: Products, options: MilpOptions | None = None) -> RoutingResult:
    """Solve the routing MILP for least-restrictive cuts (method.md §5, §7).

    MILP-static has no feasibility flows (c6-c8), as method.md §5 says: static walls
    are part of the map the system sees from its first step, so a correct system
    plans around them, and the test is feasible iff a successful run exists under
    them (``F >= 1``). An entry node that the walls alone doom is one no correct
    system enters (the environments call a run there violated: the system's fault).
    The other variants add the flows where they bind: all of them at once unless
    that would swamp the model (``EAGER_FLOW_LIMIT``), else lazily: the answer is
    checked by graph search, and the flows of the histories whose entry nodes it
    traps are added, until no entry node is trapped. A relaxation's optimum that
    satisfies every omitted constraint is optimal for the full model, so the answer
    is the optimum of method.md §5, reached with the flows only where they bind.

    Beyond the method (with ``options.closed_loop``), closed-loop configurations that
    the restrictions trap although they are not entry nodes are added as entry nodes
    of their history, so no test returned traps the system anywhere. This matters
    with one-way moves (outside method.md §2's bidirectional assumption), where the
    method's optimum can lead the system into a dead end; it is off by default
    because on irreversible systems such as fuel grids it also forbids configurations
    that only a wasteful system reaches, and can make a routable test unroutable.

    Raises
    ------
    InconsistentProblem
        ``unreachable`` or ``unroutable`` (including a MILP without solution, or
        maximum flow 0: every routing cut set would trap the system).
    """
    options = options or MilpOptions()
    check_backend(options)
    # small reactive models start with every history's flows (adding them lazily costs
    # more rounds than it saves there); reactive ones whose flows would swamp the model
    # start without
    if options.feasibility not in ("auto", "eager", "lazy"):
        raise ValueError(f"unknown feasibility option {options.feasibility!r}; expected auto, eager or lazy")
    required = required_entries(products, options)
    eager = options.feasibility == "eager" or (
        options.feasibility == "auto" and len(required) * products.system.src.size <= EAGER_FLOW_LIMIT
    )
    entries: dict[int, np.ndarray] = dict(required) if eager else {}
    clock = Clock(options.time_limit, options.after_first)
    rounds = 0
    while True:
        rounds += 1
        try:
            result = _solve_once(products, options, entries, required, clock)
        except _FlowsBind as more:
            # the phase-1 answer already traps: add those flows before phase 2
            trapped = more.trapped
        else:
            blocked = blocked_by(products, result)
            trapped = trapped_entries(products, blocked, _with_extra(required, entries))
        if not trapped:
            traps = trapped_configurations(products, blocked) if options.closed_loop else np.zeros(0, dtype=np.int64)
            if traps.size == 0:
                return _with_rounds(result, rounds, entries)
            trapped = {}
            for q in np.unique(products.virtual.hist[traps]):
                trapped[int(q)] = products.projection[traps[products.virtual.hist[traps] == q]]
        grew = False
        for q, nodes in trapped.items():
            base = entries.get(q, required.get(q, np.zeros(0, dtype=np.int64)))
            merged = np.union1d(base, nodes)
            grew |= q not in entries or merged.size > entries[q].size
            entries[q] = merged
        if not grew:
            # the model already holds these flows: the answer cannot change, and the
            # independent checks will report the disagreement as a FlowTest bug
            return _with_rounds(result, rounds, entries)
        if options.progress:
            options.progress(f"routing MILP: adding feasibility flows for {len(trapped)} trapped histories")


def check_backend(options: MilpOptions) -> None:
    """Refuse a backend that cannot run; ``"auto"`` is resolved once the model is built
    (:func:`auto_backend` decides on its size).

    Raises
    ------
    ValueError
        For an unknown backend name.
    ProblemError
        For ``"cpsat"`` without OR-Tools installed (:data:`synthesis.routing.backends.cpsat.MISSING`).
    """
    if options.backend not in BACKENDS:
        raise ValueError(f"unknown routing backend {options.backend!r}; expected one of {', '.join(BACKENDS)}")
    if options.flow_rows not in FLOW_ROWS:
        raise ValueError(f"unknown flow_rows option {options.flow_rows!r}; expected one of {', '.join(FLOW_ROWS)}")
    if options.backend == "cpsat":
        cpsat.require()


AUTO_CPSAT_ROWS: dict[str, tuple[int, int]] = {"static": (200, 15_000), "reactive": (200, 2_500)}
"""Per routing mode, the model sizes (rows, inclusive) at which ``"auto"`` runs CP-SAT; HiGHS
elsewhere and in the other modes. Measured per model kind on the 5x5 random grid study's
instances (docs/benchmarks.md, "auto's backend rule per model kind"; seeds 0-2 of all nine
cells, one worker each, 30 s each, measured under load, so CPU seconds and proofs compared):

* static, 259-13,310 rows (safety to reaction |AP| = 7): CP-SAT proved 24 of 27, HiGHS 19,
  CP-SAT in 0.13-3.9 CPU s wherever it proved (HiGHS 0.03-17.8 s on the same ones);
  mars-exploration (21,515 rows) stays on HiGHS: neither proves its fewest cuts, and its
  shipped artifact is HiGHS's under a node limit.
* reactive, 300-2,026 rows (safety, reachability |AP| = 2, 3, reaction |AP| = 3): CP-SAT
  proved 18 of 18 in 0.13-1.1 CPU s, HiGHS 17 in 0.02-7.0; from 2,706 rows (reachability
  |AP| = 4, 2,706-2,830; reaction |AP| = 5 and 7, 8,887-43,166) HiGHS proved 3 of 9 and CP-SAT
  none (also session 8: CP-SAT 2 of 14 on reachability |AP| = 4). The edge lies in the
  measured gap 2,046-2,706.
* below 200 rows (the built-ins small-reactive, example1, beaver-rescue: 84-153 rows) HiGHS
  answers in 0.03 CPU s, a CP-SAT child (start, model transfer, solve) in 0.11-0.14.

The rule reads the built model only, so the choice, and with it the answer, is the same on
every machine with the locked install. Agent problems (mode ``"mixed"``, many small MILPs)
stay on HiGHS."""

AUTO_CPSAT_MODES: tuple[str, ...] = tuple(AUTO_CPSAT_ROWS)
"""The routing modes in which ``"auto"`` may run CP-SAT (agent problems, mode ``"mixed"``, stay on HiGHS)."""


def auto_backend(rm: RoutingModel, options: MilpOptions) -> str:
    """The backend ``"auto"`` runs on a built model (see :data:`AUTO_CPSAT_ROWS`: by mode and
    rows); HiGHS when OR-Tools is missing. A function of the model and options only, so the choice, and with
    it the answer, is the same on every machine with the locked install."""
    lo, hi = AUTO_CPSAT_ROWS.get(options.mode, (1, 0))
    if lo <= rm.model.n_row <= hi and cpsat.available():
        return "cpsat"
    return "highs"


FLOW_ROWS = ("auto", "edge", "cut")
"""The ways of writing the feasibility flows' closing rows (``MilpOptions.flow_rows``)."""

PER_CUT_MIN_ROWS = 20_000
"""MILP-reactive models on HiGHS with at least this many rows (written per flow edge) get the
feasibility flows' closing rows per cut column (:func:`per_cut_flow_rows`). Measured on the
5x5 random grids' reaction |AP| = 7 reactive models (36,647-43,676 rows, 23,000-25,000 per
cut column; docs/benchmarks.md, "Session 11 (issue 18)"); below, nothing was measured
(reaction |AP| = 5: about 9,000 rows; reachability |AP| = 4: about 2,800), so those models
keep method.md's rows and their answers."""


def per_cut_flow_rows(rm: RoutingModel, options: MilpOptions) -> bool:
    """Whether ``"auto"`` writes the feasibility flows' closing rows per cut column
    (:func:`synthesis.routing.model._add_feasibility` proves the answers the same): on
    HiGHS, for MILP-reactive models of at least :data:`PER_CUT_MIN_ROWS` rows built per flow
    edge. A function of the built model and the options only, so the choice is the same on
    every machine."""
    return (
        options.backend == "highs"
        and options.mode == "reactive"
        and bool(rm.cols.feasibility)
        and rm.model.n_row >= PER_CUT_MIN_ROWS
    )


def backend_version(backend: str) -> str:
    """The version of the package a backend's answers depend on (highspy, OR-Tools)."""
    if backend == "cpsat":
        return cpsat.ortools_version() or "unknown"
    return solver_version()


def _with_rounds(result: RoutingResult, rounds: int, entries: dict[int, np.ndarray]) -> RoutingResult:
    """``result`` with the feasibility rounds and histories of its solve in its stats."""
    return replace(result, stats={**result.stats, "feasibility_rounds": rounds, "feasibility_histories": len(entries)})


def _with_extra(kept: dict[int, np.ndarray], extra: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    out = dict(kept)
    for q, nodes in extra.items():
        out[q] = np.union1d(out.get(q, np.zeros(0, dtype=np.int64)), nodes)
    return out


class _FlowsBind(Exception):
    """Phase 1's answer traps entry nodes whose feasibility flows the model lacks."""

    def __init__(self, trapped: dict[int, np.ndarray]) -> None:
        super().__init__(f"{len(trapped)} histories trapped")
        self.trapped = trapped


@dataclass(frozen=True)
class _Phase:
    """What a phase of the solve ends with."""

    x: np.ndarray
    status: str
    gap: float
    stopped_by: str | None
    cut_bound: dict[str, Any] | None = None  # phase 2: the walls' cut bound, what it proved (see _CutProof)
    hitting_set: dict[str, Any] | None = None  # phase 2: what the hitting set did (see _hitting_set)
    abandoned: bool = False  # HiGHS was left running past the deadline: its model must not be touched


ABANDON_GRACE = 0.25
"""Seconds past the solve's deadline after which a HiGHS run still busy is left behind
(:class:`~synthesis.routing.solver_control.SolverAbandoned`): the time limit holds."""


def _hard(clock: Clock) -> float | None:
    """The moment a HiGHS run is abandoned: the solve's deadline plus :data:`ABANDON_GRACE`."""
    return None if clock.deadline is None else clock.deadline + ABANDON_GRACE


def _solve_once(
    products: Products,
    options: MilpOptions,
    entries: dict[int, np.ndarray],
    required: dict[int, np.ndarray],
    clock: Clock,
) -> RoutingResult:
    """One solve of the routing MILP with feasibility flows for the given entry nodes:
    build the model, phase 1 (maximum flow), phase 2 (fewest cuts at that flow).

    Raises :class:`_FlowsBind` when the maximum-flow answer already traps ``required``
    entry nodes outside ``entries`` (before the costlier fewest-cuts phase)."""
    note = options.progress or (lambda msg: None)
    t0 = time.perf_counter()
    rm = build_model(products, options, entries, check_consistency(products))
    graph_seconds = time.perf_counter() - t0
    by_auto = options.backend == "auto"
    if by_auto:
        options = replace(options, backend=auto_backend(rm, options))
    if options.flow_rows == "auto" and per_cut_flow_rows(rm, options):
        options = replace(options, flow_rows="cut")
        rm = build_model(products, options, entries, check_consistency(products))
    if options.backend == "cpsat":
        return _solve_once_cpsat(rm, products, options, entries, required, clock, graph_seconds, by_auto)
    h = _highs(options)
    h.passModel(rm.model.to_highs(np.zeros(rm.n_col), maximize=True))
    t_solve = time.perf_counter()
    note("routing MILP, phase 1 of 2: maximum flow")
    first = _phase1(h, rm, products, options, entries, clock)
    flow = _flow_of_phase1(rm, first)
    _raise_if_flows_bind(rm, products, options, first.x, {q: v for q, v in required.items() if q not in entries})
    if first.abandoned:  # the time is spent and HiGHS still holds the model: phase 1's answer stands
        return _result(rm, products, options, first, first, flow, graph_seconds, time.perf_counter() - t_solve)
    note(f"routing MILP, phase 2 of 2: fewest cuts at flow {flow}")
    second = _phase2(h, rm, first.x, flow, options, clock, _cut_proof(products, rm, options, entries, flow))
    return _result(rm, products, options, first, second, flow, graph_seconds, time.perf_counter() - t_solve)


def _phase1(
    h: highspy.Highs, rm: RoutingModel, products: Products, options: MilpOptions, entries: dict[int, np.ndarray], clock: Clock
) -> _Phase:
    """Phase 1, maximum flow: proven by the heuristic when it attains the flow upper bound, or
    (MILP-static) by a checked candidate of the walls' cut bound at that bound
    (:func:`_test_at_bound`), else solved by HiGHS (seeded by the heuristic's answer, kept as
    the fallback)."""
    guess = rm.guess(products, traps=_trap_test(products, rm.groups, entries))
    x_guess = _guess_solution(products, rm, guess, options)
    if x_guess is not None:
        clock.first_test()
    if x_guess is not None and guess.flow == guess.upper_bound:
        return _Phase(x_guess, "optimal", 0.0, None)  # the flow upper bound is attained: proven
    x_top = _test_at_bound(products, rm, options, entries, guess.upper_bound)
    if x_top is not None:
        clock.first_test()
        return _Phase(x_top, "optimal", 0.0, None)  # a cut bound candidate attains the flow upper bound
    cost = np.zeros(rm.n_col)
    cost[rm.cols.flow[rm.out_src]] = 1.0
    h.changeColsCost(rm.n_col, np.arange(rm.n_col, dtype=np.int32), cost)
    if rm.flow_bound is not None:
        # MILP-static's walls' bound (synthesis.routing.bounds.flow_bound), below the LP's: as the
        # row F <= bound, HiGHS stops as soon as a test attains it (valid for phase 2 too)
        out = rm.cols.flow[rm.out_src].astype(np.int32)
        h.addRow(-highspy.kHighsInf, rm.flow_bound + 0.5, out.size, out, np.ones(out.size))
    # a route-seeded start is kept as the fallback but not handed to HiGHS: from
    # it, HiGHS's neighbourhood heuristics stay near the lone route (mars-exploration:
    # no flow 2 in 300 s, against 170 s from scratch)
    if x_guess is not None and not guess.from_route and options.offer_starts:
        _set_solution(h, x_guess)
    watch = clock.watching_first()
    abandoned = False
    try:
        status, gap, x1 = _run(
            h, clock.latest(), options, phase="phase 1 (maximum flow)", clock=clock, watch_first=watch, hard=_hard(clock)
        )
    except TimeoutError as exc:
        if x_guess is None:
            raise
        abandoned = isinstance(exc, SolverAbandoned)
        # the heuristic's flow against its proven upper bound
        status, gap, x1 = "feasible", (guess.upper_bound - guess.flow) / max(guess.flow, 1), None
    stopped_by = "time_limit" if abandoned else _stopped_by(h)
    if abandoned and x_guess is not None:  # (x_guess is never None here: the TimeoutError was raised then)
        return _Phase(x_guess, "feasible", gap, stopped_by, abandoned=True)
    if status == "infeasible":
        raise _no_cut_set()
    x = x1 if x1 is not None else x_guess
    if x is None:  # _run returns a solution unless it raised
        raise RuntimeError("phase 1 of the routing MILP ended without a solution")
    if x_guess is not None and guess.flow > rm.flow_of(x) + 0.5:
        return _Phase(x_guess, "feasible", gap, stopped_by)  # HiGHS stopped below the heuristic's flow
    return _Phase(x, status, gap, stopped_by)


def _no_cut_set() -> InconsistentProblem:
    """The answer when phase 1's model has no solution at all."""
    return InconsistentProblem(
        "unroutable",
        "the test objective cannot be routed without trapping the system: no cut set "
        "routes every successful execution through it while leaving a way to the goal",
    )


def _solve_once_cpsat(
    rm: RoutingModel,
    products: Products,
    options: MilpOptions,
    entries: dict[int, np.ndarray],
    required: dict[int, np.ndarray],
    clock: Clock,
    graph_seconds: float,
    by_auto: bool = False,
) -> RoutingResult:
    """:func:`_solve_once` on CP-SAT (:mod:`synthesis.routing.backends.cpsat`): the same model and
    phases, in a child process that holds the model between them; chosen ``by_auto``, phase 2
    of MILP-static with few free groups tries the hitting set first (:func:`_hitting_set`)."""
    note = options.progress or (lambda msg: None)
    a = rm.model.matrix().tocsr()
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    t_solve = time.perf_counter()
    with cpsat.CpSatSession(cpsat.ModelArrays(a, row_lo, row_hi, col_lo, col_hi), options.control) as session:
        note("routing MILP (CP-SAT), phase 1 of 2: maximum flow")
        first, runs = _phase1_cpsat(session, rm, products, options, entries, clock)
        flow = _flow_of_phase1(rm, first)
        _raise_if_flows_bind(rm, products, options, first.x, {q: v for q, v in required.items() if q not in entries})
        note(f"routing MILP (CP-SAT), phase 2 of 2: fewest cuts at flow {flow}")
        proof = _cut_proof(products, rm, options, entries, flow)
        ihs = _hitting_set(products, rm, first.x, flow, options, clock, proof) if by_auto else None
        second, more = _phase2_cpsat(session, rm, first.x, flow, options, clock, proof, ihs)
        spawn, spawn_cpu, child_cpu = session.spawn_seconds, session.spawn_cpu_seconds, session.child_cpu_seconds
    result = _result(rm, products, options, first, second, flow, graph_seconds, time.perf_counter() - t_solve)
    runs = runs + more
    figures = {
        "spawn_seconds": spawn,
        "spawn_cpu_seconds": spawn_cpu,
        "child_cpu_seconds": child_cpu,
        "runs": len(runs),
        **{k: sum(r[k] for r in runs) for k in ("wall_seconds", "cpu_seconds", "deterministic_time", "conflicts", "branches")},
    }
    return replace(result, stats={**result.stats, "cpsat": figures})


def _cpsat_budget(clock: Clock) -> tuple[float | None, float | None]:
    """``(seconds, after_first)`` of a CP-SAT run under ``clock``: the wall-clock limits the
    user asked for (none: ``(None, None)``)."""
    now = time.perf_counter()
    seconds = None if clock.deadline is None else max(clock.deadline - now, 0.01)
    return seconds, (clock.after_first if clock.watching_first() else None)


def _phase1_cpsat(
    session: cpsat.CpSatSession, rm: RoutingModel, products: Products, options: MilpOptions, entries: dict[int, np.ndarray], clock: Clock
) -> tuple[_Phase, list[dict[str, Any]]]:
    """:func:`_phase1` on CP-SAT: the heuristic's answer (or a checked candidate of the walls'
    cut bound) proves the maximum flow when it attains the upper bound; else CP-SAT maximises the flow from it (as a hint) with its
    default search, whose LP bound proves small cases at once, for at most
    :data:`~synthesis.routing.backends.cpsat.PROOF_WORK` deterministic seconds. If that does not
    prove it, phase 1 asks level by level, from the flow above the best test known, whether
    a test of that flow exists (:func:`_reach_level`): found, the best test and the level
    rise; proven impossible, the best test is the maximum (the row ``F <= level - 1`` is
    valid and kept for phase 2), and with no test at all, level 1 impossible means no cut
    set exists. ``work_limit`` bounds the whole phase."""
    guess = rm.guess(products, traps=_trap_test(products, rm.groups, entries))
    x_guess = _guess_solution(products, rm, guess, options)
    if x_guess is not None:
        clock.first_test()
    if x_guess is not None and guess.flow == guess.upper_bound:
        return _Phase(x_guess, "optimal", 0.0, None), []
    x_top = _test_at_bound(products, rm, options, entries, guess.upper_bound)
    if x_top is not None:
        clock.first_test()
        return _Phase(x_top, "optimal", 0.0, None), []  # a cut bound candidate attains the flow upper bound
    out = rm.cols.flow[rm.out_src]
    cost = np.zeros(rm.n_col)
    cost[out] = 1.0
    best = x_guess if options.offer_starts else None
    runs: list[dict[str, Any]] = []
    seconds, after_first = _cpsat_budget(clock)
    left = options.work_limit
    ans = session.solve(
        cost, True, best, seconds=seconds, after_first=after_first,
        work_limit=cpsat.PROOF_WORK if left is None else min(cpsat.PROOF_WORK, left), rel_gap=options.mip_rel_gap,
        random_seed=options.random_seed, phase="phase 1 (maximum flow)",
    )
    runs.append(ans.stats)
    left = None if left is None else left - ans.stats["deterministic_time"]
    if ans.first_age is not None:
        clock.first_test(at=time.perf_counter() - ans.first_age)
    if ans.status == "infeasible":
        raise _no_cut_set()
    if ans.x is not None:
        best = ans.x
    if ans.status == "optimal" and ans.x is not None:
        return _Phase(ans.x, "optimal", 0.0, None), runs
    # no test has a larger flow than cap (the flow upper bound, CP-SAT's bound)
    cap = guess.upper_bound if ans.bound is None else min(guess.upper_bound, int(np.floor(ans.bound + 1e-6)))
    stopped_by: str | None = ans.stopped_by
    if ans.stopped_by != "time_limit" and (left is None or left > 0.0):
        known = max(guess.flow if x_guess is not None else 0, 0 if best is None else int(round(rm.flow_of(best))))
        best, cap, stopped_by = _reach_level(session, rm, cost, best, known, cap, left, options, clock, runs)
    x = best if best is not None else x_guess
    if x is None:
        if cap < 1:
            raise _no_cut_set()
        raise TimeoutError(f"the routing MILP found no solution within the {_LIMIT_TEXT.get(stopped_by or '', 'time limit')}")
    if x_guess is not None and guess.flow > rm.flow_of(x) + 0.5:
        x = x_guess  # CP-SAT stopped below the heuristic's flow
    flow = int(round(rm.flow_of(x)))
    if flow >= cap:
        return _Phase(x, "optimal", 0.0, None), runs
    return _Phase(x, "feasible", (cap - flow) / max(flow, 1), stopped_by), runs


def _reach_level(
    session: cpsat.CpSatSession,
    rm: RoutingModel,
    cost: np.ndarray,
    best: np.ndarray | None,
    known: int,
    cap: int,
    left: float | None,
    options: MilpOptions,
    clock: Clock,
    runs: list[dict[str, Any]],
) -> tuple[np.ndarray | None, int, str | None]:
    """Phase 1 on CP-SAT after the default search: settle the maximum flow level by level,
    each level a feasibility solve for a test of that flow.

    ``level`` starts at the best flow known plus one (``known``: the flow of ``best``, or of
    the heuristic's test, which ``best`` lacks when starts are not offered). Below the top
    (``level < cap``), CP-SAT's default search gets what is left of the budget: its LP
    relaxation and clause learning prove a level empty where the search at the bound does
    not (random 5x5 reaction grids' flow 2 in 1-30 deterministic seconds, and level 1 of
    the grids without a test, docs/benchmarks.md), and it finds tests there too. At the top
    (``level == cap``: a test there is the maximum),
    :data:`~synthesis.routing.backends.cpsat.MAX_FLOW_SEARCH` (no LP, quick restarts, from ``best`` as a
    hint: finds mars-exploration's flow 2, where the default search does not) gets one turn
    of :data:`~synthesis.routing.backends.cpsat.LEVEL_WORK` first, then the default search what is
    left (one run: CP-SAT cannot resume a search, and restarting it with doubling budgets
    cost the 5x5 reaction grids 2-6 times the single run's proof). A test found raises
    ``best`` and the level; a level proven empty makes ``best`` the maximum (``cap = level -
    1``, kept as a row). Every answer is an exact solve of the same model, so no optimum is
    lost; the budgets are deterministic (``work_limit``) or the user's wall clock. Returns ``(best, cap, stopped_by)``:
    ``best`` is the maximum when its flow reaches ``cap``."""
    out = rm.cols.flow[rm.out_src]
    tried = False  # MAX_FLOW_SEARCH had its turn at the top level
    level = known + 1
    while level <= cap:
        search = cpsat.MAX_FLOW_SEARCH if level == cap and not tried else None
        tried = tried or search is not None
        work = None if search is None else cpsat.LEVEL_WORK
        if left is not None:
            work = left if work is None else min(work, left)
        seconds, after_first = _cpsat_budget(clock)
        ans = session.solve(
            cost, True, None if search is None else best, seconds=seconds, after_first=after_first, work_limit=work,
            rel_gap=0.0, random_seed=options.random_seed, phase="phase 1 (maximum flow)", search=search, reach=level,
        )
        runs.append(ans.stats)
        left = None if left is None else left - ans.stats["deterministic_time"]
        if ans.x is not None:
            clock.first_test(at=time.perf_counter() - (ans.first_age or 0.0))
            best = ans.x
            level = int(round(rm.flow_of(best))) + 1
        elif ans.status == "infeasible":  # proven: no test has flow ``level``
            cap = level - 1
            if cap >= 1:
                session.add_row(out, np.ones(out.size), -np.inf, cap + 0.5)
        elif ans.stopped_by == "time_limit" or search is None or (left is not None and left <= 0.0):
            return best, cap, ans.stopped_by or "work_limit"
    return best, cap, None


def _phase2_cpsat(
    session: cpsat.CpSatSession, rm: RoutingModel, x: np.ndarray, flow: int, options: MilpOptions, clock: Clock,
    proof: _CutProof | None = None, ihs: _HittingSet | None = None,
) -> tuple[_Phase, list[dict[str, Any]]]:
    """:func:`_phase2` on CP-SAT: fewest cuts (fewest blocked places first) at flow
    ``flow``, from phase 1's answer as a hint (kept if CP-SAT finds nothing better). With the
    walls' cut bound (``proof``), its cheaper checked candidate is the hint, an answer that
    meets the bound is proven without a search, and the search stops at the first solution
    that meets it. With the hitting set's outcome (``ihs``, :func:`_hitting_set`): its proven
    answer is the answer; else its answer, where cheaper, is the hint, and its lower bound
    (proven) stops the search as the cut bound does."""
    out = rm.cols.flow[rm.out_src]
    session.add_row(out, np.ones(out.size), flow - 0.5, np.inf)
    clock.first_test()
    cost = _phase2_cost(rm, options)
    if proof is not None:
        x = proof.start(x, cost)
        if proof.meets(x, cost):
            return _Phase(x, "optimal", 0.0, None, proof.stats(cost, x, True)), []
    stop_at = None if proof is None else proof.bound
    if ihs is not None:
        if ihs.result.proven:
            return _Phase(ihs.x, "optimal", 0.0, None, None if proof is None else proof.stats(cost, ihs.x, False), ihs.result.stats()), []
        if float(cost @ ihs.x) < float(cost @ x) - 0.5:
            x = ihs.x
        stop_at = max(stop_at or 0.0, ihs.result.bound)
    seconds, _ = _cpsat_budget(clock)
    ans = session.solve(
        cost, False, x, seconds=seconds, after_first=None, work_limit=options.work_limit,
        rel_gap=options.mip_rel_gap, random_seed=options.random_seed, phase="phase 2 (fewest cuts)", flow=flow,
        stop_at=stop_at,
    )
    if ans.status == "infeasible":  # cannot happen: phase 1's solution is feasible
        raise RuntimeError("phase 2 of the routing MILP lost the phase-1 solution")
    phase = _Phase(x, "feasible", float("inf"), ans.stopped_by) if ans.x is None else _Phase(ans.x, ans.status, ans.gap, ans.stopped_by)
    if ihs is not None:
        phase = replace(phase, hitting_set=ihs.result.stats())
        if ans.x is not None and float(cost @ ans.x) <= ihs.result.bound + 0.5:
            phase = replace(phase, status="optimal", gap=0.0, stopped_by=None)  # meets the hitting set's proven bound
    return _with_cut_proof(phase, proof, cost), [ans.stats]


@dataclass(frozen=True)
class _HittingSet:
    """The hitting set's outcome in phase 2 (:func:`_hitting_set`): its best answer as a model
    solution, checked, and the search's figures."""

    x: np.ndarray
    result: hitting_set.HittingSetResult


def _hitting_set(
    products: Products, rm: RoutingModel, x: np.ndarray, flow: int, options: MilpOptions, clock: Clock, proof: _CutProof | None
) -> _HittingSet | None:
    """Phase 2 of MILP-static by the implicit hitting set (:mod:`synthesis.routing.backends.hitting_set`)
    where it applies: MILP-static without exclusions, places objective or closed-loop traps, at
    most :data:`~synthesis.routing.backends.hitting_set.IHS_MAX_GROUPS` free groups, flow at most
    :data:`~synthesis.routing.backends.hitting_set.IHS_MAX_FLOW`, and no cut bound proof already in hand.
    It starts from the cheaper of phase 1's answer and the cut bound's candidate, with the cut bound as its lower bound, and has a deterministic budget
    (:class:`~synthesis.routing.backends.hitting_set.HittingSetBudget`: rounds and the master's
    deterministic seconds, at most ``options.work_limit``) and the user's wall clock. Its answer
    becomes a whole model solution (:func:`_model_solution`), checked against the model.
    ``None`` where it does not apply."""
    if options.mode != "static" or options.exclusions or options.block_states or options.closed_loop or flow > hitting_set.IHS_MAX_FLOW:
        return None
    groups = rm.groups
    me = replace(rm.edges, has_var=rm.edges.has_var & ~rm.reductions.fixed_open)
    sep = CoverSeparator(products, options, groups, me, {})
    if sep.n_col > hitting_set.IHS_MAX_GROUPS:
        return None
    cost = _phase2_cost(rm, options)
    if proof is not None:
        x = proof.start(x, cost)
        if proof.meets(x, cost):
            return None  # proven already: _phase2_cpsat says so
    work = hitting_set.IHS_WORK if options.work_limit is None else min(hitting_set.IHS_WORK, options.work_limit)
    budget = hitting_set.HittingSetBudget(work=work, deadline=clock.deadline)
    lower = 0.0 if proof is None else float(proof.bound)
    result = hitting_set.fewest_cuts(
        sep, flow, rm.cut_of(x), budget, bound=lower, random_seed=options.random_seed, control=options.control,
    )
    y = x if result.cut is None or np.array_equal(result.cut, rm.cut_of(x)) else _model_solution(products, rm, result.cut, flow)
    return _HittingSet(y, result)


def _model_solution(products: Products, rm: RoutingModel, cut: np.ndarray, flow: int) -> np.ndarray:
    """A whole MILP-static model solution for a cut set (``bool`` per group) that passes the
    wall-cover checks at flow ``flow``: the cuts, ``flow`` units of flow over the open model
    edges (a maximum flow from ``Src`` capped at ``flow``), and ``mu`` the reachability from
    ``Src`` over the open c5 edges. Checked against the model's every row and bound."""
    cols, me = rm.cols, rm.edges
    g = products.virtual
    n = g.n_nodes
    x = np.zeros(rm.n_col)
    with_d = np.flatnonzero(cols.cut >= 0)
    x[cols.cut[with_d]] = cut[with_d].astype(float)
    open_edge = ~cut[me.grp]
    e = np.flatnonzero(open_edge)
    # flow: super source n+1 -> Src with capacity ``flow``, targets -> super sink n
    t = np.flatnonzero(products.target)
    big = max(int(e.size), 1)
    rows_ = np.concatenate([me.eu[e], t, [n + 1]])
    cols_ = np.concatenate([me.ev[e], np.full(t.size, n), [int(g.initial)]])
    caps = np.concatenate([np.ones(e.size, dtype=np.int32), np.full(t.size, big, dtype=np.int32), [flow]]).astype(np.int32)
    cap = sp.csr_matrix((caps, (rows_, cols_)), shape=(n + 2, n + 2))
    cap.sum_duplicates()
    res = maximum_flow(cap, n + 1, n)
    if int(res.flow_value) != flow:
        raise RuntimeError(f"the hitting set's answer has flow {int(res.flow_value)}, not {flow}: a FlowTest bug")
    pair_flow = res.flow.tocsr()
    # spread each pair's flow over its parallel open edges
    key = me.eu[e].astype(np.int64) * (n + 2) + me.ev[e]
    order = np.lexsort((e, key))
    ks = key[order]
    first = np.searchsorted(ks, ks)
    rank = np.arange(ks.size) - first
    amount = np.asarray(pair_flow[me.eu[e[order]], me.ev[e[order]]]).ravel()
    on = rank < np.maximum(amount, 0)
    x[cols.flow[e[order[on]]]] = 1.0
    # mu: reachable from Src over the open c5 edges
    c5 = np.flatnonzero(open_edge & me.c5)
    graph = sp.csr_matrix((np.ones(c5.size, dtype=np.int8), (me.eu[c5], me.ev[c5])), shape=(n, n))
    reach = np.zeros(n, dtype=bool)
    reach[breadth_first_order(graph, int(g.initial), directed=True, return_predecessors=False)] = True
    has_mu = cols.reach >= 0
    x[cols.reach[has_mu]] = reach[has_mu].astype(float)
    x = rm.with_items(x)
    if not _solves_at(_model_arrays(rm), rm, x, flow):
        raise RuntimeError("the hitting set's answer is no solution of the routing model: a FlowTest bug")
    return x


def _model_arrays(rm: RoutingModel) -> cpsat.ModelArrays:
    """The routing model's matrix and bounds, to check a whole solution against every row."""
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    return cpsat.ModelArrays(rm.model.matrix().tocsr(), row_lo, row_hi, col_lo, col_hi)


def _solves_at(arrays: cpsat.ModelArrays, rm: RoutingModel, x: np.ndarray, flow: int) -> bool:
    """Whether ``x`` satisfies every row and bound of the model with flow exactly ``flow``."""
    return arrays.violation(x) <= FEASIBILITY_TOLERANCE and abs(rm.flow_of(x) - flow) <= 0.5


@dataclass(frozen=True)
class _CutProof:
    """MILP-static's walls' cut bound at phase 2's flow level (:mod:`synthesis.routing.bounds.cut_bound`:
    every valid cut set with that flow costs at least :attr:`bound`) and its cheapest
    candidate, completed into a model solution and checked (``None``: none passed)."""

    bound: float
    level: int
    x: np.ndarray | None
    candidates: int
    checked: int

    def start(self, x: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """The cheaper of ``x`` and the checked candidate (``x`` on a tie)."""
        if self.x is not None and float(cost @ self.x) < float(cost @ x) - 0.5:
            return self.x
        return x

    def meets(self, x: np.ndarray, cost: np.ndarray) -> bool:
        """Whether ``x`` (a solution of the phase-2 model) costs no more than the bound: then
        it is optimal at this level."""
        value = float(cost @ x)
        if value < self.bound - 0.5:
            raise RuntimeError(f"a test costs {value:.0f}, below the walls' cut bound {self.bound:.0f}: a FlowTest bug")
        return value <= self.bound + 0.5

    def stats(self, cost: np.ndarray, x: np.ndarray, proven: bool) -> dict[str, Any]:
        """What the bound did, for the result's stats."""
        return {
            "level": self.level,
            "bound": self.bound,
            "candidates": self.candidates,
            "checked": self.checked,
            "candidate_cost": None if self.x is None else float(cost @ self.x),
            "proven": proven,
        }


def _cut_proof(products: Products, rm: RoutingModel, options: MilpOptions, entries: dict[int, np.ndarray], flow: int) -> _CutProof | None:
    """The walls' cut bound at phase 2's level with its cheapest checked candidate, for
    MILP-static (``None`` elsewhere, with ``options.cut_bound`` off, for MILP-agent's places
    objective, or where the bound does not apply). A candidate counts only as a whole model
    solution that satisfies every row of the model (feasibility flows included) with flow
    ``flow`` exactly: the routing heuristic grows it from the candidate's walls (opening any
    of them that separation does not need) and :func:`_guess_solution` completes it."""
    groups, me = rm.groups, rm.edges
    cb = model_cut_bound(products, options, groups, me, flow)
    if cb is None:
        return None
    if not np.isfinite(cb.value):
        return _CutProof(cb.value, flow, None, 0, 0)  # no cut set has this flow (phase 2: meets() reports the bug)
    cost = _phase2_cost(rm, options)
    arrays = _model_arrays(rm)
    traps = _trap_test(products, groups, entries)
    best: np.ndarray | None = None
    checked = 0
    for walls in cb.candidates:
        guess = replace(me, has_var=me.has_var & walls).guess(products, traps=traps, route_seed=False, fixed_open=rm.reductions.fixed_open)
        if guess.flow != flow:
            continue
        x = _guess_solution(products, rm, guess, options)
        if x is None or not _solves_at(arrays, rm, x, flow):
            continue
        checked += 1
        if best is None or float(cost @ x) < float(cost @ best) - 0.5:
            best = x
    return _CutProof(cb.value, flow, best, len(cb.candidates), checked)


def _test_at_bound(
    products: Products, rm: RoutingModel, options: MilpOptions, entries: dict[int, np.ndarray], upper: int
) -> np.ndarray | None:
    """MILP-static, phase 1: a checked candidate of the walls' cut bound at the flow upper bound
    ``upper`` (see :func:`_cut_proof`), which proves the maximum flow without a search; ``None``
    where there is none (or the bound does not apply)."""
    if upper < 1:
        return None
    proof = _cut_proof(products, rm, options, entries, upper)
    return None if proof is None else proof.x


def _with_cut_proof(phase: _Phase, proof: _CutProof | None, cost: np.ndarray) -> _Phase:
    """A phase-2 answer with what the cut bound says of it: optimal when it meets the bound."""
    if proof is None:
        return phase
    proven = proof.meets(phase.x, cost)
    if proven and phase.status != "optimal":
        return _Phase(phase.x, "optimal", 0.0, None, proof.stats(cost, phase.x, True))
    return replace(phase, cut_bound=proof.stats(cost, phase.x, proven))


def _phase2_cost(rm: RoutingModel, options: MilpOptions) -> np.ndarray:
    """Phase 2's objective: the cut groups by the edges they stand for; for MILP-agent, a
    blocked place costs more than every cut together (fewest blocked places first)."""
    var_groups = rm.var_groups
    cost = np.zeros(rm.n_col)
    cost[rm.cols.cut[var_groups]] = rm.groups.weight[var_groups]
    if options.block_states and rm.cols.blocked_place.size:
        cost[rm.cols.blocked_place] = float(rm.groups.weight[var_groups].sum() + 1)
    return cost


def _flow_of_phase1(rm: RoutingModel, first: _Phase) -> int:
    """Phase 1's flow F, which must be at least 1.

    Raises
    ------
    TimeoutError
        If a limit stopped phase 1 before any test with flow >= 1.
    InconsistentProblem
        If the maximum flow is proven 0 (every cut set traps the system).
    """
    flow = int(round(rm.flow_of(first.x)))
    if flow < 1:
        if first.status != "optimal":
            raise TimeoutError(f"no test with flow >= 1 was found within the {_LIMIT_TEXT.get(first.stopped_by or '', 'time limit')}")
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed without trapping the system: every routing "
            "cut set blocks all executions to the goal",
        )
    return flow


def _raise_if_flows_bind(
    rm: RoutingModel, products: Products, options: MilpOptions, x: np.ndarray, missing: dict[int, np.ndarray]
) -> None:
    """Raise :class:`_FlowsBind` if phase 1's cuts trap entry nodes of ``missing`` (histories
    whose feasibility flows the model lacks)."""
    if not missing:
        return
    groups = rm.groups
    cut1 = rm.cut_of(x)
    blocked1 = blocked_of_edges(products, np.flatnonzero(cut1[groups.of_edge]))
    blocked1 |= (np.isin(groups.move_key, groups.keys[cut1 & groups.static]) & static_moves_of(products, options))[None, :]
    trapped1 = trapped_entries(products, blocked1, missing)
    if trapped1:
        raise _FlowsBind(trapped1)


def _phase2(
    h: highspy.Highs, rm: RoutingModel, x: np.ndarray, flow: int, options: MilpOptions, clock: Clock, proof: _CutProof | None = None
) -> _Phase:
    """Phase 2, fewest cuts (for the agent: fewest blocked places first) at flow ``flow``,
    seeded by the fewest-cuts answer with phase 1's flow held fixed. With the walls' cut
    bound (``proof``), its cheaper checked candidate is the start, and an answer that meets
    the bound is proven (before the search: without one)."""
    f_col = rm.cols.flow
    h.addRow(flow - 0.5, highspy.kHighsInf, rm.out_src.size, f_col[rm.out_src].astype(np.int32), np.ones(rm.out_src.size))
    cost = _phase2_cost(rm, options)
    h.changeObjectiveSense(highspy.ObjSense.kMinimize)
    h.changeColsCost(rm.n_col, np.arange(rm.n_col, dtype=np.int32), cost)
    x = _integral_phase2(h, rm, options, x)
    clock.first_test()
    if proof is not None:
        x = proof.start(x, cost)
        if proof.meets(x, cost):
            return _Phase(x, "optimal", 0.0, None, proof.stats(cost, x, True))
    try:
        if clock.deadline is None:  # no wall clock: a deterministic budget for the helper solve
            x = _incumbent(h, x, f_col, None, options, flow, _min_limit(INCUMBENT_NODES, options.node_limit))
        else:
            x = _incumbent(h, x, f_col, _share(clock.deadline, INCUMBENT_SHARE), options, flow, hard=_hard(clock))
    except SolverAbandoned:  # the time is spent and HiGHS still holds the model: the start is the answer
        return _with_cut_proof(_Phase(x, "feasible", float("inf"), "time_limit", abandoned=True), proof, cost)
    if options.offer_starts:
        _set_solution(h, x)
    else:
        h.clearSolver()
    abandoned = False
    try:
        status, gap, x2 = _run(h, clock.deadline, options, phase="phase 2 (fewest cuts)", flow=flow, hard=_hard(clock))
    except TimeoutError as exc:  # HiGHS kept no solution: the start is the answer
        abandoned = isinstance(exc, SolverAbandoned)
        status, gap, x2 = "feasible", float("inf"), x
    if status == "infeasible" or x2 is None:  # cannot happen: phase 1's solution is feasible
        raise RuntimeError("phase 2 of the routing MILP lost the phase-1 solution")
    stopped_by = "time_limit" if abandoned else _stopped_by(h)
    return _with_cut_proof(_Phase(x2, status, gap, stopped_by, abandoned=abandoned), proof, cost)


def _integral_phase2(h: highspy.Highs, rm: RoutingModel, options: MilpOptions, x: np.ndarray) -> np.ndarray:
    """Declare the columns of :func:`~synthesis.routing.model.phase2_integral_columns`
    (``mu`` and ``f`` of MILP-reactive) integral in the model HiGHS holds (phase 2: the
    optimum is kept, see there), and return ``x`` with ``mu`` on its level set (1 where
    positive beyond :data:`FEASIBILITY_TOLERANCE`) and ``f`` rounded, so phase 1's answer
    (integral flows, from the heuristic or a vertex) stays a start; one that is not is
    refused by :func:`_set_solution` and the helper solve of :func:`_incumbent` gives one."""
    cols = phase2_integral_columns(rm, options)
    if cols.size == 0:
        return x
    idx = cols.astype(np.int32)
    h.changeColsIntegrality(idx.size, idx, np.full(idx.size, highspy.HighsVarType.kInteger))
    x = x.copy()
    mu = rm.cols.reach[rm.cols.reach >= 0]
    x[mu] = (x[mu] > FEASIBILITY_TOLERANCE).astype(float)
    x[rm.cols.flow] = np.round(x[rm.cols.flow])
    return x


def _result(
    rm: RoutingModel,
    products: Products,
    options: MilpOptions,
    first: _Phase,
    second: _Phase,
    flow: int,
    graph_seconds: float,
    solve_seconds: float,
) -> RoutingResult:
    """The routing answer of phase 2's solution, with the model's sizes and times."""
    groups, x = rm.groups, second.x
    cut = rm.cut_of(x)
    static_moves_cut = np.isin(groups.move_key, groups.keys[cut & groups.static]) & static_moves_of(products, options)
    place_cols = rm.cols.blocked_place
    blocked = rm.cols.places[x[place_cols] > 0.5] if place_cols.size else np.zeros(0, dtype=np.int64)
    status = "optimal" if first.status == second.status == "optimal" else "feasible"
    second_gap = second.gap
    if not np.isfinite(second_gap):  # no solver bound: the cut bound's, else 0 (cuts are never fewer)
        value = float(_phase2_cost(rm, options) @ x)
        lower = float(second.cut_bound["bound"]) if second.cut_bound is not None else 0.0
        second_gap = max(value - lower, 0.0) / max(value, 1.0)
    mip_gap = float(max(first.gap, second_gap)) if status != "optimal" else 0.0
    m = rm.model
    stats: dict[str, Any] = {
        "binary_vars": m.n_integer,
        "continuous_vars": m.n_col - m.n_integer,
        "constraints": m.n_row + 1,
        "feasibility_vars": sum(fl.cols.size for fl in rm.cols.feasibility),
        "model_edges": int(rm.edges.edges.size),
        "groups_fixed_open": rm.reductions.counts(),
        "graph_seconds": graph_seconds,
        "solve_seconds": solve_seconds,
        "mip_gap": mip_gap,
        "stopped_by": None if status == "optimal" else (first.stopped_by or second.stopped_by),
        "deterministic": options.deterministic,
        "backend": options.backend,
        "solver_version": backend_version(options.backend),
    }
    if second.cut_bound is not None:
        stats["cut_bound"] = second.cut_bound
    if second.hitting_set is not None:
        stats["hitting_set"] = second.hitting_set
    return RoutingResult(
        status=status,
        flow=flow,
        cut_edges=np.flatnonzero(cut[groups.of_edge]),
        cut_group_keys=[int(k) for k in groups.keys[cut]],
        static_moves_cut=static_moves_cut,
        blocked_places=blocked,
        mip_gap=mip_gap,
        stats=stats,
    )


def _guess_solution(products: Products, rm: RoutingModel, guess: RoutingGuess, options: MilpOptions) -> np.ndarray | None:
    """The heuristic's cut set as a full model solution, or ``None`` if it is unusable.

    Unusable: no flow, a rejected cut set (an exclusion row), a cut set over a cap
    (:attr:`MilpOptions.caps`), or, with feasibility
    constraints, an entry node trapped by the cuts. The feasibility flows are
    completed along shortest open paths, so the start is a whole solution and a solve
    stopped by its time limit still returns a checked test.
    """
    if guess.flow < 1:
        return None
    cols, groups = rm.cols, rm.groups
    cut_mask = guess.cut_groups & (cols.cut >= 0)
    cut_keys = set(groups.keys[cut_mask].tolist())
    if any(excluded.excludes(cut_keys) for excluded in options.exclusions):
        return None
    if rm.caps is not None and rm.caps.items.over_cap(cut_mask, options.caps):
        return None
    g, ts = products.virtual, products.ts
    x = np.zeros(rm.n_col)
    x[cols.flow] = guess.edge_flow
    with_d = np.flatnonzero(cols.cut >= 0)
    x[cols.cut[with_d]] = cut_mask[with_d].astype(float)
    has_mu = cols.reach >= 0
    x[cols.reach[has_mu]] = guess.reach[has_mu].astype(float)
    if cols.blocked_place.size:
        e_all = np.flatnonzero(cut_mask[groups.of_edge])
        pl = ts.place[ts.dst[g.move[e_all]]]
        x[cols.blocked_place] = np.isin(cols.places, pl).astype(float)
    is_cut = x > 0.5
    sys_targets = products.system_target
    for fl in cols.feasibility:
        value = fl.tree_flow(products.system.n_nodes, is_cut, sys_targets)
        if value is None:  # the cuts trap an entry node of this history
            return None
        x[fl.cols] = value
    return rm.with_items(x)


def _trap_test(products: Products, groups: CutGroups, entries: dict[int, np.ndarray]) -> Callable[[np.ndarray], bool] | None:
    """Whether a cut set (``bool`` per group) traps an entry node, for the heuristic."""
    if not entries:
        return None
    def traps(cut: np.ndarray) -> bool:
        blocked = blocked_of_edges(products, np.flatnonzero(cut[groups.of_edge]))
        return bool(trapped_entries(products, blocked, entries))

    return traps


def _set_solution(h: highspy.Highs, x: np.ndarray) -> bool:
    """Offer HiGHS ``x`` as a starting solution if it is feasible for the model HiGHS holds
    now (every bound, row and integrality checked); returns whether it was offered.

    A start is only a hint: one that violates the model would at best be ignored, so it is
    not passed. (Feasibility alone does not make a start safe: see :func:`_run`.)"""
    if x.size != h.getNumCol() or _violation(_ModelView.of(h), x) > FEASIBILITY_TOLERANCE:
        return False
    sol = highspy.HighsSolution()
    sol.col_value = list(x)
    sol.value_valid = True
    h.setSolution(sol)
    return True


#: Largest bound, row or integrality violation of a solution we accept (HiGHS's own
#: MIP feasibility tolerance is 1e-6; our coefficients are small integers).
FEASIBILITY_TOLERANCE = 1e-5


@dataclass
class _ModelView:
    """The model HiGHS holds, as arrays, to check a solution against it ourselves."""

    a: sp.csr_matrix
    row_lo: np.ndarray
    row_hi: np.ndarray
    col_lo: np.ndarray
    col_hi: np.ndarray
    integer: np.ndarray
    cost: np.ndarray

    @classmethod
    def of(cls, h: highspy.Highs) -> _ModelView:
        lp = h.getLp()
        n, m = int(lp.num_col_), int(lp.num_row_)
        parts = (np.asarray(lp.a_matrix_.value_), np.asarray(lp.a_matrix_.index_), np.asarray(lp.a_matrix_.start_))
        # HiGHS keeps a matrix column-wise, but one that had no rows before a row was added
        # (a model of column bounds alone) comes back row-wise.
        rowwise = lp.a_matrix_.format_ != highspy.MatrixFormat.kColwise
        a = sp.csr_matrix(parts, shape=(m, n)) if rowwise else sp.csc_matrix(parts, shape=(m, n)).tocsr()
        integrality = list(lp.integrality_)
        integer = np.array([t == highspy.HighsVarType.kInteger for t in integrality], dtype=bool) if integrality else np.zeros(n, dtype=bool)
        return cls(
            a,
            np.asarray(lp.row_lower_, dtype=float),
            np.asarray(lp.row_upper_, dtype=float),
            np.asarray(lp.col_lower_, dtype=float),
            np.asarray(lp.col_upper_, dtype=float),
            integer,
            np.asarray(lp.col_cost_, dtype=float),
        )


def _violation(model: _ModelView, x: np.ndarray) -> float:
    """The largest violation by ``x`` of a column bound, a row or integrality."""
    ax = model.a @ x
    parts = [
        model.col_lo - x,
        x - model.col_hi,
        model.row_lo - ax,
        ax - model.row_hi,
        np.abs(x[model.integer] - np.round(x[model.integer])),
    ]
    return float(max((float(np.max(p)) for p in parts if p.size), default=0.0))


INCUMBENT_SHARE = 0.25


INCUMBENT_NODES = 500  # branch-and-bound nodes for the phase-2 helper solve without a clock


def _share(deadline: float, share: float) -> float:
    """A deadline for a helper solve under a wall-clock budget: ``share`` of the time left."""
    now = time.perf_counter()
    return now + share * max(deadline - now, 0.0)


def _min_limit(a: int, b: int | None) -> int:
    return a if b is None else min(a, b)


def _incumbent(
    h: highspy.Highs,
    x: np.ndarray,
    f_col: np.ndarray,
    deadline: float | None,
    options: MilpOptions,
    flow: int,
    nodes: int | None = None,
    hard: float | None = None,
) -> np.ndarray:
    """A good first phase-2 solution: fewest cuts with the phase-1 flow held fixed.
    Raises :class:`~synthesis.routing.solver_control.SolverAbandoned` when HiGHS ran past
    ``hard`` (see :func:`_run`): then ``h`` must not be touched again.

    Without the flow to choose, the model is a plain (tied) cut problem that HiGHS
    solves quickly; its answer is feasible for phase 2 and seeds the search. The helper
    solve is bounded by ``deadline`` (wall clock, under a time limit) or by ``nodes``
    (deterministic, otherwise), so it never runs away and, without a clock, gives the
    same start on every machine.
    """
    lp = h.getLp()
    lo = np.asarray(lp.col_lower_)[f_col]
    hi = np.asarray(lp.col_upper_)[f_col]
    fv = np.round(x[f_col])
    idx = f_col.astype(np.int32)
    h.changeColsBounds(idx.size, idx, fv, fv)
    if options.offer_starts:
        _set_solution(h, x)
    else:
        h.clearSolver()
    _, node_limit = h.getOptionValue("mip_max_nodes")
    if nodes is not None:
        h.setOptionValue("mip_max_nodes", int(nodes))
    try:
        _, _, y = _run(h, deadline, options, phase="phase 2 start (fewest cuts, flow fixed)", flow=flow, hard=hard)
        if y is not None:
            x = y
    except TimeoutError as exc:
        if isinstance(exc, SolverAbandoned):
            raise  # HiGHS still runs on this model: nothing more may be asked of it
    h.setOptionValue("mip_max_nodes", node_limit)
    h.changeColsBounds(idx.size, idx, lo, hi)
    return x


def _highs(options: MilpOptions) -> highspy.Highs:
    h = quiet_highs(options.threads, options.random_seed)
    h.setOptionValue("mip_rel_gap", float(options.mip_rel_gap))
    if options.node_limit is not None:
        h.setOptionValue("mip_max_nodes", int(options.node_limit))
    # both objectives are integral: an absolute gap below 1 proves optimality
    h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)
    return h


def _run(
    h: highspy.Highs,
    deadline: float | None,
    options: MilpOptions,
    *,
    phase: str,
    flow: int | None = None,
    clock: Clock | None = None,
    watch_first: bool = False,
    hard: float | None = None,
) -> tuple[str, float, np.ndarray | None]:
    """Run HiGHS until done, the deadline or a stop; return (status, relative gap, solution).

    ``hard`` is the whole solve's deadline: a HiGHS still busy :data:`ABANDON_GRACE` seconds
    past it (presolve looks at the clock rarely) is left behind with
    :class:`~synthesis.routing.solver_control.SolverAbandoned`, after which ``h`` must not
    be touched again.

    The solution HiGHS returns is checked against the model it holds, by us: every bound,
    row and integrality, and its objective, recomputed. ``"optimal"`` needs that objective
    within less than 1 of HiGHS's dual bound (both objectives are integral, so this is a
    proof), not only HiGHS's word. HiGHS 1.16.0 with a start and presolve can return the
    start itself while it reports (and proves) a better objective: the proven optimum of
    the reduced model, not postsolved (``tests/synthesis/test_highs_start.py``). When the returned
    solution does not have the objective HiGHS reports, or violates the model, the solve
    is run again without any start (``clearSolver``); if that still disagrees the answer
    is at most ``"feasible"``, with the gap its own objective leaves to the bound.

    Raises ``TimeoutError`` when HiGHS stopped with no solution, ``KeyboardInterrupt``
    on Ctrl-C or a stop request (see :func:`synthesis.routing.solver_control.run_highs`).
    """
    for attempt in (1, 2):
        run_highs(h, deadline, clock=clock, control=options.control, phase=phase, flow=flow, watch_first=watch_first, abandon_at=hard)
        status, gap, x, agrees = _read_solution(h)
        if agrees:
            return status, gap, x
        if attempt == 2:
            if x is None:
                raise RuntimeError("HiGHS returned a solution that violates its model, twice")
            return "feasible", gap, x
        h.clearSolver()  # drops the start too, so the second run begins from scratch
    raise AssertionError("unreachable")


def _read_solution(h: highspy.Highs) -> tuple[str, float, np.ndarray | None, bool]:
    """(status, gap, solution, whether HiGHS's report agrees with its solution)."""
    ms = h.getModelStatus()
    info = h.getInfo()
    if ms == highspy.HighsModelStatus.kInfeasible:
        return "infeasible", float("inf"), None, True
    has_sol = info.primal_solution_status == highspy.SolutionStatus.kSolutionStatusFeasible
    if not has_sol:
        reason = _stopped_by(h)
        if reason is not None:
            raise TimeoutError(f"the routing MILP found no solution within the {_LIMIT_TEXT[reason]}")
        raise RuntimeError(f"HiGHS stopped with status {h.modelStatusToString(ms)}")
    model = _ModelView.of(h)
    x = np.asarray(h.getSolution().col_value, dtype=float)
    objective = float(model.cost @ x)
    reported = float(info.objective_function_value)
    feasible = _violation(model, x) <= FEASIBILITY_TOLERANCE
    agrees = feasible and abs(objective - reported) <= 1e-6 * max(1.0, abs(objective))
    bound = float(info.mip_dual_bound)
    if h.getLp().sense_ == highspy.ObjSense.kMinimize and np.isfinite(bound):
        bound = max(bound, 0.0)  # minimised counts (cuts, places) are never below 0
    if not feasible:
        return "feasible", float("inf"), None, False
    # integral objectives: an absolute gap below 1 between the solution we hold and
    # HiGHS's bound proves it optimal; a larger one (a user's mip_rel_gap) does not
    proven = np.isfinite(bound) and abs(objective - bound) < 1.0 - 1e-6
    if ms == highspy.HighsModelStatus.kOptimal and proven:
        return "optimal", 0.0, x, agrees
    gap = abs(objective - bound) / max(abs(objective), 1.0) if np.isfinite(bound) else float("inf")
    return "feasible", float(gap), x, agrees


_LIMIT_TEXT = {"time_limit": "time limit", "node_limit": "node limit", "work_limit": "work limit"}


def _stopped_by(h: highspy.Highs) -> str | None:
    """Which budget stopped HiGHS's last run: ``"time_limit"`` (the wall clock, or the
    interrupt that enforces it), ``"node_limit"`` (a deterministic work limit) or ``None``."""
    ms = h.getModelStatus()
    if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kInterrupt):
        return "time_limit"
    if ms in (highspy.HighsModelStatus.kSolutionLimit, highspy.HighsModelStatus.kIterationLimit):
        return "node_limit"
    return None
