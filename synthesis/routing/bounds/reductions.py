"""Reductions of the routing model's cut groups before any solver runs.

:func:`reduce_groups` returns plain data: a ``bool`` mask over the cut groups, *fixed open*
(``d = 0``), with the rule that fixed each group. :func:`synthesis.routing.model.build_model`
applies it as column bounds (upper bound 0 on the group's binary), so every backend that
reads the model gets it; a backend that builds its own formulation from the cut groups
reads :attr:`Reductions.fixed_open` (or ``RoutingModel.reductions``) and leaves those groups
open.

Terms, on the model's edges of G (:class:`~synthesis.routing.groups.ModelEdges`): a **bypass
walk** is a walk ``Src -> Tgt`` over c5 edges (both ends outside I); a **route** is a walk
``Src -> Tgt`` over model edges that visits I. Walks, not simple paths: every statement
about all walks holds for all simple paths, and walks are decided by two graph searches.
A cut set ``S`` (the groups with ``d = 1``) is *valid* when every bypass walk uses an edge
of ``S``. Facts used below, for a valid ``S`` and a flow of the model under ``S`` (c2, c3):

* (F1) removing the flow's cycles keeps ``F``; what is left is ``F`` paths ``Src -> Tgt``
  over edges of no group of ``S``, and each visits I (one that did not would be a bypass
  walk without a cut edge). So every flow path is a route avoiding ``S``.
* (F2) the cost of ``S`` (phase 2) is ``sum_{g in S} weight[g]``, every weight >= 1.

The rules, each fixing only groups that some optimum (for rules 1 and 2: every optimum)
leaves open, so the optimum of docs/method.md §5 is kept (``tests/synthesis/test_reductions.py`` checks
each against brute force on tiny instances):

1. **Never needed.** A group with no edge on any bypass walk. For a valid ``S`` holding it,
   ``S`` minus the group is still valid (no bypass walk used it), keeps every flow and
   feasibility flow (opening only adds moves; exclusion rows and MILP-agent's ``d_state``
   rows only loosen) and costs less (F2). So no optimum closes it. Every mode.
2. **Never closed.** A group on every route (no route is left once its edges are removed).
   By F1 a solution closing it has ``F = 0``, and every test has ``F >= 1``; so no test
   closes it. If the maximum flow is 0 the problem has no test with or without the rule
   (the solve raises ``unroutable`` either way). Every mode.
3. **Dominated** (MILP-static only: no feasibility flows, no ``closed_loop``, no MILP-agent
   places, no exclusions). Group ``a`` is dominated by a group ``b`` with a binary when
   (i) every bypass walk with an edge of ``a`` has an edge of ``b`` (``a`` has no edge on a
   bypass walk once ``b``'s edges are removed), (ii) every route with an edge of ``b`` has
   an edge of ``a`` (``b`` has no edge on a route once ``a``'s edges are removed), and
   (iii) ``b`` ranks below ``a``: ``(weight[b], b) < (weight[a], a)``.

   *Proof that fixing every dominated group open keeps an optimum.* Let ``S`` be an optimum
   closing a dominated ``a``, dominated by ``b``, and ``S' = S - {a} + {b}``. Valid: a
   bypass walk through ``a`` uses ``b`` (i), which ``S'`` closes; any other keeps its cut
   edge of ``S``. Flow: by F1 the flow of ``S`` is routes avoiding ``a``; by (ii) none of
   them uses ``b``, so the same flow is a flow under ``S'`` (MILP-static has no other
   constraint on the cuts), ``F(S') >= F(S)``. Cost: ``weight[b] <= weight[a]`` (iii).
   So ``S'`` is an optimum too, and ``sum_{g in S} rank(g)`` drops strictly (``b`` ranks
   below ``a``, or ``b`` was already in ``S``). Repeating ends at an optimum closing no
   dominated group; it is feasible for the reduced model, so the reduced optimum equals
   the full one. The rank order makes the relation acyclic, so two groups can never fix
   each other open. (Rules 1 and 2 hold for *every* optimum, so they combine with it.)

Symmetric grids: no rule. Wall symmetry of an empty grid is broken by the start, goal and
labelled cells of every instance, so an orbit-based rule would rarely apply; none is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from ...graphs.products import Products, coreachable, reachable

#: Static models with more cut groups with a binary than this skip the dominance rule: it
#: costs four graph searches per group, seconds on the 10x10 grids' walls, and fixed none there
#: (docs/benchmarks/solvers.md, "Cut-group reductions"). A count, so the model stays
#: deterministic.
DOMINANCE_MAX_GROUPS = 100


@dataclass(frozen=True)
class Reductions:
    """Which cut groups the reductions fix open, and by which rule.

    Attributes
    ----------
    never_needed, never_closed, dominated
        ``bool`` per cut group: fixed open by rule 1, 2 or 3 (see the module docstring);
        a group is counted under the first rule that fixes it.
    dominator
        ``int`` per cut group: for a dominated group, the group ``b`` of rule 3; else -1.
    checked_dominance
        Whether rule 3 ran (MILP-static with at most :data:`DOMINANCE_MAX_GROUPS` groups).
    """

    never_needed: np.ndarray
    never_closed: np.ndarray
    dominated: np.ndarray
    dominator: np.ndarray
    checked_dominance: bool

    @property
    def fixed_open(self) -> np.ndarray:
        """``bool`` per cut group: its ``d`` is fixed to 0."""
        out: np.ndarray = self.never_needed | self.never_closed | self.dominated
        return out

    def counts(self) -> dict[str, int]:
        """How many groups each rule fixed open (for the solve's statistics)."""
        return {
            "never_needed": int(self.never_needed.sum()),
            "never_closed": int(self.never_closed.sum()),
            "dominated": int(self.dominated.sum()),
        }

    @classmethod
    def none(cls, n_groups: int) -> Reductions:
        """No group fixed (the reductions switched off)."""
        z = np.zeros(n_groups, dtype=bool)
        return cls(z, z.copy(), z.copy(), np.full(n_groups, -1, dtype=np.int64), False)


def reduce_groups(
    products: Products,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    c5: np.ndarray,
    has_var: np.ndarray,
    weight: np.ndarray,
    dominance: bool,
) -> Reductions:
    """Apply rules 1-3 to the cut groups of a routing model (see the module docstring).

    Parameters
    ----------
    products
        The product graphs (``Src``, ``I``, ``Tgt`` and the node count of G).
    eu, ev, grp, c5, has_var
        The model's edges, their cut groups, which are c5 edges, and which groups have a
        binary (:class:`~synthesis.routing.groups.ModelEdges`).
    weight
        Edges of G per cut group (the phase-2 cost).
    dominance
        Whether rule 3 may run (the caller knows the model is MILP-static with no
        feasibility flows, places or exclusions).
    """
    n, src = products.virtual.n_nodes, int(products.virtual.initial)
    inter, target = products.intermediate, products.target
    n_groups = has_var.size
    everything = np.ones(eu.size, dtype=bool)

    on_bypass = _bypass_groups(n, src, eu, ev, grp, c5, target, everything, n_groups)
    never_needed = has_var & ~on_bypass

    never_closed = np.zeros(n_groups, dtype=bool)
    path = _one_route(n, src, eu, ev, inter, target)
    if path is not None:
        for k in np.unique(grp[path]):
            if has_var[k] and not never_needed[k]:
                never_closed[k] = not _route_groups(n, src, eu, ev, grp, inter, target, grp != k, n_groups).any()

    dominated = np.zeros(n_groups, dtype=bool)
    dominator = np.full(n_groups, -1, dtype=np.int64)
    free = np.flatnonzero(has_var & ~never_needed & ~never_closed)
    checked = dominance and free.size <= DOMINANCE_MAX_GROUPS
    if checked and free.size > 1:
        rank = np.lexsort((np.arange(n_groups), weight))  # groups by (weight, index)
        position = np.empty(n_groups, dtype=np.int64)
        position[rank] = np.arange(n_groups)
        # bypass_without[i, j]: free[j] has an edge on a bypass walk once free[i] is removed
        bypass_without = np.stack([_bypass_groups(n, src, eu, ev, grp, c5, target, grp != b, n_groups)[free] for b in free])
        route_without = np.stack([_route_groups(n, src, eu, ev, grp, inter, target, grp != a, n_groups)[free] for a in free])
        for j, a in enumerate(free):
            # (i) a off every bypass walk without b; (ii) b off every route without a; (iii) rank
            ok = ~bypass_without[:, j] & ~route_without[j, :] & (position[free] < position[a])
            if ok.any():
                b = free[np.flatnonzero(ok)]
                dominated[a] = True
                dominator[a] = int(b[np.argmin(position[b])])
    return Reductions(never_needed, never_closed, dominated, dominator, checked)


def _bypass_groups(
    n: int,
    src: int,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    c5: np.ndarray,
    target: np.ndarray,
    keep: np.ndarray,
    n_groups: int,
) -> np.ndarray:
    """``bool`` per group: some edge of it lies on a bypass walk over the kept edges."""
    e = np.flatnonzero(c5 & keep)
    fwd = reachable(n, eu[e], ev[e], np.arange(n) == src)
    back = coreachable(n, eu[e], ev[e], target)
    out = np.zeros(n_groups, dtype=bool)
    out[grp[e[fwd[eu[e]] & back[ev[e]]]]] = True
    return out


def _layered(n: int, src: int, eu: np.ndarray, ev: np.ndarray, inter: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The route graph: node ``v + L n`` is node ``v`` with I visited (``L = 1``) or not yet.

    Returns the layered edges' tails and heads, the G edge of each, and the layered start."""
    tails = np.concatenate([eu, eu + n])
    heads = np.concatenate([ev + n * inter[ev], ev + n])
    return tails, heads, np.concatenate([np.arange(eu.size), np.arange(eu.size)]), src + n * int(inter[src])


def _route_groups(
    n: int,
    src: int,
    eu: np.ndarray,
    ev: np.ndarray,
    grp: np.ndarray,
    inter: np.ndarray,
    target: np.ndarray,
    keep: np.ndarray,
    n_groups: int,
) -> np.ndarray:
    """``bool`` per group: some edge of it lies on a route over the kept edges."""
    e = np.flatnonzero(keep)
    tails, heads, of, start = _layered(n, src, eu[e], ev[e], inter)
    fwd = reachable(2 * n, tails, heads, np.arange(2 * n) == start)
    goal = np.concatenate([np.zeros(n, dtype=bool), target])
    back = coreachable(2 * n, tails, heads, goal)
    out = np.zeros(n_groups, dtype=bool)
    out[grp[e[of[fwd[tails] & back[heads]]]]] = True
    return out


def _one_route(n: int, src: int, eu: np.ndarray, ev: np.ndarray, inter: np.ndarray, target: np.ndarray) -> np.ndarray | None:
    """The model edges between consecutive nodes of one route (every parallel edge), or
    ``None`` if there is no route. A group on every route has an edge among them."""
    tails, heads, _, start = _layered(n, src, eu, ev, inter)
    adj = sp.csr_matrix((np.ones(tails.size, dtype=np.int8), (tails, heads)), shape=(2 * n, 2 * n))
    order, pred = breadth_first_order(adj, start, directed=True, return_predecessors=True)
    ends = order[order >= n]
    ends = ends[target[ends - n]]
    if ends.size == 0:
        return None
    nodes = [int(ends[0])]
    while nodes[-1] != start:
        nodes.append(int(pred[nodes[-1]]))
    plain = np.asarray(nodes[::-1], dtype=np.int64) % n
    key = eu.astype(np.int64) * n + ev
    return np.flatnonzero(np.isin(key, plain[:-1] * n + plain[1:]))
