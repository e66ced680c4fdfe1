"""experiments/lab/time_to_score.py: the plateau and the times to it, on made-up curves (no
training): a run's plateau is the mean of its last evaluations, but a trainer whose points are
separate runs per budget (CleanRL) is judged on its largest budget alone, and a run whose last
point jumps above the one before by more than the interval is said to be still rising."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from experiments.lab import time_to_score as tts


def _run(trainer: str, mets: list[float], seed: int = 0) -> tts.Run:
    points = [tts.Point(seconds=10.0 * i, cpu=10.0 * i, steps=1000 * i, met={"heldout": m}) for i, m in enumerate(mets)]
    return tts.Run(trainer=trainer, seed=seed, phase="heldout", points=points, steps_per_second=100.0)


def test_the_plateau_of_one_run_is_its_last_evaluations_and_of_budget_runs_the_largest() -> None:
    flat = tts.plateau(_run("native", [0.1, 0.5, 0.80, 0.81, 0.79]), "heldout", 3, 1000)
    assert flat["met"] == pytest.approx(0.80) and flat["rising"] == 0.0
    budgets = tts.plateau(_run("cleanrl", [0.3, 0.5, 0.6, 0.8]), "heldout", 3, 1000)
    assert budgets["met"] == pytest.approx(0.8) and budgets["rising"] == 1.0  # 0.6 -> 0.8 is far beyond the half-width


def test_times_to_the_common_target_and_a_stored_run_resummarizes(tmp_path: Path) -> None:
    runs = [_run("native", [0.0, 0.7, 0.85, 0.86, 0.85]), _run("sb3", [0.0, 0.3, 0.6, 0.70, 0.71, 0.70])]
    s = tts.summarize(runs, 0.95, "heldout", 1000, 3, 0.5, 1.0)
    common = s["heldout_target"]["sb3_plateau_low_met"]
    assert common == pytest.approx(0.7033 - tts.binomial_half_width(0.7033, 1000), abs=1e-3)
    assert s["heldout"]["native"]["seconds_to_sb3_plateau"] == [10.0]  # 0.70 >= the target's lower end
    assert s["heldout"]["sb3"]["seconds_to_sb3_plateau"] == [30.0]
    assert s["heldout"]["native"]["still_rising"] == [False]
    path = tmp_path / "tts.json"
    from dataclasses import asdict

    path.write_text(json.dumps({"runs": [asdict(r) for r in runs], "summary": s}))
    assert tts.main(["--summarize", str(path)]) == 0
    assert json.loads(path.read_text())["summary"]["heldout"] == json.loads(json.dumps(s["heldout"]))
