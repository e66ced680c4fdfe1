"""A combinatorial lower bound on the fewest cuts of MILP-static at a flow level, and the wall
sets of its minimum cuts.

Phase 2 of a routing solve (the fewest cuts at the settled flow ``F``) is where the LP bounds
are weakest: on the random 10x10 static grids they stay far below the cuts of the tests found
(docs/benchmarks/solvers.md, "The walls' cut bound"). :func:`static_cut_bound` bounds the cost of the walls from the enclosure that
:mod:`synthesis.routing.bounds.flow_bound` proves, in one minimum cut per choice of ``A & Y``, and
returns the wall sets of those minimum cuts: where one of them, completed into a checked
routing answer, costs what the bound says, phase 2 is proven without a search.

Terms as in :mod:`synthesis.routing.bounds.flow_bound`: a valid cut set ``S`` of MILP-static closes
cut groups (every edge of G over the same move of T shares its group's cut value, c9; a
group stands for ``weight`` edges of G, and phase 2 minimises ``cost(S)``, the weight of the
groups ``S`` closes); ``R`` is what ``Src`` reaches outside I over open edges of the whole G,
``A`` its states, ``Y`` the states of the heads of G's entry edges. ``Src`` is outside I and
``Tgt`` (else no bound).

Lemmas, for a valid ``S`` whose flow is at least ``F``:

* (C1) Every move ``s -> s'`` of T with ``s`` in ``A`` and ``s'`` outside ``A | Y`` (and
  ``s != s'``) has its group closed by ``S``: flow_bound's L1 (an open move from a state of
  ``A`` leads into ``A | Y``; it holds for every valid ``S``, whatever its flow).
* (C2) ``A & Y`` is one of the choices :func:`~synthesis.routing.bounds.flow_bound.entry_choices`
  ranges over (the start's state is in ``A``; the choices are every subset of the eligible
  states of ``Y`` holding it, the ineligible ones are never in ``A`` by L0), and for that
  choice: ``A`` holds the start's state and the choice's ``A & Y``; ``A`` lies inside the
  states of the choice's ``region`` (``R`` does: ``region`` is what ``Src`` reaches over every
  edge between allowed states outside I and ``Tgt``, and ``R``'s edges are such edges by L0);
  and the choice's ``flow`` is at least ``F`` (flow_bound's L2, L3 and the over-estimates of
  its proof: ``F <= min(E, X)`` of ``S``'s own ``A``, at most the choice's value). So a choice
  with ``flow < F``, or whose ``A & Y`` is not inside its region's states, is no valid
  ``S``'s and is skipped.
* (C3) Capacities. Each move ``s -> s'`` of G's edges (``s != s'``) is an arc of a graph on
  the states, with a capacity from its group: infinite for a group that may not be cut (an
  unrestrictable move: C1 says such an arc never leaves ``A`` for outside ``A | Y``); the
  group's ``weight`` when the group has one arc, or two opposite arcs ``a -> b``, ``b -> a``
  (the c14 pair: both can never leave ``A`` at once, since the second one's tail would be the
  first one's head, outside ``A``); else ``weight / k`` on each of its ``k`` arcs (tied groups,
  such as places across fuel levels). So for every ``A`` the arcs of one group leaving ``A``
  for outside ``A | Y`` have capacities summing to at most its ``weight``: counted once, as
  the model counts it. Capacities are scaled to integers by a common factor and rounded
  down, which only lowers them.
* (C4) For the choice of ``S``'s ``A & Y``: the capacity of the arcs from ``A`` to outside
  ``A | Y`` is at most ``cost(S)`` (C1: their groups are closed; C3: each closed group counts
  at most its weight). With the states of ``Y - A`` removed (no arc into them counts, and
  no arc out of them leaves ``A``), that capacity is the value of the directed cut ``A``
  between the states forced into ``A`` (the start's, ``A & Y``) and those forced out (the
  states outside the region's, C2), so it is at least the minimum such cut.

* (C5) The states next to ``Y``. For one choice, flow_bound's ``E`` and ``X`` depend on the
  membership in ``A`` of a few more states (:class:`~synthesis.routing.bounds.flow_bound.Split`'s
  items: those with a counted entry, exit or edge into ``Tgt``): ``S``'s own ``A`` gives its
  items one membership, under which ``min(E, X) >= F`` (L2, L3 with the over-estimates, as in
  C2), and ``A`` holds the items of that membership and none of the others, so C4 holds with
  them forced in or out as well. The bound therefore ranges over every membership of the items
  whose ``min(E, X)`` reaches ``F``, each with its minimum cut, by branch and bound
  (:class:`_Search`): a partial membership's minimum cut is at most every completion's (more
  forcing only raises a minimum cut), and its completions' ``min(E, X)`` at most the one
  with every free item counted at its larger share; items outside the region's states are
  forced out (C2). Where the search's budget (a count of minimum cuts) runs out, the
  smallest lower bound of a node left open enters the minimum too.

* (C6) Dominating states. ``F >= 1`` needs ``E >= 1``: ``R`` holds the tail of a model entry
  edge, and the walk in ``R`` that reaches it is a walk in the choice's ``region`` from ``Src``
  to the tail of a model entry edge in ``region`` (``R`` lies in ``region``, C2). So a state
  whose nodes every such walk passes is in ``A`` and is forced in as well (a test objective in
  sequence passes its first cell before it can enter I). Such a state lies on every walk, so
  only those of one shortest walk are tried, each by one graph search without its nodes.

So ``cost(S) >= min`` over the kept choices and memberships of their minimum cuts, and since costs are
integers, its ceiling is a lower bound on the fewest cuts at flow ``F`` (docs/method.md §5's phase 2
optimum). Nothing about the model's pruned edges or reductions enters: the groups fixed open
and the groups without a cut binary keep their finite weight, so the bound holds for the
model and for every wall set of the unreduced problem. With no kept choice no valid cut set
has flow ``F`` (the bound is infinite).

Candidates. The source side of a minimum cut is a set of states; closing the groups of every
arc from it to outside it and ``Y - A`` gives a wall set whose cost is at least the cut's.
It need not be valid or keep flow ``F``, so it is only a candidate: the caller completes it
into a routing answer and checks it (:mod:`synthesis.routing.solve`), and only a checked
candidate whose cost equals the bound proves phase 2.

Only MILP-static (every cut history-independent), as the flow bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from ...graphs.cuts import sink_side, source_side
from ...graphs.products import Products
from .flow_bound import Split, entry_choices

#: Largest common factor the fractional capacities (C3) are scaled by; above it they are
#: rounded down (a smaller capacity keeps the bound a bound).
MAX_SCALE = 720_720

#: Integer capacities stay below this (scipy's maximum flow counts in 32 bits).
_CAP_LIMIT = 1 << 30


@dataclass(frozen=True)
class CutBound:
    """The walls' cut bound at one flow level.

    ``value``: a lower bound on the cost of every valid cut set with flow at least
    ``level`` (``math.inf``: no such cut set); ``candidates``: wall sets (``bool`` per cut
    group) from the minimum cuts, cheapest cut first, not checked; ``choices``: the choices of
    ``A & Y`` kept (C2)."""

    level: int
    value: float
    candidates: list[np.ndarray]
    choices: int


class _Search:
    """C5's branch and bound over one choice's items: every node fixes the membership of the
    first items in ``A`` and leaves the rest free; its minimum cut (the fixed items forced in or
    out) is a lower bound for every completion (more forcing only raises a minimum cut), and
    the completions' ``min(E, X)`` is at most ``min(E_max, X_max)`` (each free item counted at
    its largest ``E`` and ``X`` share). A node is dropped when that is below the level or its
    cut is larger than the best full assignment's (a tie is searched on: its leaves are more
    candidates at the same cut); a full assignment is kept when its
    ``min(E, X)`` reaches the level."""

    def __init__(self, arcs: _Arcs, n_states: int, level: int, max_cuts: int) -> None:
        self.arcs, self.n_states, self.level = arcs, n_states, level
        self.left = max_cuts
        self.best = math.inf  # the smallest cut of a kept full assignment (scaled)
        self.open = math.inf  # the smallest lower bound of a node dropped by the budget (scaled)
        self.cuts: list[tuple[int, int, np.ndarray]] = []  # (cut value, order, wall set)

    def bound(self) -> float:
        """The lower bound proven so far (unscaled; ``inf``: no assignment reaches the level)."""
        return min(self.best, self.open) / self.arcs.scale

    def run(self, split: Split, forced_in: np.ndarray, forced_out: np.ndarray, removed: np.ndarray) -> None:
        items = split.items
        # items that cannot be in A (outside the region's states, C2) are forced out
        outside = forced_out[items[:, 0]] if items.size else np.zeros(0, dtype=bool)
        fixed_x = int(items[outside, 3].sum())
        items = items[~outside]
        # the items that move E and X most first (deterministic ties: the state)
        order = np.lexsort((items[:, 0], -(items[:, 1] + items[:, 2] + items[:, 3]))) if items.size else np.zeros(0, dtype=np.int64)
        items = items[order]
        e_rest = np.concatenate([np.cumsum(items[::-1, 1])[::-1], [0]]) if items.size else np.zeros(1, dtype=np.int64)
        x_rest = np.concatenate([np.cumsum(np.maximum(items[::-1, 2], items[::-1, 3]))[::-1], [0]]) if items.size else np.zeros(1, dtype=np.int64)
        # a node: (depth, E so far, X so far, lower bound from its parent, forced in, forced out)
        stack: list[tuple[int, int, int, float, np.ndarray, np.ndarray]] = [(0, split.base_e, split.base_x + fixed_x, 0.0, forced_in, forced_out)]
        while stack:
            depth, e, x, parent, f_in, f_out = stack.pop()
            # a node no better than the best kept leaf is still searched on a tie: its leaves'
            # wall sets are more candidates at the same cut
            if min(e + e_rest[depth], x + x_rest[depth]) < self.level or parent > min(self.best, self.open):
                continue
            if self.left <= 0:
                self.open = min(self.open, parent)
                continue
            self.left -= 1
            value, sides = _min_cut(self.arcs, self.n_states, f_in, f_out, removed)
            if value >= self.arcs.inf_cap or value > self.best:
                continue
            if depth == len(items):  # a full assignment, and min(E, X) reaches the level
                self.best = min(self.best, value)
                for side in sides:
                    self.cuts.append((value, len(self.cuts), _walls_of(self.arcs, side, removed, self.arcs.n_groups)))
                continue
            state, e_in, x_in, x_out = (int(v) for v in items[depth])
            f_in2 = f_in.copy()
            f_in2[state] = True
            f_out2 = f_out.copy()
            f_out2[state] = True
            stack.append((depth + 1, e, x + x_out, float(value), f_in, f_out2))  # not in A
            stack.append((depth + 1, e + e_in, x + x_in, float(value), f_in2, f_out))  # in A (searched first)


@dataclass(frozen=True)
class _Arcs:
    """The moves of G's edges as arcs between states, one per (tail, head, group)."""

    tail: np.ndarray
    head: np.ndarray
    group: np.ndarray
    cap: np.ndarray  # integer capacities (C3), ``inf_cap`` where the group may not be cut
    scale: int  # capacities are the true ones times this, rounded down
    inf_cap: int
    n_groups: int


