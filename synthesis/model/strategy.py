"""Test strategies (docs/method.md §6): which moves are restricted, given the history.

A :class:`TestStrategy` is what an environment enforces. ``blocked[q]`` is the mask of
moves of T restricted while the history is ``q``: the static obstacles (walls for the
whole test) together with the reactive restrictions ``C(q)``.

Obstacle settings, which differ in what is *shown*, never in what is restricted:

* ``instantaneous``: the active obstacles are those on the moves out of the current
  state under the current history;
* ``accumulative``: obstacles met under the current history stay up until the
  history changes.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SETTINGS = ("instantaneous", "accumulative")


@dataclass(frozen=True)
class TestStrategy:
    """Restrictions per history over the moves of a transition system.

    Attributes
    ----------
    static_obstacles
        ``bool[n_moves]``: moves blocked for the whole test.
    restrictions
        ``bool[n_hist, n_moves]``: ``C(q)``, the reactive restrictions (cuts of G
        outside ``E(I)`` whose tail has history ``q``).
    setting
        ``"instantaneous"`` or ``"accumulative"``.
    """

    __test__ = False  # not a pytest test class

    static_obstacles: np.ndarray
    restrictions: np.ndarray
    setting: str = "instantaneous"
    blocked: np.ndarray = field(init=False, repr=False, compare=False)
    """``bool[n_hist, n_moves]``: every move restricted under each history (derived)."""

    def __post_init__(self) -> None:
        if self.setting not in SETTINGS:
            raise ValueError(f"unknown obstacle setting {self.setting!r}; expected one of {SETTINGS}")
        # a frozen dataclass's derived field is set once, here
        object.__setattr__(self, "blocked", self.restrictions | self.static_obstacles[None, :])

    @property
    def n_hist(self) -> int:
        return int(self.restrictions.shape[0])

    def blocked_moves(self, history: int) -> np.ndarray:
        """``bool[n_moves]``: the moves restricted under ``history``."""
        out: np.ndarray = self.blocked[history]
        return out

    def active_obstacles(self, history: int, state: int, visited: Iterable[int], out_moves: list[np.ndarray]) -> np.ndarray:
        """Indices of the moves shown as obstacles now.

        ``visited`` are the states met since ``history`` began (used by the
        accumulative setting); ``out_moves[s]`` the moves out of ``s``.
        """
        states = [state] if self.setting == "instantaneous" else sorted(set(visited) | {state})
        moves = np.concatenate([out_moves[s] for s in states]) if states else np.zeros(0, dtype=np.int64)
        out: np.ndarray = moves[self.blocked[history, moves]]
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "setting": self.setting,
            "static_obstacles": np.flatnonzero(self.static_obstacles).tolist(),
            "restrictions": {str(q): np.flatnonzero(self.restrictions[q]).tolist() for q in range(self.n_hist) if self.restrictions[q].any()},
            "n_hist": self.n_hist,
            "n_moves": int(self.static_obstacles.size),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TestStrategy:
        n_moves, n_hist = int(d["n_moves"]), int(d["n_hist"])
        static = np.zeros(n_moves, dtype=bool)
        static[d["static_obstacles"]] = True
        restr = np.zeros((n_hist, n_moves), dtype=bool)
        for q, moves in d["restrictions"].items():
            restr[int(q), moves] = True
        return cls(static, restr, d["setting"])
