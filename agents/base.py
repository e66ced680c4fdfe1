"""One small interface for systems under test (SUTs), and construction by name.

A :class:`Policy` is anything with ``reset(seed)`` and ``act(observation, info) -> int``.
It reads the legal actions from ``info["action_mask"]`` (or, in the PettingZoo env and
the Dict-observation wrapper, from ``observation["action_mask"]``) and, when it plans,
its own state from ``info["system_state"]``. The same object therefore drives the
Gymnasium env, the PettingZoo env (as ``system_0``) and the evaluator.

Policies are named by plain strings on the command line (``random``,
``scripted:replanner``, ``gr1``, ``ppo:PATH``, ...); :mod:`agents.registry` builds them by
name. This module knows none of them but :class:`RandomPolicy`.

Planning policies need the rules of the test they play (the transition system and
their own objective's automaton, never the hidden test objective): :func:`game_of`
finds the :class:`~flowtest_env.game.TestGame` behind an env.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from flowtest_env.game import TestGame


class PolicyError(ValueError):
    """An unknown policy name, or a policy that cannot play the given env."""


@runtime_checkable
class Policy(Protocol):
    """A system under test: chooses one legal action per step.

    ``reset`` is called at the start of every episode (with the episode's seed, so
    random policies are reproducible); ``act`` receives the observation and ``info``
    the env returned last and answers an action index that the mask allows.
    """

    name: str

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, observation: Any, info: dict[str, Any]) -> int: ...


def action_mask_of(observation: Any, info: dict[str, Any]) -> np.ndarray:
    """The legal-action mask (``int8``) from ``info`` or a Dict observation.

    Raises
    ------
    PolicyError
        If neither carries an ``action_mask``.
    """
    if info is not None and "action_mask" in info:
        return np.asarray(info["action_mask"])
    if isinstance(observation, dict) and "action_mask" in observation:
        return np.asarray(observation["action_mask"])
    raise PolicyError("no action mask in info or observation")


def game_of(env: Any) -> TestGame:
    """The :class:`TestGame` an env (Gymnasium, PettingZoo, wrapped or not) plays.

    Looks through wrappers (``unwrapped``) for an attribute ``game`` / ``_game`` /
    ``test_game`` holding a :class:`TestGame`, or accepts a :class:`TestGame` itself.

    Raises
    ------
    PolicyError
        If the env exposes no test game.
    """
    if isinstance(env, TestGame):
        return env
    chain: list[Any] = []
    obj = env
    while obj is not None and len(chain) < 16:
        chain.append(obj)
        obj = getattr(obj, "env", None)
    unwrapped = getattr(env, "unwrapped", None)
    if unwrapped is not None:
        chain.append(unwrapped)
    for obj in chain:
        for attr in ("game", "_game", "test_game"):
            g = getattr(obj, attr, None)
            if isinstance(g, TestGame):
                return g
    raise PolicyError(f"{type(env).__name__} exposes no FlowTest test game (expected an attribute `game`)")


def state_index(game: TestGame, system_state: Any) -> int:
    """The index of a system state written as in problem-format.md
    (``[row, col]``, ``[[row, col], fuel]`` or a state name)."""
    ts = game.ts
    if ts.kind == "grid":
        key: Any = (int(system_state[0]), int(system_state[1]))
    elif ts.kind == "fuel":
        (r, c), f = system_state
        key = ((int(r), int(c)), int(f))
    else:
        key = system_state
    return ts.index(key)


class RandomPolicy:
    """Uniform over the legal actions; seeded by :meth:`reset` for reproducible runs."""

    name = "random"

    def __init__(self) -> None:
        self.rng = np.random.default_rng(0)

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        legal = np.flatnonzero(action_mask_of(observation, info))
        return int(self.rng.choice(legal)) if legal.size else 0
