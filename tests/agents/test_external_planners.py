"""Systems under test from outside FlowTest: ``python:MODULE:NAME`` and ``cmd:COMMAND``
planners (docs/runtime.md) in ``flowtest evaluate``, its replay commands, the Python
``evaluate()`` and the benchmark's scoring, against a user's problem file; planners that
crash, hang or lie fail their run with a reason and the other pairs still run."""

from __future__ import annotations

import json
import re
import shlex
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from experiments.cli.cli import main

DOC = Path(__file__).resolve().parents[2] / "docs" / "runtime.md"

WAREHOUSE = '''name = "warehouse"

[system]
grid = """
S  .  .  .  .  .
.  #  .  .  #  .
x  .  A  x  .  B
.  #  .  .  #  .
.  .  .  .  .  D
"""
start = "S"
terminal = ["D"]

[labels]
dock = ["D"]
spill = ["x"]
aisle = ["A"]
bay = ["B"]

[objectives]
system = "F dock & G !spill"
test = "F aisle & F bay"

[environment]
kind = "reactive"
'''


def doc_files() -> dict[str, str]:
    """The example planners of docs/runtime.md, as written there."""
    text = DOC.read_text()
    return dict(re.findall(r"<!-- file: (\S+) -->\n```\w+\n(.*?)```", text, re.S))


