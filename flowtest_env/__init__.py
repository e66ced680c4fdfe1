"""FlowTest environments: synthesized tests as Gymnasium and PettingZoo environments.

Importing this package registers ``FlowTest-v0`` (any test, ``test=...``),
``FlowTest-<Name>-v0`` for every built-in problem and ``FlowTest-RandomGrid-v0``, each with a
NumPy ``vector_entry_point`` (:mod:`flowtest_env.vector`:
``gym.make_vec(id, num_envs, vectorization_mode="vector_entry_point")``)::

    import gymnasium as gym
    import flowtest_env

    env = gym.make("FlowTest-Maze2-v0")
    env = gym.make("FlowTest-v0", test="mine.toml")   # a problem file, an artifact, a built-in
    env = flowtest_env.make_env(problem)              # from Python objects

The options every env takes are one :class:`~flowtest_env.config.EnvConfig`;
:func:`observation_layout` names the entries of an observation (docs/envs/observations.md).
The two-player (tester vs. system) PettingZoo environment is
:mod:`flowtest_env.multiagent`.

Examples
--------
>>> import gymnasium as gym
>>> import flowtest_env
>>> env = gym.make("FlowTest-SmallReactive-v0")
>>> obs, info = env.reset(seed=0)
>>> env.action_space, obs.shape, info["action_mask"].tolist(), info["system_state"]
(Discrete(5), (78,), [1, 0, 1, 0, 1], [1, 0])
>>> envs = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=4, vectorization_mode="vector_entry_point")
>>> obs, infos = envs.reset(seed=0)
>>> obs.shape, infos["action_mask"].shape
((4, 78), (4, 5))
"""

from __future__ import annotations

from typing import Any

from gymnasium.envs.registration import register, registry

from .config import EnvConfig
from .encoding import ObservationLayout, Segment
from .envs import BUILTIN_ENVS, DEFAULT_MAX_STEPS, FlowTestEnv, RandomGridEnv
from .game import GameError, RunState, TestGame
from .sources import TestLike, load_test
from .wrappers import ActionMaskObservation, observation_layout

ANY_TEST_ID = "FlowTest-v0"
"""The registered ID that plays any test: ``gymnasium.make(ANY_TEST_ID, test=...)``."""

REGISTRATIONS: dict[str, dict[str, Any]] = {
    ANY_TEST_ID: {
        "entry_point": "flowtest_env.envs:FlowTestEnv",
        "vector_entry_point": "flowtest_env.vector:FlowTestVectorEnv",
        "kwargs": {},
    },
    **{
        f"FlowTest-{stem}-v0": {
            "entry_point": f"flowtest_env.envs:{cls.__name__}",
            "vector_entry_point": "flowtest_env.vector:FlowTestVectorEnv",
            "kwargs": {"test": name, "setting": "instantaneous", "max_steps": DEFAULT_MAX_STEPS[name], "obs_kind": "flat"},
        }
        for name, (stem, cls) in BUILTIN_ENVS.items()
    },
    "FlowTest-RandomGrid-v0": {
        "entry_point": "flowtest_env.envs:RandomGridEnv",
        "vector_entry_point": "flowtest_env.vector:RandomGridVectorEnv",
        # the pool (size 5, reachability, n 1, seeds 0..7, reactive) is RandomGridEnv's default, not
        # listed here: a spec made with `pool=...` then names that pool alone, not default seeds it ignores
        "kwargs": {"setting": "instantaneous", "max_steps": 100, "obs_kind": "flat"},
    },
}
"""Every ID this package registers -> the keyword arguments of Gymnasium's ``register``
(one table, so other registration data, e.g. a vector entry point, is added per ID)."""

ENV_IDS: list[str] = [i for i in REGISTRATIONS if i != ANY_TEST_ID]
"""Every registered FlowTest environment ID with a fixed test (``FlowTest-v0`` aside)."""


def _register_all() -> None:
    for env_id, spec in REGISTRATIONS.items():
        if env_id not in registry:
            register(id=env_id, **spec)


_register_all()


def make_env(test: TestLike, **options: Any) -> FlowTestEnv:
    """A single-agent environment of ``test``, without Gymnasium's registry.

    ``test`` is anything :func:`flowtest_env.sources.load_test` accepts: a built-in name,
    a problem or artifact file path, a :class:`~synthesis.problems.problem.Problem`, a
    :class:`~synthesis.synthesized_test.SynthesizedTest` or a
    :class:`~synthesis.artifacts.artifact.TestArtifact`; ``options`` are :class:`FlowTestEnv`'s
    arguments (``obs_kind``, ``max_steps``, ``render_mode``, ...). Equivalent to
    ``gymnasium.make("FlowTest-v0", test=test, **options).unwrapped``, without
    Gymnasium's checker wrappers.

    Examples
    --------
    >>> import flowtest_env
    >>> env = flowtest_env.make_env("small-reactive", max_steps=20)
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(0)      # action 0 is N
    >>> info["system_state"], round(reward, 2), terminated, env.config.max_steps
    ([0, 0], -0.01, False, 20)
    """
    return FlowTestEnv(test, **options)


__all__ = [
    "ANY_TEST_ID",
    "ENV_IDS",
    "REGISTRATIONS",
    "ActionMaskObservation",
    "EnvConfig",
    "FlowTestEnv",
    "GameError",
    "ObservationLayout",
    "RandomGridEnv",
    "RunState",
    "Segment",
    "TestGame",
    "TestLike",
    "load_test",
    "make_env",
    "observation_layout",
]
