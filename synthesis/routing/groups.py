"""The cut groups: the edges of G that must share one cut value (docs/method.md §5).

:class:`CutGroups` is plain data, built by :func:`synthesis.routing.model.cut_groups` and read
by the routing model, its bounds and the test agent's game. It lives apart from the model,
which imports HiGHS, so that what only reads the groups (the test agent's game, and with it an
agent test's checks) loads no solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CutGroups:
    """Edges of G grouped by shared cut value.

    ``of_edge[e]`` is the group of edge ``e`` (every edge has one; groups of
    unrestrictable edges are never cut), ``keys[g]`` its stable key, ``weight[g]``
    the number of edges of G it stands for, ``restrictable[g]`` whether it may be cut,
    ``static[g]`` whether it is a static (history-independent) group.
    """

    of_edge: np.ndarray
    keys: np.ndarray
    weight: np.ndarray
    restrictable: np.ndarray
    static: np.ndarray
    move_key: np.ndarray  # per move of T, its static tie key
