"""HiGHS as a backend of the routing model (``MilpOptions.backend = "highs"``): its two phases
(:func:`phase1`, :func:`phase2`) and the checks every HiGHS answer passes before it is used
(:func:`run`: each solution checked against the model HiGHS holds, :class:`ModelView`,
:func:`violation`; a start offered only when it satisfies that model, :func:`set_solution`).

* **Integral reachability and flows in MILP-reactive's phase 2.** The potentials ``mu``
  may be taken 0/1 and the flows integral once the cuts are binary
  (:func:`synthesis.routing.model.phase2_integral_columns` proves it), so phase 2 of
  MILP-reactive declares them integral on HiGHS (models of 200 rows or more,
  :func:`integral_phase2`): HiGHS then branches on which nodes ``Src`` reaches and its
  heuristics look for integral routes, which proves the fewest cuts of mid-size reactive
  models that branching on the cuts alone does not.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import highspy
import numpy as np
import scipy.sparse as sp

from ..certificates import CutProof, with_cut_proof
from ..model import RoutingModel, phase2_integral_columns
from ..options import MilpOptions
from ..phases import FEASIBILITY_TOLERANCE, LIMIT_TEXT, Phase, no_cut_set, phase2_cost
from ..solver_control import Clock, SolverAbandoned, quiet_highs, run_highs, solver_version
from .contract import Backend, Least, LeastQuery, Round
from .phase1_start import phase1_start

ABANDON_GRACE = 0.25
"""Seconds past the solve's deadline after which a HiGHS run still busy is left behind
(:class:`~synthesis.routing.solver_control.SolverAbandoned`): the time limit holds."""


def _hard(clock: Clock) -> float | None:
    """The moment a HiGHS run is abandoned: the solve's deadline plus :data:`ABANDON_GRACE`."""
    return None if clock.deadline is None else clock.deadline + ABANDON_GRACE


def phase1(h: highspy.Highs, r: Round) -> Phase:
    """Phase 1, maximum flow: proven by the heuristic when it attains the flow upper bound, or
    (MILP-static) by a checked candidate of the walls' cut bound at that bound
    (:func:`~synthesis.routing.certificates.test_at_bound`), else solved by HiGHS (seeded by
    the heuristic's answer, kept as the fallback)."""
    rm, options, clock = r.rm, r.options, r.clock
    start = phase1_start(r)
    if start.proven is not None:
        return start.proven
    guess, x_guess = start.guess, start.x
    cost = np.zeros(rm.n_col)
    cost[rm.cols.flow[rm.out_src]] = 1.0
    h.changeColsCost(rm.n_col, np.arange(rm.n_col, dtype=np.int32), cost)
    if rm.flow_bound is not None:
        # MILP-static's walls' bound (synthesis.routing.bounds.flow_bound), below the LP's: as the
        # row F <= bound, HiGHS stops as soon as a test attains it (valid for phase 2 too)
        out = rm.cols.flow[rm.out_src].astype(np.int32)
        h.addRow(-highspy.kHighsInf, rm.flow_bound + 0.5, out.size, out, np.ones(out.size))
    # a route-seeded start is kept as the fallback but not handed to HiGHS: from
    # it, HiGHS's neighbourhood heuristics stay near the lone route (on mars-exploration
    # they found no flow 2 in the time HiGHS from scratch needs to find one)
    if x_guess is not None and not guess.from_route and options.offer_starts:
        set_solution(h, x_guess)
    watch = clock.watching_first()
    abandoned = False
    try:
        status, gap, x1 = run(h, clock.latest(), options, phase="phase 1 (maximum flow)", clock=clock, watch_first=watch, hard=_hard(clock))
    except TimeoutError as exc:
        if x_guess is None:
            raise
        abandoned = isinstance(exc, SolverAbandoned)
        # the heuristic's flow against its proven upper bound
        status, gap, x1 = "feasible", (guess.upper_bound - guess.flow) / max(guess.flow, 1), None
    stopped_by = "time_limit" if abandoned else _stopped_by(h)
    if abandoned and x_guess is not None:  # (x_guess is never None here: the TimeoutError was raised then)
        return Phase(x_guess, "feasible", gap, stopped_by, abandoned=True)
    if status == "infeasible":
        raise no_cut_set()
    x = x1 if x1 is not None else x_guess
    if x is None:  # run returns a solution unless it raised
        raise RuntimeError("phase 1 of the routing MILP ended without a solution")
    if x_guess is not None and guess.flow > rm.flow_of(x) + 0.5:
        return Phase(x_guess, "feasible", gap, stopped_by)  # HiGHS stopped below the heuristic's flow
    return Phase(x, status, gap, stopped_by)


