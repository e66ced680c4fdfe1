"""The feasibility flows' closing rows per cut column (``MilpOptions.flow_rows = "cut"``,
:func:`synthesis.routing.model._add_feasibility`) keep the answers.

* the proof's claim, on the real models of the exhaustive-optimality generators and of
  :func:`reaction_instance` (the same graphs and grids under a reaction objective, whose
  system automaton puts several copies of a move in ``G_sys``, so one cut column closes
  several flow edges and the two ways differ): with the
  cut columns fixed to a binary vector, the feasibility flows' rows (conservation and c7)
  admit a flow when written per cut column iff they do when written per flow edge, and
  exactly when the routing MILP's own trap search finds no trapped entry node; both
  outcomes are counted, so the check cannot pass vacuously;
* the exhaustive comparisons of ``tests/synthesis/test_optimality.py`` (whose tiny models are far
  below :data:`~synthesis.routing.backends.rules.PER_CUT_MIN_ROWS`), and the same on
  :func:`reaction_instance`, run here with the per-cut rows on every reactive model on
  HiGHS, and agree;
* where ``"auto"`` chooses them (:func:`~synthesis.routing.backends.rules.per_cut_flow_rows`).
"""

from __future__ import annotations

import random
from dataclasses import replace

import highspy
import numpy as np
import pytest

import synthesis.routing.backends.rules as rules
import synthesis.routing.solve as solve
from synthesis.graphs.consistency import check_consistency
from synthesis.graphs.products import Products
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import Problem, build_graphs, make_problem
from synthesis.routing.model import RoutingModel, build_model
from synthesis.routing.options import MilpOptions
from synthesis.routing.result import blocked_of_edges, required_entries
from synthesis.routing.traps import trapped_entries
from tests.testing_optimality import compare_reactive, graph_instance, grid_instance

N = 40  # seeds, as in tests/synthesis/test_optimality.py


def reaction_instance(seed: int) -> Problem:
    """A small graph (even seeds) or 2x3 grid (odd seeds) of ``tests/synthesis/test_optimality.py``
    under the system objective ``F goal & G(r -> F s)`` (``r``, ``s`` on random inner states)
    and the test objective ``F`` of each of its test propositions."""
    base = graph_instance(500 + seed) if seed % 2 == 0 else grid_instance(700 + seed, 2, 3, "reactive", None)
    ts = base.system
    rng = random.Random(seed)
    inner = [i for i in range(len(ts.states)) if not ts.terminal[i] and i != ts.initial] or [ts.initial]
    labels = list(ts.labels)
    for prop in ("r", "s"):
        i = rng.choice(inner)
        labels[i] = labels[i] | {prop}
    present = set().union(*labels)
    test = " & ".join(f"F {p}" for p in ("I", "I1", "I2") if p in present)
    return make_problem(f"reaction-{seed}", replace(ts, labels=labels), "F goal & G(r -> F s)", test, "reactive")


def _models(problem: Problem) -> tuple[Products, MilpOptions, RoutingModel, RoutingModel] | None:
    """The problem's MILP-reactive model written per flow edge and per cut column."""
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    entries = dict(required_entries(products, options))
    try:
        keep = check_consistency(products)
        edge = build_model(products, replace(options, flow_rows="edge"), entries, keep)
        cut = build_model(products, replace(options, flow_rows="cut"), entries, keep)
    except InconsistentProblem:
        return None
    return products, options, edge, cut


def _flows_admit(rm: RoutingModel, cut: np.ndarray) -> bool:
    """Whether the rows holding the feasibility flows' columns admit a solution with the cut
    columns fixed to ``cut`` (0/1 per cut column of ``rm.var_groups``): an LP over those rows."""
    a = rm.model.matrix().tocsr()
    _, _, row_lo, row_hi = rm.model.bounds()
    col_lo, col_hi, _, _ = rm.model.bounds()
    flow_cols = np.concatenate([fl.cols for fl in rm.cols.feasibility])
    rows = np.unique(a[:, flow_cols].nonzero()[0])
    sub = a[rows]
    lo, hi = col_lo.copy(), col_hi.copy()
    dcols = rm.cols.cut[rm.var_groups]
    lo[dcols] = hi[dcols] = cut
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = rm.n_col, rows.size
    lp.col_cost_ = np.zeros(rm.n_col)
    lp.col_lower_, lp.col_upper_ = lo, hi
    lp.row_lower_, lp.row_upper_ = row_lo[rows], row_hi[rows]
    csc = sub.tocsc()
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = csc.indptr.astype(np.int32)
    lp.a_matrix_.index_ = csc.indices.astype(np.int32)
    lp.a_matrix_.value_ = csc.data
    lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = rm.n_col, rows.size
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.passModel(lp)
    h.run()
    return bool(h.getModelStatus() == highspy.HighsModelStatus.kOptimal)


def _spy_builds(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, bool]]:
    """Record each model the solve builds: its ``flow_rows`` and whether it has feasibility flows."""
    built: list[tuple[str, bool]] = []
    original = solve.build_model

    def spy(products: Products, options: MilpOptions, entries: dict[int, np.ndarray], keep: np.ndarray) -> RoutingModel:
        rm = original(products, options, entries, keep)
        built.append((options.flow_rows, bool(rm.cols.feasibility)))
        return rm

    monkeypatch.setattr(solve, "build_model", spy)
    return built


