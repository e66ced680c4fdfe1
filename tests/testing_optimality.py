"""Brute-force optima of the routing MILP on tiny instances (method.md §5), shared by the
optimality tests (``tests/synthesis/test_optimality.py`` and the backend, bound and reduction tests).

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

Two exact reductions keep the reactive enumeration small; both are proved in
:func:`reactive_optimum` and checked against the plain enumeration on the smallest
instances (:func:`reactive_optimum_naive`).
"""

from __future__ import annotations

import itertools
import random
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np
import pytest

from synthesis.graphs.products import Products
from synthesis.model.errors import InconsistentProblem
from synthesis.model.systems import TransitionSystem, graph_system, grid_world
from synthesis.pipeline import SynthesisOptions, SynthesizedTest, synthesize
from synthesis.problems.problem import Problem, build_graphs, make_problem
from synthesis.routing.backends import cpsat

#: The brute force enumerates method.md §5 exactly (entry-node feasibility only).
METHOD_EXACT = SynthesisOptions(closed_loop=False)

#: Every solver backend installed answers the same exhaustive comparisons (issue 18).
BACKENDS = [
    "highs",
    pytest.param("cpsat", marks=pytest.mark.skipif(not cpsat.available(), reason="OR-Tools is not installed (a core dependency, missing here)")),
]


def exact(backend: str) -> SynthesisOptions:
    """:data:`METHOD_EXACT` on one solver backend."""
    return replace(METHOD_EXACT, backend=backend)


# ----------------------------------------------------------------------- plain views


@dataclass
class View:
    """G and G_sys as plain Python lists, read once from :class:`Products`."""

    n: int
    state: list[int]
    hist: list[int]
    src: list[int]
    dst: list[int]
    source: int
    inter: set[int]
    tgt: set[int]
    out: list[list[int]]  # edge ids by tail
    ns: int  # G_sys
    s_state: list[int]
    s_src: list[int]
    s_dst: list[int]
    s_out: list[list[int]]
    s_tgt: set[int]
    s_index: dict[tuple[int, int], int]
    sys_of_hist: list[int]
    restrictable_move: list[bool]
    move: list[int]
    entries: dict[int, list[int]] = field(default_factory=dict)  # history -> kept G_sys entry nodes

    @property
    def m(self) -> int:
        return len(self.src)


def view_of(p: Products) -> View:
    """Copy the graphs out of ``p`` and compute entry nodes from their definition."""
    g, gs = p.virtual, p.system
    n, ns = g.n_nodes, gs.n_nodes
    out: list[list[int]] = [[] for _ in range(n)]
    for e, u in enumerate(g.src.tolist()):
        out[u].append(e)
    s_out: list[list[int]] = [[] for _ in range(ns)]
    for e, u in enumerate(gs.src.tolist()):
        s_out[u].append(e)
    v = View(
        n=n,
        state=g.state.tolist(),
        hist=g.hist.tolist(),
        src=g.src.tolist(),
        dst=g.dst.tolist(),
        source=int(g.initial),
        inter=set(np.flatnonzero(p.intermediate).tolist()),
        tgt=set(np.flatnonzero(p.target).tolist()),
        out=out,
        ns=ns,
        s_state=gs.state.tolist(),
        s_src=gs.src.tolist(),
        s_dst=gs.dst.tolist(),
        s_out=s_out,
        s_tgt=set(np.flatnonzero(p.system_target).tolist()),
        s_index={(int(s), int(q)): i for i, (s, q) in enumerate(zip(gs.state, gs.hist, strict=True))},
        sys_of_hist=p.spec.sys_state.tolist(),
        restrictable_move=p.ts.restrictable.tolist(),
        move=g.move.tolist(),
    )
    # entry nodes of each history: the initial node and heads of history changes,
    # projected to G_sys, kept when Tgt_sys is reachable from them in G_sys
    heads: dict[int, set[int]] = {v.hist[v.source]: {v.source}}
    for e in range(v.m):
        a, b = v.src[e], v.dst[e]
        if v.hist[a] != v.hist[b]:
            heads.setdefault(v.hist[b], set()).add(b)
    for q, nodes in heads.items():
        kept = []
        for x in sorted(nodes):
            w = v.s_index[(v.state[x], v.sys_of_hist[q])]
            if sys_reaches_goal(v, w, frozenset()) and w not in kept:
                kept.append(w)
        if kept:
            v.entries[q] = kept
    return v


