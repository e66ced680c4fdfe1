"""Pools disjoint by content: the content key (the same for the same game, whatever its
name, seed or statistics; changed by any change to what a policy plays), every shipped
``-v2`` pool's splits compared pairwise and each for repeats, the record's key checked on
load, the layout count and the birthday bound, and the ``-v1`` pools kept loadable but
marked superseded."""

from __future__ import annotations

import dataclasses
import fnmatch
import itertools
import json
import tomllib
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import flowtest_env.standard_pools as sp
from flowtest_env.pool_content import birthday, overlaps, split_keys
from flowtest_env.pools import load_pool, pool_seeds, random_grid_arguments
from flowtest_env.random_grid import SPLIT_SPAN, SPLITS, random_artifact
from synthesis.artifacts.artifact import TestArtifact
from synthesis.artifacts.content import content_document, content_key
from synthesis.artifacts.pool_records import certify, record_content_key, record_digest
from synthesis.model.errors import ProblemError
from synthesis.problems.random_grid import family_objectives
from synthesis.problems.random_worlds import blocked_count, layout_count, refuel_count
from tests.testing_pools import copy_split, empty_data

ROOT = Path(__file__).resolve().parents[2]
V1 = [p for p in sp.STANDARD_POOLS.values() if p.draw == "seeds"]
V2 = [p for p in sp.STANDARD_POOLS.values() if p.draw == "content"]
R1V1, R1V2 = "reachability1/5x5-v1", "reachability1/5x5-v2"
TWINS = (2_000_091, 2_000_137)
"""Two seeds of ``reachability1/5x5``'s held-out range that draw the same game (the same
start, goal and hidden cell): ``-v1`` ships both, ``-v2`` skips the second."""


@pytest.fixture
def data(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty folder in place of the shipped records."""
    return empty_data(tmp_path, monkeypatch)


@pytest.fixture(scope="module")
def r1() -> list[TestArtifact]:
    """The 1,000 held-out tests of ``reachability1/5x5-v1`` (a second or two)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sp.SupersededPoolWarning)
        return sp.load_standard_pool(R1V1, "test")


# ------------------------------------------------------------------ the content key


def test_twins_drawn_by_two_seeds_have_one_key_and_two_names(r1: list[TestArtifact]) -> None:
    a, b = r1[TWINS[0] - 2_000_000], r1[TWINS[1] - 2_000_000]
    assert a.name != b.name and a.to_dict() != b.to_dict()  # named by their seeds
    assert content_key(a) == content_key(b)
    assert len({content_key(t) for t in r1}) < len(r1)  # -v1's held-out split repeats a test


def test_name_seed_summary_and_extras_leave_the_key_unchanged(r1: list[TestArtifact]) -> None:
    t = r1[0]
    renamed = dataclasses.replace(
        t,
        name="another-name-s7",
        summary={**t.summary, "flow": 99, "stats": {"time": 1.0}},
        extras={"provenance": {"seed": 7}},
        source="0" * 64,
    )
    assert content_key(renamed) == content_key(t)
    names = dataclasses.replace(t.histories, names=[f"h{k}" for k in range(t.histories.n_states)])
    assert content_key(dataclasses.replace(t, histories=names)) == content_key(t)  # display names of automaton states


def _near_twins(t: TestArtifact) -> dict[str, TestArtifact]:
    """Hand-made tests that differ from ``t`` in one thing a policy plays."""
    s, ts = t.strategy, t.system
    restrictions = s.restrictions.copy()
    h, m = np.argwhere(~restrictions)[0]
    restrictions[h, m] = True  # one more door closed in one history
    opened = s.restrictions.copy()
    opened[tuple(np.argwhere(opened)[0])] = False  # one door left open
    walls = s.static_obstacles.copy()
    walls[0] = not walls[0]
    labels = list(ts.labels)
    free = next(k for k, a in enumerate(labels) if not a and k != ts.initial)
    labels[free] = frozenset({"p1"})  # a second hidden cell
    accepting = t.test_automaton.accepting.copy()
    accepting[0] = ~accepting[0]
    return {
        "door closed": dataclasses.replace(t, strategy=dataclasses.replace(s, restrictions=restrictions)),
        "door opened": dataclasses.replace(t, strategy=dataclasses.replace(s, restrictions=opened)),
        "wall": dataclasses.replace(t, strategy=dataclasses.replace(s, static_obstacles=walls)),
        "label": dataclasses.replace(t, system=dataclasses.replace(ts, labels=labels)),
        "start": dataclasses.replace(t, system=dataclasses.replace(ts, initial=free)),
        "move": dataclasses.replace(t, system=dataclasses.replace(ts, dst=np.roll(ts.dst, 1))),
        "objective": dataclasses.replace(t, objectives={**t.objectives, "test": t.objectives["test"] + " & F p0"}),
        "automaton": dataclasses.replace(t, test_automaton=dataclasses.replace(t.test_automaton, accepting=accepting)),
        "kind": dataclasses.replace(t, kind="static"),
    }


