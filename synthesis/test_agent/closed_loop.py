"""Closed-loop verification of a test agent (docs/method.md §7), independent of the GR(1) solver:
the test under the agent's controller explored against every behaviour of the system."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graphs.products import Products, coreachable
from ..model.agent_system import TestAgent
from ..model.errors import CheckFailed
from ..model.strategy import TestStrategy
from .controller import AgentController
from .game import blocking_places, ended_nodes, reactive_restrictions, walled_off_nodes


@dataclass(frozen=True)
class ClosedLoopReport:
    """What the exhaustive closed-loop exploration saw.

    ``positions``: reachable configurations at the system's turn; ``transitions``: their
    successors over every system behaviour; ``goal_positions``: those with the system at
    its goal; ``entries``: the table entries ``(memory, row, agent)`` the loop used.
    """

    positions: int
    transitions: int
    goal_positions: int
    entries: tuple[np.ndarray, np.ndarray, np.ndarray]


def verify_closed_loop(products: Products, strategy: TestStrategy, agent: TestAgent, controller: AgentController) -> ClosedLoopReport:
    """Explore the test under the controller against every system behaviour.

    Independent of the GR(1) solver: it reads only G, the routing strategy, the agent's
    moves and the controller's table. The system may take any move of G that is not a
    static obstacle and does not enter the agent's place, or stay; the agent answers
    with the controller. Checks, at every reachable configuration:

    * the agent never collides with the system and moves along ``T_TA``;
    * at the system's turn the blocked moves out of its state are exactly
      ``R(q) ∩ out(s)`` plus the static obstacles (no more, no less);
    * g8: the agent never stays at its turn in a place that blocks every path;
    * the agent never traps the system: from every reachable configuration where the
      test goes on and the static walls alone leave the system a way to its goal
      (:func:`~synthesis.test_agent.game.walled_off_nodes`: a correct system never walks into
      a node the walls it sees doom), a configuration with the system at its goal is
      reachable;
    * every run that reaches the goal passed through the test objective (the last node
      before ``Tgt`` is in ``I``).

    Raises
    ------
    CheckFailed
        With the first violation found (a FlowTest bug).
    """
    g, ts = products.virtual, products.ts
    n, n_agent, n_mem = g.n_nodes, agent.n_states, controller.n_memory
    places = agent.place_of_state
    moves = agent.move_matrix()
    obs = strategy.static_obstacles
    reactive = reactive_restrictions(strategy)
    ended = ended_nodes(products)
    walled = walled_off_nodes(products, obs)
    blocking = np.zeros((n, n_agent), dtype=bool)
    cells = np.flatnonzero(places >= 0)
    blocking[:, cells] = blocking_places(products, obs, places[cells])
    node_place = ts.place[g.state].astype(np.int64)
    order = np.argsort(g.src, kind="stable")
    e_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(g.src, minlength=n), out=e_ptr[1:])
    e_dst, e_move = g.dst[order].astype(np.int64), g.move[order].astype(np.int64)

    def where(v: int, a: int) -> str:
        return f"system at {ts.states[int(g.state[v])]} (history q{int(g.hist[v])}), agent at {agent.names[int(a)]}"

    def answer(m: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        na, nm = controller.lookup(m, g.state[v], g.hist[v], a)
        bad = np.flatnonzero(na < 0)
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent controller has no move for {where(int(v[k]), int(a[k]))}")
        bad = np.flatnonzero(~moves[a, na])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent moves from {agent.names[int(a[k])]} to {agent.names[int(na[k])]}, not a move of T_TA ({where(int(v[k]), int(a[k]))})")
        bad = np.flatnonzero(places[na] == node_place[v])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent collides with the system: {where(int(v[k]), int(na[k]))}")
        bad = np.flatnonzero((na == a) & blocking[v, a])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"g8 violated: the agent stays where it blocks every path ({where(int(v[k]), int(a[k]))})")
        return na, nm

    a0, m0 = controller.reset()
    v0 = np.array([g.initial], dtype=np.int64)
    used_m: list[np.ndarray] = []
    used_v: list[np.ndarray] = []
    used_a: list[np.ndarray] = []
    if controller.first == "agent":
        a_arr, m_arr = answer(np.array([m0]), v0, np.array([a0]))
        used_m.append(np.array([m0]))
        used_v.append(v0)
        used_a.append(np.array([a0]))
    else:
        a_arr, m_arr = np.array([a0]), np.array([m0])

    def key(v: np.ndarray, a: np.ndarray, m: np.ndarray) -> np.ndarray:
        """The index of configuration ``(v, a)`` with memory ``m``."""
        out: np.ndarray = (v * n_agent + a) * n_mem + m
        return out

    visited = np.zeros(n * n_agent * n_mem, dtype=bool)
    frontier = np.unique(key(v0, a_arr, m_arr))
    visited[frontier] = True
    srcs: list[np.ndarray] = []
    dsts: list[np.ndarray] = []
    while frontier.size:
        m = frontier % n_mem
        a = (frontier // n_mem) % n_agent
        v = frontier // (n_mem * n_agent)
        bad = np.flatnonzero(places[a] == node_place[v])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent collides with the system: {where(int(v[k]), int(a[k]))}")
        go = ~ended[v]
        fk, m, a, v = frontier[go], m[go], a[go], v[go]
        # the system's view: the moves blocked out of its state
        starts, lens = e_ptr[v], e_ptr[v + 1] - e_ptr[v]
        total = int(lens.sum())
        row = np.repeat(np.arange(v.size), lens)
        idx = np.repeat(starts - (np.cumsum(lens) - lens), lens) + np.arange(total)
        mv, dst = e_move[idx], e_dst[idx]
        blocked = obs[mv] | (node_place[dst] == places[a[row]])
        expected = obs[mv] | reactive[g.hist[v[row]], mv]
        bad = np.flatnonzero(blocked != expected)
        if bad.size:
            k = int(bad[0])
            what = "blocks a move the test does not restrict" if blocked[k] else "leaves open a move the test restricts"
            raise CheckFailed(f"the agent {what}: {ts.states[int(ts.src[mv[k]])]} -> {ts.states[int(ts.dst[mv[k]])]} ({where(int(v[row[k]]), int(a[row[k]]))})")
        # every system behaviour: unblocked moves and stays
        open_ = ~blocked
        stay = np.flatnonzero(ts.stay[g.state[v]])
        s_row = np.concatenate([row[open_], stay])
        s_dst = np.concatenate([dst[open_], v[stay]])
        na, nm = answer(m[s_row], s_dst, a[s_row])
        used_m.append(m[s_row])
        used_v.append(s_dst)
        used_a.append(a[s_row])
        nxt = key(s_dst, na, nm)
        srcs.append(fk[s_row])
        dsts.append(nxt)
        new = np.unique(nxt[~visited[nxt]])
        visited[new] = True
        frontier = new
    states = np.flatnonzero(visited)
    src = np.searchsorted(states, np.concatenate(srcs)) if srcs else np.zeros(0, dtype=np.int64)
    dst = np.searchsorted(states, np.concatenate(dsts)) if dsts else np.zeros(0, dtype=np.int64)
    s_node = states // (n_mem * n_agent)
    goal = products.target[s_node]
    alive = coreachable(states.size, src, dst, goal)
    trapped = np.flatnonzero(~ended[s_node] & ~walled[s_node] & ~alive)
    if trapped.size:
        k = int(states[trapped[0]])
        raise CheckFailed(f"the test traps the system: no way to the goal from {where(k // (n_mem * n_agent), (k // n_mem) % n_agent)}")
    into_goal = goal[dst] & ~goal[src]
    bypass = np.flatnonzero(into_goal & ~products.intermediate[s_node[src]])
    if bypass.size:
        k = int(states[src[bypass[0]]])
        raise CheckFailed(f"a run reaches the goal without the test objective, from {where(k // (n_mem * n_agent), (k // n_mem) % n_agent)}")
    used_m_all, used_v_all, used_a_all = (np.concatenate(x) if x else np.zeros(0, dtype=np.int64) for x in (used_m, used_v, used_a))
    entries = (used_m_all, used_v_all, used_a_all)
    return ClosedLoopReport(positions=int(states.size), transitions=int(src.size), goal_positions=int(goal.sum()), entries=entries)
