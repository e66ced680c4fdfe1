"""The routing MILP's own trap search: which entry nodes an answer leaves without a way to
the goal. It generates the MILP's lazy feasibility rows (c6-c8 of the histories an answer
traps) and tests the heuristic's cut sets.

It is deliberately not :mod:`synthesis.checks.verify`: the checks must not share code with
what they check, or a bug in a trap search would make the solver and its checker agree.
The two share only the pure graph primitive :func:`synthesis.graphs.products.coreachable`
(a breadth-first search) and compute differently: the checks run one search per history
on ``G_sys`` from the test strategy an environment enforces; this module stacks the
histories as disjoint layers of one graph and runs a single search over all of them
(in chunks that bound memory), from the MILP's own restrictions
(:func:`synthesis.routing.result.blocked_by`). ``tests/synthesis/test_checks_independent.py`` holds
this to account: a lazy-row generator that misses a trap is caught by the checks.
"""

from __future__ import annotations

import numpy as np

from ..graphs.products import Products, coreachable, reachable

LAYER_EDGES = 4_000_000
"""Most edge copies (histories x ``G_sys`` edges) one stacked search holds."""


def trapped_entries(products: Products, blocked: np.ndarray, entries: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """Per history ``q`` of ``entries`` (in its order), the listed ``G_sys`` nodes with no way
    to ``Tgt_sys`` over the moves not restricted under ``q`` (``blocked[q, m]``); histories
    without such a node are left out."""
    gs = products.system
    n, m = gs.n_nodes, gs.src.size
    histories = np.fromiter(entries, dtype=np.int64, count=len(entries))
    alive = np.zeros((histories.size, n), dtype=bool)
    per_chunk = max(1, LAYER_EDGES // max(m, 1))
    for start in range(0, histories.size, per_chunk):
        chunk = histories[start : start + per_chunk]
        layer, edge = np.nonzero(~blocked[chunk][:, gs.move])
        offset = layer.astype(np.int64) * n
        targets = np.tile(products.system_target, chunk.size)
        ok = coreachable(chunk.size * n, offset + gs.src[edge], offset + gs.dst[edge], targets)
        alive[start : start + chunk.size] = ok.reshape(chunk.size, n)
    out: dict[int, np.ndarray] = {}
    for row, (q, nodes) in enumerate(entries.items()):
        bad = nodes[~alive[row, nodes]]
        if bad.size:
            out[int(q)] = bad
    return out


def trapped_configurations(products: Products, blocked: np.ndarray) -> np.ndarray:
    """Nodes of G the restrictions trap: reachable from ``Src`` under them (each move with
    the history of its tail), with a way to ``Tgt`` in G but none under them."""
    g = products.virtual
    open_ = ~blocked[g.hist[g.src], g.move]
    src, dst = g.src[open_], g.dst[open_]
    start = np.zeros(g.n_nodes, dtype=bool)
    start[g.initial] = True
    under = reachable(g.n_nodes, src, dst, start)
    return np.flatnonzero(under & coreachable(g.n_nodes, g.src, g.dst, products.target) & ~coreachable(g.n_nodes, src, dst, products.target))
