"""The synthesized test agent as an O(1) look-up table (:class:`AgentController`), stored in
the test artifact and stepped by the environments, and its tabulation from a winning GR(1)
strategy of the test-agent game (:func:`controller_from_strategy`)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..graphs.products import Products
from ..model.agent_system import TestAgent
from .game import AgentGame
from .gr1.strategy import GR1Strategy

CONTROLLER_FORMAT = "flowtest.agent-controller"
CONTROLLER_VERSION = 1


@dataclass
class AgentController:
    """The synthesized test agent as an O(1) look-up table, for environments.

    Protocol: ``agent_state, memory = reset()`` before anyone moved. If
    :attr:`first` is ``"agent"``, call ``respond(agent_state, memory, s0, h0)`` once
    right away with the system's initial state and history: it returns the agent's
    first move. Then, every time the system under test has entered ``sys_state``
    (history ``history``, index into the specification product's states, i.e. the
    artifact's ``histories`` automaton), ``respond`` returns the agent's move and the
    new memory.

    Attributes
    ----------
    agent_places
        Per agent state: the system place (index into ``ts.places``) it occupies, ``None``
        for a park.
    agent_names
        Per agent state: ``"(r, c)"`` or the park's name.
    first
        ``"agent"`` or ``"system"``: who moves first.
    initial_agent, initial_memory
        The agent state and strategy memory at the start.
    n_hist
        Number of histories.
    node_of
        ``int32[n_system_states * n_hist]``: the row of ``(sys_state, history)`` in the
        tables (``sys_state * n_hist + history``), -1 if the table has none.
    next_agent, next_memory
        ``int32[n_memory, n_rows, n_agent]``: the answer, -1 where undefined.
    fallback
        ``int32[n_agent, n_places]``: the move used outside the table (after the test
        ended, or for a configuration the rules of the game never produce): stay if
        allowed, else the first move that avoids the system's place.
    sys_place
        ``int32[n_system_states]``: the place of each system state.
    """

    agent_places: list[int | None]
    agent_names: list[str]
    first: str
    initial_agent: int
    initial_memory: int
    n_hist: int
    node_of: np.ndarray
    next_agent: np.ndarray
    next_memory: np.ndarray
    fallback: np.ndarray
    sys_place: np.ndarray

    @property
    def n_memory(self) -> int:
        return int(self.next_agent.shape[0])

    @property
    def n_entries(self) -> int:
        """Number of defined table entries."""
        return int(np.count_nonzero(self.next_agent >= 0))

    def reset(self) -> tuple[int, int]:
        """``(agent_state, memory)`` at the start, before anyone moved."""
        return self.initial_agent, self.initial_memory

    def respond(self, agent_state: int, memory: int, sys_state: int, history: int) -> tuple[int, int]:
        """The agent's move after the system entered ``sys_state`` with ``history``.

        Returns ``(next_agent_state, next_memory)``; table look-ups only.
        """
        row = int(self.node_of[sys_state * self.n_hist + history])
        if row >= 0:
            a = int(self.next_agent[memory, row, agent_state])
            if a >= 0:
                return a, int(self.next_memory[memory, row, agent_state])
        return int(self.fallback[agent_state, self.sys_place[sys_state]]), memory

    def lookup(self, memory: np.ndarray, sys_state: np.ndarray, history: np.ndarray, agent_state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised table look-up without fallback: ``(-1, -1)`` where the table has no entry."""
        row = self.node_of[sys_state.astype(np.int64) * self.n_hist + history]
        ok = row >= 0
        a = np.full(row.size, -1, dtype=np.int64)
        m = np.full(row.size, -1, dtype=np.int64)
        a[ok] = self.next_agent[memory[ok], row[ok], agent_state[ok]]
        m[ok] = self.next_memory[memory[ok], row[ok], agent_state[ok]]
        return a, m

    def restricted(self, memory: np.ndarray, rows: np.ndarray, agents: np.ndarray) -> AgentController:
        """A copy whose table keeps only the entries ``(memory, row, agent)`` listed."""
        na = np.full_like(self.next_agent, -1)
        nm = np.full_like(self.next_memory, -1)
        na[memory, rows, agents] = self.next_agent[memory, rows, agents]
        nm[memory, rows, agents] = self.next_memory[memory, rows, agents]
        return replace(self, next_agent=na, next_memory=nm)

    def to_dict(self) -> dict[str, Any]:
        """Compact plain data: only defined entries, over the rows they use."""
        mem, row, agt = np.nonzero(self.next_agent >= 0)
        used, row_new = np.unique(row, return_inverse=True)
        n_sys = self.node_of.size // max(self.n_hist, 1)
        keys = np.flatnonzero(self.node_of >= 0)
        key_of_row = np.full(int(self.node_of.max()) + 1 if keys.size else 0, -1, dtype=np.int64)
        key_of_row[self.node_of[keys]] = keys
        k = key_of_row[used]
        return {
            "format": CONTROLLER_FORMAT,
            "version": CONTROLLER_VERSION,
            "first": self.first,
            "agent_places": list(self.agent_places),
            "agent_names": list(self.agent_names),
            "initial_agent": self.initial_agent,
            "initial_memory": self.initial_memory,
            "n_memory": self.n_memory,
            "n_hist": self.n_hist,
            "n_system_states": int(n_sys),
            "rows": np.stack([k // self.n_hist, k % self.n_hist], axis=1).tolist(),
            "table": {
                "memory": mem.tolist(),
                "row": row_new.ravel().tolist(),
                "agent": agt.tolist(),
                "next_agent": self.next_agent[mem, row, agt].tolist(),
                "next_memory": self.next_memory[mem, row, agt].tolist(),
            },
            "fallback": self.fallback.tolist(),
            "sys_place": self.sys_place.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> AgentController:
        """Rebuild a controller written by :meth:`to_dict`.

        Raises
        ------
        ValueError
            If the format tag or version does not match.
        """
        if d.get("format") != CONTROLLER_FORMAT or d.get("version") != CONTROLLER_VERSION:
            raise ValueError(f"not a {CONTROLLER_FORMAT} v{CONTROLLER_VERSION} document: format={d.get('format')!r}, version={d.get('version')!r}")
        n_hist, n_sys = int(d["n_hist"]), int(d["n_system_states"])
        n_agent, n_mem = len(d["agent_names"]), int(d["n_memory"])
        rows = np.asarray(d["rows"], dtype=np.int64).reshape(-1, 2)
        node_of = np.full(n_sys * n_hist, -1, dtype=np.int32)
        node_of[rows[:, 0] * n_hist + rows[:, 1]] = np.arange(rows.shape[0], dtype=np.int32)
        t = d["table"]
        na = np.full((n_mem, rows.shape[0], n_agent), -1, dtype=np.int32)
        nm = np.full_like(na, -1)
        idx = (np.asarray(t["memory"], dtype=np.int64), np.asarray(t["row"], dtype=np.int64), np.asarray(t["agent"], dtype=np.int64))
        na[idx] = np.asarray(t["next_agent"], dtype=np.int32)
        nm[idx] = np.asarray(t["next_memory"], dtype=np.int32)
        return cls(
            agent_places=[None if p is None else int(p) for p in d["agent_places"]],
            agent_names=list(d["agent_names"]),
            first=d["first"],
            initial_agent=int(d["initial_agent"]),
            initial_memory=int(d["initial_memory"]),
            n_hist=n_hist,
            node_of=node_of,
            next_agent=na,
            next_memory=nm,
            fallback=np.asarray(d["fallback"], dtype=np.int32).reshape(n_agent, -1),
            sys_place=np.asarray(d["sys_place"], dtype=np.int32),
        )


def _fallback_table(agent: TestAgent, n_places: int) -> np.ndarray:
    """``int32[n_agent, n_places]``: stay if allowed and clear of the system, else the
    first move clear of the system's place, else stay put."""
    places = agent.place_of_state
    moves = agent.move_matrix()
    out = np.empty((agent.n_states, n_places), dtype=np.int32)
    for a in range(agent.n_states):
        succ = [a] if moves[a, a] else []
        succ += [int(b) for b in np.flatnonzero(moves[a]) if b != a]
        for p in range(n_places):
            clear = [b for b in succ if places[b] != p]
            out[a, p] = clear[0] if clear else a
    return out


def controller_from_strategy(products: Products, game: AgentGame, strategy: GR1Strategy, agent: TestAgent) -> AgentController:
    """Tabulate a winning GR(1) strategy of the test-agent game per configuration.

    The game is a safety game, so every winning answer of a configuration ``(v', a)``
    is good whichever position the system came from: the table is keyed by the
    configuration (and the strategy memory), not by the game's choice, which makes the
    environment's look-up independent of the previous state. The closed-loop check
    (:func:`verify_closed_loop`) confirms the table, not the solver.
    """
    g, ts = products.virtual, products.ts
    n, n_agent, n_mem = g.n_nodes, agent.n_states, strategy.n_memory
    next_agent = np.full((n_mem, n, n_agent), -1, dtype=np.int32)
    next_memory = np.full_like(next_agent, -1)
    for m in range(n_mem):
        defined = np.flatnonzero(strategy.next_position[m] >= 0)
        cfg = game.choice_config[defined]
        cfg, first = np.unique(cfg, return_index=True)
        pick = defined[first]
        pos = strategy.next_position[m, pick]
        next_agent[m, cfg // n_agent, cfg % n_agent] = game.position_agent[pos]
        next_memory[m, cfg // n_agent, cfg % n_agent] = strategy.next_memory[m, pick]
    if agent.first == "agent":
        pos = int(strategy.initial[0])
        next_agent[strategy.initial_memory, g.initial, agent.start] = game.position_agent[pos]
        next_memory[strategy.initial_memory, g.initial, agent.start] = strategy.initial_memory
    node_of = np.full(ts.n_states * g.n_hist, -1, dtype=np.int32)
    node_of[g.state.astype(np.int64) * g.n_hist + g.hist] = np.arange(n, dtype=np.int32)
    places = agent.place_of_state
    return AgentController(
        agent_places=[None if p < 0 else int(p) for p in places],
        agent_names=list(agent.names),
        first=agent.first,
        initial_agent=int(agent.start),
        initial_memory=int(strategy.initial_memory),
        n_hist=int(g.n_hist),
        node_of=node_of,
        next_agent=next_agent,
        next_memory=next_memory,
        fallback=_fallback_table(agent, len(ts.places)),
        sys_place=ts.place.astype(np.int32),
    )
