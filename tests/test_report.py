"""The HTML evaluation report: the outcome matrix first, folded rows, the tests with their
objectives, filmstrips and replay commands of the failing runs."""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import pytest

from agents.registry import make_policy
from experiments.episodes import run_episode
from experiments.evaluate import evaluate, write_report
from experiments.filmstrip import MAX_FRAMES, frames_to_show
from experiments.report import fold_rows, outcome_class


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict]]:
    out = tmp_path_factory.mktemp("report")
    cells = evaluate(
        ["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"], ["scripted:replanner", "gr1", "scripted:committed"], 2, seed=0
    )
    return out, write_report(cells, out)


def test_report_opens_with_the_matrix_and_explains_the_outcomes(report: tuple[Path, list[dict]]) -> None:
    out, records = report
    page = (out / "report.html").read_text()
    assert page.index("class='matrix'") < page.index("id='tests'") < page.index("id='failures'") < page.index("id='numbers'")
    for word in ("met", "realized", "violated", "open"):
        assert f"<dt>{word}</dt>" in page
    # every column links to its test, which shows the system objective and hides the test one
    for env in ("FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"):
        slug = env.lower()
        assert f"href='#test-{slug}'" in page and f"id='test-{slug}'" in page
    assert page.count("<details><summary>Reveal the test objective") == 2
    for pic in re.findall(r"src='(tests/[^']+)'", page):
        assert (out / pic).stat().st_size > 500


def test_identical_rows_are_folded(report: tuple[Path, list[dict]]) -> None:
    out, records = report
    envs = ["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"]
    groups = fold_rows(records, envs)
    assert ["scripted:replanner", "gr1"] in groups and ["scripted:committed"] in groups
    page = (out / "report.html").read_text()
    assert "2 systems, identical results" in page
    matrix = page[page.index("class='matrix'") : page.index("</table>")]
    assert matrix.count("<tr>") == 1 + len(groups)
    assert {outcome_class(r) for r in records if r["sut"] == "gr1"} == {"pass"}


def test_failing_runs_have_a_filmstrip_and_a_replay_command_each(report: tuple[Path, list[dict]]) -> None:
    out, records = report
    page = (out / "report.html").read_text()
    failing = [r for r in records if r["n_failures"]]
    assert failing
    for r in failing:
        film = r["pictures"]["filmstrip"]
        assert (out / film).stat().st_size > 5000 and f"src='{film}'" in page
        for f in r["failures"]:
            assert f["replay"] in page.replace("&#x27;", "'")
        assert outcome_class(r) in ("some", "all")
        assert "class='all'" in page or "class='some'" in page


def test_filmstrip_keeps_start_end_and_the_changes() -> None:
    env = gym.make("FlowTest-Maze2-v0")
    t = run_episode(env, make_policy("random", env), "FlowTest-Maze2-v0", "random", 0)
    game = env.unwrapped.game
    shown = frames_to_show(game, t.states)
    assert shown[0] == 0 and shown[-1] == len(t.states) - 1 and len(shown) <= MAX_FRAMES
    everything = frames_to_show(game, t.states, limit=10_000)
    moved = [k for k in range(1, len(t.states)) if t.states[k].system != t.states[k - 1].system
             or t.states[k].agent != t.states[k - 1].agent]
    assert set(moved) <= set(everything)


def test_filmstrip_names_what_the_test_did() -> None:
    """Doors on a reactive test, the test agent's moves on an agent test."""
    from experiments.filmstrip import _events

    for env_id, sut, word in (
        ("FlowTest-SmallReactive-v0", "scripted:committed", "door closed"),
        ("FlowTest-Maze2-v0", "scripted:committed", "agent moved"),
    ):
        env = gym.make(env_id)
        t = run_episode(env, make_policy(sut, env), env_id, sut, 0)
        assert any(word in ev for ev in _events(env.unwrapped.game, t.states, t.actions)), env_id
