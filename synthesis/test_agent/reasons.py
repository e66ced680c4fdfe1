"""Why the counterexample loop rejects a cut set, as an exclusion of every cut set with the
same reason.

A rejected cut set ``C`` alone excludes one cut set per MILP solve. Unrealizability is
**not monotone** in the cut set, so "exclude every superset of a core of ``C``" would be
wrong: a cut set with one more cut asks the agent to stand on that cut's place (g6), but it
also no longer forbids the agent that place (g7) and takes a move away from the SUT, so the
agent may win the game of the larger set (the smaller one can even lose for want of a
restriction: with no cut at all the agent must stay clear of every place the SUT could
enter next). What *is* monotone is a reason with both sides: a set ``K`` of groups that are
cut and a set ``O`` of groups that stay open. The game of the rules ``(K, O)``
(:func:`synthesis.test_agent.game.build_game`: the SUT takes only open edges, the agent must
realize the cut reactive edges, must stay off the places of open edges, and g8 holds only
where it holds for every such cut set) is won by the agent whenever the game of any cut set
``C' ⊇ K`` with ``C' ∩ O = ∅`` is: every SUT move of the ``(K, O)`` game is a move of
``C'``'s game, and every legal answer there is legal here. So if the agent loses the
``(K, O)`` game it loses every such ``C'``, and the exclusion row
``sum_{g in K} d_g - sum_{g in O} d_g <= |K| - 1`` (:class:`~synthesis.routing.model.Exclusion`)
removes only cut sets the loop would reject: the loop's answer keeps its flow and cost.

:func:`unrealizable_reason` starts from ``K = C`` and ``O`` = every other group (that game
is the real one), keeps in ``O`` the groups of the edges the SUT's winning strategy takes
(the environment's attractor), then drops cuts from ``K`` one at a time while the agent
still loses. :func:`trap_reason` does the same for a cut set that traps the SUT: the cuts
around the trap stay in ``K``, a path to it stays open.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from ..graphs.products import Products, coreachable, reachable
from ..model.agent_system import TestAgent
from ..model.strategy import TestStrategy
from ..routing.groups import CutGroups
from ..routing.options import Exclusion
from .game import AgentGame, GameRules, build_game, ended_nodes
from .gr1.solver import solve as solve_gr1

__all__ = ["Reason", "reason_groups", "trap_reason", "unrealizable_reason"]


@dataclass(frozen=True)
class Reason:
    """The reason a cut set was rejected, as the exclusion it earns.

    Attributes
    ----------
    exclusion
        Every cut set that cuts ``exclusion.cut`` and leaves ``exclusion.open`` open.
    cut_groups
        Groups of the rejected cut set (``|C|``), for comparison with ``len(exclusion.cut)``.
    games
        Games of rules solved to find it.
    """

    exclusion: Exclusion
    cut_groups: int
    games: int


@dataclass(frozen=True)
class _Edges:
    """The cut groups seen per edge of G: the group, whether a cut of it blocks the edge
    in the test strategy (a reactive cut touching ``I`` is no restriction), whether the
    MILP can cut it at all, and whether it is a wall."""

    group: np.ndarray
    can_cut: np.ndarray
    static: np.ndarray


def reason_groups(products: Products, groups: CutGroups) -> _Edges:
    """The per-edge view of the MILP's cut groups that reasons are written in."""
    grp = groups.of_edge
    effective = groups.static[grp] | ~products.touches_intermediate
    return _Edges(group=grp, can_cut=effective & groups.restrictable[grp], static=groups.static[grp])


def _rules(edges: _Edges, cut: np.ndarray, open_: np.ndarray) -> GameRules:
    """Rules of the groups ``cut`` (cut) and ``open_`` (open); edges no cut can block are open."""
    c = cut[edges.group] & edges.can_cut
    o = ~edges.can_cut | open_[edges.group]
    return GameRules(cut=c, open=o, static=edges.static)


def _exclusion(groups: CutGroups, cut: np.ndarray, open_: np.ndarray) -> Exclusion:
    return Exclusion(
        cut=tuple(int(k) for k in groups.keys[cut]),
        open=tuple(int(k) for k in groups.keys[open_ & groups.restrictable]),
    )


def _lost(products: Products, rules: GameRules, agent: TestAgent) -> tuple[bool, AgentGame]:
    game = build_game(products, rules, agent)
    return not solve_gr1(game.game).realizable, game


