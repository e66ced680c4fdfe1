"""Small traps a new user fell into with the envs, each fixed: a pool of loaded tests in the
vector env, a pool-based spec, ``render_mode="human"`` without pygame."""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env
from flowtest_env.artifacts import builtin_game
from flowtest_env.envs import FlowTestEnv, render_modes
from flowtest_env.sources import load_test
from flowtest_env.vector import PoolVectorEnv, VectorActionMaskObservation
from synthesis.pipeline import synthesize
from synthesis.problems.builtins import example1, small_reactive


def test_pool_vector_env_takes_loaded_pools(pool_cache: Path) -> None:
    """As the README sets them side by side: ``PoolVectorEnv(n, load_pool(...))``."""
    from flowtest_env.pools import load_pool

    arts = load_pool("reachability1/5x5", count=3)
    vec = PoolVectorEnv(6, arts, assignment="fixed")
    assert [g.artifact.name for g in vec.games] == [a.name for a in arts]
    obs, infos = vec.reset(seed=0)
    assert obs.shape == (6, 306) and vec.test_index.tolist() == [0, 1, 2, 0, 1, 2]
    vec.step(np.full(6, 4))


def test_pool_vector_env_takes_anything_load_test_takes(tmp_path: Path) -> None:
    """Games, artifacts, built-in names, problem and artifact files, ``Problem`` and
    ``SynthesizedTest`` objects, one test or a list; each plays as its single env."""
    art_file = tmp_path / "maze2.json"
    load_test("maze2").save(art_file)
    tests = [builtin_game("maze2", "instantaneous"), load_test("example1"), "small-reactive", str(art_file), example1(), synthesize(small_reactive())]
    vec = PoolVectorEnv(len(tests), tests, assignment="fixed", max_steps=10)
    names = [g.artifact.name for g in vec.games]
    assert names == ["maze2", "example1", "small-reactive", "maze2", "example1", "small-reactive"]
    obs, _ = vec.reset(seed=0)
    for i, test in enumerate(tests):
        single = FlowTestEnv(test if not isinstance(test, flowtest_env.TestGame) else "maze2", max_steps=10)
        o, _ = single.reset(seed=0)
        assert np.array_equal(obs[i, : o.size], o) and not obs[i, o.size :].any(), names[i]
    assert PoolVectorEnv(2, "maze2").games[0].artifact.name == "maze2"  # one test alone
    with pytest.raises(ValueError, match="no test"):
        PoolVectorEnv(2, [])


def test_pool_based_spec_lists_the_pool_not_default_seeds(pool_cache: Path) -> None:
    env = gym.make("FlowTest-RandomGrid-v0", pool="reachability1/5x5", count=2)
    kwargs = env.spec.kwargs  # type: ignore[union-attr]
    assert kwargs["pool"] == "reachability1/5x5" and kwargs["count"] == 2
    assert not {"seeds", "size", "family", "n", "kind"} & set(kwargs), kwargs
    again = gym.make(env.spec)  # the spec rebuilds the same env
    assert [g.artifact.name for g in again.unwrapped.games] == [g.artifact.name for g in env.unwrapped.games]
    vec = gym.make_vec("FlowTest-RandomGrid-v0", num_envs=2, vectorization_mode="vector_entry_point", pool="reachability1/5x5", count=2)
    assert "seeds" not in vec.spec.kwargs  # type: ignore[union-attr]
    default = gym.make("FlowTest-RandomGrid-v0")
    names = [g.artifact.name for g in default.unwrapped.games]  # the documented default pool
    assert names == [f"random-5x5-reachability1-reactive-s{s}" for s in range(8)]


def test_human_rendering_without_pygame_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without pygame the env lists ``"human"`` itself, so ``gymnasium.make`` hands it over
    and the env says which extra to install."""
    assert render_modes(pygame_found=False) == ["rgb_array", "ansi", "human"]
    assert render_modes(pygame_found=True) == ["rgb_array", "ansi"]
    monkeypatch.setitem(sys.modules, "pygame", None)  # import pygame now fails
    monkeypatch.setattr(FlowTestEnv, "metadata", {**FlowTestEnv.metadata, "render_modes": render_modes(pygame_found=False)})
    with pytest.raises(gym.error.DependencyNotInstalled, match=r'pip install "flowtest\[render\]"'):
        gym.make("FlowTest-Maze2-v0", render_mode="human")
    with pytest.raises(gym.error.DependencyNotInstalled, match="flowtest"):
        FlowTestEnv("maze2", render_mode="human")


def test_human_rendering_built_directly_says_how() -> None:
    pytest.importorskip("pygame")
    with pytest.raises(ValueError, match="HumanRendering"):
        FlowTestEnv("maze2", render_mode="human")


@pytest.mark.parametrize("kwargs", [{"seeds": [3, 4]}, {"size": 7}, {"family": "reaction"}, {"kind": "static"}])
def test_a_pool_is_not_combined_with_the_arguments_it_decides(kwargs: dict[str, object]) -> None:
    """``pool=`` decides the grid and the seeds: other values for them would be ignored
    silently, so they are refused (by the single and the vector env alike)."""
    with pytest.raises(ValueError, match="cannot be combined"):
        gym.make("FlowTest-RandomGrid-v0", pool="reachability1/5x5", **kwargs)
    with pytest.raises(ValueError, match="cannot be combined"):
        gym.make_vec("FlowTest-RandomGrid-v0", num_envs=2, vectorization_mode="vector_entry_point", pool="reachability1/5x5", **kwargs)


@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP", "DISABLED"])
def test_the_mask_observation_wrapper_says_its_autoreset_mode(mode: str) -> None:
    """TorchRL's GymWrapper reads ``autoreset_mode`` off whatever env it is given."""
    inner = gym.make_vec("FlowTest-SmallReactive-v0", 2, vectorization_mode="vector_entry_point", autoreset_mode=mode)
    wrapped = VectorActionMaskObservation(inner)
    assert wrapped.autoreset_mode == inner.autoreset_mode == gym.vector.AutoresetMode[mode]
