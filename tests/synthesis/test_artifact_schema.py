"""The artifact's JSON Schema: docs/artifact-schema.json is what ``json_schema()`` generates,
it is a valid draft 2020-12 schema, every shipped artifact (and freshly synthesized mixed and
reactive tests) validates, it refuses what FlowTest's own loader refuses on shape, and
docs/artifact-schema.md explains every field it names."""

from __future__ import annotations

import copy
import json
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

jsonschema = pytest.importorskip("jsonschema")

from flowtest_env.artifacts import ARTIFACT_DIR  # noqa: E402
from synthesis.artifacts.artifact import FORMAT, VERSION  # noqa: E402
from synthesis.artifacts.schema import SCHEMA_VERSION, json_schema, validate_artifact  # noqa: E402
from synthesis.model.errors import ProblemError  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_FILE = ROOT / "docs" / "artifact-schema.json"
PAGE = ROOT / "docs" / "artifact-schema.md"
SHIPPED = sorted(ARTIFACT_DIR.glob("*.json"))


def validator() -> Any:
    return jsonschema.Draft202012Validator(json.loads(SCHEMA_FILE.read_text()))


def test_the_schema_file_is_the_generated_schema() -> None:
    assert json.loads(SCHEMA_FILE.read_text()) == json_schema(), (
        "docs/artifact-schema.json is out of date: python -m synthesis.artifacts.schema > docs/artifact-schema.json"
    )
    jsonschema.Draft202012Validator.check_schema(json_schema())
    assert SCHEMA_VERSION == VERSION and json_schema()["properties"]["format"] == {"const": FORMAT}


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_artifact_validates(path: Path) -> None:
    doc = json.loads(path.read_text())
    errors = [f"{e.json_path}: {e.message[:200]}" for e in validator().iter_errors(doc)]
    assert not errors, errors


def test_every_kind_is_shipped_or_synthesized_and_validates() -> None:
    import flowtest_env
    from synthesis.problems.files import load_problem_file

    kinds = {json.loads(p.read_text())["kind"] for p in SHIPPED}
    env: Any = flowtest_env.make_env(load_problem_file(ROOT / "tests" / "data" / "ok_mixed.toml")).unwrapped
    mixed = env.artifact
    doc = json.loads(json.dumps(mixed.to_dict()))
    assert not list(validator().iter_errors(doc))
    assert kinds | {doc["kind"]} == {"static", "reactive", "mixed", "agent"}


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(doc: dict[str, Any]) -> None:
        *keys, last = path.split(".")
        target: Any = doc
        for k in keys:
            target = target[int(k)] if isinstance(target, list) else target[k]
        if value is _DELETE:
            del target[last]
        elif isinstance(target, list):
            target[int(last)] = value
        else:
            target[last] = value

    return edit


_DELETE = object()

BROKEN: dict[str, tuple[str, Callable[[dict[str, Any]], None]]] = {
    "kind": ("small-reactive", _set("kind", "sometimes")),
    "version": ("small-reactive", _set("version", 2)),
    "empty name": ("small-reactive", _set("name", "")),
    "no source": ("small-reactive", _set("source", _DELETE)),
    "bad source": ("small-reactive", _set("source.sha256", "xyz")),
    "stay not a bit": ("small-reactive", _set("system.stay.0", 2)),
    "system kind": ("small-reactive", _set("system.kind", "hexagons")),
    "grid state": ("small-reactive", _set("system.states.0", "S")),
    "fuel state": ("refueling", _set("system.states.0", [1, 2])),
    "graph state": ("beaver-rescue", _set("system.states.0", [0, 1])),
    "negative move": ("small-reactive", _set("system.moves.0", [0, -1])),
    "setting": ("small-reactive", _set("strategy.setting", "sometimes")),
    "history key": ("small-reactive", _set("strategy.restrictions", {"01": [0]})),
    "no agent in an agent test": ("maze2", _set("agent", None)),
    "an agent in a reactive test": ("small-reactive", lambda d: d.update(agent=copy.deepcopy(_doc("maze2")["agent"]))),
    "controller first": ("maze2", _set("agent.controller.first", "nobody")),
    "flow 0": ("small-reactive", _set("summary.flow", 0)),
    "histories without components": ("small-reactive", _set("automata.histories.components", None)),
    "accepting not a bit": ("small-reactive", _set("automata.test.accepting.0.0", True)),
    "a static area in a reactive test": ("small-reactive", _set("extras.static_moves", [0, 1])),
    "a static area in a static test": ("example1", _set("extras.static_moves", [0])),
    "a grid move named NE": ("maze2", _set("system.action.0", "NE")),
    "a fuel grid move named NE": ("refueling", _set("system.action.0", "NE")),
    "a grid move given as a number": ("small-reactive", _set("system.action.0", 0)),
}


