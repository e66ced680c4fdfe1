"""Phase 2 of MILP-static (fewest cuts at a fixed flow ``F``) by an implicit hitting set over the
cut groups, with CP-SAT as the master: what ``auto`` runs first on static models with few free
groups (:func:`synthesis.routing.backends.cpsat_phases.phase2`, through :func:`try_hitting_set`,
which turns its answer into a whole model solution, checked: :func:`model_solution`).

The master is the 0-1 problem ``min sum_g weight_g d_g`` over the binaries of the groups that
may be cut (:class:`~synthesis.routing.backends.separator.CoverSeparator`'s columns), with only the rows
found so far. Each round solves it to its proven optimum ``C`` and asks
:meth:`~synthesis.routing.backends.separator.CoverSeparator.separate` what ``C`` fails at level ``F``:

(a) an open bypass path (``Src -> Tgt`` over the c5 edges, avoiding I) gives "cut one of its
    distinct groups" (several group-disjoint paths per round). Every cut set of MILP-static
    closes every bypass path (c4-c5), so it cuts a group of each: the row is valid;
(b) a flow below ``F`` gives the minimum-cut rows of a *minimal* group set ``K`` that keeps the
    flow below ``F`` (``sum_g min(n_g, F) (1 - d_g) + fixed >= F`` over the model edges of the
    minimum cut under ``K``; at ``F = 1`` the no-good "open one of ``K``"). Max-flow min-cut:
    every cut set with flow at least ``F`` leaves at least ``F`` of those edges open, and a
    group stands for at most ``min(n_g, F)`` of the ``F`` edge-disjoint paths' crossings, so the
    row is valid (proof in :mod:`synthesis.routing.backends.separator`).

MILP-static's cut sets of flow ``F`` are exactly those that pass (a) and (b) (no open bypass is
c4-c5 over binary cuts; c2-c3 with the flow row is a flow of value ``F`` over the open edges), so
the master with any set of valid rows is a relaxation: its optimum is a lower bound, a master
optimum that passes every check is optimal, and so is the incumbent once the lower bound reaches
its cost. Each round adds rows the master's answer violates, so no answer comes twice and the
search ends (at most ``2^groups`` rounds; in practice hundreds).

The master lives in one CP-SAT child (:class:`~synthesis.routing.backends.cpsat.CpSatSession`) for the
whole search: rows are added to the model it holds, each round is a fresh CP-SAT search on it
(CP-SAT cannot resume one): it solved the masters several times faster than HiGHS on the
static grids measured, and no hint is passed, which slowed the search there
(docs/benchmarks/solvers.md, "The hitting set (MILP-static phase 2)"). Budgets are deterministic: :attr:`HittingSetBudget.rounds` and the master's deterministic
seconds (``work``); a wall-clock deadline only when the user set one. A stop request (Ctrl-C)
kills the child within :data:`~synthesis.routing.solver_control.POLL` seconds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from ...graphs.products import Products
from ..certificates import CutProof, model_arrays, solves_at
from ..model import RoutingModel
from ..options import MilpOptions
from ..phases import phase2_cost
from ..solver_control import Clock, SolveControl
from . import cpsat
from .separator import CoverSeparator, Row

KEEP = 64
"""Solutions of each master search (in the order found, the optimum last) whose failures become
rows: each satisfies every row so far, so its failures are new rows, got without another master
solve; on the static grids measured this took a fraction of the rounds
(docs/benchmarks/solvers.md, "The hitting set (MILP-static phase 2)")."""


KEPT_PATHS = 4
"""Bypass paths separated per kept solution (the master's optimum gets
:data:`~synthesis.routing.backends.separator.PATHS_PER_ROUND`): the kept solutions are many, and their
separation, not the master, took most of the time on the 5x5 reaction grids."""


def _key(row: Row) -> tuple[object, ...]:
    return (tuple(row.cols.tolist()), tuple(row.vals.tolist()), row.lo, row.hi)


IHS_MAX_GROUPS = 64
"""Free groups (master columns) up to which ``auto`` runs the hitting set first in phase 2 of
MILP-static (see :func:`synthesis.routing.backends.cpsat_phases.phase2_cpsat`)."""

IHS_MAX_FLOW = 1
"""The flow levels at which ``auto`` runs the hitting set: at flow 1 its flow rows are no-goods
over minimal group sets and it proves the static 5x5 grids measured; at flow 2 the rows
``sum min(n_g, 2) (1 - d_g) >= 2`` are weak: on refueling (flow 2) it ran out of budget below
the optimum, which CP-SAT on the flow model proves at once (docs/benchmarks/solvers.md, "The hitting set (MILP-static phase 2)")."""

IHS_WORK = 40.0
"""Deterministic seconds of master search that ``auto`` grants the hitting set before it falls
back to CP-SAT on the whole flow model (docs/benchmarks/solvers.md, "The hitting set (MILP-static phase 2)")."""

IHS_ROUNDS = 5_000
"""Rounds that ``auto`` grants the hitting set (a deterministic budget far above what the 5x5
grids need)."""


@dataclass(frozen=True)
class HittingSetBudget:
    """What the hitting set may spend: ``rounds`` (master solves), ``work`` (the master's
    deterministic seconds, summed; ``None``: no limit), ``deadline`` (``time.perf_counter()``
    value, only when the user asked for a wall clock)."""

    rounds: int = IHS_ROUNDS
    work: float | None = IHS_WORK
    deadline: float | None = None


@dataclass
class HittingSetResult:
    """The best checked cut set (``bool`` per group) with its ``cost``, the proven lower bound,
    whether ``cut`` is proven optimal at the level (with ``cut`` ``None``: no cut set has the
    flow, ``empty``), what stopped the search short of a proof
    (``"work_limit"``, ``"time_limit"`` or ``None``), and the counters."""

    cut: np.ndarray | None
    cost: float
    bound: float
    proven: bool
    stopped_by: str | None
    rounds: int = 0
    rows: dict[str, int] = field(default_factory=lambda: {"cover": 0, "flow": 0})
    work: float = 0.0
    master_seconds: float = 0.0
    master_cpu_seconds: float = 0.0
    separation_seconds: float = 0.0

    @property
    def empty(self) -> bool:
        """Proven: no cut set has this flow."""
        return self.proven and self.cut is None

    def stats(self) -> dict[str, object]:
        """The figures for a routing result's stats."""
        return {
            "flow_level_empty": self.empty,
            "proven": self.proven,
            "bound": self.bound,
            "cost": self.cost,
            "rounds": self.rounds,
            "rows": dict(self.rows),
            "deterministic_time": self.work,
            "master_seconds": self.master_seconds,
            "master_cpu_seconds": self.master_cpu_seconds,
            "separation_seconds": self.separation_seconds,
            "stopped_by": self.stopped_by,
        }


