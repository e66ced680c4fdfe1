"""Every backend of the routing model meets one contract (synthesis.routing.backends.contract):
the same phase functions return the same result type, and every entry of the one table
(``synthesis.routing.solve.SOLVERS``) answers the same problems with the same flow and the
same optimal number of cuts, each answer checked by :mod:`synthesis.checks.verify`.

References: the brute force of ``test_optimality`` on seeded random grids and graphs, and the
HiGHS answer on the built-ins (small-reactive, example1, beaver-rescue, motion-primitives and
the two agent mazes). Backend-specific behaviour (CP-SAT's child, its level search, HiGHS's
starts) stays in the backends' own test modules.
"""

from __future__ import annotations

import functools
from contextlib import AbstractContextManager
from dataclasses import replace
from importlib.metadata import version

import numpy as np
import pytest

from synthesis.checks import verify
from synthesis.graphs.consistency import check_consistency
from synthesis.pipeline import SynthesisOptions, SynthesizedTest, milp_options, synthesize
from synthesis.problems.load import load_problem
from synthesis.problems.problem import build_graphs
from synthesis.routing.backends import cpsat
from synthesis.routing.backends.contract import Backend, LeastQuery, Round
from synthesis.routing.certificates import cut_proof
from synthesis.routing.model import build_model
from synthesis.routing.options import BACKENDS
from synthesis.routing.phases import Phase, phase2_cost
from synthesis.routing.restrictions import strategy_from_routing
from synthesis.routing.result import RoutingResult, required_entries
from synthesis.routing.solve import SOLVERS, solve_least, solve_routing
from synthesis.routing.solver_control import Clock
from tests.testing_optimality import compare_reactive, compare_static, graph_instance, grid_instance

#: The package each backend's answers depend on (its ``solver_version``).
PACKAGE = {"highs": "highspy", "cpsat": "ortools"}


def _installed(name: str) -> pytest.MarkDecorator:
    return pytest.mark.skipif(name == "cpsat" and not cpsat.available(), reason="OR-Tools is not installed (a core dependency, missing here)")


#: Every entry of the table (CP-SAT skipped where OR-Tools is missing).
NAMES = [pytest.param(name, marks=_installed(name)) for name in SOLVERS]

#: Built-ins every backend proves within seconds (the mazes are agent problems: many small solves).
BUILTINS = ["small-reactive", "example1", "beaver-rescue", "motion-primitives", "maze1", "maze2", pytest.param("refueling", marks=pytest.mark.slow)]


def test_one_table_of_backends() -> None:
    """The names an option may take are ``"auto"`` and the table's entries, each a
    :class:`Backend` under its own name with every field of the contract."""
    assert BACKENDS == ("auto", *SOLVERS)
    for name, backend in SOLVERS.items():
        assert isinstance(backend, Backend) and backend.name == name
        for part in (backend.version, backend.require, backend.session, backend.phase1, backend.phase2, backend.figures):
            assert callable(part), (name, part)
        assert backend.label.startswith("routing MILP")


@functools.cache
def _synthesized(name: str, backend: str) -> SynthesizedTest:
    """A built-in synthesized on one backend (once per module run)."""
    return synthesize(load_problem(name), SynthesisOptions(backend=backend))


def _reference(name: str) -> tuple[str, int, int]:
    """The HiGHS answer on a built-in: status, flow, number of cut edges."""
    test = _synthesized(name, "highs")
    return test.routing.status, test.routing.flow, int(test.routing.cut_edges.size)


def _checked(test: SynthesizedTest, backend: str) -> None:
    """What every answer of every backend holds to: the result type, who made it (with the
    version of its package), and the independent checks passed."""
    assert isinstance(test.routing, RoutingResult)
    assert test.routing.stats["backend"] == backend
    assert test.routing.stats["solver_version"] == SOLVERS[backend].version() == version(PACKAGE[backend])
    assert isinstance(test.checks, verify.CheckReport)
    assert test.checks.ok and test.checks.bypass_flow == 0


