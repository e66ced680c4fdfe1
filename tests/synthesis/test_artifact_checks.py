"""Artifacts and caches that cannot lie (issue 13, point 2).

An artifact is checked on load: every field against the schema, its source hash against
its own content, its automata against its objectives, its restrictions against its own
product graphs. Edited artifacts are refused with a message naming what is wrong; a
shipped artifact must have the bytes FlowTest shipped; an edited cache entry is refused
(with a warning saying why) and synthesized again.
"""

from __future__ import annotations

import copy
import json
import shutil
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

import flowtest_env  # noqa: F401  (registers the envs)
import flowtest_env.artifacts as artifacts
from synthesis.artifacts.artifact import TestArtifact, problem_source_hash, source_hash
from synthesis.model.errors import ProblemError
from synthesis.problems.builtins import BUILTINS
from tests.testing_artifacts import played_artifact

SHIPPED = Path(artifacts.__file__).parent / "artifacts"
NAMES = sorted(p.stem for p in SHIPPED.glob("*.json"))


def shipped(name: str) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((SHIPPED / f"{name}.json").read_text())
    return doc


def test_manifest_lists_every_shipped_artifact_with_its_bytes() -> None:
    sums = artifacts.shipped_digests()
    assert sorted(sums) == sorted(f"{n}.json" for n in NAMES)
    for name in NAMES:
        assert sums[f"{name}.json"] == artifacts.file_sha256(SHIPPED / f"{name}.json")


@pytest.mark.parametrize("name", NAMES)
def test_shipped_artifacts_pass_every_check_and_carry_their_problems_hash(name: str) -> None:
    art = TestArtifact.load(SHIPPED / f"{name}.json")  # full checks, restrictions included
    assert art.source == problem_source_hash(BUILTINS[name]())


def _empty_restrictions(d: dict[str, Any]) -> None:
    d["strategy"]["restrictions"] = {}
    d["strategy"]["static_obstacles"] = []


def _swap_automata(d: dict[str, Any]) -> None:
    other = shipped("small-reactive")
    d["automata"] = other["automata"]
    d["letters"] = other["letters"]


EDITS: list[tuple[str, str, Callable[[dict[str, Any]], None], str]] = [
    ("example1", "restrictions emptied", _empty_restrictions, "bypass flow"),
    ("small-reactive", "restrictions emptied", _empty_restrictions, "bypass flow"),
    ("maze2", "restrictions emptied", _empty_restrictions, "bypass flow"),
    ("small-reactive", "flow claimed", lambda d: d["summary"].__setitem__("flow", 7), "the MILP said 7"),
    ("small-reactive", "move index out of range", lambda d: d["strategy"]["static_obstacles"].append(10_000), "strategy.static_obstacles"),
    ("small-reactive", "history out of range", lambda d: d["strategy"]["restrictions"].__setitem__("99", [0]), "strategy.restrictions"),
    ("small-reactive", "delta out of range", lambda d: d["automata"]["histories"]["delta"][0].__setitem__(0, 99), "automata.histories.delta[0][0]"),
    ("small-reactive", "initial state out of range", lambda d: d["system"].__setitem__("initial", -1), "system.initial"),
    ("small-reactive", "boolean for an integer", lambda d: d["system"].__setitem__("initial", True), "system.initial"),
    ("small-reactive", "move out of range", lambda d: d["system"]["moves"][0].__setitem__(1, 10_000), "system.moves[0]"),
    ("small-reactive", "field missing", lambda d: d.pop("strategy"), "field strategy: missing"),
    ("small-reactive", "field of the wrong type", lambda d: d.__setitem__("letters", "abc"), "field letters"),
    ("small-reactive", "source missing", lambda d: d.pop("source"), "field source"),
    ("small-reactive", "label outside the alphabet", lambda d: d["system"]["labels"][0].append("goal"), "system.labels[0]"),
    ("small-reactive", "label edited", lambda d: d["system"]["labels"].__setitem__(0, d["system"]["labels"][2]), "source hash"),
    ("small-reactive", "objective edited", lambda d: d["objectives"].__setitem__("test", "F I1"), "source hash"),
    ("example1", "another problem's automata", _swap_automata, "is not one of the letters"),
    ("small-reactive", "automata swapped", lambda d: d["automata"].update(system=d["automata"]["test"], test=d["automata"]["system"]), "field automata."),
    (
        "small-reactive",
        "acceptance flipped",
        lambda d: d["automata"]["test"]["accepting"][0].__setitem__(0, 1 - d["automata"]["test"]["accepting"][0][0]),
        "automata.test is not the automaton of its objectives",
    ),
    ("maze2", "agent table out of range", lambda d: d["agent"]["controller"]["table"]["next_agent"].__setitem__(0, 99), "agent.controller.table.next_agent[0]"),
    ("maze2", "agent removed", lambda d: d.__setitem__("agent", None), "field agent"),
    ("small-reactive", "not an object", lambda d: d.clear(), "not a FlowTest test artifact"),
]


