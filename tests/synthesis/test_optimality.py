"""Exhaustive optimality of the routing MILP on tiny instances (method.md §5).

The optimum is recomputed here without the MILP, by enumerating cut sets and checking
each with plain breadth-first search and a small augmenting-path max flow:

* a cut set is **valid** when there is no ``Src -> Tgt`` path in G that avoids ``I``
  over uncut edges (bypass), and the system is never trapped: statically, the max
  flow is at least 1; reactively, for every history ``q`` and every kept entry node
  of ``q`` there is a path in ``G_sys`` to ``Tgt_sys`` using no transition cut under
  ``q`` (c6-c8);
* the **optimum** is the largest max flow ``F`` on G without the cut edges, then the
  fewest cut edges of G (``n_cuts``: every edge of G with ``d_e = 1``, tied copies and
  edges touching ``I`` alike).

Static cut sets are *wall sets*: every subset of the cell pairs (c14 on) or of the
directed moves (c14 off) of the grid, each wall cutting every edge of G over its
transition(s). Reactive cut sets are subsets of the restrictable edges of G outside
``E(I)``.

The enumeration lives in ``tests/testing_optimality.py`` (shared with the backend, bound and
reduction tests).
"""

from __future__ import annotations

import random
from collections.abc import Callable

import networkx as nx
import pytest

from synthesis.model.systems import grid_world
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.problem import Problem, build_graphs, make_problem
from tests.testing_optimality import (
    BACKENDS,
    METHOD_EXACT,
    any_path,
    bits,
    compare_reactive,
    compare_static,
    feasible_static,
    graph_instance,
    grid_instance,
    max_flow,
    reactive_optimum_by_sides,
    static_optimum,
    view_of,
)

# --------------------------------------------------------------------------- tests

N = 40


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(N))
def test_static_3x3_walls_both_ways(seed: int, backend: str) -> None:
    """MILP-static with c14 on 3x3 grids: all 2^12 wall sets (fewer with a blocked cell)."""
    compare_static(grid_instance(100 + seed, 3, 3, "static", True), max_sets=1 << 12, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(N))
def test_static_2x3_one_way_walls(seed: int, backend: str) -> None:
    """MILP-static without c14 on 2x3 grids: every set of directed walls."""
    compare_static(grid_instance(300 + seed, 2, 3, "static", False), max_sets=1 << 14, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(N))
def test_reactive_small_graphs(seed: int, backend: str) -> None:
    """MILP-reactive on random graphs of 4-6 states."""
    assert compare_reactive(graph_instance(500 + seed), backend=backend), "instance too large for the enumeration"


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(N))
def test_reactive_small_grids(seed: int, backend: str) -> None:
    """MILP-reactive on 2x2 and 2x3 grids (instances with over 16 candidate edges are skipped)."""
    rows, cols = (2, 2) if seed % 3 == 0 else (2, 3)
    done = compare_reactive(grid_instance(700 + seed, rows, cols, "reactive", None), backend=backend)
    if not done:
        pytest.skip("more than 16 candidate edges")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(N))
def test_reactive_3x3_grids(seed: int, backend: str) -> None:
    """MILP-reactive on 3x3 grids (skipped when every enumeration would be too large)."""
    if not compare_reactive(grid_instance(1100 + seed, 3, 3, "reactive", None), backend=backend):
        pytest.skip("too large for the enumerations")


def test_instance_mix_is_meaningful() -> None:
    """Most generated instances can route the test (a guard against vacuous comparisons)."""
    makers: tuple[Callable[[int], Problem], ...] = (
        lambda s: grid_instance(100 + s, 3, 3, "static", True),
        lambda s: grid_instance(300 + s, 2, 3, "static", False),
        lambda s: graph_instance(500 + s),
        lambda s: grid_instance(700 + s, 2, 2 if s % 3 == 0 else 3, "reactive", None),
    )
    for make in makers:
        routable = 0
        for s in range(N):
            _, products = build_graphs(make(s))
            routable += any_path(view_of(products), 0, through_i=True)
        assert routable >= N // 2


def test_max_flow_helper_matches_networkx() -> None:
    """The brute force's own max flow agrees with networkx on random cut sets."""
    rng = random.Random(4)
    for s in range(15):
        problem = grid_instance(900 + s, 3, 3, "reactive", None)
        _, products = build_graphs(problem)
        v = view_of(products)
        for _ in range(5):
            cut = 0
            for e in range(v.m):
                if rng.random() < 0.2:
                    cut |= 1 << e
            gx = nx.DiGraph()
            gx.add_nodes_from(range(v.n + 1))
            for e in range(v.m):
                if not cut >> e & 1:
                    gx.add_edge(v.src[e], v.dst[e], capacity=1)
            for t in v.tgt:
                gx.add_edge(t, v.n, capacity=v.m + 1)
            want = 0 if v.source in v.tgt else nx.maximum_flow_value(gx, v.source, v.n)
            assert max_flow(v, cut) == want


