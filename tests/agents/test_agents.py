"""Systems under test: the policy interface, the correct SUTs' guarantee, the faults."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env
from agents.base import Policy, PolicyError
from agents.registry import make_policy
from experiments.evaluation.episodes import run_episode
from flowtest_env.artifacts import artifact_path

SHIPPED_IDS = [f"FlowTest-{stem}-v0" for name, (stem, _) in flowtest_env.envs.BUILTIN_ENVS.items() if artifact_path(name).exists()]
"""Built-ins whose artifact ships (the others would be synthesized on first use: slow)."""
CORRECT = ["scripted:replanner", "gr1"]
FAULTY = ["scripted:committed", "scripted:fuel-blind", "scripted:greedy"]


@pytest.fixture(scope="module")
def envs() -> dict[str, gym.Env]:
    return {e: gym.make(e) for e in SHIPPED_IDS}


@pytest.mark.parametrize("sut", CORRECT)
@pytest.mark.parametrize("env_id", SHIPPED_IDS)
def test_correct_sut_meets_objective_and_test_is_realized(envs: dict[str, gym.Env], env_id: str, sut: str) -> None:
    env = envs[env_id]
    policy = make_policy(sut, env)
    for seed in range(3):
        t = run_episode(env, policy, env_id, sut, seed, record=False)
        assert t.verdict["system_objective"] == "met", (env_id, sut, seed, t.verdict)
        assert t.verdict["test_objective_realized"], (env_id, sut, seed, t.verdict)


@pytest.mark.parametrize("sut", FAULTY)
def test_each_faulty_sut_fails_some_builtin_test(envs: dict[str, gym.Env], sut: str) -> None:
    failed = []
    for env_id in SHIPPED_IDS:
        t = run_episode(envs[env_id], make_policy(sut, envs[env_id]), env_id, sut, 0, record=False)
        if t.kind == "sut":
            failed.append(env_id)
        assert t.kind != "test", (env_id, sut, t.reason)
    assert failed, f"{sut} passed every built-in test"


def test_random_policy_respects_mask_and_is_seeded() -> None:
    env = gym.make("FlowTest-SmallReactive-v0")
    p = make_policy("random", env)
    assert isinstance(p, Policy)
    runs = []
    for _ in range(2):
        obs, info = env.reset(seed=7)
        p.reset(7)
        actions = []
        done = False
        while not done:
            a = p.act(obs, info)
            assert info["action_mask"][a] == 1
            actions.append(a)
            obs, _, term, trunc, info = env.step(a)
            done = term or trunc
        runs.append(actions)
    assert runs[0] == runs[1]


def test_policy_reads_mask_from_dict_observation() -> None:
    env = flowtest_env.ActionMaskObservation(gym.make("FlowTest-SmallReactive-v0"))
    p = make_policy("scripted:replanner", env)
    obs, info = env.reset(seed=0)
    p.reset(0)
    a = p.act(obs, {"system_state": info["system_state"]})
    assert np.asarray(obs["action_mask"])[a] == 1


def test_unknown_policy_names_are_rejected() -> None:
    env = gym.make("FlowTest-SmallReactive-v0")
    for name in ("nope", "scripted:nope", "ppo:"):
        with pytest.raises(PolicyError):
            make_policy(name, env)


def test_gr1_controller_is_verified_and_resynthesized_on_new_restrictions() -> None:
    from agents.gr1_sut import GR1SUT

    env = gym.make("FlowTest-SmallReactive-v0")
    policy = make_policy("gr1:verify", env)  # verify_strategy checks every synthesis
    assert isinstance(policy, GR1SUT)
    t = run_episode(env, policy, "FlowTest-SmallReactive-v0", "gr1:verify", 0, record=False)
    assert t.verdict["system_objective"] == "met" and t.verdict["restrictions"] > 0
    assert policy.syntheses >= 2  # the first plan, then again when a restriction appeared


def test_ppo_smoke_training_learns_saves_model_curve_and_loads_as_sut(tmp_path) -> None:
    pytest.importorskip("sb3_contrib")
    import json

    from experiments.training.system import train

    s = train("FlowTest-SmallReactive-v0", 2048, tmp_path / "m.zip", seed=0, progress_bar=True, eval_episodes=3, n_envs=4, n_steps=64, batch_size=128)
    assert (tmp_path / "m.zip").exists() and (tmp_path / "m.png").exists()
    summary = json.loads((tmp_path / "m.json").read_text())
    assert summary["steps"] == 2048 and summary["episodes"] == len(summary["points"]) > 0
    assert s["success_rate"] == 1.0  # this tiny test is learned in 2048 steps (seeded)
    env = gym.make("FlowTest-SmallReactive-v0")
    policy = make_policy(f"ppo:{tmp_path / 'm.zip'}", env)
    assert policy.memory_kind == "visited"  # saved with the model, rebuilt when it plays
    t = run_episode(env, policy, "FlowTest-SmallReactive-v0", "ppo", 0, record=False)
    assert t.verdict["system_objective"] == "met" and t.verdict["test_objective_realized"]


def test_policy_memory_matches_the_training_wrapper() -> None:
    from agents.ppo import VisitedMemory, VisitedObservation, position_slice

    env = gym.make("FlowTest-Maze2-v0")
    wrapped = VisitedObservation(gym.make("FlowTest-Maze2-v0"))
    memory = VisitedMemory(position_slice(env))
    sut = make_policy("scripted:replanner", env)
    for seed in (0, 1):
        obs, info = env.reset(seed=seed)
        wobs, _ = wrapped.reset(seed=seed)
        memory.reset()
        sut.reset(seed)
        places = {tuple(info["system_state"])}
        done = False
        while not done:
            mine = memory(obs)
            assert wrapped.observation_space.contains(wobs) and np.array_equal(mine, wobs)
            seen = mine[env.observation_space.shape[0] :].reshape(5, 5)
            assert {tuple(p) for p in np.argwhere(seen == 1)} == places
            a = sut.act(obs, info)
            obs, _, term, trunc, info = env.step(a)
            wobs, *_ = wrapped.step(a)
            places.add(tuple(info["system_state"]))
            done = term or trunc


def test_ppo_model_for_another_observation_shape_is_refused(tmp_path) -> None:
    pytest.importorskip("sb3_contrib")
    from experiments.training.system import train

    train("FlowTest-SmallReactive-v0", 64, tmp_path / "m.zip", seed=0, progress_bar=False, eval_episodes=0, n_envs=1, n_steps=64, batch_size=64, n_epochs=1)
    with pytest.raises(PolicyError, match="shape"):
        make_policy(f"ppo:{tmp_path / 'm.zip'}", gym.make("FlowTest-Maze2-v0"))


@pytest.mark.slow
def test_ppo_learns_maze2() -> None:
    """The PPO benchmark's claim, at a fixed budget: >= 95 % over 100 evaluation runs."""
    pytest.importorskip("sb3_contrib")
    import tempfile

    from experiments.training.system import train

    with tempfile.TemporaryDirectory() as tmp:
        s = train("FlowTest-Maze2-v0", 16_384, f"{tmp}/m.zip", seed=0, progress_bar=False, eval_episodes=100)
    assert s["success_rate"] >= 0.95
