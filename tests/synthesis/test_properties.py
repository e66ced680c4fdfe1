"""Properties every synthesized test must have, on random grids and graphs.

For random problems (grids up to 5x5 with blocked cells, random graphs; 1-3 test
propositions in visits and sequenced visits; system objectives with safety,
instantaneous and delayed reactions), static and reactive:

* an answer passes checks recomputed here with networkx, not with ``synthesis.checks.verify``:
  bypass flow 0, max flow equal to the reported F (and at least 1), every kept entry
  node of every history reaches ``Tgt_sys`` in ``G_sys`` avoiding the moves restricted
  under that history; the restrictions are exactly the reported cuts;
* the **closed loop** honours Theorem 1 in execution form: exploring every execution
  of the system under the strategy's history-dependent restrictions (over ``T x B_pi``
  directly, not over G; states ``(s, q, met_I)``, which covers every path of every
  length, so no depth bound is needed), no execution reaches the goal without having
  met the test objective (passed through I);
* an inconsistent problem raises the right reason: ``unreachable`` exactly when no
  execution reaches the goal, and never when a simple valid cut set exists.

Seeds are fixed; a failure names its seed.
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from itertools import pairwise

import networkx as nx
import numpy as np
import pytest

from synthesis.graphs.products import Products
from synthesis.model.errors import InconsistentProblem
from synthesis.model.systems import TransitionSystem, graph_system, grid_world
from synthesis.pipeline import SynthesisOptions, SynthesizedTest, synthesize
from synthesis.problems.problem import Problem, build_graphs, make_problem

Cell = tuple[int, int]

# ------------------------------------------------------------------------- problems


def random_test_objective(rng: random.Random, props: list[str]) -> str:
    """Visits and sequenced visits over ``props`` (each used once), sometimes a disjunction."""
    order = props[:]
    rng.shuffle(order)
    parts: list[str] = []
    i = 0
    while i < len(order):
        k = rng.randint(1, len(order) - i)
        chunk = order[i : i + k]
        i += k
        if k == 1:
            parts.append(f"F {chunk[0]}")
        else:
            text = f"F {chunk[-1]}"
            for p in reversed(chunk[:-1]):
                text = f"F({p} & {text})"
            parts.append(text)
    if len(props) >= 2 and rng.random() < 0.15:
        parts = [f"F({props[0]} | {props[1]})"] + [f"F {p}" for p in props[2:]]
    return " & ".join(parts)


def random_system_objective(rng: random.Random, place: Callable[[str], None]) -> str:
    """``F goal`` plus, at random, safety, an instantaneous and a delayed reaction.

    ``place(prop)`` puts ``prop`` on a random non-goal location.
    """
    parts = ["F goal"]
    if rng.random() < 0.35:
        place("haz")
        parts.append("G !haz")
    if rng.random() < 0.35:
        place("p")
        place("q")
        parts.append("G(p -> F q)")
    if rng.random() < 0.15:
        place("a")
        place("b")
        parts.append("G(a -> !b)")
    return " & ".join(parts)


def grid_problem(seed: int, kind: str) -> Problem:
    """A random grid problem up to 5x5 with blocked cells and 1-3 test propositions."""
    rng = random.Random(seed)
    rows, cols = rng.randint(2, 5), rng.randint(2, 5)
    cells = [(r, c) for r in range(rows) for c in range(cols)]
    blocked = {c for c in cells if rng.random() < 0.15}
    free = [c for c in cells if c not in blocked]
    if len(free) < 4:
        free = cells
    start, goal = rng.sample(free, 2)
    others = [c for c in free if c != goal]
    labels: dict[Cell, set[str]] = {goal: {"goal"}}

    def place(prop: str) -> None:
        cands = [c for c in others if c != start] or others
        labels.setdefault(rng.choice(cands), set()).add(prop)

    props = [f"I{i + 1}" for i in range(rng.randint(1, 3))]
    for p in props:
        place(p)
    test = random_test_objective(rng, props)
    system = random_system_objective(rng, place)
    ts = grid_world(free, rows, cols, start, [goal], labels)
    return make_problem(f"grid-{seed}", ts, system, test, kind)


def graph_problem(seed: int, kind: str) -> Problem:
    """A random graph problem of 4-8 states with a start-to-goal spine (two-way moves on even seeds)."""
    rng = random.Random(seed)
    n = rng.randint(4, 8)
    names = [f"v{i}" for i in range(n)]
    start, goal = names[0], names[-1]
    middle = names[1:-1]
    rng.shuffle(middle)
    spine = [start] + middle[: rng.randint(1, len(middle))] + [goal]
    edges = []
    for a, b in pairwise(spine):
        edges += [(a, b)] + ([(b, a)] if b != goal and rng.random() < 0.8 else [])
    two_way = seed % 2 == 0  # even seeds: reversible, as method.md §2 assumes
    for a in names[:-1]:
        for b in names:
            if a != b and rng.random() < 0.22:
                edges.append((a, b))
                if two_way and b != goal:
                    edges.append((b, a))
    if two_way:
        edges += [(b, a) for a, b in edges if b != goal and a != goal]
    labels: dict[str, set[str]] = {goal: {"goal"}}

    def place(prop: str) -> None:
        labels.setdefault(rng.choice(names[1:-1]), set()).add(prop)

    props = [f"I{i + 1}" for i in range(rng.randint(1, 3))]
    for p in props:
        place(p)
    test = random_test_objective(rng, props)
    system = random_system_objective(rng, place)
    ts = graph_system(names, edges, start, [goal], labels)
    return make_problem(f"graph-{seed}", ts, system, test, kind)


# ------------------------------------------------------------------ networkx views


def g_digraph(p: Products, keep: np.ndarray | None = None) -> nx.DiGraph:
    """G (optionally a subset of its edges) plus a super sink ``"T"`` fed by every Tgt node."""
    g = p.virtual
    d = nx.DiGraph()
    d.add_nodes_from(range(g.n_nodes))
    d.add_node("T")
    for e in range(g.n_edges) if keep is None else np.flatnonzero(keep):
        d.add_edge(int(g.src[e]), int(g.dst[e]), capacity=1)
    for t in np.flatnonzero(p.target):
        d.add_edge(int(t), "T", capacity=g.n_edges + 1)
    return d


def flow_value(p: Products, keep: np.ndarray) -> int:
    src = p.virtual.initial
    if p.target[src]:
        return 0
    return int(nx.maximum_flow_value(g_digraph(p, keep), src, "T"))


def edges_blocked_by(p: Products, blocked: np.ndarray) -> np.ndarray:
    """Edges of G whose move is restricted (``blocked[q, move]``) under the tail's history."""
    g = p.virtual
    return np.array([bool(blocked[g.hist[u], m]) for u, m in zip(g.src.tolist(), g.move.tolist(), strict=True)], dtype=bool)


