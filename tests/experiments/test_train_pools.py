"""``flowtest train --pool <standard id>`` (issue 41 item 6, issue 44 item 1): both trainers
train on a standard pool's shipped tests (nothing synthesized) and print each greedy score
beside the random floor of the same tests."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from experiments.cli.cli import main

pytest.importorskip("sb3_contrib")

STANDARD = "reachability1/5x5-v2"


def _no_synthesis(monkeypatch: pytest.MonkeyPatch) -> None:
    """Building a test of a pool fails the test: a standard pool's tests are shipped."""
    import flowtest_env.random_grid as random_grid

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("a test was synthesized")

    monkeypatch.setattr(random_grid, "pool_record", refuse)


@pytest.mark.parametrize(
    "trainer, flags",
    [
        ("native", ["--n-envs", "8", "--n-steps", "16", "--net-arch", "16", "--eval-every", "0"]),
        ("sb3", ["--n-envs", "2", "--n-steps", "64", "--net-arch", "16"]),
    ],
)
def test_train_on_a_standard_pool_prints_the_floor(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, trainer: str, flags: list[str]
) -> None:
    _no_synthesis(monkeypatch)
    out = tmp_path / "m.zip"
    code = main(
        [
            "train",
            *(["FlowTest-RandomGrid-v0"] if trainer == "sb3" else []),  # with --pool the env may be left out
            "--trainer",
            trainer,
            "--pool",
            STANDARD,
            "--count",
            "8",
            "--heldout-count",
            "6",
            "--steps",
            "256",
            "--out",
            str(out),
            "-q",
            *flags,
        ]
    )
    stdout, err = capsys.readouterr()
    assert code == 0, err
    summary = json.loads(out.with_suffix(".json").read_text())
    for split, line_start in (("train", "greedy on the 8 train tests"), ("heldout", "greedy on 6 held-out tests")):
        line = next(ln for ln in stdout.splitlines() if ln.startswith(line_start))
        met, floor = (float(x) for x in re.findall(r"(\d+\.\d) %", line)[:2])
        assert met == pytest.approx(100 * summary["final"][split]["met"], abs=0.05)
        assert floor == pytest.approx(100 * summary["floor"][split], abs=0.05)
        assert "(random: " in line and "8 runs per test)" in line
    # the floor is random's share met over 8 seeded runs of the same tests
    from flowtest_env.game import TestGame
    from flowtest_env.pools import load_pool
    from flowtest_env.scoring import play_batch, random_policy

    games = [TestGame(a) for a in load_pool(STANDARD, "test", 6)]
    assert summary["floor"]["heldout"] == float(np.mean(play_batch(random_policy(), games, 8, 0)["system_objective"] == "met"))
    assert summary["env_options"]["pool"] == STANDARD


def test_a_standard_pool_split_is_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A -v2 pool ships so many tests per split: asking for more is one error line."""
    code = main(["train", "FlowTest-RandomGrid-v0", "--pool", STANDARD, "--split", "validation", "--count", "100000", "--out", str(tmp_path / "m.zip")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith(f"error: --pool {STANDARD}: ")


def test_train_needs_an_env_or_a_pool(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["train", "--out", str(tmp_path / "m.zip")]) == 2
    err = capsys.readouterr().err
    assert "give the environment to train on" in err and "Traceback" not in err
    assert not (tmp_path / "m.zip").exists()
