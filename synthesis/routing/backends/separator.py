"""The separator of the implicit hitting set (:mod:`synthesis.routing.backends.hitting_set`): which
checks a cut set fails, and the valid row over the cut binaries each failure gives.

A cut set is a ``bool`` per cut group (:class:`~synthesis.routing.groups.CutGroups`); the
master's columns are the groups with a binary, then (MILP-agent) one ``d_state`` per place
a cut may enter. The checks, all graph searches in bulk (SciPy's ``csgraph``):

* bypass (c4-c5): cheapest open ``Src -> Tgt`` paths over the c5 edges, each group with a
  binary costing 1, the groups of a found path closed before the next search (so the
  rows of one round have disjoint supports);
* flow: a maximum flow over the open model edges and, below the level, a minimal part ``K``
  of the cut groups that keeps the flow below it, and the minimum cuts under ``K`` alone on
  the source side (a :class:`FlowCut`, kept to be re-instantiated at other levels) and on
  the sink side (see :meth:`CoverSeparator._flow_cuts`);
* traps (c6-c8): :func:`synthesis.routing.traps.trapped_entries` on the restrictions of
  the cut set (plus :func:`~synthesis.routing.traps.trapped_configurations` with
  ``closed_loop``), and per trapped node the set it still reaches;
* caps: the physical restrictions a cut set uses against ``options.caps``
  (:meth:`CoverSeparator._cap_rows`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, dijkstra, maximum_flow

from ...graphs.cuts import sink_side, source_side
from ...graphs.products import Products
from ..edges import ModelEdges
from ..groups import CutGroups, PhysicalItems, physical_items, static_moves_of
from ..options import MilpOptions
from ..result import blocked_of_edges
from ..traps import trapped_configurations, trapped_entries

#: Group-disjoint bypass paths separated per round.
PATHS_PER_ROUND = 16

#: Trapped nodes per history turned into rows per round.
TRAPS_PER_HISTORY = 8


@dataclass(frozen=True)
class Row:
    """``lo <= sum vals * x[cols] <= hi`` over the master's columns."""

    cols: np.ndarray
    vals: np.ndarray
    lo: float
    hi: float


def _at_least_one_cut(cols: np.ndarray) -> Row:
    """``sum d >= 1`` over distinct columns."""
    cols = np.unique(cols)
    return Row(cols, np.ones(cols.size), 1.0, np.inf)


def _not_all_cut(cols: np.ndarray) -> Row:
    """``sum d <= |cols| - 1`` over distinct columns."""
    cols = np.unique(cols)
    return Row(cols, np.ones(cols.size), -np.inf, float(cols.size - 1))


@dataclass(frozen=True)
class FlowCut:
    """A set ``K`` of model edges that every unit of flow crosses (an ``Src``-``Tgt`` cut):
    ``count[i]`` of its edges lie in the group of master column ``cols[i]``, ``fixed`` have
    no binary (never cut)."""

    cols: np.ndarray
    count: np.ndarray
    fixed: int

    def row(self, flow: int) -> Row:
        """``sum_g min(n_g, F) (1 - d_g) + fixed >= F``, valid for every cut set whose
        flow is at least ``F``."""
        c = np.minimum(self.count, flow).astype(float)
        return Row(self.cols, c, -np.inf, float(c.sum() + self.fixed - flow))