def touches_i(p: Products) -> np.ndarray:
    g = p.virtual
    return np.array([bool(p.intermediate[u] or p.intermediate[v]) for u, v in zip(g.src, g.dst, strict=True)], dtype=bool)


def entry_projections(p: Products) -> dict[int, set[int]]:
    """Per history, the G_sys projections of its entry nodes that can reach Tgt_sys."""
    g, gs = p.virtual, p.system
    heads: dict[int, set[int]] = {int(g.hist[g.initial]): {int(g.initial)}}
    for u, v in zip(g.src.tolist(), g.dst.tolist(), strict=True):
        if g.hist[u] != g.hist[v]:
            heads.setdefault(int(g.hist[v]), set()).add(v)
    index = {(int(s), int(q)): i for i, (s, q) in enumerate(zip(gs.state, gs.hist, strict=True))}
    sys_graph = nx.DiGraph()
    sys_graph.add_nodes_from(range(gs.n_nodes))
    sys_graph.add_edges_from(zip(gs.src.tolist(), gs.dst.tolist(), strict=True))
    tgt = set(np.flatnonzero(p.system_target).tolist())
    co = set(tgt)
    for t in tgt:
        co |= nx.ancestors(sys_graph, t)
    out: dict[int, set[int]] = {}
    for h, nodes in heads.items():
        proj = {index[(int(g.state[v]), int(p.spec.sys_state[h]))] for v in nodes} & co
        if proj:
            out[h] = proj
    return out


