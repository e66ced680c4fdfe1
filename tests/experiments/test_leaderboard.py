"""experiments/tools/leaderboard.py: docs/leaderboard.md is built from result files only, and
shows their numbers (a results document made by the benchmark's own table function)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from experiments import benchmark as bench
from experiments.benchmark.table import interval_text
from experiments.tools import leaderboard as lb


def _metrics(per_test: list[float], runs: int) -> dict[str, Any]:
    met = sum(per_test) / len(per_test)
    return {
        "tests": len(per_test),
        "runs": runs,
        "met": met,
        "realized": 1.0,
        "restrictions": 1.0,
        "steps": 5.0,
        "violated": 0,
        "open": 0,
        "test_failures": 0,
        "per_test": per_test,
    }


def _doc() -> dict[str, Any]:
    config = bench.BenchmarkConfig("safety2/4x4", train_count=4, validation_count=2, test_count=4, seeds=(0, 1), bootstrap=50, runs=2)
    splits = {n: bench.Split(n, n, [10 * i, 10 * i + 3], []) for i, n in enumerate(bench.SPLIT_NAMES)}

    def row(seed: int | None, sut: str, greedy: list[float] | None, sampled: list[float] | None) -> dict[str, Any]:
        return {
            "seed": seed,
            "sut": sut,
            **{s: {"greedy": greedy and _metrics(greedy, 1), "sampled": sampled and _metrics(sampled, 2)} for s in bench.SPLIT_NAMES},
        }

    systems = [
        bench.SystemRuns("maskable-ppo", "baseline", [row(0, "ppo:a", [1, 1, 0, 1], [1, 0.5, 0.5, 1]), row(1, "ppo:b", [1, 0, 0, 1], [1, 0.5, 0, 1])]),
        bench.SystemRuns("random", "floor", [row(None, "random", None, [0.5, 0.5, 0, 0])]),
        bench.SystemRuns("gr1", "reference", [row(None, "gr1", [1, 1, 1, 1], None)]),
    ]
    return bench.benchmark_table(config, splits, systems, [])


def test_the_page_shows_the_results_numbers(tmp_path: Path) -> None:
    doc = _doc()
    assert doc["scale"]["test"] == {"floor": 0.25, "ceiling": 1.0, "ceiling_from": "gr1", "floor_runs": 2, "ceiling_is_bound": True}
    greedy = doc["headline"]["normalized_held_out"]["maskable-ppo"]["greedy"]
    sampled = doc["headline"]["normalized_held_out"]["maskable-ppo"]["sampled"]
    # seeds met 3/4 and 2/4: normalized (0.75 - 0.25) / 0.75 and (0.5 - 0.25) / 0.75; 2 seeds: preliminary, their mean
    assert greedy["point"] == pytest.approx(0.5) and greedy["low"] <= 0.5 <= greedy["high"]
    assert greedy["preliminary"] and greedy["statistic"] == "mean"
    (tmp_path / "table.json").write_text(json.dumps(doc))
    results = tmp_path / "results"
    stored = lb.add(tmp_path / "table.json", "tiny", results)
    assert stored.parent == results and json.loads(stored.read_text())["format"] == lb.ENTRY_FORMAT
    assert '"per_test"' not in stored.read_text()  # the train and validation per-test arrays are left out
    text = lb.page(lb.load_entries(results))
    assert "## safety2/4x4" in text and "### tiny" in text
    line = next(x for x in text.splitlines() if x.startswith("| maskable-ppo |"))
    assert line.startswith(f"| maskable-ppo | baseline | 2 | {interval_text(sampled)} | {interval_text(greedy)} |")
    assert f"| {greedy['point']:.2f} [{greedy['low']:.2f}, {greedy['high']:.2f}]† |" in line and "| 62.5 % |" in line
    assert f"Command: `{doc['command']}`" in text and "**Trained**: maskable-ppo" not in text  # nothing trained here
    assert doc["command"].startswith("flowtest benchmark --pool safety2/4x4 --train-count 4")
    # regenerating from the same files gives the same page; a second add keeps both
    assert lb.page(lb.load_entries(results)) == text
    lb.add(tmp_path / "table.json", "tiny", results)
    assert len(list(results.glob("*.json"))) == 2


def test_the_summary_keeps_the_held_out_matrices_and_its_numbers_recompute(tmp_path: Path) -> None:
    """The summary holds every system's held-out per-run scores (met-run counts), as rliable
    reads them (:func:`matrices`); the statistics recomputed from them alone equal the stored
    ones."""
    from flowtest_env.scoring import score_interval, tail_score

    doc = _doc()
    (tmp_path / "table.json").write_text(json.dumps(doc))
    entry = json.loads(lb.add(tmp_path / "table.json", "tiny", tmp_path / "r").read_text())
    sampled, greedy = lb.matrices(entry, "sampled"), lb.matrices(entry, "greedy")
    assert sampled["maskable-ppo"].tolist() == [[1, 0.5, 0.5, 1], [1, 0.5, 0, 1]]
    assert greedy["maskable-ppo"].tolist() == [[1, 1, 0, 1], [1, 0, 0, 1]] and sampled["random"].tolist() == [[0.5, 0.5, 0, 0]]
    assert entry["scores"]["test"]["sampled"]["random"]["met_runs"] == [[1, 1, 0, 0]]
    floor, ceiling = sampled["random"][0], greedy[entry["scale"]["test"]["ceiling_from"]][0]
    stored = next(s for s in entry["systems"] if s["name"] == "maskable-ppo")["test"]
    for mode, m in (("sampled", sampled), ("greedy", greedy)):
        again = score_interval(m["maskable-ppo"], floor, ceiling, reps=entry["config"]["bootstrap"])
        assert again is not None and again.to_json() == stored[mode]["normalized"]
        assert tail_score(m["maskable-ppo"]).to_json() == stored[mode]["tail"]


def test_a_v1_summary_is_shown_with_its_old_statistics(tmp_path: Path) -> None:
    """A summary of the first format has no matrices: it keeps its old numbers, labelled
    *v1, old statistics*, with the t interval over the seed means recomputed from its stored
    mean and t half-width, and says what the run trained."""
    old = next(lb.RESULTS_DIR.glob("safety2-5x5-fuel-v1--6d2af8d8--*.json"))
    results = tmp_path / "r"
    results.mkdir()
    (results / old.name).write_text(old.read_text())
    entry = lb.load_entries(results)[0]
    assert entry["version"] == 1 and lb.matrices(entry) == {}
    text = lb.page([entry])
    assert "*v1, old statistics*" in text and "reference on the held-out tests: 2.6 % / 41.0 % (the best reference" in text
    assert "**Trained**: maskable-ppo, seeds 0-2 (3 runs), 250,000 time steps each on the first 1,024 train tests" in text
    row = next(s for s in entry["systems"] if s["name"] == "maskable-ppo")["test"]["greedy"]
    f, c = entry["scale"]["test"]["floor"], entry["scale"]["test"]["ceiling"]
    mean, half = (row["met"] - f) / (c - f), row["met_ci95"] / (c - f)
    line = next(x for x in text.splitlines() if x.startswith("| maskable-ppo |"))
    assert f"| {mean:.2f} [{mean - half:.2f}, {mean + half:.2f}] |" in line
    assert f"| {row['normalized']['iqm']:.2f} [{row['normalized']['low']:.2f}, {row['normalized']['high']:.2f}] |" in line


def test_refuses_a_result_of_the_old_version(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    doc = _doc()
    doc["version"] = 2
    (tmp_path / "t.json").write_text(json.dumps(doc))
    code = lb.main(["--add", str(tmp_path / "t.json"), "--results", str(tmp_path / "r"), "--page", str(tmp_path / "p.md")])
    assert code == 2 and "version 2, not 3" in capsys.readouterr().err


def test_refuses_a_file_that_is_not_a_result(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "x.json"
    bad.write_text(json.dumps({"format": "something else"}))
    code = lb.main(["--add", str(bad), "--results", str(tmp_path / "r"), "--page", str(tmp_path / "p.md")])
    assert code == 2 and capsys.readouterr().err.startswith("error: not a flowtest benchmark result")
    assert not (tmp_path / "p.md").exists()
