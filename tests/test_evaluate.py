"""``flowtest evaluate``: results, report, replay commands that reproduce failures."""

from __future__ import annotations

import io
import json
import shlex
from pathlib import Path

import pytest

from experiments.cli import main
from experiments.evaluate import evaluate, replay, write_report

FAULTY_CASES = [
    ("scripted:committed", "FlowTest-SmallReactive-v0"),
    ("scripted:fuel-blind", "FlowTest-Refueling-v0"),
    ("scripted:greedy", "FlowTest-BeaverRescue-v0"),
]


def test_evaluate_writes_results_report_and_pictures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main([
        "evaluate", "--env", "FlowTest-SmallReactive-v0", "FlowTest-BeaverRescue-v0",
        "--sut", "scripted:replanner", "scripted:committed", "--episodes", "2", "--seed", "3",
        "--out", str(tmp_path), "-q",
    ])
    assert code == 0
    records = json.loads((tmp_path / "results.json").read_text())
    assert len(records) == 4
    for r in records:
        for key in ("env", "sut", "episodes", "system_objective_met_rate", "test_objective_realized_rate", "failures"):
            assert key in r
        for pic in r["pictures"].values():
            assert (tmp_path / pic).stat().st_size > 5000
    good = [r for r in records if r["sut"] == "scripted:replanner"]
    assert all(r["system_objective_met_rate"] == 1.0 and r["test_objective_realized_rate"] == 1.0 for r in good)
    bad = [r for r in records if r["sut"] == "scripted:committed"]
    assert all(r["failures"] and r["failures"][0]["seed"] in (3, 4) for r in bad)
    md = (tmp_path / "report.md").read_text()
    assert "## scripted:committed" in md and "--replay" in md
    assert "<table>" in (tmp_path / "report.html").read_text()
    assert "report:" in capsys.readouterr().out


@pytest.mark.parametrize("sut,env_id", FAULTY_CASES)
def test_replay_command_reproduces_the_failure(sut: str, env_id: str, tmp_path: Path) -> None:
    cells = evaluate([env_id], [sut], 2, seed=11)
    records = write_report(cells, tmp_path)
    failure = records[0]["failures"][0]
    args = shlex.split(failure["replay"])
    assert args[:2] == ["flowtest", "evaluate"] and "--replay" in args
    seed = int(args[args.index("--seed") + 1])
    trace = replay(args[args.index("--env") + 1], args[args.index("--sut") + 1], seed, io.StringIO())
    assert trace.verdict == failure["verdict"]
    assert trace.kind == failure["kind"] == "sut"
    original = next(t for t in cells[0].traces if t.seed == seed)
    assert trace.actions == original.actions


def test_replay_through_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "scripted:committed",
                 "--episodes", "1", "--seed", "0", "--replay"])
    out = capsys.readouterr().out
    assert code == 0 and "verdict:" in out and "step   0" in out


def test_test_failure_is_reported_loudly(tmp_path: Path) -> None:
    cells = evaluate(["FlowTest-SmallReactive-v0"], ["scripted:replanner"], 1)
    t = cells[0].traces[0]
    t.kind, t.reason = "test", "met the system objective without realizing the test objective"
    write_report(cells, tmp_path)
    assert "FLOWTEST BUG" in (tmp_path / "report.md").read_text()
    assert "FLOWTEST BUG" in (tmp_path / "report.html").read_text()


def test_unknown_env_is_invalid_input(tmp_path: Path) -> None:
    assert main(["evaluate", "--env", "FlowTest-Nope-v0", "--sut", "random", "--out", str(tmp_path), "-q"]) == 2
