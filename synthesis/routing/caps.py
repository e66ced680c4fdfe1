"""The caps on what a test may use: a first test within them, and what to say when none fits.

The caps (``max_walls``, ``max_doors``, ``max_restrictions``; :attr:`MilpOptions.caps`)
are rows of the routing model (:class:`~synthesis.routing.model.CapRows`). Around them:

* **A first test within the caps** (:func:`capped_guess`, handed to phase 1 by
  :func:`start_within_caps`): the routing heuristic keeps the flow high and may use more
  walls or doors than a cap allows; then this search, from few restrictions to a route
  (minimum cuts of the bypasses, cut again around what a route and a trapped history need
  open), gives the solver a test within the caps to start from and fall back on.
* **A cap below what any test needs** is refused before the solve
  (:func:`check_caps_reachable`, by :func:`disjoint_bypasses`), and a solve that finds no
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
from scipy.sparse.csgraph import breadth_first_order, dijkstra, maximum_flow

from ..graphs.consistency import check_consistency
from ..graphs.products import Products, reachable
from ..model.errors import InconsistentProblem
from .bounds.heuristic import RoutingGuess, guess_routing, usable_edges
from .model import CutGroups, RoutingModel, build_model, cut_groups, model_edges, physical_items
from .options import MilpOptions
from .phases import guess_solution
from .result import blocked_of_edges, required_entries
from .solver_control import quiet_highs, run_highs
from .traps import trapped_entries

CAP_NOUNS = {"max_walls": "walls", "max_doors": "doors", "max_restrictions": "restrictions (walls and doors)"}
"""What each cap counts, for messages."""

FEWEST_SECONDS = 30.0
"""The most seconds :func:`fewest_within` spends when the caller gives no deadline."""


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
    """How many items ``cap`` counts a test that :func:`capped_guess` finds uses, with ``cap``
    lifted and the other caps of ``options.caps`` kept (every feasibility flow up front, as
    :func:`fewest_within`): a cap the user can ask for and get a test, for the message of a
    capped solve that the time limit ended with neither a test nor a proof. ``None`` where
    the search finds none (by ``deadline``, a ``perf_counter`` time). Not the fewest: an
    upper bound on it, next to the proven lower bound.

    Example::

        n = found_with(products, milp, "max_walls")  # e.g. 13: --max-walls 13 gives a test
    """
    caps = {k: v for k, v in options.caps.items() if k != cap}
    caps[cap] = 10**9  # present, so its items are counted; never binding
    opts = replace(options, caps=caps, exclusions=list(options.exclusions))
    entries = dict(required_entries(products, opts))
    rm = build_model(products, opts, entries, check_consistency(products))
    guess = capped_guess(products, rm, opts, entries, deadline)
    if guess is None or rm.caps is None:
        return None
    used = np.zeros(rm.caps.items.is_wall.size, dtype=bool)
    used[rm.caps.items.of_group[guess.cut_groups]] = True
    return int((used & rm.caps.items.kinds(cap)).sum())


def check_caps_reachable(products: Products, options: MilpOptions) -> None:
    """Refuse caps far below what the problem needs before any solve: a cap ``N`` below
    :func:`disjoint_bypasses` (``N + 1`` walks around the test objective that share no item
    it counts) admits no test.

    Raises
    ------
    InconsistentProblem
        ``"unroutable"``, naming the cap and the walks that prove it.
    """
    for cap, limit in options.caps.items():
        walks = disjoint_bypasses(products, options, cap, stop_above=limit)
        if walks > limit:
            noun = CAP_NOUNS[cap].split(" (")[0]
            raise InconsistentProblem(
                "unroutable",
                f"no test with {caps_text({cap: limit})} routes every successful execution through the test objective: "
                f"at least {walks} {noun} are needed ({walks} ways from the start to the goal around the test objective "
                f"share no {noun[:-1]} this cap counts, and a test must close each); raise the cap or drop it",
            )


def caps_text(caps: dict[str, int]) -> str:
    """``"at most 3 doors and at most 2 walls"``."""
    def noun(k: str, n: int) -> str:
        word = CAP_NOUNS[k].split(" (")[0]
        return word[:-1] if n == 1 else word

    parts = [f"at most {n} {noun(k, n)}" for k, n in caps.items()]
    return " and ".join(parts)


def disjoint_bypasses(products: Products, options: MilpOptions, cap: str, stop_above: int) -> int:
    """A lower bound on the items ``cap`` counts that every test needs: the number of
    ``Src -> Tgt`` walks avoiding I (bypasses) found one after another, each over edges
    whose items no earlier walk used, and which no item the cap leaves out (a wall, for a
    cap on doors) can close. Every test closes each bypass with an item the cap counts
    (docs/method.md c4-c5), a different one for each (they share none), so it needs at least as
    many. Shortest walks first (fewest edges); stops once ``stop_above`` are found.

    Cheap (one breadth-first search of G per walk), so a cap far below what the problem
    needs is refused before any solve.
    """
    g = products.virtual
    groups = cut_groups(products, options)
    me = model_edges(products, groups, check_consistency(products))
    items = physical_items(products, groups)
    counted_item = items.kinds(cap)
    c5 = np.flatnonzero(me.c5)
    eu, ev, grp = me.eu[c5], me.ev[c5], me.grp[c5]
    cuttable = me.has_var[grp]
    item = items.of_group[grp]
    # an edge an uncounted item can close is no part of a bypass the cap must pay for
    usable = ~cuttable | counted_item[item]
    n = g.n_nodes
    src = int(g.initial)
    target = np.flatnonzero(products.target)
    found = 0
    while found <= stop_above:
        e = np.flatnonzero(usable)
        rows = np.concatenate([eu[e], target])
        cols = np.concatenate([ev[e], np.full(target.size, n)])
        adj = sp.csr_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), shape=(n + 1, n + 1))
        _, pred = breadth_first_order(adj, src, directed=True, return_predecessors=True)
        if pred[n] < 0:  # no bypass left
            break
        # the walk's edges: back from the super sink along predecessors
        path_nodes = [n]
        while path_nodes[-1] != src:
            path_nodes.append(int(pred[path_nodes[-1]]))
        path_nodes.reverse()
        walk = set(zip(path_nodes[:-2], path_nodes[1:-1], strict=True))
        on_walk = np.array([(int(a), int(b)) in walk for a, b in zip(eu[e], ev[e], strict=True)], dtype=bool)
        used = np.unique(item[e[on_walk & cuttable[e]]])
        if used.size == 0:  # a bypass nothing can close: no test at all (the solve says unroutable)
            return 0
        found += 1
        usable &= ~np.isin(item, used)
    return found


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

    It stops at the first test within every cap. A test over a cap ends an attempt (keeping
    more open only adds cuts), and the search starts over with the route search's ties broken
    another way, up to :data:`CAPPED_ATTEMPTS` attempts and :data:`CAPPED_ROUNDS` rounds in
    all, and never past ``deadline`` (a ``perf_counter`` time: the solve's time limit holds). A start,
    not an answer: the solver checks it as a whole solution and improves on it.

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
    counted = np.zeros(cuttable.size, dtype=bool)
    item = caps.items.of_group
    for cap in options.caps:
        counted |= caps.items.kinds(cap)[item]
    cost = np.where(counted, _COUNTED, _FREE)
    c5 = np.flatnonzero(me.c5)
    eu5, ev5, grp5 = me.eu[c5], me.ev[c5], me.grp[c5]
    usable = usable_edges(me.c5, me.ev, target)
    rounds = 0
    for attempt in range(CAPPED_ATTEMPTS):
        # each attempt breaks the route search's ties its own way (random edge lengths from a
        # fixed seed: the same start on every machine); the first takes the shortest routes
        jitter = None if attempt == 0 else np.random.default_rng(attempt).integers(1, 8, size=me.eu.size)
        keep_open = np.zeros(cuttable.size, dtype=bool)
        while rounds < CAPPED_ROUNDS:
            rounds += 1
            if deadline is not None and time.perf_counter() >= deadline:
                return None
            cut = _min_bypass_cut(n, src, eu5, ev5, grp5, cuttable & ~keep_open, cost, target)
            if cut is None:
                break  # a bypass nothing left may close: try again otherwise
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
                        break  # a test, over a cap: keeping more open only adds cuts; try again otherwise
                    if rm.flow_bound is not None and rm.flow_bound < guess.upper_bound:
                        guess = replace(guess, upper_bound=rm.flow_bound)  # as RoutingModel.guess lowers it
                    return guess
            keep_open[crossed] = True
    return None


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
    res = maximum_flow(mat, src, n)
    if res.flow_value >= _INF:
        return None
    residual = (mat - res.flow).tocsr()
    residual.data = (residual.data > 0).astype(np.int8)
    residual.eliminate_zeros()
    side = np.zeros(n + 1, dtype=bool)
    side[breadth_first_order(residual, src, directed=True, return_predecessors=False)] = True
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

