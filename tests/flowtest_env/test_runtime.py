"""The test as a runtime: :class:`flowtest_env.runtime.TestRuntime` stepped by the system's
states agrees with the environment; refusals say why; ``flowtest serve`` over standard
input and output and over a localhost socket."""

from __future__ import annotations

import io
import json
import random
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import flowtest_env
from experiments.cli.cli import main
from experiments.cli.serve import serve_stream
from flowtest_env.runtime import RuntimeRefused, TestRuntime

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("name", ["small-reactive", "example1", "refueling", "beaver-rescue", "maze2", "patrolling"])
def test_stepping_by_states_agrees_with_the_env(name: str) -> None:
    """Random walks: the env takes an allowed action, the runtime is told the state the
    system entered; status and verdict agree after every step (the agent's place too)."""
    rng = random.Random(name)
    env = flowtest_env.make_env(name)
    u: Any = env.unwrapped
    rt = TestRuntime.load(name)
    for episode in range(20):
        _, info = env.reset(seed=episode)
        status = rt.reset()
        while True:
            budget_spent = status["done"] and not u.run.done  # the env truncates; the runtime allows nothing more
            assert status["mask"] == ([0] * len(status["mask"]) if budget_spent else info["action_mask"].tolist())
            assert status["state"] == info["system_state"]
            assert status["verdict"] == u.game.verdict(u.run) and status["history"] == u.run.history
            if u.game.has_agent:
                assert status["agent"]["state"] == u.run.agent
            if status["done"]:
                assert u.run.done or u.run.steps >= u.max_steps
                break
            a = rng.choice([i for i, ok in enumerate(status["mask"]) if ok])
            _, _, terminated, truncated, info = env.step(a)
            status = rt.step(state=info["system_state"])
            if terminated or truncated:
                assert status["done"] and status["verdict"] == info["verdict"]


def test_a_restricted_move_is_refused_with_its_reason() -> None:
    rt = TestRuntime.load("small-reactive")
    rt.reset()
    status = rt.step(state=[1, 1])
    status = rt.step(state=[0, 1])
    assert status["restricted"] == [{"action": "E", "to": [0, 2], "by": "door"}]
    with pytest.raises(RuntimeRefused, match=r"the move \[0, 1\] -> \[0, 2\] is restricted now \(by the test\)") as refused:
        rt.step(state=[0, 2])
    assert refused.value.code == "restricted"
    with pytest.raises(RuntimeRefused, match=r"\[1, 0\] is not one move from \[0, 1\]"):
        rt.step(state=[1, 0])
    with pytest.raises(RuntimeRefused, match="is not a state of 'small-reactive'"):
        rt.step(state="T")
    with pytest.raises(RuntimeRefused, match="one of them"):
        rt.step()
    assert rt.status() == status  # refusals change nothing
    # an action the test refuses is a blocked attempt, as in the env
    status = rt.step(action="E")
    assert status["state"] == [0, 1] and status["verdict"]["blocked_attempts"] == 1
    with pytest.raises(RuntimeRefused, match="not an action here"):
        rt.step(action="NE")


def _refusals(name: str, runs: int) -> list[dict[str, object]]:
    """Every ``restricted`` entry met on random walks of ``runs`` runs."""
    rt = TestRuntime.load(name)
    found = []
    for seed in range(runs):
        rng = random.Random(seed)
        status = rt.reset()
        while not status["done"]:
            found += status["restricted"]
            status = rt.step(action=rng.choice(status["allowed"]))
    return found


def test_walls_and_the_test_agent_are_named() -> None:
    walls = _refusals("example1", 20)
    assert walls and {r["by"] for r in walls} == {"wall"}  # a static test: walls only
    agent = _refusals("maze2", 30)
    assert {r["by"] for r in agent} == {"agent"} and all(r["to"] for r in agent)
    doors = _refusals("small-reactive", 20)
    assert {r["by"] for r in doors} == {"door"}


def test_a_run_that_ended_takes_no_step() -> None:
    rt = TestRuntime.load("small-reactive", max_steps=2)
    rt.reset()
    rt.step(action="stay")
    status = rt.step(action="stay")
    assert status["done"] and status["mask"] == [0] * 5 and status["allowed"] == []
    with pytest.raises(RuntimeRefused, match="the run has ended"):
        rt.step(action="stay")


