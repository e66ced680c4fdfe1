"""Exhaustive fairness check of a tester: are its traps *found*, not sampled.

A tester (the synthesized test, a learned one, a hand-made one) plays ``tester_0`` in
the PettingZoo game (:mod:`flowtest_env.multiagent`) by its rules: it restricts moves of
the system's current state (never all of them) or moves the test agent. A test is
*unfair* when it can **trap** a correct system: some run reaches a state from which
the system, whatever legal moves it plays, can no longer meet its objective against
the tester's answers, although the static walls alone would still let it through (a
state the static walls doom ends the run as ``violated``: that is the system's doing,
not the tester's).

For a tester that is a deterministic function of the run state (the synthesized test;
a learned tester acting deterministically on its observation: the system state, the
history and the agent's place), this is decided exactly by a search over the game: the
product of the tester's choices with **all** system moves. Nodes are run states at the
system's turn (system state, history, agent place and strategy memory, and the
tester's restrictions of this step); a node is *good* when some sequence of system
moves from it meets the system objective (backward fixpoint over the explored graph).
A reachable live node that is not good is a trap. The same search also checks the
routing guarantee: whether some run meets the system objective without realizing the
test objective (a *bypass*).

The rules are played through the environment itself (:meth:`raw_env.apply_tester`,
:meth:`TestGame.system_step`), so the search and the environment cannot disagree.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .game import MET, GameError, RunState, TestGame
from .multiagent import SYSTEM, raw_env

TesterChoice = Callable[[raw_env], int]
"""A deterministic tester: reads ``env.run`` (or ``env.observe("tester_0")``) and answers
its action. It must not change the run."""

NodeKey = tuple[int, int, int, int, int]
"""``(system, history, agent, memory, restriction bits)`` at the system's turn."""

DEFAULT_MAX_NODES = 2_000_000
"""Explored nodes at most (a deterministic budget; every built-in problem needs far fewer)."""


class SearchTooLarge(GameError):
    """The game has more reachable nodes than the budget allows."""


@dataclass
class FairnessReport:
    """The outcome of :func:`check_tester`.

    Attributes
    ----------
    nodes
        Reachable nodes (run states at the system's turn) explored.
    traps
        How many of them are traps (live, the system objective unreachable).
    trap_path
        System actions from the reset to the first trap found (breadth-first: a
        shortest one), ``None`` if the tester is fair.
    trap_state
        That trap's run state.
    bypasses
        Reachable system moves that meet the system objective without the test
        objective realized (the routing guarantee broken).
    bypass_path
        System actions of a shortest such run, ``None`` if there is none.
    illegal
        Nodes at which the tester answered an action outside its mask (always 0 for a
        tester that plays by the rules; the environment would turn it into a no-op).
    trap_keys
        The first 100 trap nodes, as :data:`NodeKey` tuples.
    """

    nodes: int = 0
    traps: int = 0
    trap_path: list[int] | None = None
    trap_state: RunState | None = None
    bypasses: int = 0
    bypass_path: list[int] | None = None
    illegal: int = 0
    trap_keys: list[NodeKey] = field(default_factory=list)

    @property
    def fair(self) -> bool:
        """No reachable state traps the system."""
        return self.traps == 0

    @property
    def guaranteed(self) -> bool:
        """Every run that meets the system objective realizes the test objective."""
        return self.bypasses == 0

    def summary(self) -> dict[str, object]:
        """A JSON-ready summary."""
        return {
            "nodes": self.nodes,
            "fair": self.fair,
            "traps": self.traps,
            "trap_path": self.trap_path,
            "guaranteed": self.guaranteed,
            "bypasses": self.bypasses,
            "bypass_path": self.bypass_path,
            "illegal": self.illegal,
        }


def _key(run: RunState) -> NodeKey:
    return (run.system, run.history, run.agent, run.memory, -1 if run.override is None else run.override)


def _tester_turn(env: raw_env, run: RunState, choose: TesterChoice, report: FairnessReport) -> RunState:
    """``run`` after the tester's answer (a copy)."""
    env.run = run.copy()
    action = int(choose(env))
    if not env.apply_tester(action):
        report.illegal += 1
    return env.run


