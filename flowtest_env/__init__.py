"""FlowTest environments: synthesized tests as Gymnasium and PettingZoo environments.

Importing this package registers ``FlowTest-<Name>-v0`` for every built-in problem and
``FlowTest-RandomGrid-v0``::

    import gymnasium as gym
    import flowtest_env

    env = gym.make("FlowTest-Maze2-v0")

The two-player (tester vs. system) PettingZoo environment is
:mod:`flowtest_env.multiagent`.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from .envs import BUILTIN_ENVS, DEFAULT_MAX_STEPS, FlowTestEnv, RandomGridEnv
from .game import GameError, RunState, TestGame
from .wrappers import ActionMaskObservation

ENV_IDS: list[str] = []
"""Every registered FlowTest environment ID."""


def _register_all() -> None:
    for problem, (stem, cls) in BUILTIN_ENVS.items():
        env_id = f"FlowTest-{stem}-v0"
        ENV_IDS.append(env_id)
        if env_id in registry:
            continue
        register(
            id=env_id,
            entry_point=f"flowtest_env.envs:{cls.__name__}",
            kwargs={"problem": problem, "setting": "instantaneous", "max_steps": DEFAULT_MAX_STEPS[problem], "obs_kind": "flat"},
        )
    ENV_IDS.append("FlowTest-RandomGrid-v0")
    if "FlowTest-RandomGrid-v0" not in registry:
        register(
            id="FlowTest-RandomGrid-v0",
            entry_point="flowtest_env.envs:RandomGridEnv",
            kwargs={
                "size": 5,
                "family": "reachability",
                "n": 1,
                "seeds": list(range(8)),
                "kind": "reactive",
                "setting": "instantaneous",
                "max_steps": 100,
                "obs_kind": "flat",
            },
        )


_register_all()

__all__ = ["ENV_IDS", "ActionMaskObservation", "FlowTestEnv", "GameError", "RandomGridEnv", "RunState", "TestGame"]
