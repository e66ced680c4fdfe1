"""``tie_places``: which cuts are tied across the fuel levels of a cell (issue 18 point 5).

``"all"`` ties every cut group, ``"static"`` only the static area's (physical walls, one per
pair of cells and both directions under c14), ``"none"`` none. On a static problem the two
tying modes must build the very same model, so refueling and mars-exploration keep their
answers whichever they name.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import ProblemError
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.builtins import patrolling, refueling
from synthesis.problems.load import load_problem
from synthesis.problems.problem import TIE_PLACES, Problem, build_graphs, make_problem
from synthesis.routing.backends import cpsat
from synthesis.routing.groups import CutGroups, cut_groups
from synthesis.routing.model import build_model
from synthesis.routing.options import MilpOptions


def _groups(problem: Problem, tie: str) -> tuple[CutGroups, MilpOptions]:
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions()), tie_places=tie)
    return cut_groups(products, options), options


def _same_groups(a: CutGroups, b: CutGroups) -> None:
    for name in ("of_edge", "keys", "weight", "restrictable", "static", "move_key"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.parametrize("name", ["refueling", "mars-exploration"])
def test_static_problems_tie_the_same_way_in_both_modes(name: str) -> None:
    """Without reactive moves "static" and "all" group (and key) every edge alike."""
    problem = load_problem(name)
    assert problem.kind == "static" and problem.tie_places in ("all", "static")
    _same_groups(_groups(problem, "all")[0], _groups(problem, "static")[0])


def test_refueling_model_is_identical_in_both_modes() -> None:
    problem = refueling()
    _, products = build_graphs(problem)
    keep = check_consistency(products)
    models = []
    for tie in ("all", "static"):
        options = replace(milp_options(problem, SynthesisOptions()), tie_places=tie)
        models.append(build_model(products, options, {}, keep))
    _same_groups(models[0].groups, models[1].groups)
    a, b = (m.model for m in models)
    assert a.matrix().shape == b.matrix().shape and (a.matrix() != b.matrix()).nnz == 0
    for x, y in zip(a.bounds(), b.bounds(), strict=True):
        assert np.array_equal(x, y)
    assert np.array_equal(np.concatenate(a.integer), np.concatenate(b.integer))


def _place_pair(problem: Problem, moves: np.ndarray) -> np.ndarray:
    ts = problem.system
    a, b = ts.place[ts.src[moves]], ts.place[ts.dst[moves]]
    return np.minimum(a, b).astype(np.int64) * len(ts.places) + np.maximum(a, b)


def test_patrolling_walls_are_tied_and_the_agents_cuts_are_not() -> None:
    """Under "static" (the built-in's physical walls), patrolling's static area has one cut
    group per pair of cells (every fuel level, both directions), while each reactive group
    (moves into column 2) stays one move of T under one history: the test agent blocks per
    fuel level and history."""
    problem = patrolling()
    assert problem.tie_places == "static" and problem.bidirectional_cuts
    _, products = build_graphs(problem)
    groups, _ = _groups(problem, "static")
    g, ts = products.virtual, problem.system
    assert problem.static_moves is not None
    static_edge = problem.static_moves[g.move]
    assert np.array_equal(groups.static[groups.of_edge], static_edge)
    # static: the group is the pair of cells, and each pair is one group
    pair = _place_pair(problem, g.move[static_edge])
    grp = groups.of_edge[static_edge]
    assert np.unique(np.stack([pair, grp]), axis=1).shape[1] == np.unique(pair).size == np.unique(grp).size
    # a wall holds at every fuel level and in both directions: some group has both
    fuel = np.array([s[1] for s in ts.states])
    moves = g.move[static_edge]
    forward = ts.place[ts.src[moves]] < ts.place[ts.dst[moves]]
    per_group = {(k, f, d) for k, f, d in zip(grp.tolist(), fuel[ts.src[moves]].tolist(), forward.tolist(), strict=True)}
    levels = np.bincount([k for k, _, _ in per_group])
    assert levels.max() >= 10  # (fuel level, direction) pairs of one wall
    assert any((k, f, True) in per_group and (k, f2, False) in per_group for k, f, _ in per_group for f2 in range(11))
    # reactive: one state pair under one history per group
    reactive = np.flatnonzero(~static_edge & groups.restrictable[groups.of_edge])
    assert reactive.size
    src, dst = ts.src[g.move[reactive]], ts.dst[g.move[reactive]]
    key = np.stack([groups.of_edge[reactive], np.minimum(src, dst), np.maximum(src, dst), g.hist[g.src[reactive]]])
    assert np.unique(key, axis=1).shape[1] == np.unique(groups.of_edge[reactive]).size
    # "all" would tie the agent's cuts across fuel levels too: fewer reactive groups
    tied_all, _ = _groups(problem, "all")
    assert int((~tied_all.static).sum()) < int((~groups.static).sum())
    assert int(tied_all.static.sum()) == int(groups.static.sum())


def test_tie_places_values() -> None:
    problem = refueling()
    args = (problem.system, "F goal & G !unsafe", "F low", "static")
    assert make_problem("a", *args, tie_places=True).tie_places == "all"
    assert make_problem("b", *args, tie_places=False).tie_places == "none"
    for mode in TIE_PLACES:
        assert make_problem("c", *args, tie_places=mode).tie_places == mode
    assert make_problem("d", *args).tie_places == "none"
    for bad in ("walls", 1, None):
        with pytest.raises(ProblemError, match="unknown tie_places .*expected one of none, all, static"):
            make_problem("e", *args, tie_places=bad)
    _, products = build_graphs(problem)
    with pytest.raises(ValueError, match="unknown tie_places"):
        cut_groups(products, MilpOptions(mode="static", tie_places="walls"))


@pytest.mark.slow
@pytest.mark.skipif(not cpsat.available(), reason="OR-Tools is not installed")
def test_patrolling_with_physical_walls_is_realized() -> None:
    """paper-examples.md's patrolling (static walls tied across fuel levels and directions,
    the built-in): proven optimal at flow 1, the paper's figure, its test agent realized and
    checked (docs/benchmarks.md, "Patrolling with physical walls"; a few minutes)."""
    problem = patrolling()
    test = synthesize(problem, SynthesisOptions(backend="cpsat"))
    assert test.routing.status == "optimal" and test.routing.flow == 1
    assert int(test.routing.cut_edges.size) == 27
    assert test.checks.ok and test.checks.bypass_flow == 0
    assert test.agent is not None and test.agent.counterexamples >= 1
    # the walls hold at every fuel level: a static obstacle's cell pair is walled at all of them
    ts, walls = problem.system, test.strategy.static_obstacles
    pair = np.minimum(ts.place[ts.src], ts.place[ts.dst]) * len(ts.places) + np.maximum(ts.place[ts.src], ts.place[ts.dst])
    walled = np.unique(pair[walls])
    assert walled.size and np.all(walls[np.isin(pair, walled) & problem.static_moves])