# --------------------------------------------------------------------- graph search


def bypass_exists(v: View, cut: int) -> bool:
    """A ``Src -> Tgt`` path avoiding ``I`` over edges not in the bitmask ``cut``."""
    if v.source in v.inter:
        return False
    seen = {v.source}
    todo = [v.source]
    while todo:
        u = todo.pop()
        for e in v.out[u]:
            if cut >> e & 1:
                continue
            w = v.dst[e]
            if w in v.tgt:
                return True
            if w in seen or w in v.inter:
                continue
            seen.add(w)
            todo.append(w)
    return False


def any_path(v: View, cut: int, through_i: bool | None = None) -> bool:
    """A ``Src -> Tgt`` path in G over uncut edges (optionally one that visits I)."""
    start = (v.source, v.source in v.inter)
    seen = {start}
    todo = [start]
    while todo:
        u, met = todo.pop()
        if u in v.tgt and (through_i is None or met):
            return True
        for e in v.out[u]:
            if cut >> e & 1:
                continue
            w = v.dst[e]
            nxt = (w, met or w in v.inter)
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return False


def max_flow(v: View, cut: int) -> int:
    """Unit-capacity max flow ``Src -> Tgt`` on G without the edges in ``cut`` (Edmonds-Karp)."""
    sink = v.n
    if v.source in v.tgt:
        return 0
    # residual arcs: to, cap, index of reverse arc
    to: list[int] = []
    cap: list[int] = []
    adj: list[list[int]] = [[] for _ in range(v.n + 1)]

    def arc(a: int, b: int, c: int) -> None:
        adj[a].append(len(to))
        to.append(b)
        cap.append(c)
        adj[b].append(len(to))
        to.append(a)
        cap.append(0)

    for e in range(v.m):
        if not cut >> e & 1:
            arc(v.src[e], v.dst[e], 1)
    for t in v.tgt:
        arc(t, sink, v.m + 1)
    flow = 0
    while True:
        pred = {v.source: -1}
        todo = deque([v.source])
        while todo and sink not in pred:
            u = todo.popleft()
            for a in adj[u]:
                if cap[a] > 0 and to[a] not in pred:
                    pred[to[a]] = a
                    todo.append(to[a])
        if sink not in pred:
            return flow
        x = sink
        while x != v.source:
            a = pred[x]
            cap[a] -= 1
            cap[a ^ 1] += 1
            x = to[a ^ 1]
        flow += 1


def sys_reaches_goal(v: View, w: int, blocked: frozenset[tuple[int, int]]) -> bool:
    """Is ``Tgt_sys`` reachable from G_sys node ``w`` without the transitions ``blocked``?"""
    if w in v.s_tgt:
        return True
    seen = {w}
    todo = [w]
    while todo:
        u = todo.pop()
        for e in v.s_out[u]:
            x = v.s_dst[e]
            if x in seen or (v.s_state[u], v.s_state[x]) in blocked:
                continue
            if x in v.s_tgt:
                return True
            seen.add(x)
            todo.append(x)
    return False


def feasible(v: View, cut: int) -> bool:
    """c6-c8: every kept entry node of every history reaches ``Tgt_sys`` avoiding ``C(q)``."""
    per_hist: dict[int, set[tuple[int, int]]] = {}
    e = 0
    c = cut
    while c:
        if c & 1:
            per_hist.setdefault(v.hist[v.src[e]], set()).add((v.state[v.src[e]], v.state[v.dst[e]]))
        c >>= 1
        e += 1
    for q, entries in v.entries.items():
        blocked = frozenset(per_hist.get(q, ()))
        if not blocked:
            continue
        for w in entries:
            if not sys_reaches_goal(v, w, blocked):
                return False
    return True


def popcount(x: int) -> int:
    """Number of set bits."""
    return bin(x).count("1")


def bits(x: int) -> list[int]:
    """Positions of the set bits."""
    return [i for i in range(x.bit_length()) if x >> i & 1]


@dataclass
class Optimum:
    """The best valid cut set found: flow first, then fewest cut edges of G."""

    flow: int
    n_cuts: int
    cut: int  # bitmask over G's edges
    n_valid: int  # number of valid cut sets seen (a sanity count)


# --------------------------------------------------------------------- static optimum


