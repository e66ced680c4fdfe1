"""The public observation layout names every entry of flat, padded and grid observations,
and its position segment finds the SUT where the env says it is."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env
from flowtest_env.encoding import PADDED_CHANNELS
from flowtest_env.envs import BUILTIN_ENVS
from flowtest_env.vector import FlowTestVectorEnv
from flowtest_env.wrappers import VisitedPlaces

IDS = [f"FlowTest-{stem}-v0" for stem, _ in BUILTIN_ENVS.values()]


def _cell(state: Any) -> tuple[int, int]:
    """``(row, col)`` of a grid ``info["system_state"]`` (``[[row, col], fuel]`` with fuel)."""
    return tuple(state[0]) if isinstance(state[0], list) else tuple(state)  # type: ignore[return-value]


def _covers(lay: flowtest_env.ObservationLayout) -> None:
    """Segments follow one another from 0 to the observation's end, each its shape's size."""
    end = 0
    for seg in lay.segments:
        assert seg.start == end, (seg.name, seg.start, end)
        if lay.kind != "grid":
            assert int(np.prod(seg.shape)) == seg.size, seg.name
        end = seg.stop
    assert end == lay.shape[0]
    assert len(set(lay.names())) == len(lay.segments)


@pytest.mark.parametrize("obs_kind", ["flat", "grid", "padded"])
@pytest.mark.parametrize("env_id", IDS)
def test_position_segment_finds_the_sut(env_id: str, obs_kind: str) -> None:
    try:
        env = gym.make(env_id, obs_kind=obs_kind, max_steps=30)
    except ValueError:
        pytest.skip(f"{env_id} has no {obs_kind} observation")
    lay = flowtest_env.observation_layout(env)
    assert lay.kind == obs_kind and lay.shape == env.observation_space.shape
    _covers(lay)
    game = env.unwrapped.game
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=0)
    for _ in range(30):
        pos = lay[lay.position].of(obs)
        assert pos.sum() == (255 if obs_kind == "grid" else 1)
        if lay.grid is not None:
            assert np.unravel_index(int(pos.argmax()), pos.shape) == _cell(info["system_state"])
        else:
            assert int(pos.argmax()) == int(game.ts.place[env.unwrapped.run.system])
        a = int(rng.choice(np.flatnonzero(info["action_mask"]))) if info["action_mask"].any() else 0
        obs, _, term, trunc, info = env.step(a)
        if term or trunc:
            obs, info = env.reset()


def test_padded_observation_is_901_entries_explained() -> None:
    lay = flowtest_env.observation_layout(gym.make("FlowTest-Maze2-v0", obs_kind="padded"))
    assert lay.shape == (901,) and len(PADDED_CHANNELS) == 14
    assert lay.names() == [*PADDED_CHANNELS, "restricted_now", "fuel"]
    assert [s.size for s in lay.segments] == [64] * 14 + [4, 1]  # 14 planes of 8x8 + 4 + 1 = 901


def test_memory_segment_is_the_visited_places() -> None:
    env = gym.make("FlowTest-Maze2-v0", memory="visited")
    lay = flowtest_env.observation_layout(env)
    assert lay.names()[-1] == "visited" and lay.shape == env.observation_space.shape
    _covers(lay)
    obs, _ = env.reset(seed=0)
    for a in (0, 0, 2):
        obs, *_ = env.step(a)
    visited = lay["visited"].of(obs)
    assert visited.shape == (5, 5) and visited.sum() >= 2
    assert np.all(visited >= lay[lay.position].of(obs))  # the current place is among the visited ones
    wrapped = flowtest_env.observation_layout(VisitedPlaces(gym.make("FlowTest-Maze2-v0")))
    assert wrapped == lay  # the wrapper's memory is laid out as the option's


@pytest.mark.parametrize("options", [{}, {"memory": "visited"}, {"obs_kind": "grid"}, {"obs_kind": "padded", "memory": "visited"}])
def test_vector_env_has_the_single_envs_layout(options: dict[str, Any]) -> None:
    vec = FlowTestVectorEnv(3, "patrolling", **options)
    lay = flowtest_env.observation_layout(vec)
    assert lay == flowtest_env.observation_layout(gym.make("FlowTest-Patrolling-v0", **options))
    obs, infos = vec.reset(seed=0)
    pos = lay[lay.position].of(obs)  # a batch: [num_envs, rows, cols]
    for i in range(3):
        assert np.unravel_index(int(pos[i].argmax()), pos[i].shape) == _cell(infos["system_state"][i])


def test_mixed_pool_names_what_differs() -> None:
    from flowtest_env.artifacts import builtin_game
    from flowtest_env.vector import PoolVectorEnv

    vec = PoolVectorEnv(2, [builtin_game("example1"), builtin_game("maze2")], assignment="fixed")
    with pytest.raises(ValueError, match="test=i"):
        flowtest_env.observation_layout(vec)
    lay = vec.observation_layout(test=0)
    assert lay.names()[-1] == "padding" and lay.shape == vec.single_observation_space.shape


@pytest.mark.parametrize("module", ["flowtest_env.config", "flowtest_env.draws", "flowtest_env.wrappers", "flowtest_env.vector"])
def test_docstring_examples_run(module: str) -> None:
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(module))
    assert result.attempted > 0 and result.failed == 0
