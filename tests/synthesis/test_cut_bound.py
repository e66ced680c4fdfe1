"""The walls' cut bound of MILP-static (synthesis/routing/bounds/cut_bound.py) never exceeds the
fewest cuts at a flow level, its accepted candidates are valid and optimal, and it proves
phase 2 of a 10x10 grid without a search.

* on small static grids (walls both ways, one-way walls, safety, sequenced and one-cell
  tests, unrestrictable moves: the generators of ``tests/synthesis/test_optimality.py``), on small
  random graphs, and on small fuel grids whose walls are tied across fuel levels, every cut
  group set is enumerated; at every flow level ``F`` the bound is at most the fewest cuts of
  a valid set with flow at least ``F``; the instances where it is positive and where it is
  tight are counted (only levels some cut set reaches: at the others any bound holds), so the
  check cannot pass vacuously: a bound of 0 everywhere fails every test;
* the candidate phase 2 accepts (completed into a model solution and checked) is a valid
  wall set with flow ``F``, and where it costs the bound it costs the true fewest cuts;
* on random 10x10 reachability grids the bound is 24 and 32 at flow 2 (the optimum), and
  the pipeline's answer is proven by it, on HiGHS and CP-SAT;
* it is off outside MILP-static.
"""

from __future__ import annotations

import random
from dataclasses import replace

import numpy as np
import pytest

from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem, ProblemError
from synthesis.model.systems import fuel_grid_world
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.problem import Problem, build_graphs, make_problem
from synthesis.problems.random_grid import first_consistent
from synthesis.routing.backends import cpsat
from synthesis.routing.bounds.cut_bound import static_cut_bound
from synthesis.routing.certificates import cut_proof
from synthesis.routing.model import RoutingModel, build_model
from synthesis.routing.phases import phase2_cost
from tests.testing_optimality import View, bypass_exists, compare_static, graph_instance, grid_instance, max_flow, view_of

MAX_GROUPS = 13  # enumerate at most 2^13 cut group sets per instance


def _masks(v: View, rm: RoutingModel) -> list[tuple[int, int]]:
    """``(G-edge bitmask, weight)`` of every cut group that may be cut (restrictable)."""
    of_edge = rm.groups.of_edge
    out = []
    for grp in np.flatnonzero(rm.groups.restrictable).tolist():
        edges = np.flatnonzero(of_edge == grp)
        mask = 0
        for e in edges.tolist():
            mask |= 1 << e
        if mask:
            out.append((mask, int(rm.groups.weight[grp])))
    assert v.m == of_edge.size
    return out


def _fewest_by_level(v: View, rm: RoutingModel) -> dict[int, int] | None:
    """The fewest cut edges of a valid cut group set per exact flow (``None``: too many groups)."""
    units = _masks(v, rm)
    if len(units) > MAX_GROUPS:
        return None
    best: dict[int, int] = {}
    for chosen in range(1 << len(units)):
        cut = 0
        for i, (mask, _) in enumerate(units):
            if chosen >> i & 1:
                cut |= mask
        n_cuts = bin(cut).count("1")
        if bypass_exists(v, cut):
            continue
        f = max_flow(v, cut)
        if f >= 1 and n_cuts < best.get(f, 1 << 60):
            best[f] = n_cuts
    return best


def _at_least(best: dict[int, int], level: int) -> float:
    """The fewest cuts of a valid set with flow at least ``level`` (``inf``: none)."""
    return min((c for f, c in best.items() if f >= level), default=float("inf"))


