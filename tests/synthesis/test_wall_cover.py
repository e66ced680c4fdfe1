"""The ``"cover"`` routing backend (synthesis.routing.wall_cover): the same optimum as the
flow MILP on HiGHS, checked answers, deterministic, honours stop requests and budgets.

The exhaustive-optimality comparisons run it too (``tests/synthesis/test_optimality.py``)."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from synthesis import load_problem
from synthesis.artifacts.summary import summary_of, without_timings
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.problem import build_graphs
from synthesis.routing.cover_rows import FlowCut
from synthesis.routing.milp import solve_routing
from synthesis.routing.model import Exclusion
from synthesis.routing.solver_control import SolveControl, solves_running
from synthesis.routing.wall_cover import solve_cover

QUICK = ["example1", "small-reactive", "beaver-rescue", "maze1"]
"""Built-ins both backends prove within a second or two."""


@pytest.mark.parametrize("name", QUICK)
def test_cover_and_highs_agree_on_the_builtins(name: str) -> None:
    """Both prove the same (flow, cuts); the cover answer passes every check."""
    cover = synthesize(load_problem(name), SynthesisOptions(backend="cover"))
    highs = synthesize(load_problem(name), SynthesisOptions(backend="highs"))
    assert cover.routing.status == highs.routing.status == "optimal"
    assert (cover.routing.flow, cover.routing.cut_edges.size) == (highs.routing.flow, highs.routing.cut_edges.size)
    assert cover.checks.ok
    assert cover.routing.stats["backend"] == "cover"
    assert summary_of(cover)["stats"]["backend"] == "cover"


def test_same_answer_twice() -> None:
    """Deterministic: the same problem and options give the same summary (timings aside)."""
    a = summary_of(synthesize(load_problem("small-reactive"), SynthesisOptions(backend="cover")))
    b = summary_of(synthesize(load_problem("small-reactive"), SynthesisOptions(backend="cover")))
    assert without_timings(a) == without_timings(b)
    assert a["deterministic"] is True


def test_exclusions_give_the_next_best_cut_set() -> None:
    """With the optimum's cut set excluded, cover and HiGHS agree on the next best one."""
    _, products = build_graphs(load_problem("small-reactive"))
    options = milp_options(load_problem("small-reactive"), SynthesisOptions())
    first = solve_cover(products, options)
    excluded = replace(options, exclusions=[Exclusion(tuple(first.cut_group_keys))])
    cover = solve_cover(products, excluded)
    highs = solve_routing(products, replace(excluded, backend="highs"))
    assert cover.cut_group_keys != first.cut_group_keys
    assert (cover.flow, cover.cut_edges.size) == (highs.flow, highs.cut_edges.size)
    assert cover.status == "optimal"


def test_a_round_budget_returns_a_checked_test_or_none() -> None:
    """A deterministic round budget stops the search: the best test so far, ``feasible``
    with ``stopped_by = "node_limit"``, or no test (``TimeoutError``)."""
    problem = load_problem("motion-primitives")
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    try:
        r = solve_cover(products, options, max_rounds=2)
    except TimeoutError:
        return
    assert r.status == "feasible" and r.stats["stopped_by"] == "node_limit"


def test_flow_cut_rows_are_valid_at_every_level() -> None:
    """``sum_g min(n_g, F) (1 - d_g) + fixed >= F`` written as a row over ``d``."""
    fc = FlowCut(np.array([0, 1]), np.array([3, 1]), 1)
    row = fc.row(2)
    assert list(row.vals) == [2.0, 1.0]
    assert row.hi == 2.0 + 1.0 + 1 - 2  # both open: 3 + 1 >= 2; closing group 0 leaves 1 + 1 = 2
    assert row.vals @ np.array([1, 0]) <= row.hi and not row.vals @ np.array([1, 1]) <= row.hi


def test_a_stop_request_ends_a_cover_solve_within_a_second() -> None:
    """A stop request (Ctrl-C) during the rounds ends the solve within a second."""
    problem = load_problem("refueling")
    _, products = build_graphs(problem)
    control = SolveControl()
    options = milp_options(problem, SynthesisOptions(control=control))
    threading.Timer(1.0, control.request_stop).start()
    t0 = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        solve_cover(products, options)
    assert time.perf_counter() - t0 < 1.0 + 1.0
    deadline = time.perf_counter() + 2.0
    while solves_running() and time.perf_counter() < deadline:
        time.sleep(0.01)
    assert not solves_running()