def test_any_change_to_what_a_policy_plays_changes_the_key(r1: list[TestArtifact]) -> None:
    t = r1[0]
    twins = _near_twins(t)
    keys = {what: content_key(u) for what, u in twins.items()}
    assert all(k != content_key(t) for k in keys.values()), [w for w, k in keys.items() if k == content_key(t)]
    assert len(set(keys.values())) == len(keys)  # and each change gives its own key


def test_a_test_agents_table_is_part_of_the_key() -> None:
    (t,) = sp.load_standard_pool("reachability1/5x5/blocked/agent-v2", "test", 1)
    assert t.agent is not None
    agent = json.loads(json.dumps(t.agent))
    table = agent["controller"]["table"]["next_agent"]
    table[0] = (table[0] + 1) % len(agent["controller"]["agent_names"])  # one move of the agent's strategy
    assert content_key(dataclasses.replace(t, agent=agent)) != content_key(t)
    moved = {**t.agent, "start": "(4, 4)"}
    assert content_key(dataclasses.replace(t, agent=moved)) != content_key(t)


def test_the_document_leaves_out_names_seeds_and_statistics(r1: list[TestArtifact]) -> None:
    doc = content_document(r1[0])
    assert set(doc) == {"format", "kind", "objectives", "system", "letters", "automata", "restrictions", "agent"}
    text = json.dumps(doc)
    assert r1[0].name not in text and "2000000" not in text and "names" not in doc["automata"]["histories"]


# ------------------------------------------------------------------ every shipped pool, by content


