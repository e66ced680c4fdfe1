"""A planner with a realistic costmap bug, for the report's tests (``python:PATH:Forgetful``).

It plans a shortest path to the goal on what the planner protocol's ``hello`` gives (the map
without its walls, the system objective's automaton), around the moves it sees refused now,
and forgets a closed door as soon as it is out of view: in front of a door that stays
closed it steps aside (the door is now out of view), forgets it and comes back, forever.
Nothing of FlowTest is imported: it is a planner from outside, as a user writes one.
"""

from __future__ import annotations

from collections import deque
from typing import Any


def key(state: Any) -> Any:
    """A hashable key of a state written as JSON."""
    return tuple(key(x) for x in state) if isinstance(state, list) else state


class Forgetful:
    """Shortest path around the moves refused *now*; a door out of view is forgotten."""

    def __init__(self, test: dict[str, Any]) -> None:
        system, automaton = test["system"], test["automaton"]
        self.index = {key(s): i for i, s in enumerate(system["states"])}
        self.next, self.accepting = automaton["next"], automaton["accepting"]
        self.initial = automaton["initial"]
        self.into: dict[tuple[int, int], list[tuple[int, int, tuple[int, int]]]] = {}
        for q in range(len(self.accepting)):
            for s, t in system["moves"]:
                self.into.setdefault((t, self.next[q][t]), []).append((s, q, (s, t)))
        self.q: int | None = None

    def reset(self, seed: int | None) -> None:
        self.q = None

    def act(self, observation: dict[str, Any], mask: Any) -> str:
        here = self.index[key(observation["state"])]
        self.q = self.next[self.initial if self.q is None else self.q][here]
        refused = {(here, self.index[key(r["to"])]) for r in observation["restricted"]}  # the bug: only what it sees now
        todo = deque((s, q) for s in range(len(self.index)) for q in range(len(self.accepting)) if self.accepting[q])
        dist = dict.fromkeys(todo, 0)
        while todo:
            node = todo.popleft()
            for s, q, move in self.into.get(node, []):
                if (s, q) not in dist and move not in refused:
                    dist[(s, q)] = dist[node] + 1
                    todo.append((s, q))
        options = [
            (dist.get((self.index[key(t)], self.next[self.q][self.index[key(t)]]), 1 << 30), a)
            for a, t in zip(observation["allowed"], observation["to"], strict=True)
            if a != "stay"
        ]
        return min(options)[1] if options else "stay"
