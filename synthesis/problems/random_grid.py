"""Seeded random grid worlds: the instances of the paper's scalability study (paper-examples.md).

An instance is an empty ``size x size`` grid whose special cells are drawn uniformly
without replacement: first the start, then the goal, then one cell per remaining
proposition. Each proposition holds on one cell of its own; the goal's cell is terminal.
An instance whose problem is inconsistent is redrawn from the next *attempt* of the same
seed (the generator is seeded with ``[seed, attempt]``), so ``(size, family, n, seed)``
always names the same instance.

Spec families for a size parameter ``n``:

* ``reachability``: ``phi_sys = F p0`` (``p0`` the goal), ``phi_test = F p1 & ... & F pn``;
* ``reaction``: ``phi_sys = F p1 & G(p2 -> F q2) & ... & G(pn -> F qn)`` (``p1`` the goal),
  ``phi_test = F p0 & F p2 & ... & F pn``;
* ``safety``: ``phi_sys = F p1 & G !p2 & ... & G !pn`` (``p1`` the goal), ``phi_test = F p0``.

What "inconsistent" means is the caller's choice (:func:`first_consistent`): by default
the two cases of docs/method.md §5 that no routing MILP can change (the goal is unreachable,
or no execution reaching it passes the test objective), decided on the product graphs
alone, so MILP-static and MILP-reactive see the same instance. The Gymnasium pool
(``flowtest_env.random_grid``) instead redraws until a test is synthesized.

This module is pure: no Gymnasium, no environment code.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TypeVar

import numpy as np

from ..graphs.consistency import check_consistency
from ..model.errors import InconsistentProblem
from ..model.systems import grid_world
from .problem import Problem, build_graphs, make_problem

FAMILIES: tuple[str, ...] = ("reachability", "reaction", "safety")
MAX_ATTEMPTS = 50

#: The paper's table rows: (family, n) with the paper's |AP| in 2-4, 3/5/7 and 3-5.
PAPER_SPECS: tuple[tuple[str, int], ...] = (
    ("reachability", 1),
    ("reachability", 2),
    ("reachability", 3),
    ("reaction", 2),
    ("reaction", 3),
    ("reaction", 4),
    ("safety", 2),
    ("safety", 3),
    ("safety", 4),
)
#: The paper's grid sizes.
PAPER_SIZES: tuple[int, ...] = (5, 10, 15, 20)

T = TypeVar("T")


def family_objectives(family: str, n: int) -> tuple[str, str, list[str], str]:
    """``(phi_sys, phi_test, propositions in drawing order after the goal, goal)``.

    Raises
    ------
    ValueError
        On an unknown family or an ``n`` out of range.
    """
    if family not in FAMILIES:
        raise ValueError(f"unknown spec family {family!r}; expected one of {', '.join(FAMILIES)}")
    low = 1 if family == "reachability" else 2
    if not (low <= n <= 8):
        raise ValueError(f"spec size n={n} out of range {low}..8 for the {family} family")
    if family == "reachability":
        return "F p0", " & ".join(f"F p{i}" for i in range(1, n + 1)), [f"p{i}" for i in range(1, n + 1)], "p0"
    if family == "reaction":
        sys = " & ".join(["F p1"] + [f"G(p{i} -> F q{i})" for i in range(2, n + 1)])
        test = " & ".join(["F p0"] + [f"F p{i}" for i in range(2, n + 1)])
        props = ["p0"] + [f"p{i}" for i in range(2, n + 1)] + [f"q{i}" for i in range(2, n + 1)]
        return sys, test, props, "p1"
    sys = " & ".join(["F p1"] + [f"G !p{i}" for i in range(2, n + 1)])
    return sys, "F p0", ["p0"] + [f"p{i}" for i in range(2, n + 1)], "p1"


def paper_ap(family: str, n: int) -> int:
    """The number of atomic propositions |AP| as the paper's table counts it.

    Reachability and safety count every proposition (``n + 1``); reaction counts
    ``p0, p2..pn, q2..qn`` but not the goal ``p1`` (``2n - 1``), as paper-examples.md says.
    """
    family_objectives(family, n)  # validates
    return 2 * n - 1 if family == "reaction" else n + 1


def draw_special_cells(size: int, n_props: int, seed: int, attempt: int) -> tuple[np.random.Generator, tuple[int, int], tuple[int, int], list[tuple[int, int]]]:
    """``(generator, start, goal, proposition cells)`` of ``(seed, attempt)``: distinct cells
    drawn uniformly, start first, then the goal, then one per proposition; the generator
    (seeded with ``[seed, attempt]``) continues for whatever else an instance draws
    (:mod:`synthesis.problems.random_worlds`).

    Raises
    ------
    ValueError
        If the grid is too small for the special cells.
    """
    cells = [(r, c) for r in range(size) for c in range(size)]
    if len(cells) < n_props + 2:
        raise ValueError(f"a {size}x{size} grid has too few cells for {n_props + 2} special cells")
    rng = np.random.default_rng([seed, attempt])
    pick = rng.choice(len(cells), size=n_props + 2, replace=False)
    return rng, cells[int(pick[0])], cells[int(pick[1])], [cells[int(i)] for i in pick[2:]]


def random_problem(size: int, family: str, n: int, seed: int, attempt: int = 0, kind: str = "reactive") -> Problem:
    """The random grid instance of ``(size, family, n, seed, attempt)``, as a ``kind`` problem.

    The drawn cells depend on ``(size, family, n, seed, attempt)`` only, never on ``kind``.

    Raises
    ------
    ValueError
        If the grid is too small for the special cells.
    """
    sys_obj, test_obj, props, goal_prop = family_objectives(family, n)
    _, start, goal, prop_cells = draw_special_cells(size, len(props), seed, attempt)
    labels: dict[tuple[int, int], Iterable[str]] = {goal: [goal_prop]}
    tokens = {start: "S", goal: "T"}
    for p, cell in zip(props, prop_cells, strict=True):
        labels[cell] = [p]
        tokens[cell] = p
    cells = [(r, c) for r in range(size) for c in range(size)]
    ts = grid_world(cells, size, size, start, [goal], labels, tokens)
    name = f"random-{size}x{size}-{family}{n}-{kind}-s{seed}"
    return make_problem(name, ts, sys_obj, test_obj, kind, description=f"random grid, seed {seed}, attempt {attempt}")


def graph_consistency(problem: Problem) -> None:
    """Raise :class:`InconsistentProblem` for docs/method.md §5's two inconsistent cases.

    Decided on the product graphs only (no MILP): the goal is unreachable, or no
    ``Src -> Tgt`` path passes ``I``. Independent of the environment kind.
    """
    _, products = build_graphs(problem)
    check_consistency(products)


def first_consistent(
    size: int,
    family: str,
    n: int,
    seed: int,
    kind: str = "reactive",
    accept: Callable[[Problem], T] | None = None,
    max_attempts: int = MAX_ATTEMPTS,
) -> tuple[int, Problem, T | None]:
    """The first attempt of a seed whose problem ``accept`` takes: ``(attempt, problem, accepted)``.

    ``accept(problem)`` raises :class:`InconsistentProblem` to reject an attempt (any
    other exception propagates); its return value is handed back. The default accepts
    what :func:`graph_consistency` accepts and returns ``None``.

    Raises
    ------
    RuntimeError
        If no attempt among ``max_attempts`` is accepted.
    """
    for attempt in range(max_attempts):
        problem = random_problem(size, family, n, seed, attempt, kind)
        try:
            if accept is None:
                graph_consistency(problem)
                value = None
            else:
                value = accept(problem)
        except InconsistentProblem:
            continue
        return attempt, problem, value
    raise RuntimeError(f"no consistent random grid for seed {seed} in {max_attempts} attempts")
