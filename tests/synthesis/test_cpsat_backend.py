"""The CP-SAT solver backend (``backend="cpsat"``, OR-Tools CP-SAT, a core dependency; issue 18 pt 2).

Its exhaustive optimality is ``tests/synthesis/test_optimality.py`` (parametrized over the installed
backends); the same answers as HiGHS on the built-ins, and the solver named with its version, are
``tests/synthesis/test_backend_contract.py`` (every backend). Here: determinism under a
deterministic budget, Ctrl-C and stop requests, the child process's output kept off our
stdout, and the one-line error when the extra is missing.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from experiments.cli.cli import main
from synthesis.artifacts.summary import summary_of, without_timings
from synthesis.model.errors import InconsistentProblem, ProblemError
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.load import load_problem
from synthesis.problems.random_grid import first_consistent
from synthesis.routing import certificates, model, solver_control
from synthesis.routing.backends import cpsat, phase1_start
from synthesis.routing.solver_control import SolveControl
from tests.testing_optimality import compare_reactive, compare_static, graph_instance, grid_instance
from tests.testing_processes import start_until

FLOWTEST = Path(sys.executable).parent / "flowtest"

needs_ortools = pytest.mark.skipif(not cpsat.available(), reason="OR-Tools is not installed (a core dependency, missing here)")


@needs_ortools
def test_refueling_proven_by_cpsat() -> None:
    """The paper's refueling example: flow 2 with 101 cuts, proven (HiGHS's answer,
    docs/benchmarks.md), in a fraction of HiGHS's time."""
    test = synthesize(load_problem("refueling"), SynthesisOptions(backend="cpsat"))
    assert (test.routing.status, test.routing.flow, int(test.routing.cut_edges.size)) == ("optimal", 2, 101)
    assert test.routing.stats["solver_version"] == cpsat.ortools_version()
    assert test.checks.bypass_flow == 0


@needs_ortools
def test_deterministic_budget_gives_the_same_test() -> None:
    """One worker, a fixed seed and CP-SAT's deterministic time as the budget: a solve
    stopped by the work limit gives the same (checked) test twice, and says so."""
    options = SynthesisOptions(backend="cpsat", work_limit=0.05)
    a, b = (synthesize(load_problem("refueling"), options) for _ in range(2))
    assert a.routing.stats["stopped_by"] == "work_limit" and a.routing.status == "feasible"
    assert a.routing.stats["deterministic"] is True
    assert a.checks.bypass_flow == 0
    assert without_timings(summary_of(a)) == without_timings(summary_of(b))
    assert np.array_equal(a.routing.cut_edges, b.routing.cut_edges)


@needs_ortools
def test_the_level_search_keeps_the_optimum(monkeypatch: pytest.MonkeyPatch) -> None:
    """Phase 1's feasibility solves level by level (``cpsat_phases.reach_level``: the default
    search below the top level, ``cpsat.MAX_FLOW_SEARCH`` and the default search in turn at
    it), which follow the default search where that does not prove the maximum flow within
    ``cpsat.PROOF_WORK``, forced on every solve of exhaustive comparisons: the same optima as
    the brute force, through levels found and levels proven empty. The heuristic's test is
    withheld (the levels start at 1, so every level up to the maximum is found by a search;
    from the heuristic's flow, which is the maximum on most of these instances, only the
    level above would be searched) and the walls' flow bound of MILP-static is switched off
    (it makes the bound tight on most of these instances, so no level would be proven
    empty; the exhaustive comparisons of tests/synthesis/test_optimality.py run with both)."""
    monkeypatch.setattr(cpsat, "PROOF_WORK", 1e-9)
    monkeypatch.setattr(model, "model_flow_bound", lambda *args: None)
    monkeypatch.setattr(phase1_start, "guess_solution", lambda *args: None)
    monkeypatch.setattr(certificates, "guess_solution", lambda *args: None)
    outcomes: list[str] = []
    real = cpsat.CpSatSession.solve

    def record(self: cpsat.CpSatSession, *args: Any, **kwargs: Any) -> cpsat.CpSatAnswer:
        answer = real(self, *args, **kwargs)
        if kwargs.get("reach") is not None:
            outcomes.append("found" if answer.x is not None else answer.status)
        return answer

    monkeypatch.setattr(cpsat.CpSatSession, "solve", record)
    for seed in range(4):
        compare_static(grid_instance(100 + seed, 3, 3, "static", True), max_sets=1 << 12, backend="cpsat")
        compare_static(grid_instance(300 + seed, 2, 3, "static", False), max_sets=1 << 14, backend="cpsat")
        assert compare_reactive(graph_instance(500 + seed), backend="cpsat")
    assert "found" in outcomes and "infeasible" in outcomes, outcomes


