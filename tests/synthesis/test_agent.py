"""The dynamic test agent (method.md §7): built-ins, the loop, verification, controller, TOML."""

from __future__ import annotations

import json
import random
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from flowtest_env.game import TestGame
from synthesis.artifacts.artifact import TestArtifact, artifact_of
from synthesis.artifacts.summary import summary_of
from synthesis.model.agent_system import make_test_agent, places_of_cells
from synthesis.model.errors import CheckFailed, InconsistentProblem, ProblemError
from synthesis.pipeline import SynthesisOptions, SynthesizedTest, synthesize
from synthesis.problems.files import load_problem_file
from synthesis.problems.load import load_problem
from synthesis.problems.problem import Problem
from synthesis.test_agent.closed_loop import verify_closed_loop
from synthesis.test_agent.controller import AgentController
from synthesis.test_agent.game import blocking_places, build_agent_game, trapped_nodes, walled_off_nodes
from synthesis.test_agent.gr1.solver import solve as solve_gr1
from synthesis.test_agent.gr1.verify import verify_strategy
from synthesis.test_agent.loop import AgentSynthesis

AGENT_BUILTINS = ("maze1", "maze2", "patrolling")
#: physical walls make patrolling's MILP take minutes (docs/benchmarks.md, "Patrolling with
#: physical walls"): its synthesis runs with the slow tests only
SLOW_AGENT_BUILTINS = frozenset({"patrolling"})
AGENT_PARAMS = [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_AGENT_BUILTINS else n for n in AGENT_BUILTINS]

MAZE2_TOML = """
name = "maze2-toml"
[system]
grid = '''
.  .  t  .  T
I2 #  t  #  .
t  t  t0 t  t
.  #  t  #  I1
S  .  t  .  .
'''
start = "S"
terminal = ["T"]
[labels]
goal = ["T"]
I1 = ["I1"]
I2 = ["I2"]
[objectives]
system = "F goal"
test = "F I1 & F I2"
[environment]
kind = "agent"
[environment.agent]
cells = ["t", "t0"]
start = "t0"
first = "agent"
parks = [
  {name = "above", from = [[0, 2]]},
  {name = "below", from = [[4, 2]]},
  {name = "left", from = [[2, 0]]},
  {name = "right", from = [[2, 4]]},
]
"""


class _Synthesized(dict[str, SynthesizedTest]):
    """Agent built-ins synthesized when a test first asks for one, then kept."""

    def __missing__(self, name: str) -> SynthesizedTest:
        self[name] = synthesize(load_problem(name))
        return self[name]


@pytest.fixture(scope="module")
def tests() -> dict[str, SynthesizedTest]:
    """Each agent built-in synthesized once for the whole module (the slow ones only when
    a slow test asks for them)."""
    return _Synthesized()


@pytest.mark.parametrize("name", AGENT_PARAMS)
def test_builtin_synthesizes_and_verifies(tests: dict[str, SynthesizedTest], name: str) -> None:
    test = tests[name]
    summary = summary_of(test)
    assert summary["status"] == "optimal"
    assert summary["bypass_flow"] == 0
    assert summary["flow"] >= 1
    assert isinstance(summary["counterexamples"], int) and summary["counterexamples"] >= 0
    strat = summary["agent_strategy"]
    assert strat["iterations"] == summary["counterexamples"] + 1
    assert strat["game"]["positions"] > 0 and strat["memory"] >= 1
    json.dumps(summary)  # the --json output stays serialisable
    agent = test.agent
    assert isinstance(agent, AgentSynthesis)
    # the closed-loop verification, re-run on the shipped (restricted) table
    report = verify_closed_loop(test.products, test.strategy, test.problem.agent, agent.controller)
    assert report.positions > 0 and report.goal_positions > 0


