"""The HTML evaluation report: the outcome matrix first, folded rows, the tests with their
objectives, filmstrips and replay commands of the failing runs; tests called by their
problem's name, their restrictions per history and propositions on the card, a violation
named by its conjunct, step and cell, and one file name and anchor per test."""

from __future__ import annotations

import hashlib
import html as html_lib
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

from agents.registry import make_policy
from experiments.evaluation import Cell, evaluate, write_report
from experiments.evaluation.episodes import run_episode
from experiments.evaluation.filmstrip import MAX_FRAMES, frames_to_show, symbol_legend
from experiments.evaluation.filmstrip import test_picture as draw_test_picture
from experiments.evaluation.report import (
    STYLE,
    TestInfo,
    failures_anchor,
    file_key,
    fold_rows,
    outcome_class,
    render_html,
)
from experiments.evaluation.report import test_anchor as card_anchor
from experiments.evaluation.report import test_infos as draw_test_infos
from experiments.evaluation.report import test_titles as titles_of
from experiments.evaluation.violations import violation_of, violation_of_trace, written_conjuncts
from experiments.plots import artifact_view, panels_of
from tests.testing_reports import passing_record


def _game(env: Any) -> Any:
    """The test game behind a FlowTest env."""
    return env.unwrapped.game


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, Any]]]:
    out = tmp_path_factory.mktemp("report")
    cells = evaluate(["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"], ["scripted:replanner", "gr1", "scripted:committed"], 2, seed=0)
    return out, write_report(cells, out)


def test_report_opens_with_the_matrix_and_explains_the_outcomes(report: tuple[Path, list[dict[str, Any]]]) -> None:
    out, records = report
    page = (out / "report.html").read_text()
    assert page.index("class='matrix'") < page.index("id='tests'") < page.index("id='failures'") < page.index("id='numbers'")
    for word in ("met", "realized", "violated", "open"):
        assert f"<dt>{word}</dt>" in page
    # every column links to its test, which shows the system objective and hides the test one
    for env in ("FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"):
        anchor = card_anchor(env)
        assert f"href='#{anchor}'" in page and f"id='{anchor}'" in page
    assert page.count("<details><summary>Reveal the test objective") == 2
    for pic in re.findall(r"src='(tests/[^']+)'", page):
        assert (out / pic).stat().st_size > 500


def test_identical_rows_are_folded(report: tuple[Path, list[dict[str, Any]]]) -> None:
    out, records = report
    envs = ["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"]
    groups = fold_rows(records, envs)
    assert ["scripted:replanner", "gr1"] in groups and ["scripted:committed"] in groups
    page = (out / "report.html").read_text()
    assert "2 systems, identical results" in page
    matrix = page[page.index("class='matrix'") : page.index("</table>")]
    assert matrix.count("<tr>") == 1 + len(groups)
    assert {outcome_class(r) for r in records if r["sut"] == "gr1"} == {"pass"}


def test_failing_runs_have_a_filmstrip_and_a_replay_command_each(report: tuple[Path, list[dict[str, Any]]]) -> None:
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
    game = _game(env)
    shown = frames_to_show(game, t.states)
    assert shown[0] == 0 and shown[-1] == len(t.states) - 1 and len(shown) <= MAX_FRAMES
    everything = frames_to_show(game, t.states, limit=10_000)
    moved = [k for k in range(1, len(t.states)) if t.states[k].system != t.states[k - 1].system or t.states[k].agent != t.states[k - 1].agent]
    assert set(moved) <= set(everything)


def test_filmstrip_names_what_the_test_did() -> None:
    """Doors on a reactive test (which door, closed or opened on the floor), the test agent's
    moves on an agent test (where to)."""
    from experiments.evaluation.filmstrip import _events

    for env_id, sut, pattern in (
        ("FlowTest-SmallReactive-v0", "scripted:replanner", r"door \(0, 1\) -> \(0, 2\) opened"),  # once it saw I2
        ("FlowTest-Maze2-v0", "scripted:committed", r"test agent to \(\d, \d\)"),
    ):
        env = gym.make(env_id)
        t = run_episode(env, make_policy(sut, env), env_id, sut, 0)
        assert any(re.search(pattern, ev) for ev in _events(_game(env), t.states, t.actions)), env_id


