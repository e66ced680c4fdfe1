"""The caps on what a test may use: a first test within them, and what to say when none fits.

The caps (``max_walls``, ``max_doors``, ``max_restrictions``; :attr:`MilpOptions.caps`)
are rows of the routing model (:class:`~synthesis.routing.model.CapRows`). Around them:

* **A first test within the caps** (:func:`capped_guess`, handed to phase 1 by
  :func:`start_within_caps`): the routing heuristic keeps the flow high and may use more
  walls or doors than a cap allows; then this search, from few restrictions to a route
  (minimum cuts of the bypasses, cut again around what a route and a trapped history need
  open), gives the solver a test within the caps to start from and fall back on.
* **A cap below what any test needs** is refused before the solve
  (:func:`check_caps_reachable`, by :func:`disjoint_bypasses` and, sparing the route every
  test leaves open, :func:`routed_bypasses`), and a solve that finds no
  test within the caps is answered with *how many would do*: :func:`fewest_within`, the
  fewest walls (doors, restrictions) of any cut set that routes flow >= 1, the other caps
  kept, as the routing model's own optimum (every row of docs/method.md §5, all feasibility
  flows up front), bounded by a deadline (stopped early: HiGHS's proven lower bound).
* **A time limit that ends a capped solve with neither** raises :class:`CapsTimeout`, whose
  advice is a higher cap or time limit; :func:`found_with` tells a cap that gives a test.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import highspy
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ..graphs.consistency import check_consistency
from ..graphs.cuts import min_cut
from ..graphs.products import Products, reachable
from ..model.errors import InconsistentProblem
from .bounds.heuristic import RoutingGuess, guess_routing, usable_edges
from .groups import CutGroups, PhysicalItems, cut_groups, model_edges, physical_items
from .model import RoutingModel, build_model
from .options import MilpOptions
from .phases import guess_solution
from .result import blocked_of_edges, required_entries
from .separations import HistorySeparations
from .solver_control import quiet_highs, run_highs
from .traps import trapped_entries

CAP_NOUNS = {"max_walls": "walls", "max_doors": "doors", "max_restrictions": "restrictions (walls and doors)"}
"""What each cap counts, for messages."""

FEWEST_SECONDS = 30.0
"""The most seconds :func:`fewest_within` spends when the caller gives no deadline."""

FOUND_SECONDS = 15.0
"""The most seconds :func:`found_with` may take where a capped solve ended with neither a test
nor a proof (its budgets are deterministic and end it sooner: about 4 s for walls and 10 s for
doors on the 30x30 rack floor)."""

FOUND_SHARE = 0.1
"""The share of a capped synthesis's time limit kept back from the solve for :func:`found_with`
(at most :data:`FOUND_SECONDS`), so the limit holds for the message too."""


class CapsTimeout(TimeoutError):
    """A time limit that ended a capped solve with neither a test nor a proof that none fits.

    ``advice`` is what to try next: a gap (``--gap``) cannot help where no test was found, a
    higher cap or time limit can."""

    def __init__(self, message: str, advice: str = "raise the cap or --time-limit") -> None:
        super().__init__(message)
        self.advice = advice


@dataclass(frozen=True)
class Fewest:
    """The fewest items a cap counts that a test needs: ``value`` exactly when ``exact``,
    else at least ``value`` (``None``: no test at all, whatever the cap)."""

    value: int | None
    exact: bool
    timed_out: bool = False  # not exact because the deadline ended the solve (else: a relaxation's optimum)

    def text(self, noun: str) -> str:
        """``"the fewest is 5 doors"``, ``"at least 5 doors are needed"``."""
        if self.value is None:
            return f"no test routes it with any number of {noun}"
        if not self.exact and self.value == 0:
            return f"how many {noun} would do was not settled within the time left"
        if self.exact:
            return f"the fewest that does is {self.value} {noun}"
        if self.timed_out:
            return f"at least {self.value} {noun} are needed (not proven exactly within the time left)"
        return f"at least {self.value} {noun} are needed"


def fewest_within(products: Products, options: MilpOptions, cap: str, deadline: float | None = None) -> Fewest:
    """The fewest items ``cap`` counts over the cut sets with flow >= 1 that meet every other
    cap of ``options.caps`` and every row of the routing model (feasibility flows of every
    history with entry nodes, up front: no lazy rounds). ``deadline`` (``perf_counter``
    time; default :data:`FEWEST_SECONDS` from now) bounds the solve; stopped by it, the
    answer is HiGHS's proven lower bound (``exact`` false). With ``closed_loop`` or the test
    agent's places the model is a relaxation of the test's conditions, so the answer is
    a lower bound too."""
    if deadline is None:
        deadline = time.perf_counter() + FEWEST_SECONDS
    caps = {k: v for k, v in options.caps.items() if k != cap}
    caps[cap] = 10**9  # present, so its items have columns; never binding
    opts = replace(options, caps=caps, exclusions=list(options.exclusions))
    entries = required_entries(products, opts)
    rm = build_model(products, opts, entries, check_consistency(products))
    rows = rm.caps
    if rows is None:  # cannot happen: caps is not empty
        raise RuntimeError("the routing model has no cap rows")
    counted = rows.items.kinds(cap) & (rows.item_col >= 0)
    cost = np.zeros(rm.n_col)
    cost[rows.item_col[counted]] = 1.0
    lp = rm.model.to_highs(cost, maximize=False)
    h = quiet_highs(options.threads if options.threads else 1, options.random_seed)
    h.passModel(lp)
    out = rm.cols.flow[rm.out_src].astype(np.int32)
    h.addRow(1.0, highspy.kHighsInf, out.size, out, np.ones(out.size))
    # the item columns are integral at their least value; declared so, HiGHS's bound is integral
    item_cols = rows.item_col[rows.item_col >= 0].astype(np.int32)
    h.changeColsIntegrality(item_cols.size, item_cols, np.full(item_cols.size, highspy.HighsVarType.kInteger))
    try:
        run_highs(h, deadline, control=options.control, phase="the fewest restrictions a test needs")
    except TimeoutError:
        return Fewest(0, False, timed_out=True)
    status = h.getModelStatus()
    if status == highspy.HighsModelStatus.kInfeasible:
        return Fewest(None, True)
    info = h.getInfo()
    relaxed = options.closed_loop or options.block_states
    if status == highspy.HighsModelStatus.kOptimal:
        return Fewest(int(round(info.objective_function_value)), not relaxed)
    bound = float(info.mip_dual_bound)
    return Fewest(max(int(np.ceil(bound - 1e-6)), 0) if np.isfinite(bound) else 0, False, timed_out=True)


def found_with(products: Products, options: MilpOptions, cap: str, deadline: float | None = None) -> int | None:
    """How many items ``cap`` counts a test uses that :func:`capped_guess` finds under
    ``options.caps`` (every feasibility flow up front, as :func:`fewest_within`), where none
    fits: the test over the caps with the fewest items they count that its search met
    (:func:`fewer_items` applied), so a cap the user can ask for and get a test, for the
    message of a capped solve that the time limit ended with neither a test nor a proof.
    ``None`` where the search finds none (by ``deadline``, a ``perf_counter`` time). Not the
    fewest: an upper bound on it, next to the proven lower bound. Deterministic (the
    search's budgets), so the same problem names the same cap on every machine.

    Example::

        n = found_with(products, milp, "max_walls")  # 9 on the 30x30 rack floor under --max-walls 7
    """
    opts = replace(options, exclusions=list(options.exclusions))
    entries = dict(required_entries(products, opts))
    rm = build_model(products, opts, entries, check_consistency(products))
    guess = capped_guess(products, rm, opts, entries, deadline, keep_best=True)
    if guess is None or rm.caps is None:
        return None
    used = np.zeros(rm.caps.items.is_wall.size, dtype=bool)
    used[rm.caps.items.of_group[fewer_items(products, rm, opts, guess.cut_groups, entries, deadline)]] = True
    return int((used & rm.caps.items.kinds(cap)).sum())


def check_caps_reachable(products: Products, options: MilpOptions) -> dict[str, int]:
    """Refuse caps below what the problem needs before any solve: a cap ``N`` below
    :func:`disjoint_bypasses` (``N + 1`` walks around the test objective that share no item
    it counts) admits no test, nor does one below :func:`routed_bypasses` (the same count with
    the route every test leaves open spared, branched over its first and last moves), nor one
    that :class:`~synthesis.routing.separations.HistorySeparations` refutes (what a test must
    close under one history while leaving the system a way to its goal: the feasibility flows
    the bypass counts leave out).

    Returns the proven lower bound of each cap (:func:`proven_bound`), for the message of a
    solve the time limit ends with neither a test nor a proof.

    Raises
    ------
    InconsistentProblem
        ``"unroutable"``, naming the cap and the walks that prove it.
    """
    bounds: dict[str, int] = {}
    for cap, limit in options.caps.items():
        noun = CAP_NOUNS[cap].split(" (")[0]
        bg = bypass_graph(products, options, cap)  # built once for both bounds
        walks = count_disjoint_bypasses(bg, stop_above=limit)
        if walks > limit:
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {walks} {noun} are needed ({walks} ways from the start to the goal around the test objective "
                f"share no {noun[:-1]} this cap counts, and a test must close each); raise the cap or drop it",
            )
        deadline = None if options.time_limit is None else time.perf_counter() + ROUTED_SHARE * options.time_limit
        bounds[cap] = proven_bound(products, options, cap, limit, walks, deadline, bg)
        if bounds[cap] > limit:
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {limit + 1} {noun} are needed (whatever way through the test objective a test leaves open, "
                f"{limit + 1} ways from the start to the goal around the test objective share no {noun[:-1]} off that way, "
                f"and a test must close each); raise the cap or drop it",
            )
        separations = HistorySeparations(products, options, cap)  # built once for every bound tried
        while bounds[cap] <= limit and separations.exceed(bounds[cap], deadline=deadline):
            bounds[cap] += 1
        if bounds[cap] > limit:
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {limit + 1} {noun} are needed (under a history the system must pass on any way through the "
                f"test objective, a test must close every way to the goal that keeps that history while leaving the "
                f"system a way to the goal, and that takes more than {limit} {noun} whichever way is left); "
                f"raise the cap or drop it",
            )
    return bounds


def proven_bound(
    products: Products, options: MilpOptions, cap: str, limit: int, plain: int, deadline: float | None = None,
    bg: BypassGraph | None = None,
) -> int:
    """The largest ``k <= limit + 1`` proven by :func:`routed_bypasses` to be needed (``plain``,
    :func:`disjoint_bypasses`'s count, where it proves nothing more): ``limit + 1`` where no
    test fits the cap. Proves ``k + 1`` for ``k = plain, plain + 1, ...`` and stops at the
    first it cannot prove (a search that cannot prove ``k + 1`` cannot prove more, so this
    costs little more than the one search for ``limit + 1``), by ``deadline``. ``bg``: the
    :func:`bypass_graph`, where the caller has it already."""
    best = max(plain, 0)
    if bg is None:
        bg = bypass_graph(products, options, cap)  # built once for every k
    while best <= limit:
        if routed_bypasses(products, options, cap, stop_above=best, deadline=deadline, bg=bg) <= best:
            break
        best += 1
    return best


def caps_text(caps: dict[str, int]) -> str:
    """``"at most 3 doors and at most 2 walls"``."""
    def noun(k: str, n: int) -> str:
        word = CAP_NOUNS[k].split(" (")[0]
        return word[:-1] if n == 1 else word

    parts = [f"at most {n} {noun(k, n)}" for k, n in caps.items()]
    return " and ".join(parts)


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
        n=n, source=int(g.initial), target=tgt, eu=me.eu[c5], ev=me.ev[c5], grp=grp, item=items.of_group[grp],
        cuttable=me.has_var[grp], counted=items.kinds(cap), n_groups=int(groups.keys.size),
        route_eu=me.eu[r], route_ev=me.ev[r], route_grp=me.grp[r], route_ends=np.flatnonzero(tgt & after),
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
        path = _zero_one_path(bg.n, bg.eu[e], bg.ev[e], cuttable[e], start, bg.target)
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

ROUTED_SHARE = 0.25
"""The share of a synthesis's time limit :func:`routed_bypasses` may take before the solve."""


def routed_bypasses(
    products: Products, options: MilpOptions, cap: str, stop_above: int,
    searches: int = ROUTED_SEARCHES, deadline: float | None = None, bg: BypassGraph | None = None,
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
    stack: list[tuple[tuple[int, ...], tuple[int, ...], frozenset[int]]] = [
        ((bg.source,), (int(t),), frozenset()) for t in bg.route_ends[::-1]
    ]
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


# --------------------------------------------------------------------------- a first test within the caps

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
    traps = _trap_test(products, rm.groups, entries or {})
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
    traps = _trap_test(products, rm.groups, entries or {})
    start = np.arange(n) == src

    def n_items(c: np.ndarray) -> int:
        return int(np.unique(item[c & counted]).size)

    best, best_n, spent = cut.copy(), n_items(cut), 0
    improved = True
    while improved:
        improved = False
        for attempt in range(FEWER_ROUTES):
            jitter = None if attempt == 0 else np.random.default_rng(attempt).integers(1, 8, size=usable.size)
            path = _zero_one_path(n, me.eu[usable], me.ev[usable], best[me.grp[usable]], start, target, jitter)
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


def _trap_test(products: Products, groups: CutGroups, entries: dict[int, np.ndarray]) -> Callable[[np.ndarray], bool] | None:
    """Whether a cut set (``bool`` per group) traps an entry node of ``entries``."""
    if not entries:
        return None

    def traps(cut: np.ndarray) -> bool:
        return bool(trapped_entries(products, blocked_of_edges(products, np.flatnonzero(cut[groups.of_edge])), entries))

    return traps


def _min_bypass_cut(
    n: int, src: int, eu: np.ndarray, ev: np.ndarray, grp: np.ndarray, cuttable: np.ndarray, cost: np.ndarray,
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
    n: int, src: int, eu: np.ndarray, ev: np.ndarray, grp: np.ndarray, usable: np.ndarray, cut: np.ndarray,
    target: np.ndarray, jitter: np.ndarray | None = None,
) -> np.ndarray | None:
    """The cut groups on a ``Src -> Tgt`` route over the ``usable`` edges (every route to
    ``Tgt`` passes I) that crosses the fewest edges of ``cut``, the shortest of those (each
    edge ``jitter`` long, default 1); empty when a route is open, ``None`` when there is no
    route at all."""
    e_ok = np.flatnonzero(usable)
    path = _zero_one_path(n, eu[e_ok], ev[e_ok], cut[grp[e_ok]], np.arange(n) == src, target,
                          None if jitter is None else jitter[e_ok])
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
    path = _zero_one_path(gs.n_nodes, gs.src, gs.dst, blocked[q, gs.move], start, products.system_target)
    if path is None:
        return np.zeros(0, dtype=np.int64)
    moves = np.unique(gs.move[path][blocked[q, gs.move[path]]])
    g = products.virtual
    edges = np.flatnonzero((g.hist[g.src] == q) & np.isin(g.move, moves))
    out: np.ndarray = np.unique(groups.of_edge[edges])
    closing: np.ndarray = out[cut[out]]
    return closing


def _zero_one_path(
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

