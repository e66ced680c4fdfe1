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
* **Lexicographic objective in two phases.** ``F - (1/|E|) sum d`` with integral F
  is maximised by first maximising F and then minimising the cuts with ``F`` fixed;
  both objectives are integral, so an absolute gap below 1 proves optimality.
* **Aggregated feasibility flows.** For a history ``q`` with ``K`` kept entry nodes,
  the ``K`` unit flows of c6-c8 are replaced by one flow in which every entry node
  supplies one unit, on edges of capacity ``K (1 - d)``. By flow decomposition each
  unit reaches ``Tgt_sys`` over uncut edges, and conversely ``K`` paths give such a
  flow, so the feasible cut sets are the same. Each flow lives on the part of
  G_sys reachable from its entries and co-reachable to ``Tgt_sys``.

Layout of one solve (:func:`_solve_once`): :func:`_build_model` adds named column blocks
(:class:`_Columns`: flows ``f``, cut binaries ``d``, reachability ``mu``, the feasibility
flows, MILP-agent's ``d_state``) and row blocks (:class:`_Rows`: c2, c3, c4-c5, the
couplings, MILP-agent's place rows, the exclusions), always in the same order; then
:func:`_phase1` (maximum flow), :func:`_phase2` (fewest cuts at that flow) and
:func:`_result`. Which histories need their feasibility flows is found by the MILP's own
trap search (:mod:`synthesis.routing.traps`), never by the checks it is held to.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import highspy
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from ..graphs.consistency import check_consistency
from ..graphs.products import Products, reachable
from ..model.errors import InconsistentProblem
from .heuristic import RouteSeed, RoutingGuess, guess_routing
from .solver_control import Clock, SolveControl, run_highs, stdout_guard
from .traps import trapped_configurations, trapped_entries

MODES = ("static", "reactive", "mixed")


@dataclass
class MilpOptions:
    """Options of the routing MILP.

    Attributes
    ----------
    mode
        ``"static"`` (c9 on every transition), ``"reactive"`` (c1-c8) or ``"mixed"``
        (c1-c8, c9 on ``static_moves``).
    static_moves
        ``bool`` mask over the moves of T: the static area of a mixed problem.
    bidirectional
        c14: a cut on ``s -> s'`` also cuts ``s' -> s`` (under the same history).
    tie_places
        Static cuts are tied between places (cells), not states: one wall per pair
        of cells across fuel levels.
    block_states
        MILP-agent: add ``d_state`` per place entered by a cut and minimise them
        before the cuts (method.md §7).
    exclusions
        Rejected cut sets, each as a list of cut-group keys; each gets the row
        ``sum d <= |C| - 1``.
    time_limit
        Seconds for both phases together (``None``: no limit); with ``after_first``,
        seconds to a first test.
    after_first
        Once a first test (flow >= 1) is in hand, seconds left to improve it
        (``None``: ``time_limit`` bounds the whole solve). The paper's budget is
        ``time_limit=600, after_first=60``.
    mip_rel_gap
        Relative gap at which HiGHS may stop (reported; ``status`` is then
        ``"feasible"`` unless the gap is proven 0).
    threads
        HiGHS threads (``None``: HiGHS decides, which depends on the machine). HiGHS's
        MIP search is deterministic for fixed options, version and thread count.
    node_limit
        Branch-and-bound nodes per HiGHS run (``mip_max_nodes``; ``None``: no limit):
        a deterministic budget, unlike ``time_limit``. A run stopped by it returns its
        best test (``"feasible"``) as a time limit does.
    random_seed
        HiGHS's ``random_seed``, fixed so the search is the same on every run.
    closed_loop
        Also forbid traps at configurations that are not entry nodes (see
        :func:`solve_routing`); ``False`` (the default) gives method.md §5 exactly.
    feasibility
        When the feasibility flows (c6-c8) enter the model: ``"auto"`` (see
        :func:`solve_routing`), ``"eager"`` (all at once: one round, and every
        incumbent of a time-limited solve is trap-free) or ``"lazy"`` (where they bind).
    offer_starts
        Offer HiGHS the heuristic's answer (phase 1) and the phase-1 answer (phase 2) as
        starts (each checked against the model first). Without, they are still kept as
        the fallback answers of a time-limited solve. (``experiments.bench_starts``
        measures both.)
    control
        Shared with the caller while HiGHS runs: Ctrl-C / stop requests, and the live
        status (best answer, bound, gap) a progress line shows (see
        :mod:`synthesis.routing.solver_control`).
    """

    mode: str = "reactive"
    static_moves: np.ndarray | None = None
    bidirectional: bool = False
    tie_places: bool = False
    block_states: bool = False
    exclusions: list[list[int]] = field(default_factory=list)
    time_limit: float | None = None
    after_first: float | None = None
    mip_rel_gap: float = 0.0
    threads: int | None = None
    progress: Callable[[str], None] | None = None
    closed_loop: bool = False
    feasibility: str = "auto"
    node_limit: int | None = None
    random_seed: int = 0
    control: SolveControl | None = None
    offer_starts: bool = True

    @property
    def deterministic(self) -> bool:
        """Whether the answer depends only on the problem, these options and the versions:
        no wall-clock limit, and a fixed thread count (design.md, "Determinism")."""
        return self.time_limit is None and self.after_first is None and bool(self.threads)


@dataclass(frozen=True)
class RoutingResult:
    """The answer of the routing MILP.

    Attributes
    ----------
    status
        ``"optimal"`` only when both phases were proven optimal, else ``"feasible"``.
    flow
        The flow value F.
    cut_edges
        Indices of the edges of G with ``d_e = 1`` (tied copies included).
    cut_group_keys
        The keys of the cut groups (used to exclude this cut set later).
    static_moves_cut
        ``bool`` mask over T's moves: moves blocked for the whole test.
    blocked_places
        Places with ``d_state = 1`` (MILP-agent only).
    mip_gap
        Relative gap of the last phase.
    stats
        Model sizes and times (problem-format.md's names).
    """

    status: str
    flow: int
    cut_edges: np.ndarray
    cut_group_keys: list[int]
    static_moves_cut: np.ndarray
    blocked_places: np.ndarray
    mip_gap: float
    stats: dict[str, Any]


class _Model:
    """Columns and rows collected as arrays, assembled once into a sparse matrix."""

    def __init__(self) -> None:
        self.n_col = 0
        self.lower: list[np.ndarray] = []
        self.upper: list[np.ndarray] = []
        self.integer: list[np.ndarray] = []
        self.n_row = 0
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.vals: list[np.ndarray] = []
        self.row_lo: list[np.ndarray] = []
        self.row_hi: list[np.ndarray] = []

    def add_cols(self, n: int, lo: float, hi: float, integer: bool = False) -> np.ndarray:
        idx = np.arange(self.n_col, self.n_col + n)
        self.n_col += n
        self.lower.append(np.full(n, lo, dtype=float))
        self.upper.append(np.full(n, hi, dtype=float))
        self.integer.append(np.full(n, integer, dtype=bool))
        return idx

    def add_rows(self, lo: np.ndarray | float, hi: np.ndarray | float, n: int) -> np.ndarray:
        idx = np.arange(self.n_row, self.n_row + n)
        self.n_row += n
        self.row_lo.append(np.broadcast_to(np.asarray(lo, dtype=float), (n,)).copy())
        self.row_hi.append(np.broadcast_to(np.asarray(hi, dtype=float), (n,)).copy())
        return idx

    def add_terms(self, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray | float) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        self.rows.append(rows)
        self.cols.append(np.asarray(cols, dtype=np.int64))
        self.vals.append(np.broadcast_to(np.asarray(vals, dtype=float), rows.shape).copy())

    def to_highs(self, cost: np.ndarray, maximize: bool) -> highspy.HighsLp:
        lp = highspy.HighsLp()
        lp.num_col_ = self.n_col
        lp.num_row_ = self.n_row
        lp.col_cost_ = cost
        lp.col_lower_ = np.concatenate(self.lower) if self.lower else np.zeros(0)
        lp.col_upper_ = np.concatenate(self.upper) if self.upper else np.zeros(0)
        lp.row_lower_ = np.concatenate(self.row_lo) if self.row_lo else np.zeros(0)
        lp.row_upper_ = np.concatenate(self.row_hi) if self.row_hi else np.zeros(0)

        def cat(xs: list[np.ndarray], dt: type) -> np.ndarray:
            return np.concatenate(xs).astype(dt) if xs else np.zeros(0, dtype=dt)

        a = sp.csc_matrix(
            (cat(self.vals, float), (cat(self.rows, np.int64), cat(self.cols, np.int64))),
            shape=(self.n_row, self.n_col),
        )
        a.sum_duplicates()
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = a.indptr.astype(np.int32)
        lp.a_matrix_.index_ = a.indices.astype(np.int32)
        lp.a_matrix_.value_ = a.data
        lp.a_matrix_.num_col_ = self.n_col
        lp.a_matrix_.num_row_ = self.n_row
        integ = np.concatenate(self.integer) if self.integer else np.zeros(0, dtype=bool)
        lp.integrality_ = [
            highspy.HighsVarType.kInteger if b else highspy.HighsVarType.kContinuous for b in integ
        ]
        lp.sense_ = highspy.ObjSense.kMaximize if maximize else highspy.ObjSense.kMinimize
        return lp

    @property
    def n_integer(self) -> int:
        return int(sum(int(x.sum()) for x in self.integer))


@dataclass(frozen=True)
class CutGroups:
    """Edges of G grouped by shared cut value.

    ``of_edge[e]`` is the group of edge ``e`` (every edge has one; groups of
    unrestrictable edges are never cut), ``keys[g]`` its stable key, ``weight[g]``
    the number of edges of G it stands for, ``restrictable[g]`` whether it may be cut,
    ``static[g]`` whether it is a static (history-independent) group.
    """

    of_edge: np.ndarray
    keys: np.ndarray
    weight: np.ndarray
    restrictable: np.ndarray
    static: np.ndarray
    move_key: np.ndarray  # per move of T, its static tie key


def cut_groups(products: Products, options: MilpOptions) -> CutGroups:
    """Group the edges of G by the cut value they must share (c9, c14, fuel ties)."""
    ts, g = products.ts, products.virtual
    static_moves = _static_moves(products, options)
    place = ts.place if options.tie_places else np.arange(ts.n_states, dtype=np.int32)
    n_place = int(place.max()) + 1
    a = place[ts.src].astype(np.int64)
    b = place[ts.dst].astype(np.int64)
    if options.bidirectional:
        a, b = np.minimum(a, b), np.maximum(a, b)
    move_key = a * n_place + b  # static tie key of each move
    span = np.int64(n_place) * n_place
    is_static = static_moves[g.move]
    key = np.where(is_static, move_key[g.move], span + g.hist[g.src].astype(np.int64) * span + move_key[g.move])
    keys, of_edge = np.unique(key, return_inverse=True)
    of_edge = of_edge.ravel()
    n = keys.size
    weight = np.bincount(of_edge, minlength=n)
    unrestrictable = np.bincount(of_edge, weights=~ts.restrictable[g.move], minlength=n) > 0
    return CutGroups(
        of_edge=of_edge,
        keys=keys,
        weight=weight,
        restrictable=~unrestrictable,
        static=keys < span,
        move_key=move_key,
    )


def _static_moves(products: Products, options: MilpOptions) -> np.ndarray:
    n = products.ts.n_moves
    if options.mode == "static":
        return np.ones(n, dtype=bool)
    if options.mode == "reactive":
        return np.zeros(n, dtype=bool)
    if options.mode == "mixed":
        if options.static_moves is None:
            raise ValueError("a mixed MILP needs static_moves")
        return np.asarray(options.static_moves, dtype=bool)
    raise ValueError(f"unknown MILP mode {options.mode!r}; expected one of {MODES}")


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


def _with_rounds(result: RoutingResult, rounds: int, entries: dict[int, np.ndarray]) -> RoutingResult:
    """``result`` with the feasibility rounds and histories of its solve in its stats."""
    return replace(result, stats={**result.stats, "feasibility_rounds": rounds, "feasibility_histories": len(entries)})


def required_entries(products: Products, options: MilpOptions) -> dict[int, np.ndarray]:
    """Per history, the G_sys entry nodes the feasibility flows must serve: none for
    MILP-static (its walls are on the map, see :func:`solve_routing`), else the kept
    entry nodes of method.md §5."""
    return {} if options.mode == "static" else products.kept_entries


def _with_extra(kept: dict[int, np.ndarray], extra: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    out = dict(kept)
    for q, nodes in extra.items():
        out[q] = np.union1d(out.get(q, np.zeros(0, dtype=np.int64)), nodes)
    return out


def blocked_by(products: Products, result: RoutingResult) -> np.ndarray:
    """``bool[n_hist, n_moves]``: the moves a routing answer restricts under each history."""
    out: np.ndarray = _blocked_of_edges(products, result.cut_edges) | result.static_moves_cut[None, :]
    return out


def _blocked_of_edges(products: Products, edges: np.ndarray) -> np.ndarray:
    """``bool[n_hist, n_moves]``: the moves cut edges of G restrict, under the history of their tail."""
    g = products.virtual
    blocked = np.zeros((g.n_hist, products.ts.n_moves), dtype=bool)
    blocked[g.hist[g.src[edges]], g.move[edges]] = True
    return blocked


class _FlowsBind(Exception):
    """Phase 1's answer traps entry nodes whose feasibility flows the model lacks."""

    def __init__(self, trapped: dict[int, np.ndarray]) -> None:
        super().__init__(f"{len(trapped)} histories trapped")
        self.trapped = trapped


@dataclass(frozen=True)
class _Columns:
    """The routing model's column blocks, as column indices (``-1`` where an item has none).

    Attributes
    ----------
    flow
        (c1) ``f_e``, one per model edge (:class:`ModelEdges`).
    cut
        ``d``, one binary per cut group that may be cut on some c5 edge.
    reach
        (c4, c5) ``mu_v``, one per node of G outside ``Src``, ``I`` and ``Tgt``.
    feasibility
        (c6-c8) the aggregated feasibility flow of each history with entry nodes.
    blocked_place
        MILP-agent: ``d_state``, one binary per place of :attr:`places`.
    places
        The places a cut may enter (MILP-agent), in the order of :attr:`blocked_place`.
    """

    flow: np.ndarray
    cut: np.ndarray
    reach: np.ndarray
    feasibility: list[_FeasibilityFlow]
    blocked_place: np.ndarray
    places: np.ndarray


@dataclass(frozen=True)
class _Rows:
    """The routing model's row blocks, as row indices (``-1`` where an item has none).

    Attributes
    ----------
    conservation
        (c2) one per node of G outside ``Src`` and ``Tgt``.
    cut_stops_flow
        (c3) ``f_e + d_e <= 1``, one per model edge with a cut binary.
    path_cut
        (c4, c5) ``d_uv - mu_u + mu_v >= [u = Src]`` on the c5 edges.
    coupling
        ``f_uv <= mu_u`` and ``f_uv <= mu_v`` outside ``I`` (tails, then heads).
    place_of_cut
        MILP-agent: ``d_state(p) >= d`` for each cut group entering place ``p``.
    exclusions
        ``sum_{g in C} d_g <= |C| - 1``, one per rejected cut set still cuttable.
    """

    conservation: np.ndarray
    cut_stops_flow: np.ndarray
    path_cut: np.ndarray
    coupling: tuple[np.ndarray, np.ndarray]
    place_of_cut: np.ndarray
    exclusions: list[np.ndarray]


@dataclass(frozen=True)
class _RoutingModel:
    """The routing MILP of one solve: its edges, cut groups, column and row blocks."""

    model: _Model
    edges: ModelEdges
    groups: CutGroups
    cols: _Columns
    rows: _Rows
    out_src: np.ndarray  # model edges leaving Src: their flow is F

    @property
    def n_col(self) -> int:
        return self.model.n_col

    @property
    def var_groups(self) -> np.ndarray:
        """The cut groups with a binary."""
        return np.flatnonzero(self.cols.cut >= 0)

    def flow_of(self, x: np.ndarray) -> float:
        """The flow value F of a solution."""
        return float(x[self.cols.flow[self.out_src]].sum())

    def cut_of(self, x: np.ndarray) -> np.ndarray:
        """``bool`` per cut group: cut in solution ``x``."""
        cut = np.zeros(self.groups.keys.size, dtype=bool)
        var = self.var_groups
        cut[var] = x[self.cols.cut[var]] > 0.5
        return cut


def _build_model(
    products: Products, options: MilpOptions, entries: dict[int, np.ndarray], keep_node: np.ndarray
) -> _RoutingModel:
    """Assemble the routing MILP (method.md §5, §7) as column and row blocks.

    The blocks go in in a fixed order (columns f, d, mu; rows c2, c3, c4-c5, couplings;
    the feasibility flows; MILP-agent's places; the exclusions), so the model, and with it
    HiGHS's answer, is the same on every run."""
    g = products.virtual
    groups = cut_groups(products, options)
    me = model_edges(products, groups, keep_node)
    m = _Model()
    flow, cut, reach = _add_columns(m, products, groups, me, keep_node)
    conservation = _add_conservation(m, products, me, flow, keep_node)
    cut_stops_flow = _add_cut_stops_flow(m, me, flow, cut)
    path_cut = _add_path_cuts(m, g.initial, me, cut, reach)
    coupling = _add_coupling(m, me, flow, reach)
    feasibility = _add_feasibility(m, products, groups, cut, entries) if entries else []
    blocked_place, places, place_of_cut = _add_blocked_places(m, products, groups, cut) if options.block_states else (
        np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    exclusions = _add_exclusions(m, groups, cut, options.exclusions)
    return _RoutingModel(
        model=m,
        edges=me,
        groups=groups,
        cols=_Columns(flow, cut, reach, feasibility, blocked_place, places),
        rows=_Rows(conservation, cut_stops_flow, path_cut, coupling, place_of_cut, exclusions),
        out_src=np.flatnonzero(me.eu == g.initial),
    )


def _add_columns(
    m: _Model, products: Products, groups: CutGroups, me: ModelEdges, keep_node: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c1) the flow ``f_e`` per model edge, the cut binaries ``d`` per group, and ``mu_v``."""
    g = products.virtual
    flow = m.add_cols(me.edges.size, 0.0, 1.0)
    cut = np.full(groups.keys.size, -1, dtype=np.int64)
    var_groups = np.flatnonzero(me.has_var)
    cut[var_groups] = m.add_cols(var_groups.size, 0.0, 1.0, integer=True)
    mu_nodes = np.flatnonzero(keep_node & ~products.intermediate & ~products.target)
    mu_nodes = mu_nodes[mu_nodes != g.initial]
    reach = np.full(g.n_nodes, -1, dtype=np.int64)
    reach[mu_nodes] = m.add_cols(mu_nodes.size, 0.0, 1.0)
    return flow, cut, reach


def _add_conservation(m: _Model, products: Products, me: ModelEdges, flow: np.ndarray, keep_node: np.ndarray) -> np.ndarray:
    """(c2) flow conservation at the nodes outside ``Src`` and ``Tgt``."""
    g = products.virtual
    nodes = np.flatnonzero(keep_node & ~products.target)
    nodes = nodes[nodes != g.initial]
    row = np.full(g.n_nodes, -1, dtype=np.int64)
    row[nodes] = m.add_rows(0.0, 0.0, nodes.size)
    out_ok = row[me.eu] >= 0
    m.add_terms(row[me.eu[out_ok]], flow[out_ok], 1.0)
    in_ok = row[me.ev] >= 0
    m.add_terms(row[me.ev[in_ok]], flow[in_ok], -1.0)
    return row


def _add_cut_stops_flow(m: _Model, me: ModelEdges, flow: np.ndarray, cut: np.ndarray) -> np.ndarray:
    """(c3) a cut edge carries no flow: ``f_e + d_e <= 1``."""
    dcol = cut[me.grp]
    with_d = np.flatnonzero(dcol >= 0)
    r = m.add_rows(-np.inf, 1.0, with_d.size)
    m.add_terms(r, flow[with_d], 1.0)
    m.add_terms(r, dcol[with_d], 1.0)
    return r


def _add_path_cuts(m: _Model, src_node: int, me: ModelEdges, cut: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """(c4, c5) every ``Src -> Tgt`` path avoiding I holds a cut: ``d_uv - mu_u + mu_v >= 0``
    (``mu_Src = 1`` moved to the right-hand side).

    Raises
    ------
    InconsistentProblem
        If an unrestrictable move leads from ``Src`` straight to the goal.
    """
    k = np.flatnonzero(me.c5)
    u, v, dk = me.eu[k], me.ev[k], cut[me.grp[k]]
    rhs = np.where(u == src_node, 1.0, 0.0)
    no_vars = (dk < 0) & (reach[u] < 0) & (reach[v] < 0)
    if np.any(no_vars & (rhs > 0)):
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed: an unrestrictable move leads from the start "
            "straight to the goal",
        )
    k, u, v, dk, rhs = (x[~no_vars] for x in (k, u, v, dk, rhs))
    r = m.add_rows(rhs, np.inf, k.size)
    sel = dk >= 0
    m.add_terms(r[sel], dk[sel], 1.0)
    sel = reach[u] >= 0
    m.add_terms(r[sel], reach[u[sel]], -1.0)
    sel = reach[v] >= 0
    m.add_terms(r[sel], reach[v[sel]], 1.0)
    return r


def _add_coupling(m: _Model, me: ModelEdges, flow: np.ndarray, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Strengthening (valid, optimum unchanged): some optimal solution has ``mu_v = 1``
    exactly on the nodes reachable from ``Src`` outside I over uncut edges, and flow
    outside I runs only on those nodes, so ``f_uv <= mu_u`` and ``f_uv <= mu_v`` there."""
    rows = []
    for ends in (me.eu, me.ev):
        sel = np.flatnonzero(reach[ends] >= 0)
        r = m.add_rows(-np.inf, 0.0, sel.size)
        m.add_terms(r, flow[sel], 1.0)
        m.add_terms(r, reach[ends[sel]], -1.0)
        rows.append(r)
    return rows[0], rows[1]


def _add_blocked_places(
    m: _Model, products: Products, groups: CutGroups, cut: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MILP-agent (method.md §7): a binary ``d_state`` per place entered by a cut, at least
    every cut into it. Returns ``(columns, places, rows)``."""
    g, ts = products.virtual, products.ts
    # every edge of G in a group with a binary enters the place of its head
    e_all = np.flatnonzero(cut[groups.of_edge] >= 0)
    pl = ts.place[ts.dst[g.move[e_all]]].astype(np.int64)
    pairs = np.unique(np.stack([pl, groups.of_edge[e_all]], axis=1), axis=0)
    places = np.unique(pairs[:, 0])
    cols = m.add_cols(places.size, 0.0, 1.0, integer=True)
    pc = cols[np.searchsorted(places, pairs[:, 0])]
    r = m.add_rows(0.0, np.inf, pairs.shape[0])
    m.add_terms(r, pc, 1.0)
    m.add_terms(r, cut[pairs[:, 1]], -1.0)
    return cols, places, r


def _add_exclusions(m: _Model, groups: CutGroups, cut: np.ndarray, exclusions: list[list[int]]) -> list[np.ndarray]:
    """One row ``sum d <= |C| - 1`` per rejected cut set ``C`` (a list of group keys)."""
    rows = []
    for excluded in exclusions:
        pos = np.searchsorted(groups.keys, np.asarray(excluded, dtype=np.int64))
        ok = (pos < groups.keys.size) & (groups.keys[np.minimum(pos, groups.keys.size - 1)] == excluded)
        cols = cut[pos[ok]]
        if not ok.all() or np.any(cols < 0):
            # a group of the rejected set cannot be cut in this model: the set is already excluded
            continue
        r = m.add_rows(-np.inf, float(cols.size - 1), 1)
        m.add_terms(np.repeat(r, cols.size), cols, 1.0)
        rows.append(r)
    return rows


@dataclass(frozen=True)
class _Phase:
    """What a phase of the solve ends with."""

    x: np.ndarray
    status: str
    gap: float
    stopped_by: str | None


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
    rm = _build_model(products, options, entries, check_consistency(products))
    graph_seconds = time.perf_counter() - t0
    h = _highs(options)
    h.passModel(rm.model.to_highs(np.zeros(rm.n_col), maximize=True))
    t_solve = time.perf_counter()
    note("routing MILP, phase 1 of 2: maximum flow")
    first = _phase1(h, rm, products, options, entries, clock)
    flow = _flow_of_phase1(rm, first)
    _raise_if_flows_bind(rm, products, options, first.x, {q: v for q, v in required.items() if q not in entries})
    note(f"routing MILP, phase 2 of 2: fewest cuts at flow {flow}")
    second = _phase2(h, rm, first.x, flow, options, clock)
    return _result(rm, products, options, first, second, flow, graph_seconds, time.perf_counter() - t_solve)


def _phase1(
    h: highspy.Highs, rm: _RoutingModel, products: Products, options: MilpOptions, entries: dict[int, np.ndarray], clock: Clock
) -> _Phase:
    """Phase 1, maximum flow: proven by the heuristic when it attains the flow upper bound,
    else solved by HiGHS (seeded by the heuristic's answer, kept as the fallback)."""
    guess = rm.edges.guess(products, traps=_trap_test(products, rm.groups, entries))
    x_guess = _guess_solution(products, rm, guess, options)
    if x_guess is not None:
        clock.first_test()
    if x_guess is not None and guess.flow == guess.upper_bound:
        return _Phase(x_guess, "optimal", 0.0, None)  # the flow upper bound is attained: proven
    cost = np.zeros(rm.n_col)
    cost[rm.cols.flow[rm.out_src]] = 1.0
    h.changeColsCost(rm.n_col, np.arange(rm.n_col, dtype=np.int32), cost)
    # a route-seeded start is kept as the fallback but not handed to HiGHS: from
    # it, HiGHS's neighbourhood heuristics stay near the lone route (mars-exploration:
    # no flow 2 in 300 s, against 170 s from scratch)
    if x_guess is not None and not guess.from_route and options.offer_starts:
        _set_solution(h, x_guess)
    watch = clock.watching_first()
    try:
        status, gap, x1 = _run(h, clock.latest(), options, phase="phase 1 (maximum flow)", clock=clock, watch_first=watch)
    except TimeoutError:
        if x_guess is None:
            raise
        status, gap, x1 = "feasible", float("inf"), None
    stopped_by = _stopped_by(h)
    if status == "infeasible":
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed without trapping the system: no cut set "
            "routes every successful execution through it while leaving a way to the goal",
        )
    x = x1 if x1 is not None else x_guess
    if x is None:  # _run returns a solution unless it raised
        raise RuntimeError("phase 1 of the routing MILP ended without a solution")
    if x_guess is not None and guess.flow > rm.flow_of(x) + 0.5:
        return _Phase(x_guess, "feasible", gap, stopped_by)  # HiGHS stopped below the heuristic's flow
    return _Phase(x, status, gap, stopped_by)


def _flow_of_phase1(rm: _RoutingModel, first: _Phase) -> int:
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
    rm: _RoutingModel, products: Products, options: MilpOptions, x: np.ndarray, missing: dict[int, np.ndarray]
) -> None:
    """Raise :class:`_FlowsBind` if phase 1's cuts trap entry nodes of ``missing`` (histories
    whose feasibility flows the model lacks)."""
    if not missing:
        return
    groups = rm.groups
    cut1 = rm.cut_of(x)
    blocked1 = _blocked_of_edges(products, np.flatnonzero(cut1[groups.of_edge]))
    blocked1 |= (np.isin(groups.move_key, groups.keys[cut1 & groups.static]) & _static_moves(products, options))[None, :]
    trapped1 = trapped_entries(products, blocked1, missing)
    if trapped1:
        raise _FlowsBind(trapped1)


def _phase2(h: highspy.Highs, rm: _RoutingModel, x: np.ndarray, flow: int, options: MilpOptions, clock: Clock) -> _Phase:
    """Phase 2, fewest cuts (for the agent: fewest blocked places first) at flow ``flow``,
    seeded by the fewest-cuts answer with phase 1's flow held fixed."""
    f_col = rm.cols.flow
    h.addRow(flow - 0.5, highspy.kHighsInf, rm.out_src.size, f_col[rm.out_src].astype(np.int32), np.ones(rm.out_src.size))
    var_groups = rm.var_groups
    cost = np.zeros(rm.n_col)
    cost[rm.cols.cut[var_groups]] = rm.groups.weight[var_groups]
    if options.block_states and rm.cols.blocked_place.size:
        cost[rm.cols.blocked_place] = float(rm.groups.weight[var_groups].sum() + 1)
    h.changeObjectiveSense(highspy.ObjSense.kMinimize)
    h.changeColsCost(rm.n_col, np.arange(rm.n_col, dtype=np.int32), cost)
    clock.first_test()
    if clock.deadline is None:  # no wall clock: a deterministic budget for the helper solve
        x = _incumbent(h, x, f_col, None, options, flow, _min_limit(INCUMBENT_NODES, options.node_limit))
    else:
        x = _incumbent(h, x, f_col, _share(clock.deadline, INCUMBENT_SHARE), options, flow)
    if options.offer_starts:
        _set_solution(h, x)
    else:
        h.clearSolver()
    try:
        status, gap, x2 = _run(h, clock.deadline, options, phase="phase 2 (fewest cuts)", flow=flow)
    except TimeoutError:  # HiGHS kept no solution: the start is the answer
        status, gap, x2 = "feasible", float("inf"), x
    if status == "infeasible" or x2 is None:  # cannot happen: phase 1's solution is feasible
        raise RuntimeError("phase 2 of the routing MILP lost the phase-1 solution")
    return _Phase(x2, status, gap, _stopped_by(h))


def _result(
    rm: _RoutingModel,
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
    static_moves_cut = np.isin(groups.move_key, groups.keys[cut & groups.static]) & _static_moves(products, options)
    place_cols = rm.cols.blocked_place
    blocked = rm.cols.places[x[place_cols] > 0.5] if place_cols.size else np.zeros(0, dtype=np.int64)
    status = "optimal" if first.status == second.status == "optimal" else "feasible"
    mip_gap = float(max(first.gap, second.gap)) if status != "optimal" else 0.0
    m = rm.model
    stats: dict[str, Any] = {
        "binary_vars": m.n_integer,
        "continuous_vars": m.n_col - m.n_integer,
        "constraints": m.n_row + 1,
        "feasibility_vars": sum(fl.cols.size for fl in rm.cols.feasibility),
        "model_edges": int(rm.edges.edges.size),
        "graph_seconds": graph_seconds,
        "solve_seconds": solve_seconds,
        "mip_gap": mip_gap,
        "stopped_by": None if status == "optimal" else (first.stopped_by or second.stopped_by),
        "deterministic": options.deterministic,
    }
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


@dataclass(frozen=True)
class ModelEdges:
    """The edges of G the routing model keeps, and what the model knows of each.

    Attributes
    ----------
    edges
        Indices into G's edges: pruned to nodes that reach ``Tgt``, no edge into
        ``Src`` or out of ``Tgt``.
    eu, ev
        Their tails and heads.
    c5
        ``bool`` per kept edge: both ends outside I (the edge carries a c5 row).
    grp
        The cut group of each kept edge.
    has_var
        ``bool`` per group: the group gets a cut variable (restrictable, and on some
        c5 edge).
    """

    edges: np.ndarray
    eu: np.ndarray
    ev: np.ndarray
    c5: np.ndarray
    grp: np.ndarray
    has_var: np.ndarray

    def guess(self, products: Products, traps: Callable[[np.ndarray], bool] | None = None, route_seed: bool = True) -> RoutingGuess:
        """The routing heuristic on these edges (with the place-simple route seed unless
        ``route_seed`` is false)."""
        g = products.virtual
        return guess_routing(
            g.n_nodes,
            g.initial,
            self.eu,
            self.ev,
            self.grp,
            self.c5,
            self.has_var,
            products.target,
            traps=traps,
            route_seed=RouteSeed(products.ts.place[g.state], g.hist, products.intermediate) if route_seed else None,
        )


def model_edges(products: Products, groups: CutGroups, keep_node: np.ndarray | None = None) -> ModelEdges:
    """The routing model's edges (see :class:`ModelEdges`); ``keep_node`` is what
    :func:`~synthesis.graphs.consistency.check_consistency` returns (computed when not given)."""
    g = products.virtual
    if keep_node is None:
        keep_node = check_consistency(products)
    tgt, inter = products.target, products.intermediate
    edges = np.flatnonzero(keep_node[g.src] & keep_node[g.dst] & (g.dst != g.initial) & ~tgt[g.src])
    eu, ev = g.src[edges], g.dst[edges]
    c5 = ~inter[eu] & ~inter[ev]
    grp = groups.of_edge[edges]
    useful = np.zeros(groups.keys.size, dtype=bool)
    useful[grp[c5]] = True
    return ModelEdges(edges, eu, ev, c5, grp, useful & groups.restrictable)


def _guess_solution(products: Products, rm: _RoutingModel, guess: RoutingGuess, options: MilpOptions) -> np.ndarray | None:
    """The heuristic's cut set as a full model solution, or ``None`` if it is unusable.

    Unusable: no flow, a rejected cut set (an exclusion row), or, with feasibility
    constraints, an entry node trapped by the cuts. The feasibility flows are
    completed along shortest open paths, so the start is a whole solution and a solve
    stopped by its time limit still returns a checked test.
    """
    if guess.flow < 1:
        return None
    cols, groups = rm.cols, rm.groups
    cut_mask = guess.cut_groups & (cols.cut >= 0)
    cut_keys = set(groups.keys[cut_mask].tolist())
    for excluded in options.exclusions:
        if excluded and set(excluded) <= cut_keys:
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
    return x


def _trap_test(products: Products, groups: CutGroups, entries: dict[int, np.ndarray]) -> Callable[[np.ndarray], bool] | None:
    """Whether a cut set (``bool`` per group) traps an entry node, for the heuristic."""
    if not entries:
        return None
    def traps(cut: np.ndarray) -> bool:
        blocked = _blocked_of_edges(products, np.flatnonzero(cut[groups.of_edge]))
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
        a = sp.csc_matrix(
            (np.asarray(lp.a_matrix_.value_), np.asarray(lp.a_matrix_.index_), np.asarray(lp.a_matrix_.start_)),
            shape=(m, n),
        ).tocsr()
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
) -> np.ndarray:
    """A good first phase-2 solution: fewest cuts with the phase-1 flow held fixed.

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
        _, _, y = _run(h, deadline, options, phase="phase 2 start (fewest cuts, flow fixed)", flow=flow)
        if y is not None:
            x = y
    except TimeoutError:
        pass
    finally:
        h.setOptionValue("mip_max_nodes", node_limit)
    h.changeColsBounds(idx.size, idx, lo, hi)
    return x


def _add_feasibility(
    m: _Model,
    products: Products,
    groups: CutGroups,
    cut: np.ndarray,
    entries: dict[int, np.ndarray],
) -> list[_FeasibilityFlow]:
    """Add c6-c8 as one aggregated flow per history; returns where each flow lives.

    A flow edge over move ``t`` under history ``q`` is closed by the cut of the G edge
    of ``Gr(q)`` over ``t`` (method.md c7); where G has no such edge nothing closes it.
    """
    g, gs = products.virtual, products.system
    ts = products.ts
    co = products.system_coreachable
    sys_tgt = products.system_target
    # the edge of G in Gr(q) over move t, for every (q, t) that has one
    gkey = g.hist.astype(np.int64)[g.src] * ts.n_moves + g.move
    gorder = np.argsort(gkey)
    gkey_sorted = gkey[gorder]
    flows: list[_FeasibilityFlow] = []
    for q, nodes in entries.items():
        supply_nodes = nodes[~sys_tgt[nodes]]
        if supply_nodes.size == 0:
            continue
        area = reachable(gs.n_nodes, gs.src, gs.dst, np.isin(np.arange(gs.n_nodes), supply_nodes)) & co
        e = np.flatnonzero(area[gs.src] & area[gs.dst] & ~sys_tgt[gs.src])
        cap = float(supply_nodes.size)
        cols = m.add_cols(e.size, 0.0, cap)
        nodes = np.flatnonzero(area & ~sys_tgt)
        row_of = np.full(gs.n_nodes, -1, dtype=np.int64)
        supply = np.isin(nodes, supply_nodes).astype(float)
        row_of[nodes] = m.add_rows(supply, supply, nodes.size)
        s, d = gs.src[e], gs.dst[e]
        m.add_terms(row_of[s], cols, 1.0)
        ok = row_of[d] >= 0
        m.add_terms(row_of[d[ok]], cols[ok], -1.0)
        # (c7) no flow over a transition cut under q: x + K d <= K
        want = np.int64(q) * ts.n_moves + gs.move[e]
        pos = np.searchsorted(gkey_sorted, want)
        pos = np.minimum(pos, gkey_sorted.size - 1)
        found = gkey_sorted[pos] == want
        dcol = np.full(e.size, -1, dtype=np.int64)
        dcol[found] = cut[groups.of_edge[gorder[pos[found]]]]
        sel = np.flatnonzero(dcol >= 0)
        r = m.add_rows(-np.inf, cap, sel.size)
        m.add_terms(r, cols[sel], 1.0)
        m.add_terms(r, dcol[sel], cap)
        flows.append(_FeasibilityFlow(cols=cols, src=s, dst=d, dcol=dcol, supply_nodes=supply_nodes))
    return flows


@dataclass
class _FeasibilityFlow:
    """One aggregated feasibility flow: its columns, their G_sys edges and closing cuts."""

    cols: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    dcol: np.ndarray  # the cut column closing each edge, -1 where none
    supply_nodes: np.ndarray

    def tree_flow(self, n_nodes: int, is_cut: np.ndarray, targets: np.ndarray) -> np.ndarray | None:
        """A feasible value of this flow under the cut values ``is_cut`` (per column).

        Every supply node sends its unit along a shortest open path to ``targets``
        (a BFS tree towards them), so no edge carries more than the supply: ``None``
        if some supply node has no open path.
        """
        open_edge = np.flatnonzero((self.dcol < 0) | ~is_cut[np.maximum(self.dcol, 0)])
        s, d = self.src[open_edge], self.dst[open_edge]
        tnodes = np.flatnonzero(targets)
        # reverse graph with a super node pointing at every target
        rs = np.concatenate([d, np.full(tnodes.size, n_nodes)])
        rd = np.concatenate([s, tnodes])
        adj = sp.csr_matrix((np.ones(rs.size, dtype=np.int8), (rs, rd)), shape=(n_nodes + 1, n_nodes + 1))
        order, pred = breadth_first_order(adj, n_nodes, directed=True, return_predecessors=True)
        depth = np.full(n_nodes + 1, -1, dtype=np.int64)
        depth[n_nodes] = 0
        for v in order[1:]:  # BFS order: a node's tree parent comes before it
            depth[v] = depth[pred[v]] + 1
        if np.any(depth[self.supply_nodes] < 0):
            return None
        load = np.zeros(n_nodes + 1)
        load[self.supply_nodes] = 1.0
        value = np.zeros(self.cols.size)
        # the open edge v -> pred[v] of each node on the tree, farthest nodes first
        key = s.astype(np.int64) * (n_nodes + 1) + d
        korder = np.argsort(key)
        for level in range(int(depth.max()), 1, -1):
            v = np.flatnonzero(depth == level)
            v = v[load[v] > 0]
            if v.size == 0:
                continue
            k = korder[np.searchsorted(key[korder], v.astype(np.int64) * (n_nodes + 1) + pred[v])]
            np.add.at(value, open_edge[k], load[v])
            np.add.at(load, pred[v], load[v])
        return value


def _highs(options: MilpOptions) -> highspy.Highs:
    with stdout_guard():  # HiGHS >= 1.16 prints its banner on construction, before any option
        h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("log_to_console", False)
    if options.threads is not None:
        highspy.Highs.resetGlobalScheduler(True)
        h.setOptionValue("threads", int(options.threads))
    h.setOptionValue("mip_rel_gap", float(options.mip_rel_gap))
    h.setOptionValue("random_seed", int(options.random_seed))
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
) -> tuple[str, float, np.ndarray | None]:
    """Run HiGHS until done, the deadline or a stop; return (status, relative gap, solution).

    The solution HiGHS returns is checked against the model it holds, by us: every bound,
    row and integrality, and its objective, recomputed. ``"optimal"`` needs that objective
    within less than 1 of HiGHS's dual bound (both objectives are integral, so this is a
    proof), not only HiGHS's word. HiGHS 1.16.0 with a start and presolve can return the
    start itself while it reports (and proves) a better objective: the proven optimum of
    the reduced model, not postsolved (``tests/test_highs_start.py``). When the returned
    solution does not have the objective HiGHS reports, or violates the model, the solve
    is run again without any start (``clearSolver``); if that still disagrees the answer
    is at most ``"feasible"``, with the gap its own objective leaves to the bound.

    Raises ``TimeoutError`` when HiGHS stopped with no solution, ``KeyboardInterrupt``
    on Ctrl-C or a stop request (see :func:`synthesis.routing.solver_control.run_highs`).
    """
    for attempt in (1, 2):
        run_highs(h, deadline, clock=clock, control=options.control, phase=phase, flow=flow, watch_first=watch_first)
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
    if not feasible:
        return "feasible", float("inf"), None, False
    # integral objectives: an absolute gap below 1 between the solution we hold and
    # HiGHS's bound proves it optimal; a larger one (a user's mip_rel_gap) does not
    proven = np.isfinite(bound) and abs(objective - bound) < 1.0 - 1e-6
    if ms == highspy.HighsModelStatus.kOptimal and proven:
        return "optimal", 0.0, x, agrees
    gap = abs(objective - bound) / max(abs(objective), 1.0) if np.isfinite(bound) else float("inf")
    return "feasible", float(gap), x, agrees


_LIMIT_TEXT = {"time_limit": "time limit", "node_limit": "node limit"}


def _stopped_by(h: highspy.Highs) -> str | None:
    """Which budget stopped HiGHS's last run: ``"time_limit"`` (the wall clock, or the
    interrupt that enforces it), ``"node_limit"`` (a deterministic work limit) or ``None``."""
    ms = h.getModelStatus()
    if ms in (highspy.HighsModelStatus.kTimeLimit, highspy.HighsModelStatus.kInterrupt):
        return "time_limit"
    if ms in (highspy.HighsModelStatus.kSolutionLimit, highspy.HighsModelStatus.kIterationLimit):
        return "node_limit"
    return None
