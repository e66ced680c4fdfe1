"""The system under test's own product graph ``G_sys = T x B_sys``, over a test game's actions.

What a planning SUT knows of a test: its map (static walls included, they are on every
observation) and its own objective's automaton, never the hidden test objective. The
scripted SUTs plan on it (:mod:`agents.scripted`), and the optional reward shaping of the
environments (:class:`flowtest_env.wrappers.DistanceShaping`) measures progress on it.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .game import TestGame

INF = np.iinfo(np.int64).max // 4
"""The distance of a node from which acceptance is unreachable."""


class SystemProduct:
    """The SUT's own product graph ``G_sys = T x B_sys`` over a test game's actions.

    Node ``s * n_q + q``: system state ``s`` with ``B_sys`` in state ``q`` after reading
    ``L(s)``. ``next_node[node, a]`` is the node an action leads to (stay included),
    ``-1`` where the action does not exist. ``distances(blocked)`` is the number of
    steps to an accepting node avoiding the blocked transitions ``(s, action)``; nodes
    from which acceptance is unreachable get :data:`INF`.
    """

    def __init__(self, game: TestGame) -> None:
        self.game = game
        ts = game.ts
        dba = game.artifact.system_automaton
        letter = ts.letter_of_state(game.artifact.letters)
        self.n_q = nq = dba.n_states
        self.delta = dba.delta
        self.letter = letter
        self.q0 = int(dba.initial)
        n = ts.n_states
        n_act = game.n_actions
        nxt = np.full((n * nq, n_act), -1, dtype=np.int64)
        succ = game.successor  # [n, slots]
        walls = np.concatenate([game.artifact.strategy.static_obstacles, [False]])[game.slot_move]
        exists = (game.slot_move >= 0) & ~walls  # static walls are on the map: never planned through
        for q in range(nq):
            nodes = np.arange(n) * nq + q
            q2 = dba.delta[q, letter[succ]]  # [n, slots]
            nxt[nodes, : game.n_slots] = np.where(exists, succ * nq + q2, -1)
            qs = dba.delta[q, letter]
            nxt[nodes, game.stay_action] = np.where(ts.stay, np.arange(n) * nq + qs, -1)
        self.next_node = nxt
        self.accepting = np.repeat(dba.accepting[:, 0][None, :], n, axis=0).ravel()
        # reverse adjacency: for each node, (predecessor node, action)
        src, act = np.nonzero(nxt >= 0)
        dst = nxt[src, act]
        order = np.argsort(dst, kind="stable")
        self._rsrc, self._ract, rdst = src[order], act[order], dst[order]
        self._rptr = np.searchsorted(rdst, np.arange(n * nq + 1))
        self._cache: dict[frozenset[tuple[int, int]], np.ndarray] = {}

    def node(self, s: int, q: int) -> int:
        return s * self.n_q + q

    def step_q(self, q: int, s: int) -> int:
        """``B_sys`` after entering (or staying in) state ``s``."""
        return int(self.delta[q, self.letter[s]])

    def distances(self, blocked: frozenset[tuple[int, int]] = frozenset()) -> np.ndarray:
        """Backward BFS from the accepting nodes, skipping blocked ``(s, action)`` pairs."""
        hit = self._cache.get(blocked)
        if hit is not None:
            return hit
        nq = self.n_q
        dist = np.full(self.next_node.shape[0], INF, dtype=np.int64)
        frontier = deque(np.flatnonzero(self.accepting).tolist())
        for v in frontier:
            dist[v] = 0
        rsrc, ract, rptr = self._rsrc, self._ract, self._rptr
        while frontier:
            v = frontier.popleft()
            dv = dist[v] + 1
            for i in range(rptr[v], rptr[v + 1]):
                u = int(rsrc[i])
                if dist[u] <= dv or self.accepting[u]:
                    continue
                if blocked and (u // nq, int(ract[i])) in blocked:
                    continue
                dist[u] = dv
                frontier.append(u)
        if len(self._cache) > 256:
            self._cache.clear()
        self._cache[blocked] = dist
        return dist

    def path(self, start: int, blocked: frozenset[tuple[int, int]] = frozenset()) -> list[int]:
        """Actions of one shortest path from node ``start`` (empty if none)."""
        dist = self.distances(blocked)
        out: list[int] = []
        v = start
        nq = self.n_q
        while dist[v] not in (0, INF):
            for a in range(self.next_node.shape[1]):
                w = self.next_node[v, a]
                if w >= 0 and dist[w] == dist[v] - 1 and (v // nq, a) not in blocked:
                    out.append(a)
                    v = int(w)
                    break
            else:  # pragma: no cover - BFS guarantees a predecessor
                break
        return out
