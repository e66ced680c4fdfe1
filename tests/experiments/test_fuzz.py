"""The reliability contract under property-based fuzzing (issue 13, point 7).

Hypothesis generates hostile but fair input: structured mutations of problem files (a
value anywhere replaced by a value of any type, a key deleted, renamed or added) and of
test artifacts, byte-level mutations of both files, and action sequences mixing valid and
invalid actions. The contract asserted:

* the problem loader and the artifact loader either succeed or raise ``ProblemError``
  (never ``KeyError``, ``IndexError``, ``TypeError``, ``RecursionError``...);
* ``flowtest synthesize`` exits with 0, 2, 3 or 5, prints exactly one ``error:`` line when
  it fails, never a traceback, and touches no file (``--json`` writes none);
* an accepted artifact passed every check (so an edit that survives is harmless);
* environments never accept an invalid action: it raises ``InvalidAction`` and leaves
  the run as it was; valid actions always play.

Everything is derandomized (the same examples on every run and machine). The default run
takes well under a minute; ``pytest -m slow tests/experiments/test_fuzz.py`` runs ten times more.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json
import os
import tempfile
import tomllib
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import flowtest_env  # noqa: F401  (registers the envs)
from experiments.cli.cli import main
from synthesis.artifacts.artifact import TestArtifact
from synthesis.model.errors import ProblemError
from synthesis.problems.files import problem_from_dict

DATA = Path(__file__).resolve().parents[1] / "data"
ARTIFACTS = Path(flowtest_env.__file__).parent / "artifacts"

GRID_TOML = (DATA / "ok_grid.toml").read_text()
GRAPH_TOML = (DATA / "ok_graph.toml").read_text()
BASES = [tomllib.loads(GRID_TOML), tomllib.loads(GRAPH_TOML)]
ARTIFACT_BASES = {name: json.loads((ARTIFACTS / f"{name}.json").read_text()) for name in ("small-reactive", "maze2")}

#: Words a hostile user would try where names go.
WORDS = [
    "true",
    "false",
    "F",
    "G",
    "X",
    "U",
    "S",
    "T",
    "goal",
    ".",
    "#",
    "",
    " ",
    "a b",
    "1x",
    "I1",
    "->",
    "F goal",
    "grid",
    "static",
    "reactive",
    "agent",
    "mixed",
    "instantaneous",
    "\x00",
    "é",
    "../x",
    "nan",
]

SCALARS = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**64), max_value=2**64),
    st.sampled_from([0, 1, 2, -1, 3]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(WORDS),
    st.text(max_size=8),
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(WORDS), inner, max_size=3)),
    max_leaves=8,
)

FAST = settings(max_examples=60, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck))
SLOW = settings(max_examples=600, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck))


def mutate(doc: Any, data: st.DataObject, rounds: int = 3) -> Any:
    """A copy of ``doc`` with up to ``rounds`` random edits somewhere in its tree."""
    doc = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, rounds), label="rounds")):
        parent: Any = None
        key: Any = None
        node = doc
        while isinstance(node, (dict, list)) and node and data.draw(st.booleans(), label="descend"):
            keys = list(node) if isinstance(node, dict) else list(range(len(node)))
            parent, key = node, data.draw(st.sampled_from(keys), label="key")
            node = node[key]
        op = data.draw(st.sampled_from(["replace", "delete", "add", "rename"]), label="op")
        if parent is None:
            if isinstance(doc, dict) and op == "add":
                doc[data.draw(st.sampled_from(WORDS + ["system", "labels", "objectives"]))] = data.draw(VALUES)
            continue
        if op == "replace":
            parent[key] = data.draw(VALUES, label="value")
        elif op == "delete":
            del parent[key]
        elif op == "add" and isinstance(parent, list):
            parent.insert(key, data.draw(VALUES, label="value"))
        elif op == "add":
            parent[data.draw(st.sampled_from(WORDS), label="new key")] = data.draw(VALUES, label="value")
        elif isinstance(parent, dict):
            parent[data.draw(st.sampled_from(WORDS), label="renamed")] = parent.pop(key)
    return doc


def byte_mutate(raw: bytes, data: st.DataObject) -> bytes:
    """``raw`` with a few bytes inserted, deleted or replaced (mutations of a file on disk)."""
    out = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 4), label="byte edits")):
        pos = data.draw(st.integers(0, len(out)), label="position")
        op = data.draw(st.sampled_from(["insert", "delete", "replace"]), label="byte op")
        chunk = data.draw(
            st.one_of(
                st.binary(min_size=1, max_size=4), st.sampled_from([b'"', b"[", b"]", b"{", b"=", b"\n", b"true", b"nan", b"\xff", b"#", b"\x00", b"9" * 30])
            ),
            label="bytes",
        )
        if op == "insert":
            out[pos:pos] = chunk
        elif op == "delete":
            del out[pos : pos + len(chunk)]
        else:
            out[pos : pos + len(chunk)] = chunk
    return bytes(out)


# ----------------------------------------------------------------------------- problems


def _problem_property(data: st.DataObject) -> None:
    base = data.draw(st.sampled_from(BASES), label="base")
    doc = mutate(base, data)
    try:
        problem_from_dict(doc, "fuzz.toml")
    except ProblemError:
        pass  # the only failure allowed: a clear error


test_problem_loader_fuzz = FAST(given(st.data())(_problem_property))
test_problem_loader_fuzz_long = pytest.mark.slow(SLOW(given(st.data())(_problem_property)))


def run_cli(argv: list[str], cwd: Path) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    old = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:
                code = int(exc.code or 0)
    finally:
        os.chdir(old)
    return code, out.getvalue(), err.getvalue()


def _cli_property(data: st.DataObject) -> None:
    raw = data.draw(st.sampled_from([GRID_TOML, GRAPH_TOML]), label="base").encode()
    mutated = byte_mutate(raw, data)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "p.toml").write_bytes(mutated)
        code, out, err = run_cli(["synthesize", "p.toml", "--json", "-q", "--time-limit", "10"], root)
        assert code in (0, 2, 3, 5), err
        assert "Traceback" not in err
        if code == 0:
            json.loads(out)
        else:
            assert sum(line.startswith("error: ") for line in err.splitlines()) == 1, err
            assert out == ""
        assert sorted(p.name for p in root.iterdir()) == ["p.toml"]  # nothing else written
        assert (root / "p.toml").read_bytes() == mutated


test_cli_byte_fuzz = settings(FAST, max_examples=25)(given(st.data())(_cli_property))
test_cli_byte_fuzz_long = pytest.mark.slow(settings(SLOW, max_examples=250)(given(st.data())(_cli_property)))


# ----------------------------------------------------------------------------- artifacts


def _artifact_property(data: st.DataObject) -> None:
    name = data.draw(st.sampled_from(sorted(ARTIFACT_BASES)), label="artifact")
    doc = mutate(ARTIFACT_BASES[name], data, rounds=2)
    try:
        TestArtifact.from_dict(doc, "fuzz.json")
    except ProblemError:
        pass


def _artifact_bytes_property(data: st.DataObject) -> None:
    raw = (ARTIFACTS / "small-reactive.json").read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "a.json"
        path.write_bytes(byte_mutate(raw, data))
        try:
            TestArtifact.load(path)
        except ProblemError:
            pass


test_artifact_fuzz = FAST(given(st.data())(_artifact_property))
test_artifact_fuzz_long = pytest.mark.slow(SLOW(given(st.data())(_artifact_property)))
test_artifact_byte_fuzz = FAST(given(st.data())(_artifact_bytes_property))
test_artifact_byte_fuzz_long = pytest.mark.slow(SLOW(given(st.data())(_artifact_bytes_property)))


# ----------------------------------------------------------------------------- environments

NON_INTEGERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.text(max_size=3),
    st.integers(max_value=-1),
    st.lists(st.integers(0, 4), min_size=2, max_size=3).map(np.array),
    st.just(None),
    st.just(np.float64(1.0)),
    st.just(np.array([[1]])),
)


def invalid_actions(n: int) -> st.SearchStrategy[Any]:
    """Anything but an integer of ``Discrete(n)``."""
    return st.one_of(NON_INTEGERS, st.integers(min_value=n, max_value=2**80))


_ENVS: dict[str, Any] = {}


def _env(env_id: str) -> Any:
    if env_id not in _ENVS:
        _ENVS[env_id] = gym.make(env_id).unwrapped  # no wrappers: the env itself must refuse
    return _ENVS[env_id]


def _env_property(data: st.DataObject) -> None:
    env = _env(data.draw(st.sampled_from(["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"]), label="env"))
    env.reset(seed=data.draw(st.integers(0, 2**31), label="seed"))
    for _ in range(data.draw(st.integers(1, 60), label="length")):
        if data.draw(st.booleans(), label="invalid?"):
            bad = data.draw(invalid_actions(int(env.action_space.n)), label="invalid action")
            before = env.run.key(), env.run.steps
            with pytest.raises(gym.error.InvalidAction):
                env.step(bad)
            assert (env.run.key(), env.run.steps) == before
        else:
            _, _, terminated, truncated, _ = env.step(data.draw(st.integers(0, env.action_space.n - 1), label="action"))
            if terminated or truncated:
                with pytest.raises(gym.error.ResetNeeded):
                    env.step(0)
                return


test_env_action_fuzz = FAST(given(st.data())(_env_property))
test_env_action_fuzz_long = pytest.mark.slow(SLOW(given(st.data())(_env_property)))


def _parallel_property(data: st.DataObject) -> None:
    from flowtest_env import multiagent

    env = multiagent.parallel_env(problem=data.draw(st.sampled_from(["small-reactive", "maze2"]), label="problem"))
    env.reset(seed=0)
    for _ in range(data.draw(st.integers(1, 40), label="length")):
        if not env.agents:
            with pytest.raises(gym.error.ResetNeeded):
                env.step({a: 0 for a in env.possible_agents})
            return
        actions: dict[str, Any] = {a: data.draw(st.integers(0, int(env.action_space(a).n) - 1)) for a in env.agents}
        if data.draw(st.booleans(), label="invalid?"):
            victim = data.draw(st.sampled_from(list(actions)), label="agent")
            actions[victim] = data.draw(invalid_actions(int(env.action_space(victim).n)), label="invalid action")
            before = env.state().copy()
            with pytest.raises(gym.error.InvalidAction):
                env.step(actions)
            assert np.array_equal(env.state(), before)
        else:
            env.step(actions)


test_parallel_env_fuzz = settings(FAST, max_examples=30)(given(st.data())(_parallel_property))
test_parallel_env_fuzz_long = pytest.mark.slow(SLOW(given(st.data())(_parallel_property)))


def test_fuzz_helpers_make_edits() -> None:
    """The mutators do change their input (a fuzz suite that mutates nothing proves nothing)."""
    changed: list[bool] = []

    @settings(max_examples=30, derandomize=True, deadline=None)
    @given(st.data())
    def probe(data: st.DataObject) -> None:
        changed.append(mutate(BASES[0], data) != BASES[0])
        changed.append(byte_mutate(b"abc", data) != b"abc")

    probe()
    assert sum(changed) > len(changed) // 2