@pytest.mark.parametrize("pool", V2, ids=lambda p: p.id)
def test_a_v2_pools_splits_are_disjoint_by_content_and_repeat_nothing(pool: sp.StandardPool) -> None:
    """Keys read from the shipped records (each is checked against its test whenever the
    pool loads; a sample here): no test of one split is a test of another, none repeats."""
    keys = {s: split_keys(pool, s, rebuild=False) for s in SPLITS}
    assert {s: len(k) for s, k in keys.items()} == dict(pool.splits)  # every planned test shipped
    report = overlaps(keys)
    assert report.clean, report.lines()
    assert len(set(itertools.chain(*keys.values()))) == sum(pool.splits.values())
    for split in SPLITS:
        n = pool.shipped(split)
        for start in sorted({0, n // 2, n - 1}):
            (test,) = sp.load_standard_pool(pool.id, split, 1, start)
            assert content_key(test) == keys[split][start]


@pytest.mark.parametrize("pool", V2, ids=lambda p: p.id)
def test_a_v2_pool_json_states_layouts_the_birthday_bound_and_seeds_skipped(pool: sp.StandardPool) -> None:
    draw = json.loads((pool.folder / "pool.json").read_text(encoding="utf-8"))["draw"]
    p = pool.name
    assert draw["order"] == list(sp.DRAW_ORDER)
    assert draw["layouts"] == layout_count(p.size, p.family, p.n, p.world, p.kind)
    bound = birthday(draw["layouts"], dict(pool.splits))
    assert draw["birthday"]["shared"]["test in train"] == pytest.approx(bound["shared"]["test in train"], rel=1e-2)
    for split in SPLITS:
        seeds, base = pool.seeds(split), SPLITS.index(split) * SPLIT_SPAN
        stated = draw["splits"][split]
        assert stated["tests"] == len(seeds) and (stated["first_seed"], stated["last_seed"]) == (seeds[0], seeds[-1])
        assert stated["seeds_skipped"] == seeds[-1] - base + 1 - len(seeds)
        assert seeds[0] == base  # the first seed is never taken


def test_v2_skips_exactly_the_seeds_whose_test_was_taken(r1: list[TestArtifact]) -> None:
    """The held-out split of ``reachability1/5x5-v2`` is ``-v1``'s in seed order with every
    test whose game came earlier left out (then seeds beyond ``-v1``'s, drawn the same way)."""
    v2 = sp.standard_pool(R1V2)
    seen: set[str] = set()
    kept = []
    for t in r1:
        k = content_key(t)
        if k not in seen:
            seen.add(k)
            kept.append(int(t.name.rsplit("-s", 1)[1]))
    assert len(kept) == 962 and v2.seeds("test")[: len(kept)] == kept
    assert TWINS[0] in kept and TWINS[1] not in kept and v2.seeds("test")[len(kept)] == 2_001_000


def test_v1_pools_report_their_known_overlap_from_a_sample(r1: list[TestArtifact]) -> None:
    """``-v1`` records carry no content key; a sample rebuilt shows the known overlap (the
    whole check rebuilds every test: the slow test below)."""
    report = overlaps({"test": [content_key(t) for t in r1]})
    assert report.repeats["test"] >= 1 and not report.clean


KNOWN_V1 = {  # python -m experiments.tools.build_pools --overlaps (docs/pools.md)
    "reachability1/5x5-v1": ({"train": 532, "validation": 5, "test": 38}, {("test", "train"): 276, ("validation", "train"): 62}),
    "safety2/5x5/fuel-v1": ({"train": 1, "validation": 0, "test": 0}, {("test", "train"): 3, ("validation", "train"): 1}),
    "safety2/5x5/fuel/static-v1": ({"train": 1, "validation": 0, "test": 0}, {("test", "train"): 3, ("validation", "train"): 1}),
    "reachability1/5x5/blocked/agent-v1": ({"train": 0, "validation": 0, "test": 0}, {("test", "train"): 0, ("validation", "train"): 0}),
    "reachability2/7x7/blocked-v1": ({"train": 0, "validation": 0, "test": 0}, {("test", "train"): 0, ("validation", "train"): 0}),
}


@pytest.mark.slow
@pytest.mark.parametrize("pool", V1, ids=lambda p: p.id)
def test_v1_pools_overlap_as_documented(pool: sp.StandardPool) -> None:
    """Every ``-v1`` test rebuilt and keyed (15-100 s a pool on a loaded 2-core machine): the
    repeats and shared tests docs/pools.md reports."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sp.SupersededPoolWarning)
        report = overlaps({s: split_keys(pool, s, rebuild=True) for s in SPLITS})
    repeats, shared = KNOWN_V1[pool.id]
    assert report.repeats == repeats
    assert {pair: report.shared[pair] for pair in shared} == shared


# ------------------------------------------------------------------ the record's key


def test_a_record_whose_key_is_not_its_tests_is_refused(data: Path) -> None:
    pool = sp.standard_pool(R1V2)

    def wrong_key(records: list[dict[str, Any]]) -> None:
        records[1]["content"] = records[0]["content"]  # the key of another test, digest sealed anew
        records[1]["digest"] = {"sha256": record_digest(records[1])}

    copy_split(pool, "test", data, 2, edit=wrong_key)
    for check in ("certificate", "full"):
        with pytest.raises(ProblemError, match=r"test\.jsonl\.gz, line 2: pool record of seed 2000001 .*not the one its content key names"):
            sp.load_standard_pool(R1V2, "test", 2, check=check)


def test_an_edited_key_is_refused_by_the_digest(data: Path) -> None:
    pool = sp.standard_pool(R1V2)
    copy_split(pool, "test", data, 2, edit=lambda rs: rs[1].update(content={"sha256": "0" * 64}))
    with pytest.raises(ProblemError, match=r"line 2: pool record of seed 2000001: the record was changed"):
        sp.load_standard_pool(R1V2, "test", 2)


def test_certify_writes_the_key_of_the_test_it_checked() -> None:
    pool = sp.standard_pool(R1V2)
    (rec,) = sp.read_records(pool, "test")[:1]
    p = pool.name
    again = certify(rec, p.size, p.family, p.n, p.world, p.kind, content=True)
    assert again == rec  # a shipped record is what certify writes today
    plain = certify(rec, p.size, p.family, p.n, p.world, p.kind)
    assert "content" not in plain and record_content_key(plain) is None
    (test,) = sp.load_standard_pool(pool.id, "test", 1)
    assert record_content_key(rec) == content_key(test)


def test_a_v2_split_out_of_seed_order_is_refused(data: Path) -> None:
    pool = sp.standard_pool(R1V2)
    copy_split(pool, "test", data, 3, edit=lambda rs: rs.reverse())
    with pytest.raises(ProblemError, match=r"test\.jsonl\.gz, line 2: expected the record of a seed in 2000003\.\."):
        sp.read_records(pool, "test")


# ------------------------------------------------------------------ the builder's draw


@pytest.fixture
def tiny(data: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> sp.StandardPool:
    """A ``"content"`` pool of 2x2 grids (24 layouts, a few with a test): seeds get skipped."""
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path / "cache"))
    pool = sp.StandardPool("reachability1/2x2-v2", "reachability1/2x2", 2, {"train": 5, "validation": 2, "test": 3}, draw="content")
    monkeypatch.setitem(sp.STANDARD_POOLS, pool.id, pool)
    return pool


def test_the_builder_draws_splits_in_turn_skipping_taken_tests(tiny: sp.StandardPool, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from experiments.tools import build_pools

    build_pools.build_split(tiny, "test", 3, reuse_cache=False)
    with pytest.raises(ProblemError, match="its validation split has 0 of 2 tests; .*build validation first"):
        build_pools.build_split(tiny, "train", 5, reuse_cache=False)
    build_pools.build_split(tiny, "validation", 2, reuse_cache=False)
    build_pools.build_split(tiny, "train", 3, reuse_cache=False)
    build_pools.build_split(tiny, "train", 5, reuse_cache=False)  # resumes after its last seed
    keys = {s: split_keys(tiny, s, rebuild=False) for s in SPLITS}
    assert overlaps(keys).clean and [len(keys[s]) for s in SPLITS] == [5, 2, 3]
    draw = json.loads((tiny.folder / "pool.json").read_text(encoding="utf-8"))["draw"]
    assert draw["layouts"] == 24 and draw["splits"]["train"]["seeds_skipped"] > 0
    train = tiny.seeds("train")
    assert draw["splits"]["train"]["seeds_skipped"] == train[-1] + 1 - len(train)
    skipped = [seed for seed in range(train[-1]) if seed not in train]
    p = tiny.name
    taken = set(itertools.chain(*keys.values()))
    for seed in skipped:  # each skipped seed's test is one already taken
        assert content_key(random_artifact(p.size, p.family, p.n, seed, p.kind, p.world)) in taken
    in_turn = tiny.path("train").read_bytes()
    monkeypatch.setattr(sp, "DATA_DIR", tmp_path / "again")  # the same pool built in one go: the same bytes
    for split in sp.DRAW_ORDER:
        build_pools.build_split(tiny, split, tiny.splits[split], reuse_cache=False)
    assert tiny.path("train").read_bytes() == in_turn


# ------------------------------------------------------------------ layouts and the birthday bound


def _brute_layouts(size: int, family: str, n: int, world: str, kind: str) -> int:
    """Every draw of ``world_problem`` enumerated (small grids only)."""
    from math import comb

    _, _, props, _ = family_objectives(family, n)
    cells = [(r, c) for r in range(size) for c in range(size)]
    k = blocked_count(size) if world == "blocked" else refuel_count(size) if world == "fuel" else 0
    total = 0
    for special in itertools.permutations(cells, len(props) + 2):
        (_, c0), (_, c1) = special[0], special[1]
        if kind != "agent":
            total += comb(len(cells) - len(special), k)
            continue
        for col in (c for c in range(size) if c not in (c0, c1)):
            rest = [x for x in cells if x not in special and x[1] != col]
            total += size * comb(len(rest), k)
    return total


@pytest.mark.parametrize(
    "case",
    [
        (3, "reachability", 1, "empty", "reactive"),
        (3, "reachability", 1, "blocked", "agent"),
        (4, "safety", 2, "fuel", "static"),
        (4, "reachability", 2, "blocked", "agent"),
    ],
)
def test_the_layout_count_is_every_draw(case: tuple[int, str, int, str, str]) -> None:
    assert layout_count(*case) == _brute_layouts(*case)


def test_the_layout_count_of_the_paper_grid() -> None:
    assert layout_count(5, "reachability", 1) == 25 * 24 * 23 == 13_800


def test_the_birthday_bound_is_the_expectation_of_independent_uniform_draws() -> None:
    """Enumerated over every draw of two splits (2 and 3 tests among 5 layouts)."""
    layouts, sizes = 5, {"a": 2, "b": 3}
    shared = repeats = collide = 0.0
    draws = list(itertools.product(range(layouts), repeat=5))
    for d in draws:
        a, b = d[:2], d[2:]
        shared += sum(1 for x in a if x in b)
        repeats += len(b) - len(set(b))
        collide += len(set(d)) < len(d)
    bound = birthday(layouts, sizes)
    assert bound["shared"]["a in b"] == pytest.approx(shared / len(draws))
    assert bound["repeats"]["b"] == pytest.approx(repeats / len(draws))
    assert bound["any_collision"] == pytest.approx(collide / len(draws))


def test_the_birthday_bound_predicts_v1s_overlap() -> None:
    """Chance alone gives about 257 of ``reachability1/5x5-v1``'s 1,000 held-out tests in its
    4,096 train tests (276 measured: rejected layouts raise the rate); a 7x7 blocked grid
    gives none."""
    assert birthday(13_800, {"train": 4096, "test": 1000})["shared"]["test in train"] == pytest.approx(256.8, abs=0.1)
    assert birthday(layout_count(7, "reachability", 2, "blocked"), {"train": 4096, "test": 1000})["any_collision"] < 1e-8


# ------------------------------------------------------------------ loading: v2 standard, v1 superseded


def test_v1_is_superseded_by_v2_and_says_so_once(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sp, "_WARNED", set())
    for pool in V1:
        assert pool.superseded_by == pool.id.replace("-v1", "-v2") and sp.current(pool.id).id == pool.superseded_by
    with pytest.warns(sp.SupersededPoolWarning, match=f"{R1V1} is superseded by {R1V2}"):
        sp.load_standard_pool(R1V1, "test", 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sp.load_standard_pool(R1V1, "test", 1)  # once per process
        sp.load_standard_pool(R1V2, "test", 1)  # v2: no warning


def test_a_v2_pool_is_its_shipped_tests() -> None:
    pool = sp.standard_pool(R1V2)
    with pytest.raises(ValueError, match="ships 1000 tests .*disjoint by content"):
        load_pool(R1V2, "test", 1001)
    assert pool_seeds(R1V2, "test", 3, 136) == pool.seeds("test")[136:139]
    assert TWINS[1] not in pool_seeds(R1V2, "test", 1000)
    assert pool_seeds(R1V1, "test", 2, 136) == [2_000_136, 2_000_137]
    got = [int(t.name.rsplit("-s", 1)[1]) for t in load_pool(R1V2, "test", 3, 136)]
    assert got == pool.seeds("test")[136:139]


def test_a_random_grid_env_takes_a_v2_id() -> None:
    import gymnasium as gym

    args = random_grid_arguments(R1V2, "test", 140, 5, "reachability", None, (), "reactive")
    assert args[3] == tuple(sp.standard_pool(R1V2).seeds("test")[:140]) and TWINS[1] not in args[3]
    env = gym.make("FlowTest-RandomGrid-v0", pool=R1V2, split="test", count=140)
    names = [g.artifact.name for g in env.unwrapped.games]
    assert names == [t.name for t in load_pool(R1V2, "test", 140)]
    assert len({content_key(g.artifact) for g in env.unwrapped.games}) == 140


def test_every_shipped_pool_file_is_package_data() -> None:
    """The wheel carries every pool folder: each file under the data folder matches a
    package-data glob of pyproject.toml."""
    globs = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]["package-data"]["flowtest_env"]
    package = ROOT / "flowtest_env"
    files = [f.relative_to(package).as_posix() for f in sp.DATA_DIR.rglob("*") if f.is_file()]
    assert files and not [f for f in files if not any(fnmatch.fnmatch(f, g) for g in globs)]
    assert {p.slug for p in sp.STANDARD_POOLS.values()} <= {f.split("/")[2] for f in files}