# --------------------------------------------------------------------------- names, cards, violations

WAREHOUSE = """
name = "{name}"

[system]
grid = \"\"\"
{grid}
\"\"\"
start = "D"
terminal = ["B"]

[labels]
bay = ["B"]
hazard = ["H"]
aisle = ["A"]

[objectives]
system = "F bay & G !hazard"
test = "F aisle"

[environment]
kind = "reactive"
"""

GRIDS = (
    "D . A\n. H .\n. . B",
    "D A .\n. H .\n. . B",
    "D . .\nA H .\n. . B",
    "D . .\n. H A\n. . B",
)


def _problem(path: Path, grid: str, name: str | None = None) -> str:
    """Write a small warehouse problem (``name`` omitted: the file stem names it)."""
    text = WAREHOUSE.format(name=name or "", grid=grid)
    if name is None:
        text = text.replace('name = ""\n', "")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return str(path)


def _section(page: str, start: str, end: str) -> str:
    return page[page.index(start) : page.index(end)]


def _card(page: str, env: str) -> str:
    begin = page.index(f"<div class='test' id='{card_anchor(env)}'>")
    return page[begin : page.index("</details></div>", begin)]


def test_file_key_is_one_to_one_where_a_slug_is_not() -> None:
    """Break 11's pairs get different keys; keys are safe file names and ids and never
    hold ``--`` (the separator of a pair's key)."""
    pairs = [("probs/a.toml", "probs-a.toml"), ("A.toml", "a.toml"), ("x/a.toml", "x/a_toml"), ("scripted:committed", "scripted-committed")]
    for a, b in pairs:
        assert file_key(a) != file_key(b), (a, b)
        assert file_key(a).lower() != file_key(b).lower()  # case-blind file systems too
    for text in ("/very/long/" + "x" * 300 + "/a.toml", "<script>alert(1)</script>", "é€", "--", ""):
        key = file_key(text)
        assert re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", key), key
        assert len(key) <= 51 and key.endswith(hashlib.sha256(text.encode()).hexdigest()[:10])
    assert failures_anchor("a", "b--c") != failures_anchor("a--b", "c")


def test_titles_are_problem_names_and_tell_namesakes_apart(tmp_path: Path) -> None:
    a = str(tmp_path / "x" / "a.toml")
    b = str(tmp_path / "y" / "a.toml")
    titles = titles_of(["FlowTest-Maze2-v0", "example1", a, b, str(tmp_path / "warehouse.json")])
    assert titles["FlowTest-Maze2-v0"] == "Maze2" and titles["example1"] == "example1"
    assert titles[a] == "a (x/a.toml)" and titles[b] == "a (y/a.toml)"
    assert titles[str(tmp_path / "warehouse.json")] == "warehouse"
    named = TestInfo(a, "floor-7", "reactive", "F bay", "F aisle", 10, "p.png")
    assert titles_of([a], [named])[a] == "floor-7"  # the file's name field wins over its stem
    assert not any(str(tmp_path) in t for t in titles.values())


@pytest.fixture(scope="module")
def namesakes(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str], list[dict[str, Any]]]:
    """Break 11's two pairs side by side through the whole report: ``probs/a.toml`` and
    ``probs-a.toml``, ``A.toml`` and ``a.toml`` (four different floors)."""
    root = tmp_path_factory.mktemp("namesakes")
    envs = [
        _problem(root / "probs" / "a.toml", GRIDS[0]),
        _problem(root / "probs-a.toml", GRIDS[1]),
        _problem(root / "A.toml", GRIDS[2]),
        _problem(root / "a.toml", GRIDS[3]),
    ]
    out = root / "report"
    cells = evaluate(envs, ["scripted:replanner", "scripted:greedy"], 1, seed=0)
    records = write_report(cells, out)
    return out, envs, records


