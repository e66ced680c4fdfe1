"""What every backend's two phases share: the answer of a phase (:class:`Phase`), the
heuristic's test as a whole model solution (:func:`guess_solution`), phase 2's objective
(:func:`phase2_cost`), and the routing answer a solve ends with (:func:`routing_result`).

The lexicographic objective of the routing MILP, ``F - (1/|E|) sum d`` with integral ``F``,
is maximised in two phases: phase 1 maximises the flow ``F``, phase 2 minimises the cuts
(MILP-agent: the blocked places first) with ``F`` held at phase 1's value. Both objectives
are integral, so an absolute gap below 1 proves optimality.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..graphs.products import Products
from ..model.errors import InconsistentProblem
from .bounds.heuristic import RoutingGuess
from .groups import CutGroups, static_moves_of
from .model import RoutingModel
from .options import MilpOptions
from .result import RoutingResult, blocked_of_edges
from .traps import trapped_entries


@dataclass(frozen=True)
class Phase:
    """What a phase of the solve ends with."""

    x: np.ndarray
    status: str
    gap: float
    stopped_by: str | None
    cut_bound: dict[str, Any] | None = None  # phase 2: the walls' cut bound, what it proved (see CutProof)
    hitting_set: dict[str, Any] | None = None  # phase 2: what the hitting set did (see try_hitting_set)
    abandoned: bool = False  # HiGHS was left running past the deadline: its model must not be touched


def no_cut_set() -> InconsistentProblem:
    """The answer when phase 1's model has no solution at all."""
    return InconsistentProblem(
        "unroutable",
        "the test objective cannot be routed without trapping the system: no cut set "
        "routes every successful execution through it while leaving a way to the goal",
    )


def phase2_cost(rm: RoutingModel, options: MilpOptions) -> np.ndarray:
    """Phase 2's objective: the cut groups by the edges they stand for; for MILP-agent, a
    blocked place costs more than every cut together (fewest blocked places first)."""
    var_groups = rm.var_groups
    cost = np.zeros(rm.n_col)
    cost[rm.cols.cut[var_groups]] = rm.groups.weight[var_groups]
    if options.block_states and rm.cols.blocked_place.size:
        cost[rm.cols.blocked_place] = float(rm.groups.weight[var_groups].sum() + 1)
    return cost


def flow_of_phase1(rm: RoutingModel, first: Phase) -> int:
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
            raise TimeoutError(f"no test with flow >= 1 was found within the {LIMIT_TEXT.get(first.stopped_by or '', 'time limit')}")
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed without trapping the system: every routing cut set blocks all executions to the goal",
        )
    return flow


def routing_result(
    rm: RoutingModel,
    products: Products,
    options: MilpOptions,
    first: Phase,
    second: Phase,
    flow: int,
    graph_seconds: float,
    solve_seconds: float,
    solver_version: str,
) -> RoutingResult:
    """The routing answer of phase 2's solution, with the model's sizes and times and the
    version of the solver package that gave it."""
    groups, x = rm.groups, second.x
    cut = rm.cut_of(x)
    static_moves_cut = np.isin(groups.move_key, groups.keys[cut & groups.static]) & static_moves_of(products, options)
    place_cols = rm.cols.blocked_place
    blocked = rm.cols.places[x[place_cols] > 0.5] if place_cols.size else np.zeros(0, dtype=np.int64)
    status = "optimal" if first.status == second.status == "optimal" else "feasible"
    second_gap = second.gap
    if not np.isfinite(second_gap):  # no solver bound: the cut bound's, else 0 (cuts are never fewer)
        value = float(phase2_cost(rm, options) @ x)
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
        "solver_version": solver_version,
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


def guess_solution(products: Products, rm: RoutingModel, guess: RoutingGuess, options: MilpOptions) -> np.ndarray | None:
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


def trap_test(products: Products, groups: CutGroups, entries: dict[int, np.ndarray]) -> Callable[[np.ndarray], bool] | None:
    """Whether a cut set (``bool`` per group) traps an entry node of ``entries``, for the routing
    heuristic and the capped start (:mod:`synthesis.routing.caps.start`); ``None`` without
    entries (nothing to trap)."""
    if not entries:
        return None

    def traps(cut: np.ndarray) -> bool:
        blocked = blocked_of_edges(products, np.flatnonzero(cut[groups.of_edge]))
        return bool(trapped_entries(products, blocked, entries))

    return traps


#: Largest bound, row or integrality violation of a solution we accept (HiGHS's own
#: MIP feasibility tolerance is 1e-6; our coefficients are small integers).
FEASIBILITY_TOLERANCE = 1e-5


LIMIT_TEXT = {"time_limit": "time limit", "node_limit": "node limit", "work_limit": "work limit"}
"""How an error message names the budget that stopped a solve (``stopped_by``)."""
