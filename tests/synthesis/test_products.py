"""Tests of :mod:`synthesis.graphs.products` against a naive breadth-first product.

For random small grids and graphs with random labels and objectives, the bulk product
``build_product`` must have exactly the reachable ``(s, q)`` nodes and the edges
``(s, q) -> (s', delta(q, L(s')))`` that a plain BFS from ``(s0, delta(q0, L(s0)))``
finds over the moves of T (stay loops excluded), and the derived pieces (node sets
``I``/``Tgt``, projection onto ``G_sys``, entry nodes, kept entries) must match their
definitions in method.md §4-5.
"""

from __future__ import annotations

import random
from collections import deque

import numpy as np
import pytest

from synthesis.graphs.automata import DBA, specification_product
from synthesis.graphs.products import ProductGraph, build_product, build_products, coreachable, reachable
from synthesis.model.specs import parse_objective
from synthesis.model.systems import MOVES, TransitionSystem, graph_system, grid_world

Node = tuple[int, int]

# ------------------------------------------------------------------ random systems


def random_grid(rng: random.Random, max_side: int = 4, n_props: int = 3) -> tuple[TransitionSystem, dict]:
    """A random grid with a few blocked cells, a terminal goal and random propositions.

    Returns the system and the raw description (free cells, terminal cells) for an
    independent recomputation of the moves.
    """
    rows, cols = rng.randint(1, max_side), rng.randint(2, max_side)
    cells = [(r, c) for r in range(rows) for c in range(cols)]
    free = [c for c in cells if rng.random() > 0.2] or cells[:2]
    if len(free) < 2:
        free = cells[:2]
    start, goal = rng.sample(free, 2)
    labels: dict = {goal: {"goal"}}
    props = [f"p{i}" for i in range(n_props)]
    for c in free:
        if c != goal and rng.random() < 0.5:
            labels.setdefault(c, set()).update(p for p in props if rng.random() < 0.4)
    if rng.random() < 0.5:
        labels.setdefault(start, set()).add(rng.choice(props))  # s0 carries a label: q0 must read it
    ts = grid_world(free, rows, cols, start, [goal], labels)
    return ts, {"free": set(free), "terminal": {goal}}


def random_graph(rng: random.Random, n_props: int = 3) -> tuple[TransitionSystem, dict]:
    """A random directed graph of 3..7 named states, the last one terminal."""
    n = rng.randint(3, 7)
    names = [f"s{i}" for i in range(n)]
    goal = names[-1]
    edges = []
    for a in names[:-1]:
        for b in names:
            if rng.random() < 0.35:
                edges.append((a, b))  # may include self-loops: they must be dropped
    props = [f"p{i}" for i in range(n_props)]
    labels: dict = {goal: {"goal"}}
    for s in names[:-1]:
        labels[s] = {p for p in props if rng.random() < 0.35}
    ts = graph_system(names, edges, names[0], [goal], labels)
    return ts, {"edges": {(names.index(a), names.index(b)) for a, b in edges if a != b}}


def random_objectives(rng: random.Random, n_props: int = 3) -> tuple[str, str]:
    props = [f"p{i}" for i in range(n_props)]
    sys_parts = ["F goal"]
    if rng.random() < 0.5:
        sys_parts.append(f"G !{rng.choice(props)}")
    if rng.random() < 0.5:
        a, b = rng.sample(props, 2)
        sys_parts.append(f"G({a} -> F {b})")
    if rng.random() < 0.3:
        a, b = rng.sample(props, 2)
        sys_parts.append(f"G({a} -> !{b})")
    test_parts = []
    for _ in range(rng.randint(1, 2)):
        if rng.random() < 0.5:
            test_parts.append(f"F {rng.choice(props)}")
        else:
            a, b = rng.sample(props, 2)
            test_parts.append(f"F({a} & F({b} | goal))")
    return " & ".join(sys_parts), " & ".join(test_parts)


def random_case(seed: int):
    """A random system with its specification product."""
    rng = random.Random(seed)
    ts, raw = random_grid(rng) if seed % 2 == 0 else random_graph(rng)
    sys_text, test_text = random_objectives(rng)
    spec = specification_product(parse_objective(sys_text, "system"), parse_objective(test_text, "test"), ts.letters())
    return ts, raw, spec, (sys_text, test_text)


# ------------------------------------------------------------------ naive product