def test_namesake_tests_get_their_own_files_anchors_and_pictures(namesakes: tuple[Path, list[str], list[dict[str, Any]]]) -> None:
    out, envs, records = namesakes
    page = (out / "report.html").read_text()
    anchors = [card_anchor(env) for env in envs]
    assert len(set(anchors)) == 4
    pictures = []
    for env, anchor in zip(envs, anchors, strict=True):
        assert page.count(f"id='{anchor}'") == 1 and f"href='#{anchor}'" in page
        card = _card(page, env)
        (src,) = re.findall(r"<img src='([^']+)'", card)
        pictures.append(src)
        # the card's picture is its own test's: the same bytes as that test's artifact drawn afresh
        fresh = out / "fresh.png"
        draw_test_picture(_game(gym.make("FlowTest-v0", test=env)), fresh)
        assert (out / src).read_bytes() == fresh.read_bytes(), env
    assert len(set(pictures)) == 4 and len({p.lower() for p in pictures}) == 4
    # every run picture and failure anchor is one pair's own
    files = [name for r in records for name in r["pictures"].values()]
    assert len(files) == len(set(files)) and len({f.lower() for f in files}) == len(files)
    assert any(r["n_failures"] for r in records) and any(not r["n_failures"] for r in records)
    # scripted:greedy walks into the hazard: results.json names the broken conjunct, the report shows it
    broken = [f["violation"] for r in records for f in r["failures"] if f["verdict"]["system_objective"] == "violated"]
    assert broken and all(v["conjunct"] == "G !hazard" and v["where"] == "(1, 1)" for v in broken)
    assert page.count("class='broke'") == len(broken)
    fail_ids = re.findall(r"<h3 id='(fail-[^']+)'", page)
    assert len(fail_ids) == len(set(fail_ids)) == sum(1 for r in records if r["n_failures"])


def test_columns_and_cards_name_the_problem_never_the_path(namesakes: tuple[Path, list[str], list[dict[str, Any]]]) -> None:
    out, envs, _ = namesakes
    page = (out / "report.html").read_text()
    matrix = _section(page, "class='matrix'", "</table>")
    heads = re.findall(r"<th><a [^>]*>([^<]*)</a></th>", matrix)
    # probs/a.toml and a.toml are both "a": the shortest tails of their paths tell them apart
    assert heads[:3] == ["a (probs/a.toml)", "probs-a", "A"]
    assert heads[3].startswith("a (") and heads[3].endswith("/a.toml)") and heads[3].count("/") == 1
    tests = _section(page, "id='tests'", "id='failures'")
    root = str(Path(envs[0]).parents[1])
    assert root not in matrix and root not in tests
    for env in envs:
        card = _card(page, env)
        (title,) = re.findall(r"<h3[^>]*>([^<]*)</h3>", card)
        assert "/" not in title.split(" (")[0]
        assert card.count(f">{title}<") == 1  # the name once per card


def test_each_card_draws_the_restrictions_per_history_and_names_the_propositions(tmp_path: Path) -> None:
    """A reactive test's card shows one panel per history that closes doors (the panels of
    ``flowtest synthesize --plot``) and a legend of its propositions with their colours."""
    env = _problem(tmp_path / "wh.toml", GRIDS[0], name="warehouse-alpha")
    out = tmp_path / "out"
    (info,) = draw_test_infos([env], out)
    art = _game(gym.make("FlowTest-v0", test=env)).artifact
    assert len(panels_of(artifact_view(art))) >= 1 and any(p.restricted.any() for p in panels_of(artifact_view(art)))
    fresh = tmp_path / "fresh.png"
    draw_test_picture(_game(gym.make("FlowTest-v0", test=env)), fresh)
    assert (out / info.picture).read_bytes() == fresh.read_bytes()
    assert info.problem == "warehouse-alpha"
    legend = {name: (where, colour) for name, where, colour in info.propositions}
    assert legend["hazard"][0] == "cell H" and legend["aisle"][0] == "cell A" and legend["bay"][0] == "cell B"
    assert len({c for _, c in legend.values()}) == 3
    record = passing_record(env)
    page = render_html([record], [info])
    card = _card(page, env)
    assert "one panel per history" in card and f"src='{info.picture}'" in card
    for name, (where, colour) in legend.items():
        assert f"background:{colour}'></span>{name}</td><td>{where}</td>" in card
    # the filmstrips' and trace pictures' legend names the system's propositions by their marks
    game = _game(gym.make("FlowTest-v0", test=env))
    assert "hazard" in [h.get_label() for h in symbol_legend(game)]