class CoverSeparator:
    """The checks of a cut set and the rows its failures give (see the module docstring)."""

    def __init__(
        self,
        products: Products,
        options: MilpOptions,
        groups: CutGroups,
        me: ModelEdges,
        required: dict[int, np.ndarray],
    ) -> None:
        self.products, self.options, self.groups, self.me = products, options, groups, me
        self.required = required
        g, ts = products.virtual, products.ts
        self.var = np.flatnonzero(me.has_var)
        self.col_of = np.full(groups.keys.size, -1, dtype=np.int64)
        self.col_of[self.var] = np.arange(self.var.size)
        nv = self.var.size
        # MILP-agent: d_state per place entered by a group with a binary
        if options.block_states:
            e_all = np.flatnonzero(self.col_of[groups.of_edge] >= 0)
            pl = ts.place[ts.dst[g.move[e_all]]].astype(np.int64)
            pairs = np.unique(np.stack([pl, groups.of_edge[e_all]], axis=1), axis=0)
            self.places = np.unique(pairs[:, 0])
            self.place_pairs = pairs
        else:
            self.places = np.zeros(0, dtype=np.int64)
            self.place_pairs = np.zeros((0, 2), dtype=np.int64)
        self.n_col = nv + self.places.size
        weight = groups.weight[self.var].astype(float)
        self.place_cost = float(weight.sum() + 1)
        self.cost = np.concatenate([weight, np.full(self.places.size, self.place_cost)])
        self.n = g.n_nodes
        self.src = int(g.initial)
        self.target = products.target
        # model edges (flow) and their columns
        self.mcol = self.col_of[me.grp]
        c5 = np.flatnonzero(me.c5)
        self.c5u, self.c5v, self.c5col = me.eu[c5], me.ev[c5], self.mcol[c5]
        # c5 edges into Tgt cannot carry flow in a valid answer; nothing else needs them here
        self.static_moves = static_moves_of(products, options)
        self._closing = _ClosingGroups(products, groups, self.static_moves)
        self._items: PhysicalItems | None = None  # the caps' physical items, once needed

    # ------------------------------------------------------------------ cut sets

    def cut_of_point(self, x: np.ndarray) -> np.ndarray:
        """``bool`` per group: the master's binaries at ``x``."""
        cut = np.zeros(self.groups.keys.size, dtype=bool)
        cut[self.var] = x[: self.var.size] > 0.5
        return cut

    def blocked_places(self, cut: np.ndarray) -> np.ndarray:
        """The places a cut set enters (MILP-agent's ``d_state = 1``)."""
        if self.places.size == 0:
            return np.zeros(0, dtype=np.int64)
        hit = cut[self.place_pairs[:, 1]]
        return np.unique(self.place_pairs[hit, 0])

    def cost_of(self, cut: np.ndarray) -> float:
        """The master objective of a cut set."""
        return float(self.groups.weight[cut].sum() + self.place_cost * self.blocked_places(cut).size)

    # ------------------------------------------------------------------ separation

    def separate(self, cut: np.ndarray, flow: int, paths: int = PATHS_PER_ROUND) -> tuple[list[tuple[str, Row]], list[FlowCut]]:
        """What a cut set violates at flow level ``flow``: the ``(kind, row)`` pairs of
        bypass cover (at most ``paths``) and traps, and the minimum cuts of a too small flow
        (source side and sink side; none when the flow is at least ``flow``)."""
        rows: list[tuple[str, Row]] = [("cover", _at_least_one_cut(c)) for c in self._bypass_paths(cut, paths)]
        rows += [("trap", r) for r in self._trap_rows(cut)]
        rows += [("cap", r) for r in self._cap_rows(cut)]
        return rows, self._flow_cuts(cut, flow)

    def _cap_rows(self, cut: np.ndarray) -> list[Row]:
        """(e) caps (:attr:`MilpOptions.caps`): a cut set that uses ``k`` items a cap of ``N``
        counts (``k > N``) gives ``sum d_g <= N`` over one cut group with a column per item.
        Valid: the groups stand for ``k`` distinct items, so a cut set within the cap cuts at
        most ``N`` of them; and the cut set violates it."""
        if not self.options.caps:
            return []
        if self._items is None:
            self._items = physical_items(self.products, self.groups)
        items = self._items
        rows = []
        for cap, used in items.over_cap(cut, self.options.caps):
            groups = np.flatnonzero(cut & (self.col_of >= 0))
            of = items.of_group[groups]
            keep = np.isin(of, used)
            _, first = np.unique(of[keep], return_index=True)
            cols = self.col_of[groups[keep][first]]
            rows.append(Row(cols, np.ones(cols.size), -np.inf, float(self.options.caps[cap])))
        return rows

    def checks_pass(self, cut: np.ndarray, flow: int) -> bool:
        """Whether a cut set passes every check at flow level ``flow``."""
        rows, cuts = self.separate(cut, flow)
        return not rows and not cuts

    def _bypass_paths(self, cut: np.ndarray, limit: int) -> list[np.ndarray]:
        """Up to ``limit`` open bypass paths, as the master columns on each: group-disjoint
        ones first, then detours around each group of the first path."""
        col = self.c5col
        is_cut = np.zeros(self.n_col + 1, dtype=bool)
        is_cut[: self.var.size] = cut[self.var]
        open_ = (col < 0) | ~is_cut[np.maximum(col, 0)]
        out: list[np.ndarray] = []
        seen: set[tuple[int, ...]] = set()
        first = self._cheapest_path(open_)
        if first is None:
            return out
        out.append(first)
        seen.add(tuple(first.tolist()))
        if first.size == 0:
            return out
        rest = open_.copy()
        while len(out) < limit:  # group-disjoint paths
            on = np.zeros(self.n_col + 1, dtype=bool)
            on[np.concatenate(out)] = True
            rest = open_ & ~((col >= 0) & on[np.maximum(col, 0)])
            p = self._cheapest_path(rest)
            if p is None or p.size == 0:
                break
            out.append(p)
            seen.add(tuple(p.tolist()))
        for c in first.tolist():  # detours around each group of the first path
            if len(out) >= limit:
                break
            p = self._cheapest_path(open_ & (col != c))
            if p is not None and p.size and tuple(p.tolist()) not in seen:
                seen.add(tuple(p.tolist()))
                out.append(p)
        return out

    def _cheapest_path(self, open_: np.ndarray) -> np.ndarray | None:
        """The master columns on a cheapest ``Src -> Tgt`` path over the open c5 edges
        (each edge with a binary costs 1, others almost nothing), or ``None``."""
        col = self.c5col
        e = np.flatnonzero(open_)
        if e.size == 0:
            return None
        eps = 1.0 / (self.c5u.size + 2)
        weight = np.where(col[e] >= 0, 1.0, eps)
        graph = sp.csr_matrix((weight, (self.c5u[e], self.c5v[e])), shape=(self.n, self.n))
        dist, pred = dijkstra(graph, indices=self.src, return_predecessors=True)
        tnodes = np.flatnonzero(self.target)
        reach_t = tnodes[np.isfinite(dist[tnodes])]
        if reach_t.size == 0:
            return None
        t = int(reach_t[np.argmin(dist[reach_t])])
        nodes = [t]
        while nodes[-1] != self.src:
            nodes.append(int(pred[nodes[-1]]))
        nodes.reverse()
        return self._path_cols(np.array(nodes[:-1]), np.array(nodes[1:]), e)

    def _path_cols(self, u: np.ndarray, v: np.ndarray, e: np.ndarray) -> np.ndarray:
        """The master columns of the open c5 edges ``u -> v`` (cheapest one per pair)."""
        key = self.c5u[e].astype(np.int64) * self.n + self.c5v[e]
        # prefer an edge without a binary, then the lowest index, among parallel edges
        order = np.lexsort((e, self.c5col[e] >= 0, key))
        ks = key[order]
        pos = np.searchsorted(ks, u.astype(np.int64) * self.n + v)
        cols = self.c5col[e[order[pos]]]
        out: np.ndarray = np.unique(cols[cols >= 0])
        return out

    def _max_flow(self, cut: np.ndarray) -> tuple[int, sp.csr_matrix, sp.csr_matrix]:
        """Max flow over the open model edges; (value, capacities, flows) with a super sink."""
        is_cut = np.zeros(self.n_col + 1, dtype=bool)
        is_cut[: self.var.size] = cut[self.var]
        col = self.mcol
        ok = np.flatnonzero((col < 0) | ~is_cut[np.maximum(col, 0)])
        eu, ev = self.me.eu[ok], self.me.ev[ok]
        t = np.flatnonzero(self.target)
        n = self.n
        big = max(int(ok.size), 1)
        rows = np.concatenate([eu, t])
        cols = np.concatenate([ev, np.full(t.size, n)])
        caps = np.concatenate([np.ones(eu.size, dtype=np.int32), np.full(t.size, big, dtype=np.int32)])
        cap = sp.csr_matrix((caps, (rows, cols)), shape=(n + 1, n + 1))
        cap.sum_duplicates()
        res = maximum_flow(cap, self.src, n)
        return int(res.flow_value), cap, res.flow

    def _reaches(self, cut: np.ndarray, flow: int) -> bool:
        """Whether the maximum flow over the open model edges under ``cut`` is at least
        ``flow`` (for ``flow == 1`` a reachability search, else a maximum flow)."""
        if flow > 1:
            return self._max_flow(cut)[0] >= flow
        is_cut = np.zeros(self.n_col + 1, dtype=bool)
        is_cut[: self.var.size] = cut[self.var]
        col = self.mcol
        ok = np.flatnonzero((col < 0) | ~is_cut[np.maximum(col, 0)])
        graph = sp.csr_matrix((np.ones(ok.size, dtype=np.int8), (self.me.eu[ok], self.me.ev[ok])), shape=(self.n, self.n))
        seen = breadth_first_order(graph, self.src, directed=True, return_predecessors=False)
        return bool(np.any(self.target[seen]))

    def _flow_cuts(self, cut: np.ndarray, flow: int) -> list[FlowCut]:
        """When the maximum flow over the open model edges under ``cut`` is below ``flow``:
        the minimum cuts next to ``Src`` and next to ``Tgt`` under a *minimal* part ``K`` of
        the cut groups that still keeps the flow below ``flow`` (one cut when they coincide);
        else none.

        ``K`` starts as the cut groups with an edge leaving the source side ``S`` of a
        minimum cut under ``cut`` (closing only these keeps every edge out of ``S`` that
        ``cut`` closes closed, so the flow stays below ``flow``), and drops each group,
        in column order, whose reopening leaves the flow below ``flow``. The rows of
        the minimum cuts under ``K`` alone are violated by ``cut`` (``cut`` contains
        ``K``, so it closes at least what ``K`` closes) and, as every (b) row, valid for
        every cut set of flow at least ``flow``; for ``flow == 1`` such a row is the
        no-good "open one of ``K``" (every group of a minimal ``K`` has an edge out of
        ``S``), which implies the row of the whole boundary of ``S``."""
        value, cap, f = self._max_flow(cut)
        if value >= flow:
            return []
        near_src = self._source_side(cap, f)
        k = np.flatnonzero(near_src[self.me.eu] & ~near_src[self.me.ev])
        col = self.mcol[k]
        boundary = np.unique(col[col >= 0])
        keep = np.zeros(self.groups.keys.size, dtype=bool)
        keep[self.var[boundary[cut[self.var[boundary]]]]] = True
        for g in np.flatnonzero(keep).tolist():
            keep[g] = False
            if self._reaches(keep, flow):
                keep[g] = True
        return self._side_cuts(keep, flow)

    def _source_side(self, cap: sp.csr_matrix, f: sp.csr_matrix) -> np.ndarray:
        """``bool`` per node of G: the residual graph's nodes reachable from ``Src``."""
        out: np.ndarray = source_side(cap, f, self.src)[: self.n]
        return out

    def _side_cuts(self, cut: np.ndarray, flow: int) -> list[FlowCut]:
        """The minimum cuts next to ``Src`` and next to ``Tgt`` under ``cut`` (whose flow is
        below ``flow``)."""
        value, cap, f = self._max_flow(cut)
        if value >= flow:
            raise RuntimeError("a minimal flow-cutting group set lets the flow through: a FlowTest bug")
        near_src = self._source_side(cap, f)
        to_sink = sink_side(cap, f, self.n)
        out = [self._cut_of_side(near_src)]
        far = ~to_sink[: self.n]
        if not np.array_equal(far, near_src):
            out.append(self._cut_of_side(far))
        return out

    def _cut_of_side(self, side: np.ndarray) -> FlowCut:
        """The model edges from ``side`` out of it, by master column."""
        k = np.flatnonzero(side[self.me.eu] & ~side[self.me.ev])
        col = self.mcol[k]
        fixed = int(np.count_nonzero(col < 0))
        cols, count = np.unique(col[col >= 0], return_counts=True)
        return FlowCut(cols.astype(np.int64), count.astype(np.int64), fixed)

    def blocked(self, cut: np.ndarray) -> np.ndarray:
        """``bool[n_hist, n_moves]``: the moves a cut set restricts under each history
        (as :func:`synthesis.routing.result.blocked_by` reads an answer)."""
        groups = self.groups
        blocked = blocked_of_edges(self.products, np.flatnonzero(cut[groups.of_edge]))
        static_cut = np.isin(groups.move_key, groups.keys[cut & groups.static]) & self.static_moves
        out: np.ndarray = blocked | static_cut[None, :]
        return out

    def _trap_rows(self, cut: np.ndarray) -> list[Row]:
        if not self.required and not self.options.closed_loop:
            return []
        products = self.products
        blocked = self.blocked(cut)
        trapped = trapped_entries(products, blocked, self.required) if self.required else {}
        if self.options.closed_loop:
            traps = trapped_configurations(products, blocked)
            hist = products.virtual.hist[traps]
            for q in np.unique(hist):
                nodes = products.projection[traps[hist == q]]
                trapped[int(q)] = np.union1d(trapped.get(int(q), np.zeros(0, dtype=np.int64)), nodes)
        gs = products.system
        rows: list[Row] = []
        seen: set[tuple[int, ...]] = set()
        for q, nodes in trapped.items():
            open_edge = ~blocked[q, gs.move]
            e = np.flatnonzero(open_edge)
            graph = sp.csr_matrix((np.ones(e.size, dtype=np.int8), (gs.src[e], gs.dst[e])), shape=(gs.n_nodes, gs.n_nodes))
            covered = np.zeros(gs.n_nodes, dtype=bool)
            done = 0
            for v in nodes.tolist():
                if covered[v] or done >= TRAPS_PER_HISTORY:
                    continue
                done += 1
                inside = np.zeros(gs.n_nodes, dtype=bool)
                inside[breadth_first_order(graph, v, directed=True, return_predecessors=False)] = True
                covered |= inside
                leave = np.flatnonzero(inside[gs.src] & ~inside[gs.dst])
                grp = self._closing.of(q, gs.move[leave])
                if np.any(grp < 0):
                    continue  # an edge nothing closes leaves R: cannot happen for a trapped node
                cols = self.col_of[grp]
                if np.any(cols < 0):
                    continue
                ucols = np.unique(cols)
                if tuple(ucols.tolist()) in seen:
                    continue
                seen.add(tuple(ucols.tolist()))
                rows.append(_not_all_cut(ucols))
        return rows