def phase2(h: highspy.Highs, r: Round, x: np.ndarray, flow: int, proof: CutProof | None = None) -> Phase:
    """Phase 2, fewest cuts (for the agent: fewest blocked places first) at flow ``flow``,
    seeded by the fewest-cuts answer with phase 1's flow held fixed. With the walls' cut
    bound (``proof``), its cheaper checked candidate is the start, and an answer that meets
    the bound is proven (before the search: without one)."""
    rm, options, clock = r.rm, r.options, r.clock
    f_col = rm.cols.flow
    h.addRow(flow - 0.5, highspy.kHighsInf, rm.out_src.size, f_col[rm.out_src].astype(np.int32), np.ones(rm.out_src.size))
    cost = phase2_cost(rm, options)
    h.changeObjectiveSense(highspy.ObjSense.kMinimize)
    h.changeColsCost(rm.n_col, np.arange(rm.n_col, dtype=np.int32), cost)
    x = integral_phase2(h, rm, options, x)
    clock.first_test()
    if proof is not None:
        x = proof.start(x, cost)
        if proof.meets(x, cost):
            return Phase(x, "optimal", 0.0, None, proof.stats(cost, x, True))
    try:
        if clock.deadline is None:  # no wall clock: a deterministic budget for the helper solve
            x = _incumbent(h, x, f_col, None, options, flow, _min_limit(INCUMBENT_NODES, options.node_limit))
        else:
            x = _incumbent(h, x, f_col, _share(clock.deadline, INCUMBENT_SHARE), options, flow, hard=_hard(clock))
    except SolverAbandoned:  # the time is spent and HiGHS still holds the model: the start is the answer
        return with_cut_proof(Phase(x, "feasible", float("inf"), "time_limit", abandoned=True), proof, cost)
    if options.offer_starts:
        set_solution(h, x)
    else:
        h.clearSolver()
    abandoned = False
    try:
        status, gap, x2 = run(h, clock.deadline, options, phase="phase 2 (fewest cuts)", flow=flow, hard=_hard(clock))
    except TimeoutError as exc:  # HiGHS kept no solution: the start is the answer
        abandoned = isinstance(exc, SolverAbandoned)
        status, gap, x2 = "feasible", float("inf"), x
    if status == "infeasible" or x2 is None:  # cannot happen: phase 1's solution is feasible
        raise RuntimeError("phase 2 of the routing MILP lost the phase-1 solution")
    stopped_by = "time_limit" if abandoned else _stopped_by(h)
    return with_cut_proof(Phase(x2, status, gap, stopped_by, abandoned=abandoned), proof, cost)


def integral_phase2(h: highspy.Highs, rm: RoutingModel, options: MilpOptions, x: np.ndarray) -> np.ndarray:
    """Declare the columns of :func:`~synthesis.routing.model.phase2_integral_columns`
    (``mu`` and ``f`` of MILP-reactive) integral in the model HiGHS holds (phase 2: the
    optimum is kept, see there), and return ``x`` with ``mu`` on its level set (1 where
    positive beyond :data:`FEASIBILITY_TOLERANCE`) and ``f`` rounded, so phase 1's answer
    (integral flows, from the heuristic or a vertex) stays a start; one that is not is
    refused by :func:`set_solution` and the helper solve of :func:`_incumbent` gives one."""
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


def set_solution(h: highspy.Highs, x: np.ndarray) -> bool:
    """Offer HiGHS ``x`` as a starting solution if it is feasible for the model HiGHS holds
    now (every bound, row and integrality checked); returns whether it was offered.

    A start is only a hint: one that violates the model would at best be ignored, so it is
    not passed. (Feasibility alone does not make a start safe: see :func:`run`.)"""
    if x.size != h.getNumCol() or violation(ModelView.of(h), x) > FEASIBILITY_TOLERANCE:
        return False
    sol = highspy.HighsSolution()
    sol.col_value = list(x)
    sol.value_valid = True
    h.setSolution(sol)
    return True


@dataclass
class ModelView:
    """The model HiGHS holds, as arrays, to check a solution against it ourselves."""

    a: sp.csr_matrix
    row_lo: np.ndarray
    row_hi: np.ndarray
    col_lo: np.ndarray
    col_hi: np.ndarray
    integer: np.ndarray
    cost: np.ndarray

    @classmethod
    def of(cls, h: highspy.Highs) -> ModelView:
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


