"""Minimum cuts read off a maximum flow: the smallest and the largest source side.

scipy's :func:`~scipy.sparse.csgraph.maximum_flow` returns the flow, not the cut. After a
maximum flow ``f`` under capacities ``cap`` (both ``(n, n)`` sparse, ``f`` skew-symmetric as
scipy returns it), ``cap - f`` is the residual graph, reverse arcs included, and

* the nodes the source reaches in it are the *smallest* source side of a minimum cut;
* the nodes that do not reach the sink in it are the *largest* one.

Several bounds and separators need one side or the other (the routing model's cut rows, the
caps' lower bounds, the walls' cut bound): they read it here, so the residual graph is built
one way.

Example::

    res = maximum_flow(cap, s, t)
    near = source_side(cap, res.flow, s)   # arcs from near to ~near form a minimum cut
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_flow


def residual(cap: sp.spmatrix, flow: sp.spmatrix) -> sp.csr_matrix:
    """The residual graph of ``flow`` under ``cap``: an ``int8`` 1 per arc with room left."""
    out = sp.csr_matrix(cap - flow)
    out.data = (out.data > 0).astype(np.int8)
    out.eliminate_zeros()
    return out


def source_side(cap: sp.spmatrix, flow: sp.spmatrix, src: int) -> np.ndarray:
    """``bool`` per node: what ``src`` reaches in the residual graph of a maximum flow (the
    smallest source side of a minimum cut)."""
    side = np.zeros(cap.shape[0], dtype=bool)
    side[breadth_first_order(residual(cap, flow), src, directed=True, return_predecessors=False)] = True
    return side


def sink_side(cap: sp.spmatrix, flow: sp.spmatrix, sink: int) -> np.ndarray:
    """``bool`` per node: what reaches ``sink`` in the residual graph of a maximum flow (its
    complement is the largest source side of a minimum cut)."""
    side = np.zeros(cap.shape[0], dtype=bool)
    back = residual(cap, flow).T.tocsr()
    side[breadth_first_order(back, sink, directed=True, return_predecessors=False)] = True
    return side


def min_cut(cap: sp.csr_matrix, src: int, sink: int) -> tuple[int, np.ndarray]:
    """A minimum ``src -> sink`` cut under ``cap`` (``int32`` CSR, as scipy wants it): its
    value and its smallest source side (``bool`` per node)."""
    res = maximum_flow(cap, src, sink)
    return int(res.flow_value), source_side(cap, res.flow, src)
