"""A fast primal heuristic for the routing MILP: open cut groups greedily, flow first.

A cut set is valid (c5) iff the *open* groups leave no ``Src -> Tgt`` path outside I.
Adding open groups can only help the flow and only hurt separation, so the heuristic
grows a set of open groups one augmenting path at a time: each augmenting path of the
flow (in the residual graph, fewest newly opened groups first, by 0-1 BFS) is accepted
when opening its groups keeps ``Src`` separated from ``Tgt`` outside I, and its groups
are forbidden otherwise. The cut set returned is then only what separation needs: the
groups on the border of the region reachable from ``Src`` outside I.

Where that growth stops short of the upper bound below (typically at flow 0: the
shortest route comes back through a cell, and its own moves open a shortcut past I),
it is run again from the moves of *place-simple* routes, one route or a pair (a route's
moves alone are a valid cut set with flow 1, see :func:`simple_routes`).

The search for routes and the growth from them stop at a deterministic work budget
(:attr:`RouteSeed.work`, counted in edges visited), never at a clock: the same model
gives the same guess on every machine under any load, so the guess may seed cached and
shipped answers.

Every valid solution carries no flow on an edge from outside I straight into ``Tgt``,
so the maximum flow without those edges is an upper bound on F; when the heuristic
reaches it, phase 1 of the MILP is proven without solving it.
"""

from __future__ import annotations

import heapq
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import maximum_flow, shortest_path

from ...graphs.products import reachable


@dataclass
class RoutingGuess:
    """A valid cut set with its flow, for the model's edges."""

    flow: int
    upper_bound: int
    edge_flow: np.ndarray  # 0/1 per model edge
    cut_groups: np.ndarray  # bool per group
    reach: np.ndarray  # bool per node of G: reachable from Src outside I over open edges
    from_route: bool = False  # grown from a place-simple route (not the greedy growth alone)


def flow_upper_bound(n: int, src: int, eu: np.ndarray, ev: np.ndarray, usable: np.ndarray, target: np.ndarray) -> int:
    """Maximum flow ``src -> target`` over the usable edges (unit capacities)."""
    e = np.flatnonzero(usable)
    t = np.flatnonzero(target)
    rows = np.concatenate([eu[e], t])
    cols = np.concatenate([ev[e], np.full(t.size, n)])
    caps = np.concatenate([np.ones(e.size, dtype=np.int32), np.full(t.size, max(e.size, 1), dtype=np.int32)])
    cap = sp.csr_matrix((caps, (rows, cols)), shape=(n + 1, n + 1))
    return int(maximum_flow(cap, src, n).flow_value)


def usable_edges(c5: np.ndarray, ev: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``bool`` per model edge: the heuristic's flows and its upper bound may use it (every
    edge but the c5 edges into ``Tgt``)."""
    out: np.ndarray = ~(c5 & target[ev])
    return out


def open_flow_bound(n: int, src: int, eu: np.ndarray, ev: np.ndarray, c5: np.ndarray, target: np.ndarray) -> int:
    """The heuristic's flow upper bound: the maximum flow with every group open."""
    return flow_upper_bound(n, src, eu, ev, usable_edges(c5, ev, target), target)