def test_serve_answers_each_line_and_goes_on_after_bad_ones() -> None:
    requests = [
        {"op": "describe"},
        {"op": "reset", "id": 7},
        "not json",
        {"op": "step", "state": [1, 1]},
        {"op": "step", "state": [9, 9]},
        {"op": "step", "action": "E", "extra": 1},
        {"op": "fly"},
        [1, 2],
        {"op": "status"},
        {"op": "quit"},
        {"op": "reset"},
    ]
    inp = io.StringIO("".join((r if isinstance(r, str) else json.dumps(r)) + "\n" for r in requests))
    out = io.StringIO()
    serve_stream(TestRuntime.load("small-reactive"), inp, out)
    answers = [json.loads(line) for line in out.getvalue().splitlines()]
    assert len(answers) == 10  # nothing after quit
    assert answers[0]["test"]["objective"] == "F goal" and "test" not in json.dumps(answers[0]["test"]["system"]).lower()
    assert answers[1]["ok"] and answers[1]["id"] == 7 and answers[1]["status"]["state"] == [1, 0]
    assert answers[2] == {"ok": False, "code": "not_json", "error": "not a JSON object on one line (NaN and Infinity are not JSON)"}
    assert answers[3]["status"]["state"] == [1, 1]
    assert not answers[4]["ok"] and "is not a state" in answers[4]["error"] and answers[4]["code"] == "not_a_state"
    assert not answers[5]["ok"] and "unknown field(s) of a step: extra" in answers[5]["error"] and answers[5]["code"] == "bad_request"
    assert not answers[6]["ok"] and "unknown op" in answers[6]["error"] and answers[6]["code"] == "unknown_op"
    assert not answers[7]["ok"] and "a request is a JSON object" in answers[7]["error"] and answers[7]["code"] == "not_an_object"
    assert answers[8]["status"] == answers[3]["status"]
    assert answers[9] == {"ok": True}


def _flowtest(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "experiments", *args], cwd=ROOT, text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


def test_flowtest_serve_over_stdin_and_stdout() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "experiments", "serve", "maze2"],
        cwd=ROOT,
        capture_output=True,
        input=b'{"op":"reset"}\n{"op":"st\xffep"}\n{"op":"step","action":"N"}\n',
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    first, bad, second = (json.loads(line) for line in proc.stdout.decode().splitlines())
    assert first["status"]["agent"]["name"] and second["status"]["step"] == 1
    assert not bad["ok"] and "unknown op" in bad["error"]  # a byte that is not UTF-8: an error answer, no crash


def test_flowtest_serve_on_a_localhost_socket() -> None:
    proc = _flowtest("serve", "small-reactive", "--port", "0")
    try:
        assert proc.stderr is not None
        line = proc.stderr.readline()
        assert line.startswith("flowtest: serving small-reactive on 127.0.0.1:"), line
        port = int(line.rsplit(":", 1)[1])
        for _ in range(2):  # every connection is its own run
            with socket.create_connection(("127.0.0.1", port), timeout=60) as sock:
                f = sock.makefile("rw", encoding="utf-8")
                f.write('{"op":"reset"}\n{"op":"step","state":[0,0]}\n{"op":"quit"}\n')
                f.flush()
                answers = [json.loads(f.readline()) for _ in range(3)]
            assert answers[0]["status"]["step"] == 0 and answers[1]["status"]["state"] == [0, 0]
            assert answers[2] == {"ok": True}
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_serve_refuses_an_unknown_test(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "no-such-test"]) == 2
    assert capsys.readouterr().err.startswith("error: ")


@pytest.mark.parametrize("name,hidden", [("small-reactive", ["I1", "I2"]), ("maze2", ["I1", "I2"]), ("refueling", [])])
def test_the_public_description_hides_the_test_objective(name: str, hidden: list[str]) -> None:
    rt = TestRuntime.load(name)
    test = rt.describe()
    art = rt.game.artifact
    assert test["objective"] == art.objectives["system"] and "test" not in test
    shown = {p for lab in test["system"]["labels"] for p in lab}
    for p in hidden:
        assert p in {q for lab in art.system.to_dict()["labels"] for q in lab}  # the artifact has it
        assert p not in shown
        assert all(t[2] != p for t in (test["system"]["layout"] or {"tokens": []})["tokens"])
    assert shown  # the system objective's own propositions stay


