"""The reference reader refuses an index out of range instead of playing it (issue 43): a
negative one, which Python reads from the end of a list (a port in C would read memory), a
too large one, or an action outside the action space, as the environments do."""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from typing import Any

import pytest

from flowtest_env.artifacts import artifact_path
from tests.docs.test_reference_reader import READER, load_reader

EDITS: dict[str, tuple[str, Callable[[dict[str, Any]], None]]] = {
    "initial state -1": ("small-reactive", lambda d: d["system"].__setitem__("initial", -1)),
    "a move into state -1": ("small-reactive", lambda d: d["system"]["moves"][0].__setitem__(1, -1)),
    "a move from state n": ("small-reactive", lambda d: d["system"]["moves"][0].__setitem__(0, len(d["system"]["states"]))),
    "a history -1 in delta": ("small-reactive", lambda d: d["automata"]["histories"]["delta"][0].__setitem__(0, -1)),
    "initial history -1": ("small-reactive", lambda d: d["automata"]["histories"].__setitem__("initial", -1)),
    "a wall on move -1": ("example1", lambda d: d["strategy"]["static_obstacles"].append(-1)),
    "a restriction of history -1": ("small-reactive", lambda d: d["strategy"]["restrictions"].__setitem__("-1", [0])),
    "a door on move -2": ("small-reactive", lambda d: next(iter(d["strategy"]["restrictions"].values())).append(-2)),
    "an agent's next state -1": ("maze2", lambda d: d["agent"]["controller"]["table"]["next_agent"].__setitem__(0, -1)),
    "an agent's fallback -1": ("maze2", lambda d: d["agent"]["controller"]["fallback"][0].__setitem__(0, -1)),
    "an agent's first state -1": ("maze2", lambda d: d["agent"]["controller"].__setitem__("initial_agent", -1)),
    "one stay flag short": ("small-reactive", lambda d: d["system"]["stay"].pop()),
}


@pytest.mark.parametrize("case", list(EDITS))
def test_an_index_out_of_range_in_the_artifact_is_refused(case: str) -> None:
    reader = load_reader()
    name, edit = EDITS[case]
    doc = json.loads(artifact_path(name).read_text())
    reader.Test(copy.deepcopy(doc))  # the artifact as shipped plays
    edit(doc)
    with pytest.raises(ValueError, match=r"not an index in 0\.\.|entries, expected|rows, expected"):
        reader.Test(doc)


@pytest.mark.parametrize("action", [-1, -5, 5, 99, True, 2.0])
def test_an_action_outside_the_action_space_is_refused(action: Any) -> None:
    reader = load_reader()
    test = reader.Test(json.loads(artifact_path("small-reactive").read_text()))
    run = test.reset()
    with pytest.raises(ValueError, match="action"):
        test.step(run, action)
    assert run.steps == 0 and run.blocked_attempts == 0


def test_the_readme_says_to_validate_against_the_schema_first() -> None:
    readme = (READER.parent / "README.md").read_text()
    assert "artifact-schema.json" in readme and "validate" in readme.lower()
