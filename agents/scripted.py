"""Scripted systems under test: one correct replanner and three realistic faulty ones.

Every scripted SUT knows what a real planner would know: its transition system (the
map, with the test's *static walls*, which every observation shows), its own *system*
objective (as the automaton ``B_sys``), and the restrictions it observes *now* through
the action mask. None of them sees the hidden test objective,
the test's history or the test agent's strategy.

* ``scripted:replanner`` (:class:`Replanner`) — correct. Plans a shortest path on its
  system product graph ``G_sys = T x B_sys`` (so fuel, safety and reactions of its
  objective are respected: it never enters a node from which its objective can no
  longer be met), replanning every step. Restrictions it has seen are remembered as
  blocked transitions (so it does not oscillate in front of a closed door) and
  forgotten when it sees them open again; when the remembered blocks cut it off from
  its goal it forgets all but the ones it sees now, and when even those leave no path
  it waits in place rather than violate its objective.
* ``scripted:committed`` (:class:`Committed`) — fault: *plans once and never
  replans*. At reset it computes a shortest path on ``G_sys`` (with the restrictions
  visible at its start) and then follows it blindly; when a planned move is restricted
  it waits for it to open, so a door that closes on its plan stalls it until the step
  budget runs out.
* ``scripted:fuel-blind`` (:class:`FuelBlind`) — fault: *plans on cells only*. Shortest
  path (with the same replanning and memory as the correct SUT, walls included) to the nearest goal
  cell, ignoring fuel, safety and the other parts of its objective: it runs dry, enters
  unsafe cells, or reaches the goal without the sub-goal it had to visit first.
* ``scripted:greedy`` (:class:`Greedy`) — fault: *one-step greedy descent*. Moves to the
  legal neighbour closest to the nearest goal cell (Manhattan distance on grids, hop
  distance on graphs, ignoring walls and restrictions in the estimate); when no
  neighbour is closer than where it stands, it is stuck in a local minimum (a dead end
  of the maze, a closed door) and stays.

Contract: ``reset`` must be called after the env's ``reset`` (the env may switch games
at reset, e.g. ``FlowTest-RandomGrid-v0``).
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from flowtest_env.game import TestGame, grid_cell
from flowtest_env.system_product import INF

from .base import Policy, PolicyError
from .planning import Tracked, safe_wait


class Replanner(Tracked):
    """The correct scripted SUT (see the module docstring)."""

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        game, prod, v, mask, now_blocked = self._situation(observation, info)
        dist = prod.distances(frozenset(self.known))
        if dist[v] >= INF:
            self.known = set(now_blocked)
            dist = prod.distances(frozenset(self.known))
        if dist[v] >= INF:  # every path blocked now: wait for the test to open one
            return safe_wait(game, prod, v, mask, prod.distances())
        best, best_d = -1, INF
        for a in range(game.n_actions):
            w = prod.next_node[v, a]
            if mask[a] and w >= 0 and dist[w] < best_d:
                best, best_d = a, int(dist[w])
        return best if best >= 0 else safe_wait(game, prod, v, mask, prod.distances())


class Committed(Tracked):
    """Faulty: plans once at reset, never replans (see the module docstring)."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.plan: list[int] | None = None

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.plan = None

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        game, s, q, mask = self._look(observation, info)
        prod = self.product
        assert prod is not None
        if self.plan is None:
            blocked = frozenset((s, a) for a in range(game.n_slots) if not mask[a])
            self.plan = prod.path(prod.node(s, q), blocked)
        if not self.plan:
            return game.stay_action
        a = self.plan[0]
        if not mask[a]:
            return game.stay_action  # waits for its planned move; never looks for another
        self.plan.pop(0)
        return a


