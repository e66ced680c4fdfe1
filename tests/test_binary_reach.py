"""Binary reachability columns in MILP-reactive's phase 2 (``MilpOptions.binary_reach``,
:func:`synthesis.routing.model.reach_may_be_binary`) keep the optimum.

* the proof's step, on the real models of the exhaustive-optimality generators: a solution
  with binary cuts and *fractional* ``mu`` (the midpoint of two solutions of the model with
  the same cut set) stays a solution when ``mu`` is replaced by its level set
  ``[mu > 0]``; the instances where ``mu`` was fractional are counted, so the check cannot
  pass vacuously;
* the exhaustive comparisons of ``tests/test_optimality.py`` (whose tiny models have fewer
  than :data:`~synthesis.routing.model.BINARY_REACH_MIN_ROWS` rows, so ``mu`` stays
  continuous there) run here with binary ``mu`` forced on every model, and agree;
* which columns are declared integral: every ``mu`` of MILP-reactive with the option on,
  none otherwise (off, MILP-static and MILP-mixed, models below the row threshold).
"""

from __future__ import annotations

from dataclasses import replace

import highspy
import numpy as np
import pytest
from test_optimality import compare_reactive, graph_instance, grid_instance

import synthesis.pipeline as pipeline
import synthesis.routing.milp as milp
import synthesis.routing.model as model
from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import Problem, build_graphs
from synthesis.routing.model import RoutingModel, build_model, reach_may_be_binary
from synthesis.routing.result import required_entries

TOL = 1e-6
N = 40  # seeds, as in tests/test_optimality.py


def _model(problem: Problem) -> RoutingModel | None:
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    try:
        return build_model(products, options, dict(required_entries(products, options)), check_consistency(products))
    except InconsistentProblem:
        return None


def _solve_lp(rm: RoutingModel, cut: np.ndarray, cost: np.ndarray) -> np.ndarray | None:
    """A vertex of the model's polytope with the cut columns fixed to ``cut``, or ``None``."""
    lp = rm.model.to_highs(cost, maximize=False)
    lp.integrality_ = []
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.passModel(lp)
    cols = rm.cols.cut[rm.var_groups].astype(np.int32)
    h.changeColsBounds(cols.size, cols, cut, cut)
    h.run()
    if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
        return None
    return np.asarray(h.getSolution().col_value, dtype=float)


def _violation(rm: RoutingModel, x: np.ndarray) -> float:
    a = rm.model.matrix()
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    ax = a @ x
    return float(max(np.max(col_lo - x), np.max(x - col_hi), np.max(row_lo - ax, initial=0.0), np.max(ax - row_hi, initial=0.0)))


def _level_set_check(problem: Problem, rng: np.random.Generator) -> int:
    """Check the proof's step on random cut sets of one instance; the number of checks in
    which ``mu`` was fractional."""
    rm = _model(problem)
    if rm is None:
        return 0
    mu = rm.cols.reach[rm.cols.reach >= 0]
    n_cut = rm.var_groups.size
    fractional = 0
    for density in (0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6):
        cut = (rng.random(n_cut) < density) * rm.model.bounds()[1][rm.cols.cut[rm.var_groups]]  # groups fixed open stay open
        xs = []
        cost = np.zeros(rm.n_col)
        cost[mu] = rng.uniform(-1.0, 1.0, mu.size)
        cost[rm.cols.flow] = rng.uniform(-1.0, 1.0, rm.cols.flow.size)
        for sign in (1.0, -1.0):  # two far-apart vertices: their midpoint has fractional mu
            x = _solve_lp(rm, cut, sign * cost)
            if x is None:
                break
            xs.append(x)
        if len(xs) < 2:
            continue  # this cut set admits no solution
        x = 0.5 * (xs[0] + xs[1])  # a solution with the same cut set (convexity)
        assert _violation(rm, x) <= TOL
        if np.any((x[mu] > TOL) & (x[mu] < 1.0 - TOL)):
            fractional += 1
        level = x.copy()
        level[mu] = (x[mu] > TOL).astype(float)
        assert _violation(rm, level) <= TOL, "the level set [mu > 0] left the model"
    return fractional


def test_level_set_of_mu_stays_a_solution() -> None:
    """Replacing fractional ``mu`` by ``[mu > 0]`` keeps every row (the proof's step)."""
    rng = np.random.default_rng(7)
    fractional = 0
    for seed in range(25):
        fractional += _level_set_check(grid_instance(1100 + seed, 3, 3, "reactive", None), rng)
        fractional += _level_set_check(graph_instance(500 + seed), rng)
    assert fractional >= 10, f"only {fractional} checks had fractional mu"


@pytest.mark.parametrize("seed", range(N))
def test_exhaustive_optimum_with_binary_reach(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """With binary ``mu`` on every model, MILP-reactive on HiGHS finds the exhaustive optimum
    on the small graphs, 2x2/2x3 and 3x3 grids of ``tests/test_optimality.py``, and the
    columns were binary in its phase 2."""
    monkeypatch.setattr(model, "BINARY_REACH_MIN_ROWS", 0)
    declared: list[int] = []
    original = model.reach_may_be_binary

    def spy(rm: RoutingModel, options: pipeline.MilpOptions) -> np.ndarray:
        cols = original(rm, options)
        assert np.array_equal(cols, rm.cols.reach[rm.cols.reach >= 0])  # every mu, in phase 2
        declared.append(cols.size)
        return cols

    monkeypatch.setattr(milp, "reach_may_be_binary", spy)
    assert compare_reactive(graph_instance(500 + seed), backend="highs")
    rows, cols = (2, 2) if seed % 3 == 0 else (2, 3)
    compare_reactive(grid_instance(700 + seed, rows, cols, "reactive", None), backend="highs")
    compare_reactive(grid_instance(1100 + seed, 3, 3, "reactive", None), backend="highs")
    assert len(declared) <= 3  # one phase 2 per instance that has a test


def test_comparisons_exercise_binary_reach() -> None:
    """Most instances of those comparisons have ``mu`` columns (a guard against a vacuous
    comparison: a model without them has nothing to declare binary)."""
    with_mu = 0
    for seed in range(N):
        rows, cols = (2, 2) if seed % 3 == 0 else (2, 3)
        for problem in (graph_instance(500 + seed), grid_instance(700 + seed, rows, cols, "reactive", None),
                        grid_instance(1100 + seed, 3, 3, "reactive", None)):
            rm = _model(problem)
            with_mu += rm is not None and bool(np.any(rm.cols.reach >= 0))
    assert with_mu >= 2 * N, with_mu


def test_which_columns_are_binary(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every ``mu`` of MILP-reactive with the option on; none off, or in the other modes."""
    problem = grid_instance(1101, 3, 3, "reactive", None)
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, dict(required_entries(products, options)), check_consistency(products))
    mu = rm.cols.reach[rm.cols.reach >= 0]
    assert mu.size > 0
    monkeypatch.setattr(model, "BINARY_REACH_MIN_ROWS", 0)
    assert np.array_equal(reach_may_be_binary(rm, options), mu)
    assert reach_may_be_binary(rm, replace(options, binary_reach=False)).size == 0
    assert reach_may_be_binary(rm, replace(options, mode="static")).size == 0
    mixed = replace(options, mode="mixed", static_moves=np.zeros(products.ts.n_moves, dtype=bool))
    assert reach_may_be_binary(rm, mixed).size == 0
    monkeypatch.undo()
    assert rm.model.n_row < model.BINARY_REACH_MIN_ROWS
    assert reach_may_be_binary(rm, options).size == 0  # a tiny model keeps continuous mu
