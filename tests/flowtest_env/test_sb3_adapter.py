"""The Stable-Baselines3 VecEnv over the NumPy vector env (flowtest_env.adapters.sb3):
SB3's episode-end conventions, checked against SB3's own DummyVecEnv of the single env,
and MaskablePPO training through it."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

from sb3_contrib import MaskablePPO  # noqa: E402
from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor  # noqa: E402

import flowtest_env  # noqa: E402,F401  (registers the IDs)
from flowtest_env.adapters import make_sb3_vec_env  # noqa: E402
from flowtest_env.adapters.sb3 import FlowTestSB3VecEnv  # noqa: E402


@pytest.fixture(autouse=True)
def _one_torch_thread() -> Any:
    """Training here is tiny: one thread beats several on a shared machine."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _dummy(env_id: str, n: int, **options: Any) -> DummyVecEnv:
    return DummyVecEnv([lambda: gym.make(env_id, **options) for _ in range(n)])


@pytest.mark.parametrize(
    ("env_id", "options", "ends"),
    [
        ("FlowTest-SmallReactive-v0", {"max_steps": 9}, {"truncated", "terminated"}),
        ("FlowTest-Maze2-v0", {"max_steps": 15, "memory": "visited", "shaping": 2.0}, {"truncated"}),
    ],
)
def test_episode_ends_follow_sb3s_vecenv_conventions(env_id: str, options: dict[str, Any], ends: set[str]) -> None:
    """Step for step equal to SB3's DummyVecEnv of the single env (same seeds, same random
    legal actions): observations, rewards, dones, and at every episode end the infos
    SB3 reads (``terminal_observation``, ``TimeLimit.truncated``) and the verdict; short
    step budgets, so episodes end by the budget (and, on small-reactive, at the goal)."""
    n = 6
    ours = make_sb3_vec_env(env_id, n, seed=3, **options)
    ref = _dummy(env_id, n, **options)
    ref.seed(3)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    rng = np.random.default_rng(0)
    kinds = set()
    for _ in range(120):
        masks = ours.action_masks()
        assert np.array_equal(masks, get_action_masks(ref))
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in masks])
        o1, r1, d1, i1 = ours.step(actions)
        o2, r2, d2, i2 = ref.step(actions)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_allclose(r1, r2, rtol=0, atol=1e-6)
        np.testing.assert_array_equal(d1, d2)
        for k in range(n):
            assert i1[k]["TimeLimit.truncated"] == i2[k]["TimeLimit.truncated"]
            assert ("terminal_observation" in i1[k]) == bool(d1[k]) == ("terminal_observation" in i2[k])
            if d1[k]:
                np.testing.assert_array_equal(i1[k]["terminal_observation"], i2[k]["terminal_observation"])
                assert i1[k]["verdict"] == i2[k]["verdict"]
                kinds.add("truncated" if i1[k]["TimeLimit.truncated"] else "terminated")
    assert kinds == ends


def test_maskable_ppo_reads_the_masks_and_trains() -> None:
    """MaskablePPO takes the adapter (masking supported, masks via env_method), trains a
    few hundred steps, and never plays a masked action: every episode ends with no
    blocked attempt (a refused move would count one)."""
    envs = make_sb3_vec_env("FlowTest-SmallReactive-v0", 8, seed=0)
    assert is_masking_supported(envs)
    envs.reset()
    assert np.array_equal(get_action_masks(envs), envs.action_masks())

    class Ends(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.verdicts: list[dict[str, Any]] = []

        def _on_step(self) -> bool:
            self.verdicts += [i["verdict"] for i in self.locals["infos"] if "verdict" in i]
            return True

    model = MaskablePPO("MlpPolicy", VecMonitor(envs), n_steps=32, batch_size=64, n_epochs=2, seed=0)
    before = [p.detach().clone() for p in model.policy.parameters()]
    ends = Ends()
    model.learn(512, callback=ends)
    assert model.num_timesteps >= 512
    assert len(ends.verdicts) >= 8
    assert all(v["blocked_attempts"] == 0 for v in ends.verdicts)
    assert any(not np.array_equal(a.numpy(), b.detach().numpy()) for a, b in zip(before, model.policy.parameters(), strict=True))


@pytest.mark.slow
def test_maskable_ppo_learns_through_the_adapter() -> None:
    """8,192 steps on small-reactive: the mean return of the last 100 episodes (VecMonitor)
    rises well above the first rollout's, close to the best (0.95: five steps)."""
    envs = VecMonitor(make_sb3_vec_env("FlowTest-SmallReactive-v0", 16, seed=0))
    model = MaskablePPO("MlpPolicy", envs, n_steps=32, batch_size=128, n_epochs=4, learning_rate=3e-3, seed=0)
    means: list[float] = []

    class Rollouts(BaseCallback):
        def _on_rollout_end(self) -> None:
            buf = self.model.ep_info_buffer
            if buf:
                means.append(float(np.mean([e["r"] for e in buf])))

        def _on_step(self) -> bool:
            return True

    model.learn(8192, callback=Rollouts())
    assert means[-1] >= 0.9 and means[-1] > min(means[:3]) + 0.1, means


def test_the_adapter_refuses_other_envs_and_modes() -> None:
    with pytest.raises(ValueError, match="SAME_STEP"):
        FlowTestSB3VecEnv(gym.make_vec("FlowTest-SmallReactive-v0", num_envs=2, vectorization_mode="vector_entry_point"))
    with pytest.raises(TypeError, match="FlowTest vector env"):
        FlowTestSB3VecEnv(gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync"))
    envs = make_sb3_vec_env("FlowTest-SmallReactive-v0", 3)
    envs.reset()
    assert envs.get_attr("max_steps") == [envs.venv.max_steps] * 3
    assert len(envs.env_method("action_masks", indices=[0, 2])) == 2
    assert envs.env_is_wrapped(gym.Wrapper) == [False] * 3
    with pytest.raises(AttributeError, match="share it"):
        envs.set_attr("max_steps", 3)
