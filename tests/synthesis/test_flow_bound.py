"""The walls' flow bound of MILP-static (synthesis/routing/bounds/flow_bound.py) never cuts off a
valid wall set, fires where the heuristic's bound is loose, and settles phase 1 on a 10x10 grid.

* on small static grids of the exhaustive-optimality generators (walls both ways, one-way
  walls, safety, sequenced and one-cell tests), the bound is at least the largest flow of
  any valid wall set, found by enumerating every wall set (``tests/synthesis/test_optimality.py``);
  the instances where it lies below the heuristic's bound are counted, so the check cannot
  pass vacuously (they are most of the routable ones);
* the same on small random graphs that are not grids (one-way and two-way walls, safety
  objectives, unrestrictable moves: ``test_optimality.graph_instance`` solved as MILP-static);
* the same on small grids shaped like the study's safety and multi-cell reachability specs
  (one or two hazard cells under ``G !haz``, or two test cells under ``F I1 & F I2``), where the
  bound leaves out the dead histories (L5) and takes the smallest over the test cells' stages
  (L4); the instances where L4/L5 alone make it fire are counted;
* it is ``None`` outside MILP-static;
* on a random 10x10 reachability grid it is 2 where the heuristic's bound is 4, and the
  heuristic's flow 2 is then proven the maximum without a search.
"""

from __future__ import annotations

import random
from dataclasses import replace

import pytest

from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem
from synthesis.model.systems import graph_system, grid_world
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.problem import Problem, build_graphs, make_problem
from synthesis.problems.random_grid import first_consistent
from synthesis.routing.bounds import flow_bound
from synthesis.routing.model import build_model
from tests.testing_optimality import graph_instance, grid_instance, static_optimum, view_of


def _bound_and_truth(problem: Problem) -> tuple[int, int, int] | None:
    """``(walls' bound, heuristic's bound, largest flow of a valid wall set)``, ``None`` when
    the model is not built (the problem is inconsistent on its graphs)."""
    _, products = build_graphs(problem)
    try:
        rm = build_model(products, milp_options(problem, SynthesisOptions()), {}, check_consistency(products))
    except InconsistentProblem:
        return None  # inconsistent, or an unrestrictable move from the start to the goal
    guess = rm.edges.guess(products, fixed_open=rm.reductions.fixed_open)
    best, _ = static_optimum(view_of(products), problem.system, problem.bidirectional_cuts)
    bound = guess.upper_bound if rm.flow_bound is None else rm.flow_bound  # None: not below the heuristic's
    assert bound < guess.upper_bound or rm.flow_bound is None
    return bound, guess.upper_bound, 0 if best is None else best.flow


def _check(make: list[Problem]) -> tuple[int, int]:
    """Assert the bound on every instance; return (instances compared, instances where it fires)."""
    compared = fired = 0
    for problem in make:
        got = _bound_and_truth(problem)
        if got is None:
            continue
        bound, heuristic, truth = got
        assert truth <= bound <= heuristic, f"{problem.name}: bound {bound}, heuristic {heuristic}, largest flow {truth}"
        compared += 1
        fired += bound < heuristic
    return compared, fired


@pytest.mark.parametrize(
    ("rows", "cols", "base", "both_ways"),
    [(3, 3, 100, True), (2, 3, 300, False), (3, 3, 5000, True)],
)
def test_bound_never_below_a_valid_wall_set(rows: int, cols: int, base: int, both_ways: bool) -> None:
    compared, fired = _check([grid_instance(base + s, rows, cols, "static", both_ways) for s in range(30)])
    assert compared >= 20 and fired >= 8, (compared, fired)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("rows", "cols", "base", "both_ways"),
    [(3, 3, 6000, True), (2, 3, 7000, False), (2, 4, 8000, True)],
)
def test_bound_never_below_a_valid_wall_set_sweep(rows: int, cols: int, base: int, both_ways: bool) -> None:
    compared, fired = _check([grid_instance(base + s, rows, cols, "static", both_ways) for s in range(200)])
    assert compared >= 100 and fired >= 30, (compared, fired)


@pytest.mark.parametrize(("base", "both_ways"), [(9000, False), (9500, True)])
def test_bound_never_below_a_valid_wall_set_on_graphs(base: int, both_ways: bool) -> None:
    problems = [replace(graph_instance(base + s), kind="static", bidirectional_cuts=both_ways) for s in range(60)]
    compared, fired = _check(problems)
    assert compared >= 30 and fired >= 4, (compared, fired)


def study_like_instance(seed: int, rows: int, cols: int, both_ways: bool) -> Problem:
    """A small grid shaped like the random grid study's specs: start, terminal goal, and
    either a test cell with one or two hazard cells (``F goal & G !haz``, the safety family)
    or two test cells (``F I1 & F I2``, the reachability family with |AP| = 3)."""
    rng = random.Random(seed)
    cells = [(r, c) for r in range(rows) for c in range(cols)]
    picks = rng.sample(cells, len(cells))
    start, goal, rest = picks[0], picks[1], picks[2:]
    labels: dict[tuple[int, int], set[str]] = {goal: {"goal"}}
    if rng.random() < 0.5:
        labels[rest[0]] = {"I"}
        for cell in rest[1 : 2 + (rng.random() < 0.4)]:
            labels[cell] = {"haz"}
        system, test = "F goal & G !haz", "F I"
    else:
        labels[rest[0]], labels[rest[1]] = {"I1"}, {"I2"}
        system, test = "F goal", "F I1 & F I2"
    ts = grid_world(cells, rows, cols, start, [goal], labels)
    return make_problem(f"study-like-{seed}", ts, system, test, "static", both_ways)