def walls(v: View, ts: TransitionSystem, bidirectional: bool) -> list[tuple[frozenset[tuple[int, int]], int]]:
    """Every possible wall: the transitions of T it blocks and the bitmask of G edges it cuts.

    With c14, a wall is an unordered pair of adjacent states of T (both directions);
    without, a directed move. A wall over an unrestrictable move cannot be placed and
    is left out. A wall may cut no edge of G (its moves are never taken).
    """
    moves: dict[object, set[tuple[int, int]]] = {}
    allowed: dict[object, bool] = {}
    for mv, (a, b) in enumerate(zip(ts.src.tolist(), ts.dst.tolist(), strict=True)):
        key = frozenset((a, b)) if bidirectional else (a, b)
        moves.setdefault(key, set()).add((a, b))
        allowed[key] = allowed.get(key, True) and bool(ts.restrictable[mv])
    masks = dict.fromkeys(moves, 0)
    for e in range(v.m):
        a, b = v.state[v.src[e]], v.state[v.dst[e]]
        key = frozenset((a, b)) if bidirectional else (a, b)
        masks[key] |= 1 << e
    return [(frozenset(moves[k]), masks[k]) for k in moves if allowed[k]]


def wall_units(v: View, ts: TransitionSystem, bidirectional: bool) -> list[int]:
    """The G-edge bitmask of every possible wall."""
    return [mask for _, mask in walls(v, ts, bidirectional)]


def feasible_static(v: View, blocked: frozenset[tuple[int, int]]) -> bool:
    """c6-c8 for walls: every kept entry node of every history reaches ``Tgt_sys`` avoiding them."""
    return all(sys_reaches_goal(v, w, blocked) for entries in v.entries.values() for w in entries)


def static_optimum(v: View, ts: TransitionSystem, bidirectional: bool, require_feasible: bool = False) -> tuple[Optimum | None, int]:
    """Enumerate every wall set; return the optimum (``None`` if no valid set) and the count of sets.

    Valid: no bypass and max flow at least 1 (method.md §5: statically, feasibility is
    taken to be ``F >= 1``); with ``require_feasible`` also c6-c8 under the walls.
    """
    units = walls(v, ts, bidirectional)
    upper = max_flow(v, 0)
    verdict: dict[int, bool] = {}
    candidates: list[tuple[int, int, frozenset[tuple[int, int]]]] = []
    for chosen in range(1 << len(units)):
        cut = 0
        blocked: set[tuple[int, int]] = set()
        for i in bits(chosen):
            cut |= units[i][1]
            blocked |= units[i][0]
        if require_feasible and not feasible_static(v, frozenset(blocked)):
            continue
        if cut not in verdict:
            verdict[cut] = not bypass_exists(v, cut)
            if verdict[cut]:
                candidates.append((popcount(cut), cut, frozenset(blocked)))
    candidates.sort(key=lambda c: (c[0], c[1]))
    best: Optimum | None = None
    n_valid = 0
    flows: dict[int, int] = {}
    for n_cuts, cut, _ in candidates:
        # exact pruning: flow never exceeds the uncut max flow `upper`
        if best is not None and best.flow == upper and n_cuts >= best.n_cuts:
            break
        f = flows.setdefault(cut, max_flow(v, cut))
        if f < 1:
            continue
        n_valid += 1
        if best is None or (f, -n_cuts) > (best.flow, -best.n_cuts):
            best = Optimum(f, n_cuts, cut, n_valid)
    return best, 1 << len(units)


# ------------------------------------------------------------------- reactive optimum


def outside_ei_restrictable(v: View) -> list[int]:
    """Edges of G outside ``E(I)`` whose move the harness may restrict."""
    return [e for e in range(v.m) if v.src[e] not in v.inter and v.dst[e] not in v.inter and v.restrictable_move[v.move[e]]]


def h_reachable(v: View) -> set[int]:
    """Nodes ``Src`` reaches in ``G - E(I)`` (never entering I)."""
    fwd = {v.source} if v.source not in v.inter else set()
    todo = list(fwd)
    while todo:
        u = todo.pop()
        for e in v.out[u]:
            w = v.dst[e]
            if w not in fwd and w not in v.inter:
                fwd.add(w)
                todo.append(w)
    return fwd