def _env_witness(game: AgentGame) -> tuple[np.ndarray, np.ndarray]:
    """The SUT's winning strategy in a lost game, followed from the start against every
    answer of the agent: ``(positions visited, edges of G it takes)``.

    The agent loses a safety game exactly on the environment's attractor of the choices
    it cannot answer; the SUT plays, at a position of rank ``r``, a choice whose answers
    all have rank below ``r``.
    """
    gm = game.game
    n, m = gm.n_positions, gm.n_choices
    outdeg = np.diff(gm.choice_succ_ptr)
    matrix = sp.csr_matrix((np.ones(gm.n_edges, dtype=np.int32), gm.choice_succ, gm.choice_succ_ptr), shape=(m, n))
    pos_rank = np.full(n, -1, dtype=np.int64)
    choice_rank = np.full(m, -1, dtype=np.int64)
    inside = np.zeros(n, dtype=bool)
    full = outdeg == 0
    layer = 0
    while True:
        new_choices = full & (choice_rank < 0)
        choice_rank[new_choices] = layer
        owners = np.unique(gm.choice_owner[new_choices])
        owners = owners[~inside[owners]]
        if owners.size == 0:
            break
        inside[owners] = True
        pos_rank[owners] = layer
        layer += 1
        full = (matrix @ inside.astype(np.int32)) == outdeg
    # the choice each attractor position plays: the first one that put it there
    play = np.full(n, -1, dtype=np.int64)
    entering = np.flatnonzero((choice_rank >= 0) & (choice_rank == pos_rank[gm.choice_owner]))
    first = np.unique(gm.choice_owner[entering], return_index=True)[1]
    play[gm.choice_owner[entering[first]]] = entering[first]
    start = np.unique(np.concatenate([np.asarray(g, dtype=np.int64) for g in gm.initial]))
    seen = np.zeros(n, dtype=bool)
    frontier = start[inside[start]]
    seen[frontier] = True
    taken: list[np.ndarray] = []
    while frontier.size:
        chosen = play[frontier]
        chosen = chosen[chosen >= 0]
        taken.append(game.choice_edge[chosen])
        lo, hi = gm.choice_succ_ptr[chosen], gm.choice_succ_ptr[chosen + 1]
        succ = np.concatenate([gm.choice_succ[a:b] for a, b in zip(lo.tolist(), hi.tolist(), strict=True)]) if chosen.size else np.zeros(0, dtype=np.int64)
        succ = np.unique(succ)
        frontier = succ[~seen[succ]]
        seen[frontier] = True
    edges = np.unique(np.concatenate(taken)) if taken else np.zeros(0, dtype=np.int64)
    return np.flatnonzero(seen), edges[edges >= 0]


def unrealizable_reason(products: Products, groups: CutGroups, cut_mask: np.ndarray, agent: TestAgent) -> Reason:
    """The reason the agent loses the game of the cut set ``cut_mask`` (bool over groups).

    Falls back to the cut set itself (``Exclusion(C)``) should the game of its rules be
    won (it is the game the loop lost, so this does not happen; the fallback keeps the
    exclusion sound regardless).
    """
    edges = reason_groups(products, groups)
    n_groups = groups.keys.size
    cuttable = np.bincount(edges.group, weights=edges.can_cut, minlength=n_groups) > 0
    cut = cut_mask & cuttable
    open_ = ~cut_mask & cuttable
    whole = Exclusion(cut=tuple(int(k) for k in groups.keys[cut_mask]))
    lost, game = _lost(products, _rules(edges, cut, open_), agent)
    games = 1
    if not lost:
        return Reason(whole, int(cut_mask.sum()), games)
    # keep open only what the SUT's winning strategy takes (then also what leaves its nodes)
    visited, taken = _env_witness(game)
    used = np.zeros(n_groups, dtype=bool)
    used[edges.group[taken[edges.can_cut[taken]]]] = True
    g = products.virtual
    nodes = np.zeros(g.n_nodes, dtype=bool)
    nodes[game.position_node[visited]] = True
    around = used.copy()
    out_edges = nodes[g.src] & edges.can_cut & open_[edges.group]
    around[edges.group[out_edges]] = True
    for trial in (used & open_, around & open_):
        games += 1
        if _lost(products, _rules(edges, cut, trial), agent)[0]:
            open_ = trial
            break
    # drop cuts while the agent still loses: first every reactive cut out of nodes the
    # SUT never visits, then one at a time
    near = np.zeros(n_groups, dtype=bool)
    near[edges.group[edges.can_cut & (nodes[g.src] | edges.static)]] = True
    drop = cut & ~near
    if drop.any():
        games += 1
        if _lost(products, _rules(edges, cut & ~drop, open_), agent)[0]:
            cut = cut & ~drop
    for k in np.flatnonzero(cut).tolist():
        trial = cut.copy()
        trial[k] = False
        games += 1
        if _lost(products, _rules(edges, trial, open_), agent)[0]:
            cut = trial
    return Reason(_exclusion(groups, cut, open_), int(cut_mask.sum()), games)