@needs_ortools
@pytest.mark.slow
def test_phase1_proves_a_level_below_the_bound_empty() -> None:
    """Two random 5x5 reaction grids (|AP| = 5, MILP-static) on which phase 1's search at
    the flow bound (3) found nothing within the paper's 600 s in session 9: seed 1, whose
    heuristic test has flow 1, is now proven optimal (the level search proves flow 2
    impossible and phase 2 proves the fewest cuts), and seed 3, where the heuristic finds no
    test, has none (level 1 proven impossible: unroutable). Deterministic budgets; about
    15 s."""
    _, problem, _ = first_consistent(5, "reaction", 3, 1, "static")
    test = synthesize(problem, SynthesisOptions(backend="cpsat", work_limit=20))
    assert test.routing.status == "optimal" and test.routing.flow == 1
    assert test.checks.ok and test.checks.bypass_flow == 0
    _, problem, _ = first_consistent(5, "reaction", 3, 3, "static")
    with pytest.raises(InconsistentProblem) as err:
        synthesize(problem, SynthesisOptions(backend="cpsat", work_limit=20))
    assert err.value.reason == "unroutable"


@needs_ortools
def test_a_stop_request_kills_the_child_within_a_second() -> None:
    """A stop request (what Ctrl-C sends) during a long CP-SAT search: ``KeyboardInterrupt``
    within a second, and the child process is gone."""
    control = SolveControl()
    pids: list[int] = []
    real = cpsat.CpSatSession.__init__

    def remember(self: cpsat.CpSatSession, *args: object, **kwargs: object) -> None:
        real(self, *args, **kwargs)  # type: ignore[arg-type]
        pids.append(self.pid)

    problem = load_problem("mars-exploration")  # phase 1 takes CP-SAT seconds
    stopped: list[float] = []

    def stop_once_running() -> None:
        while control.status is None or control.status.phase != "phase 1 (maximum flow)":
            time.sleep(0.05)
        time.sleep(0.5)
        stopped.append(time.perf_counter())
        control.request_stop()

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cpsat.CpSatSession, "__init__", remember)
        threading.Thread(target=stop_once_running, daemon=True).start()
        with pytest.raises(KeyboardInterrupt):
            synthesize(problem, SynthesisOptions(backend="cpsat", control=control))
    assert stopped and time.perf_counter() - stopped[0] < 1.0
    assert pids
    with pytest.raises(ProcessLookupError):
        os.kill(pids[0], 0)  # killed and reaped


@needs_ortools
def test_ctrl_c_on_the_console_script_ends_the_child(tmp_path: Path) -> None:
    """SIGINT while CP-SAT runs (mars-exploration, phase 1): exit 130 within 2 s, nothing
    on stdout, no output file, and the child process is gone within a second."""
    art = tmp_path / "mars.json"
    proc = start_until(
        [str(FLOWTEST), "synthesize", "mars-exploration", "--backend", "cpsat", "--json", "--out", str(art), "--progress", "0.3"],
        "phase 1 (maximum flow): best",
        signal.SIGINT,
    )
    children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children")
    kids = [int(p) for p in children.read_text().split()] if children.exists() else []
    t0 = time.perf_counter()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert time.perf_counter() - t0 < 2.0
    assert out == "" and "Traceback" not in err
    assert err.splitlines()[-1] == "flowtest: interrupted"
    assert list(tmp_path.iterdir()) == []
    assert kids, "the CP-SAT child was not found"
    deadline = time.perf_counter() + 1.0
    while any(Path(f"/proc/{k}").exists() and "Z" not in _state(k) for k in kids):
        assert time.perf_counter() < deadline, "the CP-SAT child outlived flowtest by over a second"
        time.sleep(0.05)


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return "Z"