def trapped(p: Products, blocked: np.ndarray) -> list[tuple[int, int]]:
    """(history, G_sys node) pairs of kept entries with no G_sys path to Tgt_sys under ``blocked[history]``."""
    gs = p.system
    tgt = set(np.flatnonzero(p.system_target).tolist())
    bad = []
    for h, entries in entry_projections(p).items():
        d = nx.DiGraph()
        d.add_nodes_from(range(gs.n_nodes))
        for e in range(gs.n_edges):
            if not blocked[h, gs.move[e]]:
                d.add_edge(int(gs.src[e]), int(gs.dst[e]))
        for w in entries:
            if w in tgt:
                continue
            if not (nx.descendants(d, w) & tgt):
                bad.append((h, w))
    return bad


# ------------------------------------------------------------------- closed loop


def closed_loop(p: Products, blocked: np.ndarray) -> tuple[set[tuple[int, int, bool]], list[tuple[int, int]]]:
    """Every configuration ``(s, q, met_I)`` the system can reach under the restrictions.

    Explored over T and B_pi directly (not over G): the system moves along T's moves
    not blocked under its current history ``q``, and ``q`` reads the label entered.
    Returns the reachable configurations and the goal configurations reached without
    having met I (each a violation of Theorem 1).
    """
    ts, pi = p.ts, p.spec.dba
    acc_sys, acc_test = p.spec.accepting_sys, p.spec.accepting_test
    letter = {a: i for i, a in enumerate(pi.letters)}
    out: dict[int, list[tuple[int, int]]] = {}
    for m, (a, b) in enumerate(zip(ts.src.tolist(), ts.dst.tolist(), strict=True)):
        out.setdefault(a, []).append((m, b))
    q0 = int(pi.delta[pi.initial, letter[ts.labels[ts.initial]]])

    def in_i(q: int) -> bool:
        return bool(acc_test[q] and not acc_sys[q])

    start = (ts.initial, q0, in_i(q0))
    seen = {start}
    todo = deque([start])
    bad: list[tuple[int, int]] = []
    while todo:
        s, q, met = todo.popleft()
        if acc_sys[q]:
            if not met:
                bad.append((s, q))
            continue  # the test is over
        for m, s2 in out.get(s, []):
            if blocked[q, m]:
                continue
            q2 = int(pi.delta[q, letter[ts.labels[s2]]])
            nxt = (s2, q2, met or in_i(q2))
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen, bad