def _check(problems: list[Problem]) -> tuple[int, int, int, int]:
    """Assert the bound and the accepted candidates on every instance and level; return
    (levels compared, levels some cut set reaches with a positive bound, those where it is tight,
    candidates accepted)."""
    compared = positive = tight = accepted = 0
    for problem in problems:
        _, products = build_graphs(problem)
        options = milp_options(problem, SynthesisOptions())
        try:
            rm = build_model(products, options, {}, check_consistency(products))
        except InconsistentProblem:
            continue
        v = view_of(products)
        best = _fewest_by_level(v, rm)
        if not best:
            continue
        for level in range(1, max(best) + 2):
            cb = static_cut_bound(products, rm.groups.of_edge, rm.groups.weight, rm.groups.restrictable, rm.edges.eu, rm.edges.ev, level)
            if cb is None:
                continue
            truth = _at_least(best, level)
            assert cb.value <= truth, f"{problem.name} flow {level}: bound {cb.value}, fewest cuts {truth}"
            compared += 1
            if not np.isfinite(truth):  # no cut set has this flow: any bound holds, so it counts for nothing
                continue
            positive += cb.value > 0
            tight += 0 < cb.value == truth
            proof = cut_proof(products, rm, options, {}, level)
            if proof is None or proof.x is None:
                continue
            accepted += 1
            cut = 0
            for e in np.flatnonzero(rm.cut_of(proof.x)[rm.groups.of_edge]).tolist():
                cut |= 1 << e
            n_cuts = bin(cut).count("1")
            assert n_cuts == float(phase2_cost(rm, options) @ proof.x)
            assert not bypass_exists(v, cut), f"{problem.name}: an accepted candidate leaves a bypass"
            assert max_flow(v, cut) == level, f"{problem.name}: an accepted candidate has flow {max_flow(v, cut)}, not {level}"
            assert n_cuts >= best[level]
            if n_cuts <= proof.bound:  # phase 2 would call it optimal
                assert n_cuts == best[level], f"{problem.name}: candidate {n_cuts} at the bound, fewest cuts {best[level]}"
    return compared, positive, tight, accepted


def fuel_instances(seeds: range) -> list[Problem]:
    """:func:`fuel_instance` of each seed whose test cell is reached at all."""
    out = []
    for seed in seeds:
        try:
            out.append(fuel_instance(seed))
        except ProblemError:
            continue  # the test cell is out of the fuel's reach: no test objective
    return out


def fuel_instance(seed: int) -> Problem:
    """A small fuel grid (2x2 or 2x3, fuel 2-3): the goal, a test cell wanted at low fuel or at
    all, maybe a refuel cell; walls tied across fuel levels (``tie_places``) or not, one-way
    or both ways."""
    rng = random.Random(seed)
    rows, cols = 2, rng.choice([2, 3])
    cells = [(r, c) for r in range(rows) for c in range(cols)]
    start, goal, test_cell, *rest = rng.sample(cells, len(cells))
    refuel = [rest[0]] if rest and rng.random() < 0.4 else []
    low = rng.random() < 0.5

    def label(cell: tuple[int, int], fuel: int) -> list[str]:
        if cell == goal:
            return ["goal"]
        if cell == test_cell and (fuel <= 1 or not low):
            return ["I"]
        return []

    max_fuel = rng.choice([2, 3])
    tie = rng.choice(["all", "none"])
    both = rng.random() < 0.5
    ts = fuel_grid_world(cells, rows, cols, start, max_fuel, refuel, [goal], label)
    if not any("I" in names for names in ts.labels):
        low = False  # the test cell is never reached at low fuel: wanted at any fuel
        ts = fuel_grid_world(cells, rows, cols, start, max_fuel, refuel, [goal], label)
    return make_problem(f"fuel-{seed}", ts, "F goal", "F I", "static", both, tie_places=tie)


@pytest.mark.parametrize(
    ("rows", "cols", "base", "both_ways"),
    [(3, 3, 100, True), (2, 3, 300, False), (2, 3, 5000, True)],
)
def test_bound_never_above_the_fewest_cuts(rows: int, cols: int, base: int, both_ways: bool) -> None:
    compared, positive, tight, _ = _check([grid_instance(base + s, rows, cols, "static", both_ways) for s in range(25)])
    assert compared >= 20 and positive >= 8 and tight >= 5, (compared, positive, tight)


def test_bound_never_above_the_fewest_cuts_on_graphs() -> None:
    problems = [replace(graph_instance(9000 + s), kind="static", bidirectional_cuts=s % 2 == 0) for s in range(50)]
    compared, positive, tight, _ = _check(problems)
    assert compared >= 20 and positive >= 10 and tight >= 8, (compared, positive, tight)


def test_bound_never_above_the_fewest_cuts_with_tied_walls() -> None:
    compared, positive, tight, _ = _check(fuel_instances(range(40)))
    assert compared >= 15 and positive >= 10 and tight >= 10, (compared, positive, tight)


