"""The ``"scip"`` routing backend (synthesis.routing.scip, the optional extra
``flowtest[scip]``): the wall-cover master in one SCIP tree per flow level gives the same
optimum as HiGHS, checked answers, deterministic, honours stop requests and node budgets.
Skipped where PySCIPOpt is not installed (the missing-extra error is tested either way).

The exhaustive-optimality comparisons run it too (``tests/synthesis/test_optimality.py``)."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import pytest

from synthesis import load_problem
from synthesis.artifacts.summary import summary_of, without_timings
from synthesis.model.errors import ProblemError
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.problem import build_graphs
from synthesis.routing import scip, solver_control
from synthesis.routing.milp import solve_routing
from synthesis.routing.model import Exclusion
from synthesis.routing.solver_control import SolveControl, solves_running

needs_scip = pytest.mark.skipif(not scip.available(), reason="PySCIPOpt (the scip extra) is not installed")

QUICK = ["example1", "small-reactive", "beaver-rescue", "motion-primitives", "maze1"]
"""Built-ins both backends prove within a second or two."""


@needs_scip
@pytest.mark.parametrize("name", QUICK)
def test_scip_and_highs_agree_on_the_builtins(name: str) -> None:
    """Both prove the same (flow, cuts); the SCIP answer passes every check."""
    ours = synthesize(load_problem(name), SynthesisOptions(backend="scip"))
    highs = synthesize(load_problem(name), SynthesisOptions(backend="highs"))
    assert ours.routing.status == highs.routing.status == "optimal"
    assert (ours.routing.flow, ours.routing.cut_edges.size) == (highs.routing.flow, highs.routing.cut_edges.size)
    assert ours.checks.ok
    assert ours.routing.stats["backend"] == "scip"
    assert ours.routing.stats["solver_version"] == scip.scip_version()
    assert summary_of(ours)["stats"]["backend"] == "scip"


@needs_scip
def test_same_answer_twice() -> None:
    """Deterministic: the same problem and options give the same summary (timings aside)."""
    a = summary_of(synthesize(load_problem("motion-primitives"), SynthesisOptions(backend="scip")))
    b = summary_of(synthesize(load_problem("motion-primitives"), SynthesisOptions(backend="scip")))
    assert without_timings(a) == without_timings(b)
    assert a["deterministic"] is True


@needs_scip
def test_exclusions_give_the_next_best_cut_set() -> None:
    """With the optimum's cut set excluded, SCIP and HiGHS agree on the next best one."""
    problem = load_problem("small-reactive")
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions()), backend="scip")
    first = solve_routing(products, options)
    excluded = replace(options, exclusions=[Exclusion(tuple(first.cut_group_keys))])
    ours = solve_routing(products, excluded)
    highs = solve_routing(products, replace(excluded, backend="highs"))
    assert ours.cut_group_keys != first.cut_group_keys
    assert (ours.flow, ours.cut_edges.size) == (highs.flow, highs.cut_edges.size)
    assert ours.status == "optimal"


@needs_scip
def test_a_node_budget_returns_a_checked_test_or_none() -> None:
    """SCIP's node limit (deterministic) stops a level: the best checked test so far,
    ``feasible`` with ``stopped_by = "node_limit"``, or no test (``TimeoutError``)."""
    problem = load_problem("refueling")
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions()), backend="scip", node_limit=20)
    try:
        r = solve_routing(products, options)
    except TimeoutError:
        return
    assert r.status == "feasible" and r.stats["stopped_by"] == "node_limit"


@needs_scip
def test_a_stop_request_ends_a_scip_solve_within_a_second() -> None:
    """A stop request (Ctrl-C) during the tree search ends the solve within a second, and
    SCIP's thread ends soon after."""
    problem = load_problem("refueling")
    _, products = build_graphs(problem)
    control = SolveControl()
    options = replace(milp_options(problem, SynthesisOptions(control=control)), backend="scip")
    threading.Timer(1.0, control.request_stop).start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        solve_routing(products, options)
    assert time.perf_counter() - t0 < 1.0 + 1.0
    deadline = time.perf_counter() + 2.0
    while solves_running() and time.perf_counter() < deadline:
        time.sleep(0.01)
    assert not solves_running()


def test_missing_extra_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without PySCIPOpt, asking for the backend is a :class:`ProblemError` naming the extra."""
    real = solver_control.find_spec
    monkeypatch.setattr(solver_control, "find_spec", lambda name: None if name == "pyscipopt" else real(name))
    with pytest.raises(ProblemError, match=r"flowtest\[scip\]"):
        synthesize(load_problem("example1"), SynthesisOptions(backend="scip"))
