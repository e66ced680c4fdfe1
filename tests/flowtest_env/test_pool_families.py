"""Pool families beyond the paper's empty grids (issue 16, point 1): blocked cells, fuel,
reactive doors and test agents. A seed names the same problem everywhere, every stored
test comes back from its compact record checked, the envs draw from every family, and
two builds of a pool give the same bytes (in process, through Ray, under load: slow)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env  # noqa: F401  (registers the envs)
import flowtest_env.random_grid as rg
from flowtest_env.pools import load_pool, parse_pool
from synthesis.artifacts.pool_records import rebuild_artifact
from synthesis.model.errors import InconsistentProblem, ProblemError
from synthesis.problems.random_grid import random_problem
from synthesis.problems.random_worlds import blocked_count, fuel_capacity, refuel_count, world_problem
from tests.flowtest_env.test_vector import _compare
from tests.testing_processes import BURNER

#: One pool per new family at 5x5 (the train split's first seed is cheap in each).
FAMILY_POOLS = [
    "reachability1/5x5/blocked",
    "reachability1/5x5/blocked/static",
    "reachability1/5x5/fuel",
    "reachability1/5x5/fuel/static",
    "reachability1/5x5/agent",
    "reachability1/5x5/blocked/agent",
    "reachability1/5x5/fuel/agent",
]


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A private pool cache shared by this module's tests (each family's seed 0 is built once)."""
    mp = pytest.MonkeyPatch()
    path = tmp_path_factory.mktemp("flowtest-cache")
    mp.setenv("FLOWTEST_CACHE_DIR", str(path))
    mp.setattr(rg, "_POOLS", {})
    yield path
    mp.undo()


def special_cells(layout_tokens: dict[tuple[int, int], str]) -> dict[str, tuple[int, int]]:
    """Token -> cell of the start, goal and proposition cells (not agent or refuel cells)."""
    return {t: c for c, t in layout_tokens.items() if t not in ("t", "t0", "R")}


@pytest.mark.parametrize("world,kind", [(w, k) for w in ("blocked", "fuel") for k in ("reactive", "static", "agent")] + [("empty", "agent")])
def test_a_seed_names_one_problem_drawn_as_documented(world: str, kind: str) -> None:
    drawn: list[str] = []
    for seed in range(6):
        try:
            a = world_problem(7, "reaction", 2, seed, 0, world, kind)
        except InconsistentProblem as exc:  # documented: a goal or agent column out of a fuel grid's reach
            assert (world, exc.reason) == ("fuel", "unreachable")
            continue
        drawn.append(json.dumps(a.system.to_dict(), sort_keys=True))
        b = world_problem(7, "reaction", 2, seed, 0, world, kind)
        assert a.system.to_dict() == b.system.to_dict() and a.name == b.name
        empty = random_problem(7, "reaction", 2, seed, 0, "reactive")
        tokens = a.system.layout.tokens
        assert special_cells(tokens) == special_cells(empty.system.layout.tokens), "the empty instance's special cells"
        assert a.kind == kind
        if world == "blocked":
            assert len(a.system.layout.blocked) == blocked_count(7)
        if world == "fuel":
            assert a.system.max_fuel == fuel_capacity(7)
            assert sum(t == "R" for t in tokens.values()) == refuel_count(7)
            assert "G !empty" in a.system_objective.text
        if kind == "agent":
            assert a.agent is not None and a.agent.max_iterations == 20
            column = [a.system.places[int(p)] for p in a.agent.cells]
            assert len({c for _, c in column}) == 1 and len(column) == 7
            assert special_cells(tokens)["S"] not in column and special_cells(tokens)["T"] not in column
    assert len(set(drawn)) == len(drawn) >= 2, "seeds name different problems"


def test_the_empty_world_is_the_papers_grid() -> None:
    for kind in ("static", "reactive"):
        assert world_problem(5, "safety", 2, 3, 1, "empty", kind).system.to_dict() == random_problem(5, "safety", 2, 3, 1, kind).system.to_dict()
    with pytest.raises(ValueError, match="unknown world"):
        world_problem(5, "safety", 2, 0, 0, "lava", "static")
    with pytest.raises(ValueError, match="unknown kind"):
        world_problem(5, "safety", 2, 0, 0, "blocked", "mixed")


