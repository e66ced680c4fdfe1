"""One game for every planner (issue 42): a planner from outside FlowTest gets what the
built-in systems get (the map with its static walls apart, the system objective's
automaton, each step's restricted moves with their cause), so a correct outside planner
written from docs/runtime.md alone plays exactly as ``scripted:replanner``: the same
actions, steps and restrictions, run for run, on static, reactive, mixed and agent tests.
The planners are docs/runtime.md's, as written there: one in Python (``python:`` and
``cmd:``), one in JavaScript (``cmd:node``)."""

from __future__ import annotations

import re
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "runtime.md"

TESTS = {
    "static": "example1",
    "static fuel": "refueling",
    "reactive": "small-reactive",
    "reactive graph": "beaver-rescue",
    "mixed": str(ROOT / "tests" / "data" / "ok_mixed.toml"),
    "agent": "maze2",
}
"""A test of each kind (and a fuel grid, and a graph)."""


def doc_files() -> dict[str, str]:
    """The example planners of docs/runtime.md, as written there."""
    return dict(re.findall(r"<!-- file: (\S+) -->\n```\w+\n(.*?)```", DOC.read_text(), re.S))


@pytest.fixture
def planners(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    for name, body in doc_files().items():
        (tmp_path / name).write_text(body)
    monkeypatch.chdir(tmp_path)
    path = list(sys.path)
    yield tmp_path
    sys.path[:] = path
    for name, module in list(sys.modules.items()):
        if str(getattr(module, "__file__", None) or "").startswith(str(tmp_path)):
            del sys.modules[name]


def runs(cell: Any) -> list[tuple[int, list[int], dict[str, Any]]]:
    """Every run of a (system, test) pair: its seed, its actions and its verdict."""
    assert cell.error is None and cell.stopped is None, (cell.sut, cell.error, cell.stopped)
    return [(t.seed, list(t.actions), t.verdict) for t in cell.traces]


def outside_planners() -> list[str]:
    return ["python:bfs_planner:BfsPlanner", "cmd:python3 bfs_planner.py", "cmd:node replanner.js"]


@pytest.mark.parametrize("kind", list(TESTS))
def test_an_outside_planner_plays_exactly_as_scripted_replanner(planners: Path, kind: str) -> None:
    if shutil.which("node") is None:
        pytest.skip("node (Node.js) is not installed: the JavaScript planner cannot run here")
    from experiments.evaluation import evaluate

    suts = ["scripted:replanner", *outside_planners()]
    cells = evaluate([TESTS[kind]], suts, 4, seed=11, step_timeout=30)
    reference = runs(cells[0])
    assert any(v["restrictions"] for _, _, v in reference) or kind.startswith("static"), "the test restricts something"
    for cell in cells[1:]:
        assert runs(cell) == reference, cell.sut
    if kind.startswith("static"):  # the walls are on the map: no move into one is ever tried
        assert all(v["blocked_attempts"] == 0 for _, _, v in reference)


CHECKER = '''
def key(state):
    return tuple(key(x) for x in state) if isinstance(state, list) else state

class Checker:
    """Checks each step message against the hello; answers the first allowed action."""
    def __init__(self, test):
        system = test["system"]
        self.index = {key(s): i for i, s in enumerate(system["states"])}
        self.moves = {tuple(m) for m in system["moves"]}
        self.walls = {tuple(m) for m in system["walls"]}
        assert self.walls and not self.walls & self.moves, "walls apart from the moves"
        assert len(system["action"]) == len(system["moves"])

    def act(self, observation, mask):
        here = self.index[key(observation["state"])]
        out = {t for s, t in self.moves | self.walls if s == here}
        allowed = {self.index[key(t)] for a, t in zip(observation["allowed"], observation["to"]) if a != "stay"}
        refused = {self.index[key(r["to"])]: r["by"] for r in observation["restricted"]}
        assert allowed | set(refused) == out and not allowed & set(refused), (here, allowed, refused, out)
        for t, by in refused.items():
            assert (by == "wall") == ((here, t) in self.walls), (here, t, by)
            assert by in ("wall", "door", "agent")
        assert observation["mask"] == list(mask)
        return observation["allowed"][0]
'''


@pytest.mark.parametrize("test", ["example1", str(ROOT / "tests" / "data" / "ok_mixed.toml")])
def test_each_step_says_what_is_restricted_and_why(planners: Path, test: str) -> None:
    """A step's ``restricted`` and ``allowed`` cover every move out of the state, once; a
    move is ``wall`` exactly when the hello lists it among the walls."""
    from experiments.evaluation import evaluate

    (planners / "checker.py").write_text(CHECKER)
    (cell,) = evaluate([test], ["python:checker:Checker"], 3, step_timeout=30)
    assert cell.stopped is None, cell.stopped
    assert sum(len(t.actions) for t in cell.traces) > 3


def test_the_hello_has_version_2() -> None:
    from agents.base import game_of
    from agents.planner_protocol import Messages
    from experiments.evaluation.episodes import env_named as make_env

    hello = Messages(make_env("example1")).hello()
    assert (hello["protocol"], hello["version"]) == ("flowtest-planner", 2)
    assert {"walls", "moves"} <= set(hello["test"]["system"]) and "automaton" in hello["test"]
    assert "test" not in hello["test"]["objective"] and game_of(make_env("example1")).artifact.objectives["test"] not in str(hello)