def static_cut_bound(
    products: Products,
    of_edge: np.ndarray,
    weight: np.ndarray,
    restrictable: np.ndarray,
    eu: np.ndarray,
    ev: np.ndarray,
    level: int,
    max_candidates: int = 8,
    max_cuts: int = 2_000,
) -> CutBound | None:
    """The walls' cut bound of MILP-static at flow ``level`` (see the module docstring), or
    ``None`` where it does not apply (as the flow bound: ``Src`` in I, too many states of
    ``Y``).

    Parameters
    ----------
    products
        The product graphs (the whole G, ``Src``, I, ``Tgt``).
    of_edge, weight, restrictable
        The cut groups (:class:`~synthesis.routing.groups.CutGroups`): each G edge's group,
        each group's weight (phase 2's objective) and whether it may be cut.
    eu, ev
        The routing model's edges (for the flow bound's count of entries and exits).
    level
        The flow level ``F`` (at least 1).
    max_candidates
        How many minimum cuts' wall sets to return (two per kept full assignment: the
        smallest and the largest source side), cheapest cut first.
    max_cuts
        The minimum cuts the search over the states next to ``Y`` (C5) may compute: a count,
        so the bound is the same on every machine; where it runs out, the bound is the
        smallest value still open (a bound all the same, only weaker).
    """
    if level < 1:
        raise ValueError(f"a cut bound needs a flow level of at least 1, not {level}")
    choices = entry_choices(products, eu, ev, level)  # capped at the level: only flow >= level matters
    if choices is None:
        return None
    g = products.virtual
    state = g.state.astype(np.int64)
    n_states = products.ts.n_states
    start = int(state[g.initial])
    arcs = _state_arcs(state, g.src, g.dst, of_edge, weight, restrictable)
    entry = ~products.intermediate[eu] & products.intermediate[ev]  # the model's entry edges
    search = _Search(arcs, n_states, level, max_cuts)
    kept = 0
    for choice in choices:
        if choice.flow < level:
            continue  # C2: no valid cut set of flow >= level has this A & Y
        in_region = np.zeros(n_states, dtype=bool)
        in_region[state[choice.region]] = True
        if np.any(choice.in_a_y & ~in_region):
            continue  # C2: A & Y must lie inside the region's states
        kept += 1
        forced_in = choice.in_a_y.copy()
        forced_in[start] = True
        forced_in |= _dominators(products, state, choice.region, eu[entry & choice.region[eu]])
        forced_out = ~in_region & ~choice.out_y
        search.run(choice.split, forced_in, forced_out, choice.out_y)
    best = search.bound()
    cuts = search.cuts
    if not math.isfinite(best):
        return CutBound(level, math.inf, [], kept)
    cuts.sort(key=lambda c: (c[0], c[1]))
    candidates: list[np.ndarray] = []
    for _, _, walls in cuts:
        if not any(np.array_equal(walls, other) for other in candidates):
            # cheapest cut first
            candidates.append(walls)
        if len(candidates) >= max_candidates:
            break
    return CutBound(level, float(math.ceil(best - 1e-9)), candidates, kept)


