"""The edges of G the routing model keeps (docs/method.md §5), and the routing heuristic on
them (:meth:`ModelEdges.guess`): pruned to the nodes that reach ``Tgt``, no edge into ``Src``
or out of ``Tgt``, each with its cut group of :mod:`synthesis.routing.groups`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..graphs.consistency import check_consistency
from ..graphs.products import Products
from .bounds.heuristic import RouteSeed, RoutingGuess, guess_routing
from .groups import CutGroups


@dataclass(frozen=True)
class ModelEdges:
    """The edges of G the routing model keeps, and what the model knows of each.

    Attributes
    ----------
    edges
        Indices into G's edges: pruned to nodes that reach ``Tgt``, no edge into
        ``Src`` or out of ``Tgt``.
    eu, ev
        Their tails and heads.
    c5
        ``bool`` per kept edge: both ends outside I (the edge carries a c5 row).
    grp
        The cut group of each kept edge.
    has_var
        ``bool`` per group: the group gets a cut variable (restrictable, and on some
        c5 edge).
    """

    edges: np.ndarray
    eu: np.ndarray
    ev: np.ndarray
    c5: np.ndarray
    grp: np.ndarray
    has_var: np.ndarray

    def guess(
        self,
        products: Products,
        traps: Callable[[np.ndarray], bool] | None = None,
        route_seed: bool = True,
        fixed_open: np.ndarray | None = None,
    ) -> RoutingGuess:
        """The routing heuristic on these edges (with the place-simple route seed unless
        ``route_seed`` is false), cutting no group of ``fixed_open`` (``bool`` per group)."""
        g = products.virtual
        return guess_routing(
            g.n_nodes,
            g.initial,
            self.eu,
            self.ev,
            self.grp,
            self.c5,
            self.has_var if fixed_open is None else self.has_var & ~fixed_open,
            products.target,
            traps=traps,
            route_seed=RouteSeed(products.ts.place[g.state], g.hist, products.intermediate) if route_seed else None,
        )


def model_edges(products: Products, groups: CutGroups, keep_node: np.ndarray | None = None) -> ModelEdges:
    """The routing model's edges (see :class:`ModelEdges`); ``keep_node`` is what
    :func:`~synthesis.graphs.consistency.check_consistency` returns (computed when not given)."""
    g = products.virtual
    if keep_node is None:
        keep_node = check_consistency(products)
    tgt, inter = products.target, products.intermediate
    edges = np.flatnonzero(keep_node[g.src] & keep_node[g.dst] & (g.dst != g.initial) & ~tgt[g.src])
    eu, ev = g.src[edges], g.dst[edges]
    c5 = ~inter[eu] & ~inter[ev]
    grp = groups.of_edge[edges]
    useful = np.zeros(groups.keys.size, dtype=bool)
    useful[grp[c5]] = True
    return ModelEdges(edges, eu, ev, c5, grp, useful & groups.restrictable)
