"""Wrappers for FlowTest environments."""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class ActionMaskObservation(gym.Wrapper[dict[str, np.ndarray], np.int64, np.ndarray, np.int64]):
    """Put the legal-action mask into the observation.

    The observation becomes a ``Dict`` with ``"observation"`` (the wrapped env's
    observation) and ``"action_mask"`` (``int8[n_actions]``, 1 = legal now), the shape
    PettingZoo and most masked-policy libraries expect. The mask is taken from
    ``info["action_mask"]``, which every FlowTest env returns at reset and each step.

    Raises
    ------
    TypeError
        If the wrapped env's action space is not ``Discrete``.
    """

    def __init__(self, env: gym.Env[np.ndarray, np.int64]) -> None:
        super().__init__(env)
        if not isinstance(env.action_space, spaces.Discrete):
            raise TypeError(f"ActionMaskObservation needs a Discrete action space, not {env.action_space}")
        n = int(env.action_space.n)
        self.observation_space = spaces.Dict(
            {"observation": env.observation_space, "action_mask": spaces.Box(0, 1, shape=(n,), dtype=np.int8)}
        )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        return {"observation": obs, "action_mask": np.asarray(info["action_mask"], dtype=np.int8)}, info

    def step(self, action: np.int64) -> tuple[dict[str, np.ndarray], SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return {"observation": obs, "action_mask": np.asarray(info["action_mask"], dtype=np.int8)}, reward, terminated, truncated, info
