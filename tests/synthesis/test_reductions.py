"""The cut-group reductions (synthesis/routing/bounds/reductions.py) are what they claim and keep
the optimum.

* every group a rule fixes open satisfies the rule's definition, checked with networkx on
  the model's edges, and (rules 1 and 2) every group it leaves free does not;
* on instances of the exhaustive-optimality generators where a rule fires (found by
  search, asserted here so the list cannot go stale), the answer with the reductions
  equals the brute-force optimum of ``tests/synthesis/test_optimality.py``, on every installed
  solver backend;
* the solve reports how many groups each rule fixed.
"""

from __future__ import annotations

from collections.abc import Callable

import networkx as nx
import numpy as np
import pytest

from synthesis.graphs.consistency import check_consistency
from synthesis.graphs.products import Products
from synthesis.pipeline import SynthesisOptions, milp_options, synthesize
from synthesis.problems.problem import Problem, build_graphs
from synthesis.routing.model import RoutingModel, build_model
from synthesis.routing.result import required_entries
from tests.testing_optimality import BACKENDS, compare_reactive, compare_static, graph_instance, grid_instance

# routable instances of the exhaustive-optimality generators on which a rule fires, by rule
# (static3x3 #0 of NEVER_CLOSED is unroutable: the rule must keep that answer too)
NEVER_NEEDED = {"static3x3": [3, 11, 12, 34], "static2x3": [1, 14, 21], "graphs": [16, 24, 56], "r3x3": [6, 26, 31]}
NEVER_CLOSED = {"static3x3": [0, 4, 14, 16], "static2x3": [6, 12, 18], "graphs": [0, 13, 21], "r3x3": [0, 2, 3]}
DOMINATED = {"static3x3": [3, 9, 29, 33, 34, 57, 71, 76], "static2x3": [12, 23, 47, 91, 117, 156]}

GENERATORS: dict[str, Callable[[int], Problem]] = {
    "static3x3": lambda s: grid_instance(100 + s, 3, 3, "static", True),
    "static2x3": lambda s: grid_instance(300 + s, 2, 3, "static", False),
    "graphs": lambda s: graph_instance(500 + s),
    "r3x3": lambda s: grid_instance(1100 + s, 3, 3, "reactive", None),
}
METHOD_EXACT = SynthesisOptions(closed_loop=False)


def _cases(table: dict[str, list[int]]) -> list[tuple[str, int]]:
    return [(gen, seed) for gen, seeds in table.items() for seed in seeds]


def _model(problem: Problem) -> tuple[Products, RoutingModel]:
    _, products = build_graphs(problem)
    opts = milp_options(problem, METHOD_EXACT)
    return products, build_model(products, opts, dict(required_entries(products, opts)), check_consistency(products))


def _graph(eu: np.ndarray, ev: np.ndarray, keep: np.ndarray, n: int) -> nx.DiGraph:
    g = nx.DiGraph()
    g.add_nodes_from(range(n))
    g.add_edges_from(zip(eu[keep].tolist(), ev[keep].tolist(), strict=True))
    return g


def _reach(g: nx.DiGraph, nodes: set[int], forward: bool) -> set[int]:
    out = set(nodes)
    for v in nodes:
        out |= nx.descendants(g, v) if forward else nx.ancestors(g, v)
    return out


def _on_bypass(products: Products, rm: RoutingModel, keep: np.ndarray) -> np.ndarray:
    """``bool`` per model edge: a c5 edge on a ``Src -> Tgt`` walk over kept c5 edges."""
    me, n = rm.edges, products.virtual.n_nodes
    g = _graph(me.eu, me.ev, me.c5 & keep, n)
    fwd = _reach(g, {int(products.virtual.initial)}, True)
    back = _reach(g, set(np.flatnonzero(products.target).tolist()), False)
    return np.array([bool(c and u in fwd and v in back) for c, u, v in zip(me.c5 & keep, me.eu, me.ev, strict=True)])


def _on_route(products: Products, rm: RoutingModel, keep: np.ndarray) -> np.ndarray:
    """``bool`` per model edge: on a ``Src -> Tgt`` walk over kept edges that visits I."""
    me, n = rm.edges, products.virtual.n_nodes
    g = _graph(me.eu, me.ev, keep, n)
    fwd = _reach(g, {int(products.virtual.initial)}, True)
    back = _reach(g, set(np.flatnonzero(products.target).tolist()), False)
    hubs = [i for i in np.flatnonzero(products.intermediate).tolist() if i in fwd and i in back]
    before = _reach(g, set(hubs), True)  # reachable from an I node that is on a route
    after = _reach(g, set(hubs), False)  # reaching such a node
    return np.array([bool(k and u in fwd and v in back and (u in before or v in after)) for k, u, v in zip(keep, me.eu, me.ev, strict=True)])


