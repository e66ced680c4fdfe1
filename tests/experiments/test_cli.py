"""The ``flowtest synthesize`` command line against its public contract (problem-format.md).

Most tests call :func:`experiments.cli.cli.main` in-process (fast); a few run the installed
console script in a subprocess to check what a user really sees: the exit code, one
JSON object on stdout, and exactly one ``error:`` line (never a traceback) on stderr.
"""

from __future__ import annotations

import ctypes
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from experiments.cli import cli
from experiments.cli.cli import main
from experiments.cli.command import Command
from experiments.cli.commands import COMMANDS
from experiments.progress import StageProgress
from synthesis import pipeline
from synthesis.artifacts.artifact import TestArtifact
from synthesis.model.errors import CheckFailed, InconsistentProblem
from synthesis.problems.load import load_problem
from tests.testing_processes import start_until

DATA = Path(__file__).resolve().parents[1] / "data"
FLOWTEST = Path(sys.executable).parent / "flowtest"

#: built-in problem -> how its states are written (problem-format.md)
BUILTIN_STATE_KINDS = {
    "example1": "grid",
    "small-reactive": "grid",
    "beaver-rescue": "graph",
    "motion-primitives": "graph",
    "refueling": "fuel",
}


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """``main(argv)`` with its exit code, stdout and stderr."""
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def run_script(*args: str) -> subprocess.CompletedProcess[str]:
    """The installed ``flowtest`` console script, as a user runs it."""
    return subprocess.run([str(FLOWTEST), *args], capture_output=True, text=True, timeout=120)


# --------------------------------------------------------------------------- JSON contract


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _check_state(state: Any, kind: str, states: set[str] | None) -> None:
    """A state written as problem-format.md says: [r, c], [[r, c], fuel] or a name."""
    if kind == "grid":
        assert isinstance(state, list) and len(state) == 2 and all(_is_int(v) for v in state), state
    elif kind == "fuel":
        assert isinstance(state, list) and len(state) == 2, state
        cell, fuel = state
        assert isinstance(cell, list) and len(cell) == 2 and all(_is_int(v) for v in cell), state
        assert _is_int(fuel) and fuel >= 0, state
    else:
        assert isinstance(state, str) and states is not None and state in states, state


def check_summary(summary: dict, name: str, kind: str) -> None:
    """Every field of the ``--json`` object, with its type, as problem-format.md fixes it."""
    problem = load_problem(name)
    names = {str(s) for s in problem.system.states} if kind == "graph" else None
    required = {
        "problem",
        "environment",
        "status",
        "flow",
        "n_cuts",
        "cuts",
        "restrictions",
        "static_obstacles",
        "bypass_flow",
        "stats",
    }
    assert required <= set(summary), required - set(summary)
    assert summary["problem"] == name
    assert summary["environment"] == problem.kind
    assert summary["status"] == "optimal"
    assert _is_int(summary["flow"]) and summary["flow"] >= 1
    assert _is_int(summary["n_cuts"]) and summary["n_cuts"] == len(summary["cuts"])
    assert summary["bypass_flow"] == 0 and _is_int(summary["bypass_flow"])

    cut_moves: set[tuple[str, str, str]] = set()
    for cut in summary["cuts"]:
        assert set(cut) == {"from", "to"}
        for end in (cut["from"], cut["to"]):
            assert isinstance(end, list) and len(end) == 2
            _check_state(end[0], kind, names)
            assert isinstance(end[1], str)
        cut_moves.add((cut["from"][1], json.dumps(cut["from"][0]), json.dumps(cut["to"][0])))

    assert isinstance(summary["restrictions"], dict)
    for history, moves in summary["restrictions"].items():
        assert isinstance(history, str) and isinstance(moves, list) and moves
        for move in moves:
            assert isinstance(move, list) and len(move) == 2
            for s in move:
                _check_state(s, kind, names)
            # C(q) comes from the cuts whose tail has history q
            assert (history, json.dumps(move[0]), json.dumps(move[1])) in cut_moves, (history, move)

    assert isinstance(summary["static_obstacles"], list)
    for move in summary["static_obstacles"]:
        assert isinstance(move, list) and len(move) == 2
        for s in move:
            _check_state(s, kind, names)
    if problem.kind == "static":
        assert summary["static_obstacles"], "a static test restricts through walls"
    else:
        assert summary["restrictions"], "a reactive test restricts something"

    stats = summary["stats"]
    for key, fields in {
        "transition_system": ("states", "transitions"),
        "automaton": ("states", "transitions"),
        "graph": ("nodes", "edges"),
    }.items():
        assert set(fields) <= set(stats[key])
        assert all(_is_int(stats[key][f]) and stats[key][f] > 0 for f in fields), stats[key]
    assert stats["transition_system"]["states"] == problem.system.n_states
    assert stats["transition_system"]["transitions"] == problem.system.n_moves
    for key in ("binary_vars", "continuous_vars", "constraints"):
        assert _is_int(stats[key]) and stats[key] >= 0, key
    for key in ("graph_seconds", "solve_seconds", "mip_gap"):
        assert isinstance(stats[key], float) and stats[key] >= 0.0, key
    assert stats["mip_gap"] == 0.0