def trap_reason(products: Products, groups: CutGroups, cut_mask: np.ndarray, strategy: TestStrategy, node: int) -> Reason:
    """The reason the cut set ``cut_mask`` traps the SUT at ``node`` (a node of
    :func:`~synthesis.test_agent.game.trapped_nodes` for ``strategy``, the cut set's test).

    ``K`` = the cuts on the edges that leave the region the SUT can still reach from the
    trap, then fewer while they alone still close every way from the trap to ``Tgt``;
    ``O`` = the groups of a path from the start to the trap, and the walls of a way from
    the trap to ``Tgt`` that no wall of the cut set closes. Every cut set that cuts ``K``
    and leaves ``O`` open lets the SUT walk the path to the trap (the test is not over on
    the way), leaves the trap a way to ``Tgt`` on the map (not walled off) and closes
    every way from it to ``Tgt`` under its restrictions: a trap again.
    """
    edges = reason_groups(products, groups)
    g = products.virtual
    blocked = strategy.blocked[g.hist[g.src], g.move]
    keep = ~blocked
    start = np.zeros(g.n_nodes, dtype=bool)
    start[node] = True
    region = reachable(g.n_nodes, g.src[keep], g.dst[keep], start)
    leaving = blocked & region[g.src] & ~region[g.dst]
    n_groups = groups.keys.size
    cut = np.zeros(n_groups, dtype=bool)
    cut[edges.group[leaving]] = True
    cut &= cut_mask
    # fewer cuts: drop one while no way from the trap to Tgt avoids the cuts left
    for k in np.flatnonzero(cut).tolist():
        trial = cut.copy()
        trial[k] = False
        free = ~(trial[edges.group] & edges.can_cut)
        if not coreachable(g.n_nodes, g.src[free], g.dst[free], products.target)[node]:
            cut = trial
    # a shortest open path from the start to the trap, through nodes where the test goes on
    walk = np.flatnonzero(keep & ~ended_nodes(products)[g.src])
    graph = sp.csr_matrix((np.ones(walk.size), (g.src[walk], g.dst[walk])), shape=(g.n_nodes, g.n_nodes))
    _, pred = breadth_first_order(graph, int(g.initial), directed=True, return_predecessors=True)
    path_edges: list[int] = []
    edge_of = {(int(a), int(b)): int(e) for e, a, b in zip(walk.tolist(), g.src[walk].tolist(), g.dst[walk].tolist(), strict=True)}
    v = node
    while v != int(g.initial):
        u = int(pred[v])
        if u < 0:  # not reachable: the loop's trap check says it is, so keep the whole cut set
            return Reason(Exclusion(cut=tuple(int(k) for k in groups.keys[cut_mask])), int(cut_mask.sum()), 0)
        path_edges.append(edge_of[(u, v)])
        v = u
    on_path = np.asarray(path_edges, dtype=np.int64)
    open_ = np.zeros(n_groups, dtype=bool)
    open_[edges.group[on_path[edges.can_cut[on_path]]]] = True
    way = _way_on_map(products, strategy, node)
    if way is None:  # walled off: the loop's trap check says it is not, so keep the whole cut set
        return Reason(Exclusion(cut=tuple(int(k) for k in groups.keys[cut_mask])), int(cut_mask.sum()), 0)
    walls = way[edges.static[way] & edges.can_cut[way]]
    open_[edges.group[walls]] = True
    return Reason(_exclusion(groups, cut, open_), int(cut_mask.sum()), 0)


def _way_on_map(products: Products, strategy: TestStrategy, node: int) -> np.ndarray | None:
    """The edges of G of a shortest way from ``node`` to ``Tgt`` over moves that are not
    static walls of ``strategy`` (``None``: there is none, the node is walled off)."""
    g = products.virtual
    free = np.flatnonzero(~strategy.static_obstacles[g.move])
    graph = sp.csr_matrix((np.ones(free.size), (g.src[free], g.dst[free])), shape=(g.n_nodes, g.n_nodes))
    order, pred = breadth_first_order(graph, int(node), directed=True, return_predecessors=True)
    hits = order[products.target[order]]
    if hits.size == 0:
        return None
    edge_of = {(int(a), int(b)): int(e) for e, a, b in zip(free.tolist(), g.src[free].tolist(), g.dst[free].tolist(), strict=True)}
    way: list[int] = []
    v = int(hits[0])
    while v != int(node):
        u = int(pred[v])
        way.append(edge_of[(u, v)])
        v = u
    return np.asarray(way, dtype=np.int64)