def _dominators(products: Products, state: np.ndarray, region: np.ndarray, tails: np.ndarray) -> np.ndarray:
    """C6: the states (``bool`` per state of T) whose nodes every walk in ``region`` from ``Src``
    to a node of ``tails`` passes (the start's excluded). Only the states of one shortest such
    walk can be, so only those are tried, one graph search each."""
    g = products.virtual
    out = np.zeros(products.ts.n_states, dtype=bool)
    src = int(g.initial)
    inside = region[g.src] & region[g.dst]
    eu, ev = g.src[inside], g.dst[inside]
    is_tail = np.zeros(g.n_nodes, dtype=bool)
    is_tail[tails] = True
    if not is_tail.any():
        return out
    adj = sp.csr_matrix((np.ones(eu.size, dtype=np.int8), (eu, ev)), shape=(g.n_nodes, g.n_nodes))
    order, pred = breadth_first_order(adj, src, directed=True, return_predecessors=True)
    hit = order[is_tail[order]]
    if hit.size == 0:
        return out
    walk: list[int] = []
    v = int(hit[0])
    while v >= 0:
        walk.append(v)
        v = int(pred[v])
    start = int(state[src])
    for s in sorted({int(state[v]) for v in walk} - {start}):
        keep = (state[eu] != s) & (state[ev] != s)
        cut_adj = sp.csr_matrix((np.ones(int(keep.sum()), dtype=np.int8), (eu[keep], ev[keep])), shape=(g.n_nodes, g.n_nodes))
        seen = breadth_first_order(cut_adj, src, directed=True, return_predecessors=False)
        if not is_tail[seen].any():
            out[s] = True
    return out


