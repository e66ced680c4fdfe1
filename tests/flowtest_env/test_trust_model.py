"""A test is what it claims (docs/architecture.md, "Trust model: what loading checks").

Each test below is a case of the hostile battery that loaded silently before: a test
agent's controller that does not realize its restrictions, another problem's cache entry,
edited tests that stay valid (a user's file, a cache entry, a shipped file with its
manifest, a pool record), files declaring sizes far beyond their bytes, huge integers and
control characters in an artifact. Each is now refused (or, for a user's own file,
checked in full and reported as edited) through the entry points a user calls:
``gym.make`` and ``flowtest``.
"""

from __future__ import annotations

import copy
import json
import shutil
import tracemalloc
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

import flowtest_env
import flowtest_env.artifacts as artifacts
import flowtest_env.random_grid as rg
from experiments.cli.cli import main as cli_main
from flowtest_env import sources
from flowtest_env.game import TestGame, printable
from flowtest_env.render import ansi
from synthesis.artifacts.artifact import (
    MAX_TABLE_CELLS,
    EditedArtifactWarning,
    TestArtifact,
    content_digest,
    digest_matches,
    source_hash,
    with_digest,
)
from synthesis.model.errors import ProblemError
from tests.testing_artifacts import played_artifact

SHIPPED = Path(artifacts.__file__).parent / "artifacts"
DATA = Path(__file__).resolve().parents[1] / "data"


def shipped(name: str) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((SHIPPED / f"{name}.json").read_text())
    return doc


def rehash(d: dict[str, Any]) -> dict[str, Any]:
    """What an attacker who knows the format does: the source hash made true again."""
    d["source"] = {"sha256": source_hash(d["system"], d["objectives"], d["kind"])}
    return d


# ---------------------------------------------------------------- the digest


def test_every_shipped_artifact_carries_the_digest_of_its_content() -> None:
    for path in sorted(SHIPPED.glob("*.json")):
        d = json.loads(path.read_text())
        assert digest_matches(d), path.name
        assert d["digest"] == {"sha256": content_digest(d)}
        assert json.dumps(with_digest(d), separators=(",", ":")) == path.read_text(), "written canonically, digest last"


def test_a_saved_artifact_round_trips_with_its_digest(tmp_path: Path) -> None:
    art = TestArtifact.load(SHIPPED / "small-reactive.json")
    art.save(tmp_path / "a.json")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = TestArtifact.load(tmp_path / "a.json", require_digest=True)
    assert again.to_dict() == art.to_dict() and not again.edited


# ------------------------------------------------- break 3: the test agent is checked


def _parked_for_good(d: dict[str, Any]) -> None:
    """The agent of maze2 goes to a park and stays there, whatever the system does."""
    ctl = d["agent"]["controller"]
    park = ctl["agent_names"].index("above")
    ctl["table"]["next_agent"] = [park] * len(ctl["table"]["next_agent"])


def test_a_parked_agent_is_refused_through_gym_make(tmp_path: Path, cache: Path) -> None:
    d = copy.deepcopy(shipped("maze2"))
    _parked_for_good(d)
    path = tmp_path / "maze2-parked.json"
    path.write_text(json.dumps(with_digest(d)))  # even with a digest made true again
    with pytest.raises(ProblemError, match="test agent does not realize its restrictions"):
        gym.make("FlowTest-v0", test=str(path))


