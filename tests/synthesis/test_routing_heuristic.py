"""The routing MILP's primal heuristic and its time budget.

* :func:`synthesis.routing.bounds.heuristic.simple_route`: on random grids of the paper's study,
  every route it returns starts at ``Src``, follows edges of G, passes I, ends in
  ``Tgt`` and never returns to a cell, and its moves alone leave no ``Src -> Tgt`` path
  outside I; with it, the heuristic finds a first test where the greedy growth alone
  finds none.
* :func:`synthesis.routing.bounds.heuristic.disjoint_routes`: on 10x10 grids with two test cells,
  the routes it returns share no cell but where the history changes, each is a route of G,
  and grown from them the heuristic reaches flow 2 (the walls' flow bound) where pairs of
  place-simple routes gave 1; its answer passes the solution checks below.
* ``after_first`` (the paper's budget: a limit to the first test, then a little more):
  a solve stops that long after its first test, whether the test came from the
  heuristic or from HiGHS.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from synthesis.graphs.consistency import check_consistency
from synthesis.graphs.products import Products, reachable
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.problem import Problem, build_graphs
from synthesis.problems.random_grid import first_consistent
from synthesis.routing.bounds.heuristic import RouteGraph, RouteSeed, RoutingGuess, Work, disjoint_routes, guess_routing, simple_route, simple_routes
from synthesis.routing.edges import ModelEdges, model_edges
from synthesis.routing.groups import cut_groups
from synthesis.routing.model import build_model
from synthesis.routing.solver_control import Clock


def _instance(size: int, family: str, n: int, seed: int, kind: str = "static") -> tuple[Products, ModelEdges, Problem]:
    _, problem, _ = first_consistent(size, family, n, seed, kind=kind)
    _, products = build_graphs(problem)
    return products, model_edges(products, cut_groups(products, milp_options(problem, SynthesisOptions()))), problem


def _route_seed(products: Products) -> RouteSeed:
    g = products.virtual
    return RouteSeed(products.ts.place[g.state], g.hist, products.intermediate)


CASES = [(5, "reaction", 2, s) for s in range(12)] + [(10, "reaction", 3, s) for s in range(4)] + [(5, "reachability", 3, s) for s in range(4)]


@pytest.mark.parametrize("size,family,n,seed", CASES)
def test_simple_route_is_a_valid_test_by_itself(size: int, family: str, n: int, seed: int) -> None:
    products, me, _ = _instance(size, family, n, seed)
    src, tgt, n_nodes = products.virtual.initial, products.target, products.virtual.n_nodes
    usable = ~(me.c5 & tgt[me.ev])
    route = simple_route(RouteGraph(n_nodes, src, me.eu, me.ev, usable, tgt), _route_seed(products))
    if route is None:
        pytest.skip("no place-simple route found (some instances have none)")
    eu, ev = me.eu[route], me.ev[route]
    assert eu[0] == src and tgt[ev[-1]]
    assert np.array_equal(eu[1:], ev[:-1]), "the route is not a path of G"
    assert usable[route].all()
    nodes = np.concatenate([[src], ev])
    places = products.ts.place[products.virtual.state[nodes]]
    assert np.unique(places).size == places.size, "the route returns to a cell"
    assert products.intermediate[nodes].any(), "the route does not pass I"
    open_groups = ~me.has_var
    open_groups[me.grp[route]] = True
    keep = me.c5 & open_groups[me.grp]
    reach = reachable(n_nodes, me.eu[keep], me.ev[keep], np.arange(n_nodes) == src)
    assert not np.any(reach & tgt), "the route's moves alone let the system bypass I"


def test_route_seed_finds_first_tests_the_greedy_growth_misses() -> None:
    """5x5 reachability & reaction, |AP| = 3, seeds 0-19: the greedy growth alone finds a
    flow-1 cut set on 8, with the route seed on 19 (measured when this was written)."""
    alone = seeded = 0
    for seed in range(20):
        products, me, _ = _instance(5, "reaction", 2, seed)
        a, b = me.guess(products, route_seed=False), me.guess(products)
        assert b.flow >= a.flow
        alone += a.flow >= 1
        seeded += b.flow >= 1
    assert alone <= 10 and seeded >= 17, (alone, seeded)


def test_a_route_seeded_start_is_a_checked_test_within_a_second() -> None:
    """10x10 reachability & reaction, |AP| = 5, seed 1: HiGHS found no test in 10 s before
    the route seed; now the heuristic's start is returned as a checked test."""
    _, problem, _ = first_consistent(10, "reaction", 3, 1, kind="static")
    test = synthesize(problem, SynthesisOptions(time_limit=1.0))
    assert test.routing.flow >= 1
    assert test.checks.ok