@pytest.mark.parametrize("name", FAMILY_POOLS)
def test_each_family_gives_checked_tests_that_come_back_from_their_records(name: str, cache: Path) -> None:
    pool = parse_pool(name)
    (art,) = load_pool(name, "train", count=1, progress=False)
    assert art.name == f"random-5x5-reachability1-{'' if pool.world == 'empty' else pool.world + '-'}{pool.kind}-s0"
    assert art.kind == pool.kind and art.summary["bypass_flow"] == 0 and art.summary["flow"] >= 1
    assert art.summary["deterministic"] is True
    if pool.kind == "agent":
        assert art.agent is not None and art.agent["controller"]["table"]["next_agent"]
        assert art.summary["agent_strategy"]["table_entries"] >= 1
    else:
        assert art.strategy.restrictions.any() or art.strategy.static_obstacles.any()
    path = rg.pool_path(pool.size, pool.family, pool.n, 0, pool.kind, pool.world)
    (line,) = path.read_text().splitlines()
    record = json.loads(line)
    assert sorted(record) == ["attempt", "cuts", "digest", "seed", "static", "summary"]
    assert len(line) < len(json.dumps(art.to_dict())) / 4, "the record is compact"
    again = rebuild_artifact(record, pool.size, pool.family, pool.n, pool.world, pool.kind)
    assert again.strategy.to_dict() == art.strategy.to_dict() and again.agent == art.agent
    # a record whose answer was tampered with is refused, naming the check
    broken = dict(record, cuts=[], static=[])
    with pytest.raises(ProblemError, match="fails its check"):
        rebuild_artifact(broken, pool.size, pool.family, pool.n, pool.world, pool.kind)
    with pytest.raises(ProblemError, match="malformed|fields"):
        rebuild_artifact(dict(record, cuts="all"), pool.size, pool.family, pool.n, pool.world, pool.kind)


@pytest.mark.parametrize("name", FAMILY_POOLS)
def test_random_grid_env_draws_from_each_family(name: str, cache: Path) -> None:
    env = gym.make("FlowTest-RandomGrid-v0", pool=name, split="train", count=1)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    rng = np.random.default_rng(0)
    for _ in range(30):
        legal = np.flatnonzero(info["action_mask"])
        obs, _, term, trunc, info = env.step(int(rng.choice(legal)))
        if term or trunc:
            break
    env.close()


@pytest.mark.parametrize("name", FAMILY_POOLS)
def test_vector_env_of_each_family_steps_exactly_like_the_single_env(name: str, cache: Path) -> None:
    kw = {"pool": name, "split": "train", "count": 1, "max_steps": 25}
    vec = gym.make_vec("FlowTest-RandomGrid-v0", num_envs=3, vectorization_mode="vector_entry_point", **kw)
    ref = gym.make_vec("FlowTest-RandomGrid-v0", num_envs=3, vectorization_mode="sync", **kw)
    counts = _compare(vec, ref, steps=80, seed=5, p_any=0.2)  # every output equal at every step
    assert counts["terminated"] + counts["truncated"] >= 1
    vec.close()
    ref.close()


# ---------------------------------------------------------------- slow: same bytes


def build_files(cache: Path, monkeypatch: pytest.MonkeyPatch, name: str, seeds: range, **kw: object) -> dict[str, bytes]:
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(cache))
    pool = parse_pool(name)
    rg.build_pool(pool.size, pool.family, pool.n, seeds, pool.kind, progress=False, world=pool.world, **kw)  # type: ignore[arg-type]
    return {str(p.relative_to(cache)): p.read_bytes() for p in sorted(cache.rglob("*")) if p.is_file()}


@pytest.mark.slow
@pytest.mark.parametrize("name", FAMILY_POOLS)
def test_each_family_pool_is_byte_identical_under_load_and_through_ray(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 16's acceptance: the same pool built idle in process, with every core busy,
    and through Ray, gives the same bytes."""
    seeds = range(2) if name.endswith("agent") else range(3)  # an empty-grid agent test takes about a CPU minute
    quiet = build_files(tmp_path / "quiet", monkeypatch, name, seeds)
    burners = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(os.cpu_count() or 2)]
    try:
        busy = build_files(tmp_path / "busy", monkeypatch, name, seeds)
    finally:
        for p in burners:
            p.kill()
            p.wait()
    assert busy == quiet
    pytest.importorskip("ray")
    remote = build_files(tmp_path / "ray", monkeypatch, name, seeds, parallel="ray", workers=2)
    assert remote == quiet