def test_counterexamples_are_reported(tests: dict[str, SynthesizedTest]) -> None:
    # maze2's first cut sets need the agent at (0, 2) and (2, 4) at once: rejected by the game
    test = tests["maze2"]
    assert test.agent.counterexamples >= 1
    verdicts = [it["verdict"] for it in test.agent.iterations]
    assert verdicts[-1] == "realizable" and all(v != "realizable" for v in verdicts[:-1])
    assert len(summary_of(test)["agent_strategy"]["rejected"]) == test.agent.counterexamples


def test_prefilter_only_saves_solves() -> None:
    """Without the a-priori exclusions maze1 rejects a cut set on rows the agent cannot hold."""
    from synthesis.pipeline import synthesize_agent_test

    plain = synthesize_agent_test(load_problem("maze1"), prefilter=False)
    assert plain.agent.counterexamples >= 1
    assert plain.routing.flow == synthesize(load_problem("maze1")).routing.flow


@pytest.mark.parametrize("name", AGENT_PARAMS)
def test_controller_round_trip(tests: dict[str, SynthesizedTest], name: str) -> None:
    test = tests[name]
    ctrl = test.agent.controller
    loaded = AgentController.from_dict(json.loads(json.dumps(ctrl.to_dict())))
    assert loaded.reset() == ctrl.reset()
    assert loaded.first == ctrl.first and loaded.agent_names == ctrl.agent_names
    assert loaded.agent_places == ctrl.agent_places
    g = test.products.virtual
    rng = np.random.default_rng(0)
    mem, rows, agents = np.nonzero(ctrl.next_agent >= 0)
    queries = [(int(a), int(m), int(g.state[v]), int(g.hist[v])) for m, v, a in zip(mem, rows, agents, strict=True)]
    n_agent = len(ctrl.agent_names)
    for _ in range(300):  # also outside the table (fallback moves)
        v = int(rng.integers(g.n_nodes))
        queries.append((int(rng.integers(n_agent)), 0, int(g.state[v]), int(g.hist[v])))
    for q in queries:
        assert loaded.respond(*q) == ctrl.respond(*q)
    # through the whole artifact, as environments load it
    art = TestArtifact.from_dict(json.loads(json.dumps(artifact_of(test, summary_of(test)).to_dict())))
    assert art.agent is not None and {"controller", "cells", "parks", "first"} <= set(art.agent)
    again = AgentController.from_dict(art.agent["controller"])
    for q in queries:
        assert again.respond(*q) == ctrl.respond(*q)
    verify_closed_loop(test.products, test.strategy, test.problem.agent, again)


@pytest.mark.parametrize("name", AGENT_PARAMS)
def test_random_runs_through_the_public_protocol(tests: dict[str, SynthesizedTest], name: str) -> None:
    """Drive the controller as an environment does: reset, (first move), respond per step,
    until the run ends (met, or violated: the SUT can no longer meet its objective, where the
    environment stops asking the agent)."""
    test = tests[name]
    ts = test.problem.system
    art = TestArtifact.from_dict(json.loads(json.dumps(artifact_of(test, summary_of(test)).to_dict())))
    doomed = TestGame(art).doomed
    ctrl = AgentController.from_dict(art.agent["controller"])
    static = test.strategy.static_obstacles
    out_moves = [np.flatnonzero(ts.src == s) for s in range(ts.n_states)]
    rng = random.Random(1)
    for _ in range(60):
        s, h = ts.initial, art.initial_history()
        a, m = ctrl.reset()
        if ctrl.first == "agent":
            a, m = ctrl.respond(a, m, s, h)
        for _step in range(60):
            if ts.terminal[s] or doomed[h][s]:
                break
            here = ctrl.agent_places[a]
            assert here != int(ts.place[s]), "collision"
            moves = out_moves[s]
            by_agent = {int(e) for e in moves if not static[e] and here is not None and int(ts.place[ts.dst[e]]) == here}
            restricted = {int(e) for e in moves if test.strategy.restrictions[h, e] and not static[e]}
            assert by_agent == restricted, "the agent must block exactly R(q)"
            options = [int(e) for e in moves if not static[e] and e not in by_agent]
            if ts.stay[s]:
                options.append(-1)
            e = rng.choice(options)
            if e >= 0:
                s = int(ts.dst[e])
            h = art.step_history(h, s)
            a, m = ctrl.respond(a, m, s, h)
            assert ctrl.agent_places[a] != int(ts.place[s]), "collision"


