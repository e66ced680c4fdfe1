"""No silent work: ``flowtest evaluate --env floor.toml`` after ``flowtest synthesize floor.toml
--out t.json`` plays the cached test without synthesizing again; on a problem it must synthesize
it shows the progress ``flowtest synthesize`` shows and honours ``--time-limit``; the cache key
names every option that changes the answer, so a synthesis under other options never serves,
nor replaces, the default's entry.

Every test here runs with a private cache (the ``cache`` fixture of tests/conftest.py) and
counts the syntheses by wrapping :func:`synthesis.pipeline.synthesize`, which both commands call.
"""

from __future__ import annotations

import io
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from experiments.cli.cli import build_parser, main
from experiments.cli.synthesize import options_of
from flowtest_env import sources
from synthesis import pipeline
from synthesis.artifacts.artifact import TestArtifact
from synthesis.options import SynthesisOptions

DATA = Path(__file__).resolve().parents[1] / "data"
FLOWTEST = Path(sys.executable).parent / "flowtest"


@pytest.fixture
def syntheses(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[Any]]:
    """The options of every synthesis run in this process (one entry per call)."""
    calls: list[Any] = []
    real = pipeline.synthesize

    def counted(problem: Any, options: Any = None) -> Any:
        calls.append(options)
        return real(problem, options)

    monkeypatch.setattr(pipeline, "synthesize", counted)
    yield calls


@pytest.fixture
def floor(tmp_path: Path) -> Path:
    """A user's problem file (a mixed test: walls and doors)."""
    path = tmp_path / "floor.toml"
    shutil.copyfile(DATA / "ok_mixed.toml", path)
    return path


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _evaluate(floor: Path, tmp_path: Path, *more: str) -> list[str]:
    return ["evaluate", "--env", str(floor), "--sut", "scripted:replanner", "--episodes", "2", "--out", str(tmp_path / "report"), "--force", *more]


