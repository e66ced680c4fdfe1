"""FlowTest environments: synthesized tests as Gymnasium and PettingZoo environments.

Importing this package registers ``FlowTest-<Name>-v0`` for every built-in problem and
``FlowTest-RandomGrid-v0``, each with a NumPy ``vector_entry_point``
(:mod:`flowtest_env.vector`: ``gym.make_vec(id, num_envs, vectorization_mode="vector_entry_point")``)::

    import gymnasium as gym
    import flowtest_env

    env = gym.make("FlowTest-Maze2-v0")

The two-player (tester vs. system) PettingZoo environment is
:mod:`flowtest_env.multiagent`.
"""

from __future__ import annotations

from typing import Any

from gymnasium.envs.registration import register, registry

from .envs import BUILTIN_ENVS, DEFAULT_MAX_STEPS, FlowTestEnv, RandomGridEnv
from .game import GameError, RunState, TestGame
from .wrappers import ActionMaskObservation

ENV_IDS: list[str] = []
"""Every registered FlowTest environment ID."""


def _env_specs() -> list[dict[str, Any]]:
    """The registry data: one entry per ID (``id``, ``entry_point``,
    ``vector_entry_point``, ``kwargs``); add an ID by adding an entry here."""
    specs: list[dict[str, Any]] = [
        {
            "id": f"FlowTest-{stem}-v0",
            "entry_point": f"flowtest_env.envs:{cls.__name__}",
            "vector_entry_point": "flowtest_env.vector:FlowTestVectorEnv",
            "kwargs": {"problem": problem, "setting": "instantaneous", "max_steps": DEFAULT_MAX_STEPS[problem], "obs_kind": "flat"},
        }
        for problem, (stem, cls) in BUILTIN_ENVS.items()
    ]
    specs.append(
        {
            "id": "FlowTest-RandomGrid-v0",
            "entry_point": "flowtest_env.envs:RandomGridEnv",
            "vector_entry_point": "flowtest_env.vector:RandomGridVectorEnv",
            "kwargs": {
                "size": 5,
                "family": "reachability",
                "n": 1,
                "seeds": list(range(8)),
                "kind": "reactive",
                "setting": "instantaneous",
                "max_steps": 100,
                "obs_kind": "flat",
            },
        }
    )
    return specs


def _register_all() -> None:
    for spec in _env_specs():
        ENV_IDS.append(spec["id"])
        if spec["id"] not in registry:
            register(**spec)


_register_all()

__all__ = ["ENV_IDS", "ActionMaskObservation", "FlowTestEnv", "GameError", "RandomGridEnv", "RunState", "TestGame"]
