"""Planning pieces every product-graph system under test shares.

A planning SUT (the scripted ones, :mod:`agents.scripted`, and the GR(1) controller,
:mod:`agents.gr1_sut`) knows its transition system, its own objective's automaton
``B_sys`` (so it plans on ``G_sys = T x B_sys``, :class:`~flowtest_env.system_product.SystemProduct`)
and the restrictions it observes through the action mask; never the hidden test
objective. :class:`Tracked` keeps that knowledge up to date step by step;
:func:`safe_wait` is what such a SUT does when every way to its goal is closed for now.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from flowtest_env.game import TestGame
from flowtest_env.system_product import SystemProduct

from .base import PolicyError, action_mask_of, game_of, state_index


class Tracked:
    """What every product-graph SUT keeps track of: the env's game, its own state and its
    ``B_sys`` state, and the restrictions it has seen (:meth:`_situation`).

    A subclass answers ``act(observation, info)``; ``reset`` must be called after the
    env's ``reset`` (the env may switch games at reset).
    """

    name = "scripted"

    def __init__(self, env: Any) -> None:
        self.env = env
        self.game: TestGame | None = None
        self.product: SystemProduct | None = None
        self.q: int | None = None
        self.known: set[tuple[int, int]] = set()  # (state, action) restrictions seen and not seen lifted
        self._refresh()

    def _refresh(self) -> None:
        g = game_of(self.env)
        if g is not self.game:
            self.game = g
            self.product = SystemProduct(g)

    def reset(self, seed: int | None = None) -> None:
        self._refresh()
        self.q = None
        self.known = set()

    def _remember(self, s: int, v: int, mask: np.ndarray) -> set[tuple[int, int]]:
        """Update the remembered restrictions from the mask at product node ``v``.

        A restriction seen now is remembered; one seen lifted is forgotten. Returns the
        restrictions active now.
        """
        assert self.game is not None and self.product is not None
        now: set[tuple[int, int]] = set()
        for a in range(self.game.n_slots):
            if self.product.next_node[v, a] < 0:
                continue
            if mask[a]:
                self.known.discard((s, a))
            else:
                now.add((s, a))
        self.known |= now
        return now

    def _observe(self, info: dict[str, Any]) -> tuple[int, int]:
        """The current state index and ``B_sys`` state (updated by the state entered)."""
        if "system_state" not in info:
            raise PolicyError("a scripted SUT needs info['system_state']")
        assert self.game is not None and self.product is not None
        s = state_index(self.game, info["system_state"])
        self.q = self.product.step_q(self.product.q0 if self.q is None else self.q, s)
        return s, self.q

    def _look(self, observation: Any, info: dict[str, Any]) -> tuple[TestGame, int, int, np.ndarray]:
        """The game, the current state index, the ``B_sys`` state (:meth:`_observe`) and the
        legal-action mask: what every SUT here reads first."""
        s, q = self._observe(info)
        assert self.game is not None
        return self.game, s, q, action_mask_of(observation, info)

    def _situation(self, observation: Any, info: dict[str, Any]) -> tuple[TestGame, SystemProduct, int, np.ndarray, set[tuple[int, int]]]:
        """What a product-graph SUT knows before it acts: the game, its product graph,
        its node there, the legal-action mask and the restrictions active now (also
        remembered, see :meth:`_remember`)."""
        game, s, q, mask = self._look(observation, info)
        prod = self.product
        assert prod is not None
        v = prod.node(s, q)
        return game, prod, v, mask, self._remember(s, v, mask)


def safe_wait(game: TestGame, prod: SystemProduct, v: int, mask: np.ndarray, free_dist: np.ndarray) -> int:
    """Stay if allowed; otherwise the legal action that keeps the objective reachable."""
    if mask[game.stay_action]:
        return game.stay_action
    legal = [a for a in range(game.n_actions) if mask[a] and prod.next_node[v, a] >= 0]
    legal.sort(key=lambda a: free_dist[prod.next_node[v, a]])
    return legal[0] if legal else game.stay_action
