"""Stage 5 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the counter strategy
tabulated from the basins of the last ``nu Z`` pass (:func:`build_strategy`): per memory (the
guarantee pursued) and environment choice, the move to a lower rank, or from a goal into the
winning region with the next memory."""

from __future__ import annotations

import numpy as np

from .basin import INF_RANK, KIND_GOAL, KIND_PERSIST, Basin
from .game import GR1Game
from .index import GameIndex
from .strategy import GR1Strategy


def _segment_argmin(key: np.ndarray, ptr: np.ndarray, sentinel: int) -> np.ndarray:
    """Per-CSR-segment minimum of ``key``; ``sentinel`` for empty segments."""
    m = ptr.size - 1
    out = np.full(m, sentinel, dtype=np.int64)
    nonempty = np.flatnonzero(ptr[1:] > ptr[:-1])
    if nonempty.size:
        out[nonempty] = np.minimum.reduceat(key, ptr[nonempty])
    return out


def build_strategy(game: GR1Game, ix: GameIndex, winning: np.ndarray, basins: list[Basin]) -> GR1Strategy:
    """Tabulate the counter strategy from the final fixpoint data.

    Raises
    ------
    RuntimeError
        If some position inside a basin has no admissible move (this would
        indicate a bug in the fixpoint computation).
    """
    n_mem = len(basins)
    E = ix.n_edges
    next_position = np.full((n_mem, ix.m), -1, dtype=np.int32)
    next_memory = np.full((n_mem, ix.m), -1, dtype=np.int32)
    succ = ix.succ
    edge_owner = ix.owner[ix.edge_choice]
    edge_id = np.arange(E, dtype=np.int64)
    sentinel = np.iinfo(np.int64).max
    for j, b in enumerate(basins):
        nxt_b = basins[(j + 1) % n_mem]
        r_v = b.rank[edge_owner].astype(np.int64)
        r_u = b.rank[succ].astype(np.int64)
        k_v = b.kind[edge_owner]
        valid = r_u < r_v
        is_goal = k_v == KIND_GOAL
        valid[is_goal] = winning[succ[is_goal]]
        if b.member.shape[1]:
            pers = np.flatnonzero(k_v == KIND_PERSIST)
            same = (r_u[pers] == r_v[pers]) & b.member[succ[pers], b.persist[edge_owner[pers]]]
            valid[pers] |= same
        valid &= r_v < INF_RANK
        score = np.where(is_goal, nxt_b.rank[succ].astype(np.int64), r_u)
        key = np.where(valid, score * (E + 1) + edge_id, sentinel)
        best = _segment_argmin(key, ix.ptr, sentinel)
        has = best != sentinel
        active = b.inside[ix.owner]
        if np.any(active & ~has):
            c = int(np.flatnonzero(active & ~has)[0])
            raise RuntimeError(f"internal error: no admissible move for goal {j}, choice {c}")
        chosen = best[has] % (E + 1)
        next_position[j, has] = succ[chosen]
        goal_choice = b.kind[ix.owner] == KIND_GOAL
        next_memory[j, has] = np.where(goal_choice[has], (j + 1) % n_mem, j)
    init = np.empty(len(game.initial), dtype=np.int32)
    rank0 = basins[0].rank
    for g, group in enumerate(game.initial):
        cand = group[winning[group]]
        init[g] = int(cand[np.argmin(rank0[cand])])
    return GR1Strategy(
        n_positions=game.n_positions,
        initial=init,
        next_position=next_position,
        next_memory=next_memory,
    )