def test_after_first_stops_soon_after_the_heuristic_start() -> None:
    """10x10 reachability |AP| = 2, seed 2: HiGHS runs past 10 s without a proof; with
    ``after_first`` it stops that long after the first test. (HiGHS named: ``auto`` runs CP-SAT
    on this static model. Seed 0, used before, is now proven at once by the walls' cut bound:
    its phase-2 answer costs the bound, 24.)"""
    _, problem, _ = first_consistent(10, "reachability", 1, 2, kind="static")
    t0 = time.perf_counter()
    test = synthesize(problem, SynthesisOptions(time_limit=600.0, after_first=1.0, backend="highs"))
    assert time.perf_counter() - t0 < 5.0
    assert test.routing.status == "feasible" and test.routing.flow >= 1
    assert test.checks.ok


def test_after_first_stops_soon_after_highs_finds_a_first_test(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without a heuristic start, the first test comes from HiGHS's maximum-flow phase; the
    solve still ends ``after_first`` seconds after it (the interrupt callback), not at the
    overall limit."""
    import synthesis.routing.edges as milp  # the routing MILP's model edges: where the heuristic is called

    def no_guess(n, src, eu, ev, grp, c5, has_var, target, **kw):  # type: ignore[no-untyped-def]
        g = guess_routing(n, src, eu, ev, grp, c5, has_var, target)
        return RoutingGuess(0, g.upper_bound, np.zeros(eu.size), np.zeros(has_var.size, dtype=bool), np.zeros(n, dtype=bool))

    monkeypatch.setattr(milp, "guess_routing", no_guess)
    first: list[float] = []
    real_first_test = Clock.first_test

    def first_test(self: Clock) -> None:
        if not self.found:
            first.append(time.perf_counter())
        real_first_test(self)

    monkeypatch.setattr(Clock, "first_test", first_test)
    _, problem, _ = first_consistent(10, "reachability", 1, 0, kind="static")
    t0 = time.perf_counter()
    test = synthesize(problem, SynthesisOptions(time_limit=600.0, after_first=1.0, backend="highs"))
    t_end = time.perf_counter()
    assert test.routing.flow >= 1 and test.checks.ok
    # the first test's time depends on HiGHS's search (about 10 s with 1.15, 20-40 s with
    # 1.16 under load); what this test holds is the rule: the end comes after_first (1 s)
    # after it -- plus HiGHS's wait for its next interrupt callback (up to 10 s with 1.16
    # on a loaded machine) and the checks -- not at the 600 s limit
    assert len(first) == 1
    assert t_end - first[0] < 1.0 + 15.0, f"ended {t_end - first[0]:.1f} s after the first test"
    assert t_end - t0 < 120.0


@pytest.mark.parametrize("seed", [0, 3, 4])
def test_disjoint_routes_reach_flow_two_with_two_test_cells(seed: int) -> None:
    """10x10 reachability |AP| = 3 (two test cells), seeds 0, 3, 4: the heuristic gave flow 1
    before disjoint routes (measured when this was written), 2 with them, which is the walls'
    flow bound: phase 1 is proven without a search."""
    products, me, problem = _instance(10, "reachability", 2, seed)
    g, tgt = products.virtual, products.target
    seed_ = _route_seed(products)
    usable = ~(me.c5 & tgt[me.ev])
    work = Work(seed_.work)
    graph = RouteGraph(g.n_nodes, g.initial, me.eu, me.ev, usable, tgt)
    route = next(simple_routes(graph, seed_, work))
    group = disjoint_routes(graph, seed_, route, 2, work)
    if len(group) == 2:
        a, b = group
        changes = g.hist[me.eu] != g.hist[me.ev]
        shared = set(products.ts.place[g.state[me.ev[a[changes[a]]]]].tolist())
        shared |= {int(products.ts.place[g.state[g.initial]]), int(products.ts.place[g.state[me.ev[a[-1]]]])}
        for r in group:
            assert me.eu[r[0]] == g.initial and tgt[me.ev[r[-1]]] and np.array_equal(me.eu[r[1:]], me.ev[r[:-1]])
        cells_a = set(products.ts.place[g.state[me.ev[a]]].tolist())
        cells_b = set(products.ts.place[g.state[me.ev[b]]].tolist())
        assert cells_a & cells_b <= shared
    rm = build_model(products, milp_options(problem, SynthesisOptions()), {}, check_consistency(products))
    guess = rm.guess(products)
    assert guess.flow == guess.upper_bound == 2


@pytest.mark.parametrize("size,family,n,seed", CASES[::2] + [(5, "safety", 3, 0), (10, "reachability", 1, 2), (10, "reachability", 2, 0)])
def test_guess_is_a_valid_cut_set_and_flow(size: int, family: str, n: int, seed: int) -> None:
    """Whatever the heuristic returns is a solution of the model: its cuts leave no
    ``Src -> Tgt`` path outside I, and its edge flow is a unit flow of the value it
    claims, on uncut edges, conserved outside ``Src`` and ``Tgt``."""
    products, me, _ = _instance(size, family, n, seed)
    n_nodes, src, tgt = products.virtual.n_nodes, products.virtual.initial, products.target
    guess = me.guess(products)
    cut = guess.cut_groups
    assert not np.any(cut & ~me.has_var), "an unrestrictable group is cut"
    open_edge = ~cut[me.grp]
    keep = me.c5 & open_edge
    reach = reachable(n_nodes, me.eu[keep], me.ev[keep], np.arange(n_nodes) == src)
    assert not np.any(reach & tgt)
    f = guess.edge_flow > 0.5
    assert not np.any(f & ~open_edge), "flow on a cut edge"
    assert not np.any(f & me.c5 & tgt[me.ev]), "flow straight from outside I into Tgt"
    balance = np.bincount(me.eu[f], minlength=n_nodes) - np.bincount(me.ev[f], minlength=n_nodes)
    inner = ~tgt
    inner[src] = False
    assert not np.any(balance[inner]), "flow not conserved"
    assert balance[src] == guess.flow <= guess.upper_bound


@pytest.mark.parametrize("size,family,n,seed", [(10, "reaction", 4, 18), (5, "reaction", 2, 0), (5, "reachability", 2, 1)])
def test_reactive_guess_traps_no_entry_node(size: int, family: str, n: int, seed: int) -> None:
    """With the feasibility test (c6-c8) the heuristic's answer, when it has flow, traps no
    kept entry node. 10x10 reaction |AP| = 7 seed 18: the greedy growth ends trapping
    (it starts from a trapping cut set), so the answer comes from the route seed; before,
    the trapping answer was returned, was unusable as a start, and HiGHS found no test in
    600 s."""
    import synthesis.routing.phases as phases

    products, me, problem = _instance(size, family, n, seed, kind="reactive")
    groups = cut_groups(products, milp_options(problem, SynthesisOptions()))
    traps = phases.trap_test(products, groups, products.kept_entries)
    guess = me.guess(products, traps=traps)
    assert guess.flow >= 1
    assert not traps(guess.cut_groups)
