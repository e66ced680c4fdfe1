"""flowtest_env.adapters.numeric: the vector env with numeric infos (for TorchRL), checked
against the vector env's own infos in every autoreset mode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env  # noqa: F401  (registers the IDs)
from flowtest_env.adapters.numeric import VERDICT_KEYS, NumericVectorEnv

CODES = {"open": 0, "met": 1, "violated": 2}


def _pair(mode: str) -> tuple[gym.vector.VectorEnv, NumericVectorEnv]:
    def make() -> gym.vector.VectorEnv:
        return gym.make_vec("FlowTest-SmallReactive-v0", num_envs=5, vectorization_mode="vector_entry_point", autoreset_mode=mode, max_steps=8)

    return make(), NumericVectorEnv(make())


@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP", "DISABLED"])
def test_numeric_infos_equal_the_vector_envs_verdicts(mode: str) -> None:
    """Same observations, rewards and ends; numeric infos with the same keys at every step,
    numbers only, and at every episode end the verdict the vector env reports."""
    plain, numeric = _pair(mode)
    assert numeric.autoreset_mode.name == mode
    o1, i1 = plain.reset(seed=1)
    o2, i2 = numeric.reset(seed=1)
    np.testing.assert_array_equal(o1, o2)
    base = {"action_mask", *VERDICT_KEYS}
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(60):
        np.testing.assert_array_equal(i1["action_mask"].astype(bool), i2["action_mask"])
        actions = np.argmax(rng.random(i1["action_mask"].shape) * i1["action_mask"], axis=1)
        o1, r1, t1, u1, i1 = plain.step(actions)
        o2, r2, t2, u2, i2 = numeric.step(actions)
        for a, b in ((o1, o2), (r1, r2), (t1, t2), (u1, u2)):
            np.testing.assert_array_equal(a, b)
        assert base <= set(i2) <= base | {"final_obs", "_final_obs", "final_info", "_final_info"}
        assert all(np.asarray(i2[k]).dtype.kind in "ib" for k in base)
        ended = t1 | u1
        if ended.any():
            ends += int(ended.sum())
            verdict = i1["final_info"]["verdict"] if mode == "SAME_STEP" else i1["verdict"]
            for e in np.flatnonzero(ended):
                assert i2["system_objective"][e] == CODES[verdict["system_objective"][e]]
                for k in ("test_objective_realized", "restrictions", "blocked_attempts", "steps"):
                    assert i2[k][e] == int(verdict[k][e])
            if mode == "SAME_STEP":
                for e in np.flatnonzero(ended):
                    np.testing.assert_array_equal(i2["final_obs"][e], i1["final_obs"][e])
                    assert i2["final_info"]["steps"][e] == i2["steps"][e]
            if mode == "DISABLED":
                _, i2 = numeric.reset(options={"reset_mask": ended})
                _, i1 = plain.reset(options={"reset_mask": np.zeros(5, dtype=bool) | ended})
    assert ends >= 10


def test_numeric_vector_env_refuses_other_envs() -> None:
    with pytest.raises(TypeError, match="FlowTest vector env"):
        NumericVectorEnv(gym.make_vec("CartPole-v1", num_envs=2, vectorization_mode="sync"))
