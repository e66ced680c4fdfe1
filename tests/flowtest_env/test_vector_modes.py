"""The vector env in every autoreset mode and with every option equals a ``SyncVectorEnv``
of the single env built with the same options and the same mode.

Each comparison steps both on the same actions (random legal ones, often any action at
all) through many episode ends and asserts every output equal: observations, rewards,
terminated, truncated and every info key, ``final_obs``/``final_info``/``verdict``
included. In ``DISABLED`` mode the driver resets the envs that ended with a reset mask,
as TorchRL does.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

from flowtest_env.vector import FlowTestVectorEnv, autoreset_mode_of

MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED]
KINDS = {
    "static": "FlowTest-Example1-v0",
    "reactive": "FlowTest-SmallReactive-v0",
    "agent": "FlowTest-Maze2-v0",
    "fuel": "FlowTest-Refueling-v0",
    "graph": "FlowTest-BeaverRescue-v0",
}


def _pair(env_id: str, n: int, mode: AutoresetMode, **kw: Any) -> tuple[Any, Any]:
    vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=mode, **kw)
    ref = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, **kw)
    assert vec.autoreset_mode == mode and vec.metadata["autoreset_mode"] == mode
    assert vec.single_observation_space == ref.single_observation_space
    assert vec.single_action_space == ref.single_action_space
    return vec, ref


def _actions(rng: np.random.Generator, mask: np.ndarray, n_actions: int, p_any: float) -> np.ndarray:
    legal = np.argmax(rng.random(mask.shape) * (mask > 0), axis=1)
    anything = rng.integers(n_actions, size=mask.shape[0])
    return np.where(rng.random(mask.shape[0]) < p_any, anything, legal)


def _same(a: Any, b: Any, what: str) -> None:
    assert data_equivalence(a, b, exact=True), f"{what} differ:\n{a}\n{b}"


def compare(vec: Any, ref: Any, steps: int, seed: int, p_any: float = 0.3) -> dict[str, int]:
    """Step both; assert every output equal; count episode ends and verdicts seen."""
    mode = vec.autoreset_mode
    rng = np.random.default_rng(seed)
    o1, i1 = vec.reset(seed=seed)
    o2, i2 = ref.reset(seed=seed)
    _same((o1, i1), (o2, i2), "reset")
    n = int(vec.single_action_space.n)
    counts = {"ended": 0, "met": 0, "final": 0, "masked_resets": 0}
    mask = i1["action_mask"]
    for t in range(steps):
        a = _actions(rng, mask, n, p_any)
        o1, r1, te1, tr1, i1 = vec.step(a)
        o2, r2, te2, tr2, i2 = ref.step(a)
        _same(o1, o2, f"step {t}: observations")
        assert r1.dtype == r2.dtype and np.array_equal(r1, r2), f"step {t}: rewards {r1} != {r2}"
        assert np.array_equal(te1, te2) and np.array_equal(tr1, tr2), f"step {t}: terminated/truncated differ"
        _same(i1, i2, f"step {t}: infos")
        ended = te1 | tr1
        counts["ended"] += int(ended.sum())
        verdict = i1["final_info"]["verdict"] if mode == AutoresetMode.SAME_STEP and "final_info" in i1 else i1.get("verdict")
        if verdict is not None:
            counts["met"] += int(np.sum(verdict["system_objective"] == "met"))
        counts["final"] += int("final_obs" in i1)
        mask = i1["action_mask"]
        if mode == AutoresetMode.DISABLED and ended.any():
            o1, j1 = vec.reset(options={"reset_mask": ended.copy()})
            o2, j2 = ref.reset(options={"reset_mask": ended.copy()})
            _same((o1, j1), (o2, j2), f"step {t}: masked reset")
            counts["masked_resets"] += 1
            mask = np.where(ended[:, None], j1["action_mask"], mask)
    if mode == AutoresetMode.SAME_STEP:
        assert counts["final"] > 0
    if mode == AutoresetMode.DISABLED:
        assert counts["masked_resets"] > 0
    return counts


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
@pytest.mark.parametrize("kind", list(KINDS))
def test_every_mode_equals_sync_vector_env_with_memory_and_shaping(kind: str, mode: AutoresetMode) -> None:
    """The acceptance case: ``memory="visited"`` and ``shaping`` on built-ins of every
    kind (static walls, reactive doors, a test agent, fuel, a graph)."""
    kw: dict[str, Any] = {"max_steps": 20}
    if kind != "graph":
        kw.update(memory="visited", shaping=10.0, shaping_gamma=0.9)
    else:
        kw.update(shaping=3.0)
    vec, ref = _pair(KINDS[kind], 5, mode, **kw)
    counts = compare(vec, ref, steps=120, seed=4)
    assert counts["ended"] >= 10


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
def test_every_mode_equals_sync_on_a_random_grid_pool(mode: AutoresetMode, pool_cache: Path) -> None:
    kw = {"seeds": [0, 1, 2], "max_steps": 15, "memory": "visited", "shaping": 10.0}
    vec, ref = _pair("FlowTest-RandomGrid-v0", 6, mode, **kw)
    counts = compare(vec, ref, steps=100, seed=9)
    assert counts["ended"] >= 20


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
def test_every_mode_without_options_and_reaching_the_goal(mode: AutoresetMode) -> None:
    """No options, legal moves only: episodes end met, not only truncated."""
    vec, ref = _pair("FlowTest-Example1-v0", 8, mode)
    assert compare(vec, ref, steps=150, seed=2, p_any=0.0)["met"] > 0


@pytest.mark.parametrize(
    "options",
    [
        {"obs_kind": "grid"},
        {"obs_kind": "padded", "memory": "visited"},
        {"obs_kind": "padded", "pad_to": 6},
        {"step_cost": 0.5, "restricted_penalty": 0.0, "goal_reward": 7.0, "violation_penalty": 2.5},
        {"shaping": 1.0, "shaping_gamma": 1.0},
    ],
)
def test_each_option_equals_sync_vector_env(options: dict[str, Any]) -> None:
    vec, ref = _pair("FlowTest-Maze2-v0", 4, AutoresetMode.SAME_STEP, max_steps=25, **options)
    compare(vec, ref, steps=80, seed=1)


def test_the_mode_is_taken_by_name() -> None:
    for name in ("SAME_STEP", "same_step", "SameStep", AutoresetMode.SAME_STEP):
        assert autoreset_mode_of(name) == AutoresetMode.SAME_STEP
    with pytest.raises(ValueError, match="autoreset_mode"):
        FlowTestVectorEnv(2, "example1", autoreset_mode="sometimes")
    env = FlowTestVectorEnv(2, "example1", autoreset_mode="DISABLED")
    assert env.autoreset_mode == AutoresetMode.DISABLED and env.metadata["autoreset_mode"] == AutoresetMode.DISABLED
    assert FlowTestVectorEnv.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP  # the class default is untouched


def test_disabled_mode_refuses_stepping_an_ended_env() -> None:
    env = FlowTestVectorEnv(3, "example1", autoreset_mode="DISABLED", max_steps=2)
    env.reset(seed=0)
    env.step(np.full(3, 4))
    _, _, _, truncated, _ = env.step(np.full(3, 4))
    assert truncated.all()
    with pytest.raises(gym.error.ResetNeeded, match="reset_mask"):
        env.step(np.full(3, 4))
    env.reset(options={"reset_mask": np.array([True, True, True])})
    env.step(np.full(3, 4))


def test_reset_mask_is_checked_like_sync_vector_env() -> None:
    env = FlowTestVectorEnv(3, "example1")
    env.reset(seed=0)
    with pytest.raises(TypeError, match="numpy array"):
        env.reset(options={"reset_mask": [True, False, True]})
    with pytest.raises(ValueError, match="shape"):
        env.reset(options={"reset_mask": np.ones(2, dtype=bool)})
    with pytest.raises(TypeError, match="bool"):
        env.reset(options={"reset_mask": np.ones(3, dtype=np.int64)})
    with pytest.raises(ValueError, match="at least one"):
        env.reset(options={"reset_mask": np.zeros(3, dtype=bool)})


def test_masked_reset_keeps_the_other_runs() -> None:
    env = FlowTestVectorEnv(3, "maze2", memory="visited")
    env.reset(seed=0)
    before, _, _, _, _ = env.step(np.array([0, 2, 4]))
    steps = env.verdicts()["steps"].copy()
    obs, infos = env.reset(options={"reset_mask": np.array([False, True, False])})
    assert np.array_equal(obs[[0, 2]], before[[0, 2]])
    assert env.verdicts()["steps"].tolist() == [steps[0], 0, steps[2]]
    assert infos["_system_state"].tolist() == [False, True, False] and infos["system_state"][0] is None


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
def test_numeric_infos_equal_sync_vector_env(mode: AutoresetMode) -> None:
    """``numeric_infos=True``: numbers only (the state index, the outcome code), the same in
    the single and the vector env."""
    vec, ref = _pair("FlowTest-Refueling-v0", 6, mode, max_steps=25, numeric_infos=True, memory="visited")
    compare(vec, ref, steps=120, seed=3)
    _, infos = vec.reset(seed=0)
    assert infos["system_state"].dtype == np.int64


def _numbers_only(infos: dict[str, Any]) -> None:
    for key, value in infos.items():
        if isinstance(value, dict):
            _numbers_only(value)
        elif key != "final_obs":
            assert value.dtype != object, key


def test_numeric_infos_hold_numbers_only() -> None:
    env = FlowTestVectorEnv(4, "refueling", autoreset_mode="SAME_STEP", numeric_infos=True, max_steps=3)
    _, infos = env.reset(seed=0)
    _numbers_only(infos)
    ended = False
    for _ in range(3):
        _, _, te, tr, infos = env.step(np.full(4, 4))
        _numbers_only(infos)
        ended = ended or bool((te | tr).any())
    assert ended and infos["final_info"]["verdict"]["system_objective"].dtype == np.int64
    single = gym.make("FlowTest-Refueling-v0", numeric_infos=True)
    _, info = single.reset(seed=0)
    assert single.unwrapped.game.state_json(int(info["system_state"])) == gym.make("FlowTest-Refueling-v0").reset(seed=0)[1]["system_state"]


@pytest.mark.slow  # importing torch and TorchRL takes about 20 s
@pytest.mark.parametrize("mode", ["SAME_STEP", "DISABLED"])
def test_torchrl_gym_wrapper_takes_the_vector_env(mode: str) -> None:
    """TorchRL's ``GymWrapper`` runs the vector env through episode ends in the two modes
    it accepts (numeric infos: TorchRL turns infos into tensors)."""
    pytest.importorskip("torchrl")
    from torchrl.envs import GymWrapper

    venv = gym.make_vec(
        "FlowTest-Maze2-v0", num_envs=8, vectorization_mode="vector_entry_point", autoreset_mode=mode, memory="visited", numeric_infos=True, max_steps=10
    )
    env = GymWrapper(venv, device="cpu")
    rollout = env.rollout(35, break_when_any_done=False)
    assert tuple(rollout.batch_size) == (8, 35)
    assert int(rollout["next", "done"].sum()) >= 8 * 3  # every env ended at least three episodes


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
@pytest.mark.parametrize(
    "env_id,options",
    [
        ("FlowTest-SmallReactive-v0", {}),
        ("FlowTest-SmallReactive-v0", {"obs_kind": "grid"}),
        ("FlowTest-SmallReactive-v0", {"obs_kind": "padded", "memory": "visited"}),
        ("FlowTest-Maze2-v0", {"memory": "visited"}),
        ("FlowTest-BeaverRescue-v0", {}),
        ("FlowTest-MotionPrimitives-v0", {}),
        ("FlowTest-Patrolling-v0", {"shaping": 5.0}),
    ],
)
def test_accumulative_setting_equals_sync_vector_env(env_id: str, options: dict[str, Any], mode: AutoresetMode) -> None:
    """The accumulative setting shows the restrictions of every state visited under the
    current history: the vector env keeps them per env as the single env does."""
    vec, ref = _pair(env_id, 4, mode, setting="accumulative", max_steps=30, **options)
    compare(vec, ref, steps=120, seed=5)


def test_accumulative_observation_shows_more_than_the_instantaneous_one() -> None:
    """The comparison above is not trivial: somewhere the two settings' observations differ."""
    rng = np.random.default_rng(0)
    acc = FlowTestVectorEnv(8, "small-reactive", setting="accumulative", max_steps=30)
    ins = FlowTestVectorEnv(8, "small-reactive", setting="instantaneous", max_steps=30)
    o1, i1 = acc.reset(seed=0)
    o2, _ = ins.reset(seed=0)
    differ = 0
    for _ in range(60):
        a = _actions(rng, i1["action_mask"], 5, 0.0)
        o1, _, _, _, i1 = acc.step(a)
        o2, _, _, _, _ = ins.step(a)
        assert np.all(o1 >= o2)  # the accumulative view adds shown restrictions, never removes one
        differ += int(np.any(o1 != o2, axis=1).sum())
    assert differ > 0


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.name)
def test_mask_in_the_observation_in_every_mode(mode: AutoresetMode) -> None:
    from flowtest_env import ActionMaskObservation
    from flowtest_env.vector import VectorActionMaskObservation

    vec = VectorActionMaskObservation(gym.make_vec("FlowTest-Maze1-v0", num_envs=4, vectorization_mode="vector_entry_point", autoreset_mode=mode, max_steps=15))
    ref = gym.make_vec(
        "FlowTest-Maze1-v0", num_envs=4, vectorization_mode="sync", wrappers=[ActionMaskObservation], vector_kwargs={"autoreset_mode": mode}, max_steps=15
    )
    rng = np.random.default_rng(0)
    o1, i1 = vec.reset(seed=4)
    o2, i2 = ref.reset(seed=4)
    _same((o1, i1), (o2, i2), "reset")
    ends = 0
    for t in range(80):
        a = _actions(rng, o1["action_mask"], 5, 0.2)
        o1, r1, te1, tr1, i1 = vec.step(a)
        o2, r2, te2, tr2, i2 = ref.step(a)
        _same((o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2), f"step {t}")
        ended = te1 | tr1
        ends += int(ended.sum())
        if mode == AutoresetMode.DISABLED and ended.any():
            o1, i1 = vec.reset(options={"reset_mask": ended.copy()})
            o2, i2 = ref.reset(options={"reset_mask": ended.copy()})
            _same((o1, i1), (o2, i2), f"step {t}: masked reset")
    assert ends >= 8


def test_options_as_one_config() -> None:
    """The vector envs take the options as one EnvConfig too, and refuse unknown ones."""
    from flowtest_env import EnvConfig
    from flowtest_env.vector import RandomGridVectorEnv

    config = EnvConfig(memory="visited", shaping=2.0, max_steps=9)
    env = FlowTestVectorEnv(3, "maze2", config=config)
    assert env.config == config and env.max_steps == 9
    same = FlowTestVectorEnv(3, "maze2", memory="visited", shaping=2.0, max_steps=9)
    assert np.array_equal(env.reset(seed=1)[0], same.reset(seed=1)[0])
    with pytest.raises(TypeError, match="not both"):
        FlowTestVectorEnv(3, "maze2", config=config, memory="none")
    with pytest.raises(TypeError, match="bogus"):
        FlowTestVectorEnv(3, "maze2", bogus=1)
    with pytest.raises(TypeError, match="bogus"):
        RandomGridVectorEnv(3, bogus=1)
