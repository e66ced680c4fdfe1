"""A first test within the caps (:func:`capped_guess`, handed to phase 1 by
:func:`start_within_caps`): the routing heuristic keeps the flow high and may use more walls or
doors than a cap allows; this search goes from few restrictions to a route (minimum cuts of the
bypasses, cut again around what a route and a trapped history need open), so the solver has a
test within the caps to start from and fall back on. :func:`fewer_items` closes a test's bypasses
with fewer items, for the search and for :func:`~synthesis.routing.caps.fewest.found_with`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ...graphs.cuts import min_cut
from ...graphs.products import Products, reachable
from ..bounds.heuristic import RoutingGuess, guess_routing, usable_edges
from ..groups import CutGroups, PhysicalItems
from ..model import RoutingModel
from ..options import MilpOptions
from ..phases import guess_solution, trap_test
from ..result import blocked_of_edges
from ..traps import trapped_entries
from .bypasses import zero_one_path

CAPPED_ROUNDS = 400
"""The most minimum cuts :func:`capped_guess` tries (each keeps open the moves the last one
closed on the cheapest route): a deterministic budget, never a clock, so the same model gives
the same start on every machine."""

CAPPED_ATTEMPTS = 8
"""How many times :func:`capped_guess` starts over (each breaking ties its own way) within
:data:`CAPPED_ROUNDS` rounds in all."""

_INF = 1 << 26  # the capacity of an edge no cut may close (far above any finite cut)
_COUNTED = 64  # the capacity of an edge whose cut uses an item a cap counts
_FREE = 1  # ... of one whose item no cap counts (a wall under a cap on doors): cheap, not free


def capped_guess(
    products: Products,
    rm: RoutingModel,
    options: MilpOptions,
    entries: dict[int, np.ndarray] | None = None,
    deadline: float | None = None,
    keep_best: bool = False,
) -> RoutingGuess | None:
    """A test within the caps to start a capped solve from, where the routing heuristic's test
    (:meth:`RoutingModel.guess`) uses more walls or doors than a cap allows; ``None`` where
    none is found.

    The heuristic keeps the flow high and cuts whatever that needs; under a tight cap the
    solver then starts from nothing, and on a large floor may find no test at all within its
    time limit. This search goes the other way, from few restrictions to a route:

    1. a minimum cut of the bypasses (every ``Src -> Tgt`` walk outside I, docs/method.md c4-c5),
       each edge costing what its cut group uses of the caps, the groups kept open uncut;
    2. the heuristic's own growth (:func:`~synthesis.routing.bounds.heuristic.guess_routing`)
       on that cut set alone: the largest flow it lets through while every bypass stays
       closed (and no entry node of ``entries`` trapped: the feasibility flows the solve
       holds), cutting only the border of
       what ``Src`` reaches;
    3. if no route is left open (the cut walls in ``Src`` or the goal), the cheapest route
       from ``Src`` through I to ``Tgt`` (fewest groups of the cut on it) keeps those groups
       open from now on, and the next round cuts around them (a trapped history keeps open
       the groups that close its way out).

    A door counts once however many histories it is closed under, so where a door stands for
    several cut groups every other attempt is *tied*: each group costs its share of the door,
    and a cut closes the whole door (every group of it still allowed to close).

    It stops at the first test within every cap. A test over a cap is handed to
    :func:`fewer_items` (a local search that closes its bypasses with fewer items: on the
    30x30 rack floor 13 walls become 9); still over, it ends the attempt (keeping more open
    only adds cuts), and the search starts over with the route search's ties broken
    another way, up to :data:`CAPPED_ATTEMPTS` attempts and :data:`CAPPED_ROUNDS` rounds in
    all, and never past ``deadline`` (a ``perf_counter`` time: the solve's time limit holds). A start,
    not an answer: the solver checks it as a whole solution and improves on it. With
    ``keep_best``, where no test fits, the test over the caps with the fewest items they
    count that the search met (after :func:`fewer_items`) instead of ``None``.

    Example::

        guess = capped_guess(products, rm, options)
        if guess is not None:
            x = guess_solution(products, rm, guess, options)  # within every cap
    """
    caps = rm.caps
    if caps is None or not options.caps:
        return None
    traps = trap_test(products, rm.groups, entries or {})
    g = products.virtual
    me, groups = rm.edges, rm.groups
    n, src, target = g.n_nodes, int(g.initial), products.target
    cuttable = me.has_var & ~rm.reductions.fixed_open
    item = caps.items.of_group
    prices = _group_prices(caps.items, options)
    cost, tied_cost, tie = prices.cost, prices.tied_cost, prices.tie
    c5 = np.flatnonzero(me.c5)
    eu5, ev5, grp5 = me.eu[c5], me.ev[c5], me.grp[c5]
    usable = usable_edges(me.c5, me.ev, target)
    rounds = 0
    best: tuple[int, np.ndarray] | None = None  # the fewest counted items of a test over the caps, and its cut

    def fallback() -> RoutingGuess | None:
        if not keep_best or best is None:
            return None
        return guess_routing(n, src, me.eu, me.ev, me.grp, me.c5, me.has_var & best[1], target, traps=traps)

    for attempt in range(CAPPED_ATTEMPTS):
        # each attempt breaks the route search's ties its own way (random edge lengths from a
        # fixed seed: the same start on every machine); the first takes the shortest routes
        jitter = None if attempt // (1 + tie) == 0 else np.random.default_rng(attempt).integers(1, 8, size=me.eu.size)
        tied = tie and attempt % 2 == 0
        keep_open = np.zeros(cuttable.size, dtype=bool)
        while rounds < CAPPED_ROUNDS:
            rounds += 1
            if deadline is not None and time.perf_counter() >= deadline:
                return fallback()
            open_now = cuttable & ~keep_open
            cut = _min_bypass_cut(n, src, eu5, ev5, grp5, open_now, tied_cost if tied else cost, target)
            if cut is None:
                break  # a bypass nothing left may close: try again otherwise
            if tied:
                cut = open_now & np.isin(item, item[cut])  # every group of each door the cut closes
            crossed = _cheapest_route(n, src, me.eu, me.ev, me.grp, usable, cut, target, jitter)
            if crossed is None:
                return None  # no route at all, whatever is open
            if crossed.size == 0:
                # only the border of what Src reaches outside I needs closing; a trapped history
                # there keeps its way out open (the growth below would report flow 0)
                reach = reachable(n, eu5[~cut[grp5]], ev5[~cut[grp5]], np.arange(n) == src)
                border = np.zeros(cut.size, dtype=bool)
                border[grp5[reach[eu5] & ~reach[ev5]]] = True
                border &= cut
                if traps is not None and traps(border):
                    crossed = _way_out(products, groups, border, entries or {})
                    if crossed.size == 0:
                        break
                else:
                    guess = guess_routing(n, src, me.eu, me.ev, me.grp, me.c5, me.has_var & cut, target, traps=traps)
                    if guess.flow < 1 or (traps is not None and traps(guess.cut_groups)):
                        break  # cannot happen: the border routes and traps nothing; try again otherwise
                    if caps.items.over_cap(guess.cut_groups, options.caps):
                        # a test, over a cap: the local search may close its bypasses with fewer
                        fewer = fewer_items(products, rm, options, guess.cut_groups, entries, deadline)
                        if caps.items.over_cap(fewer, options.caps):
                            n_fewer = caps.items.n_counted(fewer, options.caps)
                            if best is None or n_fewer < best[0]:
                                best = (n_fewer, fewer)
                            break  # keeping more open only adds cuts; try again otherwise
                        guess = guess_routing(n, src, me.eu, me.ev, me.grp, me.c5, me.has_var & fewer, target, traps=traps)
                        if guess.flow < 1 or (traps is not None and traps(guess.cut_groups)):
                            break  # cannot happen: the smaller test routes and traps nothing
                    if rm.flow_bound is not None and rm.flow_bound < guess.upper_bound:
                        guess = replace(guess, upper_bound=rm.flow_bound)  # as RoutingModel.guess lowers it
                    return guess
            keep_open[crossed] = True
    return fallback()


FEWER_CUTS = 1500
"""The most minimum cuts :func:`fewer_items` tries: a deterministic budget, never a clock."""

FEWER_ROUTES = 4
"""How many routes :func:`fewer_items` spares in turn (the shortest, then others with their
ties broken by a fixed seed) before it gives up on a cut set."""


def fewer_items(
    products: Products,
    rm: RoutingModel,
    options: MilpOptions,
    cut: np.ndarray,
    entries: dict[int, np.ndarray] | None = None,
    deadline: float | None = None,
) -> np.ndarray:
    """A test (cut set, ``bool`` per group) with fewer of the items the caps count than the
    test ``cut``, where a local search finds one; else ``cut`` itself.

    The routing heuristic and :func:`capped_guess` close the bypasses around whatever route
    they keep open, and may close a corridor with four walls where two across its mouth
    would do. This search takes all, one or two of the test's items off and closes the
    bypasses that opens again with a minimum cut (:func:`_min_bypass_cut`) in which the rest
    of the test costs nothing and the groups of one route ``Src -> I -> Tgt`` the test leaves open
    are never cut (where a door stands for several cut groups, the new cut closes each of
    its doors under every history the route leaves it to). The new cut set keeps only what
    separation needs (the rest of the test
    off its border is dropped with it), closes every bypass (the cut is finite), leaves that
    route open (flow >= 1) and is kept when it traps no entry node of ``entries`` and counts
    fewer items; the search then starts again from it, until no removal helps under any of
    :data:`FEWER_ROUTES` routes or :data:`FEWER_CUTS` cuts are spent (or ``deadline``, a
    ``perf_counter`` time). Every answer is a valid test; the fewest is not promised.

    Example::

        smaller = fewer_items(products, rm, milp, guess.cut_groups, entries)
    """
    if rm.caps is None:
        return cut
    g = products.virtual
    me = rm.edges
    n, src, target = g.n_nodes, int(g.initial), products.target
    item = rm.caps.items.of_group
    prices = _group_prices(rm.caps.items, options)
    counted, cost, tie = prices.counted, prices.tied_cost, prices.tie
    cuttable = me.has_var & ~rm.reductions.fixed_open
    c5 = np.flatnonzero(me.c5)
    eu5, ev5, grp5 = me.eu[c5], me.ev[c5], me.grp[c5]
    usable = np.flatnonzero(usable_edges(me.c5, me.ev, target))
    traps = trap_test(products, rm.groups, entries or {})
    start = np.arange(n) == src

    def n_items(c: np.ndarray) -> int:
        return int(np.unique(item[c & counted]).size)

    best, best_n, spent = cut.copy(), n_items(cut), 0
    improved = True
    while improved:
        improved = False
        for attempt in range(FEWER_ROUTES):
            jitter = None if attempt == 0 else np.random.default_rng(attempt).integers(1, 8, size=usable.size)
            path = zero_one_path(n, me.eu[usable], me.ev[usable], best[me.grp[usable]], start, target, jitter)
            if path is None:
                return best
            on_route = np.zeros(best.size, dtype=bool)
            on_route[me.grp[usable[path]]] = True
            if (on_route & best).any():
                return best  # no route open: not a test (cannot happen for a valid cut)
            if tie:  # close each door of the test under every history it may be (the route's aside)
                whole = cuttable & ~on_route & np.isin(item, item[best])
                if (whole != best).any() and n_items(whole) == best_n and not (traps is not None and traps(whole)):
                    best = whole
            used = np.unique(item[best & counted]).tolist()
            removals = [tuple(used)] + [(i,) for i in used] + [(i, j) for k, i in enumerate(used) for j in used[k + 1 :]]
            allowed = cuttable & ~on_route
            for off in removals:
                if spent >= FEWER_CUTS or (deadline is not None and time.perf_counter() >= deadline):
                    return best
                spent += 1
                base = best & ~np.isin(item, off)
                new = _min_bypass_cut(n, src, eu5, ev5, grp5, allowed, np.where(base, 0, cost), target)
                if new is not None and tie:  # a door counts once: close it under every history it may be
                    new = allowed & np.isin(item, item[new])
                if new is None or n_items(new) >= best_n or (traps is not None and traps(new)):
                    continue
                best, best_n, improved = new, n_items(new), True
                break
            if improved:
                break
    return best


@dataclass(frozen=True)
class _GroupPrices:
    """What closing each cut group costs the searches for a test within the caps:
    ``counted`` whether its item is one a cap counts (every item without caps), ``cost`` the
    capacity of its edges in a minimum cut, ``tied_cost`` the same where a door closed under
    several histories counts once (each of its groups a share of the door), ``tie`` whether
    any item stands for several groups."""

    counted: np.ndarray
    cost: np.ndarray
    tied_cost: np.ndarray
    tie: bool


def _group_prices(items: PhysicalItems, options: MilpOptions) -> _GroupPrices:
    """The :class:`_GroupPrices` of the cut groups under ``options.caps``."""
    item = items.of_group
    counted = np.zeros(item.size, dtype=bool)
    for cap in options.caps or {"max_restrictions": 0}:
        counted |= items.kinds(cap)[item]
    per_item = np.bincount(item, minlength=int(item.max(initial=-1)) + 1)
    return _GroupPrices(
        counted=counted,
        cost=np.where(counted, _COUNTED, _FREE),
        tied_cost=np.where(counted, np.maximum(1, _COUNTED // per_item[item]), _FREE),
        tie=bool((per_item > 1).any()),
    )


def start_within_caps(
    products: Products,
    rm: RoutingModel,
    options: MilpOptions,
    entries: dict[int, np.ndarray],
    guess: RoutingGuess,
    x_guess: np.ndarray | None,
    deadline: float | None,
) -> tuple[RoutingGuess, np.ndarray | None]:
    """Phase 1's start under caps: ``(guess, x_guess)`` as they are, unless the heuristic's
    test was dropped for using more than a cap allows (``x_guess`` is ``None``, the model has
    caps); then :func:`capped_guess`'s test within them, as a whole model solution
    (:func:`~synthesis.routing.phases.guess_solution`), where it finds one by ``deadline``.
    Its ``upper_bound`` is the heuristic's (so phase 1 is proven at once where it attains it).

    Example (in a backend's phase 1)::

        x_guess = guess_solution(products, rm, guess, options)
        guess, x_guess = start_within_caps(products, rm, options, entries, guess, x_guess, clock.deadline)
    """
    if x_guess is not None or rm.caps is None or not options.caps:
        return guess, x_guess
    capped = capped_guess(products, rm, options, entries, deadline)
    if capped is None:
        return guess, x_guess
    capped = replace(capped, upper_bound=min(capped.upper_bound, guess.upper_bound))
    x = guess_solution(products, rm, capped, options)
    return (capped, x) if x is not None else (guess, x_guess)


def _min_bypass_cut(
    n: int,
    src: int,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    cuttable: np.ndarray,
    cost: np.ndarray,
    target: np.ndarray,
) -> np.ndarray | None:
    """The cut groups (``bool`` per group) of a minimum ``Src -> Tgt`` cut over the bypass
    edges ``eu -> ev`` (the c5 edges), an edge of a ``cuttable`` group costing ``cost`` of its
    group, any other never cut; ``None`` when every cut is infinite (a bypass nothing may close)."""
    cap = np.where(cuttable[grp], cost[grp], _INF).astype(np.int64)
    t = np.flatnonzero(target)
    rows = np.concatenate([eu, t])
    cols = np.concatenate([ev, np.full(t.size, n)])
    caps = np.concatenate([cap, np.full(t.size, _INF, dtype=np.int64)])
    # parallel edges add up (scipy sums duplicates); capped below int32
    mat = sp.csr_matrix((caps, (rows, cols)), shape=(n + 1, n + 1))
    mat.data = np.minimum(mat.data, _INF).astype(np.int32)
    mat.indices = mat.indices.astype(np.int32)
    mat.indptr = mat.indptr.astype(np.int32)
    value, side = min_cut(mat, src, n)
    if value >= _INF:
        return None
    cut = np.zeros(cuttable.size, dtype=bool)
    crossing = side[eu] & ~side[ev]
    cut[grp[crossing]] = True
    closed: np.ndarray = cut & cuttable
    return closed


def _cheapest_route(
    n: int,
    src: int,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    usable: np.ndarray,
    cut: np.ndarray,
    target: np.ndarray,
    jitter: np.ndarray | None = None,
) -> np.ndarray | None:
    """The cut groups on a ``Src -> Tgt`` route over the ``usable`` edges (every route to
    ``Tgt`` passes I) that crosses the fewest edges of ``cut``, the shortest of those (each
    edge ``jitter`` long, default 1); empty when a route is open, ``None`` when there is no
    route at all."""
    e_ok = np.flatnonzero(usable)
    path = zero_one_path(n, eu[e_ok], ev[e_ok], cut[grp[e_ok]], np.arange(n) == src, target, None if jitter is None else jitter[e_ok])
    if path is None:
        return None
    on = e_ok[path]
    crossed: np.ndarray = np.unique(grp[on][cut[grp[on]]])
    return crossed


def _way_out(products: Products, groups: CutGroups, cut: np.ndarray, entries: dict[int, np.ndarray]) -> np.ndarray:
    """For the first history whose entry node ``cut`` traps: the cut groups that close the
    cheapest way out of it (fewest moves restricted under that history) in ``G_sys``."""
    blocked = blocked_of_edges(products, np.flatnonzero(cut[groups.of_edge]))
    trapped = trapped_entries(products, blocked, entries)
    if not trapped:
        return np.zeros(0, dtype=np.int64)
    q, nodes = next(iter(trapped.items()))
    gs = products.system
    start = np.zeros(gs.n_nodes, dtype=bool)
    start[int(nodes[0])] = True
    path = zero_one_path(gs.n_nodes, gs.src, gs.dst, blocked[q, gs.move], start, products.system_target)
    if path is None:
        return np.zeros(0, dtype=np.int64)
    moves = np.unique(gs.move[path][blocked[q, gs.move[path]]])
    g = products.virtual
    edges = np.flatnonzero((g.hist[g.src] == q) & np.isin(g.move, moves))
    out: np.ndarray = np.unique(groups.of_edge[edges])
    closing: np.ndarray = out[cut[out]]
    return closing
