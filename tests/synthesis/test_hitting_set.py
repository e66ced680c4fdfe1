"""The implicit hitting set of MILP-static's phase 2 (synthesis.routing.backends.hitting_set) and its use by
``auto`` (synthesis.routing.backends.hitting_set.try_hitting_set), held to exhaustive enumeration on tiny grids
(tests/synthesis/test_optimality.py's instances and brute force): at the maximum flow its proven answer
has the fewest cuts of all wall sets, a level above it is proven empty, and through ``auto``
(forced onto the CP-SAT path, where the hitting set runs) the pipeline's answer is the
exhaustive optimum and passes every check."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from synthesis.graphs.consistency import check_consistency
from synthesis.graphs.products import Products
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import Problem, build_graphs
from synthesis.routing import certificates, solve
from synthesis.routing.backends import cpsat, hitting_set
from synthesis.routing.backends.separator import CoverSeparator
from synthesis.routing.model import build_model
from tests.testing_optimality import compare_static, grid_instance, static_optimum, view_of

pytestmark = pytest.mark.skipif(not cpsat.available(), reason="OR-Tools is not installed (a core dependency, missing here)")

UNLIMITED = hitting_set.HittingSetBudget(rounds=100_000, work=None)


def _separator(problem: Problem) -> tuple[Products, CoverSeparator]:
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, {}, check_consistency(products))
    me = replace(rm.edges, has_var=rm.edges.has_var & ~rm.reductions.fixed_open)
    return products, CoverSeparator(products, options, rm.groups, me, {})


@pytest.mark.parametrize("seed", range(24))
def test_fewest_cuts_matches_enumeration(seed: int) -> None:
    """From no incumbent, the hitting set at the exhaustive maximum flow proves the exhaustive
    fewest cuts (a wall set passing every check), and the level above is proven empty."""
    problem = grid_instance(100 + seed, 3, 3, "static", True)
    try:
        products, sep = _separator(problem)
    except InconsistentProblem:
        pytest.skip("no Src -> Tgt path through I")
    best, _ = static_optimum(view_of(products), problem.system, problem.bidirectional_cuts)
    if best is None:
        assert hitting_set.fewest_cuts(sep, 1, None, UNLIMITED).empty
        return
    at = hitting_set.fewest_cuts(sep, best.flow, None, UNLIMITED)
    assert at.proven and at.cut is not None
    assert at.cost == best.n_cuts
    assert sep.checks_pass(at.cut, best.flow)
    above = hitting_set.fewest_cuts(sep, best.flow + 1, None, UNLIMITED)
    assert above.empty


def _solved_from_nothing(seed: int) -> tuple[CoverSeparator, int, hitting_set.HittingSetResult]:
    """A 3x3 static grid's separator, its exhaustive maximum flow, and the hitting set's
    answer there from no incumbent."""
    problem = grid_instance(seed, 3, 3, "static", True)
    products, sep = _separator(problem)
    best, _ = static_optimum(view_of(products), problem.system, problem.bidirectional_cuts)
    assert best is not None
    at = hitting_set.fewest_cuts(sep, best.flow, None, UNLIMITED)
    assert at.cut is not None
    return sep, best.flow, at


def test_incumbent_and_bound_stop_the_search() -> None:
    """An incumbent the lower bound already meets is proven without a master solve; an
    incumbent that fails a check is refused."""
    sep, flow, at = _solved_from_nothing(101)
    again = hitting_set.fewest_cuts(sep, flow, at.cut, UNLIMITED, bound=at.cost)
    assert again.proven and again.rounds == 0
    with pytest.raises(RuntimeError, match="incumbent"):
        hitting_set.fewest_cuts(sep, flow, np.zeros_like(at.cut), UNLIMITED)


def test_a_spent_budget_keeps_the_incumbent() -> None:
    """With no rounds left, the search returns its incumbent unproven, stopped by the work limit."""
    sep, flow, at = _solved_from_nothing(103)
    out = hitting_set.fewest_cuts(sep, flow, at.cut, hitting_set.HittingSetBudget(rounds=0))
    assert (out.proven, out.stopped_by, out.cost) == (at.cost <= 0.5, None if at.cost <= 0.5 else "work_limit", at.cost)


@pytest.mark.parametrize("walls_bound", [True, False])
@pytest.mark.parametrize("seed", range(16))
def test_auto_with_the_hitting_set_is_exact(seed: int, walls_bound: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """``auto`` forced onto the CP-SAT path (where phase 2 of MILP-static runs the hitting set
    first) answers the exhaustive optimum, proven, and the answer passes the checks; without
    the walls' cut bound (which settles most of these tiny grids before phase 2's search) the
    hitting set, and the model solution made of its answer, do the work."""
    monkeypatch.setattr(solve, "auto_backend", lambda rm, options: "cpsat")
    if not walls_bound:
        monkeypatch.setattr(certificates, "model_cut_bound", lambda *args: None)
    compare_static(grid_instance(100 + seed, 3, 3, "static", True), max_sets=1 << 12, backend="auto")
    compare_static(grid_instance(300 + seed, 2, 3, "static", False), max_sets=1 << 14, backend="auto")
