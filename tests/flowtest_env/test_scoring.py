"""flowtest_env.scoring: any batched policy scored by the benchmark's protocol, and the
protocol's statistics, checked against hand-computed values and the single env."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from flowtest_env.game import TestGame
from flowtest_env.pools import load_pool
from flowtest_env.scoring import (
    iqm,
    normalized,
    play_batch,
    random_policy,
    score_interval,
    score_policy,
    seed_iqm,
    worst_share_mean,
)

POOL = "safety2/4x4"
"""Tests that build in a fraction of a second; a random walk fails some (``G !p2``)."""


@pytest.fixture(scope="module")
def games() -> list[TestGame]:
    return [TestGame(a) for a in load_pool(POOL, "test", 5, progress=False)]


def test_statistics_by_hand() -> None:
    assert iqm([1, 2, 3, 4, 5, 6, 7, 100]) == pytest.approx(np.mean([3, 4, 5, 6]))  # 2 cut at each end
    assert iqm([0.2, 0.4, 0.9]) == pytest.approx(0.5)  # fewer than 4: the plain mean
    assert worst_share_mean([1.0] * 18 + [0.0, 0.5]) == pytest.approx(0.25)  # the worst 2 of 20
    assert worst_share_mean([0.3, 0.9]) == 0.3  # at least one test
    assert normalized(0.75, 0.5, 1.0) == 0.5 and normalized(0.25, 0.5, 1.0) == -0.5
    assert normalized(0.5, 1.0, 1.0) is None and normalized(None, 0.0, 1.0) is None
    with pytest.raises(ValueError):
        iqm([])
    with pytest.raises(ValueError):
        worst_share_mean([0.5], share=0.0)


def test_bootstrap_is_seeded_and_covers_the_spread() -> None:
    """The seed-and-test bootstrap (no floor or ceiling given: the raw met share). Its
    agreement with an independent implementation and its coverage: test_score_intervals.py."""
    rng = np.random.default_rng(1)
    scores = (rng.random((10, 200)) < np.linspace(0.3, 0.7, 10)[:, None]).astype(float)
    a = score_interval(scores, reps=300, seed=4)
    assert a is not None and a == score_interval(scores, reps=300, seed=4)  # seeded
    assert a.point == seed_iqm(scores) and a.low < a.point < a.high
    assert 0.3 < a.low and a.high < 0.7  # within the seeds' range, not the whole [0, 1]
    flat = score_interval(np.full((5, 50), 0.4), reps=50)
    assert flat is not None and (flat.point, flat.low, flat.high) == pytest.approx((0.4, 0.4, 0.4))  # no spread, no width
    one_seed = score_interval(scores[:1], reps=200, seed=0)  # only the tests are resampled
    assert one_seed is not None and one_seed.low < one_seed.point < one_seed.high and one_seed.preliminary
    with pytest.raises(ValueError):
        score_interval(np.zeros((0, 3)))


def test_random_policy_is_legal_and_seeded(games: list[TestGame]) -> None:
    masks = np.array([[True, False, True], [False, False, True]])
    acts = random_policy(3)(np.zeros((2, 4)), masks)
    assert masks[np.arange(2), acts].all()
    a = play_batch(random_policy(), games, runs=4, seed=7)
    b = play_batch(random_policy(), games, runs=4, seed=7)
    assert a["system_objective"].shape == (4, 5)
    for key in a:
        assert (a[key] == b[key]).all(), key


def test_batch_gives_the_single_env_verdicts(games: list[TestGame]) -> None:
    """A deterministic batched policy played in one batch gives, for every test and run,
    the verdict the single env gives for the same actions."""
    from flowtest_env.envs import FlowTestEnv

    def first_legal(observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.argmax(masks, axis=1)
        return out

    v = play_batch(first_legal, games, runs=2)
    for i, game in enumerate(games):
        env = FlowTestEnv(game.artifact)
        obs, info = env.reset(seed=0)
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(int(np.argmax(info["action_mask"])))
            done = terminated or truncated
        for r in range(2):
            for key in ("system_objective", "test_objective_realized", "restrictions", "steps"):
                assert v[key][r, i] == info["verdict"][key], (i, key)


def test_score_policy_result_and_errors(games: list[TestGame]) -> None:
    calls: list[tuple[int, int]] = []

    class Stay:
        """Always the last legal action; records its resets."""

        def reset(self, num_runs: int, seed: int) -> None:
            calls.append((num_runs, seed))

        def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
            return np.asarray(masks.shape[1] - 1 - np.argmax(masks[:, ::-1], axis=1))

    s = score_policy(Stay(), tests=[g.artifact for g in games], runs=3, seed=5)
    assert calls == [(15, 5)]
    assert (s.tests, s.runs, s.seed) == (5, 3, 5) and len(s.per_test_met) == 5
    assert s.met == pytest.approx(np.mean(s.per_test_met))
    assert s.to_json()["per_test_met"] == list(s.per_test_met)
    with pytest.raises(AttributeError):
        s.met = 1.0  # type: ignore[misc]  # frozen
    seen: list[tuple[str, str, int]] = []

    def source(pool: str, split: str, count: int) -> list[Any]:
        seen.append((pool, split, count))
        return [g.artifact for g in games[:count]]

    r = score_policy(random_policy(), pool="my-pool", split="validation", count=2, runs=2, source=source)
    assert seen == [("my-pool", "validation", 2)] and r.tests == 2
    with pytest.raises(ValueError, match="pool= .* or tests="):
        score_policy(random_policy())
    with pytest.raises(ValueError, match="shape"):
        score_policy(lambda o, m: np.zeros(1, dtype=int), tests=games)
    with pytest.raises(ValueError, match="runs"):
        score_policy(random_policy(), tests=games, runs=0)