def trapped_configurations(p: Products, blocked: np.ndarray) -> list[tuple[int, int]]:
    """Closed-loop configurations ``(s, q)`` where the system is trapped by the test.

    Trapped: reachable under the restrictions, not at the goal, the goal still reachable
    from there without restrictions (the system has not doomed itself), yet not
    reachable under the restrictions (history-dependent, as the closed loop applies them).
    """
    ts, pi = p.ts, p.spec.dba
    acc_sys = p.spec.accepting_sys
    letter = {a: i for i, a in enumerate(pi.letters)}
    out: dict[int, list[tuple[int, int]]] = {}
    for m, (a, b) in enumerate(zip(ts.src.tolist(), ts.dst.tolist(), strict=True)):
        out.setdefault(a, []).append((m, b))

    def succ(x: tuple[int, int], restricted: bool) -> list[tuple[int, int]]:
        s, q = x
        return [(s2, int(pi.delta[q, letter[ts.labels[s2]]])) for m, s2 in out.get(s, []) if not (restricted and blocked[q, m])]

    def graph(restricted: bool) -> nx.DiGraph:
        d = nx.DiGraph()
        for s in range(ts.n_states):
            for q in range(pi.n_states):
                d.add_node((s, q))
                if not acc_sys[q]:
                    d.add_edges_from(((s, q), y) for y in succ((s, q), restricted))
        return d

    free, tight = graph(False), graph(True)
    goals = [x for x in free if acc_sys[x[1]]]
    q0 = int(pi.delta[pi.initial, letter[ts.labels[ts.initial]]])
    start = (ts.initial, q0)
    reach = nx.descendants(tight, start) | {start}
    can_free = set(goals).union(*(nx.ancestors(free, g) for g in goals))
    can_tight = set(goals).union(*(nx.ancestors(tight, g) for g in goals))
    return sorted(x for x in reach if not acc_sys[x[1]] and x in can_free and x not in can_tight)


def reversible(ts) -> bool:
    """method.md §2's assumption: every move is bidirectional unless it enters a terminal state."""
    moves = set(zip(ts.src.tolist(), ts.dst.tolist(), strict=True))
    return all((b, a) in moves for a, b in moves if not ts.terminal[b])


# ------------------------------------------------------------------------- checks


def check_answer(res: SynthesizedTest) -> None:
    """Every property of a synthesized test, recomputed independently."""
    p, problem = res.products, res.problem
    g, ts = p.virtual, p.ts
    strat = res.strategy
    blocked = strat.blocked
    restricted = edges_blocked_by(p, blocked)
    cut = np.zeros(g.n_edges, dtype=bool)
    cut[res.routing.cut_edges] = True
    e_i = touches_i(p)
    if problem.kind == "static":
        # C(q) is the same for every q: the walls (restrictions may repeat them per history)
        assert not (strat.restrictions & ~strat.static_obstacles[None, :]).any()
        assert (blocked == strat.static_obstacles[None, :]).all()
        assert np.array_equal(restricted, cut), "the walls block exactly the cut edges of G"
        if problem.bidirectional_cuts:
            idx = ts.move_index()
            for m in np.flatnonzero(strat.static_obstacles):
                back = idx.get((int(ts.dst[m]), int(ts.src[m])))
                assert back is None or strat.static_obstacles[back], "c14: a wall blocks both ways"
    else:
        assert not strat.static_obstacles.any()
        assert not (cut & e_i).any(), "reactive cuts lie outside E(I)"
        assert np.array_equal(restricted, cut), "C(q) restricts exactly the cut edges"
    assert not (restricted & ~ts.restrictable[g.move]).any(), "only harness moves are restricted"
    # Theorem 1 on G: no bypass; and the flow is what the MILP said
    assert flow_value(p, ~e_i & ~restricted) == 0
    f = flow_value(p, ~restricted)
    assert f == res.routing.flow >= 1
    # Theorem 2 (c6-c8): no kept entry node is trapped
    assert trapped(p, blocked) == []
    # Theorem 1 in execution form
    reach, bad = closed_loop(p, blocked)
    assert bad == [], f"executions reach the goal without meeting the test objective: {bad[:3]}"
    assert any(p.spec.accepting_sys[q] for _, q, _ in reach), "the closed loop never reaches the goal"
    # Theorem 2 in execution form: on a reversible system the test never traps the system
    if reversible(ts):
        assert trapped_configurations(p, blocked) == [], "the test traps the system"