def _groups_of(rm: RoutingModel, edges: np.ndarray) -> np.ndarray:
    out = np.zeros(rm.groups.keys.size, dtype=bool)
    out[rm.edges.grp[edges]] = True
    return out


@pytest.mark.parametrize(("gen", "seed"), _cases(NEVER_NEEDED) + _cases(NEVER_CLOSED) + _cases(DOMINATED))
def test_rules_match_their_definitions(gen: str, seed: int) -> None:
    products, rm = _model(GENERATORS[gen](seed))
    red, me = rm.reductions, rm.edges
    everything = np.ones(me.eu.size, dtype=bool)
    has_var = me.has_var
    # rule 1: exactly the groups with a binary and no edge on a bypass walk
    assert np.array_equal(red.never_needed, has_var & ~_groups_of(rm, _on_bypass(products, rm, everything)))
    # rule 2: exactly the other groups with a binary whose removal leaves no route
    for k in np.flatnonzero(has_var & ~red.never_needed):
        assert red.never_closed[k] == (not _on_route(products, rm, me.grp != k).any()), f"group {k}"
    # rule 3: each dominated group with its dominator satisfies (i)-(iii)
    w = rm.groups.weight
    for a in np.flatnonzero(red.dominated):
        b = int(red.dominator[a])
        assert has_var[b] and not red.never_needed[b] and not red.never_closed[b]
        assert (w[b], b) < (w[a], a)
        assert not _groups_of(rm, _on_bypass(products, rm, me.grp != b))[a], f"(i) fails for {a} by {b}"
        assert not _groups_of(rm, _on_route(products, rm, me.grp != a))[b], f"(ii) fails for {a} by {b}"
    assert not np.any(red.dominated) or red.checked_dominance


def _fires(problem: Problem, rule: str) -> bool:
    return bool(getattr(_model(problem)[1].reductions, rule).any())


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("gen", "seed"), _cases(NEVER_NEEDED))
def test_never_needed_keeps_the_optimum(gen: str, seed: int, backend: str) -> None:
    _keeps_the_optimum(gen, seed, "never_needed", backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("gen", "seed"), _cases(NEVER_CLOSED))
def test_never_closed_keeps_the_optimum(gen: str, seed: int, backend: str) -> None:
    _keeps_the_optimum(gen, seed, "never_closed", backend)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(("gen", "seed"), _cases(DOMINATED))
def test_dominated_keeps_the_optimum(gen: str, seed: int, backend: str) -> None:
    _keeps_the_optimum(gen, seed, "dominated", backend)


def _keeps_the_optimum(gen: str, seed: int, rule: str, backend: str) -> None:
    """The answer on ``backend`` (every installed one reads the reduced model's bounds)
    equals the brute-force optimum."""
    problem = GENERATORS[gen](seed)
    assert _fires(problem, rule), f"{rule} no longer fires on {gen} #{seed}: pick another instance"
    if gen.startswith("static3x3"):
        compare_static(problem, max_sets=1 << 12, backend=backend)
    elif gen.startswith("static"):
        compare_static(problem, max_sets=1 << 14, backend=backend)
    else:
        assert compare_reactive(problem, backend=backend), "instance too large for the enumeration"


def test_dominance_only_where_its_proof_holds() -> None:
    """Rule 3 runs for MILP-static only, and not with closed_loop."""
    problem = GENERATORS["static3x3"](DOMINATED["static3x3"][0])
    _, products = build_graphs(problem)
    for opts, expect in (
        (milp_options(problem, METHOD_EXACT), True),
        (milp_options(problem, SynthesisOptions(closed_loop=True)), False),
    ):
        rm = build_model(products, opts, {}, check_consistency(products))
        assert rm.reductions.checked_dominance is expect
    reactive = GENERATORS["r3x3"](NEVER_CLOSED["r3x3"][0])
    assert not _model(reactive)[1].reductions.checked_dominance


def test_fixed_groups_get_upper_bound_zero_and_are_reported() -> None:
    problem = GENERATORS["static3x3"](DOMINATED["static3x3"][0])
    _, rm = _model(problem)
    fixed = rm.reductions.fixed_open
    upper = np.concatenate(rm.model.upper)
    cols = rm.cols.cut[rm.var_groups]
    assert np.array_equal(upper[cols] == 0.0, fixed[rm.var_groups])
    assert set(rm.free_groups.tolist()) == set(rm.var_groups.tolist()) - set(np.flatnonzero(fixed).tolist())
    res = synthesize(problem, METHOD_EXACT)
    assert res.routing.stats["groups_fixed_open"] == rm.reductions.counts()
    assert sum(res.routing.stats["groups_fixed_open"].values()) == int(fixed.sum()) > 0