@needs_ortools
def test_json_stdout_only_with_cpsat() -> None:
    """With ``--json`` stdout holds the JSON document alone: the child's output never reaches it."""
    proc = subprocess.run([str(FLOWTEST), "synthesize", "small-reactive", "--backend", "cpsat", "--json"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["status"] == "optimal" and summary["stats"]["backend"] == "cpsat"


def test_missing_ortools_is_one_clear_error(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """``--backend cpsat`` without OR-Tools: exit 2, one ``error:`` line naming the package,
    before any work; the library raises :class:`ProblemError` with the same words."""
    monkeypatch.setattr(solver_control, "find_spec", lambda name: None)
    code = main(["synthesize", "small-reactive", "--backend", "cpsat", "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    errors = [line for line in err.splitlines() if not line.startswith("flowtest: ")]
    assert errors == [f"error: {cpsat.MISSING}"], err
    assert "ortools" in errors[0]
    with pytest.raises(ProblemError, match=r"needs OR-Tools"):
        synthesize(load_problem("small-reactive"), SynthesisOptions(backend="cpsat"))


def test_unknown_backend_is_refused() -> None:
    with pytest.raises(ProblemError, match="unknown solver backend 'gurobi'"):
        synthesize(load_problem("small-reactive"), SynthesisOptions(backend="gurobi"))
    with pytest.raises(ProblemError, match="work_limit"):
        synthesize(load_problem("small-reactive"), replace(SynthesisOptions(), work_limit=-1.0))


@needs_ortools
def test_the_child_never_imports_highspy() -> None:
    """The worker module loads OR-Tools' compiled CP-SAT helper and the standard library
    only: highspy cannot share a process with OR-Tools' own HiGHS build, and NumPy, SciPy
    and pandas (which OR-Tools' ``cp_model`` imports) made most of a fresh child's start-up."""
    heavy = ("highspy", "numpy", "scipy", "pandas", "synthesis", "ortools.sat.python.cp_model")
    code = f"import runpy, sys; runpy.run_path(sys.argv[1], run_name='not_main'); print(sorted(m for m in {heavy!r} if m in sys.modules))"
    proc = subprocess.run([sys.executable, "-P", "-c", code, str(cpsat.WORKER)], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


@needs_ortools
def test_wall_clock_budget_is_reported_non_deterministic() -> None:
    """The paper's budget rule (``time_limit`` to a first test, then ``after_first``) on
    CP-SAT: a checked test, reported as depending on the wall clock."""
    test = synthesize(load_problem("refueling"), SynthesisOptions(backend="cpsat", time_limit=120, after_first=30))
    assert test.routing.flow == 2 and test.checks.bypass_flow == 0
    assert test.routing.stats["deterministic"] is False
    assert summary_of(test)["deterministic"] is False


@needs_ortools
def test_human_summary_names_the_solver(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["synthesize", "small-reactive", "--backend", "cpsat", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert f"solver       cpsat (OR-Tools CP-SAT, ortools {cpsat.ortools_version()})" in out


def _flow_in_fork(queue: Any) -> None:
    test = synthesize(load_problem("small-reactive"), SynthesisOptions(backend="cpsat"))
    queue.put((test.routing.flow, test.routing.status))


@needs_ortools
def test_a_forked_process_starts_its_own_child() -> None:
    """The idle child kept for later solves belongs to its process: a fork forgets it (the
    pipes would be shared) and both processes solve on their own children."""
    import multiprocessing

    synthesize(load_problem("small-reactive"), SynthesisOptions(backend="cpsat"))  # leaves an idle child
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_flow_in_fork, args=(queue,))
    proc.start()
    assert queue.get(timeout=120) == (2, "optimal")
    proc.join(timeout=30)
    assert proc.exitcode == 0
    again = synthesize(load_problem("small-reactive"), SynthesisOptions(backend="cpsat"))
    assert (again.routing.flow, again.routing.status) == (2, "optimal")


@needs_ortools
@pytest.mark.parametrize(
    ("name", "backend"),
    [("refueling", "cpsat"), ("motion-primitives", "cpsat"), ("small-reactive", "highs"), ("maze1", "highs")],
)
def test_auto_runs_the_measured_rule(name: str, backend: str) -> None:
    """``auto`` runs CP-SAT on static models of 200-15,000 rows (refueling: 1,096) and reactive
    ones of 200-2,500 (motion-primitives: 687), HiGHS on smaller ones (small-reactive: 153) and
    on agent problems, and says which in the stats."""
    test = synthesize(load_problem(name), SynthesisOptions())
    assert test.routing.stats["backend"] == backend
    assert test.routing.status == "optimal" and test.checks.bypass_flow == 0


@needs_ortools
@pytest.mark.parametrize(
    ("mode", "rows", "backend"),
    [
        ("static", 199, "highs"),
        ("static", 200, "cpsat"),
        ("static", 15_000, "cpsat"),
        ("static", 15_001, "highs"),
        ("static", 21_515, "highs"),  # mars-exploration
        ("reactive", 199, "highs"),
        ("reactive", 200, "cpsat"),
        ("reactive", 2_500, "cpsat"),
        ("reactive", 2_501, "highs"),
        ("mixed", 1_000, "highs"),
    ],
)
def test_auto_backend_edges(mode: str, rows: int, backend: str) -> None:
    """The rule's edges per mode (:data:`synthesis.routing.backends.rules.AUTO_CPSAT_ROWS`, inclusive):
    a reactive model of 2,706 rows (the 5x5 reachability |AP| = 4 cell) goes to HiGHS, a
    static one of 13,000 (reaction |AP| = 7) to CP-SAT, an agent problem's never."""
    from types import SimpleNamespace

    from synthesis.routing.backends.rules import auto_backend
    from synthesis.routing.options import MilpOptions

    rm: Any = SimpleNamespace(model=SimpleNamespace(n_row=rows))
    assert auto_backend(rm, MilpOptions(mode=mode)) == backend
