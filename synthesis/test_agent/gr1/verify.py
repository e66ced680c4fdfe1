"""Stage 7 of the GR(1) solver (:mod:`synthesis.test_agent.gr1`): the independent check that
a strategy wins a game (:func:`verify_strategy`), from the game and the strategy's table alone
(no solver data): the closed loop explored under every environment choice, and no reachable
cycle that meets every assumption but avoids a guarantee."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .game import GR1Game
from .index import gather_ranges
from .strategy import GR1Strategy


class StrategyError(AssertionError):
    """Raised by :func:`verify_strategy` when a strategy is not winning.

    It derives from :class:`AssertionError` so that test code can treat a
    failed verification like a failed assertion.
    """


def verify_strategy(game: GR1Game, strategy: GR1Strategy) -> None:
    """Check that ``strategy`` wins ``game``; raise :class:`StrategyError` if not.

    The check uses only the game and the strategy table (no solver data):

    1. every initial pick lies in its group;
    2. the closed loop over states ``(position, memory)`` reachable from
       ``(pick, initial_memory)`` is explored under all environment choices;
       every reached (memory, choice) must have a move into the choice's
       successor list with a valid memory value;
    3. for each guarantee ``j``, the closed loop with the states at
       ``J^s_j`` positions removed is decomposed into strongly connected
       components; a component with an internal edge that meets every
       ``J^e_i`` is a reachable cycle satisfying all assumptions but visiting
       ``J^s_j`` finitely often, i.e. a counterexample.

    Parameters
    ----------
    game
        The game.
    strategy
        The strategy to check.

    Raises
    ------
    StrategyError
        With a description of the first violation found.
    """
    n, m = game.n_positions, game.n_choices
    n_mem = strategy.n_memory
    if strategy.n_positions != n or strategy.n_choices != m:
        raise StrategyError(f"strategy is for {strategy.n_positions} positions / {strategy.n_choices} choices, game has {n} / {m}")
    if strategy.initial.size != len(game.initial):
        raise StrategyError(f"strategy has {strategy.initial.size} initial picks, game has {len(game.initial)} groups")
    for g, group in enumerate(game.initial):
        pick = int(strategy.initial[g])
        if pick not in set(group.tolist()):
            raise StrategyError(f"initial pick {pick} is not in initial group {g}")
    owner = game.choice_owner
    order = np.argsort(owner, kind="stable")
    cptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=cptr[1:])
    edge_choice = np.repeat(np.arange(m, dtype=np.int64), np.diff(game.choice_succ_ptr))
    legal = np.unique(edge_choice * max(n, 1) + game.choice_succ)
    visited = np.zeros(n * n_mem, dtype=bool)
    start = np.unique(strategy.initial.astype(np.int64) * n_mem + strategy.initial_memory)
    visited[start] = True
    frontier = start
    srcs: list[np.ndarray] = []
    dsts: list[np.ndarray] = []
    while frontier.size:
        pos = frontier // n_mem
        idx = gather_ranges(cptr, pos)
        counts = cptr[pos + 1] - cptr[pos]
        src = np.repeat(frontier, counts)
        c = order[idx]
        mem = src % n_mem
        nxt = strategy.next_position[mem, c].astype(np.int64)
        nmem = strategy.next_memory[mem, c].astype(np.int64)
        bad = np.flatnonzero((nxt < 0) | (nmem < 0) | (nmem >= n_mem))
        if bad.size:
            k = int(bad[0])
            raise StrategyError(f"no valid move at position {int(src[k] // n_mem)}, memory {int(mem[k])}, environment choice {int(c[k])}")
        keys = c * max(n, 1) + nxt
        where = np.searchsorted(legal, keys)
        ok = where < legal.size
        ok[ok] = legal[where[ok]] == keys[ok]
        if not ok.all():
            k = int(np.flatnonzero(~ok)[0])
            raise StrategyError(f"illegal move to position {int(nxt[k])} after environment choice {int(c[k])} (memory {int(mem[k])})")
        dst = nxt * n_mem + nmem
        srcs.append(src)
        dsts.append(dst)
        new = np.unique(dst[~visited[dst]])
        visited[new] = True
        frontier = new
    states = np.flatnonzero(visited)
    n_states = states.size
    if n_states == 0:
        return
    src = np.concatenate(srcs) if srcs else np.empty(0, dtype=np.int64)
    dst = np.concatenate(dsts) if dsts else np.empty(0, dtype=np.int64)
    s_idx = np.searchsorted(states, src)
    d_idx = np.searchsorted(states, dst)
    state_pos = states // n_mem
    guarantees = list(game.sys_liveness) or [np.ones(n, dtype=bool)]
    for j, goal in enumerate(guarantees):
        keep = ~goal[state_pos]
        e_keep = keep[s_idx] & keep[d_idx]
        es, ed = s_idx[e_keep], d_idx[e_keep]
        if es.size == 0:
            continue
        graph = sp.csr_matrix((np.ones(es.size, dtype=np.int8), (es, ed)), shape=(n_states, n_states))
        n_comp, labels = connected_components(graph, directed=True, connection="strong")
        internal = labels[es] == labels[ed]
        nontrivial = np.zeros(n_comp, dtype=bool)
        nontrivial[labels[es[internal]]] = True
        bad_comp = nontrivial
        for live in game.env_liveness:
            hit = np.zeros(n_comp, dtype=bool)
            hit[labels[keep & live[state_pos]]] = True
            bad_comp = bad_comp & hit
        if bad_comp.any():
            comp = int(np.flatnonzero(bad_comp)[0])
            members = states[labels == comp]
            sample = [(int(s // n_mem), int(s % n_mem)) for s in members[:8]]
            raise StrategyError(
                f"guarantee {j} can be avoided forever while all assumptions hold: "
                f"reachable cycle through (position, memory) states {sample}" + (" ..." if members.size > 8 else "")
            )
