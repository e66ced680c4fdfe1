"""The vector env's output options.

``obs_dtype="uint8"``: the flat and padded observations as ``uint8`` 0/1, the same numbers as
the default ``float32`` ones, everything else the same; refused where an observation holds
another value (the fuel fraction). The torch twin of such an env keeps the dtype and steps
like it. ``copy=False``: every observation written into one buffer, the same values as the
fresh arrays of ``copy=True``."""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import flowtest_env
from flowtest_env.vector import PoolVectorEnv

NO_FUEL = [
    "FlowTest-Example1-v0",
    "FlowTest-SmallReactive-v0",
    "FlowTest-BeaverRescue-v0",
    "FlowTest-MotionPrimitives-v0",
    "FlowTest-Maze1-v0",
    "FlowTest-Maze2-v0",
]
FUEL = ["FlowTest-Refueling-v0", "FlowTest-MarsExploration-v0", "FlowTest-Patrolling-v0"]


def _same_runs(compact: Any, full: Any, steps: int = 120, seed: int = 3) -> int:
    """Step both on the same random actions (often any action); the observations equal as
    numbers, every other output equal; the number of episode ends."""
    assert compact.single_observation_space.dtype == np.uint8
    assert compact.single_observation_space.shape == full.single_observation_space.shape
    rng = np.random.default_rng(seed)
    o1, i1 = compact.reset(seed=seed)
    o2, i2 = full.reset(seed=seed)
    ends = 0
    for t in range(steps):
        assert o1.dtype == np.uint8 and np.array_equal(o1.astype(np.float32), o2), t
        assert o1 in compact.observation_space
        assert (
            data_equivalence(i1, i2, exact=True)
            if "final_obs" not in i1
            else data_equivalence({k: v for k, v in i1.items() if k != "final_obs"}, {k: v for k, v in i2.items() if k != "final_obs"}, exact=True)
        )
        if "final_obs" in i1:
            for a, b in zip(i1["final_obs"], i2["final_obs"], strict=True):
                assert (a is None and b is None) or np.array_equal(np.asarray(a, dtype=np.float32), b)
        n = int(compact.single_action_space.n)
        legal = np.argmax(rng.random(i1["action_mask"].shape) * (i1["action_mask"] > 0), axis=1)
        a = np.where(rng.random(legal.size) < 0.3, rng.integers(n, size=legal.size), legal)
        o1, r1, te1, tr1, i1 = compact.step(a)
        o2, r2, te2, tr2, i2 = full.step(a)
        assert np.array_equal(r1, r2) and np.array_equal(te1, te2) and np.array_equal(tr1, tr2), t
        ends += int((te1 | tr1).sum())
        if compact.autoreset_mode == AutoresetMode.DISABLED and (te1 | tr1).any():
            o1, i1 = compact.reset(options={"reset_mask": te1 | tr1})
            o2, i2 = full.reset(options={"reset_mask": te2 | tr2})
    return ends


def _pair(env_id: str, mode: str = "NEXT_STEP", **kw: Any) -> tuple[Any, Any]:
    def make(**extra: Any) -> Any:
        return gym.make_vec(env_id, 6, vectorization_mode="vector_entry_point", autoreset_mode=mode, max_steps=20, **kw, **extra)

    return make(obs_dtype="uint8"), make()


@pytest.mark.parametrize("env_id", NO_FUEL)
def test_uint8_observations_are_the_float_ones(env_id: str) -> None:
    assert _same_runs(*_pair(env_id)) >= 6


@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP", "DISABLED"])
def test_with_the_memory_the_accumulative_setting_and_every_mode(mode: str) -> None:
    assert _same_runs(*_pair("FlowTest-Maze2-v0", mode, memory="visited", shaping=5.0)) >= 6
    assert _same_runs(*_pair("FlowTest-SmallReactive-v0", mode, setting="accumulative", memory="visited")) >= 6


def test_a_standard_pool_padded(pool_cache: Any) -> None:
    from flowtest_env.pools import load_pool

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tests = load_pool("reachability1/5x5-v2", "train", 8)
    compact = PoolVectorEnv(9, tests, obs_kind="padded", memory="visited", max_steps=25, obs_dtype="uint8")
    full = PoolVectorEnv(9, tests, obs_kind="padded", memory="visited", max_steps=25)
    assert _same_runs(compact, full) >= 9


def test_the_grid_observation_is_uint8_already() -> None:
    a = gym.make_vec("FlowTest-Maze2-v0", 3, vectorization_mode="vector_entry_point", obs_kind="grid", obs_dtype="uint8")
    b = gym.make_vec("FlowTest-Maze2-v0", 3, vectorization_mode="vector_entry_point", obs_kind="grid")
    assert a.single_observation_space == b.single_observation_space
    assert data_equivalence(a.reset(seed=1), b.reset(seed=1), exact=True)