@pytest.fixture
def project(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A user's folder: the warehouse problem and the documented planners; the current
    directory for the test (Python's module search path and module table restored after)."""
    (tmp_path / "warehouse.toml").write_text(WAREHOUSE)
    for name, body in doc_files().items():
        (tmp_path / name).write_text(body)
    monkeypatch.chdir(tmp_path)
    path = list(sys.path)
    yield tmp_path
    sys.path[:] = path
    for name, module in list(sys.modules.items()):  # the user's modules, imported from this folder
        if str(getattr(module, "__file__", None) or "").startswith(str(tmp_path)):
            del sys.modules[name]


def write(folder: Path, name: str, body: str) -> None:
    (folder / name).write_text(body)


def replay_args(command: str, folder: Path) -> list[str]:
    """The arguments after ``flowtest`` of a replay command, checked to ``cd`` into ``folder``."""
    words = shlex.split(command)
    assert words[:3] == ["cd", str(folder), "&&"], command
    assert words[3:5] == ["flowtest", "evaluate"] and "--replay" in words
    return words[4:]


def test_the_doc_has_a_python_a_javascript_and_a_shell_planner() -> None:
    files = doc_files()
    assert set(files) == {"bfs_planner.py", "replanner.js", "prefer.sh"}
    assert "import flowtest" not in files["bfs_planner.py"] and "from flowtest" not in files["bfs_planner.py"]


def test_documented_planners_run_from_the_cli_with_a_report_and_replay_commands(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    suts = ["python:bfs_planner:BfsPlanner", "cmd:python3 bfs_planner.py", "cmd:sh prefer.sh S E"]
    code = main(["evaluate", "--env", "warehouse.toml", "--sut", *suts, "--episodes", "1", "--seed", "5", "--out", "report", "-q"])
    assert code == 0, capsys.readouterr().err
    records = {r["sut"]: r for r in json.loads((project / "report" / "results.json").read_text())}
    assert set(records) == set(suts)
    for sut in ("python:bfs_planner:BfsPlanner", "cmd:python3 bfs_planner.py"):
        r = records[sut]
        assert r["error"] is None and r["stopped"] is None and r["episodes"] == 1
        assert r["system_objective_met_rate"] == 1.0 and r["test_objective_realized_rate"] == 1.0, r
    naive = records["cmd:sh prefer.sh S E"]
    assert naive["episodes"] == 1 and naive["stopped"] is None and naive["n_failures"] == 1
    assert all(f["kind"] == "sut" and f["verdict"]["system_objective"] == "violated" for f in naive["failures"])
    assert naive["failures"][0]["verdict"]["steps"] == 2  # south, south: into the spill
    page = (project / "report" / "report.html").read_text()
    assert "prefer.sh" in page and "bfs_planner" in page
    # every replay command cds into the folder the evaluation ran in and reproduces the run
    for f in naive["failures"]:
        capsys.readouterr()
        assert main(replay_args(f["replay"], project)) == 0
        out = capsys.readouterr().out
        assert "outcome: sut: violated the system objective" in out
        assert f"verdict: {json.dumps(f['verdict'])}" in out


def test_replay_of_a_python_planner_runs_from_its_folder(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from experiments.evaluation.runs import replay_command

    command = replay_command("warehouse.toml", "python:bfs_planner:BfsPlanner", 4)
    assert main(replay_args(command, project)) == 0
    out = capsys.readouterr().out
    assert out.startswith("python:bfs_planner:BfsPlanner on warehouse.toml, seed 4")
    assert '"system_objective": "met"' in out and '"test_objective_realized": true' in out


BAD_PLANNERS: dict[str, str] = {
    # exits at its fourth step with a message on stderr
    "crash.py": (
        "import json, sys\n"
        "for line in sys.stdin:\n"
        "    m = json.loads(line)\n"
        "    if m['type'] == 'step':\n"
        "        if m['step'] == 3:\n"
        "            sys.exit('out of battery at step 3')\n"
        "        print(m['allowed'][-1], flush=True)\n"
    ),
    # never answers
    "hang.py": "import sys, time\nfor line in sys.stdin:\n    time.sleep(60)\n",
    # answers a move into the wall west of the start
    "lie.py": (
        "import json, sys\nfor line in sys.stdin:\n    if json.loads(line)['type'] == 'step':\n        print(json.dumps({'action': 'W'}), flush=True)\n"
    ),
    # prints its debugging on stdout
    "chatty.py": (
        "import json, sys\nfor line in sys.stdin:\n    if json.loads(line)['type'] == 'step':\n        print('thinking about', line.strip()[:20], flush=True)\n"
    ),
}


EXPECTED = {
    "crash.py": "step 3: the planner exited with status 1; its last error output: out of battery at step 3",
    "hang.py": "step 0: the planner sent no answer within 1.5 s (--step-timeout); it was stopped",
    "lie.py": "step 0: chose 'W', which the test does not allow now (allowed: ",
    "chatty.py": 'step 0: answered \'thinking about {"type":"step","step\', which is not an action',
}


def test_crashing_hanging_and_lying_planners_fail_their_run_and_the_others_go_on(project: Path) -> None:
    from experiments.evaluation.runs import evaluate

    for name, body in BAD_PLANNERS.items():
        write(project, name, body)
    suts = [f"cmd:python3 {name}" for name in BAD_PLANNERS] + ["cmd:python3 bfs_planner.py"]
    cells = evaluate(["warehouse.toml", "small-reactive"], suts, 3, step_timeout=1.5)
    by = {(c.sut, c.env_id): c.record() for c in cells}
    assert len(by) == 2 * len(suts)
    for env in ("warehouse.toml", "small-reactive"):
        for name, reason in EXPECTED.items():
            r = by[(f"cmd:python3 {name}", env)]
            # every run is played, each with a fresh planner process, and each fails the same way
            assert r["error"] is None and r["episodes"] == 3 and r["n_failures"] == 3 and r["stopped"] is None, r
            for f in r["failures"]:
                assert f["kind"] == "sut" and f["reason"].startswith("the planner failed: ")
                assert reason in f["reason"], (name, f["reason"])
                assert f["verdict"]["system_objective"] == "open"
                assert f["replay"].startswith(f"cd {shlex.quote(str(project))} && flowtest evaluate")
                assert "--step-timeout 1.5" in f["replay"]
        good = by[("cmd:python3 bfs_planner.py", env)]
        assert good["episodes"] == 3 and good["system_objective_met_rate"] == 1.0 and good["stopped"] is None


PYTHON_HANGS = (
    "import time\n"
    "def spin(observation, mask):\n"
    "    while True:\n"
    "        pass\n"
    "def sleepy(observation, mask):\n"
    "    time.sleep(60)\n"
    "def stubborn(observation, mask):\n"  # its own except Exception does not swallow the timer
    "    try:\n"
    "        while True:\n"
    "            pass\n"
    "    except Exception:\n"
    "        return 0\n"
    "class SlowReset:\n"
    "    def reset(self, seed):\n"
    "        time.sleep(60)\n"
    "    def act(self, observation, mask):\n"
    "        return observation['allowed'][0]\n"
)


def test_hanging_python_planners_fail_their_run_and_the_others_go_on(project: Path) -> None:
    """A ``python:`` planner runs in FlowTest's process; one that loops, sleeps or swallows
    exceptions past ``--step-timeout`` fails its run with the reason (a walker once waited
    ten minutes on one, and Ctrl-C lost the pairs already played)."""
    from experiments.evaluation.runs import evaluate

    write(project, "hangs.py", PYTHON_HANGS)
    suts = [f"python:hangs:{name}" for name in ("spin", "sleepy", "stubborn", "SlowReset")] + ["python:bfs_planner:BfsPlanner"]
    t0 = time.perf_counter()
    cells = evaluate(["warehouse.toml"], suts, 2, step_timeout=0.5)
    took = time.perf_counter() - t0
    by = {c.sut: c.record() for c in cells}
    for name in ("spin", "sleepy", "stubborn"):
        r = by[f"python:hangs:{name}"]
        assert r["n_failures"] == 2 and r["episodes"] == 2, r  # every run played, each ends at the step timeout
        for f in r["failures"]:
            assert "step 0: the planner gave no answer within 0.5 s (--step-timeout)" in f["reason"], r
            assert "--step-timeout 0.5" in f["replay"]
    slow = by["python:hangs:SlowReset"]
    assert "reset: the planner did not return within 0.5 s" in str(slow), slow
    good = by["python:bfs_planner:BfsPlanner"]
    assert good["episodes"] == 2 and good["system_objective_met_rate"] == 1.0
    assert took < 30, took
    import signal

    assert signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None) and signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_a_timer_the_caller_armed_is_left_alone(project: Path) -> None:
    """Where the caller has a real-time timer armed (pytest-timeout's signal method, a
    script's own alarm), the planner's step is not timed, so that timer is not cancelled."""
    import signal

    from agents.registry import make_policy
    from experiments.evaluation.episodes import env_named as make_env

    env = make_env("warehouse.toml")
    policy = make_policy("python:bfs_planner:BfsPlanner", env, step_timeout=0.05)
    obs, info = env.reset(seed=0)
    policy.reset(0)
    rang: list[int] = []
    old = signal.signal(signal.SIGALRM, lambda signum, frame: rang.append(signum))
    try:
        signal.setitimer(signal.ITIMER_REAL, 5.0)
        policy.act(obs, info)
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0  # still armed, not cancelled
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        time.sleep(0.5)
        assert rang == [signal.SIGALRM]  # and the caller's handler is back
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def test_ctrl_c_keeps_the_pairs_played(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C in the middle of an evaluation (here: while a planner thinks about its step)
    exits 130 at once, and the pairs played to the end are kept in results.json and
    report.md (a walker lost every finished pair to a Ctrl-C). The planner runs in a child
    process of its own session: it sends the Ctrl-C to FlowTest, as a terminal would."""
    import signal

    old = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's Ctrl-C, even under a runner that ignores it
    try:
        _ctrl_c_keeps_the_pairs_played(project, capsys)
    finally:
        signal.signal(signal.SIGINT, old)


def _ctrl_c_keeps_the_pairs_played(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write(project, "quitter.py", "import os, signal, time\ndef quit_now(observation, mask):\n    os.kill(os.getppid(), signal.SIGINT)\n    time.sleep(30)\n")
    code = main(
        [
            "evaluate",
            "--env",
            "warehouse.toml",
            "--sut",
            "python:bfs_planner:BfsPlanner",
            "python:quitter:quit_now",
            "scripted:replanner",
            "--episodes",
            "2",
            "--out",
            "report",
        ]
    )
    err = capsys.readouterr().err
    assert code == 130 and err.rstrip().endswith("flowtest: interrupted"), err
    assert "1 of 3 (system, test) pairs were played to the end" in err, err
    records = json.loads((project / "report" / "results.json").read_text())
    assert [(r["sut"], r["episodes"], r["interrupted"]) for r in records] == [("python:bfs_planner:BfsPlanner", 2, True)]
    md = (project / "report" / "report.md").read_text()
    assert md.startswith("# FlowTest evaluation (interrupted: the pairs played)") and "| warehouse |" in md
    assert not (project / "report" / "report.html").exists()
    # interrupted before any pair ends: the earlier run's files do not stay as if current
    code = main(["evaluate", "--env", "warehouse.toml", "--sut", "python:quitter:quit_now", "--out", "report"])
    assert code == 130 and "no (system, test) pair was played to the end" in capsys.readouterr().err
    assert json.loads((project / "report" / "results.json").read_text()) == []
    assert (project / "report" / "report.md").read_text().startswith("# FlowTest evaluation (interrupted before any pair")


@pytest.mark.slow
def test_misbehaving_planners_in_the_cli_report_and_replay(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for name, body in BAD_PLANNERS.items():
        write(project, name, body)
    suts = [f"cmd:python3 {name}" for name in BAD_PLANNERS] + ["python:bfs_planner:BfsPlanner"]
    code = main(["evaluate", "--env", "warehouse.toml", "--sut", *suts, "--episodes", "2", "--step-timeout", "1.5", "--out", "report", "-q"])
    assert code == 0
    out = capsys.readouterr().out
    records = {r["sut"]: r for r in json.loads((project / "report" / "results.json").read_text())}
    for name in BAD_PLANNERS:  # every run played, each failing, printed as one way of failing
        assert records[f"cmd:python3 {name}"]["n_failures"] == 2 and records[f"cmd:python3 {name}"]["stopped"] is None
        assert f"cmd:python3 {name}" in out and "seeds 0, 1 (2 runs): the planner failed: " in out
    page = (project / "report" / "report.html").read_text()
    for name, reason in EXPECTED.items():
        f = records[f"cmd:python3 {name}"]["failures"][0]
        assert reason in f["reason"]
        assert html_escaped(reason.split(": ")[-1][:30]) in page or reason.split(": ")[-1][:30] in page
    md = (project / "report" / "report.md").read_text()
    assert md.count("— 2 of 2 runs failed") >= len(BAD_PLANNERS), md
    # the test by its problem's name, as in the HTML, never the file's path
    assert "| system under test | warehouse |" in md and str(project) + "/warehouse.toml |" not in md
    assert all(r["title"] == "warehouse" for r in records.values())
    crash = records["cmd:python3 crash.py"]["failures"][0]
    assert main(replay_args(crash["replay"], project)) == 0
    assert "out of battery at step 3" in capsys.readouterr().out


def html_escaped(text: str) -> str:
    import html

    return html.escape(text)


@pytest.mark.parametrize(
    "sut,message",
    [
        ("python:no_such_planner:Bfs", "no Python module 'no_such_planner'"),
        ("python:bfs_planner:Nope", "module 'bfs_planner' has no attribute 'Nope'"),
        ("python:bfs_planner", "expected python:MODULE:NAME"),
        ("cmd:no-such-program --fast", "command 'no-such-program' not found on PATH"),
        ("cmd:./missing.sh", "no program './missing.sh'"),
        ("cmd:", "cmd: needs a command"),
    ],
)
def test_a_missing_module_name_or_program_is_one_error_line(project: Path, capsys: pytest.CaptureFixture[str], sut: str, message: str) -> None:
    code = main(["evaluate", "--env", "warehouse.toml", "--sut", sut, "--out", "report", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"error: --sut {sut}: ") and message in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (project / "report").exists()


def test_a_module_that_raises_on_import_is_one_error_line(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write(project, "broken_planner.py", "raise RuntimeError('no map loaded')\n")
    code = main(["evaluate", "--env", "warehouse.toml", "--sut", "python:broken_planner:P", "--out", "r", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "raised while being imported: RuntimeError: no map loaded" in err


def test_python_api_takes_planner_objects(project: Path) -> None:
    from experiments.evaluation.runs import NOT_REPLAYABLE, evaluate

    sys.path.insert(0, str(project))
    from bfs_planner import BfsPlanner  # type: ignore[import-not-found]

    def stubborn(observation: dict[str, Any], mask: object) -> str:
        return "E" if "E" in observation["allowed"] else "stay"

    cells = evaluate(["warehouse.toml"], [BfsPlanner, lambda obs, mask: int(obs["mask"].index(1)), stubborn], 2)
    records = {c.sut: c.record() for c in cells}
    assert records["python:bfs_planner:BfsPlanner"]["system_objective_met_rate"] == 1.0
    lam = next(r for name, r in records.items() if "lambda" in name)
    assert lam["error"] is None and all(f["replay"] == NOT_REPLAYABLE for f in lam["failures"])
    named = next(r for name, r in records.items() if name.endswith("<locals>.stubborn"))
    assert named["failures"] and all(f["replay"] == NOT_REPLAYABLE for f in named["failures"])


def test_a_python_planner_that_raises_or_lies_fails_its_run(project: Path) -> None:
    from experiments.evaluation.runs import evaluate

    def raises(observation: dict[str, Any], mask: object) -> int:
        if observation["step"] == 2:
            raise ZeroDivisionError("division by zero")
        return int(observation["mask"].index(1))

    def lies(observation: dict[str, Any], mask: object) -> int:
        return 7

    cells = evaluate(["small-reactive"], [raises, lies, "scripted:replanner"], 2)
    assert [len(c.traces) for c in cells] == [2, 2, 2]  # every run is played; a failure ends its own run
    assert all(t.reason == "the planner failed: step 2: raised ZeroDivisionError: division by zero" for t in cells[0].traces)
    assert all("step 0: answered 7, which is not an action (expected an index 0..4" in t.reason for t in cells[1].traces)
    assert cells[2].stopped is None and all(t.verdict["system_objective"] == "met" for t in cells[2].traces)


def test_benchmark_scores_a_planner_process_through_make_policy(project: Path) -> None:
    """``flowtest benchmark`` scores other systems through make_policy (no change there)."""
    from experiments.benchmark import Split, score_systems
    from flowtest_env.artifacts import load_builtin

    art = load_builtin("small-reactive")
    path = project / "seed0.json"
    art.save(path)
    split = Split("test", "held-out", [0], [art], [path])
    write(project, "lie.py", BAD_PLANNERS["lie.py"])
    traces = score_systems(["cmd:python3 bfs_planner.py", "cmd:python3 lie.py"], split)
    assert traces["cmd:python3 bfs_planner.py"][0].verdict["system_objective"] == "met"
    lied = traces["cmd:python3 lie.py"][0]
    assert lied.kind == "sut" and "which the test does not allow now" in lied.reason


def test_a_factory_that_raises_is_one_error_line(project: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write(project, "moody.py", "class Planner:\n    def __init__(self, test):\n        raise ValueError('no map for ' + test['name'])\n")
    code = main(["evaluate", "--env", "warehouse.toml", "--sut", "python:moody:Planner", "--out", "r", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.strip() == "error: --sut python:moody:Planner: the factory raised ValueError: no map for warehouse"


def test_a_planner_that_writes_unasked_lines_fails_its_run(project: Path) -> None:
    from experiments.evaluation.runs import evaluate

    write(
        project,
        "banner.py",
        "import sys\nprint('BFS planner v2 ready', flush=True)\nfor line in sys.stdin:\n    if '\"step\"' in line[:20]:\n        print('stay', flush=True)\n",
    )
    cells = evaluate(["small-reactive"], ["cmd:python3 banner.py"], 2)
    said = cells[0].traces[0].planner_error
    assert (
        "wrote 'BFS planner v2 ready' before it was asked" in said
        or "step 0: answered 'BFS planner v2 ready', which is not an action" in said
        or "step 0: the planner answered 'BFS planner v2 ready' without reading this step" in said
    ), said
    assert "logs to standard error" in said, said  # either way, where the banner belongs
