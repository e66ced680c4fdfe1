"""Integral reachability and flows in MILP-reactive's phase 2 (``MilpOptions.integral_phase2``,
:func:`synthesis.routing.model.phase2_integral_columns`) keep the optimum.

* the proof's two steps, on the real models of the exhaustive-optimality generators: a
  solution with binary cuts and *fractional* ``mu`` and flows (the midpoint of two solutions
  of the model with the same cut set) stays a solution when ``mu`` is replaced by its level
  set ``[mu > 0]`` (step 1), and with the cuts and that ``mu`` fixed, a maximum flow of the
  model is integral, a solution, and at least the midpoint's flow (step 2); the checks where
  ``mu`` or the flows were fractional are counted, so they cannot pass vacuously;
* the exhaustive comparisons of ``tests/synthesis/test_optimality.py`` (whose tiny models have fewer
  than :data:`~synthesis.routing.model.INTEGRAL_PHASE2_MIN_ROWS` rows, so the columns stay
  continuous there) run here with them integral on every model, and agree;
* which columns are declared integral: every ``mu`` and flow of MILP-reactive with the
  option on, none otherwise (off, MILP-static and MILP-mixed, models below the row threshold).
"""

from __future__ import annotations

from dataclasses import replace

import highspy
import numpy as np
import pytest

import synthesis.pipeline as pipeline
import synthesis.routing.backends.highs as highs
import synthesis.routing.model as model
from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import Problem, build_graphs
from synthesis.routing.model import RoutingModel, build_model, phase2_integral_columns
from synthesis.routing.result import required_entries
from tests.testing_optimality import compare_reactive, graph_instance, grid_instance

TOL = 1e-6
N = 40  # seeds, as in tests/synthesis/test_optimality.py


def _model(problem: Problem) -> RoutingModel | None:
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    try:
        return build_model(products, options, dict(required_entries(products, options)), check_consistency(products))
    except InconsistentProblem:
        return None


def _solve_lp(rm: RoutingModel, cut: np.ndarray, cost: np.ndarray, mu: np.ndarray | None = None) -> np.ndarray | None:
    """A vertex of the model's polytope minimising ``cost`` with the cut columns fixed to
    ``cut`` (and ``mu`` fixed too when given), or ``None`` if there is none."""
    lp = rm.model.to_highs(cost, maximize=False)
    lp.integrality_ = []
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.passModel(lp)
    cols = rm.cols.cut[rm.var_groups].astype(np.int32)
    h.changeColsBounds(cols.size, cols, cut, cut)
    if mu is not None:
        mcols = rm.cols.reach[rm.cols.reach >= 0].astype(np.int32)
        h.changeColsBounds(mcols.size, mcols, mu, mu)
    h.run()
    if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
        return None
    return np.asarray(h.getSolution().col_value, dtype=float)


def _violation(rm: RoutingModel, x: np.ndarray) -> float:
    a = rm.model.matrix()
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    ax = a @ x
    return float(max(np.max(col_lo - x), np.max(x - col_hi), np.max(row_lo - ax, initial=0.0), np.max(ax - row_hi, initial=0.0)))


def _fractional(v: np.ndarray) -> bool:
    return bool(np.any((v > TOL) & (v < 1.0 - TOL)))


def _steps_check(problem: Problem, rng: np.random.Generator) -> tuple[int, int]:
    """Check both steps of the proof on random cut sets of one instance; the numbers of
    checks in which ``mu``, and the flows, were fractional."""
    rm = _model(problem)
    if rm is None:
        return 0, 0
    mu = rm.cols.reach[rm.cols.reach >= 0]
    f = rm.cols.flow
    out = rm.cols.flow[rm.out_src]
    n_cut = rm.var_groups.size
    frac_mu = frac_f = 0
    for density in (0.0, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6):
        cut = (rng.random(n_cut) < density) * rm.model.bounds()[1][rm.cols.cut[rm.var_groups]]  # groups fixed open stay open
        xs = []
        cost = np.zeros(rm.n_col)
        cost[mu] = rng.uniform(-1.0, 1.0, mu.size)
        cost[f] = rng.uniform(-1.0, 1.0, f.size)
        for sign in (1.0, -1.0):  # two far-apart vertices: their midpoint is fractional
            x = _solve_lp(rm, cut, sign * cost)
            if x is None:
                break
            xs.append(x)
        if len(xs) < 2:
            continue  # this cut set admits no solution
        x = 0.5 * (xs[0] + xs[1])  # a solution with the same cut set (convexity)
        assert _violation(rm, x) <= TOL
        frac_mu += _fractional(x[mu])
        frac_f += _fractional(x[f])
        # step 1: the level set of mu
        level = x.copy()
        level[mu] = (x[mu] > TOL).astype(float)
        assert _violation(rm, level) <= TOL, "the level set [mu > 0] left the model"
        # step 2: with the cuts and that mu fixed, a maximum flow is integral and a solution
        value = np.zeros(rm.n_col)
        value[out] = -1.0
        y = _solve_lp(rm, cut, value, mu=level[mu])
        assert y is not None
        assert not _fractional(y[f]), "a maximum flow vertex with fractional flows"
        assert y[out].sum() >= x[out].sum() - TOL, "the maximum flow is below the solution's flow"
        y[mu] = level[mu]
        assert _violation(rm, y) <= TOL
    return frac_mu, frac_f


