"""The routing MILP as a model (docs/method.md §5, §7): named column and row blocks over the cut
groups and model edges of :mod:`synthesis.routing.groups`.

:func:`build_model` adds the blocks in a fixed order, so the model, and with it HiGHS's
answer, is the same on every run: columns (:class:`Columns`: flows ``f``, cut binaries
``d``, reachability ``mu``), rows (:class:`Rows`: c2, c3, c4-c5, the couplings), the
aggregated feasibility flows (c6-c8, :class:`FeasibilityFlow`), MILP-agent's ``d_state``
columns and rows, the exclusions, the caps (:class:`CapRows`). Solving it is
:mod:`synthesis.routing.solve`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import highspy
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from ..graphs.products import Products, reachable
from ..model.errors import InconsistentProblem
from .bounds.cut_bound import CutBound, static_cut_bound
from .bounds.flow_bound import static_flow_bound
from .bounds.heuristic import RoutingGuess, open_flow_bound
from .bounds.reductions import Reductions, reduce_groups
from .edges import ModelEdges, model_edges
from .groups import CutGroups, PhysicalItems, cut_groups, physical_items
from .options import Exclusion, MilpOptions


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

    def add_cols(self, n: int, lo: float, hi: float | np.ndarray, integer: bool = False) -> np.ndarray:
        idx = np.arange(self.n_col, self.n_col + n)
        self.n_col += n
        self.lower.append(np.full(n, lo, dtype=float))
        self.upper.append(np.broadcast_to(np.asarray(hi, dtype=float), (n,)).copy())
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

    def matrix(self) -> sp.csc_matrix:
        """The constraint matrix (rows x columns), duplicates summed."""

        def cat(xs: list[np.ndarray], dt: type) -> np.ndarray:
            return np.concatenate(xs).astype(dt) if xs else np.zeros(0, dtype=dt)

        a = sp.csc_matrix(
            (cat(self.vals, float), (cat(self.rows, np.int64), cat(self.cols, np.int64))),
            shape=(self.n_row, self.n_col),
        )
        a.sum_duplicates()
        return a

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(col_lo, col_hi, row_lo, row_hi)``."""

        def cat(xs: list[np.ndarray]) -> np.ndarray:
            return np.concatenate(xs) if xs else np.zeros(0)

        return cat(self.lower), cat(self.upper), cat(self.row_lo), cat(self.row_hi)

    def to_highs(self, cost: np.ndarray, maximize: bool) -> highspy.HighsLp:
        lp = highspy.HighsLp()
        lp.num_col_ = self.n_col
        lp.num_row_ = self.n_row
        lp.col_cost_ = cost
        lp.col_lower_, lp.col_upper_, lp.row_lower_, lp.row_upper_ = self.bounds()
        a = self.matrix()
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = a.indptr.astype(np.int32)
        lp.a_matrix_.index_ = a.indices.astype(np.int32)
        lp.a_matrix_.value_ = a.data
        lp.a_matrix_.num_col_ = self.n_col
        lp.a_matrix_.num_row_ = self.n_row
        integ = np.concatenate(self.integer) if self.integer else np.zeros(0, dtype=bool)
        lp.integrality_ = [highspy.HighsVarType.kInteger if b else highspy.HighsVarType.kContinuous for b in integ]
        lp.sense_ = highspy.ObjSense.kMaximize if maximize else highspy.ObjSense.kMinimize
        return lp

    @property
    def n_integer(self) -> int:
        return int(sum(int(x.sum()) for x in self.integer))


@dataclass(frozen=True)
class Columns:
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
    feasibility: list[FeasibilityFlow]
    blocked_place: np.ndarray
    places: np.ndarray


