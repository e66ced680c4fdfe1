"""The counter-based test draws: one formula, computed alike by plain integers, NumPy
``uint64`` and the signed-int64 recipe a torch backend runs; the single and vector envs
follow it episode by episode."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flowtest_env.draws import MAX_TESTS, draw_test, draw_tests, draw_tests_int64, draw_word, mix64
from flowtest_env.envs import RandomGridEnv
from flowtest_env.vector import RandomGridVectorEnv

SPLITMIX64_FROM_0 = [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F]
"""The first outputs of the reference splitmix64 generator from state 0 (Vigna's C code)."""


def test_mix64_is_splitmix64() -> None:
    """From state 0 the reference generator outputs mix64(i * GOLDEN), i = 1, 2, ...:
    ``draw_word(0, e)`` is that stream since mix64(0) = 0."""
    assert mix64(0) == 0
    assert [draw_word(0, e) for e in range(3)] == SPLITMIX64_FROM_0


def test_three_implementations_agree_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    edge = [0, 1, 2**31 - 1, 2**32, 2**63 - 1, 2**63, 2**64 - 1]
    keys = np.concatenate([np.array(edge, dtype=np.uint64), rng.integers(0, 2**64 - 1, size=500, dtype=np.uint64)])
    episodes = rng.integers(0, 2**40, size=keys.size)
    episodes[:7] = [0, 1, 2**62, 5, 0, 3, 2**63 - 2]
    for n in (1, 2, 3, 7, 8, 1000, 2**31 - 1, MAX_TESTS):
        u = draw_tests(keys, episodes, n)
        s = draw_tests_int64(keys.view(np.int64), episodes, n)
        py = [draw_test(int(k), int(e), n) for k, e in zip(keys.tolist(), episodes.tolist(), strict=True)]
        assert np.array_equal(u, s), n
        assert u.tolist() == py, n
        assert int(u.min()) >= 0 and int(u.max()) < n


def test_draws_are_spread_over_the_pool() -> None:
    """Each of 8 tests drawn about as often (keys s + i, episodes 0..), within 5 %."""
    keys = np.repeat(np.arange(64, dtype=np.uint64), 1000)
    episodes = np.tile(np.arange(1000), 64)
    counts = np.bincount(draw_tests(keys, episodes, 8), minlength=8)
    assert np.all(np.abs(counts / counts.sum() - 1 / 8) < 0.05 / 8), counts


def test_pool_size_is_bounded() -> None:
    with pytest.raises(ValueError, match="tests"):
        draw_test(0, 0, 0)
    with pytest.raises(ValueError, match="tests"):
        draw_tests(np.zeros(1, dtype=np.uint64), np.zeros(1), MAX_TESTS + 1)


def test_single_env_plays_the_drawn_tests(pool_cache: Path) -> None:
    """Key = the seed given at reset; a reset without a seed is the key's next episode;
    a new seed restarts the count."""
    env = RandomGridEnv(seeds=[0, 1, 2], max_steps=5)
    names = [g.artifact.name for g in env.games]
    env.reset(seed=42)
    played = [env.artifact.name]
    for _ in range(9):
        env.reset()
        played.append(env.artifact.name)
    assert played == [names[draw_test(42, e, 3)] for e in range(10)]
    env.reset(seed=5)
    assert env.artifact.name == names[draw_test(5, 0, 3)]


def test_unseeded_single_env_keys_itself_from_np_random(pool_cache: Path) -> None:
    env = RandomGridEnv(seeds=[0, 1, 2], max_steps=5)
    env.reset()
    key = env._draw_key
    assert key is not None
    env.reset()
    assert env._draw_key == key and env._episode == 1
    assert env.artifact.name == env.games[draw_test(key, 1, 3)].artifact.name


def test_vector_env_draws_per_env_keys(pool_cache: Path) -> None:
    """Env i of reset(seed=s) is keyed s + i; a list gives one seed per env (None: that
    env's next episode); autoresets count episodes."""
    vec = RandomGridVectorEnv(4, seeds=[0, 1, 2], max_steps=3)
    vec.reset(seed=100)
    assert vec.test_index.tolist() == [draw_test(100 + i, 0, 3) for i in range(4)]
    for _ in range(4):  # 3 steps end every episode, the 4th autoresets
        vec.step(np.full(4, 4))
    assert vec.test_index.tolist() == [draw_test(100 + i, 1, 3) for i in range(4)]
    vec.reset(seed=[7, None, 9, None])
    assert vec.test_index.tolist() == [draw_test(7, 0, 3), draw_test(101, 2, 3), draw_test(9, 0, 3), draw_test(103, 2, 3)]
