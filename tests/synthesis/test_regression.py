"""Answers that must not change: flow, cut count and proven optimality on the example suite.

The routing MILP is being made faster (issue 6: formulation, solver options, warm
starts); every such change must keep the optimum of method.md §5. These are the
answers of the built-in examples and of a few instances of the random grid study, all
proven optimal: ``(flow F, cut edges of G, status)``. A proven optimum's flow and cut
count are properties of the problem, not of the solver, so any correct change keeps
them (the cut set itself may change between equally good optima and is not pinned).

``tests/synthesis/test_optimality.py`` checks the MILP against exhaustive enumeration on tiny
instances; ``tests/experiments/test_cli.py`` checks the built-ins' JSON and that they are optimal;
neither pins the examples' values. mars-exploration is left out: its phase 2 does not
finish in reasonable time yet (docs/benchmarks.md).
"""

from __future__ import annotations

import pytest

from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.load import load_problem
from synthesis.problems.random_grid import first_consistent, random_problem

#: built-in example -> (flow, cut edges of G); measured with the two-phase MILP, proven optimal
EXAMPLES: dict[str, tuple[int, int]] = {
    "example1": (3, 14),
    "small-reactive": (2, 4),
    "beaver-rescue": (2, 2),
    "motion-primitives": (3, 15),
    "maze1": (1, 3),
    "patrolling": (1, 27),
    "maze2": (2, 8),
    "refueling": (2, 101),
}
SLOW_EXAMPLES = {"maze2", "refueling", "patrolling"}

#: (size, family, n, seed, MILP) -> (flow, cut edges of G), from the random grid study, proven optimal
RANDOM: dict[tuple[int, str, int, int, str], tuple[int, int]] = {
    (5, "reachability", 1, 1, "static"): (2, 18),
    (5, "reachability", 1, 3, "static"): (2, 16),
    (5, "reachability", 1, 3, "reactive"): (2, 4),
    (5, "reachability", 1, 4, "reactive"): (2, 2),
    (5, "reaction", 2, 3, "reactive"): (2, 8),
    (5, "reaction", 2, 10, "reactive"): (2, 6),
}


def _examples() -> list:
    return [pytest.param(name, marks=pytest.mark.slow) if name in SLOW_EXAMPLES else name for name in EXAMPLES]


@pytest.mark.parametrize("name", _examples())
def test_builtin_answers_are_unchanged(name: str) -> None:
    test = synthesize(load_problem(name), SynthesisOptions(threads=1))
    assert test.routing.status == "optimal"
    assert (test.routing.flow, int(test.routing.cut_edges.size)) == EXAMPLES[name]
    assert test.checks.ok and test.checks.bypass_flow == 0


@pytest.mark.parametrize("key", list(RANDOM), ids=lambda k: f"{k[0]}x{k[0]}-{k[1]}{k[2]}-s{k[3]}-{k[4]}")
def test_random_grid_answers_are_unchanged(key: tuple[int, str, int, int, str]) -> None:
    size, family, n, seed, milp = key
    attempt, _, _ = first_consistent(size, family, n, seed)
    test = synthesize(random_problem(size, family, n, seed, attempt, milp), SynthesisOptions(threads=1))
    assert test.routing.status == "optimal"
    assert (test.routing.flow, int(test.routing.cut_edges.size)) == RANDOM[key]
    assert test.checks.ok
