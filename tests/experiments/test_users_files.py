"""Users' files are sacred, and the CLI's remaining tracebacks (issue 13, points 1 and 6).

Every case runs ``main`` in-process and asserts the contract: the documented exit code,
exactly one ``error:`` line on stderr, no traceback, and no file outside the output path
touched (a snapshot of the working folder before and after).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from experiments.cli.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"


def snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in root.rglob("*") if p.is_file() and not p.is_symlink()}


def refused(argv: list[str], capsys: pytest.CaptureFixture[str], words: str, code: int = 2) -> None:
    try:
        got = main(argv)
    except SystemExit as exc:  # argparse usage errors
        got = exc.code
    out, err = capsys.readouterr()
    assert got == code, err
    lines = err.splitlines()
    assert sum(line.startswith("error: ") for line in lines) == 1, err
    assert "Traceback" not in err
    assert words in err, err


@pytest.fixture()
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("precious")
    (tmp_path / "a-file").write_text("precious")
    (tmp_path / "target.json").write_text("precious")
    (tmp_path / "link.json").symlink_to(tmp_path / "target.json")
    shutil.copy(DATA / "ok_grid.toml", tmp_path / "p.toml")
    (tmp_path / "p.json").write_text("precious json")
    (tmp_path / "p.png").write_text("precious png")
    return tmp_path


@pytest.mark.parametrize(
    "argv,words",
    [
        (["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "random", "--episodes", "1", "--out", "mine"], "did not write"),
        (["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "random", "--episodes", "1", "--out", "a-file"], "not a folder"),
        (["evaluate", "--env", "CartPole-v1", "--sut", "random", "--out", "o"], "not a FlowTest environment"),
        (["evaluate", "--env", "Nope-v0", "--sut", "random", "--out", "o"], "unknown environment"),
        (["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "random", "--seed", "-1", "--replay"], "--seed"),
        (["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "random", "--episodes", "0", "--replay"], "--episodes"),
        (["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "ppo:/dev/zero", "--out", "o"], "not a regular file"),
        (["synthesize", "/dev/zero"], "not a regular file"),
        (["synthesize", "small-reactive", "--out", "link.json", "--force"], "symbolic link"),
        (["synthesize", "small-reactive", "--out", "a-file/x.json"], "is a file, not a folder"),
        (["synthesize", "small-reactive", "--out", "mine"], "is a directory"),
        (["synthesize", "small-reactive", "--threads", "100000"], "CPUs"),
        (["synthesize", ""], "empty problem name"),
        (["train", "CartPole-v1", "--out", "m.zip"], "not a FlowTest environment"),
        (["train", "FlowTest-SmallReactive-v0", "--steps", "0", "--out", "m.zip"], "--steps"),
        (["train", "FlowTest-SmallReactive-v0", "--out", "target.json"], "exists; use --force"),
        (["demo", "--out", "mine", "--no-evaluation", "--problems", "small-reactive"], "did not write"),
        (["demo", "--out", "d", "--problems", "nope"], "unknown problem"),
        (["demo", "--out", "d", "--episodes", "-1"], "--episodes"),
        (["frobnicate"], "invalid choice"),
    ],
)
def test_refused_with_one_line_and_nothing_touched(workdir: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str) -> None:
    if "/dev/zero" in " ".join(argv) and not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero here")
    before = snapshot(workdir)
    refused(argv, capsys, words)
    assert snapshot(workdir) == before
    assert (workdir / "link.json").is_symlink()


def test_unwritable_output_refused_before_work(workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A place nothing can be written to (``/proc`` even for root) is refused up front."""
    if not Path("/proc/self").exists():
        pytest.skip("no /proc here")
    refused(["synthesize", "small-reactive", "--out", "/proc/flowtest-x.json"], capsys, "cannot write")
    refused(["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "random", "--out", "/proc/flowtest/x"], capsys, "cannot create")


def test_evaluate_force_and_own_folder(workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "random", "--episodes", "1", "-q"]
    assert main(argv + ["--out", "mine", "--force"]) == 0
    assert (workdir / "mine" / "notes.txt").read_text() == "precious"
    assert main(argv + ["--out", "report"]) == 0
    assert main(argv + ["--out", "report"]) == 0  # its own folder: accepted again
    capsys.readouterr()


def test_demo_writes_only_inside_its_folder(workdir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = snapshot(workdir)
    problems = ["p.toml", str(workdir / "p.toml")]
    assert main(["demo", "--out", "d", "--no-evaluation", "-q", "--problems", *problems]) == 0
    capsys.readouterr()
    after = snapshot(workdir)
    outside = {k for k in after if not k.startswith("d" + os.sep)}
    assert outside == set(before) and all(after[k] == before[k] for k in before)
    names = sorted(p.name for p in (workdir / "d").iterdir())
    assert names == sorted([".flowtest-demo", "summary.json", "summary.md", "ok-grid.json", "ok-grid.png", "ok-grid-2.json", "ok-grid-2.png"])
