"""Stage 4 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the outer greatest fixpoint
``nu Z`` over every guarantee (:func:`solve`), realizability from the initial groups, and the
answer (:class:`GR1Result`) with the strategy the last pass's basins give
(:func:`~synthesis.test_agent.gr1.extract.build_strategy`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .basin import Basin, basin
from .extract import build_strategy
from .game import GR1Game
from .index import GameIndex
from .strategy import GR1Strategy


@dataclass
class GR1Result:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    realizable
        Whether the system wins from the initial condition.
    winning
        Boolean mask of the winning region ``Z``.
    strategy
        A winning strategy if realizable, else ``None``.
    """

    realizable: bool
    winning: np.ndarray
    strategy: GR1Strategy | None


def solve(game: GR1Game) -> GR1Result:
    """Solve a GR(1) game.

    Parameters
    ----------
    game
        The game to solve.

    Returns
    -------
    GR1Result
        The verdict for the initial condition, the winning region and, if
        realizable, a winning strategy (initial memory ``0``).

    Notes
    -----
    The outer ``nu Z`` is evaluated Gauss-Seidel style (``Z := Z & Y_j(Z)``
    for each ``j`` in turn) until a full pass leaves ``Z`` unchanged; the
    ``Y`` data of that last pass, all computed with the final ``Z``, define
    the strategy.  Environment assumption sets equal to all positions are
    trivially satisfied and dropped; duplicates are merged.
    """
    ix = GameIndex(game)
    n = ix.n
    env: list[np.ndarray] = []
    for live in game.env_liveness:
        if live.all() or any(np.array_equal(live, e) for e in env):
            continue
        env.append(live)
    goals = list(game.sys_liveness) or [np.ones(n, dtype=bool)]
    winning = np.ones(n, dtype=bool)
    while True:
        changed = False
        basins: list[Basin] = []
        for goal_set in goals:
            target = goal_set & ix.cpre(winning)
            b = basin(ix, target, env)
            shrunk = winning & b.inside
            if np.count_nonzero(shrunk) != np.count_nonzero(winning):
                winning = shrunk
                changed = True
            basins.append(b)
        if not changed:
            break
    realizable = all(bool(np.any(winning[g])) for g in game.initial)
    strategy = build_strategy(game, ix, winning, basins) if realizable else None
    return GR1Result(realizable=realizable, winning=winning, strategy=strategy)