def _csr(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(keys, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(ptr, keys + 1, 1)
    return np.cumsum(ptr), order


def guess_routing(
    n: int,
    src: int,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    c5: np.ndarray,
    has_var: np.ndarray,
    target: np.ndarray,
    max_rounds: int = 200,
    traps: Callable[[np.ndarray], bool] | None = None,
    route_seed: RouteSeed | None = None,
) -> RoutingGuess:
    """Greedy valid cut set with large flow (see the module docstring).

    Parameters
    ----------
    n, src
        Nodes of G and the source node.
    eu, ev, grp
        The model's edges and the cut group of each.
    c5
        ``bool`` per edge: both ends outside I (the edges separation is about).
    has_var
        ``bool`` per group: the group may be cut; other groups are always open.
    target
        ``bool`` per node: ``Tgt``.
    traps
        Whether a cut set (``bool`` per group) traps the system (the feasibility
        constraints c6-c8); an augmenting path whose cut set traps is rejected
        unless the current one traps already.
    route_seed
        Where the greedy growth from nothing open ends below the upper bound, it is
        also grown from the moves of place-simple routes (:func:`simple_routes`), one
        route and pairs of routes, and the largest flow is kept.
    """
    m = eu.size
    usable = usable_edges(c5, ev, target)
    upper = flow_upper_bound(n, src, eu, ev, usable, target)
    out_ptr, out_order = _csr(eu, n)
    in_ptr, in_order = _csr(ev, n)

    def separated(open_mask: np.ndarray) -> tuple[bool, np.ndarray]:
        keep = c5 & open_mask[grp]
        reach = reachable(n, eu[keep], ev[keep], np.arange(n) == src)
        return not np.any(reach & target), reach

    def border(reach: np.ndarray) -> np.ndarray:
        cut = np.zeros(has_var.size, dtype=bool)
        cut[grp[c5 & reach[eu] & ~reach[ev]]] = True
        return cut

    if not separated(~has_var)[0]:  # even cutting every cuttable group leaves a path outside I
        return RoutingGuess(0, upper, np.zeros(m), np.zeros(has_var.size, dtype=bool), np.zeros(n, dtype=bool))

    def grow(is_open: np.ndarray, f: np.ndarray, flow: int, work: Work | None = None) -> tuple[int, np.ndarray, np.ndarray]:
        f = f.copy()
        forbidden = np.zeros(has_var.size, dtype=bool)
        _, reach = separated(is_open)
        trapping = traps is not None and traps(border(reach))
        for _ in range(max_rounds):
            if flow >= upper:
                break
            if work is not None:
                work.spend(m)  # an augmenting path search and a separation test visit the edges
            path = _augmenting_path(n, src, eu, ev, grp, usable, f, is_open, forbidden, target, out_ptr, out_order, in_ptr, in_order)
            if path is None:
                break
            edges, forward = path
            new = np.unique(grp[edges[forward & ~is_open[grp[edges]]]])
            trial = is_open.copy()
            trial[new] = True
            ok, reach = separated(trial)
            if ok and traps is not None and not trapping:
                ok = not traps(border(reach))
            elif ok and traps is not None:
                trapping = traps(border(reach))
            if ok:
                is_open = trial
                f[edges[forward]] = True
                f[edges[~forward]] = False
                flow += 1
            else:
                forbidden[new] = True
        return flow, is_open, f

    flow, is_open, f = grow(~has_var, np.zeros(m, dtype=bool), 0)
    from_route = False
    if traps is not None and flow > 0 and traps(border(separated(is_open)[1])):
        # grown from a trapping start and never left it: no use as a solution
        flow, is_open, f = 0, ~has_var, np.zeros(m, dtype=bool)

    def grow_from(routes: list[np.ndarray], work: Work) -> tuple[int, np.ndarray, np.ndarray] | None:
        """Grow from the first of ``routes`` with every route's groups open, ``None`` where
        those groups alone open a bypass or trap."""
        seeded = ~has_var
        for r in routes:
            seeded[grp[r]] = True
        ok, reach = separated(seeded)
        if not ok or (traps is not None and traps(border(reach))):
            return None
        f0 = np.zeros(m, dtype=bool)
        f0[routes[0]] = True
        return grow(seeded, f0, 1, work)

    def seed_with(routes: list[np.ndarray], work: Work) -> bool:
        """Grow from ``routes`` (:func:`grow_from`) and keep that test where its flow is larger
        than the best so far; whether the flow upper bound is reached."""
        nonlocal flow, is_open, f, from_route
        grown = grow_from(routes, work)
        if grown is not None and grown[0] > flow:
            flow, is_open, f = grown
            from_route = True
        return flow >= upper

    graph = RouteGraph(n, src, eu, ev, usable, target)
    if route_seed is not None and flow < upper:
        # grow from one route, then from the union of two (two routes through the same
        # labelled cell in different orders can cross there without a shortcut)
        pool: list[np.ndarray] = []
        work = Work(route_seed.work)
        for route in simple_routes(graph, route_seed, work):
            for other in [None] + pool:
                if work.exhausted or seed_with([route] if other is None else [route, other], work):
                    break
            pool.append(route)
            if flow >= upper or len(pool) >= route_seed.pool or work.exhausted:
                break
    if route_seed is not None and flow < upper and upper >= 2:
        # F routes that share no place but where the history changes (and the start and
        # the goal): the idea is that with only their moves open a walk from Src follows
        # one of them between two such places, and so passes I as each route does. Not a
        # proof (two-way walls, ties and states sharing a place open more), so grow_from
        # checks the seed (random 10x10 grids with two test cells: flow 2 where the pairs
        # above give 1)
        work = Work(route_seed.work)
        for route in simple_routes(graph, route_seed, work):
            if work.exhausted:
                break
            group = disjoint_routes(graph, route_seed, route, upper, work)
            if len(group) < 2:
                continue
            if seed_with(group, work):  # group[0] is route
                break
    _, reach = separated(is_open)
    return RoutingGuess(flow, upper, f.astype(float), border(reach), reach, from_route)


@dataclass
class RouteSeed:
    """What :func:`simple_route` needs to know about the nodes of G.

    Attributes
    ----------
    place, hist
        Per node of G: the place (cell) of its state, and its history.
    intermediate
        ``bool`` per node: I.
    tries
        History sequences to try before giving up.
    pool
        Routes to combine in pairs (when one gives less than the flow's upper bound).
    per_order
        Routes to look for per order of history changes (the first with shortest
        segments, the others randomized).
    work
        Work budget, in edges visited, for finding routes and growing from them
        together (large grids with many orders that fail); deterministic, unlike a
        time cap; the default is seconds of work at most (docs/benchmarks/solvers.md,
        "The heuristic's first test").
    seed
        Seed of the randomized segments.
    """

    place: np.ndarray
    hist: np.ndarray
    intermediate: np.ndarray
    tries: int = 64
    pool: int = 12
    per_order: int = 3
    work: int = 3_000_000
    seed: int = 0


class Work:
    """A deterministic work budget: units spent (edges visited) against a limit."""

    def __init__(self, limit: int) -> None:
        self.limit = int(limit)
        self.spent = 0

    def spend(self, units: int) -> None:
        self.spent += int(units)

    @property
    def exhausted(self) -> bool:
        return self.spent >= self.limit


@dataclass(frozen=True)
class RouteGraph:
    """The part of G a route may take: ``n`` nodes, from ``src`` to a node of ``target`` over
    the edges ``eu[e] -> ev[e]`` with ``usable[e]``."""

    n: int
    src: int
    eu: np.ndarray
    ev: np.ndarray
    usable: np.ndarray
    target: np.ndarray

    def search(self, seed: RouteSeed, work: Work) -> _RouteSearch:
        """A backtracking route search over the usable edges, within ``work``."""
        ok = np.flatnonzero(self.usable)
        out_ptr, out_order = _csr(self.eu[ok], self.n)
        return _RouteSearch(self.eu, self.ev, out_ptr, ok[out_order], self.target, seed, work)


def simple_route(graph: RouteGraph, seed: RouteSeed) -> np.ndarray | None:
    """The first of :func:`simple_routes`, or ``None``."""
    return next(simple_routes(graph, seed), None)


def simple_routes(graph: RouteGraph, seed: RouteSeed, work: Work | None = None) -> Iterator[np.ndarray]:
    """``Src -> I -> Tgt`` paths of G that never return to a place, as edge indices: at most
    one per order of history changes, within the work budget ``work`` (a fresh one of
    ``seed.work`` if not given; shared with the caller's growth from the routes).

    Why: with only its moves open, a walk from ``Src`` to ``Tgt`` can do nothing but
    retrace the route, back and forth, so it sees the route's labels in the route's
    order and (for the visit patterns of a test objective) passes I too. That is a
    valid cut set with flow 1 where the greedy growth finds none, e.g. where the
    shortest route comes back through a cell and so opens its own shortcut. The
    caller still checks separation rather than rely on the argument.

    A route follows an order of history changes (:func:`_history_sequences`), one
    segment per history, each a shortest path through places no earlier segment used
    (then randomized ones, backtracking when a segment walls off the goal).
    """
    src = graph.src
    search = graph.search(seed, work if work is not None else Work(seed.work))
    for changes in _history_sequences(src, graph.eu[graph.usable], graph.ev[graph.usable], graph.target, seed):
        if search.work.exhausted:
            break
        seen: set[tuple[int, ...]] = set()
        for again in range(seed.per_order):
            search.left = _RouteSearch.BUDGET
            route = search.through(changes, 0, src, frozenset([int(seed.place[src])]), randomized=again > 0)
            if route is None:
                break
            if tuple(route) not in seen:
                seen.add(tuple(route))
                yield np.asarray(route, dtype=np.int64)


def disjoint_routes(graph: RouteGraph, seed: RouteSeed, route: np.ndarray, count: int, work: Work) -> list[np.ndarray]:
    """``route`` and up to ``count - 1`` more place-simple routes through its order of
    history changes, each sharing no place with the others but the places where a route's
    history changes, the start's and the goal's (edge indices; fewer where none is found
    within ``work``).

    Why: the moves of such routes alone open no walk past I that a single route's moves do
    not (a walk can leave a route only at a shared place, where every route has passed the
    same histories), and they carry ``count`` units of flow where the place-simple routes
    of :func:`simple_routes`, combined in pairs, cross each other and open a shortcut. The
    caller checks separation rather than rely on the argument."""
    h, place, src, eu, ev = seed.hist, seed.place, graph.src, graph.eu, graph.ev
    change = h[eu[route]] != h[ev[route]]
    changes = (int(h[src]),) + tuple(int(x) for x in h[ev[route[change]]])
    shared = {int(p) for p in place[ev[route[change]]]} | {int(place[ev[route[-1]]])}
    taken = {int(place[src])} | {int(p) for p in place[ev[route]]}
    search = graph.search(seed, work)
    group = [route]
    while len(group) < count and not work.exhausted:
        used = frozenset((taken - shared) | {int(place[src])})
        found = None
        for again in range(seed.per_order):
            search.left = _RouteSearch.BUDGET
            found = search.through(changes, 0, src, used, randomized=again > 0)
            if found is not None:
                break
        if found is None:
            break
        group.append(np.asarray(found, dtype=np.int64))
        taken |= {int(p) for p in place[ev[group[-1]]]}
    return group


def _history_sequences(src: int, eu: np.ndarray, ev: np.ndarray, target: np.ndarray, seed: RouteSeed) -> list[tuple[int, ...]]:
    """Up to ``seed.tries`` sequences of histories a ``Src -> I -> Tgt`` path of G can
    pass, each history once, shortest estimated tour first: the orders to try a route in.

    A tour's estimate adds the distances (on the places) between the places where
    its histories change. Short tours are the likely place-simple ones: a shortest
    tour through points never crosses itself.
    """
    h, place = seed.hist, seed.place
    n_hist = int(h.max()) + 1
    inter = np.zeros(n_hist, dtype=bool)
    inter[h[seed.intermediate]] = True
    final = np.zeros(n_hist, dtype=bool)
    final[h[target]] = True
    change = h[eu] != h[ev]
    steps = np.unique(np.stack([h[eu[change]], h[ev[change]], place[ev[change]]], axis=1), axis=0)
    stops = np.unique(np.concatenate([[place[src]], steps[:, 2]]))
    n_place = int(place.max()) + 1
    moves = sp.csr_matrix((np.ones(eu.size), (place[eu], place[ev])), shape=(n_place, n_place))
    dist = shortest_path(moves, unweighted=True, indices=stops)  # rows: stops
    row = {int(p): i for i, p in enumerate(stops)}
    succ: dict[int, list[tuple[int, int]]] = {}
    for a, b, p in steps.tolist():
        succ.setdefault(a, []).append((b, p))
    out: list[tuple[int, ...]] = []
    heap: list[tuple[float, tuple[int, ...], int]] = [(0.0, (int(h[src]),), int(place[src]))]
    pops = 0
    while heap and len(out) < seed.tries and pops < 200 * seed.tries:
        pops += 1
        cost, seq, at = heapq.heappop(heap)
        if final[seq[-1]]:
            if inter[list(seq)].any() and seq not in out:
                out.append(seq)
            continue
        for b, p in succ.get(seq[-1], []):
            d = dist[row[at], p]
            if b not in seq and np.isfinite(d):
                heapq.heappush(heap, (cost + float(d), seq + (b,), p))
    return out


class _RouteSearch:
    """Backtracking over segment candidates for :func:`simple_route`, with a budget."""

    CANDIDATES = 4  # per segment: the shortest, then randomized ones
    BUDGET = 40  # segment searches per history sequence

    def __init__(
        self,
        eu: np.ndarray,
        ev: np.ndarray,
        ptr: np.ndarray,
        order: np.ndarray,
        target: np.ndarray,
        seed: RouteSeed,
        work: Work,
    ) -> None:
        self.eu, self.ev, self.ptr, self.order = eu, ev, ptr, order
        self.target, self.place, self.hist = target, seed.place, seed.hist
        self.rng = np.random.default_rng(seed.seed)
        self.left = self.BUDGET
        self.work = work

    def through(self, changes: tuple[int, ...], k: int, cur: int, used: frozenset[int], randomized: bool = False) -> list[int] | None:
        """Segments ``k..`` of a place-simple route from ``cur`` through the histories
        ``changes`` (the last one a target history); ``randomized``: no shortest
        segment first, for another route through the same order."""
        h, nxt = changes[k], changes[k + 1]
        last = k + 1 == len(changes) - 1

        def goal(v: int) -> bool:
            return int(self.hist[v]) == nxt and int(self.place[v]) not in used

        def inside(v: int) -> bool:
            return int(self.hist[v]) == h and int(self.place[v]) not in used

        seen: set[tuple[int, ...]] = set()
        for c in range(self.CANDIDATES):
            if self.left <= 0 or self.work.exhausted:
                return None
            self.left -= 1
            seg = _shortest(self, cur, goal, inside, None if c == 0 and not randomized else self.rng)
            if seg is None:
                return None
            key = tuple(seg)
            if key in seen:
                continue
            seen.add(key)
            places = [int(self.place[self.ev[e]]) for e in seg]
            if len(set(places)) < len(places):
                continue
            if last:
                return seg
            end = int(self.ev[seg[-1]])
            now_used = used.union(places)
            if _shortest(self, end, lambda v: bool(self.target[v]), self._outside(now_used)) is None:
                continue  # this segment walls the goal off
            rest = self.through(changes, k + 1, end, now_used, randomized)
            if rest is not None:
                return seg + rest
        return None

    def _outside(self, used: frozenset[int]) -> Callable[[int], bool]:
        """Whether a node's place is outside ``used`` (bound now, not at call time)."""
        return lambda v: int(self.place[v]) not in used


def _shortest(
    graph: _RouteSearch,
    start: int,
    goal: Callable[[int], bool],
    inside: Callable[[int], bool],
    rng: np.random.Generator | None = None,
) -> list[int] | None:
    """Edges of a shortest path from ``start`` to a ``goal`` node whose inner nodes are
    ``inside``: fewest edges, or with ``rng`` under random edge lengths in [1, 3)."""
    ptr, order, head, tail = graph.ptr, graph.order, graph.ev, graph.eu
    graph.work.spend(1)
    via = {start: -1}
    dist = {start: 0.0}
    heap: list[tuple[float, int]] = [(0.0, start)]
    done: set[int] = set()
    while heap:
        du, u = heapq.heappop(heap)
        if u in done:
            continue
        done.add(u)
        if u != start and goal(u):
            path = []
            while u != start:
                path.append(via[u])
                u = int(tail[via[u]])
            return path[::-1]
        if u != start and not inside(u):
            continue
        graph.work.spend(int(ptr[u + 1] - ptr[u]))
        for k in range(ptr[u], ptr[u + 1]):
            e = int(order[k])
            v = int(head[e])
            dv = du + (1.0 if rng is None else 1.0 + 2.0 * rng.random())
            if v not in done and dv < dist.get(v, np.inf):
                dist[v], via[v] = dv, e
                heapq.heappush(heap, (dv, v))
    return None


def _augmenting_path(
    n: int,
    src: int,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    usable: np.ndarray,
    f: np.ndarray,
    is_open: np.ndarray,
    forbidden: np.ndarray,
    target: np.ndarray,
    out_ptr: np.ndarray,
    out_order: np.ndarray,
    in_ptr: np.ndarray,
    in_order: np.ndarray,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Residual ``src -> Tgt`` path opening the fewest new groups (0-1 BFS).

    Returns the edges of the path and, per edge, whether it is used forward (a new
    unit of flow) or backward (flow cancelled).
    """
    inf = np.iinfo(np.int64).max
    dist = np.full(n, inf, dtype=np.int64)
    via = np.full(n, -1, dtype=np.int64)
    fwd = np.zeros(n, dtype=bool)
    allowed = usable & ~f & (is_open[grp] | ~forbidden[grp])
    cost = (~is_open[grp]).astype(np.int64)
    dist[src] = 0
    dq: deque[int] = deque([src])
    while dq:
        u = dq.popleft()
        du = dist[u]
        if target[u]:
            break
        for k in range(out_ptr[u], out_ptr[u + 1]):
            e = out_order[k]
            if not allowed[e]:
                continue
            v = ev[e]
            nd = du + cost[e]
            if nd < dist[v]:
                dist[v], via[v], fwd[v] = nd, e, True
                (dq.appendleft if cost[e] == 0 else dq.append)(v)
        for k in range(in_ptr[u], in_ptr[u + 1]):
            e = in_order[k]
            if not f[e]:
                continue
            v = eu[e]
            if du < dist[v]:
                dist[v], via[v], fwd[v] = du, e, False
                dq.appendleft(v)
    reached = np.flatnonzero(target & (dist < inf))
    if reached.size == 0:
        return None
    t = reached[np.argmin(dist[reached])]
    edges, forward = [], []
    v = t
    seen = 0
    while v != src:
        e = via[v]
        edges.append(e)
        forward.append(fwd[v])
        v = eu[e] if fwd[v] else ev[e]
        seen += 1
        if seen > 4 * n:  # a cycle through cancelled flow: give up on this path
            return None
    return np.array(edges, dtype=np.int64), np.array(forward, dtype=bool)
