"""experiments/tools/leaderboard.py: docs/leaderboard.md is built from result files only, and
shows their numbers (a results document made by the benchmark's own table function)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from experiments import benchmark as bench
from experiments.tools import leaderboard as lb


def _metrics(per_test: list[float], runs: int) -> dict[str, Any]:
    met = sum(per_test) / len(per_test)
    return {"tests": len(per_test), "runs": runs, "met": met, "realized": 1.0, "restrictions": 1.0, "steps": 5.0,
            "violated": 0, "open": 0, "test_failures": 0, "per_test": per_test}


def _doc() -> dict[str, Any]:
    config = bench.BenchmarkConfig("safety2/4x4", train_count=4, validation_count=2, test_count=4, seeds=(0, 1),
                                   bootstrap=50, runs=2)
    splits = {n: bench.Split(n, n, [10 * i, 10 * i + 3], []) for i, n in enumerate(bench.SPLIT_NAMES)}

    def row(seed: int | None, sut: str, greedy: list[float] | None, sampled: list[float] | None) -> dict[str, Any]:
        return {"seed": seed, "sut": sut, **{s: {"greedy": greedy and _metrics(greedy, 1),
                                                 "sampled": sampled and _metrics(sampled, 2)} for s in bench.SPLIT_NAMES}}

    systems = [
        bench.SystemRuns("maskable-ppo", "baseline", [row(0, "ppo:a", [1, 1, 0, 1], [1, 0.5, 0.5, 1]),
                                                       row(1, "ppo:b", [1, 0, 0, 1], [1, 0.5, 0, 1])]),
        bench.SystemRuns("random", "floor", [row(None, "random", None, [0.5, 0.5, 0, 0])]),
        bench.SystemRuns("gr1", "reference", [row(None, "gr1", [1, 1, 1, 1], None)]),
    ]
    return bench.benchmark_table(config, splits, systems, [])


def test_the_page_shows_the_results_numbers(tmp_path: Path) -> None:
    doc = _doc()
    assert doc["scale"]["test"] == {"floor": 0.25, "ceiling": 1.0, "ceiling_from": "gr1"}
    greedy = doc["headline"]["normalized_held_out"]["maskable-ppo"]["greedy"]
    # seeds met 3/4 and 2/4: normalized (0.75 - 0.25) / 0.75 and (0.5 - 0.25) / 0.75; IQM of two = their mean
    assert greedy["iqm"] == pytest.approx(0.5) and greedy["low"] <= 0.5 <= greedy["high"]
    (tmp_path / "table.json").write_text(json.dumps(doc))
    results = tmp_path / "results"
    stored = lb.add(tmp_path / "table.json", "tiny", results)
    assert stored.parent == results and json.loads(stored.read_text())["format"] == lb.ENTRY_FORMAT
    assert "\"per_test\"" not in stored.read_text()  # the summary leaves the per-test arrays out
    text = lb.page(lb.load_entries(results))
    assert "## safety2/4x4" in text and "### tiny" in text
    line = next(x for x in text.splitlines() if x.startswith("| maskable-ppo |"))
    assert f"| {greedy['iqm']:.2f} [{greedy['low']:.2f}, {greedy['high']:.2f}] |" in line and "| 62.5 % |" in line
    assert f"Command: `{doc['command']}`" in text
    assert doc["command"].startswith("flowtest benchmark --pool safety2/4x4 --train-count 4")
    # regenerating from the same files gives the same page; a second add keeps both
    assert lb.page(lb.load_entries(results)) == text
    lb.add(tmp_path / "table.json", "tiny", results)
    assert len(list(results.glob("*.json"))) == 2


def test_refuses_a_file_that_is_not_a_result(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "x.json"
    bad.write_text(json.dumps({"format": "something else"}))
    code = lb.main(["--add", str(bad), "--results", str(tmp_path / "r"), "--page", str(tmp_path / "p.md")])
    assert code == 2 and capsys.readouterr().err.startswith("error: not a flowtest benchmark result")
    assert not (tmp_path / "p.md").exists()