def test_candidates_accepted_are_valid_and_optimal() -> None:
    _, _, _, accepted = _check([grid_instance(700 + s, 3, 3, "static", True) for s in range(25)])
    assert accepted >= 5, accepted


@pytest.mark.slow
@pytest.mark.parametrize(
    ("rows", "cols", "base", "both_ways"),
    [(3, 3, 6000, True), (2, 3, 7000, False), (2, 4, 8000, True), (2, 3, 8500, False)],
)
def test_bound_never_above_the_fewest_cuts_sweep(rows: int, cols: int, base: int, both_ways: bool) -> None:
    compared, positive, tight, _ = _check([grid_instance(base + s, rows, cols, "static", both_ways) for s in range(150)])
    assert compared >= 80 and positive >= 40, (compared, positive, tight)


@pytest.mark.slow
def test_bound_never_above_the_fewest_cuts_sweep_graphs_and_fuel() -> None:
    problems = [replace(graph_instance(20000 + s), kind="static", bidirectional_cuts=s % 2 == 0) for s in range(200)]
    problems += fuel_instances(range(30000, 30150))
    compared, positive, _, _ = _check(problems)
    assert compared >= 100 and positive >= 30, (compared, positive)


def test_no_bound_outside_milp_static() -> None:
    problem = grid_instance(1100, 3, 3, "reactive", None)
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, {}, check_consistency(products))
    assert cut_proof(products, rm, options, {}, 1) is None


@pytest.mark.parametrize(("seed", "bound"), [(0, 24), (1, 32)])
def test_bound_proves_phase_2_of_a_10x10_grid(seed: int, bound: int) -> None:
    _, problem, _ = first_consistent(10, "reachability", 1, seed, "static")
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, {}, check_consistency(products))
    cb = static_cut_bound(products, rm.groups.of_edge, rm.groups.weight, rm.groups.restrictable, rm.edges.eu, rm.edges.ev, 2)
    assert cb is not None and cb.value == bound
    backends = ["highs"] + (["cpsat"] if cpsat.available() else [])
    for backend in backends:
        test = synthesize(problem, SynthesisOptions(backend=backend, node_limit=2000, work_limit=20))
        assert test.routing.flow == 2 and test.checks.bypass_flow == 0
        assert test.routing.status == "optimal" and test.routing.cut_edges.size == bound
        assert test.routing.stats["cut_bound"]["proven"]


def test_candidate_proves_the_maximum_flow_of_a_10x10_grid() -> None:
    """Seed 6: the heuristic's flow is 1, the walls' flow bound 2; a candidate of the cut bound
    at flow 2 passes the checks, so phase 1 is proven by it, and it costs the cut bound (22), so
    phase 2 too: CP-SAT is never run."""
    _, problem, _ = first_consistent(10, "reachability", 1, 6, "static")
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, {}, check_consistency(products))
    assert rm.guess(products).flow == 1 and rm.flow_bound == 2
    if not cpsat.available():
        pytest.skip("OR-Tools is not installed")
    test = synthesize(problem, SynthesisOptions(backend="cpsat", work_limit=20))
    assert (test.routing.status, test.routing.flow, int(test.routing.cut_edges.size)) == ("optimal", 2, 22)
    assert test.checks.ok and test.checks.bypass_flow == 0
    assert test.routing.stats["cpsat"]["runs"] == 0 and test.routing.stats["cut_bound"]["proven"]


@pytest.mark.parametrize("backend", ["highs", "cpsat"])
def test_a_level_the_cut_bound_proves_empty(backend: str) -> None:
    """On this 3x3 grid the cut bound is infinite at flow 2, the heuristic's upper bound (no
    cut set has flow 2); the answer is still the exhaustive optimum
    (``test_optimality.compare_static``)."""
    if backend == "cpsat" and not cpsat.available():
        pytest.skip("OR-Tools is not installed")
    problem = grid_instance(392, 3, 3, "static", True)
    _, products = build_graphs(problem)
    rm = build_model(products, milp_options(problem, SynthesisOptions()), {}, check_consistency(products))
    assert rm.guess(products).upper_bound == 2
    cb = static_cut_bound(products, rm.groups.of_edge, rm.groups.weight, rm.groups.restrictable, rm.edges.eu, rm.edges.ev, 2)
    assert cb is not None and cb.value == float("inf")
    compare_static(problem, backend=backend)