def relevant_candidates(v: View) -> list[int]:
    """Restrictable edges outside ``E(I)`` on some ``Src -> Tgt`` walk of ``G - E(I)``, not into ``Src``."""
    fwd = h_reachable(v)
    back = set(v.tgt)
    rin: dict[int, list[int]] = {}
    for e in range(v.m):
        rin.setdefault(v.dst[e], []).append(e)
    todo = list(back)
    while todo:
        w = todo.pop()
        for e in rin.get(w, []):
            u = v.src[e]
            if u not in back and u not in v.inter:
                back.add(u)
                todo.append(u)
    return [e for e in outside_ei_restrictable(v) if v.src[e] in fwd and v.dst[e] in back and v.dst[e] != v.source]


def reactive_optimum(v: View, candidates: list[int]) -> Optimum | None:
    """Optimum over subsets of restrictable edges outside ``E(I)``, exactly, via two reductions.

    1. Only ``candidates`` (see :func:`relevant_candidates`) need be considered. Let ``C``
       be valid and ``e`` in ``C`` lie on no ``Src -> Tgt`` walk of ``G - E(I)``, or enter
       ``Src``. Then ``C - {e}`` still has no bypass (a bypass using ``e`` would be such a
       walk; one entering ``Src`` has a bypass suffix after its last visit of ``Src``), is
       still feasible (fewer restrictions), has at least the flow of ``C`` and fewer cuts.
    2. Only inclusion-minimal bypass-blocking sets need be evaluated: if ``B`` blocks every
       bypass and ``C`` strictly contains ``B``, then ``C`` feasible implies ``B`` feasible,
       ``flow(B) >= flow(C)`` and ``|B| < |C|``.
    """
    minimal: list[int] = []
    n = len(candidates)
    for k in range(n + 1):
        for combo in itertools.combinations(range(n), k):
            sel = 0
            for i in combo:
                sel |= 1 << i
            if any(m & sel == m for m in minimal):
                continue
            cut = 0
            for i in combo:
                cut |= 1 << candidates[i]
            if not bypass_exists(v, cut):
                minimal.append(sel)
    best: Optimum | None = None
    n_valid = 0
    for sel in minimal:
        cut = 0
        for i in bits(sel):
            cut |= 1 << candidates[i]
        if not feasible(v, cut):
            continue
        f = max_flow(v, cut)
        if f < 1:
            continue
        n_valid += 1
        if best is None or (f, -popcount(cut)) > (best.flow, -best.n_cuts):
            best = Optimum(f, popcount(cut), cut, n_valid)
    return best


def reactive_optimum_by_sides(v: View) -> Optimum | None:
    """Optimum over the cut sets ``delta+(S)`` of every source side ``S`` (a third, exact method).

    ``S`` ranges over the sets of nodes that contain ``Src`` and otherwise hold nodes
    ``Src`` reaches in ``G - E(I)``, outside ``I`` and ``Tgt`` (the minimal ones below are such);
    its cut is every edge of ``G - E(I)`` leaving ``S`` (unrealisable if one of them is
    unrestrictable). Each such cut blocks every bypass, and every inclusion-minimal
    bypass-blocking set ``B`` is one of them: with ``S`` the nodes ``Src`` reaches in
    ``G - E(I) - B``, every edge of ``G - E(I)`` leaving ``S`` is in ``B`` and already
    blocks every bypass, so by minimality it is ``B``. With reduction 2 of
    :func:`reactive_optimum`, the optimum over these cuts is the optimum.
    """
    if v.source in v.inter:
        # every execution starts in I: the empty cut set is the only minimal one
        return Optimum(max_flow(v, 0), 0, 0, 1) if max_flow(v, 0) >= 1 else None
    free = sorted(h_reachable(v) - v.tgt - {v.source})
    upper = max_flow(v, 0)
    sides: list[tuple[int, int]] = []
    for sel in range(1 << len(free)):
        side = {v.source} | {free[i] for i in bits(sel)}
        cut = 0
        ok = True
        for u in side:
            for e in v.out[u]:
                w = v.dst[e]
                if w in side or w in v.inter:
                    continue
                if not v.restrictable_move[v.move[e]]:
                    ok = False
                    break
                cut |= 1 << e
            if not ok:
                break
        if ok:
            sides.append((popcount(cut), cut))
    best: Optimum | None = None
    n_valid = 0
    for n_cuts, cut in sorted(set(sides)):
        if best is not None and best.flow == upper and n_cuts >= best.n_cuts:
            break
        if not feasible(v, cut):
            continue
        f = max_flow(v, cut)
        if f < 1:
            continue
        n_valid += 1
        if best is None or (f, -n_cuts) > (best.flow, -best.n_cuts):
            best = Optimum(f, n_cuts, cut, n_valid)
    return best


