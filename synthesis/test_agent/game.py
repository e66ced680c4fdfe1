"""The test-agent game of docs/method.md §7 as an explicit GR(1) game over integer arrays.

Players and turns
-----------------
The test agent is the controlled player (the GR(1) *system*); the system under test
(SUT) is its environment. A game *position* is a configuration at the SUT's turn,
``(v, a)`` with ``v = (x_sys, q_hist)`` a node of the virtual product graph G and ``a``
an agent state (a cell of the agent or a park). One round of :class:`~synthesis.test_agent.gr1.game.GR1Game`
is one SUT step followed by one agent step, so ``turn`` (g3, g4, a3) is built into the
rounds and needs no variable:

1. the SUT picks an edge of G out of ``v`` or stays (a2), never into the agent's place
   (a5) and never over a static obstacle of ``Obs``; the history is updated with the
   state entered (``q' = delta(q, L(s'))``; a stay keeps it, the automata being
   idempotent on a repeated letter). The pair ``(v', a)`` reached is a *configuration*
   where the agent decides;
2. the agent picks a move of ``T_TA`` (g2), never into the SUT's place (g5), such that
   the next position is *legal* (below), and not a stay in a place that blocks every
   path of the SUT to its goal (g8).

The initial condition (a1, g1): the SUT at the initial node of G with the initial
history, the agent at its start. If the agent moves first, the single initial group is
the set of positions its first move can reach from configuration ``(Src, a0)``;
otherwise it is ``{(Src, a0)}`` when that position is legal (else empty: unrealizable).

Legal positions (g5, g6, g7)
----------------------------
Write ``R(q)`` for the reactive restrictions of history ``q`` (the cuts ``C(q)`` outside
the static obstacles). A position ``((s, q), a)`` is legal iff the agent does not stand
on the SUT's place and, for every move ``(s, s')`` of ``T`` that is not a static
obstacle, the agent stands on the place of ``s'`` **exactly when** ``(s, s') in R(q)``.
So at every SUT turn the agent blocks ``R(q)`` out of ``s`` — no less (g6), no more
(g7). If ``R(q)`` restricts two places out of ``s``, or a place the agent cannot
occupy, no position at ``(s, q)`` is legal. A move into a static obstacle's target is
blocked anyway, so the agent may stand there (the static area is off the agent's cells,
so this only matters for hand-given static areas).

End of the test (terminal handling)
-----------------------------------
A test ends when the SUT reaches ``Tgt`` (goal states are terminal) or stands on a node
of G from which ``Tgt`` is unreachable even without restrictions: the SUT has then
failed its objective on its own and the verdict is fixed. Positions at such *ended*
nodes have no SUT choices, which the GR(1) solver counts as won by the agent; they only
need to be collision-free (g6/g7 are about the SUT's next move, and there is none).

Liveness (a4) and g8
--------------------
Every guarantee of the agent (g1-g8) is a safety property, and the game asks the agent
to keep them on *every* play, including plays where the SUT never reaches its goal.
That is stronger than the paper's ``(a4 & ...) -> guarantees`` (a4: ``G F goal``), so a
strategy found here also wins the paper's specification; a4 would only excuse liveness
guarantees and the agent has none, so the game carries no liveness sets (the GR(1)
solver's ``G F true``). The SUT's progress is the SUT's business: since the agent blocks
exactly ``R(q)``, the SUT's options at ``(s, q)`` are those of the routing strategy,
and the counterexample loop rejects a cut set under which some reachable configuration
has lost every way to the goal although the static walls leave it one
(:func:`trapped_nodes`). A configuration the walls alone doom is one no correct SUT
enters (the walls are on the map it sees from its first step), as the routing checks
and the environments hold for entry nodes (:func:`walled_off_nodes`).

g8 (the livelock guard) is computed, not hand-listed: a place ``p`` *blocks every path*
of the SUT at node ``v`` when ``Tgt`` is reachable from ``v`` in G without the static
obstacles, but not once every move into ``p`` is removed as well. In turn-based time
the agent stands still during the SUT's step (g3), so "staying two steps in a row" in
such a place means staying there again at its own turn, which g8 forbids (Maze 1's
"must leave rows 6, 4, 2, 0" is an instance of this rule).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graphs.products import Products, coreachable, reachable
from ..model.agent_system import TestAgent
from ..model.strategy import TestStrategy
from ..routing.groups import CutGroups
from .gr1.game import GR1Game

__all__ = [
    "AgentGame",
    "GameRules",
    "build_agent_game",
    "build_game",
    "rules_of_strategy",
    "ended_nodes",
    "walled_off_nodes",
    "blocking_places",
    "trapped_nodes",
    "reactive_restrictions",
    "realizability_exclusions",
]


def _ranges(ptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand CSR rows: ``(row of each entry, entry index)`` over ``rows``."""
    starts = ptr[rows]
    lens = ptr[rows + 1] - starts
    total = int(lens.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    offsets = np.cumsum(lens) - lens
    idx = np.repeat(starts - offsets, lens) + np.arange(total, dtype=np.int64)
    return np.repeat(np.arange(rows.size, dtype=np.int64), lens), idx


def _csr(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Stable order of ``keys`` and the CSR pointer of ``n`` rows."""
    order = np.argsort(keys, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys, minlength=n), out=ptr[1:])
    return order, ptr


def reactive_restrictions(strategy: TestStrategy) -> np.ndarray:
    """``bool[n_hist, n_moves]``: ``R(q)``, the restrictions of ``C(q)`` that are not static obstacles."""
    out: np.ndarray = strategy.restrictions & ~strategy.static_obstacles[None, :]
    return out


def ended_nodes(products: Products) -> np.ndarray:
    """``bool[n_nodes]``: nodes of G where the test is over (``Tgt``, or ``Tgt`` unreachable)."""
    g = products.virtual
    viable = coreachable(g.n_nodes, g.src, g.dst, products.target)
    out: np.ndarray = products.target | ~viable
    return out


def walled_off_nodes(products: Products, static_obstacles: np.ndarray) -> np.ndarray:
    """``bool[n_nodes]``: nodes where the test goes on (not ended) but the static walls
    ``static_obstacles`` (``bool`` per move of T) alone leave no way to ``Tgt``.

    The walls are on the map the SUT sees from its first step, so a correct SUT never
    enters such a node: walking in is its own fault (the environments call the run
    violated there), not a trap the test set. Every node reachable from one over moves
    that are not walls is one too.
    """
    g = products.virtual
    free = ~static_obstacles[g.move]
    on_map = coreachable(g.n_nodes, g.src[free], g.dst[free], products.target)
    out: np.ndarray = ~on_map & ~ended_nodes(products)
    return out


def blocking_places(products: Products, static_obstacles: np.ndarray, places: np.ndarray) -> np.ndarray:
    """``bool[n_nodes, len(places)]``: place ``places[k]`` blocks every path of the SUT at node ``v``.

    That is: ``Tgt`` is reachable from ``v`` in G without the static obstacles, but not
    when every move into the place is removed too (g8). Ended nodes block nothing.
    """
    free = ~static_obstacles[products.virtual.move]
    return _blocking(products, free, free, places)


def _blocking(products: Products, base_edges: np.ndarray, keep_edges: np.ndarray, places: np.ndarray) -> np.ndarray:
    """g8's "blocks every path", from two edge sets of G: ``Tgt`` reachable from ``v`` over
    ``base_edges``, and not over ``keep_edges`` once every move into the place is removed.
    With both the edges that are not static obstacles this is :func:`blocking_places`;
    :func:`build_game` passes the edges that are surely not obstacles and the edges that
    are not surely obstacles (a sure answer for every cut set its rules stand for)."""
    g, ts = products.virtual, products.ts
    base = coreachable(g.n_nodes, g.src[base_edges], g.dst[base_edges], products.target) & ~ended_nodes(products)
    head_place = ts.place[g.state[g.dst]]
    out = np.zeros((g.n_nodes, places.size), dtype=bool)
    for k, p in enumerate(places.tolist()):
        keep = keep_edges & (head_place != p)
        out[:, k] = base & ~coreachable(g.n_nodes, g.src[keep], g.dst[keep], products.target)
    return out


def trapped_nodes(products: Products, strategy: TestStrategy) -> np.ndarray:
    """Nodes of G the SUT can reach under the test's restrictions and where it is trapped.

    The SUT moves over G without the restricted edges (static obstacles and ``C(q)`` of
    the tail's history, exactly what a legal agent blocks) and stops at ended nodes. A
    reachable node that is not ended (so the goal is reachable without restrictions) and
    not walled off (:func:`walled_off_nodes`: the static walls alone leave it a way to the
    goal) but from which no restricted path reaches ``Tgt`` is a trap: the test's
    restrictions took the SUT's last way to its goal. Returns the indices of such nodes
    (empty: no trap).
    """
    g = products.virtual
    blocked = strategy.blocked[g.hist[g.src], g.move]
    ended = ended_nodes(products)
    keep = ~blocked
    alive = coreachable(g.n_nodes, g.src[keep], g.dst[keep], products.target)
    walk = keep & ~ended[g.src]
    start = np.zeros(g.n_nodes, dtype=bool)
    start[g.initial] = True
    seen = reachable(g.n_nodes, g.src[walk], g.dst[walk], start)
    walled = walled_off_nodes(products, strategy.static_obstacles)
    return np.flatnonzero(seen & ~ended & ~alive & ~walled)


@dataclass(frozen=True)
class GameRules:
    """What the test-agent game needs to know of a cut set, per edge of G.

    ``cut`` edges are restricted (reactive ones: the agent must stand on their head's
    place, g6; ``static`` ones are walls), ``open`` edges are free (the SUT may take
    them, so the agent must not stand on their head's place, g7). For one cut set
    (:func:`rules_of_strategy`) every edge is one or the other. A set of rules that
    leaves some edges *undecided* (neither) stands for every cut set that cuts the
    ``cut`` edges and leaves the ``open`` ones open: its game lets the SUT take only
    the open edges and holds the agent only to what every such cut set asks, so an
    agent that wins one of those cut sets' games wins this one too
    (:mod:`synthesis.test_agent.reasons` uses that to exclude all of them at once).

    Attributes
    ----------
    cut, open
        ``bool[n_edges]`` over G, disjoint.
    static
        ``bool[n_edges]``: edges whose cut is a wall (a static obstacle), not a
        restriction the agent realizes.
    """

    cut: np.ndarray
    open: np.ndarray
    static: np.ndarray


def rules_of_strategy(products: Products, strategy: TestStrategy) -> GameRules:
    """The rules of one test strategy: its blocked edges cut (walls where they are static
    obstacles), every other edge open."""
    g = products.virtual
    cut = strategy.blocked[g.hist[g.src], g.move]
    return GameRules(cut=cut, open=~cut, static=strategy.static_obstacles[g.move])


@dataclass
class AgentGame:
    """The test-agent game and the tables that translate it back to the test.

    Attributes
    ----------
    game
        The GR(1) game (positions at the SUT's turn; see the module docstring).
    n_agent
        Number of agent states.
    position_node, position_agent
        ``int64[n_positions]``: the node of G and the agent state of each position.
    position_index
        ``int64[n_nodes * n_agent]``: the position of ``(v, a)`` (``v * n_agent + a``), or -1.
    choice_config
        ``int64[n_choices]``: the configuration ``v' * n_agent + a`` each SUT choice leads to.
    choice_config_index
        ``int64[n_choices]``: index of that configuration in :attr:`configs`.
    choice_edge
        ``int64[n_choices]``: the edge of G each SUT choice takes (-1 for a stay).
    configs
        ``int64[n_configs]``: the configurations (``v' * n_agent + a``) where the agent decides.
    initial_config
        The configuration ``(Src, a0)`` of the agent's first move when it moves first, else -1.
    legal
        ``bool[n_nodes, n_agent]``: legal positions (g5-g7; collision-free only at ended nodes).
    ended
        ``bool[n_nodes]``: nodes where the test is over.
    blocking
        ``bool[n_nodes, n_agent]``: g8's "blocks every path" (False for parks).
    rules
        The cut and open edges the game was built from.
    """

    game: GR1Game
    n_agent: int
    position_node: np.ndarray
    position_agent: np.ndarray
    position_index: np.ndarray
    choice_config: np.ndarray
    choice_config_index: np.ndarray
    choice_edge: np.ndarray
    configs: np.ndarray
    initial_config: int
    legal: np.ndarray
    ended: np.ndarray
    blocking: np.ndarray
    rules: GameRules

    @property
    def n_positions(self) -> int:
        return self.game.n_positions

    def size(self) -> dict[str, int]:
        """Positions, SUT choices, agent moves and configurations (for summaries)."""
        return {
            "positions": self.game.n_positions,
            "choices": self.game.n_choices,
            "moves": self.game.n_edges,
            "configurations": int(self.configs.size),
        }


def legal_positions(products: Products, rules: GameRules, agent_place: np.ndarray, ended: np.ndarray) -> np.ndarray:
    """``bool[n_nodes, n_agent]``: positions where the agent blocks exactly ``R(q)`` (g5-g7):
    on the place of every cut reactive edge out of the node, on no place of an open one.

    ``agent_place[a]`` is the place of agent state ``a`` (-1 for a park).
    """
    g, ts = products.virtual, products.ts
    n, n_agent = g.n_nodes, agent_place.size
    n_places = len(ts.places)
    agent_of_place = np.full(n_places, -1, dtype=np.int64)
    cells = np.flatnonzero(agent_place >= 0)
    agent_of_place[agent_place[cells]] = cells
    node_place = ts.place[g.state].astype(np.int64)
    head_agent = agent_of_place[node_place[g.dst]]
    # g6: the agent must stand on the place of every restricted move out of s
    need = ~ended[g.src] & rules.cut & ~rules.static
    impossible = np.zeros(n, dtype=bool)
    impossible[g.src[need & (head_agent < 0)]] = True
    ok = need & (head_agent >= 0)
    req_lo = np.full(n, n_agent, dtype=np.int64)
    req_hi = np.full(n, -1, dtype=np.int64)
    np.minimum.at(req_lo, g.src[ok], head_agent[ok])
    np.maximum.at(req_hi, g.src[ok], head_agent[ok])
    impossible |= (req_hi >= 0) & (req_lo != req_hi)
    required = np.where(req_hi >= 0, req_hi, -1)
    # g7: and on no place of an unrestricted move out of s
    forbid = ~ended[g.src] & rules.open & (head_agent >= 0)
    forbidden = np.zeros((n, n_agent), dtype=bool)
    forbidden[g.src[forbid], head_agent[forbid]] = True
    agents = np.arange(n_agent)
    exact = ~forbidden & ~impossible[:, None] & ((required[:, None] < 0) | (agents[None, :] == required[:, None]))
    no_collision = agent_place[None, :] != node_place[:, None]
    out: np.ndarray = no_collision & (ended[:, None] | exact)
    return out


def build_agent_game(products: Products, strategy: TestStrategy, agent: TestAgent) -> AgentGame:
    """Build the test-agent game for the restrictions of ``strategy`` (docs/method.md §7).

    Parameters
    ----------
    products
        G and its node sets.
    strategy
        The routing strategy: ``Obs`` (static obstacles) and ``C(q)``.
    agent
        The test agent (``place_of_state``, ``moves``, ``start``, ``first``).

    Returns
    -------
    AgentGame
        The game (a safety game: no liveness sets) and its translation tables.
    """
    return build_game(products, rules_of_strategy(products, strategy), agent)


def build_game(products: Products, rules: GameRules, agent: TestAgent) -> AgentGame:
    """Build the test-agent game of a set of :class:`GameRules` (the module docstring's game;
    for the rules of one strategy, exactly :func:`build_agent_game`).

    The SUT takes open edges (or stays); the agent must stand where the cut reactive edges
    out of the SUT's node lead (g6) and nowhere an open edge leads (g7); g8 forbids a
    second step in a place that surely blocks every path of the SUT: ``Tgt`` reachable
    over edges that are surely no wall (open, or outside the static area), and not
    reachable, without the moves into the place, over the edges that are not surely walls.
    """
    g, ts = products.virtual, products.ts
    n, n_agent = g.n_nodes, agent.n_states
    agent_place = agent.place_of_state
    ended = ended_nodes(products)
    legal = legal_positions(products, rules, agent_place, ended)
    blocking = np.zeros((n, n_agent), dtype=bool)
    cells = np.flatnonzero(agent_place >= 0)
    wall = rules.cut & rules.static
    blocking[:, cells] = _blocking(products, rules.open | ~rules.static, ~wall, agent_place[cells])

    flat_legal = legal.ravel()
    positions = np.flatnonzero(flat_legal)
    position_index = np.full(n * n_agent, -1, dtype=np.int64)
    position_index[positions] = np.arange(positions.size)
    pos_node = positions // n_agent
    pos_agent = positions % n_agent
    node_place = ts.place[g.state].astype(np.int64)

    # the SUT's moves: open edges of G (a cut reactive edge leads onto the agent) and stays
    stay_nodes = np.flatnonzero(ts.stay[g.state] & ~ended)
    free = np.flatnonzero(rules.open)
    m_src = np.concatenate([g.src[free].astype(np.int64), stay_nodes])
    m_dst = np.concatenate([g.dst[free].astype(np.int64), stay_nodes])
    m_edge = np.concatenate([free.astype(np.int64), np.full(stay_nodes.size, -1, dtype=np.int64)])
    m_order, m_ptr = _csr(m_src, n)
    m_dst = m_dst[m_order]
    m_edge = m_edge[m_order]

    # choices: from every legal position at a node where the test goes on (a2, a5)
    owners = np.flatnonzero(~ended[pos_node])
    row, idx = _ranges(m_ptr, pos_node[owners])
    c_owner = owners[row]
    c_dst = m_dst[idx]
    c_edge = m_edge[idx]
    c_agent = pos_agent[c_owner]
    keep = node_place[c_dst] != agent_place[c_agent]
    c_owner, c_dst, c_agent, c_edge = c_owner[keep], c_dst[keep], c_agent[keep], c_edge[keep]
    c_config = c_dst * n_agent + c_agent

    # configurations: the agent's answers (g2, g5 via legality, g6/g7, g8)
    src_node, a0 = g.initial, agent.start
    initial_config = src_node * n_agent + a0 if agent.first == "agent" else -1
    extra = np.array([initial_config] if initial_config >= 0 else [], dtype=np.int64)
    configs, inverse = np.unique(np.concatenate([c_config, extra]), return_inverse=True)
    choice_config_index = inverse[: c_config.size]
    k_node, k_agent = configs // n_agent, configs % n_agent
    ta_order, ta_ptr = _csr(agent.moves[:, 0].astype(np.int64), n_agent)
    ta_dst = agent.moves[ta_order, 1].astype(np.int64)
    krow, kidx = _ranges(ta_ptr, k_agent)
    cand = ta_dst[kidx]
    cnode = k_node[krow]
    ok = legal[cnode, cand] & ~((cand == k_agent[krow]) & blocking[cnode, k_agent[krow]])
    krow, cand, cnode = krow[ok], cand[ok], cnode[ok]
    k_succ = position_index[cnode * n_agent + cand]
    k_ptr = np.zeros(configs.size + 1, dtype=np.int64)
    np.cumsum(np.bincount(krow, minlength=configs.size), out=k_ptr[1:])

    # each choice owns a copy of its configuration's answers
    crow, cidx = _ranges(k_ptr, choice_config_index)
    choice_succ = k_succ[cidx]
    choice_ptr = np.zeros(c_owner.size + 1, dtype=np.int64)
    np.cumsum(np.bincount(crow, minlength=c_owner.size), out=choice_ptr[1:])

    if agent.first == "agent":
        k0 = int(np.searchsorted(configs, initial_config))
        group = k_succ[k_ptr[k0] : k_ptr[k0 + 1]]
    else:
        p0 = position_index[src_node * n_agent + a0]
        group = np.array([p0] if p0 >= 0 else [], dtype=np.int64)
    game = GR1Game(
        n_positions=int(positions.size),
        choice_owner=c_owner,
        choice_succ_ptr=choice_ptr,
        choice_succ=choice_succ,
        initial=[group],
        env_liveness=[],
        sys_liveness=[],
    )
    return AgentGame(
        game=game,
        n_agent=n_agent,
        position_node=pos_node,
        position_agent=pos_agent,
        position_index=position_index,
        choice_config=c_config,
        choice_config_index=choice_config_index,
        choice_edge=c_edge,
        configs=configs,
        initial_config=int(initial_config),
        legal=legal,
        ended=ended,
        blocking=blocking,
        rules=rules,
    )


def realizability_exclusions(products: Products, agent: TestAgent, groups: CutGroups) -> list[list[int]]:
    """Cuts no test agent can hold, as MILP exclusion rows ``d_g <= 0`` (before the first solve).

    A cut group ``g`` is excluded when every edge of it leaves a node ``v = (s, q)``
    where the SUT may stay, into an agent place ``p`` where the agent cannot stay (no
    stay move in ``T_TA``) or that blocks every path of the SUT at ``v`` (g8). If ``v``
    is reachable, the SUT can stay at ``s`` and the agent would have to hold ``p`` (g6)
    by staying, which ``T_TA`` or g8 forbids.

    Soundness: if a cut set containing ``g`` were realizable, the tails of ``g`` would be
    unreachable under it (the closed loop follows G minus the cuts exactly), so dropping
    ``g`` leaves a realizable routing cut set with no fewer paths, no more cuts and no
    more blocked places: the MILP-agent optimum over realizable cut sets is unchanged.
    Blocking is computed without static obstacles; where a place blocks every path
    there, with obstacles it either still does or the node is trapped, which the loop
    rejects as well. (Pairs of cuts out of one node into two places are unrealizable
    too, but adding those rows only perturbed HiGHS's choice among equally good cut sets
    and cost more solves on the built-ins, so they are left to the loop.)

    Parameters
    ----------
    products
        G (with the harness the MILP uses).
    agent
        The test agent.
    groups
        The MILP's cut groups (``of_edge``, ``keys``, ``restrictable``, ``static``), from
        :func:`synthesis.routing.groups.cut_groups`.

    Returns
    -------
    list[list[int]]
        One single-key exclusion per excluded group.
    """
    g, ts = products.virtual, products.ts
    n_agent = agent.n_states
    agent_place = agent.place_of_state
    agent_of_place = np.full(len(ts.places), -1, dtype=np.int64)
    cells = np.flatnonzero(agent_place >= 0)
    agent_of_place[agent_place[cells]] = cells
    ended = ended_nodes(products)
    head = agent_of_place[ts.place[g.state[g.dst]]]
    grp = groups.of_edge
    reactive = ~groups.static[grp] & groups.restrictable[grp] & (head >= 0) & ~ended[g.src]
    can_stay = np.zeros(n_agent, dtype=bool)
    can_stay[agent.moves[agent.moves[:, 0] == agent.moves[:, 1], 0]] = True
    blocking = np.zeros((g.n_nodes, n_agent), dtype=bool)
    blocking[:, cells] = blocking_places(products, np.zeros(ts.n_moves, dtype=bool), agent_place[cells])
    hopeless = reactive & ts.stay[g.state[g.src]]
    hopeless[hopeless] = ~can_stay[head[hopeless]] | blocking[g.src[hopeless], head[hopeless]]
    n_groups = groups.keys.size
    all_bad = np.bincount(grp, weights=hopeless, minlength=n_groups) == np.bincount(grp, minlength=n_groups)
    used = np.zeros(n_groups, dtype=bool)
    used[grp[reactive]] = True
    return [[int(k)] for k in groups.keys[all_bad & used]]