def test_both_steps_of_the_proof() -> None:
    """``[mu > 0]`` keeps every row (step 1); then a maximum flow is integral (step 2)."""
    rng = np.random.default_rng(7)
    frac_mu = frac_f = 0
    for seed in range(25):
        for problem in (grid_instance(1100 + seed, 3, 3, "reactive", None), graph_instance(500 + seed)):
            a, b = _steps_check(problem, rng)
            frac_mu, frac_f = frac_mu + a, frac_f + b
    assert frac_mu >= 10, f"only {frac_mu} checks had fractional mu"
    assert frac_f >= 10, f"only {frac_f} checks had fractional flows"


@pytest.mark.parametrize("seed", range(N))
def test_exhaustive_optimum_with_integral_phase2(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """With ``mu`` and the flows integral on every model, MILP-reactive on HiGHS finds the
    exhaustive optimum on the small graphs, 2x2/2x3 and 3x3 grids of
    ``tests/synthesis/test_optimality.py``, and those columns were integral in its phase 2."""
    monkeypatch.setattr(model, "INTEGRAL_PHASE2_MIN_ROWS", 0)
    declared: list[int] = []
    original = model.phase2_integral_columns

    def spy(rm: RoutingModel, options: pipeline.MilpOptions) -> np.ndarray:
        cols = original(rm, options)
        assert np.array_equal(cols, np.concatenate([rm.cols.reach[rm.cols.reach >= 0], rm.cols.flow]))
        declared.append(cols.size)
        return cols

    monkeypatch.setattr(highs, "phase2_integral_columns", spy)
    assert compare_reactive(graph_instance(500 + seed), backend="highs")
    rows, cols = (2, 2) if seed % 3 == 0 else (2, 3)
    compare_reactive(grid_instance(700 + seed, rows, cols, "reactive", None), backend="highs")
    compare_reactive(grid_instance(1100 + seed, 3, 3, "reactive", None), backend="highs")
    assert len(declared) <= 3  # one phase 2 per instance that has a test


def test_comparisons_exercise_integral_phase2() -> None:
    """Most instances of those comparisons have ``mu`` columns (a guard against a vacuous
    comparison: a model without them has nothing to declare binary)."""
    with_mu = 0
    for seed in range(N):
        rows, cols = (2, 2) if seed % 3 == 0 else (2, 3)
        for problem in (
            graph_instance(500 + seed),
            grid_instance(700 + seed, rows, cols, "reactive", None),
            grid_instance(1100 + seed, 3, 3, "reactive", None),
        ):
            rm = _model(problem)
            with_mu += rm is not None and bool(np.any(rm.cols.reach >= 0))
    assert with_mu >= 2 * N, with_mu


def test_which_columns_are_integral(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every ``mu`` and flow of MILP-reactive with the option on; none off, in the other
    modes, or below the row threshold."""
    problem = grid_instance(1101, 3, 3, "reactive", None)
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, dict(required_entries(products, options)), check_consistency(products))
    mu = rm.cols.reach[rm.cols.reach >= 0]
    assert mu.size > 0
    monkeypatch.setattr(model, "INTEGRAL_PHASE2_MIN_ROWS", 0)
    assert np.array_equal(phase2_integral_columns(rm, options), np.concatenate([mu, rm.cols.flow]))
    assert phase2_integral_columns(rm, replace(options, integral_phase2=False)).size == 0
    assert phase2_integral_columns(rm, replace(options, mode="static")).size == 0
    mixed = replace(options, mode="mixed", static_moves=np.zeros(products.ts.n_moves, dtype=bool))
    assert phase2_integral_columns(rm, mixed).size == 0
    monkeypatch.undo()
    assert rm.model.n_row < model.INTEGRAL_PHASE2_MIN_ROWS
    assert phase2_integral_columns(rm, options).size == 0  # a tiny model keeps continuous columns