def simple_witness_exists(p: Products, kind: str) -> bool:
    """A quick valid cut set, if one of two obvious ones works (then the problem is consistent).

    The empty cut set (when nothing bypasses I already); reactively also the cut of
    every edge that enters Tgt from outside I.
    """
    g = p.virtual
    e_i = touches_i(p)
    if flow_value(p, ~e_i) == 0 and flow_value(p, np.ones(g.n_edges, dtype=bool)) >= 1:
        return True
    if kind != "reactive":
        return False
    late = ~e_i & p.target[g.dst] & p.ts.restrictable[g.move]
    if flow_value(p, ~e_i & ~late) != 0 or flow_value(p, ~late) < 1:
        return False
    blocked = np.zeros((g.n_hist, p.ts.n_moves), dtype=bool)
    blocked[g.hist[g.src[late]], g.move[late]] = True
    return trapped(p, blocked) == []


def check_inconsistent(problem: Problem, exc: InconsistentProblem) -> None:
    _, p = build_graphs(problem)
    g = p.virtual
    reach_goal = flow_value(p, np.ones(g.n_edges, dtype=bool)) >= 1
    assert exc.reason in ("unreachable", "unroutable")
    assert (exc.reason == "unreachable") == (not reach_goal), (exc.reason, reach_goal)
    assert not simple_witness_exists(p, problem.kind), f"reported {exc.reason!r} but a valid cut set exists"


def run_case(problem: Problem, time_limit: float | None = None) -> str:
    """Synthesize and check; return ``"ok"`` or the inconsistency reason.

    With a ``time_limit``, a solve that finds nothing in time is skipped.
    """
    try:
        res = synthesize(problem, SynthesisOptions(time_limit=time_limit))
    except TimeoutError:
        pytest.skip(f"no solution within {time_limit} s")
    except InconsistentProblem as exc:
        check_inconsistent(problem, exc)
        return exc.reason
    check_answer(res)
    return "ok"


# -------------------------------------------------------------------------- tests

SEEDS = range(30)


@pytest.mark.parametrize("kind", ["static", "reactive"])
@pytest.mark.parametrize("seed", SEEDS)
def test_grid_answers_hold(seed: int, kind: str) -> None:
    """Random grids up to 5x5: answers pass every check, inconsistencies have the right reason."""
    run_case(grid_problem(40_000 + seed, kind))


@pytest.mark.parametrize("kind", ["static", "reactive"])
@pytest.mark.parametrize("seed", range(20))
def test_graph_answers_hold(seed: int, kind: str) -> None:
    """Random graphs of 4-8 states, one-way moves on odd seeds."""
    run_case(graph_problem(50_000 + seed, kind))


def test_generators_give_consistent_instances() -> None:
    """Most random problems have a test (so the properties above are not vacuous)."""
    outcomes = [run_case(grid_problem(40_000 + s, "reactive")) for s in range(0, 30, 3)]
    assert outcomes.count("ok") >= len(outcomes) // 2, outcomes


def test_unreachable_goal_is_reported() -> None:
    """The middle cell of a 1x3 corridor is blocked: the goal cannot be reached."""
    ts = grid_world([(0, 0), (0, 2)], 1, 3, (0, 0), [(0, 2)], {(0, 2): {"goal"}, (0, 0): {"I"}})
    for kind in ("static", "reactive"):
        with pytest.raises(InconsistentProblem) as err:
            synthesize(make_problem("u", ts, "F goal", "F I", kind))
        assert err.value.reason == "unreachable"


def test_test_objective_only_at_goal_is_unroutable() -> None:
    """I holds only where the goal is: no execution passes I before reaching the goal."""
    ts = grid_world([(0, 0), (0, 1), (0, 2)], 1, 3, (0, 0), [(0, 2)], {(0, 2): {"goal", "I"}})
    for kind in ("static", "reactive"):
        with pytest.raises(InconsistentProblem) as err:
            synthesize(make_problem("u", ts, "F goal", "F I", kind))
        assert err.value.reason == "unroutable"