@pytest.mark.parametrize("name", ["example1", "refueling", "ok_mixed"])
def test_the_description_gives_the_walls_apart_from_the_moves(name: str) -> None:
    """What the built-in systems know (static walls are on their map, never planned through),
    an outside planner knows too: ``walls`` are the static walls, none of them among
    ``moves`` (whose per-move lists lose the same entries)."""
    rt = TestRuntime.load(str(ROOT / "tests" / "data" / "ok_mixed.toml") if name == "ok_mixed" else name)
    art = rt.game.artifact
    system, full = rt.describe()["system"], art.system.to_dict()
    wall = art.strategy.static_obstacles
    assert wall.any(), "a test with walls"
    assert system["walls"] == [m for m, w in zip(full["moves"], wall, strict=True) if w]
    assert system["moves"] == [m for m, w in zip(full["moves"], wall, strict=True) if not w]
    assert len(system["action"]) == len(system["restrictable"]) == len(system["moves"])
    assert system["action"] == [a for a, w in zip(full["action"], wall, strict=True) if not w]


@pytest.mark.parametrize("name", ["small-reactive", "refueling", "mars-exploration", "patrolling"])
def test_the_description_gives_the_system_objectives_automaton(name: str) -> None:
    """``automaton.next[q][s]`` is the system objective's automaton after entering ``s``
    (the table the built-in planners plan on), and it reads only what the description
    shows: states with the same shown labels have the same column."""
    from flowtest_env.system_product import SystemProduct

    rt = TestRuntime.load(name)
    test = rt.describe()
    aut, prod = test["automaton"], SystemProduct(rt.game)
    assert aut["initial"] == prod.q0 and len(aut["accepting"]) == prod.n_q
    assert aut["accepting"] == [bool(a) for a in rt.game.artifact.system_automaton.accepting[:, 0]]
    for q in range(prod.n_q):
        assert aut["next"][q] == [prod.step_q(q, s) for s in range(rt.game.ts.n_states)]
    by_labels: dict[tuple[str, ...], list[int]] = {}
    for s, labels in enumerate(test["system"]["labels"]):
        column = [aut["next"][q][s] for q in range(prod.n_q)]
        assert by_labels.setdefault(tuple(sorted(labels)), column) == column


def test_a_status_says_why_the_run_ended_and_names_histories_neutrally() -> None:
    rt = TestRuntime.load("small-reactive")
    status = rt.reset()
    assert status["reason"] is None and status["history_name"] == "q0"
    for state in ([0, 0], [0, 1], [1, 1], [1, 2]):
        status = rt.step(state=state)
    assert status["history_name"] == f"q{status['history']}"
    assert "I" not in json.dumps([status["history_name"], rt.history_names])  # nothing of "saw I1; saw I2"
    status = rt.step(state=[0, 2])
    assert status["done"] and status["reason"] == "met the system objective in 5 steps"
    revealed = TestRuntime.load("small-reactive", reveal=True)
    assert revealed.history_names == list(revealed.game.artifact.extras["history_descriptions"])
    short = TestRuntime.load("small-reactive", max_steps=2)
    short.reset()
    short.step(action="stay")
    assert short.step(action="stay")["reason"] == "did not meet the system objective within the step budget of 2 steps"
    unsafe = TestRuntime.load("refueling")  # a static test: walk around its walls into an unsafe state
    test = unsafe.describe()["system"]
    status = unsafe.reset()
    start = test["states"].index(status["state"])
    path, todo, target = {start: [start]}, [start], None
    while target is None:
        s = todo.pop(0)
        for a, b in test["moves"]:
            if a == s and b not in path:
                path[b] = [*path[s], b]
                todo.append(b)
                target = b if "unsafe" in test["labels"][b] and target is None else target
    for s in path[target][1:]:  # (the objective is violated once the fuel left cannot reach the goal)
        status = unsafe.step(state=test["states"][s])
        if status["done"]:
            break
    assert status["verdict"]["system_objective"] == "violated"
    assert status["reason"] == f"violated the system objective at step {status['step']}, entering {json.dumps(test['states'][s])}"


@pytest.mark.parametrize(
    "kwargs,code",
    [
        ({}, "bad_request"),
        ({"state": [0, 0], "action": "N"}, "bad_request"),
        ({"state": "T"}, "not_a_state"),
        ({"state": [1, 2]}, "not_one_move"),
        ({"action": "NE"}, "not_an_action"),
    ],
)
def test_each_refusal_has_its_code(kwargs: dict[str, Any], code: str) -> None:
    from flowtest_env.runtime import REFUSALS

    rt = TestRuntime.load("small-reactive")
    rt.reset()
    with pytest.raises(RuntimeRefused) as refused:
        rt.step(**kwargs)
    assert refused.value.code == code and code in REFUSALS