@pytest.mark.parametrize("backend", BACKENDS)
def test_known_instance_small_reactive(backend: str) -> None:
    """The paper's small-reactive example (2x3): flow 2 with 4 cuts, by enumeration and by the MILP."""
    free = [(r, c) for r in range(2) for c in range(3)]
    ts = grid_world(free, 2, 3, (1, 0), [(0, 2)], {(0, 0): {"I1"}, (1, 2): {"I2"}, (0, 2): {"goal"}})
    problem = make_problem("small-reactive", ts, "F goal", "F I1 & F I2", "reactive")
    _, products = build_graphs(problem)
    best = reactive_optimum_by_sides(view_of(products))
    assert best is not None and (best.flow, best.n_cuts) == (2, 4)
    assert compare_reactive(problem, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("kind", ["static", "reactive"])
def test_status_optimal_without_binaries(kind: str, backend: str) -> None:
    """Start on the test cell (Src in I): nothing to cut, no binary, yet the answer is proven optimal.

    (Regression: HiGHS leaves ``mip_dual_bound`` at 0 on a model without integer
    columns, which once made such answers ``feasible`` with ``mip_gap`` inf.)
    """
    ts = grid_world([(0, 0), (0, 1)], 1, 2, (0, 0), [(0, 1)], {(0, 0): {"I"}, (0, 1): {"goal"}})
    res = synthesize(make_problem("no-binaries", ts, "F goal", "F I", kind), SynthesisOptions(backend=backend))
    assert res.routing.flow == 1 and res.routing.stats["binary_vars"] == 0
    assert res.routing.status == "optimal"
    assert res.routing.mip_gap == 0.0


def trap_instance() -> Problem:
    """A 2x3 static problem whose only (flow, n_cuts)-optimal wall traps the system.

    ::

        goal .  I
        q    p  S

    ``phi_sys = F goal & G(p -> F q)``, ``phi_test = F I``. The cheapest routing wall is
    (1,0) -> (0,0): then a system that goes S -> p -> q stands in (1,0), where every way
    to the goal passes p again after the last q, so it can never meet ``phi_sys``.
    """
    free = [(r, c) for r in range(2) for c in range(3)]
    labels = {(0, 0): {"goal"}, (0, 2): {"I"}, (1, 0): {"q"}, (1, 1): {"p"}}
    ts = grid_world(free, 2, 3, (1, 2), [(0, 0)], labels)
    return make_problem("static-trap", ts, "F goal & G(p -> F q)", "F I", "static")


def test_static_trap_instance_by_enumeration() -> None:
    """The enumeration itself: the bypass/flow optimum (1, 2) is infeasible, the feasible one is (1, 6)."""
    problem = trap_instance()
    _, products = build_graphs(problem)
    v = view_of(products)
    loose, _ = static_optimum(v, problem.system, True)
    strict, _ = static_optimum(v, problem.system, True, require_feasible=True)
    assert loose is not None and (loose.flow, loose.n_cuts) == (1, 2)
    assert strict is not None and (strict.flow, strict.n_cuts) == (1, 6)
    blocked = frozenset((v.state[v.src[e]], v.state[v.dst[e]]) for e in bits(loose.cut))
    assert not feasible_static(v, blocked)


def test_static_walls_are_on_the_map() -> None:
    """MILP-static returns the method's optimum: the walls are on the map, so a system
    that knows them never needs to enter p, and only ``F >= 1`` is required (method.md §5);
    the game calls a run that enters p anyway violated by the system, not trapped by the test.
    With ``closed_loop`` the stricter optimum, which traps no configuration at all."""
    from flowtest_env.game import TestGame
    from synthesis.artifacts.artifact import artifact_of
    from synthesis.artifacts.summary import summary_of

    res = synthesize(trap_instance(), METHOD_EXACT)
    assert (res.routing.flow, int(res.routing.cut_edges.size)) == (1, 2)
    assert res.checks.trapped_nodes.size > 0  # reported, not failed: S -> p -> q with the wall up
    game = TestGame(artifact_of(res, summary_of(res)))
    ts = res.problem.system
    h = game.reset().history
    for cell in [(1, 1), (1, 0)]:  # S -> p -> q
        h = game.next_history[h][ts.index(cell)]
    assert game.doomed[h][ts.index((1, 0))]
    strict = synthesize(trap_instance(), SynthesisOptions(closed_loop=True))
    assert (strict.routing.flow, int(strict.routing.cut_edges.size)) == (1, 6)
    assert strict.checks.trapped_nodes.size == 0


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(200))
def test_sweep_static_3x3(seed: int, backend: str) -> None:
    """A larger static sweep."""
    compare_static(grid_instance(10_000 + seed, 3, 3, "static", True), max_sets=1 << 12, backend=backend)


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(200))
def test_sweep_reactive_graphs(seed: int, backend: str) -> None:
    """A larger reactive sweep on graphs."""
    compare_reactive(graph_instance(20_000 + seed), max_candidates=18, backend=backend)


@pytest.mark.slow
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(200))
def test_sweep_reactive_grids(seed: int, backend: str) -> None:
    """A larger reactive sweep on 2x3 grids."""
    compare_reactive(grid_instance(30_000 + seed, 2, 3, "reactive", None), max_candidates=18, backend=backend)