def test_the_card_explains_static_and_agent_pictures() -> None:
    for env, words in (("FlowTest-Example1-v0", "Static test"), ("FlowTest-Maze2-v0", "Agent test")):
        record = passing_record(env)
        info = TestInfo(env, "x", "static" if "Example" in env else "agent", "F goal", "F I", 9, "p.png")
        assert words in _card(render_html([record], [info]), env)


def test_the_layout_wraps_at_laptop_width() -> None:
    """The cards are a grid that fills the width with as many 480 px columns as fit (two at
    1366 px) and shrinks to one on a narrow screen; pictures shrink to their card (never
    stretched past their size) and link to themselves at full size; the matrix and the
    number tables scroll inside the page instead of widening it."""
    css = STYLE.replace(" ", "")
    assert ".tests{display:grid;grid-template-columns:repeat(auto-fill,minmax(min(100%,480px),1fr))" in css
    assert ".test{" in css and "min-width:0" in css.split(".test{")[1].split("}")[0]
    assert ".testimg{max-width:100%;height:auto" in css
    assert ".scroll{max-width:100%;overflow-x:auto}" in css
    record = passing_record("/a/very/long/path/" + "x" * 200 + ".toml", sut="cmd:" + "y" * 200)
    page = render_html([record], [])
    assert "<div class='scroll'><table class='matrix'>" in page
    assert "/a/very/long/path" not in _section(page, "class='matrix'", "</table>")


def test_hostile_names_are_escaped_in_titles_and_legends(tmp_path: Path) -> None:
    env = str(tmp_path / "<img src=x onerror=alert(1)>.toml")
    info = TestInfo(env, "<script>alert(1)</script>", "reactive", "F <bad-a>", "F <bad-b>", 5, "tests/x'.png", (("<bad-c>", "<bad-d>", "red' onmouseover='x"),))
    record = {
        "env": env,
        "sut": "<svg onload=alert(2)>",
        "episodes": 1,
        "seed": 0,
        "system_objective_met_rate": 0.0,
        "test_objective_realized_rate": None,
        "violated": 1,
        "open": 0,
        "mean_restrictions": 0.0,
        "mean_steps": 3.0,
        "test_failures": 0,
        "n_failures": 1,
        "pictures": {},
        "failures": [
            {
                "seed": 0,
                "kind": "sut",
                "reason": "violated <bad-e>",
                "verdict": {},
                "replay": "r",
                "violation": {"conjunct": "G !<bad-f>", "step": 1, "where": "(0, <bad-g>)", "alone": True, "text": "broke G !<bad-h>"},
            }
        ],
    }
    record["stopped"] = "the planner <bad-i> failed in run 1 of 2 (seed 0)"
    page = render_html([record], [info])
    assert "stopped early" in page and "Stopped: the planner &lt;bad-i&gt; failed in run 1 of 2 (seed 0)." in page
    for raw in ("<script>", "<img src=x", "<svg", "<bad-", "onmouseover='x", "tests/x'.png"):
        assert raw not in page, raw
    assert html_lib.escape("<script>alert(1)</script>") in page
    assert "background:red" not in page  # a colour that is not #rrggbb is left out


def test_written_conjuncts_keep_the_users_words() -> None:
    assert written_conjuncts("F bay & G !hazard") == {"F bay": "F bay", "G(!hazard)": "G !hazard"}
    assert written_conjuncts("F (a & F b) &  G (a -> F b)")["G(a -> F b)"] == "G (a -> F b)"


def _run_through(env_id: str, cells: list[tuple[int, int]]) -> list[int]:
    """The system states of a grid run through ``cells`` (one step each)."""
    ts = _game(gym.make("FlowTest-v0", test=env_id)).artifact.system
    return [ts.places.index(c) for c in cells]


