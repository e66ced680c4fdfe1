"""Named pools and their splits (issue 16, point 1): names parse, splits never overlap,
a split's tests are the checked tests of its seeds."""

from __future__ import annotations

from pathlib import Path

import pytest

import flowtest_env.random_grid as rg
from flowtest_env.pools import SPLIT_SPAN, SPLITS, PoolName, load_pool, parse_pool, split_seeds


def test_pool_names_parse_and_print_back() -> None:
    assert parse_pool("reachability1/5x5") == PoolName("reachability", 1, 5, "reactive")
    assert parse_pool("reaction2/7x7/static") == PoolName("reaction", 2, 7, "static")
    assert parse_pool("reachability2/7x7/blocked") == PoolName("reachability", 2, 7, "reactive", "blocked")
    assert parse_pool("safety2/5x5/fuel/agent") == PoolName("safety", 2, 5, "agent", "fuel")
    assert parse_pool("safety2/5x5/agent/fuel") == parse_pool("safety2/5x5/fuel/agent")
    assert parse_pool("reachability1/5x5/empty/reactive") == parse_pool("reachability1/5x5")
    for name in (
        "reachability1/5x5",
        "reaction2/7x7/static",
        "safety3/10x10",
        "reachability1/5x5/agent",
        "reachability1/7x7/blocked",
        "reaction2/10x10/fuel/static",
    ):
        assert str(parse_pool(name)) == name


@pytest.mark.parametrize(
    "name,match",
    [
        ("reachability1", "expected"),
        ("liveness1/5x5", "unknown family"),
        ("reachability/5x5", "unknown family"),
        ("reachability1/5x6", "square"),
        ("reachability1/axa", "square"),
        ("reachability1/5x5/lava", "unknown part 'lava'"),
        ("reachability1/5x5/blocked/fuel", "more than one world"),
        ("reachability1/5x5/static/agent", "more than one kind"),
        ("reachability1/5x5/blocked/static/x", "expected"),
        ("reaction1/5x5", "out of range"),
    ],
)
def test_bad_pool_names_say_what_is_wrong(name: str, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        parse_pool(name)


def test_splits_never_overlap() -> None:
    ranges = [split_seeds(s, SPLIT_SPAN) for s in SPLITS]
    for i, a in enumerate(ranges):
        for b in ranges[i + 1 :]:
            assert a.stop <= b.start or b.stop <= a.start
    assert split_seeds("validation", 3, start=5) == range(SPLIT_SPAN + 5, SPLIT_SPAN + 8)
    with pytest.raises(ValueError, match="unknown split"):
        split_seeds("dev", 1)
    with pytest.raises(ValueError, match="holds seeds"):
        split_seeds("train", 2, start=SPLIT_SPAN - 1)


def test_a_split_gives_the_checked_tests_of_its_seeds(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(rg, "_POOLS", {})
    test = load_pool("reachability1/5x5", "test", count=2, progress=False)
    train = load_pool("reachability1/5x5", "train", count=2, progress=False)
    assert [a.name for a in test] == [f"random-5x5-reachability1-reactive-s{2 * SPLIT_SPAN + i}" for i in range(2)]
    assert [a.name for a in train] == [f"random-5x5-reachability1-reactive-s{i}" for i in range(2)]
    for art in test + train:
        assert art.summary["bypass_flow"] == 0 and art.summary["flow"] >= 1 and art.summary["deterministic"] is True
    # the train split's first seeds are the default FlowTest-RandomGrid-v0 pool's
    assert [a.to_dict() for a in train] == [a.to_dict() for a in rg.build_pool(5, "reachability", 1, (0, 1), progress=False)]


def test_random_grid_env_draws_from_a_named_pool_and_split(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import gymnasium as gym

    import flowtest_env  # noqa: F401  (registers the envs)

    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(rg, "_POOLS", {})
    env = gym.make("FlowTest-RandomGrid-v0", pool="reachability1/5x5", split="validation", count=2)
    names = set()
    for seed in range(8):
        env.reset(seed=seed)
        names.add(env.unwrapped.artifact.name)
    assert names == {f"random-5x5-reachability1-reactive-s{SPLIT_SPAN + i}" for i in range(2)}
    vec = gym.make_vec("FlowTest-RandomGrid-v0", num_envs=2, vectorization_mode="vector_entry_point", pool="reachability1/5x5", split="validation", count=2)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="unknown split"):
        gym.make("FlowTest-RandomGrid-v0", pool="reachability1/5x5", split="holdout")