def test_same_flows_for_every_binary_cut_set() -> None:
    """Per cut column or per flow edge, the flows' rows admit a flow at the same binary cut
    vectors, exactly the ones the trap search finds trap-free."""
    rng = np.random.default_rng(11)
    admitted = refused = fewer_rows = 0
    for seed in range(30):
        for problem in (grid_instance(1100 + seed, 3, 3, "reactive", None), graph_instance(500 + seed), reaction_instance(seed)):
            built = _models(problem)
            if built is None or not built[2].cols.feasibility:
                continue
            products, options, edge, cut_model = built
            assert edge.n_col == cut_model.n_col
            fewer_rows += cut_model.model.n_row < edge.model.n_row
            entries = dict(required_entries(products, options))
            for density in (0.1, 0.3, 0.6):
                cut = (rng.random(edge.var_groups.size) < density).astype(float)
                by_edge, by_cut = _flows_admit(edge, cut), _flows_admit(cut_model, cut)
                assert by_edge == by_cut
                is_cut = np.zeros(edge.groups.keys.size, dtype=bool)
                is_cut[edge.var_groups] = cut > 0.5
                blocked = blocked_of_edges(products, np.flatnonzero(is_cut[edge.groups.of_edge]))
                assert by_edge == (not trapped_entries(products, blocked, entries))
                admitted += by_edge
                refused += not by_edge
    assert admitted >= 20, f"only {admitted} cut vectors left every entry node a way"
    assert refused >= 20, f"only {refused} cut vectors trapped an entry node"
    assert fewer_rows >= 5, f"only {fewer_rows} models had fewer rows per cut column"


@pytest.mark.parametrize("seed", range(N))
def test_exhaustive_optimum_with_per_cut_rows(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """With the per-cut rows on every reactive model on HiGHS (``"auto"`` with no row
    threshold), MILP-reactive finds the exhaustive optimum on the small graphs, 2x2/2x3 and
    3x3 grids of ``tests/synthesis/test_optimality.py``, and the per-cut model is what it solved."""
    monkeypatch.setattr(rules, "PER_CUT_MIN_ROWS", 0)
    built = _spy_builds(monkeypatch)
    assert compare_reactive(graph_instance(500 + seed), backend="highs")
    rows, cols = (2, 2) if seed % 3 == 0 else (2, 3)
    compare_reactive(grid_instance(700 + seed, rows, cols, "reactive", None), backend="highs")
    compare_reactive(grid_instance(1100 + seed, 3, 3, "reactive", None), backend="highs")
    compare_reactive(reaction_instance(seed), backend="highs")
    # every model built with feasibility flows was rebuilt per cut column, and solved so
    for (rows_first, flows_first), (rows_next, _) in zip(built, [*built[1:], ("end", False)], strict=True):
        if rows_first == "auto" and flows_first:
            assert rows_next == "cut"


def test_comparisons_exercise_per_cut_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """Most instances of those comparisons are solved per cut column (a guard against a
    vacuous comparison: a model without feasibility flows has no such rows)."""
    monkeypatch.setattr(rules, "PER_CUT_MIN_ROWS", 0)
    built = _spy_builds(monkeypatch)
    for seed in range(N):
        compare_reactive(graph_instance(500 + seed), backend="highs")
    assert sum(rows == "cut" for rows, _ in built) >= N // 2, built
    compared = fewer = 0
    for seed in range(N):
        built_models = _models(reaction_instance(seed))
        fewer += built_models is not None and built_models[3].model.n_row < built_models[2].model.n_row
        compared += compare_reactive(reaction_instance(seed), backend="highs")
    assert compared >= N // 2, f"only {compared} reaction instances were small enough to compare"
    assert fewer >= N // 4, f"only {fewer} reaction instances have fewer rows per cut column"


def test_where_auto_writes_rows_per_cut(monkeypatch: pytest.MonkeyPatch) -> None:
    """HiGHS, MILP-reactive with feasibility flows and at least the row threshold; never on
    CP-SAT, in the other modes, without flows or below the threshold. An unknown value is
    refused."""
    built = _models(grid_instance(1101, 3, 3, "reactive", None))
    assert built is not None
    products, options, edge, _ = built
    assert edge.cols.feasibility
    highs = replace(options, backend="highs")
    assert not rules.per_cut_flow_rows(edge, highs)  # far below the threshold
    monkeypatch.setattr(rules, "PER_CUT_MIN_ROWS", edge.model.n_row)
    assert rules.per_cut_flow_rows(edge, highs)
    assert not rules.per_cut_flow_rows(edge, replace(options, backend="cpsat"))
    assert not rules.per_cut_flow_rows(edge, replace(highs, mode="static"))
    mixed = replace(highs, mode="mixed", static_moves=np.zeros(products.ts.n_moves, dtype=bool))
    assert not rules.per_cut_flow_rows(edge, mixed)
    no_flows = build_model(products, highs, {}, check_consistency(products))
    assert not rules.per_cut_flow_rows(no_flows, highs)
    with pytest.raises(ValueError, match="flow_rows"):
        solve.check_backend(replace(options, flow_rows="rows"))
    assert MilpOptions().flow_rows == "auto"