@pytest.mark.parametrize("backend", NAMES)
@pytest.mark.parametrize("problem", BUILTINS)
def test_same_answers_on_builtins(problem: str, backend: str) -> None:
    """Built-ins every backend proves: the same status, flow and number of cuts as HiGHS
    (which cuts may differ where several optima tie; every answer is checked)."""
    test = _synthesized(problem, backend)
    _checked(test, backend)
    mine = test.routing.status, test.routing.flow, int(test.routing.cut_edges.size)
    reference = _reference(problem)
    assert reference[0] == mine[0] == "optimal"
    assert mine[1:] == reference[1:], f"{problem}: HiGHS {reference[1:]}, {backend} {mine[1:]}"


@pytest.mark.parametrize("backend", NAMES)
@pytest.mark.parametrize("seed", range(3))
def test_same_optima_as_brute_force_on_random_grids(seed: int, backend: str) -> None:
    """Seeded random static grids and reactive graphs: every backend's flow and number of
    cuts is the exhaustive optimum (``test_optimality``'s brute force), and its answer passes
    the checks (``compare_static`` and ``compare_reactive`` synthesize through the pipeline)."""
    compare_static(grid_instance(100 + seed, 3, 3, "static", True), max_sets=1 << 12, backend=backend)
    compare_static(grid_instance(300 + seed, 2, 3, "static", False), max_sets=1 << 14, backend=backend)
    assert compare_reactive(graph_instance(500 + seed), backend=backend)


@pytest.mark.parametrize("backend", NAMES)
def test_the_same_phases_return_the_same_type(backend: str) -> None:
    """The contract itself, driven by hand on small-reactive: ``session``, ``phase1`` and
    ``phase2`` of every backend give :class:`Phase` answers (whole model solutions), proven
    optimal, with the same maximum flow and the same phase-2 objective; the routing answer
    :func:`solve_routing` makes of them passes :func:`verify.check_test`."""
    problem = load_problem("small-reactive")
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions()), backend=backend, feasibility="eager")
    entries = required_entries(products, options)
    rm = build_model(products, options, entries, check_consistency(products))
    r = Round(products, rm, options, entries, Clock(None, None))
    chosen = SOLVERS[backend]
    session = chosen.session(r)
    assert isinstance(session, AbstractContextManager)
    with session as s:
        first = chosen.phase1(s, r)
        flow = int(round(rm.flow_of(first.x)))
        second = chosen.phase2(s, r, first.x, flow, cut_proof(products, rm, options, entries, flow))
        figures = chosen.figures(s)
    assert isinstance(first, Phase) and isinstance(second, Phase) and isinstance(figures, dict)
    assert first.status == second.status == "optimal"
    assert first.x.shape == second.x.shape == (rm.n_col,)
    assert flow == 2 and abs(rm.flow_of(second.x) - flow) < 0.5
    assert float(phase2_cost(rm, options) @ second.x) == pytest.approx(_reference("small-reactive")[2])
    routing = solve_routing(products, options)
    assert isinstance(routing, RoutingResult) and routing.stats["backend"] == backend
    assert (routing.status, routing.flow, int(routing.cut_edges.size)) == ("optimal", flow, _reference("small-reactive")[2])
    report = verify.check_test(products, strategy_from_routing(products, routing, "instantaneous"), routing.flow)
    assert report.ok


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_least_question_is_answered_whatever_the_backend(backend: str) -> None:
    """The contract's question beside the phases (:class:`LeastQuery`: the least cost over the
    model's solutions with flow >= 1): HiGHS answers it, CP-SAT provides none, and
    :func:`solve_least` answers it for every backend name (``"auto"`` included) on the first
    entry of the table that does. On small-reactive the least of ``-F`` is minus the maximum
    flow, 2, as both phases prove."""
    assert SOLVERS["highs"].least is not None and SOLVERS["cpsat"].least is None
    problem = load_problem("small-reactive")
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions()), feasibility="eager")
    entries = required_entries(products, options)
    rm = build_model(products, options, entries, check_consistency(products))
    cost = np.zeros(rm.n_col)
    cost[rm.cols.flow[rm.out_src]] = -1.0
    least = solve_least(backend, LeastQuery(rm, cost, np.zeros(0, dtype=np.int64), options, None, "the largest flow"))
    assert (least.status, least.value) == ("optimal", -2.0)
