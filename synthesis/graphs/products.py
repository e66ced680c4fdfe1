"""Product graphs (docs/method.md §4): the virtual product G = T x B_pi and G_sys = T x B_sys.

A product node ``(s, q)`` is numbered densely; the arrays ``state[v]`` and ``hist[v]``
give its parts. Products are built in bulk: every move of T is paired with every
automaton state at once (``q' = delta(q, L(s'))``), then only the part reachable
from the initial node ``(s0, delta(q0, L(s0)))`` is kept, renumbered in BFS order.
Stay self-loops are left out.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from ..model.systems import TransitionSystem
from .automata import DBA, SpecificationProduct


@dataclass
class ProductGraph:
    """A reachable product of a transition system and an automaton.

    Attributes
    ----------
    state, hist
        ``int32[n]``: the T state and the automaton state of each node.
    src, dst
        ``int32[m]``: the edges.
    move
        ``int32[m]``: the move of T each edge follows.
    initial
        The initial node (index 0).
    """

    state: np.ndarray
    hist: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    move: np.ndarray
    initial: int
    n_hist: int

    @property
    def n_nodes(self) -> int:
        return int(self.state.size)

    @property
    def n_edges(self) -> int:
        return int(self.src.size)

    def adjacency(self, edge_mask: np.ndarray | None = None) -> sp.csr_matrix:
        """Sparse adjacency (``A[u, v] = 1`` per edge), optionally of a subset of edges."""
        src, dst = (self.src, self.dst) if edge_mask is None else (self.src[edge_mask], self.dst[edge_mask])
        n = self.n_nodes
        return sp.csr_matrix((np.ones(src.size, dtype=np.int8), (src, dst)), shape=(n, n))

    def node_index(self) -> dict[tuple[int, int], int]:
        return {(int(s), int(q)): v for v, (s, q) in enumerate(zip(self.state, self.hist, strict=True))}

    @cached_property
    def entry_nodes(self) -> dict[int, np.ndarray]:
        """Entry nodes of each history: the initial node and the heads of history changes."""
        changed = self.hist[self.src] != self.hist[self.dst]
        heads = np.unique(np.concatenate([[self.initial], self.dst[changed]]))
        hs = self.hist[heads]
        return {int(h): heads[hs == h] for h in np.unique(hs)}


def build_product(ts: TransitionSystem, dba: DBA) -> ProductGraph:
    """The reachable synchronous product ``T x B`` (docs/method.md §4)."""
    nq = dba.n_states
    letter = ts.letter_of_state(dba.letters)
    q = np.arange(nq, dtype=np.int64)
    # all (move, q) pairs at once: tail (src, q), head (dst, delta[q, L(dst)])
    tail = (ts.src.astype(np.int64)[:, None] * nq + q[None, :]).ravel()
    head_q = dba.delta[:, letter[ts.dst]].T  # [m, nq]
    head = (ts.dst.astype(np.int64)[:, None] * nq + head_q).ravel()
    move = np.repeat(np.arange(ts.n_moves, dtype=np.int32), nq)
    n_full = ts.n_states * nq
    init = ts.initial * nq + int(dba.delta[dba.initial, letter[ts.initial]])
    order = _bfs_order(n_full, tail, head, init)
    renum = np.full(n_full, -1, dtype=np.int64)
    renum[order] = np.arange(order.size)
    keep = renum[tail] >= 0
    src = renum[tail[keep]].astype(np.int32)
    dst = renum[head[keep]].astype(np.int32)
    # sort edges by tail for locality and determinism
    perm = np.lexsort((dst, src))
    return ProductGraph(
        state=(order // nq).astype(np.int32),
        hist=(order % nq).astype(np.int32),
        src=src[perm],
        dst=dst[perm],
        move=move[keep][perm],
        initial=0,
        n_hist=nq,
    )


SMALL_PRODUCT = 50_000
"""Pairs up to which :func:`build_product` searches in plain Python (a random-grid test's
product has a few hundred: faster than building a sparse matrix for the search)."""


def _bfs_order(n: int, tail: np.ndarray, head: np.ndarray, start: int) -> np.ndarray:
    """Nodes reachable from ``start`` along ``tail -> head`` in breadth-first order, each
    node's successors in increasing order (the order of scipy's ``breadth_first_order`` on
    the canonical CSR matrix of these edges, which large graphs still use)."""
    if tail.size > SMALL_PRODUCT:
        adj = sp.csr_matrix((np.ones(tail.size, dtype=np.int8), (tail, head)), shape=(n, n))
        order: np.ndarray = breadth_first_order(adj, start, directed=True, return_predecessors=False)
        return order
    key = np.unique(tail.astype(np.int64) * n + head)  # sorted by tail, then head; duplicates once
    first = np.searchsorted(key // n, np.arange(n + 1)).tolist()
    heads = (key % n).tolist()
    seen = bytearray(n)
    seen[start] = 1
    out = [int(start)]
    i = 0
    while i < len(out):
        u = out[i]
        i += 1
        for v in heads[first[u] : first[u + 1]]:
            if not seen[v]:
                seen[v] = 1
                out.append(v)
    return np.asarray(out, dtype=np.int32)


def coreachable(n: int, src: np.ndarray, dst: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``bool[n]``: nodes with a path to some target along the edges ``src -> dst``."""
    if not np.any(targets):
        return np.zeros(n, dtype=bool)
    # reverse graph with a super node n pointing at every target
    tmask = np.flatnonzero(targets)
    rs = np.concatenate([dst, np.full(tmask.size, n)])
    rd = np.concatenate([src, tmask])
    adj = sp.csr_matrix((np.ones(rs.size, dtype=np.int8), (rs, rd)), shape=(n + 1, n + 1))
    order = breadth_first_order(adj, n, directed=True, return_predecessors=False)
    out = np.zeros(n + 1, dtype=bool)
    out[order] = True
    return out[:n]