def _plain_bound(problem: Problem) -> int | None:
    """The bound of L0-L3 alone (I only, dead nodes kept), ``None`` where no model is built."""
    _, products = build_graphs(problem)
    try:
        rm = build_model(products, milp_options(problem, SynthesisOptions()), {}, check_consistency(products))
    except InconsistentProblem:
        return None
    known = rm.edges.guess(products, fixed_open=rm.reductions.fixed_open).upper_bound
    choices = flow_bound.entry_choices(products, rm.edges.eu, rm.edges.ev, known)
    return known if choices is None else min(known, max((c.flow for c in choices), default=0))


@pytest.mark.parametrize(("rows", "cols", "base", "both_ways"), [(3, 3, 12000, True), (2, 3, 12500, False)])
def test_stages_and_dead_histories_never_below_a_valid_wall_set(rows: int, cols: int, base: int, both_ways: bool) -> None:
    problems = [study_like_instance(base + s, rows, cols, both_ways) for s in range(40)]
    compared, fired = _check(problems)
    sharper = 0
    for problem in problems:
        got, plain = _bound_and_truth(problem), _plain_bound(problem)
        if got is not None and plain is not None:
            sharper += got[0] < plain
    assert compared >= 25 and fired >= 8 and sharper >= 3, (compared, fired, sharper)


@pytest.mark.slow
@pytest.mark.parametrize(("rows", "cols", "base", "both_ways"), [(3, 3, 13000, True), (2, 3, 14000, False), (2, 4, 15000, True)])
def test_stages_and_dead_histories_never_below_a_valid_wall_set_sweep(rows: int, cols: int, base: int, both_ways: bool) -> None:
    compared, fired = _check([study_like_instance(base + s, rows, cols, both_ways) for s in range(150)])
    assert compared >= 90 and fired >= 30, (compared, fired)


def dead_and_live_instance(seed: int) -> Problem:
    """A random graph whose system objective is sequenced (``F(b & F goal)``) or has a
    reaction (``G(a -> F c)``), so that a state can hold both dead and live nodes of G: the
    only case where L5's entry states ``D`` change the bound (the review of session 11)."""
    rng = random.Random(seed)
    n = rng.randint(4, 7)
    names = [f"s{i}" for i in range(n)]
    start, goal, inner = names[0], names[-1], names[1:-1]
    density = rng.uniform(0.25, 0.6)
    edges = [(a, b) for a in names for b in names if a != b and a != goal and rng.random() < density]
    labels: dict[str, set[str]] = {goal: {"goal"}}
    labels.setdefault(rng.choice(inner), set()).add("I1")
    system = "F goal"
    if rng.random() < 0.5:
        labels.setdefault(rng.choice(inner), set()).add("b")
        system = "F(b & F goal)"
    else:
        labels.setdefault(rng.choice([start, *inner]), set()).add("a")
        labels.setdefault(rng.choice(inner), set()).add("c")
        system = "F goal & G(a -> F c)"
    ts = graph_system(names, edges, start, [goal], labels)
    return make_problem(f"dead-and-live-{seed}", ts, system, "F I1", "static", rng.random() < 0.5)


def test_dead_entry_states_are_kept() -> None:
    """L5 must add the states where dead nodes are entered to Y: without them the bound of
    this graph is 0, while a wall set of flow 1 (6 cuts) exists and no heuristic finds it."""
    names = [f"s{i}" for i in range(7)]
    edges = [("s0", "s4"), ("s0", "s5"), ("s1", "s0"), ("s2", "s4"), ("s2", "s5"), ("s3", "s2"), ("s4", "s1"), ("s4", "s5"), ("s5", "s3"), ("s5", "s6")]
    ts = graph_system(names, edges, "s0", ["s6"], {"s1": {"I1"}, "s3": {"b"}, "s6": {"goal"}})
    problem = make_problem("dead-entry", ts, "F(b & F goal)", "F I1", "static", False)
    got = _bound_and_truth(problem)
    assert got is not None
    bound, _, truth = got
    assert truth == 1 and bound >= 1, got
    r = synthesize(problem, SynthesisOptions(backend="highs")).routing
    assert (r.status, r.flow, r.cut_edges.size) == ("optimal", 1, 6)


@pytest.mark.slow
def test_bound_never_below_a_valid_wall_set_with_dead_and_live_histories() -> None:
    compared, fired = _check([dead_and_live_instance(16000 + s) for s in range(80)])
    assert compared >= 25 and fired >= 1, (compared, fired)


def test_no_bound_outside_milp_static() -> None:
    problem = grid_instance(1100, 3, 3, "reactive", None)
    _, products = build_graphs(problem)
    rm = build_model(products, milp_options(problem, SynthesisOptions()), {}, check_consistency(products))
    assert rm.flow_bound is None


def test_settles_the_flow_level_of_a_10x10_grid() -> None:
    _, problem, _ = first_consistent(10, "reachability", 1, 0, "static")
    _, products = build_graphs(problem)
    rm = build_model(products, milp_options(problem, SynthesisOptions()), {}, check_consistency(products))
    heuristic = rm.edges.guess(products, fixed_open=rm.reductions.fixed_open)
    assert (heuristic.flow, heuristic.upper_bound, rm.flow_bound) == (2, 4, 2)
    assert rm.guess(products).upper_bound == 2
    # phase 1 is proven by the bound; phase 2 on HiGHS under a deterministic budget
    test = synthesize(problem, SynthesisOptions(backend="highs", node_limit=2000))
    assert test.routing.flow == 2 and test.checks.bypass_flow == 0
    assert test.routing.status == "optimal"