def test_a_violation_names_the_conjunct_the_step_and_the_cell(tmp_path: Path) -> None:
    env = _problem(tmp_path / "floor.toml", "D . A\n. H .\n. . B", name="floor")
    art = _game(gym.make("FlowTest-v0", test=env)).artifact
    v = violation_of(art, _run_through(env, [(0, 0), (0, 1), (1, 1)]))
    assert v is not None and (v.conjunct, v.step, v.where, v.kind) == ("G !hazard", 2, "(1, 1)", "safety")
    assert v.text() == "broke G !hazard at step 2 in cell (1, 1)"
    # a visit made impossible: refueling's random run 0 spends the fuel it needs to reach the goal
    renv = gym.make("FlowTest-Refueling-v0")
    t = run_episode(renv, make_policy("random", renv), "FlowTest-Refueling-v0", "random", 0)
    assert t.verdict["system_objective"] == "violated"
    found = violation_of_trace(t)
    assert found is not None and found["conjunct"] == "F goal" and found["where"].endswith(f"with fuel {8}")
    assert found["step"] <= t.verdict["steps"] and "can no longer be met" in found["text"]
    # a run that did not violate anything has no violation
    ok = run_episode(renv, make_policy("scripted:replanner", renv), "FlowTest-Refueling-v0", "scripted:replanner", 0)
    assert violation_of_trace(ok) is None


def test_the_card_and_the_filmstrip_name_the_broken_conjunct(tmp_path: Path) -> None:
    env = _problem(tmp_path / "floor.toml", "D . A\n. H .\n. . B", name="floor")
    genv = gym.make("FlowTest-v0", test=env)
    policy = make_policy("random", genv)
    trace = next(t for t in (run_episode(genv, policy, env, "random", seed) for seed in range(40)) if t.verdict["system_objective"] == "violated")
    v = violation_of_trace(trace)
    assert v is not None and v["conjunct"] == "G !hazard" and v["where"] == "(1, 1)"
    cell = Cell(env, "random", [trace], trace.seed, 0.1)
    record = cell.record()
    record["failures"][0].setdefault("violation", v)  # evaluate.py records it (violation_of_trace)
    page = render_html([record], [])
    broke = re.findall(r"<p class='broke'>(.*?)</p>", page)
    assert broke == [f"Seed {trace.seed} broke <code>G !hazard</code> of the system objective at step {v['step']}, in cell (1, 1)."]
    assert f"broke G !hazard at step {v['step']} in cell (1, 1)" in page
    # the filmstrip keeps the frame of the violation however long the run
    game = _game(genv)
    assert v["step"] in frames_to_show(game, trace.states, limit=3, keep_step=v["step"])


MIXED = Path(__file__).resolve().parents[1] / "data" / "ok_mixed.toml"


def test_a_mixed_card_draws_the_static_area_typed_in(tmp_path: Path) -> None:
    """A mixed test's card picture draws its static area (dashed borders, a legend line), as
    ``flowtest synthesize --plot`` does: the artifact carries the area, so the report's panels
    read it; without it (an older file) the picture differs. The caption says what the dashes are."""
    import dataclasses

    from experiments.plots import _static_area, plot_artifact, plot_test

    out = tmp_path / "out"
    (info,) = draw_test_infos([str(MIXED)], out)
    art = _game(gym.make("FlowTest-v0", test=str(MIXED))).artifact
    assert info.kind == "mixed" and art.static_area is not None and int(art.static_area.sum()) == 6
    view = artifact_view(art)
    assert len(_static_area(view)) == 5  # ok_mixed.toml types six moves: five borders, one both ways
    svg = plot_artifact(art, tmp_path / "card.svg", header=False).read_text()
    assert "static area (walls only here)" in svg
    without = dataclasses.replace(view, problem=dataclasses.replace(view.problem, static_moves=None))
    assert _static_area(without) == set()
    assert "static area (walls only here)" not in plot_test(without, tmp_path / "old.svg", header=False).read_text()
    fresh = tmp_path / "fresh.png"
    draw_test_picture(_game(gym.make("FlowTest-v0", test=str(MIXED))), fresh)
    assert (out / info.picture).read_bytes() == fresh.read_bytes()
    record = passing_record(str(MIXED))
    assert "static area the problem gives them (its borders dashed)" in _card(render_html([record], [info]), str(MIXED))
