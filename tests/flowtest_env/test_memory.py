"""The SUT's place memory (flowtest_env/memory.py): ``memory="counts"`` holds how often each
place was occupied, capped, and reads the same in the single env, the NumPy vector env and
the torch env, in every autoreset mode; under it a two-cell loop changes the observation
on every pass (up to the cap), where ``memory="visited"`` repeats it."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import flowtest_env
from flowtest_env.config import EnvConfig
from flowtest_env.memory import COUNT_CAP, PlaceMemory, first_memory, increment_of, remember, remember_into
from flowtest_env.wrappers import VisitedPlaces

MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED]


def _legal(rng: np.random.Generator, mask: np.ndarray) -> np.ndarray:
    return np.argmax(rng.random(mask.shape) * (mask > 0), axis=1)


def _drive(envs: list[Any], steps: int, seed: int, as_array: Any) -> int:
    """Step every env of ``envs`` on the same random legal actions, resetting ended envs by
    mask in ``DISABLED`` mode; assert every observation (and ``final_obs``) equal to the
    first env's; the episode ends seen."""
    rng = np.random.default_rng(seed)
    outs = [e.reset(seed=seed) for e in envs]
    ref_obs, ref_info = outs[0]
    for obs, _ in outs[1:]:
        assert np.array_equal(ref_obs, as_array(obs)), "reset"
    ended_total = 0
    mode = envs[0].metadata["autoreset_mode"]
    for t in range(steps):
        a = _legal(rng, np.asarray(ref_info["action_mask"]))
        outs5 = [e.step(a) for e in envs]
        ref = outs5[0]
        ended = np.asarray(ref[2]) | np.asarray(ref[3])
        for o in outs5[1:]:
            assert np.array_equal(ref[0], as_array(o[0])), f"step {t}: observations differ"
            if "final_obs" in ref[4] and ended.any():
                for i in np.flatnonzero(ended):
                    assert np.array_equal(np.asarray(ref[4]["final_obs"][i]), as_array(o[4]["final_obs"][i])), f"step {t}: final obs"
        ref_info = ref[4]
        ended_total += int(ended.sum())
        if mode == AutoresetMode.DISABLED and ended.any():
            outs = [e.reset(options={"reset_mask": ended.copy()}) for e in envs]
            for obs, _ in outs[1:]:
                assert np.array_equal(outs[0][0], as_array(obs)), f"step {t}: masked reset"
            ref_info = {"action_mask": np.where(ended[:, None], outs[0][1]["action_mask"], ref_info["action_mask"])}
    return ended_total


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
@pytest.mark.parametrize("env_id", ["FlowTest-Maze2-v0", "FlowTest-Refueling-v0"])
def test_counts_read_the_same_in_the_single_env_and_the_vector_env(env_id: str, mode: AutoresetMode) -> None:
    kw: dict[str, Any] = {"memory": "counts", "max_steps": 20}
    vec = gym.make_vec(env_id, num_envs=5, vectorization_mode="vector_entry_point", autoreset_mode=mode, **kw)
    ref = gym.make_vec(env_id, num_envs=5, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kw)
    assert vec.single_observation_space == ref.single_observation_space
    assert _drive([ref, vec], steps=120, seed=4, as_array=np.asarray) >= 10


@pytest.mark.parametrize("mode", ["next_step", "same_step", "disabled"])
def test_counts_read_the_same_in_the_torch_env(mode: str) -> None:
    torch = pytest.importorskip("torch")
    from flowtest_env.torch_vector import TorchVectorEnv

    gym_mode = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP, "disabled": AutoresetMode.DISABLED}[mode]
    ref = gym.make_vec("FlowTest-Maze2-v0", num_envs=6, vectorization_mode="vector_entry_point", autoreset_mode=gym_mode, memory="counts", max_steps=25)
    env = TorchVectorEnv.from_numpy(ref)
    assert env.memory is not None and env.single_observation_space == ref.single_observation_space

    def as_array(x: Any) -> np.ndarray:
        return x.cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)

    class Actions:  # the torch env takes the NumPy actions as a tensor
        def __init__(self, inner: Any) -> None:
            self.inner, self.metadata = inner, inner.metadata

        def reset(self, **kw: Any) -> Any:
            if "options" in kw:
                kw["options"] = {"reset_mask": torch.as_tensor(kw["options"]["reset_mask"])}
            return self.inner.reset(**kw)

        def step(self, a: np.ndarray) -> Any:
            return self.inner.step(torch.as_tensor(a))

    assert _drive([ref, Actions(env)], steps=150, seed=6, as_array=as_array) >= 8
    with pytest.raises(ValueError, match="compact"):
        TorchVectorEnv(env.tables, 2, compact=True, memory=env.memory)