class _ClosingGroups:
    """The cut group that closes a move of T under a history (``-1``: none), as
    :meth:`CoverSeparator.blocked` applies restrictions: a static move's tied group,
    else the group of G's edge of ``Gr(q)`` over the move."""

    def __init__(self, products: Products, groups: CutGroups, static_moves: np.ndarray) -> None:
        g, ts = products.virtual, products.ts
        self.n_moves = ts.n_moves
        gkey = g.hist.astype(np.int64)[g.src] * ts.n_moves + g.move
        self.order = np.argsort(gkey, kind="stable")
        self.sorted = gkey[self.order]
        self.of_edge = groups.of_edge
        pos = np.minimum(np.searchsorted(groups.keys, groups.move_key), groups.keys.size - 1)
        found = groups.keys[pos] == groups.move_key
        self.static_group = np.where(static_moves & found, pos, -1)
        self.static_moves = static_moves

    def of(self, q: int, moves: np.ndarray) -> np.ndarray:
        """The closing group of each move under history ``q``."""
        out: np.ndarray = self.static_group[moves].astype(np.int64)
        reactive = ~self.static_moves[moves]
        if np.any(reactive) and self.sorted.size:
            want = np.int64(q) * self.n_moves + moves[reactive]
            pos = np.minimum(np.searchsorted(self.sorted, want), self.sorted.size - 1)
            hit = self.sorted[pos] == want
            grp = np.where(hit, self.of_edge[self.order[pos]], -1)
            out[reactive] = grp
        return out
