"""A fast primal heuristic for the routing MILP: open cut groups greedily, flow first.

A cut set is valid (c5) iff the *open* groups leave no ``Src -> Tgt`` path outside I.
Adding open groups can only help the flow and only hurt separation, so the heuristic
grows a set of open groups one augmenting path at a time: each augmenting path of the
flow (in the residual graph, fewest newly opened groups first, by 0-1 BFS) is accepted
when opening its groups keeps ``Src`` separated from ``Tgt`` outside I, and its groups
are forbidden otherwise. The cut set returned is then only what separation needs: the
groups on the border of the region reachable from ``Src`` outside I.

Every valid solution carries no flow on an edge from outside I straight into ``Tgt``,
so the maximum flow without those edges is an upper bound on F; when the heuristic
reaches it, phase 1 of the MILP is proven without solving it.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import maximum_flow

from .products import reachable


@dataclass
class RoutingGuess:
    """A valid cut set with its flow, for the model's edges."""

    flow: int
    upper_bound: int
    edge_flow: np.ndarray  # 0/1 per model edge
    cut_groups: np.ndarray  # bool per group
    reach: np.ndarray  # bool per node of G: reachable from Src outside I over open edges


def flow_upper_bound(n: int, src: int, eu: np.ndarray, ev: np.ndarray, usable: np.ndarray, target: np.ndarray) -> int:
    """Maximum flow ``src -> target`` over the usable edges (unit capacities)."""
    e = np.flatnonzero(usable)
    t = np.flatnonzero(target)
    rows = np.concatenate([eu[e], t])
    cols = np.concatenate([ev[e], np.full(t.size, n)])
    caps = np.concatenate([np.ones(e.size, dtype=np.int32), np.full(t.size, max(e.size, 1), dtype=np.int32)])
    cap = sp.csr_matrix((caps, (rows, cols)), shape=(n + 1, n + 1))
    return int(maximum_flow(cap, src, n).flow_value)


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
    """
    m = eu.size
    usable = ~(c5 & target[ev])
    upper = flow_upper_bound(n, src, eu, ev, usable, target)
    is_open = ~has_var
    forbidden = np.zeros(has_var.size, dtype=bool)
    f = np.zeros(m, dtype=bool)
    out_ptr, out_order = _csr(eu, n)
    in_ptr, in_order = _csr(ev, n)
    tgt_nodes = target

    def separated(open_mask: np.ndarray) -> tuple[bool, np.ndarray]:
        keep = c5 & open_mask[grp]
        reach = reachable(n, eu[keep], ev[keep], np.arange(n) == src)
        return not np.any(reach & target), reach

    def border(reach: np.ndarray) -> np.ndarray:
        cut = np.zeros(has_var.size, dtype=bool)
        cut[grp[c5 & reach[eu] & ~reach[ev]]] = True
        return cut

    ok, reach = separated(is_open)
    if not ok:  # even cutting every cuttable group leaves a path outside I
        return RoutingGuess(0, upper, f.astype(float), np.zeros(has_var.size, dtype=bool), np.zeros(n, dtype=bool))
    trapping = traps is not None and traps(border(reach))
    flow = 0
    for _ in range(max_rounds):
        if flow >= upper:
            break
        path = _augmenting_path(n, src, eu, ev, grp, usable, f, is_open, forbidden, tgt_nodes, out_ptr, out_order, in_ptr, in_order)
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
    _, reach = separated(is_open)
    return RoutingGuess(flow, upper, f.astype(float), border(reach), reach)


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
