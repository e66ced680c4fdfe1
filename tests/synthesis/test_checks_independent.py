"""The independent checks share no trap search with the routing MILP they check.

Which way it is done: the MILP has its own trap search (``synthesis.routing.traps``: one
search over the histories stacked as layers of one graph, from the MILP's cut edges),
the checks theirs (``synthesis.checks.verify``: one search per history, from the test
strategy an environment enforces). Neither package imports the other; both call the pure
graph primitive ``synthesis.graphs.products.coreachable``. So a bug in the MILP's lazy-row
generator cannot make the solver and its checker agree: it is caught below.
"""

from __future__ import annotations

import ast
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import synthesis
import synthesis.routing.phases as phases
import synthesis.routing.solve as solve
from synthesis.checks import verify
from synthesis.graphs.products import Products
from synthesis.model.errors import CheckFailed
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.problem import build_graphs
from synthesis.routing import traps
from synthesis.routing.options import MilpOptions
from synthesis.routing.restrictions import strategy_from_routing
from synthesis.routing.solve import solve_routing

PACKAGE = Path(synthesis.__file__).parent


def _imported_modules(folder: str) -> set[str]:
    """Every module the sources of ``synthesis/<folder>`` import (relative imports resolved)."""
    out: set[str] = set()
    for path in (PACKAGE / folder).glob("*.py"):
        here = ["synthesis", folder]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = here[: len(here) - node.level + 1] if node.level else []
                mod = ".".join(base + ([node.module] if node.module else []))
                out.add(mod)
                out.update(f"{mod}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                out.update(a.name for a in node.names)
    return out


def test_routing_and_checks_do_not_import_each_other() -> None:
    routing = _imported_modules("routing")
    checks = _imported_modules("checks")
    assert not any(m.startswith("synthesis.checks") for m in routing), sorted(routing)
    assert not any(m.startswith("synthesis.routing") for m in checks), sorted(checks)
    # the one thing they share: the pure graph search
    assert "synthesis.graphs.products.coreachable" in routing & checks


def _small_reactive() -> tuple[Products, MilpOptions]:
    problem = BUILTINS["small-reactive"]()
    _, products = build_graphs(problem)
    return products, replace(milp_options(problem, SynthesisOptions()), feasibility="lazy")


def test_both_trap_searches_agree_on_random_restrictions() -> None:
    products, _ = _small_reactive()
    g = products.virtual
    rng = np.random.default_rng(0)
    for density in (0.0, 0.1, 0.3, 0.6):
        blocked = rng.random((g.n_hist, products.ts.n_moves)) < density
        mine = traps.trapped_entries(products, blocked, products.kept_entries)
        theirs = verify.trapped_entries_of(products, blocked, products.kept_entries)
        assert list(mine) == list(theirs)
        assert all(np.array_equal(mine[q], theirs[q]) for q in mine)
        assert np.array_equal(traps.trapped_configurations(products, blocked), verify.trapped_configurations(products, blocked))


def test_the_lazy_rows_are_needed_here() -> None:
    """small-reactive without its feasibility flows traps an entry node: the lazy solve
    needs a second round, and its answer passes the checks."""
    products, options = _small_reactive()
    routing = solve_routing(products, options)
    assert routing.stats["feasibility_rounds"] == 2
    verify.check_test(products, strategy_from_routing(products, routing, "instantaneous"), routing.flow)


def test_a_broken_lazy_row_generator_is_caught_by_the_checks(monkeypatch: pytest.MonkeyPatch) -> None:
    """The MILP's trap search made blind (it never sees a trap, so no feasibility row is
    added): the answer traps the system, and the independent checks say so."""
    products, options = _small_reactive()
    monkeypatch.setattr(solve, "trapped_entries", lambda products, blocked, entries: {})
    monkeypatch.setattr(phases, "trapped_entries", lambda products, blocked, entries: {})
    routing = solve_routing(products, options)
    assert routing.stats["feasibility_rounds"] == 1
    with pytest.raises(CheckFailed, match="no way to the goal"):
        verify.check_test(products, strategy_from_routing(products, routing, "instantaneous"), routing.flow)