def reactive_optimum_naive(v: View) -> Optimum | None:
    """Plain enumeration of every subset of restrictable edges outside ``E(I)`` (no reduction)."""
    cand = outside_ei_restrictable(v)
    best: Optimum | None = None
    n_valid = 0
    for sel in range(1 << len(cand)):
        cut = 0
        for i in bits(sel):
            cut |= 1 << cand[i]
        if bypass_exists(v, cut) or not feasible(v, cut):
            continue
        f = max_flow(v, cut)
        if f < 1:
            continue
        n_valid += 1
        if best is None or (f, -popcount(cut)) > (best.flow, -best.n_cuts):
            best = Optimum(f, popcount(cut), cut, n_valid)
    return best


# ------------------------------------------------------------------------ instances

Cell = tuple[int, int]


def grid_instance(seed: int, rows: int, cols: int, kind: str, bidirectional: bool | None) -> Problem:
    """A random small grid problem: start, terminal goal, 1-2 test cells, maybe a blocked cell."""
    rng = random.Random(seed)
    cells = [(r, c) for r in range(rows) for c in range(cols)]
    picks = rng.sample(cells, len(cells))
    start, goal = picks[0], picks[1]
    rest = picks[2:]
    blocked: set[Cell] = set()
    if rows * cols >= 6 and rng.random() < 0.4:
        blocked.add(rest.pop())
    labels: dict[Cell, set[str]] = {goal: {"goal"}}
    shape = rng.choice(["one", "one2", "two", "seq"])
    if shape == "one":
        labels.setdefault(rest[0], set()).add("I")
        test = "F I"
    elif shape == "one2":  # one proposition on two cells
        labels.setdefault(rest[0], set()).add("I")
        labels.setdefault(rest[1], set()).add("I")
        test = "F I"
    else:
        i1, i2 = rest[0], rest[1] if rng.random() < 0.85 else rest[0]
        labels.setdefault(i1, set()).add("I1")
        labels.setdefault(i2, set()).add("I2")
        test = "F I1 & F I2" if shape == "two" else "F(I1 & F I2)"
    system = "F goal"
    if len(rest) > 2 and rng.random() < 0.25:
        labels.setdefault(rest[2], set()).add("haz")
        system = "F goal & G !haz"
    if rng.random() < 0.05:  # rarely, the start carries a test proposition
        labels.setdefault(start, set()).add("I" if shape.startswith("one") else "I1")
    free = [c for c in cells if c not in blocked]
    ts = grid_world(free, rows, cols, start, [goal], labels)
    if rng.random() < 0.15:  # a harness that cannot restrict one move
        ts.restrictable[rng.randrange(ts.n_moves)] = False
    return make_problem(f"grid-{seed}", ts, system, test, kind, bidirectional)


def graph_instance(seed: int) -> Problem:
    """A random reactive problem on a graph of 4..6 states."""
    rng = random.Random(seed)
    n = rng.randint(4, 6)
    names = [f"s{i}" for i in range(n)]
    start, goal = names[0], names[-1]
    edges: list[tuple[str, str]] = []
    # a random spine start -> ... -> goal (two-way except into the goal), then random extras
    middle = names[1:-1]
    rng.shuffle(middle)
    spine = [start] + middle[: rng.randint(1, len(middle))] + [goal]
    for a, b in itertools.pairwise(spine):
        edges += [(a, b), (b, a)] if rng.random() < 0.8 else [(a, b)]
    for i in range(n - 1):
        for j in range(i + 1, n):
            r = rng.random()
            a, b = names[i], names[j]
            if r < 0.25:
                edges += [(a, b), (b, a)]
            elif r < 0.35:
                edges.append((a, b))
            elif r < 0.45:
                edges.append((b, a))
    edges = [(a, b) for a, b in edges if a != goal]
    inner = names[1:-1]
    labels: dict[str, set[str]] = {goal: {"goal"}}
    if rng.random() < 0.5:
        labels.setdefault(rng.choice(inner), set()).add("I1")
        test = "F I1"
    else:
        a, b = rng.choice(inner), rng.choice(inner)
        labels.setdefault(a, set()).add("I1")
        labels.setdefault(b, set()).add("I2")
        test = rng.choice(["F I1 & F I2", "F(I1 & F I2)"])
    if rng.random() < 0.05:
        labels.setdefault(goal, set()).add("I1")  # test cell only at the goal: unroutable
    system = "F goal"
    if rng.random() < 0.2:
        labels.setdefault(rng.choice(inner), set()).add("haz")
        system = "F goal & G !haz"
    ts = graph_system(names, edges, start, [goal], labels)
    if rng.random() < 0.15 and ts.n_moves:
        ts.restrictable[rng.randrange(ts.n_moves)] = False
    return make_problem(f"graph-{seed}", ts, system, test, "reactive")


