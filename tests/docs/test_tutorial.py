"""docs/tutorial.md runs as written: its TOML is saved as the problem file it names, each
command and each Python block runs in order in an empty folder (a private cache), and what the
page says they produce is there. A small training budget keeps it fast."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "tutorial.md"


def blocks() -> list[tuple[str, str]]:
    """``(language, text)`` of every fenced block, in page order."""
    return re.findall(r"```(toml|bash|python)\n(.*?)```", PAGE.read_text(), flags=re.S)


def _run(argv: list[str], cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{shlex.join(argv)} exited {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done


def test_the_tutorial_runs_as_written(tmp_path: Path) -> None:
    pytest.importorskip("sb3_contrib")
    env = {
        **os.environ,
        "FLOWTEST_CACHE_DIR": str(tmp_path / "cache"),
        "MPLBACKEND": "Agg",
        "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
    }
    work = tmp_path / "work"
    work.mkdir()
    seen = {"toml": 0, "bash": 0, "python": 0}
    for lang, text in blocks():
        seen[lang] += 1
        if lang == "toml":
            (work / "warehouse.toml").write_text(text)
        elif lang == "bash":
            for line in text.strip().splitlines():
                argv = shlex.split(line)
                assert argv[0] == "flowtest", line
                _run([sys.executable, "-m", "experiments", *argv[1:]], work, env)
        else:
            _run([sys.executable, "-c", text], work, env)
    assert seen == {"toml": 1, "bash": 3, "python": 2}
    for name in ("warehouse.png", "warehouse.json", "ppo-warehouse.zip", "ppo-warehouse.json", "report/report.html"):
        assert (work / name).exists(), name
    settings = json.loads((work / "ppo-warehouse.json").read_text())["settings"]
    assert settings["memory"] == "visited" and settings["shaping"] == 10.0
    rates = {r["sut"]: r["system_objective_met_rate"] for r in json.loads((work / "report" / "results.json").read_text())}
    assert rates["scripted:replanner"] == 1.0 and rates["gr1"] == 1.0  # as the page says
    assert set(rates) == {"scripted:replanner", "scripted:greedy", "gr1", "ppo:ppo-warehouse.zip"}
    summary = json.loads((work / "warehouse.json").read_text())["summary"]
    assert summary["bypass_flow"] == 0 and summary["status"] == "optimal"