def test_g8_is_computed_from_the_graphs(tests: dict[str, SynthesizedTest]) -> None:
    """Maze 1's hand rule (leave rows 6, 4, 2, 0) is an instance of the computed g8."""
    test = tests["maze1"]
    ts, agent, products = test.problem.system, test.problem.agent, test.products
    blocking = blocking_places(products, test.strategy.static_obstacles, agent.cells)
    col = {ts.places[int(p)]: k for k, p in enumerate(agent.cells)}
    src = products.virtual.initial  # the system at (6, 0)
    assert blocking[src, col[(6, 2)]]
    assert not blocking[src, col[(5, 2)]]
    somewhere = blocking.any(axis=0)
    assert somewhere[col[(0, 2)]] and somewhere[col[(2, 2)]] and somewhere[col[(4, 2)]]


def test_walls_alone_dooming_a_node_set_no_trap(tests: dict[str, SynthesizedTest]) -> None:
    """The loop's trap rule: a node the static walls alone doom is the system's own fault
    (the walls are on the map it sees), while the same moves restricted reactively (by the
    agent, unseen in advance) trap the system there."""
    test = tests["maze1"]
    products, strategy = test.products, test.strategy
    ts, g = products.ts, products.virtual
    assert trapped_nodes(products, strategy).size == 0
    h0 = int(g.hist[g.initial])
    first = [int(m) for m in np.flatnonzero(ts.src == ts.initial) if not strategy.blocked[h0, m] and not ts.terminal[ts.dst[m]]]
    s = int(ts.dst[first[0]])
    out_of_s = ts.src == s
    at_s = g.state == s
    walls = replace(strategy, static_obstacles=strategy.static_obstacles | out_of_s)
    assert walled_off_nodes(products, walls.static_obstacles)[at_s].any()
    assert trapped_nodes(products, walls).size == 0
    doors = replace(strategy, restrictions=strategy.restrictions | out_of_s[None, :])
    assert not walled_off_nodes(products, doors.static_obstacles)[at_s].any()
    trapped = trapped_nodes(products, doors)
    assert trapped.size and at_s[trapped].any()


def test_game_is_solved_and_strategy_verified(tests: dict[str, SynthesizedTest]) -> None:
    test = tests["maze2"]
    game = build_agent_game(test.products, test.strategy, test.problem.agent)
    result = solve_gr1(game.game)
    assert result.realizable and result.strategy is not None
    verify_strategy(game.game, result.strategy)


def test_verifier_rejects_a_lazy_agent(tests: dict[str, SynthesizedTest]) -> None:
    """An agent that always stays where it is must fail the closed-loop check."""
    test = tests["maze2"]
    lazy = AgentController.from_dict(test.agent.controller.to_dict())
    stay = np.broadcast_to(np.arange(lazy.next_agent.shape[2]), lazy.next_agent.shape)
    lazy.next_agent = np.where(lazy.next_agent >= 0, stay, -1).astype(np.int32)
    with pytest.raises(CheckFailed):
        verify_closed_loop(test.products, test.strategy, test.problem.agent, lazy)
    empty = AgentController.from_dict(test.agent.controller.to_dict())
    empty.next_agent[:] = -1
    with pytest.raises(CheckFailed, match="no move"):
        verify_closed_loop(test.products, test.strategy, test.problem.agent, empty)


