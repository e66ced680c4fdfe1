"""Generalized counterexamples of the agent loop (issue 18 pt 6, synthesis/test_agent/reasons.py):
the rules of a whole cut set are its game, every cut set an exclusion removes is one the loop
would reject, and the loop's answer keeps its flow and cost with fewer or equal work."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from synthesis.graphs.products import Products
from synthesis.model.agent_system import TestAgent
from synthesis.model.strategy import TestStrategy
from synthesis.pipeline import SynthesisOptions, build_graphs, milp_options, synthesize_agent_test
from synthesis.problems.files import load_problem_file
from synthesis.problems.load import load_problem
from synthesis.problems.problem import Problem
from synthesis.problems.random_worlds import world_problem
from synthesis.routing.backends import cpsat
from synthesis.routing.groups import CutGroups, cut_groups
from synthesis.routing.options import Exclusion, MilpOptions
from synthesis.routing.restrictions import strategy_from_routing
from synthesis.routing.result import RoutingResult
from synthesis.test_agent.game import build_agent_game, build_game, trapped_nodes
from synthesis.test_agent.gr1.solver import solve as solve_gr1
from synthesis.test_agent.loop import _restrictable_for_agent
from synthesis.test_agent.reasons import _rules, reason_groups, trap_reason, unrealizable_reason

MAZE_ALL = Path(__file__).resolve().parents[2] / "docs" / "data" / "agent-problems" / "maze-all-free.toml"


def _maze_all() -> Problem:
    """maze2's grid with a test agent over every free cell (more cut sets to reject)."""
    return load_problem_file(str(MAZE_ALL))


def _setup(problem: Problem) -> tuple[Products, TestAgent, MilpOptions, CutGroups]:
    """The products, agent, MILP options and cut groups exactly as the loop builds them."""
    _, products = build_graphs(problem)
    agent = problem.agent
    assert isinstance(agent, TestAgent) and problem.static_moves is not None
    mopts = replace(milp_options(problem, SynthesisOptions()), mode="mixed", static_moves=problem.static_moves, block_states=True)
    harness = _restrictable_for_agent(products.ts, agent, problem.static_moves)
    milp_products = replace(products, ts=replace(products.ts, restrictable=harness))
    return products, agent, mopts, cut_groups(milp_products, mopts)


def _strategy_of(products: Products, groups: CutGroups, cut_mask: np.ndarray, static_moves: np.ndarray) -> TestStrategy:
    """The test strategy of a cut set given as groups (what the MILP's answer turns into)."""
    cut_edges = np.flatnonzero(cut_mask[groups.of_edge])
    static_cut = np.isin(groups.move_key, groups.keys[cut_mask & groups.static]) & static_moves
    routing = RoutingResult(  # only the fields strategy_from_routing reads matter
        status="optimal",
        flow=0,
        cut_edges=cut_edges,
        cut_group_keys=[int(k) for k in groups.keys[cut_mask]],
        static_moves_cut=static_cut,
        blocked_places=np.zeros(0, dtype=np.int64),
        mip_gap=0.0,
        stats={},
    )
    return strategy_from_routing(products, routing, "instantaneous")


def _rejected(products: Products, agent: TestAgent, strategy: TestStrategy) -> bool:
    """Whether the loop rejects this strategy's cut set (a trap, or a lost game)."""
    if trapped_nodes(products, strategy).size:
        return True
    return not solve_gr1(build_agent_game(products, strategy, agent).game).realizable


@pytest.mark.parametrize("name", ["maze2", "patrolling"])
def test_rules_of_a_whole_cut_set_are_its_game(name: str) -> None:
    """K = C and O = every other group: the game of the rules is the loop's game (same
    positions, choices, moves), so the reasons start from the game the loop lost."""
    problem = load_problem(name)
    products, agent, _, groups = _setup(problem)
    edges = reason_groups(products, groups)
    rng = np.random.default_rng(0)
    cuttable = np.bincount(edges.group, weights=edges.can_cut, minlength=groups.keys.size) > 0
    assert problem.static_moves is not None
    for _ in range(20):
        cut = cuttable & (rng.random(groups.keys.size) < 0.05)
        strategy = _strategy_of(products, groups, cut, problem.static_moves)
        real = build_agent_game(products, strategy, agent)
        ours = build_game(products, _rules(edges, cut, cuttable & ~cut), agent)
        assert np.array_equal(real.legal, ours.legal)
        assert np.array_equal(real.blocking, ours.blocking)
        for part in ("choice_owner", "choice_succ_ptr", "choice_succ"):
            assert np.array_equal(getattr(real.game, part), getattr(ours.game, part)), part