# -------------------------------------------------------------------------- checks


def compare_static(problem: Problem, max_sets: int = 1 << 14, backend: str = "highs") -> None:
    """The MILP-static answer equals the exhaustive optimum over wall sets."""
    _, products = build_graphs(problem)
    v = view_of(products)
    best, n_sets = static_optimum(v, problem.system, problem.bidirectional_cuts)
    assert n_sets <= max_sets
    try:
        res = synthesize(problem, exact(backend))
    except InconsistentProblem as exc:
        assert best is None, f"MILP says {exc.reason!r}, brute force found {best}"
        assert (exc.reason == "unreachable") == (not any_path(v, 0)), exc.reason
        return
    assert best is not None, f"MILP found flow {res.routing.flow}, brute force found no valid wall set"
    got = (res.routing.flow, int(res.routing.cut_edges.size))
    assert got == (best.flow, best.n_cuts), f"MILP (flow, n_cuts) = {got}, exhaustive optimum = {(best.flow, best.n_cuts)}"
    # the MILP's own cut set is a wall set, valid, and has the flow it claims
    assert np.array_equal(res.products.virtual.src, products.virtual.src)
    cut = 0
    for e in res.routing.cut_edges.tolist():
        cut |= 1 << e
    for unit in wall_units(v, problem.system, problem.bidirectional_cuts):
        assert unit & cut in (0, unit), "a wall cuts only some of its G edges"
    assert not bypass_exists(v, cut)
    assert max_flow(v, cut) == res.routing.flow
    assert_proven_optimal(res)


def compare_reactive(problem: Problem, max_candidates: int = 16, max_side_bits: int = 14, backend: str = "highs") -> bool:
    """The MILP-reactive answer equals the exhaustive optimum; ``False`` if skipped (too big).

    Up to three exact enumerations run, whichever are small enough, and must agree:
    plain subsets (at most 12 restrictable edges outside ``E(I)``), minimal
    bypass-blocking subsets of the relevant candidates, and source sides.
    """
    _, products = build_graphs(problem)
    v = view_of(products)
    answers: list[tuple[str, Optimum | None]] = []
    cand = relevant_candidates(v)
    if len(cand) <= max_candidates:
        answers.append(("minimal subsets", reactive_optimum(v, cand)))
    n_free = len(h_reachable(v) - v.tgt - {v.source})
    if n_free <= max_side_bits:
        answers.append(("source sides", reactive_optimum_by_sides(v)))
    if len(outside_ei_restrictable(v)) <= 12:
        answers.append(("all subsets", reactive_optimum_naive(v)))
    if not answers:
        return False
    values = {name: None if b is None else (b.flow, b.n_cuts) for name, b in answers}
    assert len(set(values.values())) == 1, f"the enumerations disagree: {values}"
    best = answers[0][1]
    try:
        res = synthesize(problem, exact(backend))
    except InconsistentProblem as exc:
        assert best is None, f"MILP says {exc.reason!r}, brute force found {(best.flow, best.n_cuts)}"
        assert (exc.reason == "unreachable") == (not any_path(v, 0)), exc.reason
        return True
    assert best is not None, f"MILP found flow {res.routing.flow}, brute force found no valid cut set"
    got = (res.routing.flow, int(res.routing.cut_edges.size))
    assert got == (best.flow, best.n_cuts), f"MILP (flow, n_cuts) = {got}, exhaustive optimum = {(best.flow, best.n_cuts)}"
    cut = 0
    for e in res.routing.cut_edges.tolist():
        cut |= 1 << e
    assert not bypass_exists(v, cut)
    assert feasible(v, cut)
    assert max_flow(v, cut) == res.routing.flow
    assert_proven_optimal(res)
    return True


def assert_proven_optimal(res: SynthesizedTest) -> None:
    """A solve that ran to the end reports ``optimal`` with gap 0."""
    assert res.routing.status == "optimal", res.routing.status
    assert res.routing.mip_gap == 0.0
