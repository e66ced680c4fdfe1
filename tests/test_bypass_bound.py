"""experiments/bypass_bound.py: its bound is valid and, where it claims a proof, exact
(brute force over every wall set of tiny static grids, as tests/test_optimality.py)."""

from __future__ import annotations

import pytest

from experiments.bypass_bound import arrays_of, bound_in_child
from synthesis.model.errors import InconsistentProblem
from synthesis.problems.load import load_problem
from synthesis.problems.problem import build_graphs
from tests.test_optimality import grid_instance, static_optimum, view_of


@pytest.mark.parametrize("seed", range(12))
def test_proof_matches_brute_force(seed: int) -> None:
    """At the exhaustive optimum's flow, the loop proves exactly its fewest cut edges; the
    relaxations (no flow condition; only walks missing a test cell) stay below it."""
    problem = grid_instance(100 + seed, 3, 3, "static", True)
    _, products = build_graphs(problem)
    best, _ = static_optimum(view_of(products), problem.system, problem.bidirectional_cuts)
    try:
        arrays = arrays_of(problem)
    except InconsistentProblem:
        assert best is None
        return
    if best is None:  # no wall set keeps a flow: the master runs out of answers
        assert bound_in_child(arrays, flow=1)["status"] == "infeasible"
        return
    got = bound_in_child(arrays, flow=best.flow)
    assert got["status"] == "proved"
    assert got["bound"] == got["incumbent"] == best.n_cuts
    relaxed = bound_in_child(arrays, flow=best.flow, use_flow=False)
    assert relaxed["status"] == "proved" and relaxed["bound"] <= best.n_cuts


def test_refueling_bounds_below_its_optimum() -> None:
    """refueling (optimum 101 cuts at flow 2): the bypass cover alone is 15; a few rounds with
    the flow cuts give a bound between that and the optimum, and no false proof."""
    arrays = arrays_of(load_problem("refueling"))
    cover = bound_in_child(arrays, use_flow=False)
    assert (cover["status"], cover["bound"], cover["flow"]) == ("proved", 15.0, 2)
    part = bound_in_child(arrays, rounds=20)
    assert part["status"] == "bound"
    assert 15 <= part["bound"] <= 101
    assert part["incumbent"] is None or part["incumbent"] >= 101


def test_mars_parts_by_missed_atom() -> None:
    """mars-exploration's bypass walks, split by the test atom they miss: the rock and lowfuel
    parts are proven at once (with flow 2), and the union of the three parts is the whole family
    (the same rows, hence the same bounds, round by round)."""
    problem = load_problem("mars-exploration")
    rock = bound_in_child(arrays_of(problem, ["rock"]))
    assert (rock["status"], rock["bound"], rock["flow"]) == ("proved", 183.0, 2)
    lowfuel = bound_in_child(arrays_of(problem, ["lowfuel"]))
    assert (lowfuel["status"], lowfuel["bound"]) == ("proved", 329.0)
    whole = bound_in_child(arrays_of(problem), rounds=3)
    union = bound_in_child(arrays_of(problem, ["ice", "rock", "lowfuel"]), rounds=3)
    assert (union["bound"], union["cover_rows"], union["flow_rows"]) == (whole["bound"], whole["cover_rows"], whole["flow_rows"])
    assert whole["status"] == "bound" and whole["bound"] < 1557