def fewest_cuts(
    sep: CoverSeparator,
    flow: int,
    incumbent: np.ndarray | None,
    budget: HittingSetBudget,
    *,
    bound: float = 0.0,
    random_seed: int = 0,
    control: SolveControl | None = None,
) -> HittingSetResult:
    """The fewest cuts at flow ``flow`` by the implicit hitting set (module docstring), from
    ``incumbent`` (``bool`` per group: a cut set that passes every check at ``flow``; its cost
    is the upper bound; ``None``: none known) and a proven lower ``bound`` (such as the walls'
    cut bound). Without an incumbent, a master without solution proves that no cut set has flow
    ``flow`` (``empty``): the rows are valid for every such cut set.

    Raises ``RuntimeError`` if the incumbent fails a check (a caller's bug) or the master
    becomes infeasible (the incumbent satisfies every row: a FlowTest bug);
    ``KeyboardInterrupt`` on Ctrl-C or a stop request."""
    if incumbent is not None and not sep.checks_pass(incumbent, flow):
        raise RuntimeError("the hitting set's incumbent fails a check: a FlowTest bug")
    best = None if incumbent is None else incumbent.copy()
    out = HittingSetResult(best, float("inf") if best is None else sep.cost_of(best), float(bound), False, None)
    if best is not None and out.bound >= out.cost - 0.5:
        out.proven = True
        return out
    n = sep.n_col
    arrays = cpsat.ModelArrays(sp.csr_matrix((0, n)), np.zeros(0), np.zeros(0), np.zeros(n), np.ones(n))
    with cpsat.CpSatSession(arrays, control) as session:
        while True:
            if control is not None and control.stop_requested:
                raise KeyboardInterrupt
            if out.rounds >= budget.rounds:
                out.stopped_by = "work_limit"
                return out
            left = None if budget.work is None else budget.work - out.work
            if left is not None and left <= 0.0:
                out.stopped_by = "work_limit"
                return out
            seconds = None
            if budget.deadline is not None:
                seconds = budget.deadline - time.perf_counter()
                if seconds <= 0.0:
                    out.stopped_by = "time_limit"
                    return out
            out.rounds += 1
            t = time.perf_counter()
            ans = session.solve(
                sep.cost,
                False,
                None,
                seconds=seconds,
                after_first=None,
                work_limit=left,
                rel_gap=0.0,
                random_seed=random_seed,
                phase="phase 2 (fewest cuts, hitting set)",
                flow=flow,
                keep=KEEP,
            )
            out.master_seconds += time.perf_counter() - t
            out.master_cpu_seconds += float(ans.stats["cpu_seconds"])
            out.work += float(ans.stats["deterministic_time"])
            if ans.status == "infeasible":
                if out.cut is not None:
                    raise RuntimeError("the hitting set's master lost the incumbent: a FlowTest bug")
                out.proven, out.bound = True, float("inf")  # no cut set has this flow
                return out
            if ans.status != "optimal" or ans.x is None:
                out.stopped_by = ans.stopped_by or "work_limit"
                return out
            value = float(sep.cost @ np.round(ans.x))
            out.bound = max(out.bound, value)
            if out.cut is not None and out.bound >= out.cost - 0.5:  # the relaxation's optimum reaches the incumbent
                out.proven = True
                return out
            cut = sep.cut_of_point(ans.x)
            t = time.perf_counter()
            found, flow_cuts = sep.separate(cut, flow)
            rows: list[tuple[str, Row]] = found + [("flow", fc.row(flow)) for fc in flow_cuts]
            if not rows:  # the master's optimum passes every check: optimal
                out.cut, out.cost, out.proven = cut, value, True
                return out
            # the search's earlier solutions satisfy every row so far too: their failures are
            # rows as well, found without another master solve
            seen = {_key(r) for _, r in rows}
            for y in ans.solutions[:-1]:
                other = sep.cut_of_point(y)
                more, more_cuts = sep.separate(other, flow, KEPT_PATHS)
                if not more and not more_cuts and sep.cost_of(other) < out.cost:  # a test: a better incumbent
                    out.cut, out.cost = other, sep.cost_of(other)
                for kind, row in more + [("flow", fc.row(flow)) for fc in more_cuts]:
                    if _key(row) not in seen:
                        seen.add(_key(row))
                        rows.append((kind, row))
            out.separation_seconds += time.perf_counter() - t
            for kind, _ in rows:
                out.rows[kind] = out.rows.get(kind, 0) + 1
            session.add_rows([(row.cols, row.vals, row.lo, row.hi) for _, row in rows])


