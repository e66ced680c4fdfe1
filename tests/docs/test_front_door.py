"""One front door for tests: a built-in name, a problem file, an artifact file or a Python
object all make the same environments (Gymnasium, PettingZoo, the CLI), and a problem
file is synthesized once, then found in the cache under its content and versions."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env
from experiments.cli.cli import main
from flowtest_env import multiagent, sources
from synthesis.artifacts import provenance
from synthesis.artifacts.artifact import TestArtifact, artifact_of
from synthesis.artifacts.summary import summary_of
from synthesis.model.errors import ProblemError
from synthesis.pipeline import synthesize
from synthesis.problems.files import load_problem_file

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture()
def problem_file(tmp_path: Path) -> Path:
    p = tmp_path / "mine.toml"
    shutil.copy(DATA / "ok_grid.toml", p)
    return p


def _episode(env: gym.Env) -> dict:
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    rng = np.random.default_rng(0)
    done = False
    while not done:
        a = int(rng.choice(np.flatnonzero(info["action_mask"])))
        obs, _, term, trunc, info = env.step(a)
        done = term or trunc
    return info["verdict"]


def test_problem_file_is_synthesized_once_then_cached(cache: Path, problem_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    env = gym.make("FlowTest-v0", test=str(problem_file))
    assert env.unwrapped.problem == "ok-grid"
    _episode(env)
    entries = list((cache / "problems").glob("mine-*.json"))
    assert len(entries) == 1
    # a new process (empty memory cache) finds the disk entry and never synthesizes
    monkeypatch.setattr(sources, "_LOADED", {})
    monkeypatch.setattr("synthesis.pipeline.synthesize", lambda *a, **k: pytest.fail("synthesized again"))  # where sources synthesizes
    art = flowtest_env.load_test(problem_file)
    assert art.name == "ok-grid"
    # another content is another key: synthesized again
    problem_file.write_text(problem_file.read_text().replace('test = "F I"', 'test = "F I"\n# changed'))
    with pytest.raises(pytest.fail.Exception, match="synthesized again"):
        flowtest_env.load_test(problem_file)


def test_cache_key_depends_on_content_versions_and_options(monkeypatch: pytest.MonkeyPatch) -> None:
    k = provenance.content_key("problem", b"a")
    assert k == provenance.content_key("problem", b"a")
    assert k != provenance.content_key("problem", b"b")
    assert k != provenance.content_key("pool", b"a")
    assert provenance.content_key("problem", b"a", {"x": 1, "y": 2}) == provenance.content_key("problem", b"a", {"y": 2, "x": 1})
    assert provenance.content_key("problem", b"a", {"x": 1}) != k
    assert {"flowtest", "flowtest_source", "highspy"} <= set(provenance.versions())
    other = {**provenance.versions(), "highspy": "0.0.0-other"}
    monkeypatch.setattr(provenance, "versions", lambda: other)
    assert provenance.content_key("problem", b"a") != k


def test_artifact_file_and_python_objects(cache: Path, tmp_path: Path) -> None:
    test = synthesize(load_problem_file(DATA / "ok_grid.toml"))
    art = artifact_of(test, summary_of(test))
    path = tmp_path / "mine.json"
    art.save(path)
    verdicts = [
        _episode(gym.make("FlowTest-v0", test=str(path))),
        _episode(gym.make("FlowTest-v0", test=path)),
        _episode(flowtest_env.make_env(test)),
        _episode(flowtest_env.make_env(art)),
        _episode(flowtest_env.make_env(test.problem)),
    ]
    assert verdicts[0]["system_objective"] == "met"
    assert all(v == verdicts[0] for v in verdicts)
    assert flowtest_env.make_env(art, max_steps=7).max_steps == 7
    assert isinstance(flowtest_env.load_test(path), TestArtifact)


def test_builtin_names_and_registered_ids_agree() -> None:
    a = gym.make("FlowTest-v0", test="small-reactive")
    b = gym.make("FlowTest-SmallReactive-v0")
    assert a.unwrapped.artifact is b.unwrapped.artifact
    assert a.observation_space == b.observation_space
    assert gym.make("FlowTest-Maze2-v0", test="maze2").unwrapped.problem == "maze2"


def test_multiagent_takes_the_same_forms(cache: Path, problem_file: Path) -> None:
    aec = multiagent.env(test=str(problem_file))
    aec.reset(seed=0)
    assert aec.unwrapped.problem == "ok-grid"
    par = multiagent.parallel_env(test=problem_file)
    obs, _ = par.reset(seed=0)
    assert set(obs) == {"tester_0", "system_0"}
    assert multiagent.raw_env(problem="maze2").problem == "maze2"  # the older keyword


@pytest.mark.parametrize(
    "bad, needle",
    [("no-such-file.toml", "neither a built-in"), ("{json}", "not a FlowTest test artifact")],
)
def test_bad_tests_are_one_clear_error(bad: str, needle: str, cache: Path, tmp_path: Path) -> None:
    if bad == "{json}":
        p = tmp_path / "other.json"
        p.write_text(json.dumps({"format": "something-else"}))
        bad = str(p)
    with pytest.raises(ProblemError, match=needle):
        flowtest_env.make_env(bad)
    with pytest.raises(ProblemError, match="test must be"):
        flowtest_env.make_env(42)  # type: ignore[arg-type]


def test_cli_evaluate_a_problem_file_without_registration(cache: Path, problem_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    code = main(["evaluate", "--env", str(problem_file), "--sut", "scripted:replanner", "gr1", "--episodes", "2", "--out", str(out), "-q"])
    assert code == 0
    records = json.loads((out / "results.json").read_text())
    assert {r["env"] for r in records} == {str(problem_file)}
    assert all(r["system_objective_met_rate"] == 1.0 for r in records)
    code = main(["evaluate", "--env", "FlowTest-Nope-v0", "--sut", "gr1", "--out", str(tmp_path / "x")])
    assert code == 2
    assert "not a registered ID" in capsys.readouterr().err


def test_a_damaged_cache_entry_is_refused_and_rebuilt(cache: Path, problem_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    flowtest_env.load_test(problem_file)
    (entry,) = (cache / "problems").glob("mine-*.json")
    good = entry.read_text()
    entry.write_text(good.replace('"flow":1', '"flow":7'))
    monkeypatch.setattr(sources, "_LOADED", {})
    with pytest.warns(UserWarning, match="refused a cache entry"):
        art = flowtest_env.load_test(problem_file)
    assert art.summary["flow"] == 1
    assert TestArtifact.load(entry).summary["flow"] == 1