@pytest.mark.parametrize("name", list(BUILTIN_STATE_KINDS))
def test_synthesize_builtin_json(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / f"{name}.png"
    code, out, err = run(["synthesize", name, "--json", "--plot", str(png)], capsys)
    assert code == 0, err
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000
    summary = json.loads(out)  # exactly one JSON object, nothing else on stdout
    assert isinstance(summary, dict)
    assert out.strip().count("\n") == 0
    check_summary(summary, name, BUILTIN_STATE_KINDS[name])
    assert "Traceback" not in err
    assert err.strip(), "progress lines go to stderr"


@pytest.mark.slow
def test_synthesize_mars_exploration_json(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["synthesize", "mars-exploration", "--json"], capsys)
    assert code == 0, err
    check_summary(json.loads(out), "mars-exploration", "fuel")


def test_console_script_json_stdout_only() -> None:
    proc = run_script("synthesize", "small-reactive", "--json")
    assert proc.returncode == 0, proc.stderr
    check_summary(json.loads(proc.stdout), "small-reactive", "grid")
    lines = proc.stderr.splitlines()
    assert lines and all(line.startswith("flowtest: ") for line in lines), proc.stderr
    assert "\r" not in proc.stderr  # not a TTY: plain stage lines, no live indicator


def test_json_stdout_whatever_a_library_prints(capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A library that writes to file descriptor 1 during synthesis -- ``write(1, ...)``,
    C's ``printf``, Python's ``print`` -- does not reach stdout: it holds only our JSON."""
    real = pipeline.synthesize

    def noisy(problem: Any, options: Any = None) -> Any:
        os.write(1, b"noise from write(1)\n")
        ctypes.CDLL(None).printf(b"noise from printf\n")
        print("noise from print")
        test = real(problem, options)
        os.write(1, b"noise after the solve\n")
        return test

    monkeypatch.setattr(pipeline, "synthesize", noisy)
    code = main(["synthesize", "small-reactive", "--json", "--quiet"])
    out, err = capfd.readouterr()
    assert code == 0, err
    assert json.loads(out)["problem"] == "small-reactive"
    assert out.count("\n") == 1 and "noise" not in out and "noise" not in err
    os.write(1, b"after\n")  # fd 1 is restored
    assert capfd.readouterr().out == "after\n"


def test_python_dash_m() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "experiments", "synthesize", "small-reactive", "--json", "--quiet"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["problem"] == "small-reactive"
    assert proc.stderr == ""


def test_toml_file_graph_and_mixed(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["synthesize", str(DATA / "ok_graph.toml"), "--json"], capsys)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["problem"] == "ok-graph" and summary["environment"] == "reactive"
    assert all(isinstance(s, str) for c in summary["cuts"] for s in (c["from"][0], c["to"][0]))
    code, out, err = run(["synthesize", str(DATA / "ok_mixed.toml"), "--json"], capsys)
    assert code == 0, err
    summary = json.loads(out)
    assert summary["environment"] == "mixed"
    assert summary["static_obstacles"] and summary["restrictions"]


def test_human_summary(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["synthesize", "small-reactive"], capsys)
    assert code == 0, err
    assert "optimal" in out and "flow" in out and "cuts" in out
    assert "q3 [saw I2]" in out  # restrictions by history, with what the history means
    assert "static walls none" in out
    assert "solve" in out
    assert "flowtest:" not in out  # progress never on stdout
    code, out, err = run(["synthesize", "example1", "--quiet"], capsys)
    assert code == 0 and err == ""
    # example1 has several optimal wall sets; the summary must list the one found
    walls = next(line for line in out.splitlines() if "static walls" in line)
    assert "none" not in walls and ("|" in walls or "->" in walls)


def test_options_reach_the_solver(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, Any] = {}
    real = pipeline.synthesize

    def spy(problem: Any, options: Any) -> Any:
        seen.update(vars(options))
        return real(problem, options)

    monkeypatch.setattr(pipeline, "synthesize", spy)
    argv = [
        "synthesize",
        "small-reactive",
        "--json",
        "--time-limit",
        "30",
        "--gap",
        "0.01",
        "--threads",
        "1",
        "--setting",
        "accumulative",
        "--after-first",
        "5",
    ]
    code, out, err = run(argv, capsys)
    assert code == 0, err
    assert seen["time_limit"] == 30.0 and seen["mip_rel_gap"] == 0.01 and seen["threads"] == 1
    assert seen["after_first"] == 5.0
    assert seen["setting"] == "accumulative" and callable(seen["progress"])


@pytest.mark.parametrize(
    "args",
    [["--time-limit", "0"], ["--time-limit", "soon"], ["--after-first", "-1"], ["--gap", "2"], ["--threads", "0"], ["--setting", "sometimes"]],
)
def test_bad_options_exit_2(args: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["synthesize", "small-reactive", *args])
    assert exc.value.code == 2
    assert "error:" in capsys.readouterr().err


# --------------------------------------------------------------------------- invalid input


def assert_one_error_line(code: int, out: str, err: str, expected_code: int, *needles: str) -> str:
    """Exit code, nothing on stdout, exactly one ``error: ...`` line on stderr."""
    assert code == expected_code, err
    assert out == ""
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if not line.startswith("flowtest: ")]
    assert len(errors) == 1 and errors[0].startswith("error: "), err
    for needle in needles:
        assert needle in errors[0], (needle, errors[0])
    return errors[0]


@pytest.mark.parametrize(
    ("file", "needles"),
    [
        ("bad_syntax.toml", ["invalid TOML", "line 3"]),
        ("unknown_top_key.toml", ["'solver'", "top level"]),
        ("unknown_section_key.toml", ["'strat'", "[system]"]),
        ("unknown_proposition.toml", ["'teleporter'"]),
        ("fragment_gf.toml", ["G(F goal)", "fragment"]),
        ("fragment_until.toml", ["U I", "fragment"]),
        ("start_blocked.toml", ["start", "blocked"]),
        ("missing_start.toml", ["`start`"]),
        ("missing_terminal.toml", ["`terminal`"]),
        ("no_terminal.toml", ["terminal", "empty"]),
        ("empty_grid.toml", ["grid", "empty"]),
    ],
)
def test_invalid_problem_file(file: str, needles: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["synthesize", str(DATA / file), "--json"], capsys)
    line = assert_one_error_line(code, out, err, 2, *needles)
    assert file in line  # says where


def test_nonexistent_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.toml"
    code, out, err = run(["synthesize", str(missing)], capsys)
    assert_one_error_line(code, out, err, 2, "nope.toml")
    code, out, err = run(["synthesize", "no-such-builtin"], capsys)
    assert_one_error_line(code, out, err, 2, "no-such-builtin", "small-reactive")


def test_garbage_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("this is { not ] a problem\n")
    code, out, err = run(["synthesize", str(text)], capsys)
    assert_one_error_line(code, out, err, 2, "notes.txt", "invalid TOML")
    binary = tmp_path / "noise.toml"
    binary.write_bytes(bytes(range(256)) * 4)
    code, out, err = run(["synthesize", str(binary)], capsys)
    assert_one_error_line(code, out, err, 2, "noise.toml")
    directory = tmp_path / "adir.toml"
    directory.mkdir()
    code, out, err = run(["synthesize", str(directory)], capsys)
    assert_one_error_line(code, out, err, 2, "adir.toml")


def test_invalid_input_through_the_console_script() -> None:
    proc = run_script("synthesize", str(DATA / "fragment_gf.toml"), "--json")
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("error: ")
    assert "Traceback" not in proc.stderr


# --------------------------------------------------------------------------- inconsistent


@pytest.mark.parametrize(
    ("file", "reason"),
    [
        ("unreachable.toml", "unreachable"),
        ("unroutable_walled.toml", "unroutable"),
        ("unroutable_behind_goal.toml", "unroutable"),
    ],
)
def test_inconsistent_problem_exit_3(file: str, reason: str, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["synthesize", str(DATA / file), "--json"], capsys)
    line = assert_one_error_line(code, out, err, 3, reason)
    other = {"unreachable": "unroutable", "unroutable": "unreachable"}[reason]
    assert other not in line


def test_inconsistent_through_the_console_script() -> None:
    proc = run_script("synthesize", str(DATA / "unreachable.toml"), "--quiet")
    assert proc.returncode == 3 and proc.stdout == ""
    assert proc.stderr.startswith("error: inconsistent problem (unreachable)")
    assert proc.stderr.count("\n") == 1


# --------------------------------------------------------------------------- bugs, time, Ctrl-C


def _raising(exc: BaseException) -> Any:
    def synthesize(problem: Any, options: Any) -> Any:
        raise exc

    return synthesize


def test_check_failed_exit_4(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "synthesize", _raising(CheckFailed("bypass flow 1")))
    code, out, err = run(["synthesize", "small-reactive", "--json"], capsys)
    line = assert_one_error_line(code, out, err, 4, "bypass flow 1")
    assert "FLOWTEST BUG" in line


def test_timeout_exit_5(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "synthesize", _raising(TimeoutError("no solution within the time limit")))
    code, out, err = run(["synthesize", "small-reactive", "--json", "--time-limit", "1"], capsys)
    line = assert_one_error_line(code, out, err, 5, "time limit")
    assert "--time-limit" in line


def test_keyboard_interrupt_exit_130(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "synthesize", _raising(KeyboardInterrupt()))
    code, out, err = run(["synthesize", "small-reactive", "--json"], capsys)
    assert code == 130 and out == ""
    assert "Traceback" not in err and "error:" not in err
    # one line says so (issue 12), after the stage lines
    assert err.splitlines()[-1] == "flowtest: interrupted" and err.count("interrupted") == 1


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_ctrl_c_on_the_console_script(sig: signal.Signals, tmp_path: Path) -> None:
    """SIGINT (Ctrl-C) while HiGHS runs a long solve (mars-exploration's branch and bound):
    exit 130 within 2 s, one line, no traceback, nothing on stdout, no (partial or hidden)
    output file; SIGTERM takes the same path."""
    art = tmp_path / "mars.json"
    proc = start_until(
        [str(FLOWTEST), "synthesize", "mars-exploration", "--json", "--out", str(art), "--progress", "0.3"],
        "bound",
        sig,  # a status line with a bound: HiGHS's search runs
    )
    t0 = time.perf_counter()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    elapsed = time.perf_counter() - t0
    assert proc.returncode == 130, err
    assert elapsed < 2.0, f"exit {elapsed:.2f} s after {sig.name}"
    assert out == "" and "Traceback" not in err
    assert err.splitlines()[-1] == "flowtest: interrupted"
    assert list(tmp_path.iterdir()) == [], "no output file, partial or whole"


def test_infeasible_agent_reason_is_named(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "synthesize", _raising(InconsistentProblem("infeasible", "no agent strategy")))
    code, out, err = run(["synthesize", "small-reactive"], capsys)
    assert_one_error_line(code, out, err, 3, "infeasible", "no agent strategy")


def test_unexpected_error_is_a_bug_with_traceback(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "synthesize", _raising(RuntimeError("HiGHS stopped")))
    code, out, err = run(["synthesize", "small-reactive"], capsys)
    assert code == 1 and out == ""
    assert "Traceback" in err and "error: internal error" in err


# --------------------------------------------------------------------------- output files


def test_out_and_plot_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    art = tmp_path / "deep" / "er" / "test.json"
    png = tmp_path / "pics" / "test.png"
    argv = ["synthesize", "small-reactive", "--json", "--out", str(art), "--plot", str(png)]
    code, out, err = run(argv, capsys)
    assert code == 0, err
    summary = json.loads(out)
    assert art.stat().st_size > 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not [p for p in tmp_path.rglob(".*")], "temporary files are cleaned up"

    loaded = TestArtifact.load(art)
    from synthesis.pipeline import synthesize

    fresh = synthesize(load_problem("small-reactive"))
    assert np.array_equal(loaded.strategy.restrictions, fresh.strategy.restrictions)
    assert np.array_equal(loaded.strategy.static_obstacles, fresh.strategy.static_obstacles)
    assert loaded.strategy.setting == fresh.strategy.setting
    assert loaded.summary == summary

    # again without --force: refused before any work, files unchanged
    art_before, png_before = art.read_bytes(), png.read_bytes()
    for flag, path in (("--out", art), ("--plot", png)):
        code, out, err = run(["synthesize", "small-reactive", flag, str(path)], capsys)
        assert_one_error_line(code, out, err, 2, str(path), "exists; use --force to overwrite")
    assert art.read_bytes() == art_before and png.read_bytes() == png_before

    # with --force: overwritten
    art.write_text("stale")
    png.write_bytes(b"stale")
    code, out, err = run(["synthesize", "small-reactive", "--out", str(art), "--plot", str(png), "--force", "-q"], capsys)
    assert code == 0, err
    assert TestArtifact.load(art).name == "small-reactive"
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_out_setting_is_recorded(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    art = tmp_path / "t.json"
    code, _, err = run(["synthesize", str(DATA / "ok_grid.toml"), "--out", str(art), "--setting", "accumulative", "-q"], capsys)
    assert code == 0, err
    assert TestArtifact.load(art).strategy.setting == "accumulative"


def test_output_path_problems(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    same = tmp_path / "x.png"
    code, out, err = run(["synthesize", "small-reactive", "--out", str(same), "--plot", str(same)], capsys)
    assert_one_error_line(code, out, err, 2, "same file")
    code, out, err = run(["synthesize", "small-reactive", "--plot", str(tmp_path / "x.gif")], capsys)
    assert_one_error_line(code, out, err, 2, ".png")
    code, out, err = run(["synthesize", "small-reactive", "--out", str(tmp_path), "--force"], capsys)
    assert_one_error_line(code, out, err, 2, "directory")
    assert not same.exists()


# --------------------------------------------------------------------------- progress


class FakeTTY(io.StringIO):
    """A stream that claims to be a terminal."""

    def isatty(self) -> bool:
        return True


def test_progress_live_indicator_on_a_tty() -> None:
    stream = FakeTTY()
    with StageProgress(stream, delay=0.05, interval=0.01) as progress:
        progress("solving")
        time.sleep(0.3)
        progress("checking")
    text = stream.getvalue()
    assert "\rflowtest: solving ... " in text  # the live elapsed-time indicator
    assert text.endswith(")\n")  # every stage line is terminated
    assert text.count("\n") == 2


def test_progress_plain_lines_elsewhere() -> None:
    stream = io.StringIO()
    with StageProgress(stream, delay=0.0, interval=0.01) as progress:
        progress("solving")
        time.sleep(0.05)
        progress.done("done")
    assert stream.getvalue() == "flowtest: solving\nflowtest: done\n"
    quiet = io.StringIO()
    with StageProgress(quiet, enabled=False) as progress:
        progress("solving")
    assert quiet.getvalue() == ""


def test_parser_has_room_for_more_commands() -> None:
    assert "synthesize" in [c.name for c in COMMANDS]
    with pytest.raises(ValueError):  # a second command of the same name is refused
        cli.build_parser([*COMMANDS, Command("synthesize", "again", lambda p: None, lambda a: 0)])


def _listed_commands(help_text: str) -> list[str]:
    """The subcommand names a ``--help`` text lists (one per line, indented under COMMAND)."""
    return re.findall(r"^ {4}(\S+)", help_text, flags=re.MULTILINE)


def test_every_entry_point_lists_the_same_commands() -> None:
    """``flowtest --help`` and ``python -m experiments.cli.cli --help`` list every command of
    the one list (``python -m experiments.cli.cli`` once listed only ``synthesize``)."""
    names = [c.name for c in COMMANDS]
    assert names[0] == "synthesize" and {"demo", "evaluate", "train", "train-tester"} <= set(names)
    for argv in ([str(FLOWTEST), "--help"], [sys.executable, "-m", "experiments.cli.cli", "--help"], [sys.executable, "-m", "experiments", "--help"]):
        proc = subprocess.run(argv, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        assert _listed_commands(proc.stdout) == names, (argv, proc.stdout)