@dataclass(frozen=True)
class HittingSetOutcome:
    """The hitting set's outcome in phase 2 (:func:`try_hitting_set`): its best answer as a model
    solution, checked, and the search's figures."""

    x: np.ndarray
    result: HittingSetResult


def try_hitting_set(
    products: Products, rm: RoutingModel, x: np.ndarray, flow: int, options: MilpOptions, clock: Clock, proof: CutProof | None
) -> HittingSetOutcome | None:
    """Phase 2 of MILP-static by the implicit hitting set (:func:`fewest_cuts`)
    where it applies: MILP-static without exclusions, places objective or closed-loop traps, at
    most :data:`IHS_MAX_GROUPS` free groups, flow at most
    :data:`IHS_MAX_FLOW`, and no cut bound proof already in hand.
    It starts from the cheaper of phase 1's answer and the cut bound's candidate, with the cut bound as its lower bound, and has a deterministic budget
    (:class:`HittingSetBudget`: rounds and the master's
    deterministic seconds, at most ``options.work_limit``) and the user's wall clock. Its answer
    becomes a whole model solution (:func:`model_solution`), checked against the model.
    ``None`` where it does not apply."""
    if options.mode != "static" or options.exclusions or options.block_states or options.closed_loop or flow > IHS_MAX_FLOW:
        return None
    groups = rm.groups
    me = replace(rm.edges, has_var=rm.edges.has_var & ~rm.reductions.fixed_open)
    sep = CoverSeparator(products, options, groups, me, {})
    if sep.n_col > IHS_MAX_GROUPS:
        return None
    cost = phase2_cost(rm, options)
    if proof is not None:
        x = proof.start(x, cost)
        if proof.meets(x, cost):
            return None  # proven already: phase2_cpsat says so
    work = IHS_WORK if options.work_limit is None else min(IHS_WORK, options.work_limit)
    budget = HittingSetBudget(work=work, deadline=clock.deadline)
    lower = 0.0 if proof is None else float(proof.bound)
    result = fewest_cuts(
        sep,
        flow,
        rm.cut_of(x),
        budget,
        bound=lower,
        random_seed=options.random_seed,
        control=options.control,
    )
    y = x if result.cut is None or np.array_equal(result.cut, rm.cut_of(x)) else model_solution(products, rm, result.cut, flow)
    return HittingSetOutcome(y, result)


def model_solution(products: Products, rm: RoutingModel, cut: np.ndarray, flow: int) -> np.ndarray:
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
    if not solves_at(model_arrays(rm), rm, x, flow):
        raise RuntimeError("the hitting set's answer is no solution of the routing model: a FlowTest bug")
    return x