def test_evaluate_after_synthesize_does_not_synthesize_again(
    floor: Path, tmp_path: Path, cache: Path, syntheses: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    out_file = tmp_path / "t.json"
    code, _, err = _run(["synthesize", str(floor), "--out", str(out_file)], capsys)
    assert code == 0, err
    assert len(syntheses) == 1
    assert f"cached for flowtest evaluate --env {floor}" in err
    sources._LOADED.clear()  # what a new process starts from: only the cache on disk
    code, out, err = _run(_evaluate(floor, tmp_path), capsys)
    assert code == 0, err
    assert len(syntheses) == 1, "flowtest evaluate synthesized the problem again"
    assert "its cached test" in err and "synthesizing" not in err
    assert "met  100 %" in out
    # the test evaluated is the one flowtest synthesize wrote
    entry = TestArtifact.load(next((cache / "problems").glob("floor-*.json")))
    written = TestArtifact.load(out_file)
    assert entry.summary["cuts"] == written.summary["cuts"]
    assert (entry.strategy.restrictions == written.strategy.restrictions).all()


def test_the_console_scripts_share_the_cache(floor: Path, tmp_path: Path) -> None:
    """The same as two real processes, as a user types them: the evaluation says it found the
    cached test and no synthesis stage appears."""
    env = {**os.environ, "FLOWTEST_CACHE_DIR": str(tmp_path / "cache")}
    first = subprocess.run([str(FLOWTEST), "synthesize", str(floor), "--out", str(tmp_path / "t.json")], capture_output=True, text=True, timeout=300, env=env)
    assert first.returncode == 0, first.stderr
    assert "routing MILP" in first.stderr
    second = subprocess.run([str(FLOWTEST), *_evaluate(floor, tmp_path)], capture_output=True, text=True, timeout=300, env=env)
    assert second.returncode == 0, second.stderr
    assert "its cached test" in second.stderr
    assert "synthesizing" not in second.stderr and "routing MILP" not in second.stderr


def test_evaluate_shows_the_synthesis_it_must_do_and_caches_it(
    floor: Path, tmp_path: Path, cache: Path, syntheses: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = _run(_evaluate(floor, tmp_path), capsys)
    assert code == 0, err
    assert len(syntheses) == 1
    lines = err.splitlines()
    for stage in (
        "flowtest: synthesizing ok-mixed (mixed test; no time limit",
        "flowtest: building automata and product graphs",
        "flowtest: routing MILP, phase 1 of 2",
        "flowtest: checking the test",
        f"flowtest: {floor}: its test is cached in",
    ):
        assert any(line.startswith(stage) for line in lines), (stage, err)
    assert "\r" not in err  # not a terminal: plain stage lines
    assert "routing MILP" not in out  # stdout holds the outcome lines only
    sources._LOADED.clear()
    code, _, err = _run(_evaluate(floor, tmp_path), capsys)
    assert code == 0 and len(syntheses) == 1 and "its cached test" in err
    sources._LOADED.clear()
    code, _, err = _run([*_evaluate(floor, tmp_path), "--quiet"], capsys)
    assert code == 0 and "its cached test" not in err


def test_evaluate_passes_its_time_limit_to_the_synthesis(
    floor: Path, tmp_path: Path, cache: Path, syntheses: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = _run(_evaluate(floor, tmp_path, "--time-limit", "45"), capsys)
    assert code == 0, err
    assert [o.time_limit for o in syntheses] == [45.0]
    assert "the time limit of 45 s bounds it" in err
    with pytest.raises(SystemExit) as refused:
        main(_evaluate(floor, tmp_path, "--time-limit", "-1"))
    assert refused.value.code == 2 and "error: flowtest evaluate: argument --time-limit" in capsys.readouterr().err


def test_evaluate_shows_the_live_line_on_a_terminal(
    floor: Path, tmp_path: Path, cache: Path, syntheses: list[Any], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """On a terminal the synthesis's stages share one live line (rewritten with ``\\r``), as
    ``flowtest synthesize``'s do."""

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert main(_evaluate(floor, tmp_path)) == 0
    text = terminal.getvalue()
    assert "\rflowtest: synthesizing ok-mixed" in text and "\rflowtest: routing MILP, phase 1 of 2" in text
    assert len(syntheses) == 1


def test_replay_of_a_problem_file_shows_its_synthesis(floor: Path, cache: Path, syntheses: list[Any], capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = _run(["evaluate", "--env", str(floor), "--sut", "scripted:replanner", "--episodes", "1", "--replay"], capsys)
    assert code == 0, err
    assert len(syntheses) == 1 and "flowtest: synthesizing ok-mixed" in err
    assert out.startswith("scripted:replanner on ") and "routing MILP" not in out


def test_other_answer_options_do_not_poison_the_default_entry(
    floor: Path, tmp_path: Path, cache: Path, syntheses: list[Any], capsys: pytest.CaptureFixture[str]
) -> None:
    """A synthesis under the accumulative setting (another test: what it shows) files its own
    entry; the evaluation, which asks for the default, synthesizes the default's and plays
    the instantaneous test."""
    code, _, err = _run(["synthesize", str(floor), "--setting", "accumulative"], capsys)
    assert code == 0, err
    sources._LOADED.clear()
    code, _, err = _run(_evaluate(floor, tmp_path), capsys)
    assert code == 0, err
    assert len(syntheses) == 2 and "synthesizing ok-mixed" in err
    entries = sorted((cache / "problems").glob("floor-*.json"))
    assert len(entries) == 2
    assert sorted(TestArtifact.load(p).strategy.setting for p in entries) == ["accumulative", "instantaneous"]
    raw = floor.read_bytes()
    assert sources.problem_cache_path(floor, raw) != sources.problem_cache_path(floor, raw, SynthesisOptions(setting="accumulative"))


def _options(*argv: str) -> SynthesisOptions:
    """The options ``flowtest synthesize x.toml ARGV`` synthesizes under."""
    return options_of(build_parser().parse_args(["synthesize", "x.toml", *argv]))


def test_the_cache_key_names_every_option_that_changes_the_answer() -> None:
    """``flowtest synthesize`` without options files its answer under the key ``flowtest evaluate``
    (its own ``--time-limit`` or none) looks up; each option that changes the answer gives
    another key; the budgets that only stop a search do not."""
    default = sources.answer_options()
    for same in ((), ("--time-limit", "30"), ("--after-first", "5", "--time-limit", "60"), ("--threads", "1"), ("--progress", "2"), ("--no-size-limit",)):
        assert sources.answer_options(_options(*same)) == default, same
    assert sources.answer_options(SynthesisOptions(time_limit=12.0, node_limit=500)) == default
    others = [("--gap", "0.1"), ("--backend", "highs"), ("--setting", "accumulative"), ("--max-walls", "3"), ("--max-doors", "0"), ("--max-restrictions", "2")]
    if (os.cpu_count() or 1) >= 2:
        others.append(("--threads", "2"))
    keys = {json.dumps(sources.answer_options(_options(*o)), sort_keys=True) for o in others}
    assert len(keys) == len(others) and json.dumps(default, sort_keys=True) not in keys