def test_a_parked_agent_is_one_error_line_from_flowtest_evaluate(tmp_path: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = copy.deepcopy(shipped("maze2"))
    _parked_for_good(d)
    path = tmp_path / "maze2-parked.json"
    path.write_text(json.dumps(d))
    code = cli_main(["evaluate", "--env", str(path), "--sut", "random", "--episodes", "1", "--out", str(tmp_path / "r"), "-q"])
    err = capsys.readouterr().err
    assert code == 2, err  # invalid input, not a FlowTest bug (exit 4)
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "test agent does not realize" in errors[0] and "Traceback" not in err


def test_a_parked_agent_in_the_shipped_maze2_is_refused_even_with_its_manifest_and_digest(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "shipped"
    shutil.copytree(SHIPPED, folder)
    monkeypatch.setattr(artifacts, "ARTIFACT_DIR", folder)
    d = shipped("maze2")
    _parked_for_good(d)
    (folder / "maze2.json").write_text(json.dumps(with_digest(d), separators=(",", ":")))
    artifacts.write_manifest(folder)
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()
    try:
        with pytest.raises(ProblemError, match="test agent does not realize its restrictions"):
            gym.make("FlowTest-Maze2-v0")
    finally:
        artifacts.load_builtin.cache_clear()
        artifacts.builtin_game.cache_clear()


def test_an_agent_whose_controller_belongs_to_another_agent_is_refused(tmp_path: Path) -> None:
    d = copy.deepcopy(shipped("maze2"))
    d["agent"]["start"] = "(2, 1)"
    path = tmp_path / "a.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ProblemError, match="does not belong to the test agent"):
        TestArtifact.load(path)


# ----------------------------------------- break 4: the problem-file cache checks its source


def test_the_problem_file_cache_never_serves_another_problems_test(tmp_path: Path, cache: Path) -> None:
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    shutil.copy(DATA / "ok_grid.toml", a)
    shutil.copy(DATA / "ok_graph.toml", b)
    assert flowtest_env.load_test(a).name == "ok-grid"
    assert flowtest_env.load_test(b).name == "ok-graph"
    (entry_a,) = (cache / "problems").glob("a-*.json")
    (entry_b,) = (cache / "problems").glob("b-*.json")
    shutil.copy(entry_b, entry_a)  # b's test (another grid, another kind) filed under a
    sources._LOADED.clear()
    with pytest.warns(UserWarning, match="another problem file"):
        env = gym.make("FlowTest-v0", test=str(a))
    assert played_artifact(env).name == "ok-grid" and played_artifact(env).kind == "static"
    with warnings.catch_warnings():  # the entry was rebuilt: the next process takes it silently
        warnings.simplefilter("error")
        sources._LOADED.clear()
        assert flowtest_env.load_test(a).name == "ok-grid"


# ----------------------------------------------- break 5: edited tests that stay valid


def _one_more_restriction(d: dict[str, Any]) -> None:
    """small-reactive with one more restriction that still passes every check."""
    d["strategy"]["restrictions"]["2"] = [0]


def test_a_users_edited_but_valid_artifact_is_checked_and_reported(tmp_path: Path, cache: Path) -> None:
    d = copy.deepcopy(shipped("small-reactive"))
    _one_more_restriction(d)
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(d))
    with pytest.warns(EditedArtifactWarning, match="changed after FlowTest wrote it"):
        env = gym.make("FlowTest-v0", test=str(path))
    assert played_artifact(env).edited


def test_an_edited_but_valid_cache_entry_is_refused_and_rebuilt(tmp_path: Path, cache: Path) -> None:
    p = tmp_path / "mine.toml"
    shutil.copy(DATA / "ok_grid.toml", p)
    true_summary = flowtest_env.load_test(p).summary
    (entry,) = (cache / "problems").glob("mine-*.json")
    d = json.loads(entry.read_text())
    d["summary"]["status"] = "optimal-by-hand"
    entry.write_text(json.dumps(d))
    sources._LOADED.clear()
    with pytest.warns(UserWarning, match="refused a cache entry.*changed after FlowTest wrote it"):
        art = flowtest_env.load_test(p)
    assert art.summary["status"] == true_summary["status"] != "optimal-by-hand"


def test_an_edited_shipped_artifact_with_its_manifest_rewritten_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "shipped"
    shutil.copytree(SHIPPED, folder)
    monkeypatch.setattr(artifacts, "ARTIFACT_DIR", folder)
    path = folder / "small-reactive.json"
    d = json.loads(path.read_text())
    _one_more_restriction(d)
    path.write_text(json.dumps(d, separators=(",", ":")))
    artifacts.write_manifest(folder)  # the manifest made true again
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()
    try:
        with pytest.raises(ProblemError, match="changed after FlowTest wrote it"):
            gym.make("FlowTest-SmallReactive-v0")
    finally:
        artifacts.load_builtin.cache_clear()
        artifacts.builtin_game.cache_clear()


def test_an_edited_pool_record_is_refused_and_synthesized_again(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (art,) = rg.build_pool(5, "reachability", 1, [0])
    path = rg.pool_path(5, "reachability", 1, 0, "reactive")
    (line,) = path.read_text().splitlines()
    record = json.loads(line)
    assert record["digest"]["sha256"]
    record["summary"]["status"] = "optimal-by-hand"
    path.write_text(json.dumps(record) + "\n")
    built: list[tuple[Any, ...]] = []
    real = rg.pool_record

    def counted(*a: Any, **k: Any) -> dict[str, Any]:
        built.append(a)
        return real(*a, **k)

    monkeypatch.setattr(rg, "pool_record", counted)
    with pytest.warns(UserWarning, match="changed after FlowTest wrote it"):
        (again,) = rg.build_pool(5, "reachability", 1, [0])
    assert built, "the seed was synthesized again"
    assert again.summary["status"] == art.summary["status"] != "optimal-by-hand"


# -------------------------------------------------------- break 6: artifact bombs


def test_a_huge_layout_for_a_small_system_is_refused_before_observations(tmp_path: Path, cache: Path) -> None:
    d = copy.deepcopy(shipped("small-reactive"))  # a 2x3 grid
    d["system"]["layout"].update(rows=3000, cols=3000)
    path = tmp_path / "bomb.json"
    path.write_text(json.dumps(rehash(d)))
    assert path.stat().st_size < 4000
    tracemalloc.start()
    try:
        with pytest.raises(ProblemError, match="layout"):
            gym.make("FlowTest-v0", test=str(path))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20_000_000, f"{peak} bytes before the refusal"


def test_a_declared_agent_table_beyond_the_limit_is_refused_before_it_is_built(tmp_path: Path) -> None:
    d = copy.deepcopy(shipped("maze2"))
    ctl = d["agent"]["controller"]
    ctl["n_memory"] = 50_000  # 50,000 x 52 rows x 13 agent states: far above the limit
    assert ctl["n_memory"] * len(ctl["rows"]) * len(ctl["agent_names"]) > MAX_TABLE_CELLS
    path = tmp_path / "bomb.json"
    path.write_text(json.dumps(d))
    tracemalloc.start()
    try:
        with pytest.raises(ProblemError, match="above the limit"):
            TestArtifact.load(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20_000_000, f"{peak} bytes before the refusal"


# ----------------------------------------------- break 10: huge integers in an artifact


@pytest.mark.parametrize("digits", [5000, 400])
def test_a_huge_integer_in_an_artifact_is_an_input_error(tmp_path: Path, cache: Path, digits: int) -> None:
    text = (SHIPPED / "small-reactive.json").read_text()
    path = tmp_path / "big.json"
    path.write_text(text.replace('"extras":{', '"extras":{"x":' + "9" * digits + ",", 1))
    with pytest.raises(ProblemError, match="digits"):
        gym.make("FlowTest-v0", test=str(path))


def test_a_huge_integer_is_one_error_line_from_the_cli(tmp_path: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = (SHIPPED / "small-reactive.json").read_text()
    path = tmp_path / "big.json"
    path.write_text(text.replace('"initial":', '"initial":' + "1" * 5000 + "0*", 1).replace("0*", "", 1))
    code = cli_main(["evaluate", "--env", str(path), "--sut", "random", "--episodes", "1", "--replay", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("error:") == 1 and "Traceback" not in err, err


# ---------------------------------------------- break 14: names are printable


def _graph_with_a_control_name(d: dict[str, Any], bad: str) -> dict[str, Any]:
    states = d["system"]["states"]
    old = states[1]
    states[1] = bad
    d["system"]["places"] = [bad if p == old else p for p in d["system"]["places"]]
    return rehash(d)


@pytest.mark.parametrize("bad", ["red\x1b[31m", "two\nlines", "bell\x07"])
def test_control_characters_in_artifact_names_are_refused(tmp_path: Path, cache: Path, bad: str) -> None:
    d = _graph_with_a_control_name(copy.deepcopy(shipped("beaver-rescue")), bad)
    path = tmp_path / "names.json"
    path.write_text(json.dumps(d))
    with pytest.raises(ProblemError, match="non-printable"):
        gym.make("FlowTest-v0", test=str(path))


def test_a_control_character_never_comes_out_raw() -> None:
    """A Problem built in Python may still name a state with one: the text outputs escape it."""
    art = TestArtifact.load(SHIPPED / "beaver-rescue.json")
    states = list(art.system.states)
    states[0] = "start\x1b[2J"
    art2 = replace(art, system=replace(art.system, states=states))
    game = TestGame(art2)
    run = game.reset()
    shown = game.state_json(0)
    assert shown == "start\\x1b[2J" and "\x1b" not in str(shown)
    assert printable("ok") == "ok"
    assert "\x1b" not in ansi(game, run, "engineer") and "\x1b" not in ansi(game, run)


def test_the_edited_warning_is_one_line_from_the_console_script(tmp_path: Path) -> None:
    """``flowtest`` shows a user's edited (but valid) artifact as one warning line, then runs it."""
    import subprocess
    import sys

    d = copy.deepcopy(shipped("small-reactive"))
    _one_more_restriction(d)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(d))
    flowtest = Path(sys.executable).parent / "flowtest"
    proc = subprocess.run(
        [str(flowtest), "evaluate", "--env", str(path), "--sut", "random", "--episodes", "1", "--replay", "-q"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    warned = [line for line in proc.stderr.splitlines() if "changed after FlowTest wrote it" in line]
    assert len(warned) == 1 and warned[0].startswith("flowtest: warning: artifact "), proc.stderr
    assert "Traceback" not in proc.stderr and "\x1b" not in proc.stderr