def _place_distances(game: TestGame, blocked: frozenset[tuple[int, int]] = frozenset()) -> np.ndarray:
    """Hop distance from every place to the nearest goal place (terminal states), over
    the place graph minus the static walls and the blocked ``(place, place')`` transitions."""
    ts = game.ts
    walls = game.artifact.strategy.static_obstacles
    n_places = len(ts.places)
    goal = np.zeros(n_places, dtype=bool)
    goal[ts.place[ts.terminal]] = True
    radj: list[set[int]] = [set() for _ in range(n_places)]
    for a, b, w in zip(ts.place[ts.src].tolist(), ts.place[ts.dst].tolist(), walls.tolist(), strict=True):
        if a != b and not w and (a, b) not in blocked:
            radj[b].add(a)
    dist = np.full(n_places, INF, dtype=np.int64)
    dq = deque(np.flatnonzero(goal).tolist())
    dist[goal] = 0
    while dq:
        v = dq.popleft()
        for u in radj[v]:
            if dist[u] == INF:
                dist[u] = dist[v] + 1
                dq.append(u)
    return dist


class FuelBlind(Tracked):
    """Faulty: shortest path in cells to the goal, ignoring fuel, safety and sub-goals."""

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self.known: set[tuple[int, int]] = set()

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.known = set()

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        game, s, _, mask = self._look(observation, info)
        place = game.ts.place
        p = int(place[s])
        now = set()
        for a in range(game.n_slots):
            if game.slot_list[s][a] < 0:
                continue
            edge = (p, int(place[game.succ_list[s][a]]))
            if mask[a]:
                self.known.discard(edge)
            else:
                now.add(edge)
        self.known |= now
        dist = _place_distances(game, frozenset(self.known))
        if dist[p] >= INF:
            self.known = now
            dist = _place_distances(game, frozenset(self.known))
        best, best_d = game.stay_action, INF
        for a in range(game.n_slots):
            if mask[a] and game.slot_list[s][a] >= 0:
                d = int(dist[place[game.succ_list[s][a]]])
                if d < best_d:
                    best, best_d = a, d
        return best if mask[best] or best != game.stay_action else _any_legal(game, mask)


def _any_legal(game: TestGame, mask: np.ndarray) -> int:
    legal = np.flatnonzero(mask)
    return int(legal[0]) if legal.size else game.stay_action


class Greedy(Tracked):
    """Faulty: one-step greedy descent on a goal-distance estimate; stuck at local minima."""

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        game = self.game
        assert game is not None
        ts = game.ts
        if ts.layout is not None:
            goals = [grid_cell(ts.places[int(p)]) for p in np.unique(ts.place[ts.terminal])]
            cells = [grid_cell(place) for place in ts.places]
            self.h = np.array(
                [min(abs(c[0] - g[0]) + abs(c[1] - g[1]) for g in goals) if goals else 0 for c in cells],
                dtype=np.int64,
            )
        else:
            self.h = _place_distances(game)

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        game, s, _, mask = self._look(observation, info)
        place = game.ts.place
        here = int(self.h[place[s]])
        best, best_h = game.stay_action, here
        for a in range(game.n_slots):
            if mask[a] and game.slot_list[s][a] >= 0:
                hv = int(self.h[place[game.succ_list[s][a]]])
                if hv < best_h:
                    best, best_h = a, hv
        if best == game.stay_action and not mask[best]:
            return _any_legal(game, mask)
        return best


SCRIPTED: dict[str, type[Tracked]] = {
    "replanner": Replanner,
    "committed": Committed,
    "fuel-blind": FuelBlind,
    "greedy": Greedy,
}
"""The scripted SUTs by name (``scripted:<name>``)."""


def make_scripted(env: Any, arg: str) -> Policy:
    """The scripted SUT ``scripted:<arg>`` (``replanner`` when ``arg`` is empty) for ``env``.

    Raises
    ------
    PolicyError
        On an unknown name.
    """
    cls = SCRIPTED.get(arg or "replanner")
    if cls is None:
        raise PolicyError(f"unknown scripted SUT {arg!r}; known: {', '.join(SCRIPTED)}")
    policy = cls(env)
    policy.reset(None)
    return policy  # type: ignore[return-value]
