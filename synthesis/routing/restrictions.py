"""From a routing answer to a test strategy (docs/method.md §6): the cut edges of G outside
``E(I)`` become the restrictions ``C(q)`` of their tail's history, the static cuts the
static obstacles."""

from __future__ import annotations

import numpy as np

from ..graphs.products import Products
from ..model.strategy import TestStrategy
from .result import RoutingResult


def strategy_from_routing(products: Products, routing: RoutingResult, setting: str) -> TestStrategy:
    """``C(q)`` per history and the static obstacles, as a test strategy (docs/method.md §6)."""
    g, ts = products.virtual, products.ts
    e = routing.cut_edges
    e = e[~products.touches_intermediate[e]]
    restrictions = np.zeros((g.n_hist, ts.n_moves), dtype=bool)
    restrictions[g.hist[g.src[e]], g.move[e]] = True
    return TestStrategy(routing.static_moves_cut.copy(), restrictions, setting)