def reachable(n: int, src: np.ndarray, dst: np.ndarray, sources: np.ndarray) -> np.ndarray:
    """``bool[n]``: nodes reachable from some source along ``src -> dst``."""
    return coreachable(n, dst, src, sources)


@dataclass
class Products:
    """Everything §4 defines: G, G_sys, the node sets and the projection.

    Attributes
    ----------
    virtual
        ``G = T x B_pi``; ``virtual.hist`` are histories (states of B_pi).
    system
        ``G_sys = T x B_sys``.
    source
        The initial node of G.
    intermediate, target
        ``bool`` masks over G: ``q_test in F_test and q_sys not in F_sys``, and ``q_sys in F_sys``.
    system_target
        ``bool`` mask over G_sys.
    projection
        ``int[n]``: the G_sys node of each G node.
    """

    ts: TransitionSystem
    spec: SpecificationProduct
    virtual: ProductGraph
    system: ProductGraph
    intermediate: np.ndarray
    target: np.ndarray
    system_target: np.ndarray
    projection: np.ndarray

    @property
    def source(self) -> int:
        return self.virtual.initial

    @cached_property
    def touches_intermediate(self) -> np.ndarray:
        """``bool[m]``: the edges ``E(I)`` of G, with an end in I."""
        g = self.virtual
        out: np.ndarray = self.intermediate[g.src] | self.intermediate[g.dst]
        return out

    @cached_property
    def system_coreachable(self) -> np.ndarray:
        """G_sys nodes from which ``Tgt_sys`` is reachable."""
        s = self.system
        return coreachable(s.n_nodes, s.src, s.dst, self.system_target)

    @cached_property
    def kept_entries(self) -> dict[int, np.ndarray]:
        """Per history, the G_sys projections of its entry nodes that can reach ``Tgt_sys``."""
        out: dict[int, np.ndarray] = {}
        for h, nodes in self.virtual.entry_nodes.items():
            proj = np.unique(self.projection[nodes])
            proj = proj[self.system_coreachable[proj]]
            if proj.size:
                out[h] = proj
        return out


def build_products(ts: TransitionSystem, spec: SpecificationProduct) -> Products:
    """Build G and G_sys and their node sets."""
    g = build_product(ts, spec.dba)
    gs = build_product(ts, spec.sys)
    acc_sys = spec.accepting_sys[g.hist]
    acc_test = spec.accepting_test[g.hist]
    # projection (s, (q_sys, q_test)) -> (s, q_sys)
    key = gs.state.astype(np.int64) * gs.n_hist + gs.hist
    order = np.argsort(key)
    want = g.state.astype(np.int64) * gs.n_hist + spec.sys_state[g.hist]
    pos = np.searchsorted(key[order], want)
    projection = order[pos]
    assert np.array_equal(key[projection], want), "projection of G must land in G_sys"
    return Products(
        ts=ts,
        spec=spec,
        virtual=g,
        system=gs,
        intermediate=acc_test & ~acc_sys,
        target=acc_sys,
        system_target=spec.sys.accepting[gs.hist, 0],
        projection=projection,
    )