@pytest.mark.parametrize("name,what,edit,words", EDITS, ids=[f"{e[0]}-{e[1]}" for e in EDITS])
def test_edited_artifact_is_refused_naming_what_is_wrong(tmp_path: Path, name: str, what: str, edit: Callable[[dict[str, Any]], None], words: str) -> None:
    d = copy.deepcopy(shipped(name))
    edit(d)
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ProblemError) as info:
        TestArtifact.load(path)
    assert words in str(info.value), str(info.value)
    assert str(path) in str(info.value)


def test_edited_artifact_with_a_recomputed_hash_still_fails_its_restrictions(tmp_path: Path) -> None:
    """Recomputing the source hash does not help: the restrictions are searched again."""
    d = shipped("small-reactive")
    _empty_restrictions(d)
    d["source"] = {"sha256": source_hash(d["system"], d["objectives"], d["kind"])}
    (tmp_path / "a.json").write_text(json.dumps(d))
    with pytest.raises(ProblemError, match="bypass flow"):
        TestArtifact.load(tmp_path / "a.json")


def test_artifact_files_that_are_not_artifacts(tmp_path: Path) -> None:
    for text, words in (
        ("[]", "not a FlowTest test artifact"),
        ("{", "invalid JSON"),
        ("[" * 100_000, "JSON"),
        ('{"format": "flowtest-test", "version": 99}', "version"),
    ):
        (tmp_path / "a.json").write_text(text)
        with pytest.raises(ProblemError, match=words):
            TestArtifact.load(tmp_path / "a.json")
    (tmp_path / "b.json").write_bytes(b"\xff\xfe")
    with pytest.raises(ProblemError, match="UTF-8"):
        TestArtifact.load(tmp_path / "b.json")


@pytest.fixture
def own_artifacts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A copy of the shipped artifacts and an empty cache under ``tmp_path``."""
    monkeypatch.setattr(artifacts, "ARTIFACT_DIR", tmp_path / "shipped")
    shutil.copytree(SHIPPED, tmp_path / "shipped")
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path / "cache"))
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()
    yield tmp_path
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()


def test_edited_shipped_artifact_is_refused(own_artifacts: Path) -> None:
    path = own_artifacts / "shipped" / "small-reactive.json"
    d = json.loads(path.read_text())
    _empty_restrictions(d)
    path.write_text(json.dumps(d, separators=(",", ":")))
    with pytest.raises(ProblemError, match="not the file FlowTest shipped"):
        gym.make("FlowTest-SmallReactive-v0")


def test_shipped_artifact_of_another_problem_is_refused(own_artifacts: Path) -> None:
    """Even with its bytes in the manifest, example1's file does not stand for small-reactive."""
    folder = own_artifacts / "shipped"
    shutil.copy(folder / "example1.json", folder / "small-reactive.json")
    artifacts.write_manifest(folder)
    with pytest.raises(ProblemError, match="another problem"):
        gym.make("FlowTest-SmallReactive-v0")


def test_edited_cache_entry_is_refused_with_a_warning_and_rebuilt(own_artifacts: Path) -> None:
    (own_artifacts / "shipped" / "small-reactive.json").unlink()
    cached = artifacts.builtin_cache_path("small-reactive")
    cached.parent.mkdir(parents=True)
    d = shipped("small-reactive")
    _empty_restrictions(d)
    d["source"] = {"sha256": source_hash(d["system"], d["objectives"], d["kind"])}
    cached.write_text(json.dumps(d))
    with pytest.warns(UserWarning, match="refused a cache entry.*bypass flow"):
        env = gym.make("FlowTest-SmallReactive-v0")
    assert played_artifact(env).strategy.restrictions.any()  # the true test, not the edited one
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym.make("FlowTest-SmallReactive-v0")  # the rebuilt entry is accepted silently


def test_cache_entry_of_another_problem_is_refused(own_artifacts: Path) -> None:
    (own_artifacts / "shipped" / "small-reactive.json").unlink()
    cached = artifacts.builtin_cache_path("small-reactive")
    cached.parent.mkdir(parents=True)
    shutil.copy(SHIPPED / "example1.json", cached)
    with pytest.warns(UserWarning, match="another problem"):
        env = gym.make("FlowTest-SmallReactive-v0")
    assert played_artifact(env).name == "small-reactive"


def test_edited_random_grid_cache_entry_is_refused(own_artifacts: Path) -> None:
    from flowtest_env.random_grid import _POOLS, pool_path, random_pool

    random_pool(5, "reachability", 1, (0,))
    path = pool_path(5, "reachability", 1, 0, "reactive")
    d = json.loads(path.read_text())
    d["cuts"], d["static"] = [], []  # no restrictions: the bypass flow is no longer 0
    path.write_text(json.dumps(d) + "\n")
    _POOLS.clear()
    try:
        with pytest.warns(UserWarning, match="refused a cache entry.*bypass flow"):
            (art,) = random_pool(5, "reachability", 1, (0,))
        assert art.strategy.restrictions.any() or art.strategy.static_obstacles.any()
        d = json.loads(path.read_text())
        d["seed"] = 1  # seed 0's answer filed as seed 1's
        path.write_text(path.read_text() + json.dumps(d) + "\n")
        _POOLS.clear()
        with pytest.warns(UserWarning, match="refused a cache entry.*seed 1"):
            (art,) = random_pool(5, "reachability", 1, (1,))
        assert art.name.endswith("-s1")
    finally:
        _POOLS.clear()