def check_tester(env: raw_env, choose: TesterChoice, max_nodes: int = DEFAULT_MAX_NODES) -> FairnessReport:
    """Search every run of ``env``'s game against the tester ``choose`` (see the module
    docstring). ``env`` is a :func:`flowtest_env.multiagent.raw_env`; its run is restored
    afterwards.

    Raises
    ------
    SearchTooLarge
        If more than ``max_nodes`` nodes are reachable.
    """
    game = env.game
    saved = env.run
    report = FairnessReport()
    tester_first = env.possible_agents[0] != SYSTEM
    try:
        start = game.reset(agent_first_move=False)
        if tester_first:
            start = _tester_turn(env, start, choose, report)
        index: dict[NodeKey, int] = {_key(start): 0}
        runs: list[RunState] = [start]
        parent: list[tuple[int, int]] = [(-1, -1)]
        edges_src: list[int] = []
        edges_dst: list[int] = []
        good_direct: list[bool] = [False]
        first_bypass: tuple[int, int] | None = None
        i = 0
        while i < len(runs):  # breadth-first over the nodes
            run = runs[i]
            for a in np.flatnonzero(game.action_mask(run)):
                nxt = run.copy()
                game.system_step(nxt, int(a))
                if nxt.outcome == MET:
                    good_direct[i] = True
                    if not game.test_accepting[nxt.history]:
                        report.bypasses += 1
                        if first_bypass is None:
                            first_bypass = (i, int(a))
                    continue
                if nxt.done:  # violated: the static walls doom it, the system's own doing
                    continue
                nxt = _tester_turn(env, nxt, choose, report)  # answers the system's move
                k = _key(nxt)
                j = index.get(k)
                if j is None:
                    if len(runs) >= max_nodes:
                        raise SearchTooLarge(f"more than {max_nodes} reachable game states")
                    j = index[k] = len(runs)
                    runs.append(nxt)
                    parent.append((i, int(a)))
                    good_direct.append(False)
                edges_src.append(i)
                edges_dst.append(j)
            i += 1
        n = len(runs)
        good = np.asarray(good_direct, dtype=bool)
        src = np.asarray(edges_src, dtype=np.int64)
        dst = np.asarray(edges_dst, dtype=np.int64)
        while True:  # backward fixpoint: good if some move leads to a good node
            grow = np.unique(src[good[dst] & ~good[src]])
            if grow.size == 0:
                break
            good[grow] = True
        report.nodes = n
        traps = np.flatnonzero(~good)
        report.traps = int(traps.size)
        report.trap_keys = [_key(runs[t]) for t in traps[:100]]
        if traps.size:
            t = int(traps[0])  # breadth-first order: a shortest way in
            report.trap_state = runs[t].copy()
            report.trap_path = _path(parent, t)
        if first_bypass is not None:
            report.bypass_path = _path(parent, first_bypass[0]) + [first_bypass[1]]
        return report
    finally:
        env.run = saved


def _path(parent: list[tuple[int, int]], node: int) -> list[int]:
    out: list[int] = []
    while parent[node][0] >= 0:
        node, a = parent[node]
        out.append(a)
    return out[::-1]


def can_still_meet(env: raw_env, choose: TesterChoice, run: RunState, tester_next: bool, max_nodes: int = DEFAULT_MAX_NODES) -> bool:
    """Whether some sequence of legal system moves from ``run`` meets the system objective
    against the tester ``choose``: ``run`` waits for the tester's answer when
    ``tester_next``, else it is at the system's turn (the tester's restrictions of this
    step chosen). ``env``'s run is restored afterwards.

    Raises
    ------
    SearchTooLarge
        If more than ``max_nodes`` nodes are reachable.
    """
    if run.outcome == MET:
        return True
    if run.done:
        return False
    saved = env.run
    try:
        start = _tester_turn(env, run, choose, FairnessReport()) if tester_next else run.copy()
        return _meets_from(env.game, start, lambda r: _tester_turn(env, r, choose, FairnessReport()), max_nodes)
    finally:
        env.run = saved


def can_still_meet_in_game(game: TestGame, run: RunState) -> bool:
    """Whether some sequence of legal system moves from ``run`` meets the system objective
    against the test as the single-agent game plays it (its restrictions per history, its
    test agent moved by the synthesized strategy), with no step budget: the search of
    :func:`can_still_meet` with the game's own answers. ``run`` is not changed.

    The test is deterministic, so this is a search over the run states reachable from
    ``run``. A run that ends where this is false, although the static walls alone would let
    the system through, was trapped by the test (``flowtest evaluate`` calls it a FlowTest bug).
    """
    if run.outcome == MET:
        return True
    if run.done:
        return False

    def answer(r: RunState) -> RunState:
        if game.has_agent:
            game.agent_respond(r)
        return r

    return _meets_from(game, run.copy(), answer, None)


def _meets_from(game: TestGame, start: RunState, answer: Callable[[RunState], RunState], max_nodes: int | None) -> bool:
    """The search of :func:`can_still_meet`: breadth first over the run states at the system's
    turn reachable from ``start`` (a live run at the system's turn), each system move followed
    by the test's ``answer`` (a function of the run after the move); whether one meets the
    system objective. ``max_nodes`` bounds the states explored (``None``: no bound).

    Raises
    ------
    SearchTooLarge
        If more than ``max_nodes`` nodes are reachable.
    """
    seen = {_key(start)}
    frontier = [start]
    while frontier:
        nxt_frontier = []
        for r in frontier:
            for a in np.flatnonzero(game.action_mask(r)):
                r2 = r.copy()
                game.system_step(r2, int(a))
                if r2.outcome == MET:
                    return True
                if r2.done:
                    continue
                r2 = answer(r2)
                k = _key(r2)
                if k in seen:
                    continue
                if max_nodes is not None and len(seen) >= max_nodes:
                    raise SearchTooLarge(f"more than {max_nodes} reachable game states")
                seen.add(k)
                nxt_frontier.append(r2)
        frontier = nxt_frontier
    return False
