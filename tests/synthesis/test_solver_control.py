"""synthesis.routing.solver_control: stop requests, live status, time budget, the stdout guard."""

from __future__ import annotations

import os
import threading
import time

import highspy
import numpy as np
import pytest
import scipy.sparse as sp

from synthesis.routing.solver_control import Clock, SolveControl, SolveStatus, run_highs, solves_running, status_line, stdout_guard


def market_split(m: int = 4, n: int = 40, seed: int = 0) -> highspy.Highs:
    """A market-split feasibility problem (Cornuejols-Dawande): tiny, and far beyond
    branch and bound for seconds to hours, so HiGHS is busy when it is stopped."""
    rng = np.random.default_rng(seed)
    a = rng.integers(0, 100, size=(m, n)).astype(float)
    rhs = np.floor(a.sum(axis=1) / 2)
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = n, m
    lp.col_cost_, lp.col_lower_, lp.col_upper_ = np.zeros(n), np.zeros(n), np.ones(n)
    lp.row_lower_, lp.row_upper_ = rhs, rhs
    csc = sp.csc_matrix(a)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = csc.indptr.astype(np.int32)
    lp.a_matrix_.index_ = csc.indices.astype(np.int32)
    lp.a_matrix_.value_ = csc.data
    lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = n, m
    lp.integrality_ = [highspy.HighsVarType.kInteger] * n
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.passModel(lp)
    return h


def test_a_stop_request_ends_a_running_solve_within_a_second() -> None:
    """Another thread's stop request (what Ctrl-C does) ends the run with
    ``KeyboardInterrupt`` within a second, and HiGHS's thread ends too."""
    h = market_split()
    control = SolveControl()
    statuses: list[str | None] = []

    def look_then_stop() -> None:
        statuses.append(status_line(control))
        control.request_stop()

    threading.Timer(0.5, look_then_stop).start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        run_highs(h, None, control=control, phase="market split")
    t_stop = time.perf_counter() - t0
    assert t_stop < 0.5 + 1.0, f"stopped {t_stop - 0.5:.2f} s after the request"
    deadline = time.perf_counter() + 2.0
    while solves_running() and time.perf_counter() < deadline:
        time.sleep(0.01)
    assert not solves_running(), "HiGHS's thread kept running"
    assert statuses and statuses[0] is not None and statuses[0].startswith("market split:")
    assert control.status is None  # no solve runs any more


def test_a_solve_that_ends_reports_nothing_running() -> None:
    h = market_split(m=1, n=8)
    control = SolveControl()
    run_highs(h, None, control=control, phase="small")
    assert h.getModelStatus() in (highspy.HighsModelStatus.kOptimal, highspy.HighsModelStatus.kInfeasible)
    assert control.status is None and not solves_running()


def test_status_line_shows_best_bound_gap_and_time() -> None:
    t0 = time.perf_counter() - 12.0
    phase1 = SolveStatus("phase 1 (maximum flow)", "max", 2.0, 3.0, t0)
    assert phase1.text() == "phase 1 (maximum flow): best flow 2, bound 3, gap 50.0%, 12 s"
    phase2 = SolveStatus("phase 2 (fewest cuts)", "min", 14.0, 11.0, t0, flow=2)
    assert phase2.text().startswith("phase 2 (fewest cuts): flow 2, best cuts 14, bound 11, gap 21.4%")
    # no bound: said in words, never a "gap -" or a gap from a placeholder bound
    assert SolveStatus("phase 1", "max", None, None, t0).text().startswith("phase 1: best flow -, no bound yet, ")
    assert SolveStatus("phase 1", "max", -0.0, None, t0).text().startswith("phase 1: best flow 0, no bound yet, ")
    # a minimised count is never below 0: HiGHS's early bound -1040 means 0 (gap 100%, not 200%)
    assert SolveStatus("p2", "min", 1040.0, -1040.0, t0, flow=1).text().startswith("p2: flow 1, best cuts 1040, bound 0, gap 100.0%")
    # a bound on the wrong side of the best answer proves nothing
    assert SolveStatus("p1", "max", 3.0, 1.0, t0).text().startswith("p1: best flow 3, no bound yet, ")


def test_status_line_has_one_clock() -> None:
    """The seconds a status line shows run from the command's one clock (the control's
    start), not from the start of the solver run that published it."""
    control = SolveControl()
    control.started -= 100.0
    control.report(SolveStatus("phase 2", "min", 5.0, 3.0, time.perf_counter(), flow=1))
    line = status_line(control)
    assert line is not None and line.endswith(", 100 s")


def test_clock_moves_the_deadline_after_the_first_test() -> None:
    clock = Clock(100.0, 1.0)
    assert clock.watching_first() and clock.latest() is not None
    assert clock.latest() > clock.deadline  # type: ignore[operator]
    clock.first_test()
    assert not clock.watching_first()
    assert clock.deadline is not None and clock.deadline - time.perf_counter() <= 1.0
    assert Clock(None, None).latest() is None


def test_stdout_guard_drops_writes_to_fd_1_and_restores_it(capfd: pytest.CaptureFixture[str]) -> None:
    os.write(1, b"before\n")
    with stdout_guard():
        os.write(1, b"inside\n")
        print("inside too")
    os.write(1, b"after\n")
    assert capfd.readouterr().out == "before\nafter\n"


def test_library_synthesis_prints_nothing_on_stdout(capfd: pytest.CaptureFixture[str]) -> None:
    """Used as a library (``synthesize``, ``gym.make`` of a problem file), FlowTest keeps the
    caller's standard output clean: HiGHS >= 1.16 prints a banner when a solver object is
    made, before any option can silence it."""
    from synthesis.pipeline import synthesize
    from synthesis.problems.load import load_problem

    capfd.readouterr()
    synthesize(load_problem("small-reactive"))
    assert capfd.readouterr().out == ""