def _check_reasons_sound(problem: Problem, n_sets: int, n_supersets: int, seed: int) -> int:
    """For rejected cut sets of ``problem``, every sampled cut set its reason excludes is
    rejected too (a trap or a lost game). Returns how many reasons were checked."""
    products, agent, _, groups = _setup(problem)
    assert problem.static_moves is not None
    edges = reason_groups(products, groups)
    cuttable = (np.bincount(edges.group, weights=edges.can_cut, minlength=groups.keys.size) > 0) & groups.restrictable
    rng = np.random.default_rng(seed)
    checked = 0
    for _ in range(n_sets):
        cut = cuttable & (rng.random(groups.keys.size) < rng.uniform(0.02, 0.15))
        strategy = _strategy_of(products, groups, cut, problem.static_moves)
        trapped = trapped_nodes(products, strategy)
        if trapped.size:
            reason = trap_reason(products, groups, cut, strategy, int(trapped[0]))
        elif not solve_gr1(build_agent_game(products, strategy, agent).game).realizable:
            reason = unrealizable_reason(products, groups, cut, agent)
        else:
            continue
        keys = set(int(k) for k in groups.keys[cut])
        assert reason.exclusion.excludes(keys), "a reason must exclude its own cut set"
        assert len(reason.exclusion.cut) <= int(cut.sum())
        core = np.isin(groups.keys, reason.exclusion.cut)
        keep_open = np.isin(groups.keys, reason.exclusion.open)
        undecided = cuttable & ~core & ~keep_open
        for _ in range(n_supersets):
            other = core | (undecided & (rng.random(groups.keys.size) < rng.uniform(0.0, 0.3)))
            assert reason.exclusion.excludes(set(int(k) for k in groups.keys[other]))
            assert _rejected(products, agent, _strategy_of(products, groups, other, problem.static_moves)), "an excluded cut set the loop would accept"
        checked += 1
    return checked


@pytest.mark.parametrize("name", ["maze1", "maze2", "patrolling"])
def test_every_excluded_cut_set_is_rejected_builtins(name: str) -> None:
    assert _check_reasons_sound(load_problem(name), n_sets=12, n_supersets=8, seed=1) >= 1


def test_every_excluded_cut_set_is_rejected_physical_walls() -> None:
    """patrolling's physical walls (tied across fuel levels, ``tie_places="static"``; a second
    seed beside the built-ins' test): random walls often doom what a system reaches, so trap
    reasons must keep the trap's way on the map open too."""
    problem = load_problem("patrolling")
    assert problem.tie_places == "static"
    assert _check_reasons_sound(problem, n_sets=12, n_supersets=8, seed=3) >= 1


def test_every_excluded_cut_set_is_rejected_all_free_cells() -> None:
    assert _check_reasons_sound(_maze_all(), n_sets=12, n_supersets=8, seed=2) >= 1


def test_exclusion_rows_cut_and_open() -> None:
    """An exclusion with open groups removes exactly the cut sets with its core cut and
    its open groups open: the MILP answers around it."""
    ex = Exclusion(cut=(3, 5), open=(7,))
    assert ex.excludes({3, 5}) and ex.excludes({3, 5, 9})
    assert not ex.excludes({3, 5, 7}) and not ex.excludes({3})
    assert Exclusion(cut=()).excludes(set())


def _same_answer(problem: Problem, backend: str = "auto") -> tuple[int, int]:
    """The loop with reasons and without: same flow, blocked places and cuts (the MILP's
    objective); returns the number of solves of each."""
    options = SynthesisOptions(backend=backend)
    with_reasons = synthesize_agent_test(problem, options, reasons=True)
    plain = synthesize_agent_test(problem, options, reasons=False)
    for t in (with_reasons, plain):
        assert t.checks is not None and t.agent is not None
    a, b = with_reasons.routing, plain.routing
    assert a.status == b.status == "optimal"
    assert (a.flow, len(a.blocked_places), a.cut_edges.size) == (b.flow, len(b.blocked_places), b.cut_edges.size)
    assert with_reasons.agent is not None and plain.agent is not None
    return len(with_reasons.agent.iterations), len(plain.agent.iterations)


@pytest.mark.parametrize("name", ["maze1", "maze2", pytest.param("patrolling", marks=pytest.mark.slow)])
def test_reasons_keep_the_answer_builtins(name: str) -> None:
    _same_answer(load_problem(name))


@pytest.mark.skipif(not cpsat.available(), reason="OR-Tools is not installed (a core dependency: a broken install)")
def test_reasons_keep_the_answer_on_cpsat() -> None:
    """The exclusion rows with open groups reach CP-SAT through the same model."""
    _same_answer(load_problem("maze2"), backend="cpsat")


@pytest.mark.slow
@pytest.mark.parametrize(("world", "n", "seed"), [("empty", 1, 0), ("empty", 1, 2), ("blocked", 2, 0), ("blocked", 2, 2), ("blocked", 2, 5)])
def test_reasons_keep_the_answer_random_agent_instances(world: str, n: int, seed: int) -> None:
    """Random 5x5 agent instances (random_worlds, kind "agent") that have a test agent
    strategy (empty #0 needs 3 solves without reasons, 2 with)."""
    _same_answer(world_problem(5, "reachability", n, seed, world=world, kind="agent"))


@pytest.mark.slow
def test_reasons_keep_the_answer_all_free_cells() -> None:
    solves, plain_solves = _same_answer(_maze_all())
    assert solves < plain_solves