@dataclass(frozen=True)
class Rows:
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
class RoutingModel:
    """The routing MILP of one solve: its edges, cut groups, column and row blocks."""

    model: _Model
    edges: ModelEdges
    groups: CutGroups
    cols: Columns
    rows: Rows
    out_src: np.ndarray  # model edges leaving Src: their flow is F
    reductions: Reductions  # the cut groups fixed open (d = 0) before the solve
    flow_bound: int | None = None  # MILP-static: the walls' flow bound where below the heuristic's (synthesis.routing.bounds.flow_bound)
    caps: CapRows | None = None  # the caps' items and rows (options.caps), None without caps

    def guess(self, products: Products, traps: Callable[[np.ndarray], bool] | None = None) -> RoutingGuess:
        """The routing heuristic on this model: its edges, no group fixed open cut; its flow
        upper bound lowered to :attr:`flow_bound` where that is smaller (it is proven too)."""
        guess = self.edges.guess(products, traps=traps, fixed_open=self.reductions.fixed_open)
        if self.flow_bound is not None and self.flow_bound < guess.upper_bound:
            if self.flow_bound < guess.flow:
                raise RuntimeError(f"flow bound {self.flow_bound} below the heuristic's valid flow {guess.flow}: a FlowTest bug")
            guess = replace(guess, upper_bound=self.flow_bound)
        return guess

    @property
    def n_col(self) -> int:
        return self.model.n_col

    @property
    def var_groups(self) -> np.ndarray:
        """The cut groups with a binary (fixed open ones included: their upper bound is 0)."""
        return np.flatnonzero(self.cols.cut >= 0)

    @property
    def free_groups(self) -> np.ndarray:
        """The cut groups with a binary that the reductions leave free."""
        return np.flatnonzero((self.cols.cut >= 0) & ~self.reductions.fixed_open)

    def flow_of(self, x: np.ndarray) -> float:
        """The flow value F of a solution."""
        return float(x[self.cols.flow[self.out_src]].sum())

    def cut_of(self, x: np.ndarray) -> np.ndarray:
        """``bool`` per cut group: cut in solution ``x``."""
        cut = np.zeros(self.groups.keys.size, dtype=bool)
        var = self.var_groups
        cut[var] = x[self.cols.cut[var]] > 0.5
        return cut

    def with_items(self, x: np.ndarray) -> np.ndarray:
        """``x`` with the caps' item columns at their least values (1 where a cut group of
        the item is cut), so a solution built from cut values alone meets the item rows."""
        caps = self.caps
        if caps is None:
            return x
        x = x.copy()
        used = np.zeros(caps.items.is_wall.size, dtype=bool)
        used[caps.items.of_group[self.cut_of(x)]] = True
        has = caps.item_col >= 0
        x[caps.item_col[has]] = used[has].astype(float)
        return x


