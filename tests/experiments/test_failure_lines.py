"""A failure explained in one line (issue 42 item 2): for every failing run the report and
``results.json`` say what happened in the floor's terms. An open run: the loop it ended in
(from which step, between which cells) and what the test did with each move toward the goal
out of it (refused on every visit, and by what: a door under a history, the test agent; or
allowed and never taken); a violation: the conjunct, the step and the cell; runs that
failed the same way folded into one line with their seeds and one replay command."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import pytest

from agents.registry import make_policy
from experiments.evaluation import evaluate, write_report
from experiments.evaluation.episodes import run_episode
from experiments.evaluation.explain import explain, find_loop, fold, seed_words

HERE = Path(__file__).resolve().parent
FORGETFUL = f"python:{HERE / 'forgetful_planner.py'}:Forgetful"
"""A planner that forgets a door seen closed once it is out of view (tests/experiments/forgetful_planner.py)."""


@pytest.fixture(scope="module")
def forgetful_report(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, Any]], list[Any]]:
    out = tmp_path_factory.mktemp("forgetful")
    cells = evaluate(["small-reactive"], [FORGETFUL, "scripted:replanner"], 5, seed=0)
    return out, write_report(cells, out), cells


def test_a_planner_that_forgets_a_door_is_told_where_it_loops_and_which_door_refused_it(
    forgetful_report: tuple[Path, list[dict[str, Any]], list[Any]],
) -> None:
    out, records, cells = forgetful_report
    bad = records[0]
    assert bad["n_failures"] == 5 and records[1]["n_failures"] == 0
    # what the runs did, read from the runs themselves: the two cells of the loop's end
    trace = cells[0].traces[0]
    game = trace.game
    tail = {game.cells[game.place_list[r.system]] for r in trace.states[-10:]}
    assert tail == {(1, 1), (1, 2)}
    door = game.restricted_bits_of(trace.states[-1])  # the door in front of (1, 2) or (1, 1), closed at the end
    assert door, "the run ends in front of a closed door"
    line = (
        "from step 2 on, alternates between (1, 1) and (1, 2) until the step budget ran out; "
        "the move (1, 1) -> (0, 1) was refused on every visit: door closed under history q3; "
        "the move (1, 2) -> (0, 2) was refused on every visit: door closed under history q3"
    )
    (way,) = bad["outcomes"]  # five runs, one way of failing: one line
    assert way["seeds"] == [0, 1, 2, 3, 4] and way["text"] == line and way["line"] == f"seeds 0-4 (5 runs): {line}"
    assert way["replay"].endswith("--seed 0 --replay")
    for f in bad["failures"]:
        e = f["explanation"]
        assert e["what"] == "loop" and e["text"] == line and e["loop"]["cells"] == ["(1, 1)", "(1, 2)"]
        assert e["loop"]["period"] == 2 and e["loop"]["from_step"] == 2
        assert [(m["from"], m["to"], m["refused"] == m["visits"], m["causes"]) for m in e["moves"]] == [
            ("(1, 1)", "(0, 1)", True, ["door closed under history q3"]),
            ("(1, 2)", "(0, 2)", True, ["door closed under history q3"]),
        ]
    # the same line in results.json, report.md and report.html, once each, with one replay command
    saved = json.loads((out / "results.json").read_text())
    assert saved[0]["outcomes"][0]["line"] == way["line"]
    md = (out / "report.md").read_text()
    assert md.count(line) == 1 and f"- seeds 0-4 (5 runs): {line}" in md
    page = (out / "report.html").read_text()
    outcomes = re.findall(r"<ul class='outcomes'>(.*?)</ul>", page, re.S)
    assert len(outcomes) == 1 and outcomes[0].count("<li>") == 1
    assert "<b>seeds 0-4 (5 runs)</b>: " + html.escape(line) in outcomes[0] and outcomes[0].count("<code>") == 1
    assert "within the step budget of 50 steps" in bad["failures"][0]["reason"]


def test_a_door_and_the_test_agent_are_named_as_the_cause() -> None:
    for env_id, cause in (("small-reactive", "door closed under history q"), ("maze2", "the test agent stood in the way")):
        cells = evaluate([env_id], ["scripted:committed"], 1, seed=0)
        (way,) = cells[0].record()["outcomes"]
        assert way["what"] == "loop" and "stays in (0, 1)" in way["text"] and f"was refused on every visit: {cause}" in way["text"]


def test_a_move_toward_the_goal_allowed_and_never_taken_is_named() -> None:
    """The run of a planner that forgets what it saw, by hand on small-reactive: north, east
    to the door (0, 1) -> (0, 2), then south and north to the end of the budget, while the
    way round the door, (1, 1) -> (1, 2), stays open."""
    from experiments.evaluation import Trace

    env: Any = gym.make("FlowTest-SmallReactive-v0")
    game = env.unwrapped.game
    run = game.reset()
    states = [run.copy()]
    moves = [0, 2] + [1, 0] * 24  # N, E, then S, N, ... (GRID_ACTIONS: N, S, E, W)
    for a in moves:
        game.step(run, a)
        states.append(run.copy())
    assert not run.done
    trace = Trace("small-reactive", "by hand", 0, states, moves, game.verdict(run), kind="sut", reason="open", game=game)
    e = explain(trace)
    assert e.what == "loop" and e.cells == ("(0, 1)", "(1, 1)") and e.step == 2
    assert "the move (1, 1) -> (1, 2) toward the goal was allowed on every visit and never taken" in e.text
    assert "the move (0, 1) -> (0, 2) was refused on every visit: door closed under history q1" in e.text


def test_find_loop_reads_the_end_of_a_run() -> None:
    assert find_loop([5, 6, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7]) is not None
    loop = find_loop([5, 6, 7, 7, 7, 7, 7, 7, 7, 7, 7, 7])
    assert loop is not None and (loop.start, loop.period, loop.states) == (2, 1, (7,))
    loop = find_loop([0, 1, 2, 3, 1, 2, 3, 1, 2, 3, 1, 2, 3, 1])
    assert loop is not None and (loop.start, loop.period, loop.states) == (1, 3, (1, 2, 3))
    assert find_loop([0, 1, 2, 3, 4, 5, 6, 6, 6]) is None  # three steps alike at the end: no loop yet
    # the run repeats only once the test, too, repeats (its history changed at step 4)
    systems = [0, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2, 1, 2]
    keys = [(s, 0 if i < 4 else 1) for i, s in enumerate(systems)]
    loop = find_loop(systems, keys)
    assert loop is not None and (loop.start, loop.period) == (4, 2)


def test_a_loop_is_told_as_it_is_walked() -> None:
    from experiments.evaluation.explain import _loop_words

    assert _loop_words(["(0, 1)"]) == "stays in (0, 1)"
    assert _loop_words(["(0, 1)", "(1, 1)"]) == "alternates between (0, 1) and (1, 1)"
    assert _loop_words(["a", "b", "c"], "states") == "goes round a -> b -> c -> a (every 3 steps)"
    assert _loop_words([str(i) for i in range(10)], "states") == "goes round 10 states, every 10 steps"


def test_runs_alike_are_folded_with_their_seeds_and_steps() -> None:
    assert seed_words([3]) == "seed 3" and seed_words([0, 1, 2, 3]) == "seeds 0-3 (4 runs)"
    assert seed_words([0, 1, 5, 7, 8, 9]) == "seeds 0, 1, 5, 7-9 (6 runs)"
    env = gym.make("FlowTest-Refueling-v0")
    policy = make_policy("random", env)
    traces = [run_episode(env, policy, "refueling", "random", seed) for seed in range(12)]
    failing = [t for t in traces if t.failed]
    explained = [explain(t) for t in failing]
    assert all(e.what in ("violation", "loop", "wander") for e in explained)
    ways = fold([(t.seed, t.kind, e) for t, e in zip(failing, explained, strict=True)])
    assert sum(len(w.seeds) for w in ways) == len(failing) and len(ways) < len(failing)
    for w in ways:
        assert w.line().startswith(seed_words(w.seeds))
        if len(w.seeds) > 1 and w.what == "violation":
            assert re.search(r"at steps? \d+(-\d+)? ", w.text), w.text
    violated = [e for e in explained if e.what == "violation"]
    assert violated and all("broke F goal at step" in e.text for e in violated)


def test_a_run_that_never_loops_says_how_near_it_came() -> None:
    env = gym.make("FlowTest-Maze2-v0")
    policy = make_policy("random", env)
    t = run_episode(env, policy, "maze2", "random", 0)
    assert t.verdict["system_objective"] == "open"
    e = explain(t)
    assert e.what == "wander" and e.text.startswith("never settled into a loop before the step budget ran out: went through ")
    assert re.search(r"\d+ moves? from meeting the system objective past the walls \(nearest: \d+ moves?, at step \d+ in \(\d, \d\)\)", e.text)
