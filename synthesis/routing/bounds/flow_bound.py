"""A combinatorial upper bound on the maximum flow of MILP-static.

The routing heuristic's bound (:func:`synthesis.routing.bounds.heuristic.flow_upper_bound`, the
maximum flow with every group open) ignores that the walls which route every bypass through I
are walls in I too. On random grids it is 3-4 where no wall set gives more than 2, and proving
that the flow level above the optimum is empty was the part of a 10x10 MILP-static solve that
no backend finished (docs/benchmarks/solvers.md, "The walls' flow bound"). :func:`static_flow_bound`
is a bound that sees the walls, computed from the product graph alone in a few graph searches.

Terms. In MILP-static every edge of G over the same move of T shares one cut value (c9), so a
cut set ``S`` opens or closes *moves*. Let ``S`` be valid (every bypass walk holds a cut edge),
and let

* ``R`` be the nodes of the whole G reachable from ``Src`` over open edges with both ends
  outside I (the potentials' region), ``A`` the states of T of the nodes of ``R``;
* ``Y`` be the states of the heads of G's *entry edges* (tail outside I, head in I), a set fixed
  by G alone, and ``Z = A | Y``.

``R``, ``A``, ``Y`` and the eligible states below are taken over the whole G, not the model's
edges: L1 reasons about open edges of G that the model may have pruned (a head in I that
reaches no ``Tgt``). The counted entries and exits are model edges, which routes use.

Facts, for a valid ``S`` with ``Src`` outside I and outside ``Tgt`` (with ``Src`` in ``Tgt``
no model edge leaves ``Src``, the known bound is 0 and it is returned as it is):

* (L0) ``R`` holds no ``Tgt`` node: a shortest open walk from ``Src`` to ``Tgt`` outside I
  would be a bypass walk of the model (its nodes reach ``Tgt``, so the model keeps them).
  So ``A`` holds only states with a node outside I and ``Tgt`` (*eligible* states), and
  the state of ``Src``.
* (L1) An open move ``s -> s'`` with ``s`` in ``A`` leads into ``Z``. Take ``(s, q)`` in ``R``:
  G has the edge ``(s, q) -> (s', q')`` (the automaton is total, and G holds every node
  reachable from ``Src``), open because the move is. If ``(s', q')`` is outside I it is in
  ``R`` (so ``s'`` is in ``A``), else the edge is an entry edge (so ``s'`` is in ``Y``).
* (L2) By flow decomposition (reductions.py, F1) a flow of value ``F`` is ``F`` edge-disjoint
  routes over open model edges. Each has a first entry edge, whose tail is in ``R`` (what
  comes before is an open walk outside I from ``Src``): so ``F <= E``, the number of model
  entry edges with a tail in ``R``.
* (L3) After its first entry edge a route is at a state of ``Y``, inside ``Z``, and ends at
  a ``Tgt`` node. Either that node's state is in ``Z`` (then the route's last edge is an
  edge into ``Tgt`` whose head's state is in ``Z``), or the route leaves ``Z`` by some move
  ``y -> x``, ``x`` outside ``Z``, whose tail ``y`` is not in ``A`` (L1), so in ``Y - A``.
  Both edges come after an I node (``I`` and ``Tgt`` are disjoint: ``intermediate`` is
  ``acc_test & ~acc_sys``: a route reaches ``Tgt`` strictly after its first I node).
  So ``F <= X``, the number of model edges with a tail reachable from I that are of either
  kind.

``E`` depends on ``S`` through ``R``, ``X`` through ``A``; once ``R`` is over-estimated by a
region that depends on ``A`` alone (below), both do. The bound is the largest
``min(E, X)`` over every set ``A`` of eligible states holding the start's, over-estimated
so that it takes few graph searches: for each choice of ``A & Y`` (at most
:data:`MAX_ENTRY_STATES` states of ``Y``, ``2^|Y|`` choices), ``R`` is at most the nodes
reachable from ``Src`` outside I and ``Tgt`` over eligible states not in ``Y - A`` (monotone in
``A``), and each other state ``x`` adds to ``E`` the entry edges with a tail at ``x`` in that
set if ``x`` is in ``A``, and to ``X`` the exits into ``x`` if not (the edges into ``Tgt``
nodes at ``x`` if so). Choosing the other states' membership to maximise ``min(E, X)`` is a
two-value knapsack over a few states, solved exactly by dynamic programming over ``E``
(capped at the bound already known). Every step over-estimates ``min(E, X)`` of the true
``A``, so every valid cut set has flow at most the bound, and the optimum of docs/method.md §5 is
kept: the bound only proves a flow level empty, or tells phase 1 that the heuristic's flow
is the maximum (``tests/synthesis/test_flow_bound.py`` checks it against brute force).

(L4) Every fact above holds with I replaced by any set ``I'`` of nodes of G that holds I and
no ``Tgt`` node. A valid ``S`` is valid for ``I'``: a walk from ``Src`` to ``Tgt`` outside
``I'`` is outside I, so it is a bypass walk (and L0 holds for the region outside ``I'``). A
route passes an I node before its ``Tgt`` node, and that node is in ``I'``: so every route is a
route through ``I'`` (L2 counts its first entry edge into ``I'``, L3 its edges after its first
``I'`` node), and the flow through I is at most the bound computed for ``I'``. The bound is
therefore the smallest over I and a few such sets (:func:`stage_sets`): for each place where a
history changes, I together with every node reachable in G from the nodes entered there by a
change of history, less ``Tgt``. Why: a test of several cells (``F p1 & F p2``) passes each of
them, so each test cell is a bottleneck of its own, and the enclosure around one that lies on the
grid's border (3 moves) allows 1 where the enclosure around I (the last cell visited) allows 2
(random 10x10 reachability grids with two test cells: docs/benchmarks/solvers.md, "The walls' flow bound").

(L5) L0-L3 hold too with every node that reaches no ``Tgt`` node in G (a *dead* node: a
safety objective already violated) left out of ``R`` and of the eligible states, and with
``Y`` grown by ``D``, the states of the dead heads of edges of G from live nodes outside I and
``Tgt``. L0: an open walk from ``Src`` to ``Tgt`` has only live nodes. L1 becomes: an open move
``s -> s'`` with ``s`` in ``A`` leads into ``Z`` (the edge from ``(s, q)`` in ``R`` reaches a live
node outside I, in ``R``, or an I node, an entry edge, or a dead node, whose state is in
``D``). L2 is unchanged (a route has only live nodes: it reaches ``Tgt``), and L3 holds with the
larger ``Y``: its argument uses only L1 and ``Y`` inside ``Z``. Why: on the safety objectives
(``G !p2``) every state is in ``A`` through the histories where ``p2`` was visited, and the
bound said nothing; without them the enclosure sees the test cell again (random 10x10 safety
grids: docs/benchmarks/solvers.md, "The walls' flow bound"). This variant is the flow bound's only
(``live=True`` of :func:`entry_choices`); :mod:`synthesis.routing.bounds.cut_bound` keeps L0-L3.

Only MILP-static (every cut history-independent); with ``Src`` in I there is no entry edge
to count and no bound.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ...graphs.products import Products, coreachable, reachable

#: States of ``Y`` (heads of entry edges) up to which the bound is computed: it takes
#: ``2^|Y|`` graph searches. A count, so whether it runs is the same on every machine.
MAX_ENTRY_STATES = 10


@dataclass(frozen=True)
class EntryChoice:
    """One choice of ``A & Y`` in the bound's maximisation, with what the bound derives from it.

    ``in_a_y`` (``bool`` per state of T): the states of ``Y`` in ``A``; ``out_y``: those of
    ``Y - A``; ``allowed``: the states that may be in ``A`` (eligible, not in ``Y - A``);
    ``region`` (``bool`` per node of G): the over-estimate of ``R`` (the nodes ``Src`` reaches
    outside I and ``Tgt`` over ``allowed`` states); ``flow``: the largest ``min(E, X)`` over
    every ``A`` with this ``A & Y``, capped at the known bound; ``split``: ``E`` and ``X`` by
    the other states' membership (:class:`Split`). Every valid cut set's ``A``
    has ``R`` inside ``region`` and flow at most ``flow`` for its own ``A & Y``.
    (:mod:`synthesis.routing.bounds.cut_bound` reuses the choices for the cost of the walls.)"""

    in_a_y: np.ndarray
    out_y: np.ndarray
    allowed: np.ndarray
    region: np.ndarray
    flow: int
    split: Split


def static_flow_bound(products: Products, eu: np.ndarray, ev: np.ndarray, known: int) -> int:
    """An upper bound on the flow of every valid cut set of MILP-static (see the module
    docstring), at most ``known`` (a bound already proven; returned when this one is no
    better or does not apply).

    Parameters
    ----------
    products
        The product graphs (the whole G, ``Src``, I, ``Tgt``).
    eu, ev
        The routing model's edges (:class:`~synthesis.routing.groups.ModelEdges`).
    known
        A proven upper bound on the flow (the heuristic's maximum flow with every group open).
    """
    bound = _bound_through(products, products.intermediate, eu, ev, known)
    for inter in stage_sets(products):
        if bound <= 0:
            break
        bound = _bound_through(products, inter, eu, ev, bound)  # L4
    return bound


def _bound_through(products: Products, inter: np.ndarray, eu: np.ndarray, ev: np.ndarray, known: int) -> int:
    """The bound of L0-L3 with ``inter`` (I, or a set ``I'`` of L4) in the place of I, at most
    ``known``."""
    choices = entry_choices(products, eu, ev, known, inter, live=True)
    if choices is None:
        return known
    best = 0
    for choice in choices:
        best = max(best, choice.flow)
        if best >= known:
            return known
    return best


def stage_sets(products: Products) -> list[np.ndarray]:
    """The sets ``I'`` of L4 (``bool`` per node of G), one per place where an edge of G changes
    the history (in place order): I, and every node reachable in G from the heads of those
    edges at that place, less ``Tgt``; those equal to I are left out. Each holds I and no
    ``Tgt`` node, which is all L4 needs; which ones are tried only decides how tight the
    bound is."""
    g = products.virtual
    inter, target = products.intermediate, products.target
    place = products.ts.place[g.state]
    change = g.hist[g.src] != g.hist[g.dst]
    heads = g.dst[change]
    out: list[np.ndarray] = []
    for p in np.unique(place[heads]).tolist():
        seeds = np.zeros(g.n_nodes, dtype=bool)
        seeds[heads[place[heads] == p]] = True
        stage = (inter | reachable(g.n_nodes, g.src, g.dst, seeds)) & ~target
        if not np.array_equal(stage, inter):
            out.append(stage)
    return out


def entry_choices(
    products: Products, eu: np.ndarray, ev: np.ndarray, known: int, inter: np.ndarray | None = None, live: bool = False
) -> Iterator[EntryChoice] | None:
    """The choices of ``A & Y`` the bound ranges over, each with its capped ``min(E, X)``
    (see :class:`EntryChoice`), or ``None`` where the bound does not apply (``Src`` in I, no
    known flow, or more than :data:`MAX_ENTRY_STATES` free states of ``Y``). Every set ``A``
    of a valid cut set matches one of the choices (its ``A & Y``; the start's state is in it).
    ``inter``: I (the default), or a set ``I'`` of L4 in its place; ``live``: the choices of
    L5 (dead nodes left out, ``Y`` grown by ``D``)."""
    g = products.virtual
    target = products.target
    if inter is None:
        inter = products.intermediate
    src = int(g.initial)
    if inter[src] or known <= 0:
        return None
    state = g.state.astype(np.int64)
    n_states = products.ts.n_states
    alive = coreachable(g.n_nodes, g.src, g.dst, target) if live else np.ones(g.n_nodes, dtype=bool)
    entry_full = ~inter[g.src] & inter[g.dst]
    ys = np.unique(state[g.dst[entry_full]])
    if live:  # L5: D, the states of dead heads of edges from live nodes outside I and Tgt
        from_live = (alive & ~inter & ~target)[g.src] & ~alive[g.dst]
        ys = np.union1d(ys, state[g.dst[from_live]])
    eligible = np.zeros(n_states, dtype=bool)
    eligible[state[~inter & ~target & alive]] = True
    start = int(state[src])
    free_y = ys[eligible[ys]]
    if free_y.size > MAX_ENTRY_STATES:
        return None
    in_y = np.zeros(n_states, dtype=bool)
    in_y[ys] = True

    n = g.n_nodes
    outside = ~inter & ~target & alive
    g_out = outside[g.src] & outside[g.dst]
    m_entry = ~inter[eu] & inter[ev]
    after_i = reachable(n, eu, ev, inter)
    m_tgt = after_i[eu] & target[ev]  # last edges of routes into Tgt
    m_from_y = after_i[eu] & in_y[state[eu]]  # candidate exits, by the state of their tail

    def choices() -> Iterator[EntryChoice]:
        for bits in range(1 << free_y.size):
            chosen = free_y[[(bits >> i) & 1 == 1 for i in range(free_y.size)]]
            in_a_y = np.zeros(n_states, dtype=bool)
            in_a_y[chosen] = True
            out_y = in_y & ~in_a_y  # states of Y not in A
            if out_y[start]:
                continue  # the start's state is in A
            allowed = eligible & ~out_y
            e = np.flatnonzero(g_out & allowed[state[g.src]] & allowed[state[g.dst]])
            region = reachable(n, g.src[e], g.dst[e], np.arange(n) == src)
            split = _split(
                n_states,
                state,
                eu,
                ev,
                m_entry & region[eu],
                m_from_y & out_y[state[eu]],
                m_tgt,
                allowed,
                in_y,
                start,
            )
            yield EntryChoice(in_a_y, out_y, allowed, region, _best_split(split, known), split)

    return choices()


@dataclass(frozen=True)
class Split:
    """``E`` and ``X`` of one choice of ``A & Y`` as functions of the other states' membership
    in ``A``: ``E = base_e + sum e_in``, ``X = base_x + sum (x_in if in A else x_out)`` over the
    ``items`` (rows ``(state, e_in, x_in, x_out)``: the allowed states outside ``Y`` other
    than the start's with an edge counted; every other state's share is in the bases)."""

    base_e: int
    base_x: int
    items: np.ndarray


def _split(
    n_states: int,
    state: np.ndarray,
    eu: np.ndarray,
    ev: np.ndarray,
    entries: np.ndarray,
    exits: np.ndarray,
    into_tgt: np.ndarray,
    allowed: np.ndarray,
    in_y: np.ndarray,
    start: int,
) -> Split:
    """:class:`Split` of one choice (``A & Y`` fixed by the caller through ``allowed``).

    ``entries``: model entry edges with a tail in the search region (``E`` counts those with
    a tail state in ``A``); ``exits``: model edges from a state of ``Y - A`` after I (``X``
    counts those with a head state outside ``Z``); ``into_tgt``: edges into ``Tgt`` after I
    (``X`` counts those with a head state in ``Z``)."""
    e_of = np.bincount(state[eu[entries]], minlength=n_states)
    tg_of = np.bincount(state[ev[into_tgt]], minlength=n_states)
    # an edge both an exit and into Tgt counts once: as an exit when its head is outside Z,
    # as an edge into Tgt when inside
    out_of = np.bincount(state[ev[exits]], minlength=n_states)
    base_x = int(tg_of[in_y].sum())  # Y is in Z whatever A is
    # states of Y in A: their entry tails count (Y - A states have none in the region)
    base_e = int(e_of[in_y & allowed].sum())
    items: list[tuple[int, int, int, int]] = []
    for x in np.flatnonzero((e_of > 0) | (tg_of > 0) | (out_of > 0)):
        if in_y[x]:
            continue
        if x == start:
            base_e += int(e_of[x])
            base_x += int(tg_of[x])
        elif allowed[x]:
            items.append((int(x), int(e_of[x]), int(tg_of[x]), int(out_of[x])))
        else:
            base_x += int(out_of[x])
    return Split(base_e, base_x, np.array(items, dtype=np.int64).reshape(-1, 4))


def _best_split(split: Split, cap: int) -> int:
    """The largest ``min(E, X)`` (capped at ``cap``) over the membership in ``A`` of the
    split's items: a two-value knapsack, by dynamic programming over ``E``."""
    # dp[k] = the largest X with E = k (E capped at cap), -1: unreachable
    dp = np.full(cap + 1, -1, dtype=np.int64)
    dp[min(split.base_e, cap)] = split.base_x
    for _, e_in, x_in, x_out in split.items.tolist():
        nxt = np.full(cap + 1, -1, dtype=np.int64)
        ok = np.flatnonzero(dp >= 0)
        np.maximum.at(nxt, ok, dp[ok] + x_out)  # not in A
        np.maximum.at(nxt, np.minimum(ok + e_in, cap), dp[ok] + x_in)  # in A
        dp = nxt
    ok = np.flatnonzero(dp >= 0)
    return int(min(cap, max((min(int(k), int(dp[k])) for k in ok), default=0)))