def _state_arcs(state: np.ndarray, src: np.ndarray, dst: np.ndarray, of_edge: np.ndarray, weight: np.ndarray, restrictable: np.ndarray) -> _Arcs:
    """The arcs of C3 with their integer capacities."""
    a, b = state[src], state[dst]
    keep = a != b
    key = np.unique(np.stack([of_edge[keep], a[keep], b[keep]], axis=1), axis=0)
    group, tail, head = key[:, 0], key[:, 1], key[:, 2]
    k = np.bincount(group, minlength=weight.size)[group]
    # a group whose two arcs are opposite (a c14 pair) can never have both leave A; the
    # rows are sorted by group, so a group's two arcs are neighbours
    i = np.flatnonzero((k[:-1] == 2) & (group[:-1] == group[1:]))
    opposite = i[(tail[i] == head[i + 1]) & (head[i] == tail[i + 1])]
    k[opposite] = 1
    k[opposite + 1] = 1
    fractional = np.unique(k[k > 1])
    scale = 1
    for d in fractional.tolist():
        scale = math.lcm(scale, int(d))
        if scale > MAX_SCALE:
            scale = MAX_SCALE
            break
    w = weight[group].astype(np.int64)
    finite = restrictable[group]
    total = int(w[finite].sum())
    scale = max(1, min(scale, (_CAP_LIMIT // 4) // max(total, 1)))
    cap = (w * scale) // k  # rounded down: never above the true capacity times scale
    inf_cap = total * scale + 1
    cap = np.where(finite, cap, inf_cap)
    return _Arcs(tail, head, group, cap.astype(np.int64), scale, inf_cap, int(weight.size))


def _min_cut(arcs: _Arcs, n_states: int, forced_in: np.ndarray, forced_out: np.ndarray, removed: np.ndarray) -> tuple[int, list[np.ndarray]]:
    """The minimum directed cut (C4) between ``forced_in`` and ``forced_out`` states over the
    arcs that touch no ``removed`` state, and its smallest and largest source sides (``bool``
    per state). Infinite capacities count as ``arcs.inf_cap``; a value at least that is no cut."""
    use = ~removed[arcs.tail] & ~removed[arcs.head] & (arcs.cap > 0)
    big = arcs.inf_cap
    if np.any(forced_in & forced_out):
        return big, []
    # S -> hub_in -> forced_in and forced_out -> hub_out -> T, the hub arcs of capacity
    # ``big``: the flow never exceeds ``big``, so it fits scipy's 32 bits
    s, hub_in, hub_out, t = n_states, n_states + 1, n_states + 2, n_states + 3
    ins, outs = np.flatnonzero(forced_in), np.flatnonzero(forced_out)
    rows = np.concatenate([arcs.tail[use], [s], np.full(ins.size, hub_in), outs, [hub_out]])
    cols = np.concatenate([arcs.head[use], [hub_in], ins, np.full(outs.size, hub_out), [t]])
    caps = np.concatenate([arcs.cap[use], [big], np.full(ins.size, big), np.full(outs.size, big), [big]])
    n = n_states + 4
    cap = sp.csr_matrix((caps.astype(np.int64), (rows.astype(np.int64), cols.astype(np.int64))), shape=(n, n))
    cap.sum_duplicates()
    cap.data = np.minimum(cap.data, big)
    cap = cap.astype(np.int32)
    res = maximum_flow(cap, s, t)
    value = int(res.flow_value)
    if value >= big:
        return value, []
    small = source_side(cap, res.flow, s)
    large = ~sink_side(cap, res.flow, t)
    return value, [small[:n_states], large[:n_states]]


def _walls_of(arcs: _Arcs, side: np.ndarray, removed: np.ndarray, n_groups: int) -> np.ndarray:
    """The wall set of a source side: every group with an arc from ``side`` to a state
    outside it and outside ``removed``."""
    walls = np.zeros(n_groups, dtype=bool)
    walls[arcs.group[side[arcs.tail] & ~side[arcs.head] & ~removed[arcs.head]]] = True
    return walls
