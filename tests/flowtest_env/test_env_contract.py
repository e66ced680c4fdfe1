"""Environments reject what Gymnasium and PettingZoo would (issue 13, point 5)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import flowtest_env  # noqa: F401  (registers the envs)
from flowtest_env import multiagent
from flowtest_env.wrappers import ActionMaskObservation, DistanceShaping, VisitedPlaces

BAD_ACTIONS = [
    1.0,
    1.5,
    float("nan"),
    True,
    np.True_,
    "1",
    b"1",
    None,
    [1],
    np.array([1, 2]),
    np.array([[1]]),
    np.array(1.0),
    np.float32(2),
    -1,
    5,
    2**70,
    object(),
]


@pytest.mark.parametrize("action", BAD_ACTIONS, ids=[repr(a)[:20] for a in BAD_ACTIONS])
def test_single_env_rejects_non_actions(action: object) -> None:
    env = gym.make("FlowTest-SmallReactive-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(gym.error.InvalidAction):
        env.step(action)
    assert env.run.steps == 0  # nothing was played


@pytest.mark.parametrize("action", [0, np.int64(1), np.int8(2), np.array(3), np.array([4]), np.uint8(0)])
def test_single_env_accepts_integers_of_the_space(action: object) -> None:
    env = gym.make("FlowTest-SmallReactive-v0")
    env.reset(seed=0)
    env.step(action)


SINGLE_ENV_BAD_KWARGS = [
    ({"tile_size": 0}, "tile_size"),
    ({"tile_size": 2.5}, "tile_size"),
    ({"tile_size": True}, "tile_size"),
    ({"max_steps": 1.5}, "max_steps"),
    ({"max_steps": "10"}, "max_steps"),
    ({"max_steps": 0}, "max_steps"),
    ({"step_cost": float("nan")}, "step_cost"),
    ({"goal_reward": float("inf")}, "goal_reward"),
    ({"violation_penalty": "1"}, "violation_penalty"),
    ({"restricted_penalty": None}, "restricted_penalty"),
    ({"view": "god"}, "view"),
    ({"view": ["system"]}, "view"),
    ({"obs_kind": "pixels"}, "obs_kind"),
    ({"render_mode": "human3d"}, "render_mode"),
    ({"setting": 3}, "setting"),
    ({"test": "nope"}, "nope"),
    ({"memory": "everything"}, "memory"),
    ({"shaping": -1.0}, "shaping"),
    ({"shaping": float("nan")}, "shaping"),
    ({"shaping_gamma": 1.5}, "shaping_gamma"),
    ({"pad_to": 0}, "pad_to"),
    ({"memory": "visited", "obs_kind": "grid"}, "flat"),
]


@pytest.mark.parametrize("kwargs,words", SINGLE_ENV_BAD_KWARGS)
def test_single_env_arguments_are_named(kwargs: dict[str, Any], words: str) -> None:
    with pytest.raises(ValueError, match=words):
        gym.make("FlowTest-SmallReactive-v0", **kwargs)


RANDOM_GRID_BAD_KWARGS = [
    ({"size": 0}, "size"),
    ({"size": 2.0}, "size"),
    ({"size": 2.5}, "size"),
    ({"n": True}, "n"),
    ({"seeds": []}, "seed"),
    ({"seeds": [-1]}, "seeds"),
    ({"seeds": [1.5]}, "seeds"),
    ({"seeds": "01"}, "seeds"),
    ({"family": ["reachability"]}, "family"),
    ({"kind": "mixed"}, "kind"),
    ({"world": "lava"}, "world"),
    ({"pool": "reachability1/5x5", "count": 2.5}, "count"),
]


@pytest.mark.parametrize("kwargs,words", RANDOM_GRID_BAD_KWARGS)
def test_random_grid_arguments_are_named(kwargs: dict[str, Any], words: str) -> None:
    with pytest.raises(ValueError, match=words):
        gym.make("FlowTest-RandomGrid-v0", **kwargs)


def _message(env_id: str, mode: str, kwargs: dict[str, Any]) -> str:
    try:
        if mode == "single":
            gym.make(env_id, **kwargs)
        else:
            gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    except ValueError as e:
        return str(e).split(" was raised from the environment creator")[0]
    raise AssertionError(f"{env_id} ({mode}) took {kwargs}")


@pytest.mark.parametrize("kwargs,words", [kw for kw in SINGLE_ENV_BAD_KWARGS if kw[0] != {"render_mode": "human3d"}])
def test_vector_env_refuses_the_single_envs_arguments_with_its_message(kwargs: dict[str, Any], words: str) -> None:
    """One validator: the vector entry point refuses what the single env refuses, with the
    same message (NaN rewards, ``max_steps=1.5``, ``tile_size=0``, ...)."""
    single = _message("FlowTest-SmallReactive-v0", "single", kwargs)
    assert _message("FlowTest-SmallReactive-v0", "vector", kwargs) == single
    assert words in single


@pytest.mark.parametrize("kwargs,words", RANDOM_GRID_BAD_KWARGS)
def test_random_grid_vector_env_refuses_the_same_arguments(kwargs: dict[str, Any], words: str) -> None:
    single = _message("FlowTest-RandomGrid-v0", "single", kwargs)
    assert _message("FlowTest-RandomGrid-v0", "vector", kwargs) == single
    assert words in single


@pytest.mark.parametrize("num_envs", [0, -3, 2.5, True, "8"])
def test_vector_env_num_envs_must_be_a_positive_integer(num_envs: object) -> None:
    from flowtest_env.vector import FlowTestVectorEnv

    with pytest.raises(ValueError, match="num_envs"):
        FlowTestVectorEnv(num_envs, "small-reactive")  # type: ignore[arg-type]


def test_vector_env_num_envs_is_bounded_by_the_memory_it_needs(monkeypatch: pytest.MonkeyPatch) -> None:
    """10**7 maze2 runs need tens of GiB: refused before anything that size is allocated,
    saying how much it would take."""
    from flowtest_env import step_tables, vector

    with pytest.raises(ValueError, match=r"num_envs=10000000000 would need about \d+\.\d GiB"):  # on any machine
        gym.make_vec("FlowTest-Maze2-v0", num_envs=10**10, vectorization_mode="vector_entry_point")
    monkeypatch.setattr(step_tables, "available_memory", lambda: 23 * 2**30)  # the machine that was killed at 23 GB
    with pytest.raises(ValueError, match=r"num_envs=10000000 would need about 3\d\.\d GiB"):
        gym.make_vec("FlowTest-Maze2-v0", num_envs=10**7, vectorization_mode="vector_entry_point")
    monkeypatch.setattr(step_tables, "available_memory", lambda: 2**30)
    with pytest.raises(ValueError, match="1.0 GiB are available"):
        vector.FlowTestVectorEnv(10**6, "maze2", memory="visited")
    vector.FlowTestVectorEnv(1000, "maze2", memory="visited")  # 1000 runs fit in 1 GiB


@pytest.mark.parametrize("action", [True, 1.0, np.float64(2.0), np.True_])
def test_vector_env_refuses_bool_and_float_actions_like_the_single_env(action: object) -> None:
    single = gym.make("FlowTest-SmallReactive-v0").unwrapped
    single.reset(seed=0)
    with pytest.raises(gym.error.InvalidAction):
        single.step(action)
    vec = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=2, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    with pytest.raises(gym.error.InvalidAction):
        vec.step(np.array([action, action]))
    with pytest.raises(gym.error.InvalidAction):
        vec.step(action)


@pytest.mark.parametrize(
    "kwargs,words",
    [
        ({"max_cycles": 0}, "max_cycles"),
        ({"tile_size": -3}, "tile_size"),
        ({"step_cost": float("inf")}, "step_cost"),
        ({"view": "x"}, "view"),
        ({"problem": "nope"}, "nope"),
    ],
)
def test_multiagent_arguments_are_named(kwargs: dict[str, Any], words: str) -> None:
    with pytest.raises(ValueError, match=words):
        multiagent.raw_env(**{"problem": "small-reactive", **kwargs})


def test_parallel_env_raises_before_reset_and_after_the_end() -> None:
    env = multiagent.parallel_env(problem="small-reactive")
    with pytest.raises(gym.error.ResetNeeded):
        env.step({a: 0 for a in env.possible_agents})
    env.reset(seed=0)
    for bad in ({"tester_0": 0}, {"tester_0": 0, "system_0": 1.5}, {"tester_0": True, "system_0": 0}, {"tester_0": 0, "system_0": 0, "intruder": 0}, [0, 0]):
        with pytest.raises(gym.error.InvalidAction):
            env.step(bad)  # type: ignore[arg-type]
    for _ in range(1000):
        if not env.agents:
            break
        env.step({a: int(env.action_space(a).sample()) for a in env.agents})
    assert not env.agents
    with pytest.raises(gym.error.ResetNeeded):
        env.step({a: 0 for a in env.possible_agents})


def test_aec_env_rejects_non_actions_and_steps_before_reset() -> None:
    env = multiagent.raw_env(problem="small-reactive")
    with pytest.raises(gym.error.ResetNeeded):
        env.step(0)
    env.reset(seed=0)
    for bad in (1.5, True, "0", np.array([0, 1]), 10_000):
        with pytest.raises(gym.error.InvalidAction):
            env.step(bad)


@pytest.mark.parametrize("wrapper", [ActionMaskObservation, VisitedPlaces, DistanceShaping])
@pytest.mark.parametrize("env_id", ["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0", "FlowTest-BeaverRescue-v0"])
def test_every_wrapper_passes_check_env_and_make_spec(wrapper: type, env_id: str) -> None:
    env = wrapper(gym.make(env_id))
    check_env(env.unwrapped, skip_render_check=True)
    check_env(env, skip_render_check=True)  # (it warns that a wrapper is applied: that is the point)
    again = gym.make(env.spec)
    assert type(again) is wrapper and again.observation_space == env.observation_space
    a, _ = env.reset(seed=3)
    b, _ = again.reset(seed=3)
    assert gym.utils.env_checker.data_equivalence(a, b)
