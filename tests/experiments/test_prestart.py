"""``flowtest synthesize`` starts its CP-SAT child before its own imports (experiments/cli/prestart.py,
synthesis/routing/backends/cpsat_pool.py): the child is used when CP-SAT runs, and always reaped (when
HiGHS runs, on an agent problem, on errors, on Ctrl-C); the answer is the one of an in-process
synthesis, stdout holds the JSON alone, and the early start loads nothing heavy.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from experiments.cli import prestart
from experiments.cli.cli import main
from synthesis import pipeline
from synthesis.artifacts.summary import summary_of, without_timings
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.load import load_problem
from synthesis.routing.backends import cpsat, cpsat_pool

FLOWTEST = Path(sys.executable).parent / "flowtest"

needs_ortools = pytest.mark.skipif(not cpsat.available(), reason="OR-Tools is not installed (a core dependency, missing here)")


@pytest.fixture(autouse=True)
def _no_idle_child() -> None:
    """Each test starts without a kept child (one from an earlier test would be taken instead)."""
    cpsat_pool.close_idle_workers()


def _reaped(pid: int) -> bool:
    """Whether ``pid`` (a child of this process) is gone and reaped (a zombie still answers)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


@needs_ortools
@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["synthesize", "refueling"], True),
        (["synthesize", "refueling", "--backend", "cpsat"], True),
        (["synthesize", "x.toml", "--backend=auto", "--json"], True),
        (["synthesize", "refueling", "--backend", "highs"], False),
        (["synthesize", "refueling", "--backend=cover"], False),
        (["synthesize", "refueling", "--backend", "highs", "--backend", "cpsat"], True),  # the last one counts
        (["synthesize", "--help"], False),
        (["demo"], False),
        ([], False),
    ],
)
def test_the_command_line_decides(argv: list[str], expected: bool) -> None:
    assert prestart.may_use_cpsat(argv) is expected


@needs_ortools
def test_a_failed_early_start_is_no_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """No process to spare at start-up: the command goes on, and the solve starts its own child."""

    def refused() -> None:
        raise OSError("Resource temporarily unavailable")

    monkeypatch.setattr(prestart, "prestart", refused)
    assert prestart.prestart_for(["synthesize", "refueling"]) is False
    assert cpsat_pool.idle_pids() == []


@needs_ortools
def test_the_prestarted_child_solves_and_is_reaped(capsys: pytest.CaptureFixture[str]) -> None:
    """refueling on ``auto`` (CP-SAT): the solve runs on the child started before, which is
    reaped when the command ends; the answer is the in-process one."""
    assert prestart.prestart_for(["synthesize", "refueling", "--json"])
    (pid,) = cpsat_pool.idle_pids()
    used: list[int] = []
    real = cpsat.CpSatSession.__init__

    def remember(self: cpsat.CpSatSession, *args: object, **kwargs: object) -> None:
        real(self, *args, **kwargs)  # type: ignore[arg-type]
        used.append(self.pid)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cpsat.CpSatSession, "__init__", remember)
        assert main(["synthesize", "refueling", "--json", "-q"]) == 0
    assert used == [pid]
    assert _reaped(pid) and cpsat_pool.idle_pids() == []
    document = json.loads(capsys.readouterr().out)
    assert (document["status"], document["flow"], document["n_cuts"]) == ("optimal", 2, 101)
    assert document["stats"]["backend"] == "cpsat"


@needs_ortools
@pytest.mark.parametrize(
    ("argv", "code"),
    [
        (["synthesize", "example1", "--json", "-q"], 0),  # auto runs HiGHS on its small model
        (["synthesize", "maze1", "--json", "-q"], 0),  # an agent problem: HiGHS
        (["synthesize", "no-such-problem", "--json", "-q"], 2),  # an error
    ],
)
def test_an_unused_child_is_reaped(argv: list[str], code: int) -> None:
    assert prestart.prestart_for(argv)
    (pid,) = cpsat_pool.idle_pids()
    assert main(argv) == code
    assert _reaped(pid) and cpsat_pool.idle_pids() == []


@needs_ortools
def test_an_agent_problem_ends_the_child_before_synthesis() -> None:
    """The problem's kind shows at once that ``auto`` will not run CP-SAT: the child is
    ended before the graphs are built, not at the end."""
    assert prestart.prestart_for(["synthesize", "maze1"])
    (pid,) = cpsat_pool.idle_pids()
    seen: list[bool] = []
    real = pipeline.synthesize

    def look(*args: object, **kwargs: object) -> object:
        seen.append(_reaped(pid))
        return real(*args, **kwargs)  # type: ignore[arg-type]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "synthesize", look)
        assert main(["synthesize", "maze1", "--json", "-q"]) == 0
    assert seen == [True]


@needs_ortools
def test_ctrl_c_reaps_the_child() -> None:
    """Ctrl-C during the synthesis (a ``KeyboardInterrupt``): exit 130 and the child reaped."""
    assert prestart.prestart_for(["synthesize", "refueling"])
    (pid,) = cpsat_pool.idle_pids()

    def interrupted(*args: object, **kwargs: object) -> object:
        raise KeyboardInterrupt

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "synthesize", interrupted)
        assert main(["synthesize", "refueling", "--json", "-q"]) == 130
    assert _reaped(pid) and cpsat_pool.idle_pids() == []


@needs_ortools
def test_the_console_script_gives_the_in_process_answer() -> None:
    """``flowtest synthesize refueling --json`` (prestarted child): stdout is the JSON
    document alone, with the answer an in-process synthesis gives (deterministic)."""
    proc = subprocess.run([str(FLOWTEST), "synthesize", "refueling", "--json"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    document = json.loads(proc.stdout)
    expected = json.loads(json.dumps(summary_of(synthesize(load_problem("refueling"), SynthesisOptions()))))
    assert without_timings(document) == without_timings(expected)


def _children(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    try:
        return [int(p) for p in path.read_text().split()]
    except OSError:
        return []


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return True
    return state == "Z"


@needs_ortools
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs /proc to find the child")
def test_ctrl_c_at_start_up_ends_the_child() -> None:
    """SIGINT as soon as the child is started (the command still importing): exit 130,
    nothing on stdout, and the child gone within a second."""
    proc = subprocess.Popen(
        [str(FLOWTEST), "synthesize", "refueling", "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.perf_counter() + 30.0
    kids: list[int] = []
    while not kids and proc.poll() is None:
        assert time.perf_counter() < deadline, "no CP-SAT child was started"
        kids = _children(proc.pid)
        time.sleep(0.005)
    assert kids, "the command ended before a child was seen"
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert out == "" and "Traceback" not in err
    deadline = time.perf_counter() + 1.0
    while not all(_gone(k) for k in kids):
        assert time.perf_counter() < deadline, "the CP-SAT child outlived flowtest by over a second"
        time.sleep(0.05)


def test_the_early_start_loads_nothing_heavy() -> None:
    """What the console script imports before the child starts: the standard library and
    the two small modules, not NumPy, SciPy, HiGHS or the rest of FlowTest."""
    code = (
        "import sys; import experiments.cli.prestart; "
        "print(sorted(m for m in ('numpy', 'scipy', 'highspy', 'synthesis.pipeline', 'synthesis.routing.backends.cpsat', 'experiments.cli.cli') "
        "if m in sys.modules))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"
