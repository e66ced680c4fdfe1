"""A test at hand is not synthesized again: ``flowtest synthesize patrolling`` (146 s of HiGHS when
its artifact was built, 99 % of it proving that no second way through exists) shows its shipped
test in seconds and says so; ``--fresh`` and any option that changes the answer synthesize; a
problem file's cached test that took long is shown the same way."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

import experiments.cli.synthesize as synthesize_command
from experiments.cli.cli import main
from flowtest_env.artifacts import artifact_path
from synthesis import pipeline
from synthesis.artifacts.artifact import TestArtifact

DATA = Path(__file__).resolve().parents[1] / "data"
FLOWTEST = Path(sys.executable).parent / "flowtest"


class Synthesized(Exception):  # noqa: N818 - what happened, as the traceback shows it
    """Raised instead of a synthesis: the command chose to solve (it ends in an internal error)."""


@pytest.fixture
def no_synthesis(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every synthesis asked for, by problem name, raising :class:`Synthesized` instead of solving."""
    asked: list[str] = []

    def refuse(problem: Any, options: Any = None) -> Any:
        asked.append(problem.name)
        raise Synthesized(problem.name)

    monkeypatch.setattr(pipeline, "synthesize", refuse)
    return asked


def test_synthesize_patrolling_shows_its_shipped_test_in_seconds(tmp_path: Path) -> None:
    """The console script, as a user types it: well under the minutes a synthesis takes, the
    summary of the proven optimum, and where it came from on both streams."""
    started = time.perf_counter()
    proc = subprocess.run(
        [str(FLOWTEST), "synthesize", "patrolling", "--out", str(tmp_path / "p.json"), "--plot", str(tmp_path / "p.png")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    seconds = time.perf_counter() - started
    assert proc.returncode == 0, proc.stderr
    assert seconds < 60, f"flowtest synthesize patrolling took {seconds:.0f} s"
    assert proc.stdout.startswith("patrolling: agent test, optimal (proven, gap 0)")
    assert "  stored       the shipped test " in proc.stdout and "--fresh" in proc.stdout
    assert "the shipped test" in proc.stderr and "synthesizing it took 146 s" in proc.stderr
    shipped = TestArtifact.load(artifact_path("patrolling"))
    written = TestArtifact.load(tmp_path / "p.json")
    assert written.to_dict() == shipped.to_dict()
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"


def test_the_stored_summary_is_the_shipped_one(no_synthesis: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["synthesize", "patrolling", "--json", "--time-limit", "5"]) == 0
    out = capsys.readouterr().out
    assert json.loads(out) == json.loads(artifact_path("patrolling").read_text())["summary"]
    assert no_synthesis == []


@pytest.mark.parametrize("argv", [["--fresh"], ["--gap", "0.1"], ["--backend", "cpsat"], ["--setting", "accumulative"], ["--max-walls", "2"]])
def test_fresh_or_another_answer_synthesizes(argv: list[str], no_synthesis: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["synthesize", "patrolling", "--quiet", *argv]) != 0  # the stand-in synthesis raised
    assert no_synthesis == ["patrolling"]
    assert "Synthesized: patrolling" in capsys.readouterr().err


def test_a_quick_builtin_is_synthesized_as_before(no_synthesis: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """small-reactive's shipped test took a fraction of a second: the command solves it."""
    assert main(["synthesize", "small-reactive", "--quiet"]) != 0  # the stand-in synthesis raised
    assert no_synthesis == ["small-reactive"]
    assert "Synthesized: small-reactive" in capsys.readouterr().err


def test_a_problem_files_cached_test_is_shown_when_it_took_long(
    tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A problem file synthesized once (filed in the cache), asked again: shown from the cache when
    its synthesis took at least ``STORED_AFTER`` seconds (lowered here to 0), synthesized again
    otherwise, and after an edit of the file."""
    floor = tmp_path / "floor.toml"
    shutil.copyfile(DATA / "ok_mixed.toml", floor)
    assert main(["synthesize", str(floor), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    calls: list[str] = []
    real = pipeline.synthesize

    def counted(problem: Any, options: Any = None) -> Any:
        calls.append(problem.name)
        return real(problem, options)

    monkeypatch.setattr(pipeline, "synthesize", counted)
    assert main(["synthesize", str(floor), "--quiet"]) == 0  # quick: solved again
    assert calls == ["ok-mixed"]
    capsys.readouterr()
    monkeypatch.setattr(synthesize_command, "STORED_AFTER", 0.0)
    assert main(["synthesize", str(floor), "--json"]) == 0
    out, err = capsys.readouterr()
    assert calls == ["ok-mixed"]
    assert json.loads(out)["cuts"] == first["cuts"] and "its cached test" in err
    assert main(["synthesize", str(floor)]) == 0
    assert "  stored       its cached test" in capsys.readouterr().out
    floor.write_text(floor.read_text() + "\n# edited\n")
    assert main(["synthesize", str(floor), "--quiet"]) == 0
    assert calls == ["ok-mixed", "ok-mixed"]
