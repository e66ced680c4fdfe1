"""OR-Tools CP-SAT as a backend of the routing model: its two phases on the model
:func:`synthesis.routing.model.build_model` builds, in a child process
(:class:`~synthesis.routing.backends.cpsat.CpSatSession`) that holds the model between them.
Why CP-SAT keeps the optimum, and how the child runs, is said in
:mod:`synthesis.routing.backends.cpsat`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..certificates import CutProof, with_cut_proof
from ..model import RoutingModel
from ..options import MilpOptions
from ..phases import LIMIT_TEXT, Phase, no_cut_set, phase2_cost
from ..solver_control import Clock
from . import cpsat
from .contract import Backend, Round
from .hitting_set import HittingSetOutcome, try_hitting_set
from .phase1_start import phase1_start


def _cpsat_budget(clock: Clock) -> tuple[float | None, float | None]:
    """``(seconds, after_first)`` of a CP-SAT run under ``clock``: the wall-clock limits the
    user asked for (none: ``(None, None)``)."""
    now = time.perf_counter()
    seconds = None if clock.deadline is None else max(clock.deadline - now, 0.01)
    return seconds, (clock.after_first if clock.watching_first() else None)


def phase1_cpsat(session: cpsat.CpSatSession, r: Round) -> tuple[Phase, list[dict[str, Any]]]:
    """:func:`synthesis.routing.backends.highs.phase1` on CP-SAT: the heuristic's answer (or a checked candidate of the walls'
    cut bound) proves the maximum flow when it attains the upper bound; else CP-SAT maximises the flow from it (as a hint) with its
    default search, whose LP bound proves small cases at once, for at most
    :data:`~synthesis.routing.backends.cpsat.PROOF_WORK` deterministic seconds. If that does not
    prove it, phase 1 asks level by level, from the flow above the best test known, whether
    a test of that flow exists (:func:`reach_level`): found, the best test and the level
    rise; proven impossible, the best test is the maximum (the row ``F <= level - 1`` is
    valid and kept for phase 2), and with no test at all, level 1 impossible means no cut
    set exists. ``work_limit`` bounds the whole phase."""
    rm, options, clock = r.rm, r.options, r.clock
    start = phase1_start(r)
    if start.proven is not None:
        return start.proven, []
    guess, x_guess = start.guess, start.x
    out = rm.cols.flow[rm.out_src]
    cost = np.zeros(rm.n_col)
    cost[out] = 1.0
    best = x_guess if options.offer_starts else None
    runs: list[dict[str, Any]] = []
    seconds, after_first = _cpsat_budget(clock)
    left = options.work_limit
    ans = session.solve(
        cost,
        True,
        best,
        seconds=seconds,
        after_first=after_first,
        work_limit=cpsat.PROOF_WORK if left is None else min(cpsat.PROOF_WORK, left),
        rel_gap=options.mip_rel_gap,
        random_seed=options.random_seed,
        phase="phase 1 (maximum flow)",
    )
    runs.append(ans.stats)
    left = None if left is None else left - ans.stats["deterministic_time"]
    if ans.first_age is not None:
        clock.first_test(at=time.perf_counter() - ans.first_age)
    if ans.status == "infeasible":
        raise no_cut_set()
    if ans.x is not None:
        best = ans.x
    if ans.status == "optimal" and ans.x is not None:
        return Phase(ans.x, "optimal", 0.0, None), runs
    # no test has a larger flow than cap (the flow upper bound, CP-SAT's bound)
    cap = guess.upper_bound if ans.bound is None else min(guess.upper_bound, int(np.floor(ans.bound + 1e-6)))
    stopped_by: str | None = ans.stopped_by
    if ans.stopped_by != "time_limit" and (left is None or left > 0.0):
        known = max(guess.flow if x_guess is not None else 0, 0 if best is None else int(round(rm.flow_of(best))))
        best, cap, stopped_by = reach_level(session, rm, cost, best, known, cap, left, options, clock, runs)
    x = best if best is not None else x_guess
    if x is None:
        if cap < 1:
            raise no_cut_set()
        raise TimeoutError(f"the routing MILP found no solution within the {LIMIT_TEXT.get(stopped_by or '', 'time limit')}")
    if x_guess is not None and guess.flow > rm.flow_of(x) + 0.5:
        x = x_guess  # CP-SAT stopped below the heuristic's flow
    flow = int(round(rm.flow_of(x)))
    if flow >= cap:
        return Phase(x, "optimal", 0.0, None), runs
    return Phase(x, "feasible", (cap - flow) / max(flow, 1), stopped_by), runs


def reach_level(
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
    not (random 5x5 reaction grids' flow 2, and level 1 of the grids without a test:
    docs/benchmarks/solvers.md, "CP-SAT's phase 1"), and it finds tests there too. At the top
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
            cost,
            True,
            None if search is None else best,
            seconds=seconds,
            after_first=after_first,
            work_limit=work,
            rel_gap=0.0,
            random_seed=options.random_seed,
            phase="phase 1 (maximum flow)",
            search=search,
            reach=level,
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


def phase2_cpsat(
    session: cpsat.CpSatSession,
    rm: RoutingModel,
    x: np.ndarray,
    flow: int,
    options: MilpOptions,
    clock: Clock,
    proof: CutProof | None = None,
    ihs: HittingSetOutcome | None = None,
) -> tuple[Phase, list[dict[str, Any]]]:
    """:func:`synthesis.routing.backends.highs.phase2` on CP-SAT: fewest cuts (fewest blocked places first) at flow
    ``flow``, from phase 1's answer as a hint (kept if CP-SAT finds nothing better). With the
    walls' cut bound (``proof``), its cheaper checked candidate is the hint, an answer that
    meets the bound is proven without a search, and the search stops at the first solution
    that meets it. With the hitting set's outcome (``ihs``, :func:`try_hitting_set`): its proven
    answer is the answer; else its answer, where cheaper, is the hint, and its lower bound
    (proven) stops the search as the cut bound does."""
    out = rm.cols.flow[rm.out_src]
    session.add_row(out, np.ones(out.size), flow - 0.5, np.inf)
    clock.first_test()
    cost = phase2_cost(rm, options)
    if proof is not None:
        x = proof.start(x, cost)
        if proof.meets(x, cost):
            return Phase(x, "optimal", 0.0, None, proof.stats(cost, x, True)), []
    stop_at = None if proof is None else proof.bound
    if ihs is not None:
        if ihs.result.proven:
            return Phase(ihs.x, "optimal", 0.0, None, None if proof is None else proof.stats(cost, ihs.x, False), ihs.result.stats()), []
        if float(cost @ ihs.x) < float(cost @ x) - 0.5:
            x = ihs.x
        stop_at = max(stop_at or 0.0, ihs.result.bound)
    seconds, _ = _cpsat_budget(clock)
    ans = session.solve(
        cost,
        False,
        x,
        seconds=seconds,
        after_first=None,
        work_limit=options.work_limit,
        rel_gap=options.mip_rel_gap,
        random_seed=options.random_seed,
        phase="phase 2 (fewest cuts)",
        flow=flow,
        stop_at=stop_at,
    )
    if ans.status == "infeasible":  # cannot happen: phase 1's solution is feasible
        raise RuntimeError("phase 2 of the routing MILP lost the phase-1 solution")
    phase = Phase(x, "feasible", float("inf"), ans.stopped_by) if ans.x is None else Phase(ans.x, ans.status, ans.gap, ans.stopped_by)
    if ihs is not None:
        phase = replace(phase, hitting_set=ihs.result.stats())
        if ans.x is not None and float(cost @ ans.x) <= ihs.result.bound + 0.5:
            phase = replace(phase, status="optimal", gap=0.0, stopped_by=None)  # meets the hitting set's proven bound
    return with_cut_proof(phase, proof, cost), [ans.stats]


@dataclass
class CpSatRun:
    """The CP-SAT child holding the routing model for one solve, and the figures of its runs."""

    session: cpsat.CpSatSession
    runs: list[dict[str, Any]] = field(default_factory=list)


@contextmanager
def session(r: Round) -> Iterator[CpSatRun]:
    """A CP-SAT child process holding the routing model between the two phases (closed on exit)."""
    a = r.rm.model.matrix().tocsr()
    col_lo, col_hi, row_lo, row_hi = r.rm.model.bounds()
    with cpsat.CpSatSession(cpsat.ModelArrays(a, row_lo, row_hi, col_lo, col_hi), r.options.control) as child:
        yield CpSatRun(child)


def phase1(s: CpSatRun, r: Round) -> Phase:
    """Phase 1 (maximum flow) on CP-SAT: :func:`phase1_cpsat`, its runs kept for :func:`figures`."""
    first, runs = phase1_cpsat(s.session, r)
    s.runs += runs
    return first


def phase2(s: CpSatRun, r: Round, x: np.ndarray, flow: int, proof: CutProof | None = None) -> Phase:
    """Phase 2 (fewest cuts at flow ``flow``) on CP-SAT: :func:`phase2_cpsat`; where ``"auto"``
    chose CP-SAT, MILP-static with few free groups tries the implicit hitting set first
    (:func:`~synthesis.routing.backends.hitting_set.try_hitting_set`)."""
    ihs = try_hitting_set(r.products, r.rm, x, flow, r.options, r.clock, proof) if r.by_auto else None
    second, runs = phase2_cpsat(s.session, r.rm, x, flow, r.options, r.clock, proof, ihs)
    s.runs += runs
    return second


def figures(s: CpSatRun) -> dict[str, Any]:
    """The child's start-up and CPU seconds and its runs' work, as the result's ``stats["cpsat"]``."""
    runs = s.runs
    return {
        "cpsat": {
            "spawn_seconds": s.session.spawn_seconds,
            "spawn_cpu_seconds": s.session.spawn_cpu_seconds,
            "child_cpu_seconds": s.session.child_cpu_seconds,
            "runs": len(runs),
            **{k: sum(run[k] for run in runs) for k in ("wall_seconds", "cpu_seconds", "deterministic_time", "conflicts", "branches")},
        }
    }


def version() -> str:
    """OR-Tools' version: the package CP-SAT's answers depend on (``"unknown"`` without it)."""
    return cpsat.ortools_version() or "unknown"


BACKEND: Backend[CpSatRun] = Backend(
    name="cpsat",
    label="routing MILP (CP-SAT)",
    version=version,
    require=cpsat.require,
    session=session,
    phase1=phase1,
    phase2=phase2,
    figures=figures,
)
"""OR-Tools CP-SAT as a backend of the routing model (``MilpOptions.backend = "cpsat"``)."""