def naive_product(ts: TransitionSystem, dba: DBA) -> tuple[Node, set[Node], set[tuple[Node, Node]]]:
    """BFS product from ``(s0, delta(q0, L(s0)))`` over the moves of ``ts``."""
    succ: dict[int, list[int]] = {}
    for a, b in zip(ts.src.tolist(), ts.dst.tolist(), strict=True):
        succ.setdefault(a, []).append(b)
    init = (ts.initial, dba.step(dba.initial, ts.labels[ts.initial]))
    nodes = {init}
    edges: set[tuple[Node, Node]] = set()
    todo = deque([init])
    while todo:
        s, q = todo.popleft()
        for s2 in succ.get(s, []):
            v = (s2, dba.step(q, ts.labels[s2]))
            edges.add(((s, q), v))
            if v not in nodes:
                nodes.add(v)
                todo.append(v)
    return init, nodes, edges


def graph_sets(g: ProductGraph) -> tuple[Node, set[Node], list[tuple[Node, Node]]]:
    key = [(int(s), int(q)) for s, q in zip(g.state, g.hist, strict=True)]
    edges = [(key[u], key[v]) for u, v in zip(g.src.tolist(), g.dst.tolist(), strict=True)]
    return key[g.initial], set(key), edges


def bfs(adj: dict[Node, list[Node]], starts: list[Node]) -> set[Node]:
    seen = set(starts)
    todo = deque(starts)
    while todo:
        u = todo.popleft()
        for v in adj.get(u, []):
            if v not in seen:
                seen.add(v)
                todo.append(v)
    return seen


# -------------------------------------------------------------------------- tests


def test_grid_moves_are_the_four_neighbours() -> None:
    """On random grids, T's moves are exactly the N/S/E/W steps between free cells, none from terminals."""
    rng = random.Random(1)
    for _ in range(40):
        ts, raw = random_grid(rng, max_side=5)
        want = {
            (a, (a[0] + dr, a[1] + dc)) for a in raw["free"] if a not in raw["terminal"] for dr, dc in MOVES.values() if (a[0] + dr, a[1] + dc) in raw["free"]
        }
        got = [(ts.states[a], ts.states[b]) for a, b in zip(ts.src.tolist(), ts.dst.tolist(), strict=True)]
        assert len(got) == len(set(got)) and set(got) == want
        for e, (a, b) in enumerate(got):
            assert MOVES[ts.action[e]] == (b[0] - a[0], b[1] - a[1])
        assert not ts.stay[ts.terminal].any() and ts.stay[~ts.terminal].all()


def test_graph_moves_drop_self_loops_and_duplicates() -> None:
    rng = random.Random(2)
    for _ in range(40):
        ts, raw = random_graph(rng)
        got = list(zip(ts.src.tolist(), ts.dst.tolist(), strict=True))
        assert len(got) == len(set(got)) and set(got) == raw["edges"]


@pytest.mark.parametrize("seed", range(40))
def test_build_product_equals_naive_bfs(seed: int) -> None:
    """Same reachable nodes, same edges (no duplicates, no stay loops), same initial node."""
    ts, _, spec, texts = random_case(seed)
    for dba in (spec.dba, spec.sys, spec.test):
        g = build_product(ts, dba)
        init, nodes, edges = naive_product(ts, dba)
        g_init, g_nodes, g_edges = graph_sets(g)
        assert g.initial == 0 and g_init == init, texts
        assert g.n_nodes == len(g_nodes) == len(nodes) and g_nodes == nodes, texts
        assert len(g_edges) == len(set(g_edges)), "duplicate edges"
        assert set(g_edges) == edges, texts
        assert g.n_hist == dba.n_states
        # each edge follows its move of T, and no edge stays in place
        assert np.array_equal(ts.src[g.move], g.state[g.src])
        assert np.array_equal(ts.dst[g.move], g.state[g.dst])
        assert np.all(g.state[g.src] != g.state[g.dst])


def test_initial_node_reads_the_start_label() -> None:
    """If s0 carries the test proposition, the initial history has already seen it."""
    free = [(0, 0), (0, 1), (0, 2)]
    ts = grid_world(free, 1, 3, (0, 0), [(0, 2)], {(0, 0): {"I"}, (0, 2): {"goal"}})
    spec = specification_product(parse_objective("F goal", "system"), parse_objective("F I", "test"), ts.letters())
    p = build_products(ts, spec)
    g = p.virtual
    assert g.state[g.initial] == ts.initial
    assert spec.accepting_test[g.hist[g.initial]]  # F I already seen at s0
    assert p.intermediate[g.initial]
    assert g.hist[g.initial] == spec.dba.step(spec.dba.initial, ts.labels[ts.initial])


def test_explicit_self_loops_never_become_edges() -> None:
    ts = graph_system(["a", "b", "g"], [("a", "a"), ("a", "b"), ("b", "b"), ("b", "g")], "a", ["g"], {"g": {"goal"}})
    spec = specification_product(parse_objective("F goal", "system"), parse_objective("F goal", "test"), ts.letters())
    g = build_product(ts, spec.dba)
    assert np.all(g.src != g.dst)
    assert np.all(g.state[g.src] != g.state[g.dst])