def violation(model: ModelView, x: np.ndarray) -> float:
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
    ``hard`` (see :func:`run`): then ``h`` must not be touched again.

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
        set_solution(h, x)
    else:
        h.clearSolver()
    _, node_limit = h.getOptionValue("mip_max_nodes")
    if nodes is not None:
        h.setOptionValue("mip_max_nodes", int(nodes))
    try:
        _, _, y = run(h, deadline, options, phase="phase 2 start (fewest cuts, flow fixed)", flow=flow, hard=hard)
        if y is not None:
            x = y
    except TimeoutError as exc:
        if isinstance(exc, SolverAbandoned):
            raise  # HiGHS still runs on this model: nothing more may be asked of it
    h.setOptionValue("mip_max_nodes", node_limit)
    h.changeColsBounds(idx.size, idx, lo, hi)
    return x


def new_highs(options: MilpOptions) -> highspy.Highs:
    h = quiet_highs(options.threads, options.random_seed)
    h.setOptionValue("mip_rel_gap", float(options.mip_rel_gap))
    if options.node_limit is not None:
        h.setOptionValue("mip_max_nodes", int(options.node_limit))
    # both objectives are integral: an absolute gap below 1 proves optimality
    h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)
    return h


def run(
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
    proof), not only HiGHS's word. HiGHS with a start and presolve can return the
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
            raise TimeoutError(f"the routing MILP found no solution within the {LIMIT_TEXT[reason]}")
        raise RuntimeError(f"HiGHS stopped with status {h.modelStatusToString(ms)}")
    model = ModelView.of(h)
    x = np.asarray(h.getSolution().col_value, dtype=float)
    objective = float(model.cost @ x)
    reported = float(info.objective_function_value)
    feasible = violation(model, x) <= FEASIBILITY_TOLERANCE
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


def _stopped_by(h: highspy.Highs) -> str | None:
    """Which budget stopped HiGHS's last run: ``"time_limit"`` (the wall clock, or the
    interrupt that enforces it), ``"node_limit"`` (a deterministic work limit) or ``None``."""
    ms = h.getModelStatus()
    if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kInterrupt):
        return "time_limit"
    if ms in (highspy.HighsModelStatus.kSolutionLimit, highspy.HighsModelStatus.kIterationLimit):
        return "node_limit"
    return None


@contextmanager
def session(r: Round) -> Iterator[highspy.Highs]:
    """A HiGHS instance holding the routing model (phase 1's objective is set by :func:`phase1`)."""
    h = new_highs(r.options)
    h.passModel(r.rm.model.to_highs(np.zeros(r.rm.n_col), maximize=True))
    yield h


def least(q: LeastQuery) -> Least:
    """A :class:`~synthesis.routing.backends.contract.LeastQuery` on HiGHS: the model minimised
    with the row ``F >= 1`` added and ``q.integral`` declared integral, on ``q.options.threads``
    threads (one where unset) with its seed; stopped by ``q.deadline``, HiGHS's proven (dual)
    bound, where it has a finite one."""
    options = q.options
    h = quiet_highs(options.threads if options.threads else 1, options.random_seed)
    h.passModel(q.rm.model.to_highs(q.cost, maximize=False))
    out = q.rm.cols.flow[q.rm.out_src].astype(np.int32)
    h.addRow(1.0, highspy.kHighsInf, out.size, out, np.ones(out.size))
    cols = q.integral.astype(np.int32)
    h.changeColsIntegrality(cols.size, cols, np.full(cols.size, highspy.HighsVarType.kInteger))
    try:
        run_highs(h, q.deadline, control=options.control, phase=q.label)
    except TimeoutError:
        return Least("stopped")
    status = h.getModelStatus()
    if status == highspy.HighsModelStatus.kInfeasible:
        return Least("infeasible")
    info = h.getInfo()
    if status == highspy.HighsModelStatus.kOptimal:
        return Least("optimal", value=float(info.objective_function_value))
    bound = float(info.mip_dual_bound)
    return Least("stopped", bound=bound if np.isfinite(bound) else None)


def version() -> str:
    """highspy's version: the package HiGHS's answers depend on."""
    return solver_version()


BACKEND: Backend[highspy.Highs] = Backend(
    name="highs",
    label="routing MILP",
    version=version,
    require=lambda: None,  # highspy is a core dependency
    session=session,
    phase1=phase1,
    phase2=phase2,
    figures=lambda h: {},
    least=least,
)
"""HiGHS's branch and cut as a backend of the routing model (``MilpOptions.backend = "highs"``)."""