def test_the_counts_are_capped_visits_scaled_to_one() -> None:
    here, there = np.eye(3, dtype=np.float32)[1], np.eye(3, dtype=np.float32)[2]
    memory = PlaceMemory(slice(0, 3), "counts")
    seen = [memory(x)[3:].tolist() for x in (here, there, here, here, here, here)]
    q = 1.0 / COUNT_CAP
    assert seen[0] == [0.0, q, 0.0] and seen[1] == [0.0, q, q] and seen[2] == [0.0, 2 * q, q]
    assert seen[4] == [0.0, 1.0, q] == seen[5]  # the fourth visit reaches the cap, the fifth stays there
    memory.reset()
    assert memory(there)[3:].tolist() == [0.0, 0.0, q]
    # "visited" is the same rule with increment 1: max(seen, here)
    assert increment_of("visited") == 1.0 and increment_of("counts") == q
    m = first_memory(here, 1.0)
    remember_into(m, there, 1.0)
    assert m.tolist() == [0.0, 1.0, 1.0] == remember(here, there, 1.0).tolist()
    with pytest.raises(ValueError, match="keeps no places"):
        increment_of("none")


def test_under_counts_a_two_cell_loop_changes_the_observation_until_the_cap() -> None:
    """The loop that traps a greedy policy under ``visited``: back and forth between two
    cells. ``visited`` repeats the observation from the first return on; ``counts`` gives a
    new one on each of the first ``COUNT_CAP`` returns."""

    def loop(memory: str) -> list[bytes]:
        env = gym.make("FlowTest-Example1-v0", memory=memory, max_steps=40)
        obs, info = env.reset(seed=0)
        start = info["system_state"]
        seen = []
        back = {0: 1, 1: 0, 2: 3, 3: 2}  # N-S, E-W (flowtest_env.game.GRID_ACTIONS)
        first = next(a for a in back if info["action_mask"][a])
        for t in range(2 * COUNT_CAP + 4):
            obs, _, term, trunc, info = env.step(first if t % 2 == 0 else back[first])
            assert not (term or trunc)
            if t % 2 == 1:
                assert info["system_state"] == start  # back on the start cell
                seen.append(obs.tobytes())
        return seen

    visited, counts = loop("visited"), loop("counts")
    assert len(set(visited)) == 1  # every return to the start looks the same
    # the k-th return shows (start, other cell) = (k + 1, k) visits, capped: COUNT_CAP different
    # observations, then the same one once both cells reach the cap
    assert len(set(counts)) == COUNT_CAP and len(set(counts[:COUNT_CAP])) == COUNT_CAP
    assert counts[COUNT_CAP - 1] == counts[-1]


def test_the_layout_names_the_counts_and_the_options_are_checked() -> None:
    env = gym.make("FlowTest-Maze2-v0", memory="counts")
    obs, _ = env.reset(seed=0)
    lay = flowtest_env.observation_layout(env)
    seg = lay["counts"]
    assert seg.stop == obs.shape[0] and "min(visits" in seg.what
    assert seg.of(obs).max() == 1.0 / COUNT_CAP
    wrapped = VisitedPlaces(gym.make("FlowTest-Maze2-v0"), memory="counts")
    assert data_equivalence(wrapped.reset(seed=0)[0], obs)
    assert flowtest_env.observation_layout(wrapped)["counts"].start == seg.start
    assert EnvConfig(memory="counts").memory == "counts"
    with pytest.raises(ValueError, match="memory='counts' needs a flat observation"):
        EnvConfig(memory="counts", obs_kind="grid")
    with pytest.raises(ValueError, match="memory"):
        EnvConfig(memory="count")
