"""The reference reader (docs/reference_reader/reader.py, plain Python with no FlowTest
import) agrees with the FlowTest environments step by step: masks, states, histories, the
test agent's moves, the verdict, on at least 10,000 random steps per kind of test
(reactive, static, mixed, agent)."""

from __future__ import annotations

import ast
import importlib.util
import json
import random
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

import flowtest_env
from flowtest_env.artifacts import artifact_path
from synthesis.problems.files import load_problem_file

ROOT = Path(__file__).resolve().parents[2]
READER = ROOT / "docs" / "reference_reader" / "reader.py"
STEPS_PER_KIND = 10_000

KINDS: dict[str, list[str]] = {
    "reactive": ["small-reactive", "beaver-rescue", "motion-primitives"],
    "static": ["example1", "refueling", "mars-exploration"],
    "mixed": ["tests/data/ok_mixed.toml"],
    "agent": ["maze1", "maze2", "patrolling"],
}


def load_reader() -> ModuleType:
    spec = importlib.util.spec_from_file_location("flowtest_reference_reader", READER)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_reader_imports_nothing_but_json_and_stays_short() -> None:
    tree = ast.parse(READER.read_text())
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported == {"json"}
    code = [line for line in READER.read_text().splitlines() if line.strip() and not line.strip().startswith("#")]
    assert len(code) < 200


def _doc(name: str) -> dict[str, Any]:
    if name.endswith(".toml"):
        u: Any = flowtest_env.make_env(load_problem_file(ROOT / name)).unwrapped
        return dict(u.game.artifact.to_dict())
    return dict(json.loads(artifact_path(name).read_text()))


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_reader_agrees_with_the_env_on_random_steps(kind: str) -> None:
    reader = load_reader()
    rng = random.Random(f"reader-{kind}")
    steps = 0
    names = KINDS[kind]
    per_test = -(-STEPS_PER_KIND // len(names))
    for name in names:
        doc = _doc(name)
        assert doc["kind"] == kind
        test = reader.Test(json.loads(json.dumps(doc)))  # what a file gives: plain JSON data
        env = flowtest_env.make_env(doc["name"] if not name.endswith(".toml") else load_problem_file(ROOT / name))
        u: Any = env.unwrapped
        done_here, episodes = 0, 0
        while done_here < per_test:
            _, info = env.reset(seed=episodes)
            run = test.reset()
            episodes += 1
            while True:
                mine = u.run
                assert (run.system, run.history, run.agent, run.memory, run.outcome) == (mine.system, mine.history, mine.agent, mine.memory, mine.outcome), (
                    name,
                    run.steps,
                )
                assert test.mask(run) == info["action_mask"].tolist(), (name, run.steps)
                if mine.done or mine.steps >= u.max_steps:
                    break
                legal = [a for a, ok in enumerate(test.mask(run)) if ok]
                # mostly allowed actions, sometimes any action: refusals and impossible moves too
                action = rng.choice(legal) if rng.random() < 0.8 else rng.randrange(len(info["action_mask"]))
                _, _, terminated, truncated, info = env.step(action)
                test.step(run, action)
                steps += 1
                done_here += 1
                assert test.verdict(run) == u.game.verdict(u.run), (name, run.steps)
                if terminated or truncated:
                    assert test.verdict(run) == info["verdict"]
        env.close()
    assert steps >= STEPS_PER_KIND