@pytest.mark.parametrize("seed", range(40))
def test_node_sets_projection_and_entries(seed: int) -> None:
    """I, Tgt, Tgt_sys, the projection G -> G_sys, E(I), entry nodes and kept entries, naively."""
    ts, _, spec, texts = random_case(seed)
    p = build_products(ts, spec)
    g, gs = p.virtual, p.system
    acc_sys, acc_test = spec.accepting_sys, spec.accepting_test
    # node sets
    for v in range(g.n_nodes):
        h = int(g.hist[v])
        assert p.target[v] == bool(acc_sys[h])
        assert p.intermediate[v] == bool(acc_test[h] and not acc_sys[h])
    assert p.source == g.initial
    for v in range(gs.n_nodes):
        assert p.system_target[v] == bool(spec.sys.accepting[int(gs.hist[v]), 0])
    # E(I)
    for e in range(g.n_edges):
        assert p.touches_intermediate[e] == bool(p.intermediate[g.src[e]] or p.intermediate[g.dst[e]])
    # projection: same state, sys component of the history; edges map to edges; onto G_sys
    for v in range(g.n_nodes):
        w = int(p.projection[v])
        assert gs.state[w] == g.state[v] and gs.hist[w] == spec.sys_state[g.hist[v]]
    gs_edges = set(zip(gs.src.tolist(), gs.dst.tolist(), strict=True))
    for u, v in zip(g.src.tolist(), g.dst.tolist(), strict=True):
        assert (int(p.projection[u]), int(p.projection[v])) in gs_edges
    assert set(p.projection.tolist()) == set(range(gs.n_nodes)), "projection must be onto G_sys"
    assert p.projection[g.initial] == gs.initial
    # entry nodes: the initial node and the heads of edges that change the history
    want: dict[int, set[int]] = {int(g.hist[g.initial]): {g.initial}}
    for u, v in zip(g.src.tolist(), g.dst.tolist(), strict=True):
        if g.hist[u] != g.hist[v]:
            want.setdefault(int(g.hist[v]), set()).add(v)
    got = {h: set(nodes.tolist()) for h, nodes in g.entry_nodes.items()}
    assert got == want, texts
    # kept entries: projections that can reach Tgt_sys in G_sys
    radj: dict[Node, list[Node]] = {}
    for u, v in zip(gs.src.tolist(), gs.dst.tolist(), strict=True):
        radj.setdefault(v, []).append(u)
    co = bfs(radj, [v for v in range(gs.n_nodes) if p.system_target[v]])
    kept_want = {}
    for h, nodes in want.items():
        proj = {int(p.projection[v]) for v in nodes} & co
        if proj:
            kept_want[h] = proj
    assert {h: set(x.tolist()) for h, x in p.kept_entries.items()} == kept_want
    assert set(np.flatnonzero(p.system_coreachable).tolist()) == co


@pytest.mark.parametrize("seed", range(20))
def test_reachable_and_coreachable_helpers(seed: int) -> None:
    rng = random.Random(seed)
    n = rng.randint(1, 12)
    edges = [(rng.randrange(n), rng.randrange(n)) for _ in range(rng.randint(0, 25))]
    src = np.array([a for a, _ in edges], dtype=np.int32)
    dst = np.array([b for _, b in edges], dtype=np.int32)
    mask = np.array([rng.random() < 0.2 for _ in range(n)])
    adj: dict = {}
    radj: dict = {}
    for a, b in edges:
        adj.setdefault(a, []).append(b)
        radj.setdefault(b, []).append(a)
    starts = [v for v in range(n) if mask[v]]
    assert set(np.flatnonzero(reachable(n, src, dst, mask)).tolist()) == bfs(adj, starts)
    assert set(np.flatnonzero(coreachable(n, src, dst, mask)).tolist()) == bfs(radj, starts)


def test_small_product_search_orders_nodes_as_scipy_does() -> None:
    """The plain search :func:`build_product` uses on small products numbers the nodes exactly
    as scipy's breadth-first order on the sparse matrix did (shipped pool records name nodes
    by that numbering): random graphs with duplicate edges and self-loops."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order

    from synthesis.graphs.products import _bfs_order

    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(1, 40))
        m = int(rng.integers(0, 4 * n))
        tail, head = rng.integers(0, n, m), rng.integers(0, n, m)
        start = int(rng.integers(0, n))
        adj = sp.csr_matrix((np.ones(m, dtype=np.int8), (tail, head)), shape=(n, n))
        want = breadth_first_order(adj, start, directed=True, return_predecessors=False)
        assert _bfs_order(n, tail, head, start).tolist() == want.tolist()