def _doc(name: str) -> dict[str, Any]:
    return dict(json.loads((ARTIFACT_DIR / f"{name}.json").read_text()))


@pytest.mark.parametrize("case", list(BROKEN))
def test_the_schema_refuses_what_the_loader_refuses(case: str) -> None:
    name, edit = BROKEN[case]
    doc = _doc(name)
    edit(doc)
    assert list(validator().iter_errors(doc)), f"the schema accepts a broken artifact ({case})"
    with pytest.raises(ProblemError):
        validate_artifact(doc, f"{name}.json", FORMAT, VERSION)


def test_the_schema_is_valid_draft_2020_12_and_refuses_a_grid_move_named_ne() -> None:
    """Draft202012Validator's own check of the file, every shipped artifact valid under it, and the
    moves of a grid held to its move names: "NE" on maze2 fails (at ``system.action``), while a
    graph's moves keep any name (beaver-rescue's first move renamed "NE" still validates)."""
    schema = json.loads(SCHEMA_FILE.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    check = jsonschema.Draft202012Validator(schema)
    for path in SHIPPED:
        assert not list(check.iter_errors(json.loads(path.read_text()))), path.name
    grid = _doc("maze2")
    grid["system"]["action"][3] = "NE"
    errors = list(check.iter_errors(grid))
    assert errors and any(list(e.absolute_path)[:3] == ["system", "action", 3] for e in errors), errors
    graph = _doc("beaver-rescue")
    graph["system"]["action"][0] = "NE"
    assert not list(check.iter_errors(graph))
    validate_artifact(graph, "beaver-rescue.json", FORMAT, VERSION)


def _doc_blocks() -> list[str]:
    """The shell blocks of docs/artifact-schema.md."""
    return re.findall(r"```bash\n(.*?)```", PAGE.read_text(), flags=re.S)


def test_the_pages_validation_command_works_after_the_first_install(tmp_path: Path) -> None:
    """The page's jsonschema command installs what the core lacks (its block starts with ``pip
    install jsonschema``: the README's first install, ``pip install -e .``, has no validator), then
    writes the schema with the core and validates: a shipped artifact passes (nothing printed), a
    grid move named "NE" fails (exit 1, the error named)."""
    import shlex
    import subprocess
    import sys

    block = next(b for b in _doc_blocks() if "jsonschema" in b)
    lines = [line for line in block.splitlines() if line.strip()]
    assert lines[0].startswith("pip install") and "jsonschema" in lines[0], lines[0]
    steps = [shlex.split(line) for line in lines[1:]]
    assert [step[:1] for step in steps] == [["python"], ["python"]], steps
    (tmp_path / "test.json").write_text(json.dumps(_doc("maze2")))
    schema_step, check_step = steps
    assert schema_step[-2:] == [">", "artifact-schema.json"], schema_step
    out = subprocess.run([sys.executable, *schema_step[1:-2]], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    (tmp_path / "artifact-schema.json").write_text(out.stdout)
    assert json.loads(out.stdout) == json_schema()
    ok = subprocess.run([sys.executable, *check_step[1:]], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert (ok.returncode, ok.stdout, ok.stderr) == (0, "", "")
    bad = _doc("maze2")
    bad["system"]["action"][0] = "NE"
    (tmp_path / "test.json").write_text(json.dumps(bad))
    refused = subprocess.run([sys.executable, *check_step[1:]], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert refused.returncode == 1 and "'NE' is not one of" in refused.stderr, refused.stderr[-2000:]


def test_the_schema_refuses_an_unknown_field_and_a_malformed_digest() -> None:
    for edit in (_set("colour", "red"), _set("digest", {"sha256": "0" * 64, "md5": ""}), _set("system.wormholes", [])):
        doc = _doc("maze1")
        edit(doc)
        assert list(validator().iter_errors(doc))


def _field_names(node: Any) -> Iterator[str]:
    if isinstance(node, dict):
        for key, value in node.get("properties", {}).items():
            yield key
            yield from _field_names(value)
        for key, value in node.items():
            if key != "properties":
                yield from _field_names(value)
    elif isinstance(node, list):
        for item in node:
            yield from _field_names(item)


def test_the_page_explains_every_field() -> None:
    page = PAGE.read_text()
    named = set(re.findall(r"`([a-z_0-9]+)`", page))
    missing = sorted(set(_field_names(json_schema())) - named)
    assert not missing, f"docs/artifact-schema.md does not explain: {missing}"


def _mixed_doc() -> dict[str, Any]:
    """A freshly synthesized mixed test (tests/data/ok_mixed.toml) as plain data."""
    import flowtest_env
    from synthesis.problems.files import load_problem_file

    env: Any = flowtest_env.make_env(load_problem_file(ROOT / "tests" / "data" / "ok_mixed.toml")).unwrapped
    return dict(json.loads(json.dumps(env.artifact.to_dict())))


def test_a_mixed_test_carries_its_static_area_and_older_files_still_load() -> None:
    """The static area typed in (six moves of ok_mixed.toml) is ``extras.static_moves``, read
    back as ``TestArtifact.static_area``; its walls lie in it. A file without it (written
    before FlowTest carried it) loads, with no area."""
    import warnings

    import numpy as np

    from synthesis.artifacts.artifact import EditedArtifactWarning, TestArtifact, with_digest
    from synthesis.problems.files import load_problem_file

    doc = _mixed_doc()
    problem = load_problem_file(ROOT / "tests" / "data" / "ok_mixed.toml")
    assert problem.static_moves is not None
    want = np.flatnonzero(problem.static_moves).tolist()
    assert doc["extras"]["static_moves"] == want and len(want) == 6
    art = TestArtifact.from_dict(doc, require_digest=True)
    assert art.static_area is not None and np.flatnonzero(art.static_area).tolist() == want
    assert not (art.strategy.static_obstacles & ~art.static_area).any()
    older = copy.deepcopy(doc)
    del older["extras"]["static_moves"]
    assert not list(validator().iter_errors(older))
    assert TestArtifact.from_dict(with_digest(older), require_digest=True).static_area is None
    for key, value in (("shipped", _doc("small-reactive")), ("maze2", _doc("maze2"))):
        assert TestArtifact.from_dict(value, verify=False).static_area is None, key
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EditedArtifactWarning)
        assert TestArtifact.from_dict(older).static_area is None


def test_a_malformed_static_area_is_refused() -> None:
    """Negative or repeated move indices: refused by the schema and the loader; an index past
    the moves or out of order (what a JSON Schema cannot say): by the loader; a wall outside
    the area: by the loader's check of meaning (naming the field)."""
    from synthesis.artifacts.artifact import TestArtifact, with_digest

    doc = _mixed_doc()
    m = len(doc["system"]["moves"])
    area = doc["extras"]["static_moves"]
    for bad in ([m], [-1], [area[0], area[0]]):
        broken = copy.deepcopy(doc)
        broken["extras"]["static_moves"] = bad
        assert bool(list(validator().iter_errors(broken))) == (bad != [m]), bad
        with pytest.raises(ProblemError, match="extras.static_moves"):
            validate_artifact(broken, "mixed.json", FORMAT, VERSION)
    unsorted = copy.deepcopy(doc)
    unsorted["extras"]["static_moves"] = list(reversed(area))
    with pytest.raises(ProblemError, match="increasing order"):
        validate_artifact(unsorted, "mixed.json", FORMAT, VERSION)
    walls = doc["strategy"]["static_obstacles"]
    assert walls, "ok_mixed's test puts a wall in its static area"
    narrowed = copy.deepcopy(doc)
    narrowed["extras"]["static_moves"] = [i for i in area if i != walls[0]]
    with pytest.raises(ProblemError, match="outside the static area"):
        TestArtifact.from_dict(with_digest(narrowed), require_digest=True)