def _maze2_with(cells: list[tuple[int, int]], stay: bool, first: str, max_iterations: int = 100) -> Problem:
    """Maze 2 whose harness restricts only moves into the plus, with another agent."""
    problem = load_problem("maze2")
    ts = problem.system
    plus = [(2, c) for c in range(5)] + [(r, 2) for r in range(5) if r != 2]
    on_plus = np.zeros(len(ts.places), dtype=bool)
    on_plus[places_of_cells(ts, plus)] = True
    ts.restrictable = on_plus[ts.place[ts.dst]]
    problem.agent = make_test_agent(
        ts,
        places_of_cells(ts, cells),
        places_of_cells(ts, [cells[0]])[0],
        [("away", places_of_cells(ts, [cells[0]]))],
        stay=stay,
        first=first,
        max_iterations=max_iterations,
    )
    problem.static_moves = problem.agent.static_moves(ts)
    return problem


def test_agent_that_cannot_reach_any_cut_position_is_infeasible() -> None:
    # the agent must leave (2, 2) at its first move and can never come back
    problem = _maze2_with([(2, 2)], stay=False, first="agent")
    with pytest.raises(InconsistentProblem) as err:
        synthesize(problem)
    assert err.value.reason == "infeasible"
    assert "no test agent strategy exists" in str(err.value)


def test_loop_bound_ends_with_infeasible() -> None:
    # maze2's first cut sets need the agent in two places at once: the game rejects them,
    # so a bound of 2 MILP solves is reached before a realizable cut set
    lines: list[str] = []
    with pytest.raises(InconsistentProblem) as err:
        synthesize(load_problem("maze2"), SynthesisOptions(progress=lines.append, agent_iterations=2))
    assert err.value.reason == "infeasible"
    assert "bound of 2 iterations" in str(err.value)
    assert sum(line.startswith("agent loop") for line in lines) == 2


def test_agent_that_can_only_sit_in_the_middle_has_no_test() -> None:
    # an agent that can only sit on (2, 2) (or park): no cut set it could realize exists;
    # the routing MILP or the counterexample-guided loop proves it
    problem = _maze2_with([(2, 2)], stay=True, first="agent", max_iterations=100)
    with pytest.raises(InconsistentProblem) as err:
        synthesize(problem)
    assert err.value.reason in ("unroutable", "infeasible")
    assert "no" in str(err.value)


def test_toml_agent_problem(tmp_path: Path) -> None:
    path = tmp_path / "maze2.toml"
    path.write_text(MAZE2_TOML)
    problem = load_problem_file(path)
    assert problem.kind == "agent" and problem.agent.first == "agent"
    assert [p.name for p in problem.agent.parks] == ["above", "below", "left", "right"]
    test = synthesize(problem)
    summary = summary_of(test)
    assert summary["status"] == "optimal" and summary["bypass_flow"] == 0
    assert "counterexamples" in summary
    verify_closed_loop(test.products, test.strategy, problem.agent, test.agent.controller)


@pytest.mark.parametrize(
    ("edits", "message"),
    [
        ([('first = "agent"', 'first = "agent"\ncolour = "red"')], "unknown key 'colour'"),
        ([('cells = ["t", "t0"]\n', "")], "missing `cells`"),
        ([("from = [[4, 2]]", "from = [[4, 0]]")], "not an agent cell"),
        ([('start = "t0"', "start = [4, 0]")], "not an agent cell"),
        ([('first = "agent"', 'first = "tester"')], "`first` must be one of"),
        ([('{name = "left", from = [[2, 0]]}', '{name = "above", from = [[2, 0]]}')], "used twice"),
        ([('first = "agent"', 'first = "agent"\nmoves = "diagonal"')], "unknown `moves` rule"),
        ([('cells = ["t", "t0"]', 'cells = ["t", "t0", "S"]'), ('start = "t0"', 'start = "S"')], "collide"),
    ],
)
def test_toml_agent_errors(tmp_path: Path, edits: list[tuple[str, str]], message: str) -> None:
    text = MAZE2_TOML
    for old, new in edits:
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ProblemError, match=message) as err:
        load_problem_file(path)
    assert "[environment.agent]" in str(err.value)
