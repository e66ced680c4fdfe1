"""The two inconsistent problems of docs/method.md §5, decided on the product graphs alone: no
routing MILP can change them (the goal is unreachable, or no execution reaching it passes
the test objective)."""

from __future__ import annotations

import numpy as np

from ..model.errors import InconsistentProblem
from .products import Products, coreachable


def check_consistency(products: Products) -> np.ndarray:
    """Raise :class:`InconsistentProblem` for the two cases of docs/method.md §5.

    Returns the mask of G's nodes that can reach ``Tgt``.
    """
    g = products.virtual
    co = coreachable(g.n_nodes, g.src, g.dst, products.target)
    if not co[g.initial]:
        raise InconsistentProblem("unreachable", "the system objective cannot be met: no execution from the start reaches the goal")
    if not np.any(products.intermediate & co):
        raise InconsistentProblem(
            "unroutable",
            "the test objective cannot be routed: no execution that meets the system objective also meets the test objective",
        )
    return co
