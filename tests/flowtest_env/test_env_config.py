"""One frozen env configuration (:class:`flowtest_env.config.EnvConfig`) for the five entry
points: the single env (:class:`FlowTestEnv`, :class:`RandomGridEnv`), the vector envs
(:class:`FlowTestVectorEnv`, :class:`RandomGridVectorEnv`, :class:`PoolVectorEnv`) and the
PettingZoo env (:func:`multiagent.raw_env`, :func:`multiagent.parallel_env`). Each takes
the same options, as keyword arguments or as one ``config=``, refuses a bad value with
the one validator's message, and exposes the checked object as ``env.config``."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from flowtest_env import multiagent
from flowtest_env.config import DEFAULTS, FIELDS, MULTIAGENT_UNUSED, EnvConfig
from flowtest_env.envs import FlowTestEnv, Maze2Env, RandomGridEnv
from flowtest_env.multiagent import SYSTEM, TESTER
from flowtest_env.vector import FlowTestVectorEnv, PoolVectorEnv, RandomGridVectorEnv

Make = Callable[..., Any]

# every entry point, building a small env of the built-in small-reactive test (or a one-seed random pool)
ENTRY_POINTS: dict[str, Make] = {
    "FlowTestEnv": lambda **kw: FlowTestEnv("small-reactive", **kw),
    "RandomGridEnv": lambda **kw: RandomGridEnv(seeds=[0], **kw),
    "FlowTestVectorEnv": lambda **kw: FlowTestVectorEnv(2, "small-reactive", **kw),
    "RandomGridVectorEnv": lambda **kw: RandomGridVectorEnv(2, seeds=[0], **kw),
    "PoolVectorEnv": lambda **kw: PoolVectorEnv(2, ["small-reactive"], **kw),
    "raw_env": lambda **kw: multiagent.raw_env(test="small-reactive", **kw),
    "parallel_env": lambda **kw: multiagent.parallel_env(test="small-reactive", **kw),
}
CLASSES: dict[str, Any] = {
    "FlowTestEnv": FlowTestEnv,
    "RandomGridEnv": RandomGridEnv,
    "FlowTestVectorEnv": FlowTestVectorEnv,
    "RandomGridVectorEnv": RandomGridVectorEnv,
    "PoolVectorEnv": PoolVectorEnv,
    "raw_env": multiagent.raw_env,
}
TWO_PLAYER = ("raw_env", "parallel_env")

# one value each option refuses (EnvConfig's validator says why)
BAD: dict[str, Any] = {
    "setting": "sometimes",
    "max_steps": 2.7,
    "obs_kind": "voxels",
    "pad_to": 0,
    "render_mode": "svg",
    "view": "top",
    "tile_size": -3,
    "step_cost": float("nan"),
    "restricted_penalty": "0.1",
    "goal_reward": float("inf"),
    "violation_penalty": True,
    "memory": "everything",
    "shaping": -1.0,
    "shaping_gamma": 1.5,
    "numeric_infos": "yes",
}


def test_every_option_has_a_bad_value_here() -> None:
    assert set(BAD) == set(FIELDS)


def config_error(name: str, value: Any) -> str:
    with pytest.raises(ValueError) as e:
        EnvConfig(**{name: value})
    return str(e.value)


@pytest.mark.parametrize("entry", list(CLASSES))
def test_every_entry_point_shows_the_same_options(entry: str) -> None:
    """``help()`` and ``inspect.signature`` list EnvConfig's options (less the ones the
    two-player env has no use for), with EnvConfig's defaults (the two-player env's view
    aside), and nothing restates them by hand."""
    params = inspect.signature(CLASSES[entry]).parameters
    expected = [f for f in FIELDS if not (entry in TWO_PLAYER and f in MULTIAGENT_UNUSED)]
    assert [p for p in params if p in FIELDS] == expected
    assert "config" in params
    for name in expected:
        default = "engineer" if (entry in TWO_PLAYER and name == "view") else DEFAULTS[name]
        assert params[name].default == default, (entry, name)
        assert params[name].kind is inspect.Parameter.KEYWORD_ONLY


@pytest.mark.parametrize("name", list(BAD))
@pytest.mark.parametrize("entry", list(ENTRY_POINTS))
def test_a_bad_value_gets_the_same_error_everywhere(entry: str, name: str) -> None:
    """The one validator's message, word for word, from every entry point, also for the
    options the two-player env does not apply (checked first, then refused)."""
    with pytest.raises(ValueError) as e:
        ENTRY_POINTS[entry](**{name: BAD[name]})
    assert str(e.value) == config_error(name, BAD[name])


def test_the_same_error_through_the_registry_and_make_vec() -> None:
    message = config_error("max_steps", 0)
    with pytest.raises(ValueError) as e:
        gym.make("FlowTest-Maze2-v0", max_steps=0)
    assert str(e.value) == message
    with pytest.raises(ValueError) as e:
        gym.make_vec("FlowTest-Maze2-v0", num_envs=2, vectorization_mode="vector_entry_point", max_steps=0)
    assert str(e.value) == message


@pytest.mark.parametrize("entry", list(ENTRY_POINTS))
def test_an_unknown_option_is_named(entry: str) -> None:
    with pytest.raises(TypeError, match="bogus"):
        ENTRY_POINTS[entry](bogus=1)


@pytest.mark.parametrize("entry", list(ENTRY_POINTS))
def test_config_or_keywords_build_the_same_env(entry: str) -> None:
    """``config=EnvConfig(...)`` and the same options as keyword arguments give the same
    ``env.config``; options given both ways are refused."""
    options: dict[str, Any] = {"max_steps": 9, "tile_size": 16, "step_cost": 0.02, "view": "engineer"}
    if entry not in TWO_PLAYER:
        options |= {"memory": "visited", "shaping": 2.0}
    config = EnvConfig(**options)
    by_config = ENTRY_POINTS[entry](config=config)
    by_keywords = ENTRY_POINTS[entry](**options)
    assert by_config.config == config == by_keywords.config
    with pytest.raises(TypeError, match="not both"):
        ENTRY_POINTS[entry](config=config, max_steps=3)
    with pytest.raises(TypeError, match="EnvConfig"):
        ENTRY_POINTS[entry](config={"max_steps": 9})


def test_keywords_keep_working_as_before() -> None:
    """The user-facing keyword arguments: gym.make, a built-in's class, the older
    ``problem=``, the two-player ``max_cycles``."""
    env = gym.make("FlowTest-Maze2-v0", max_steps=7, obs_kind="grid").unwrapped
    assert isinstance(env, FlowTestEnv)
    assert env.config.max_steps == env.max_steps == 7 and env.obs_kind == "grid"
    assert Maze2Env(max_steps=5).config.max_steps == 5
    assert FlowTestEnv(problem="maze2").problem == "maze2"
    aec = multiagent.raw_env(problem="small-reactive", max_cycles=12)
    assert aec.max_cycles == aec.config.max_steps == 12
    assert multiagent.raw_env(test="small-reactive", max_steps=12).max_cycles == 12
    assert multiagent.raw_env(test="small-reactive").config.view == "engineer"
    assert multiagent.raw_env(test="small-reactive", max_cycles=12, max_steps=12).max_cycles == 12
    with pytest.raises(ValueError, match="max_cycles"):
        multiagent.raw_env(test="small-reactive", max_cycles=12, max_steps=13)
    # the default budget is the single env's
    assert multiagent.raw_env(test="maze2").max_cycles == FlowTestEnv("maze2").max_steps


@pytest.mark.parametrize("name", MULTIAGENT_UNUSED)
@pytest.mark.parametrize("entry", TWO_PLAYER)
def test_the_two_player_env_refuses_the_options_it_does_not_apply(entry: str, name: str) -> None:
    value: Any = {"memory": "visited", "shaping": 1.0, "shaping_gamma": 0.5, "numeric_infos": True}[name]
    EnvConfig(**{name: value})  # a good value for the single env
    with pytest.raises(ValueError, match=f"does not take {name}="):
        ENTRY_POINTS[entry](**{name: value})
    ENTRY_POINTS[entry](**{name: DEFAULTS[name]})  # the default passes


def _system_return(goal_reward: float, violation_penalty: float, seed: int) -> tuple[float, str]:
    """The system's return and outcome of one run of small-reactive: the synthesized
    tester against a random system (the same moves for every reward weight)."""
    env = multiagent.raw_env(test="small-reactive", goal_reward=goal_reward, violation_penalty=violation_penalty)
    env.reset()
    rng = np.random.default_rng(seed)
    total = 0.0
    for agent in env.agent_iter():
        _, reward, terminated, truncated, _ = env.last()
        if agent == SYSTEM:
            total += float(reward)
        if terminated or truncated:
            env.step(None)
            continue
        if agent == TESTER:
            env.step(env.synthesized_action())
        else:
            legal = np.flatnonzero(env.system_mask())
            env.step(int(rng.choice(legal)))
    return total, env.run.outcome


def test_the_two_player_env_applies_the_reward_weights() -> None:
    """``goal_reward`` and ``violation_penalty`` weigh the system's end of run as in the
    single env (default 1, as before)."""
    outcomes = set()
    for seed in range(30):
        base, outcome = _system_return(1.0, 1.0, seed)
        weighted, same = _system_return(5.0, 3.0, seed)
        assert same == outcome
        outcomes.add(outcome)
        expected = {"met": 4.0, "violated": -2.0}.get(outcome, 0.0)
        assert weighted - base == pytest.approx(expected), (seed, outcome)
    assert "met" in outcomes
