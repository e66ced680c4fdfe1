"""A lower bound on the walls (doors, restrictions) every test needs, from the walks around the
test objective (bypasses, docs/method.md c4-c5): each needs its own item of the test where the
walks share none (:func:`disjoint_bypasses`), also once the route every test leaves open is
spared, branched over that route's first and last moves (:func:`routed_bypasses`). Both read the
bypass graph (:class:`BypassGraph`) and find walks with :func:`zero_one_path`, which the capped
start (:mod:`synthesis.routing.caps.start`) uses too.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ...graphs.consistency import check_consistency
from ...graphs.products import Products, reachable
from ..edges import model_edges
from ..groups import cut_groups, physical_items
from ..options import MilpOptions


@dataclass(frozen=True)
class BypassGraph:
    """The edges of G a bypass may take, as the cap bounds see them: ``eu -> ev`` the c5 edges
    of the routing model (both ends outside I), ``grp`` their cut groups, ``item`` their
    physical items, ``cuttable`` whether a cut may close them, ``counted`` (per item) whether
    the cap counts the item; ``source`` and ``target`` as in G. ``route_*`` are the model's
    edges between nodes some route ``Src -> I -> Tgt`` can visit, for :func:`routed_bypasses`."""

    n: int
    source: int
    target: np.ndarray
    eu: np.ndarray
    ev: np.ndarray
    grp: np.ndarray
    item: np.ndarray
    cuttable: np.ndarray
    counted: np.ndarray
    n_groups: int
    route_eu: np.ndarray
    route_ev: np.ndarray
    route_grp: np.ndarray
    route_ends: np.ndarray


def bypass_graph(products: Products, options: MilpOptions, cap: str) -> BypassGraph:
    """The :class:`BypassGraph` of ``products`` under ``options`` for the cap ``cap``."""
    g = products.virtual
    groups = cut_groups(products, options)
    me = model_edges(products, groups, check_consistency(products))
    items = physical_items(products, groups)
    c5 = np.flatnonzero(me.c5)
    grp = me.grp[c5]
    n = g.n_nodes
    tgt, inter = products.target, products.intermediate
    src = np.zeros(n, dtype=bool)
    src[int(g.initial)] = True
    # the nodes of routes Src -> I -> Tgt: before I (reached from Src, reaching I), after (reached from I, reaching Tgt)
    to_tgt = reachable(n, me.ev, me.eu, tgt)
    from_src = reachable(n, me.eu, me.ev, src)
    after = reachable(n, me.eu, me.ev, inter & from_src) & to_tgt
    before = from_src & reachable(n, me.ev, me.eu, inter & to_tgt)
    on_route = after | before
    r = on_route[me.eu] & on_route[me.ev]
    return BypassGraph(
        n=n,
        source=int(g.initial),
        target=tgt,
        eu=me.eu[c5],
        ev=me.ev[c5],
        grp=grp,
        item=items.of_group[grp],
        cuttable=me.has_var[grp],
        counted=items.kinds(cap),
        n_groups=int(groups.keys.size),
        route_eu=me.eu[r],
        route_ev=me.ev[r],
        route_grp=me.grp[r],
        route_ends=np.flatnonzero(tgt & after),
    )


def count_disjoint_bypasses(bg: BypassGraph, stop_above: int, spared: np.ndarray | None = None) -> int:
    """See :func:`counted_bypasses`: the count alone."""
    return counted_bypasses(bg, stop_above, spared)[0]


def counted_bypasses(bg: BypassGraph, stop_above: int, spared: np.ndarray | None = None) -> tuple[int, int]:
    """Bypasses found one after another, each over edges whose items no earlier one used,
    never over an edge only an item the cap leaves out (a wall, for a cap on doors) can close;
    ``spared`` (``bool`` per cut group) are groups no cut may use: their edges are free to
    every bypass. Each walk takes the fewest edges a cut could close (then the fewest edges),
    so it uses up as few items as it can. Stops once ``stop_above`` are found; 0 where a
    bypass nothing can close is found (no test at all). Returns the count and the number of
    shortest-path searches it made."""
    cuttable = bg.cuttable if spared is None else bg.cuttable & ~spared[bg.grp]
    usable = ~cuttable | bg.counted[bg.item]
    start = np.zeros(bg.n, dtype=bool)
    start[bg.source] = True
    found = searches = 0
    while found <= stop_above:
        e = np.flatnonzero(usable)
        searches += 1
        path = zero_one_path(bg.n, bg.eu[e], bg.ev[e], cuttable[e], start, bg.target)
        if path is None:  # no bypass left
            break
        walk = e[path]
        used = np.unique(bg.item[walk[cuttable[walk]]])
        if used.size == 0:  # a bypass nothing can close: no test at all (the solve says unroutable)
            return 0, searches
        found += 1
        usable &= ~np.isin(bg.item, used)
    return found, searches


def disjoint_bypasses(products: Products, options: MilpOptions, cap: str, stop_above: int) -> int:
    """A lower bound on the items ``cap`` counts that every test needs: the number of
    ``Src -> Tgt`` walks avoiding I (bypasses) found one after another, each over edges
    whose items no earlier walk used, and which no item the cap leaves out (a wall, for a
    cap on doors) can close (:func:`count_disjoint_bypasses`). Every test closes each bypass
    with an item the cap counts (docs/method.md c4-c5), a different one for each (they share
    none), so it needs at least as many. Stops once ``stop_above`` are found.

    Cheap (one shortest-path search of G per walk), so a cap far below what the problem
    needs is refused before any solve.
    """
    return count_disjoint_bypasses(bypass_graph(products, options, cap), stop_above)


ROUTED_SEARCHES = 4000
"""The most shortest-path searches of G :func:`routed_bypasses` makes (a few per bypass count):
a deterministic budget, so the same problem gets the same answer on every machine."""


def routed_bypasses(
    products: Products,
    options: MilpOptions,
    cap: str,
    stop_above: int,
    searches: int = ROUTED_SEARCHES,
    deadline: float | None = None,
    bg: BypassGraph | None = None,
) -> int:
    """``stop_above + 1`` where it is proven that every test needs more than ``stop_above``
    items the cap ``cap`` counts; else :func:`disjoint_bypasses`'s bound.

    Why it holds: a test ``X`` (a set of cut groups) lets flow >= 1 through, so some simple
    walk ``R`` from ``Src`` through I to ``Tgt`` keeps every cut group on it open. Every
    bypass must still be closed (docs/method.md c4-c5), by a group off ``R``. So for any set
    ``P`` of groups on ``R``, bypasses that share no item a cut outside ``P`` could close
    each need their own item of ``X`` (:func:`count_disjoint_bypasses` with ``P`` spared),
    and that count bounds ``X`` from below. Which ``R`` the test leaves open is unknown: the
    search branches over it, extending a prefix from ``Src`` and a suffix into ``Tgt`` by one
    edge at a time (over every edge a route may take), spares the groups of both, and closes
    a branch once the count exceeds ``stop_above``. Every route has its prefix and suffix on
    one branch, so where every branch closes before its prefix and suffix meet, every test
    needs more. The count only grows as more is spared: a short prefix and suffix raise the
    bound from the two or three ways into the goal (all a plain count can use) to the ways
    around the whole corner a route must cross.

    ``searches`` bounds the shortest-path searches made (:data:`ROUTED_SEARCHES`); ``deadline``
    (``perf_counter`` time) ends the search early. A search that runs out proves nothing.
    ``bg``: the :func:`bypass_graph` of ``products``, ``options`` and ``cap``, where the caller
    has it already.

    Example::

        routed_bypasses(products, milp, "max_walls", stop_above=4)  # 5: no test has 4 walls
    """
    if bg is None:
        bg = bypass_graph(products, options, cap)
    plain = count_disjoint_bypasses(bg, stop_above)
    if plain > stop_above or plain == 0 or bg.route_ends.size == 0:
        return plain
    out_edges: dict[int, list[int]] = {}
    in_edges: dict[int, list[int]] = {}
    for k, (a, b) in enumerate(zip(bg.route_eu.tolist(), bg.route_ev.tolist(), strict=True)):
        out_edges.setdefault(a, []).append(k)
        in_edges.setdefault(b, []).append(k)
    counts: dict[frozenset[int], int] = {}
    made = 0

    def count(spared_groups: frozenset[int]) -> int | None:
        nonlocal made
        if spared_groups not in counts:
            if made >= searches or (deadline is not None and time.perf_counter() > deadline):
                return None
            spared = np.zeros(bg.n_groups, dtype=bool)
            spared[list(spared_groups)] = True
            counts[spared_groups], used = counted_bypasses(bg, stop_above, spared)
            made += used
        return counts[spared_groups]

    # depth first, over (prefix from Src, suffix into Tgt, the groups on both)
    stack: list[tuple[tuple[int, ...], tuple[int, ...], frozenset[int]]] = [((bg.source,), (int(t),), frozenset()) for t in bg.route_ends[::-1]]
    while stack:
        head, tail, spared_groups = stack.pop()
        found = count(spared_groups)
        if found is None:
            return plain  # out of budget: nothing proven
        if found > stop_above:
            continue
        if set(head) & set(tail):
            return plain  # a whole route with too few bypasses: nothing proven
        if len(head) <= len(tail):
            for k in reversed(out_edges.get(head[-1], [])):
                v = int(bg.route_ev[k])
                if v not in head:
                    stack.append((head + (v,), tail, spared_groups | {int(bg.route_grp[k])}))
        else:
            for k in reversed(in_edges.get(tail[0], [])):
                v = int(bg.route_eu[k])
                if v not in tail:
                    stack.append((head, (v,) + tail, spared_groups | {int(bg.route_grp[k])}))
    return stop_above + 1


def zero_one_path(
    n: int,
    eu: np.ndarray,
    ev: np.ndarray,
    costly: np.ndarray,
    start: np.ndarray,
    target: np.ndarray,
    jitter: np.ndarray | None = None,
) -> np.ndarray | None:
    """Indices of the edges of a path from a ``start`` node to a ``target`` node over the edges
    ``eu -> ev`` with the fewest ``costly`` edges, and among those the shortest (each edge
    counting ``jitter`` of it, default 1: a tie-break); ``None`` if there is none."""
    step = np.ones(eu.size, dtype=np.float64) if jitter is None else jitter.astype(np.float64)
    cross = float(n + 1) * float(step.max(initial=1.0))  # one costly edge outweighs any path of cheap ones
    w = np.where(costly, cross, 0.0) + step
    key = eu.astype(np.int64) * n + ev.astype(np.int64)
    order = np.lexsort((w, key))
    first = np.ones(order.size, dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    keep = order[first]  # the cheapest of each pair of nodes, in key order
    mat = sp.csr_matrix((w[keep], (eu[keep], ev[keep])), shape=(n, n))
    starts = np.flatnonzero(start)
    if starts.size == 0:
        return None
    dist, pred, _ = dijkstra(mat, directed=True, indices=starts, return_predecessors=True, min_only=True)
    ends = np.flatnonzero(target & np.isfinite(dist))
    if ends.size == 0:
        return None
    v = int(ends[np.argmin(dist[ends])])
    nodes = [v]
    while not start[v]:
        v = int(pred[v])
        nodes.append(v)
    nodes.reverse()
    pairs = np.array(nodes[:-1], dtype=np.int64) * n + np.array(nodes[1:], dtype=np.int64)
    out: np.ndarray = keep[np.searchsorted(key[keep], pairs)]
    return out