def build_model(products: Products, options: MilpOptions, entries: dict[int, np.ndarray], keep_node: np.ndarray) -> RoutingModel:
    """Assemble the routing MILP (docs/method.md §5, §7) as column and row blocks.

    The blocks go in in a fixed order (columns f, d, mu; rows c2, c3, c4-c5, couplings;
    the feasibility flows; MILP-agent's places; the exclusions), so the model, and with it
    HiGHS's answer, is the same on every run. The cut groups that
    :func:`~synthesis.routing.bounds.reductions.reduce_groups` fixes open get upper bound 0."""
    g = products.virtual
    groups = cut_groups(products, options)
    me = model_edges(products, groups, keep_node)
    reductions = group_reductions(products, options, groups, me, bool(entries))
    m = _Model()
    flow, cut, reach = _add_columns(m, products, groups, me, keep_node, reductions.fixed_open)
    conservation = _add_conservation(m, products, me, flow, keep_node)
    cut_stops_flow = _add_cut_stops_flow(m, me, flow, cut)
    path_cut = _add_path_cuts(m, g.initial, me, cut, reach)
    coupling = _add_coupling(m, me, flow, reach)
    feasibility = _add_feasibility(m, products, groups, cut, entries, options.flow_rows == "cut") if entries else []
    blocked_place, places, place_of_cut = (
        _add_blocked_places(m, products, groups, cut)
        if options.block_states
        else (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    )
    exclusions = _add_exclusions(m, groups, cut, options.exclusions)
    caps = _add_caps(m, products, groups, cut, options.caps) if options.caps else None
    return RoutingModel(
        model=m,
        edges=me,
        groups=groups,
        cols=Columns(flow, cut, reach, feasibility, blocked_place, places),
        rows=Rows(conservation, cut_stops_flow, path_cut, coupling, place_of_cut, exclusions),
        out_src=np.flatnonzero(me.eu == g.initial),
        reductions=reductions,
        flow_bound=model_flow_bound(products, options, me),
        caps=caps,
    )


@dataclass(frozen=True)
class CapRows:
    """The caps in the model: ``y_i`` per physical item (:class:`PhysicalItems`) with a cut
    binary, at least each of its groups' ``d`` (``y_i - d_g >= 0``), and per cap
    ``sum y_i <= cap`` over the items it counts. Over binary ``d`` the rows admit exactly the
    cut sets within the caps (``y_i = max d_g`` meets them when the cut set does, and every
    solution has ``y_i >= max d_g``). ``y`` is continuous on HiGHS (its least value is
    integral) and integral on CP-SAT (every column is)."""

    items: PhysicalItems
    item_col: np.ndarray  # per item, its y column (-1: no group of it has a binary)
    cap_rows: dict[str, np.ndarray]


def _add_caps(m: _Model, products: Products, groups: CutGroups, cut: np.ndarray, caps: dict[str, int]) -> CapRows:
    """The rows of :class:`CapRows`."""
    items = physical_items(products, groups)
    var = np.flatnonzero(cut >= 0)
    of = items.of_group[var]
    used = np.unique(of)
    item_col = np.full(items.is_wall.size, -1, dtype=np.int64)
    item_col[used] = m.add_cols(used.size, 0.0, 1.0)
    r = m.add_rows(0.0, np.inf, var.size)
    m.add_terms(r, item_col[of], 1.0)
    m.add_terms(r, cut[var], -1.0)
    cap_rows: dict[str, np.ndarray] = {}
    for key, limit in caps.items():
        counted = used[items.kinds(key)[used]]
        row = m.add_rows(-np.inf, float(limit), 1)
        m.add_terms(np.repeat(row, counted.size), item_col[counted], 1.0)
        cap_rows[key] = row
    return CapRows(items, item_col, cap_rows)


def model_flow_bound(products: Products, options: MilpOptions, me: ModelEdges) -> int | None:
    """MILP-static: :func:`~synthesis.routing.bounds.flow_bound.static_flow_bound` where it is below
    the maximum flow with every group open (the heuristic's bound), else ``None``; ``None``
    in the other modes too, where cuts depend on the history and the bound's proof does not
    hold (and with ``options.flow_bound`` off). So a model whose bound does not improve is
    the model it was without this bound."""
    if options.mode != "static" or not options.flow_bound:
        return None
    g = products.virtual
    known = open_flow_bound(g.n_nodes, g.initial, me.eu, me.ev, me.c5, products.target)
    bound = static_flow_bound(products, me.eu, me.ev, known)
    return bound if bound < known else None


def model_cut_bound(products: Products, options: MilpOptions, groups: CutGroups, me: ModelEdges, level: int) -> CutBound | None:
    """MILP-static: :func:`~synthesis.routing.bounds.cut_bound.static_cut_bound` of this model's cut
    groups at flow ``level``; ``None`` in the other modes (cuts depend on the history), for
    MILP-agent's places objective (the bound counts cuts only), with ``options.cut_bound`` off,
    or where the bound does not apply."""
    if options.mode != "static" or not options.cut_bound or options.block_states:
        return None
    return static_cut_bound(products, groups.of_edge, groups.weight, groups.restrictable, me.eu, me.ev, level)


def group_reductions(products: Products, options: MilpOptions, groups: CutGroups, me: ModelEdges, with_feasibility: bool) -> Reductions:
    """The reductions of this model's cut groups (none with ``options.reductions`` off);
    the dominance rule only where its proof holds: MILP-static without feasibility flows,
    ``closed_loop``, MILP-agent places or exclusions."""
    if not options.reductions:
        return Reductions.none(groups.keys.size)
    dominance = (
        options.mode == "static"
        and not options.caps
        and not with_feasibility
        and not options.closed_loop
        and not options.block_states
        and not options.exclusions
    )
    return reduce_groups(products, me.eu, me.ev, me.grp, me.c5, me.has_var, groups.weight, dominance)


def _add_columns(
    m: _Model, products: Products, groups: CutGroups, me: ModelEdges, keep_node: np.ndarray, fixed_open: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c1) the flow ``f_e`` per model edge, the cut binaries ``d`` per group (upper bound 0
    where ``fixed_open``), and ``mu_v``."""
    g = products.virtual
    flow = m.add_cols(me.edges.size, 0.0, 1.0)
    cut = np.full(groups.keys.size, -1, dtype=np.int64)
    var_groups = np.flatnonzero(me.has_var)
    cut[var_groups] = m.add_cols(var_groups.size, 0.0, np.where(fixed_open[var_groups], 0.0, 1.0), integer=True)
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
            "the test objective cannot be routed: an unrestrictable move leads from the start straight to the goal",
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


INTEGRAL_PHASE2_MIN_ROWS = 200
"""Models with fewer rows keep continuous ``mu`` and ``f`` in phase 2 (:func:`phase2_integral_columns`):
HiGHS answers them in hundredths of a second either way, and the small built-ins
(small-reactive, beaver-rescue: 84-153 rows) keep their shipped answers. ``auto`` sends
reactive models of 200-2,500 rows to CP-SAT, whose columns are all integral anyway."""


def phase2_integral_columns(rm: RoutingModel, options: MilpOptions) -> np.ndarray:
    """The columns HiGHS's phase 2 declares integral (:attr:`MilpOptions.integral_phase2`):
    the reachability ``mu`` and the flows ``f`` of MILP-reactive with the option on and at
    least :data:`INTEGRAL_PHASE2_MIN_ROWS` rows, else none.

    Why the optimum is kept. Take any solution ``(f, d, mu, x)`` of phase 2's model (the
    model, and the row ``sum_{Src} f >= F - 1/2`` fixing the flow level) with ``d`` binary
    (``x``: the feasibility flows, untouched). It gives one with ``mu`` and ``f`` integral
    and the same objective (phase 2's cost holds ``d`` and MILP-agent's place binaries only):

    1. ``mu`` binary. Only the c4-c5 rows (``d_uv - mu_u + mu_v >= [u = Src]``, ``mu`` of
       ``Tgt`` taken as 0) and the coupling rows (``f_uv <= mu_u``, ``f_uv <= mu_v``) hold
       ``mu``. Let ``mu'_v = 1`` where ``mu_v > 0``, else 0 (a level set of the potentials).
       c4-c5 with ``d_uv = 1``: ``1 - mu'_u + mu'_v >= 0`` always, ``>= 1`` when ``u = Src``.
       With ``d_uv = 0`` the row gives ``mu_v >= mu_u`` (``mu_v >= 1`` when ``u = Src``), so
       ``mu_u > 0`` implies ``mu_v > 0``: ``mu'_v >= mu'_u`` (``mu'_v = 1`` when ``u = Src``);
       when ``v`` is in ``Tgt`` the row gives ``mu_u <= 0``, so ``mu'_u = 0``. Coupling:
       ``0 < f_uv <= mu_u`` implies ``mu'_u = 1 >= f_uv``, the same for ``v``. So
       ``(f, d, mu', x)`` is a solution.
    2. ``f`` integral. With ``d`` and ``mu'`` fixed, the rows on ``f`` are conservation
       outside ``Src`` and ``Tgt`` and the upper bounds ``f_e <= 1``, ``f_e <= 1 - d_e`` (c3),
       ``f_e <= mu'`` of its ends (coupling): a flow network with integral capacities. ``f``
       is a flow in it of value at least ``F - 1/2``, so its maximum flow, an integer, is at
       least ``F``, and some maximum flow ``f'`` is integral (max-flow integrality). No other
       row holds ``f`` in MILP-reactive (the walls' flow bound row is MILP-static's), so
       ``(f', d, mu', x)`` is a solution.

    So every cut set phase 2 admits is admitted with ``mu`` and ``f`` integral, at the same
    cost. (:mod:`synthesis.routing.backends.cpsat` rests on the same facts, with every column
    integral.) Checked on the generators' models (``tests/synthesis/test_integral_phase2.py``: each
    step on solutions with fractional ``mu`` and ``f``) and by the exhaustive comparisons of
    ``tests/synthesis/test_optimality.py`` run with these columns integral.
    """
    if not options.integral_phase2 or options.mode != "reactive" or rm.model.n_row < INTEGRAL_PHASE2_MIN_ROWS:
        return np.zeros(0, dtype=np.int64)
    reach = rm.cols.reach
    out: np.ndarray = np.concatenate([reach[reach >= 0], rm.cols.flow])
    return out


def _add_blocked_places(m: _Model, products: Products, groups: CutGroups, cut: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MILP-agent (docs/method.md §7): a binary ``d_state`` per place entered by a cut, at least
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


def _add_exclusions(m: _Model, groups: CutGroups, cut: np.ndarray, exclusions: list[Exclusion]) -> list[np.ndarray]:
    """One row ``sum_{cut} d - sum_{open} d <= |cut| - 1`` per :class:`Exclusion`."""
    rows = []
    for excluded in exclusions:
        cut_cols = _cut_columns(groups, cut, excluded.cut)
        if cut_cols is None:
            # a group it needs cut cannot be cut in this model: nothing to exclude
            continue
        open_cols = _cut_columns(groups, cut, excluded.open, keep_missing=True)
        assert open_cols is not None
        r = m.add_rows(-np.inf, float(cut_cols.size - 1), 1)
        m.add_terms(np.repeat(r, cut_cols.size), cut_cols, 1.0)
        m.add_terms(np.repeat(r, open_cols.size), open_cols, -1.0)
        rows.append(r)
    return rows


def _cut_columns(groups: CutGroups, cut: np.ndarray, keys: tuple[int, ...], keep_missing: bool = False) -> np.ndarray | None:
    """The ``d`` columns of the groups with these keys; ``None`` if one has none (a group
    that cannot be cut), unless ``keep_missing``, which skips such groups (never cut)."""
    want = np.asarray(keys, dtype=np.int64)
    pos = np.searchsorted(groups.keys, want)
    ok = (pos < groups.keys.size) & (groups.keys[np.minimum(pos, groups.keys.size - 1)] == want)
    cols = np.where(ok, cut[np.minimum(pos, groups.keys.size - 1)], -1)
    if not keep_missing and np.any(cols < 0):
        return None
    out: np.ndarray = cols[cols >= 0]
    return out


def _add_feasibility(
    m: _Model,
    products: Products,
    groups: CutGroups,
    cut: np.ndarray,
    entries: dict[int, np.ndarray],
    per_cut: bool = False,
) -> list[FeasibilityFlow]:
    """Add c6-c8 as one aggregated flow per history; returns where each flow lives.

    A flow edge over move ``t`` under history ``q`` is closed by the cut of the G edge
    of ``Gr(q)`` over ``t`` (docs/method.md c7); where G has no such edge nothing closes it.
    One cut column ``d`` closes every flow edge over its move, one per copy of the move in
    ``G_sys`` (the system automaton's states).

    ``per_cut`` writes c7 as one row per closing column ``d`` of the flow,
    ``sum_{e closed by d} x_e + K n_d d <= K n_d`` (``n_d`` flow edges, capacity ``K``),
    instead of one row ``x_e + K d <= K`` per flow edge. Why the answers are the same: the
    rows differ only at fractional ``d``. With ``d = 1`` both force every ``x_e`` closed by
    ``d`` to 0 (the per-cut row reads ``sum x_e <= 0`` with ``x_e >= 0``); with ``d = 0``
    both are implied by the column bounds ``x_e <= K`` (the per-cut row by their sum).
    Every solution with binary cuts satisfies one set of rows iff it satisfies the other,
    and no other row differs, so the two models admit the same solutions with binary cuts
    (the only ones the MILP returns) and have the same optimum. The LP relaxation is weaker
    (a fractional ``d`` leaves room for ``K n_d (1 - d)`` over all its edges together), but
    phase 2's LP bound on the large reactive models is the same with the feasibility flows
    or without any, and a model with ``n_d`` times fewer closing rows runs more
    branch-and-bound nodes per second (docs/benchmarks/solvers.md, "MILP-reactive's phase 2"). Checked by ``tests/synthesis/test_flow_rows.py``.
    """
    g, gs = products.virtual, products.system
    ts = products.ts
    co = products.system_coreachable
    sys_tgt = products.system_target
    # the edge of G in Gr(q) over move t, for every (q, t) that has one
    gkey = g.hist.astype(np.int64)[g.src] * ts.n_moves + g.move
    gorder = np.argsort(gkey)
    gkey_sorted = gkey[gorder]
    flows: list[FeasibilityFlow] = []
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
        if per_cut:
            closing, of_edge, copies = np.unique(dcol[sel], return_inverse=True, return_counts=True)
            big = cap * copies.astype(float)
            r = m.add_rows(-np.inf, big, closing.size)
            m.add_terms(r[of_edge.ravel()], cols[sel], 1.0)
            m.add_terms(r, closing, big)
        else:
            r = m.add_rows(-np.inf, cap, sel.size)
            m.add_terms(r, cols[sel], 1.0)
            m.add_terms(r, dcol[sel], cap)
        flows.append(FeasibilityFlow(cols=cols, src=s, dst=d, dcol=dcol, supply_nodes=supply_nodes))
    return flows


@dataclass
class FeasibilityFlow:
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