def one_way_trap() -> TransitionSystem:
    """A graph with one-way moves into a dead end ``d`` (outside method.md §2's assumption).

    ``s <-> a1, s <-> a2, a1 -> d, a2 -> d, d -> g, s <-> i, i -> g``; ``I`` at ``i``.
    The cheapest routing cut is ``d -> g`` under the start history; ``d`` is then a trap
    (no entry node of any history lies there, so c6-c8 do not see it).
    """
    names = ["s", "a1", "a2", "d", "i", "g"]
    edges = [("s", "a1"), ("a1", "s"), ("s", "a2"), ("a2", "s"), ("a1", "d"), ("a2", "d"), ("d", "g"), ("s", "i"), ("i", "s"), ("i", "g")]
    return graph_system(names, edges, "s", ["g"], {"g": {"goal"}, "i": {"I"}})


@pytest.mark.parametrize("kind", ["static", "reactive"])
def test_one_way_moves_can_trap_the_system(kind: str) -> None:
    """No closed-loop configuration may be trapped by the test (fails: see the reason)."""
    ts = one_way_trap()
    assert not reversible(ts)
    res = synthesize(make_problem("one-way-trap", ts, "F goal", "F I", kind), SynthesisOptions(closed_loop=True))
    assert trapped_configurations(res.products, res.strategy.blocked) == []
    # method.md §5 exactly (the default) may trap here: the report says so
    exact = synthesize(make_problem("one-way-trap", ts, "F goal", "F I", kind))
    assert exact.checks.ok


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["static", "reactive"])
@pytest.mark.parametrize("seed", range(300))
def test_sweep_grid_answers_hold(seed: int, kind: str) -> None:
    """A larger sweep of the grid properties (30 s per solve at most)."""
    run_case(grid_problem(60_000 + seed, kind), time_limit=30.0)


@pytest.mark.parametrize("kind", ["static", "reactive"])
@pytest.mark.parametrize("seed", range(12))
def test_feasibility_flows_eager_or_lazy_give_the_same_optimum(seed: int, kind: str) -> None:
    """Adding c6-c8 all at once or only where they bind is the same MILP optimum."""
    from synthesis.pipeline import milp_options
    from synthesis.routing.solve import solve_routing

    problem = grid_problem(40_000 + seed, kind)
    _, products = build_graphs(problem)
    answers = []
    for feasibility in ("eager", "lazy"):
        options = replace(milp_options(problem, SynthesisOptions()), feasibility=feasibility)
        try:
            r = solve_routing(products, options)
        except InconsistentProblem as exc:
            answers.append(exc.reason)
            continue
        assert r.status == "optimal"
        answers.append((r.flow, int(np.sum(r.cut_edges.size))))
    assert answers[0] == answers[1], answers


def test_unknown_feasibility_option_is_rejected() -> None:
    from synthesis.routing.options import MilpOptions
    from synthesis.routing.solve import solve_routing

    _, products = build_graphs(grid_problem(40_000, "reactive"))
    with pytest.raises(ValueError, match="feasibility"):
        solve_routing(products, MilpOptions(feasibility="sometimes"))


def test_time_limited_answer_reports_the_flow_its_restrictions_let_through(monkeypatch: pytest.MonkeyPatch) -> None:
    """A feasible (not proven) MILP answer whose flow variables under-count its own cut
    set is reported with the true flow, and passes the checks (it was a CheckFailed)."""
    import dataclasses

    import synthesis.pipeline as pipeline
    from synthesis.problems.builtins import BUILTINS

    real = pipeline.solve_routing

    def undercounted(products: Products, options):  # type: ignore[no-untyped-def]
        r = real(products, options)
        return dataclasses.replace(r, status="feasible", flow=r.flow - 1)

    monkeypatch.setattr(pipeline, "solve_routing", undercounted)
    test = synthesize(BUILTINS["example1"]())
    assert test.routing.status == "feasible"
    assert test.routing.flow == 3 == test.checks.flow