@pytest.mark.parametrize("env_id", FUEL)
def test_an_observation_with_the_fuel_fraction_is_refused(env_id: str) -> None:
    with pytest.raises(ValueError, match="obs_dtype='uint8' needs an observation of 0/1 entries.*fuel fraction"):
        gym.make_vec(env_id, 2, vectorization_mode="vector_entry_point", obs_dtype="uint8")


def test_other_dtypes_are_refused() -> None:
    for bad in ("float16", "bool", np.uint8):
        with pytest.raises(ValueError, match="obs_dtype"):
            gym.make_vec("FlowTest-Maze2-v0", 2, vectorization_mode="vector_entry_point", obs_dtype=bad)


def test_the_torch_twin_keeps_the_dtype_and_steps_alike() -> None:
    torch = pytest.importorskip("torch")
    from flowtest_env.torch_vector import TorchVectorEnv

    ref = gym.make_vec("FlowTest-Maze2-v0", 5, vectorization_mode="vector_entry_point", obs_dtype="uint8", memory="visited", max_steps=15)
    twin = TorchVectorEnv.from_numpy(ref)
    o1, _ = ref.reset(seed=2)
    o2, _ = twin.reset(seed=2)
    assert o2.dtype == torch.uint8 and np.array_equal(o1, o2.numpy())
    rng = np.random.default_rng(0)
    for _ in range(60):
        a = rng.integers(5, size=5)
        o1, r1, *_ = ref.step(a)
        o2, r2, *_ = twin.step(torch.as_tensor(a))
        assert np.array_equal(o1, o2.numpy()) and np.array_equal(r1.astype(np.float32), r2.numpy())


def test_every_entry_point_takes_the_option(pool_cache: Any) -> None:
    for env_id in NO_FUEL:
        env = gym.make_vec(env_id, 1, vectorization_mode="vector_entry_point", obs_dtype="uint8")
        assert env.single_observation_space.dtype == np.uint8
    grid = gym.make_vec("FlowTest-RandomGrid-v0", 4, vectorization_mode="vector_entry_point", size=3, seeds=[0, 1], obs_dtype="uint8")
    assert grid.reset(seed=0)[0].dtype == np.uint8
    assert set(flowtest_env.ENV_IDS) == set(NO_FUEL + FUEL + ["FlowTest-RandomGrid-v0"])


@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP", "DISABLED"])
@pytest.mark.parametrize(
    "options",
    [
        {},
        {"memory": "visited", "shaping": 5.0},
        {"setting": "accumulative", "memory": "visited"},
        {"obs_kind": "grid"},
        {"obs_dtype": "uint8", "memory": "visited"},
    ],
)
def test_copy_false_writes_every_observation_into_one_buffer(mode: str, options: dict[str, Any]) -> None:
    env_id = "FlowTest-SmallReactive-v0" if options.get("setting") else "FlowTest-Maze2-v0"

    def make(copy: bool) -> Any:
        return gym.make_vec(env_id, 5, vectorization_mode="vector_entry_point", autoreset_mode=mode, max_steps=12, copy=copy, **options)

    reused, fresh = make(False), make(True)
    o1, i1 = reused.reset(seed=4)
    o2, i2 = fresh.reset(seed=4)
    buffer = o1
    rng = np.random.default_rng(1)
    ends = 0
    for t in range(80):
        assert o1 is buffer and data_equivalence((o1, i1), (o2, i2), exact=True), t
        a = rng.integers(5, size=5)
        o1, r1, te1, tr1, i1 = reused.step(a)
        o2, r2, te2, tr2, i2 = fresh.step(a)
        assert data_equivalence((r1, te1, tr1), (r2, te2, tr2), exact=True), t
        ends += int((te1 | tr1).sum())
        if mode == "DISABLED" and (te1 | tr1).any():
            o1, i1 = reused.reset(options={"reset_mask": te1 | tr1})
            o2, i2 = fresh.reset(options={"reset_mask": te2 | tr2})
    assert ends >= 5


def test_copy_must_be_a_bool() -> None:
    with pytest.raises(ValueError, match="copy must be True or False, not 'no'"):
        gym.make_vec("FlowTest-Maze2-v0", 2, vectorization_mode="vector_entry_point", copy="no")


def test_uint8_refuses_the_counting_memory() -> None:
    """The counting memory holds quarters, which ``uint8`` 0/1 entries cannot carry."""
    with pytest.raises(ValueError, match="memory='counts' counts in quarters"):
        gym.make_vec("FlowTest-Maze2-v0", 2, vectorization_mode="vector_entry_point", obs_dtype="uint8", memory="counts")
