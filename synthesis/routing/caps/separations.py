"""A lower bound on the walls (doors) a test needs, one history at a time: what the test must
close under a history the SUT is certain to pass through, while leaving it a way to its goal.

The bypass counts of :mod:`synthesis.routing.caps.bypasses` know nothing of the feasibility flows
(docs/method.md c6-c8): on a reactive floor they see that closing the two moves into the goal
under every history before I closes every bypass, and prove 2 doors, where that test traps
the SUT (under the start's history it has no way left to the goal). This bound uses them (and,
for walls, the route itself, which leaves every history it passes a way to the goal).

**Lemma.** Let ``X`` be a test, ``q`` a history outside I and ``e`` an entry node of ``q``
(the initial node, or the head of an edge of G that changes the history) that the SUT reaches
under ``X``. Then ``X`` (its walls, and its doors under ``q``) must

* (a) close every walk of G from ``e`` to ``Tgt`` whose nodes all have the history ``q``
  (outside I): with the walk that reaches ``e`` it is a bypass (c4-c5);
* (b) leave a way from ``e``'s place to the goal in ``G_sys`` over the moves not restricted
  under ``q``: c6-c8 of a reactive or mixed test (every kept entry: the route's entries reach
  ``Tgt``, so their places reach the goal); for a static test, where ``e`` is the route's
  entry into ``q``, the route's own rest (walls close a move under every history, and the
  route from ``e`` to ``Tgt`` crosses none, so its projection is such a way).

So ``X`` uses at least ``sep(q, e)`` items, the fewest of any restriction of the moves of the
history ``q`` with (a) and (b), and ``sep`` is computed from below by branching on where the way
of (b) crosses a minimum cut of (a) (:func:`separation_exceeds`): a minimum cut of the walks of
(a), over the arcs of the history ``q`` with their items priced so that no cut pays more
than one for an item, either leaves a way (b) open (then nothing more is proven here) or every
way of (b) crosses one of its moves, which the test then leaves open: the children spare each
such move (made disjoint as usual: the ``i``-th child's way avoids the first ``i - 1``).

**Which histories.** The SUT reaches the initial node. Its route through the test objective
(flow >= 1) passes a sequence of histories from the initial one to I, and reaches each one at an
entry node of it. So where ``sep(q, e) > N`` for every entry ``e`` of every history ``q`` of a
set ``B`` that every such sequence passes (removing ``B`` from the histories' graph cuts the
initial history off from I), or for the initial node, no test fits a cap of ``N``.

Not modelled (the function proves nothing there): closed-loop traps and the test agent's
places.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...graphs.consistency import check_consistency
from ...graphs.cuts import min_cut
from ...graphs.products import Products, reachable
from ..edges import model_edges
from ..groups import cut_groups, physical_items
from ..options import MilpOptions

SEPARATION_CUTS = 6000
"""The most minimum cuts one :func:`separations_exceed` makes in all: a deterministic budget,
so the same problem gets the same answer on every machine (the 30x30 rack floor's proof that
4 doors are too few takes about 5,000, 9 s here)."""

_INF = 1 << 26  # capacity of an arc no cut may close
_MAX_SCALE = 720  # prices are shares 1/k of an item, scaled by lcm(k) up to this


@dataclass(frozen=True)
class _Layer:
    """The arcs of one history ``q`` (both ends of history ``q`` outside I, or the head in
    ``Tgt``) as a flow network over its own node numbers (``local``: per node of G, its number,
    -1 outside the layer), and per arc its move, whether a cut may close it and its integer
    price (``scale`` per item)."""

    local: np.ndarray
    network: _Network
    move: np.ndarray
    cuttable: np.ndarray
    price: np.ndarray
    scale: int


def _layer_prices(eu: np.ndarray, ev: np.ndarray, item: np.ndarray, counted: np.ndarray) -> tuple[np.ndarray, int]:
    """Integer prices of a layer's arcs and their scale: an item with ``m`` arcs here, ``p`` of
    them pairs of opposite arcs between the same two nodes (never both leaving one side of a
    cut), has at most ``m - p`` arcs in any cut: each costs ``scale / (m - p)``."""
    if eu.size == 0:
        return np.zeros(0, dtype=np.int64), 1
    m = np.bincount(item, minlength=int(item.max()) + 1)
    span = np.int64(int(max(eu.max(), ev.max())) + 1)
    lo, hi = np.minimum(eu, ev).astype(np.int64), np.maximum(eu, ev).astype(np.int64)
    pair = (item.astype(np.int64) * span + lo) * span + hi  # an item's arcs between two nodes
    forward = np.unique(pair[eu < ev], return_counts=True)
    backward = np.unique(pair[eu > ev], return_counts=True)
    both, at_f, at_b = np.intersect1d(forward[0], backward[0], return_indices=True)
    pairs = np.zeros(m.size, dtype=np.int64)  # per item: opposite arcs matched one to one
    np.add.at(pairs, both // (span * span), np.minimum(forward[1][at_f], backward[1][at_b]))
    room = np.maximum(m - pairs, 1)
    scale = 1
    for k in np.unique(room[item[counted[item]]]).tolist():
        scale = min(_MAX_SCALE, math.lcm(scale, int(k)))
    price = np.where(counted[item], scale // room[item], 0).astype(np.int64)
    return price, scale


@dataclass(frozen=True)
class _Network:
    """A layer's flow network, built once: its arcs and one to a sink ``n`` from each end in
    ``Tgt``, as a CSR pattern (``slot``: each arc's entry, parallel arcs sharing one)."""

    n: int
    indptr: np.ndarray
    indices: np.ndarray
    slot: np.ndarray
    n_entries: int
    to_sink: np.ndarray

    @staticmethod
    def of(n: int, eu: np.ndarray, ev: np.ndarray, target: np.ndarray) -> _Network:
        t = np.flatnonzero(target)
        rows = np.concatenate([eu, t]).astype(np.int64)
        cols = np.concatenate([ev, np.full(t.size, n)]).astype(np.int64)
        key = rows * (n + 1) + cols
        uniq, slot = np.unique(key, return_inverse=True)
        indptr = np.searchsorted(uniq // (n + 1), np.arange(n + 2)).astype(np.int32)
        return _Network(n, indptr, (uniq % (n + 1)).astype(np.int32), slot.ravel(), int(uniq.size), slot.ravel()[eu.size :])

    def min_cut(self, src: int, cap: np.ndarray) -> tuple[int, np.ndarray]:
        """A minimum ``src -> Tgt`` cut under the arcs' capacities ``cap``: its value and, per
        arc, whether it crosses the cut (the source side: what ``src`` reaches in the
        residual graph)."""
        data = np.zeros(self.n_entries, dtype=np.int64)
        np.add.at(data, self.slot[: cap.size], cap)
        data[self.to_sink] = _INF
        mat = sp.csr_matrix((np.minimum(data, _INF).astype(np.int32), self.indices, self.indptr), shape=(self.n + 1, self.n + 1))
        value, side = min_cut(mat, src, self.n)
        rows = np.repeat(np.arange(self.n + 1), np.diff(self.indptr))
        crossing_entry = side[rows] & ~side[self.indices]
        crossing: np.ndarray = crossing_entry[self.slot[: cap.size]]
        return value, crossing


class _Budget:
    """The minimum cuts left and the deadline."""

    def __init__(self, cuts: int, deadline: float | None) -> None:
        self.cuts, self.deadline = cuts, deadline

    def spend(self) -> bool:
        """Take one minimum cut; ``False`` once none is left (or the deadline passed)."""
        if self.cuts <= 0 or (self.deadline is not None and time.perf_counter() >= self.deadline):
            return False
        self.cuts -= 1
        return True


def separation_exceeds(products: Products, layer: _Layer, entry: int, limit: int, budget: _Budget) -> bool | None:
    """Whether ``sep(q, entry) > limit`` (module docstring) for the history ``q`` of ``layer``:
    ``True`` proven, ``False`` a restriction within ``limit`` meets (a) and (b) (of the
    relaxation, where prices are shares), ``None`` out of budget."""
    gs = products.system
    start_sys = np.zeros(gs.n_nodes, dtype=bool)
    start_sys[int(products.projection[entry])] = True
    bound = limit * layer.scale  # a cut priced above it uses more than limit items
    stack: list[tuple[frozenset[int], frozenset[int]]] = [(frozenset(), frozenset())]
    while stack:
        spared_moves, banned_moves = stack.pop()
        spared = np.isin(layer.move, list(spared_moves)) if spared_moves else np.zeros(layer.move.size, dtype=bool)
        if not budget.spend():
            return None
        cap = np.where(layer.cuttable & ~spared, layer.price, _INF).astype(np.int64)
        value, crossing = layer.network.min_cut(int(layer.local[entry]), cap)
        if value > bound:
            continue
        closed = np.unique(layer.move[crossing & layer.cuttable & ~spared])
        # (b): a way in G_sys from the entry's place to the goal over moves not closed
        usable = ~np.isin(gs.move, list(banned_moves)) if banned_moves else np.ones(gs.move.size, dtype=bool)
        way_ok = usable & ~np.isin(gs.move, closed)  # this branch's way takes no banned move
        if reachable(gs.n_nodes, gs.src[way_ok], gs.dst[way_ok], start_sys)[products.system_target].any():
            return False
        # every way crosses a closed move: branch on which, each child's way avoiding the earlier ones
        reach = reachable(gs.n_nodes, gs.src[usable], gs.dst[usable], start_sys)
        back = reachable(gs.n_nodes, gs.dst[usable], gs.src[usable], products.system_target)
        on_way = usable & reach[gs.src] & back[gs.dst]
        candidates = np.intersect1d(closed, np.unique(gs.move[on_way]))
        branch = []
        banned_more = set(banned_moves)
        for m in candidates.tolist():
            branch.append((spared_moves | {m}, frozenset(banned_more)))
            banned_more.add(m)
        stack.extend(reversed(branch))
    return True


class HistorySeparations:
    """The lemma of the module docstring for one problem and cap, its graphs built once (every
    history's layer on first use) and asked for one limit after another
    (:meth:`exceed`), as :func:`~synthesis.routing.caps.refusal.check_caps_reachable` raises its bound."""

    def __init__(self, products: Products, options: MilpOptions, cap: str) -> None:
        self.products = products
        self.modelled = not (options.closed_loop or options.block_states)
        g = products.virtual
        groups = cut_groups(products, options)
        self.me = me = model_edges(products, groups, check_consistency(products))
        items = physical_items(products, groups)
        self._item, self._counted, self._has_var = items.of_group, items.kinds(cap), me.has_var
        c5 = np.flatnonzero(me.c5)
        self._eu, self._ev, self._grp, self._move = me.eu[c5], me.ev[c5], me.grp[c5], g.move[me.edges[c5]]
        self._layers: dict[int, _Layer] = {}
        # a route's entries lie on a walk Src -> I over the model's edges (the others never matter)
        inter = products.intermediate
        start = np.zeros(g.n_nodes, dtype=bool)
        start[int(g.initial)] = True
        outside = ~inter[me.eu]
        before = reachable(g.n_nodes, me.eu[outside], me.ev[outside], start) & reachable(g.n_nodes, me.ev, me.eu, inter)
        self._entries = {int(q): nodes[before[nodes] & ~inter[nodes] & ~products.target[nodes]] for q, nodes in g.entry_nodes.items()}

    def _layer(self, q: int) -> _Layer:
        if q not in self._layers:
            hist, target = self.products.virtual.hist, self.products.target
            eu, ev, grp = self._eu, self._ev, self._grp
            keep = (hist[eu] == q) & ((hist[ev] == q) | target[ev])
            price, scale = _layer_prices(eu[keep], ev[keep], self._item[grp[keep]], self._counted)
            ends = np.unique(np.concatenate([eu[keep], ev[keep], np.flatnonzero(hist == q)]))
            local = np.full(hist.size, -1, dtype=np.int64)
            local[ends] = np.arange(ends.size)
            network = _Network.of(int(ends.size), local[eu[keep]], local[ev[keep]], target[ends])
            self._layers[q] = _Layer(local, network, self._move[keep], self._has_var[grp[keep]], price, scale)
        return self._layers[q]

    def exceed(self, limit: int, cuts: int = SEPARATION_CUTS, deadline: float | None = None) -> bool:
        """Whether the lemma proves that no test uses at most ``limit`` of the items the cap
        counts (``False``: not proven within ``cuts`` minimum cuts and by ``deadline``, a
        ``perf_counter`` time)."""
        if not self.modelled:
            return False
        g, products = self.products.virtual, self.products
        budget = _Budget(cuts, deadline)
        src = int(g.initial)
        q0 = int(g.hist[src])
        first = separation_exceeds(products, self._layer(q0), src, limit, budget)
        if first is None:
            return False
        if first:
            return True
        # the histories' graph: a route passes from q0 to I; is every way through a history all of
        # whose entries are proven to need more than limit?
        blocked: set[int] = set()
        for q in sorted(self._entries):
            nodes = self._entries[q]
            if q == q0 or nodes.size == 0:
                continue
            proven = True
            for e in nodes.tolist():
                r = separation_exceeds(products, self._layer(q), int(e), limit, budget)
                if r is None:
                    return False
                if not r:
                    proven = False
                    break
            if proven:
                blocked.add(q)
            if _cut_off(self.me.eu, self.me.ev, g.hist, products.intermediate, q0, blocked):
                return True
        return False


def separations_exceed(
    products: Products,
    options: MilpOptions,
    cap: str,
    limit: int,
    cuts: int = SEPARATION_CUTS,
    deadline: float | None = None,
) -> bool:
    """Whether the lemma of the module docstring proves that no test uses at most ``limit`` of
    the items ``cap`` counts (``False``: not proven within ``cuts`` minimum cuts in all and by
    ``deadline``, a ``perf_counter`` time); :class:`HistorySeparations` for several limits.

    Example::

        separations_exceed(products, milp, "max_doors", 4)  # True on the 30x30 rack floor
    """
    return HistorySeparations(products, options, cap).exceed(limit, cuts, deadline)


def _cut_off(eu: np.ndarray, ev: np.ndarray, hist: np.ndarray, inter: np.ndarray, q0: int, blocked: set[int]) -> bool:
    """Whether every walk of G from the history ``q0`` into I passes a history of ``blocked``."""
    if not blocked:
        return False
    bad = np.isin(hist, list(blocked)) & ~inter
    ok = ~bad[eu] & ~bad[ev]
    n = hist.size
    start = (hist == q0) & ~inter & ~bad
    return not bool(reachable(n, eu[ok], ev[ok], start)[inter].any())
