"""When no test fits the caps: how few physical restrictions a test needs.

The caps (``max_walls``, ``max_doors``, ``max_restrictions``; :attr:`MilpOptions.caps`)
are rows of the routing model (:class:`~synthesis.routing.model.CapRows`). When the capped
solve finds no test, :func:`fewest_within` answers the user's next question, *how many
would do?*: the fewest walls (doors, restrictions) of any cut set that routes flow >= 1,
the other caps kept, as the routing model's own optimum (every row of docs/method.md §5, all
feasibility flows up front), so the figure is the one a cap must allow. The solve is
bounded by a deadline; stopped early it gives HiGHS's proven lower bound.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import highspy
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from ..graphs.consistency import check_consistency
from ..graphs.products import Products
from ..model.errors import InconsistentProblem
from .model import build_model, cut_groups, model_edges, physical_items
from .options import MilpOptions
from .result import required_entries
from .solver_control import quiet_highs, run_highs

CAP_NOUNS = {"max_walls": "walls", "max_doors": "doors", "max_restrictions": "restrictions (walls and doors)"}
"""What each cap counts, for messages."""

FEWEST_SECONDS = 30.0
"""The most seconds :func:`fewest_within` spends when the caller gives no deadline."""


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
