"""Seeded random grid worlds beyond the paper's empty grids: blocked cells, fuel, test agents.

A pool instance is named by ``(size, family, n, seed, attempt, world, kind)``:

* ``family``, ``n``: the spec family of :mod:`synthesis.problems.random_grid` (reachability,
  reaction, safety) and its size;
* ``world``: what the grid holds besides the special cells,

  - ``"empty"``: the paper's empty grid (exactly :func:`synthesis.problems.random_grid.random_problem`);
  - ``"blocked"``: :func:`blocked_count` blocked cells (``size * size // 5``: 5 at 5x5,
    9 at 7x7, 20 at 10x10), drawn among the cells left after the special cells;
  - ``"fuel"``: a fuel grid (``paper-examples.md``, refueling): states ``((row, col),
    fuel)``, capacity :func:`fuel_capacity` (``size``), start at full fuel, a move costs
    one unit, staying costs nothing, entering a refuel cell (:func:`refuel_count` of
    them: 1 below 8x8, else 2) refills; ``empty`` holds at fuel 0 and the system
    objective gains ``G !empty``. One label per state, priority goal > empty > the
    cell's proposition. Static walls are tied across fuel levels (as in refueling);

* ``kind``: the environment, ``"reactive"`` (reactive doors: restrictions that open and
  close with the history, docs/method.md §6), ``"static"`` (walls for the whole test) or
  ``"agent"`` (a test agent, docs/method.md §7): the agent lives on one column of the grid
  that holds neither the start nor the goal, drawn by seed, moves one cell up or down
  or stays, starts on a drawn cell of its column, and parks off the grid above row 0 or
  below the last row; the system moves first. Its static area is every move into a
  cell off the column (the default of an agent problem). The loop that turns cuts into an agent strategy is bounded by
  :data:`AGENT_ITERATIONS` MILP solves.

**Drawing order** (one generator seeded with ``[seed, attempt]``, as
:mod:`synthesis.problems.random_grid`): the special cells exactly as the empty grid draws them
(start, goal, one cell per proposition), then the agent's column and start row (agent
kind), then the blocked or refuel cells among the remaining cells in row-major order
(never on the agent's column). So a ``blocked``, ``fuel`` or ``agent`` instance has the
special cells of the empty instance of the same seed and attempt; ``static`` and
``reactive`` see the same instance.

**Layouts.** :func:`layout_count` counts the distinct draws of a family exactly (the
special cells in order, the agent's column and start row, the blocked or refuel cells as
a set): an upper bound on its distinct tests, and what the birthday bound of a pool's
expected repeats is computed from (docs/pools.md).

An attempt whose problem has no test is redrawn from the next attempt
(:func:`first_accepted`): what "no test" means is the caller's ``accept``. An attempt
whose goal or agent column is cut off from the start (a fuel grid's far cells may be
out of reach) is inconsistent by construction and redrawn too.

This module is pure: no Gymnasium, no environment code.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from math import comb, perm
from typing import TypeVar

from ..model.agent_system import TestAgent, make_test_agent, places_of_cells
from ..model.errors import InconsistentProblem, ProblemError
from ..model.systems import Cell, TransitionSystem, fuel_grid_world, grid_world
from .problem import Problem, make_problem
from .random_grid import MAX_ATTEMPTS, draw_special_cells, family_objectives, random_problem

__all__ = [
    "AGENT_ITERATIONS",
    "POOL_KINDS",
    "WORLDS",
    "blocked_count",
    "first_accepted",
    "fuel_capacity",
    "layout_count",
    "refuel_count",
    "world_problem",
    "world_problem_name",
]

WORLDS: tuple[str, ...] = ("empty", "blocked", "fuel")
"""What a random grid holds besides its special cells (module docstring)."""
POOL_KINDS: tuple[str, ...] = ("reactive", "static", "agent")
"""The environment kinds a random grid is synthesized for."""
AGENT_ITERATIONS = 20
"""Bound on the counterexample-guided loop of a random agent instance (MILP solves): a
deterministic budget; an instance without an agent strategy within it is redrawn."""
EMPTY_PROPOSITION = "empty"
"""Fuel worlds: the proposition of fuel 0 (``G !empty`` in the system objective)."""

T = TypeVar("T")


def blocked_count(size: int) -> int:
    """Blocked cells of a ``blocked`` world: a fifth of the grid, rounded down."""
    return size * size // 5


def fuel_capacity(size: int) -> int:
    """The fuel capacity of a ``fuel`` world: the grid's side (a corner-to-corner trip needs a refuel)."""
    return size


def refuel_count(size: int) -> int:
    """Refuel cells of a ``fuel`` world: 1 below 8x8, else 2."""
    return 1 if size < 8 else 2


def layout_count(size: int, family: str, n: int, world: str = "empty", kind: str = "reactive") -> int:
    """The number of distinct layouts :func:`world_problem` draws for a family: every way
    to place the start, the goal and one cell per proposition (distinct cells, in order),
    then, for a test agent, its column (one holding neither the start nor the goal) and
    start row, then the blocked or refuel cells (a set, among the cells left and off the
    agent's column). Exact: a sum over the columns and over how many proposition cells
    fall on the agent's column. An upper bound on the family's distinct tests (an attempt
    without a test is redrawn, so some layouts never appear).

    Example::

        layout_count(5, "reachability", 1)   # 25 * 24 * 23 = 13,800

    Raises
    ------
    ValueError
        On an unknown family, ``n``, world or kind.
    """
    _check_world(world, kind)
    _, _, props, _ = family_objectives(family, n)
    cells, p = size * size, len(props)
    k = blocked_count(size) if world == "blocked" else refuel_count(size) if world == "fuel" else 0
    if kind != "agent":
        return perm(cells, p + 2) * comb(cells - p - 2, k)
    total = 0
    for same_column in (True, False):  # the start and the goal in one column, or in two
        pairs = cells * (size - 1) if same_column else cells * (cells - size)
        columns = size - (1 if same_column else 2)
        for j in range(p + 1):  # proposition cells on the agent's column
            props_placed = comb(p, j) * perm(size, j) * perm(cells - 2 - size, p - j)
            left = cells - size - 2 - (p - j)
            total += pairs * columns * props_placed * size * comb(left, k)
    return total


def world_problem_name(size: int, family: str, n: int, seed: int, world: str, kind: str) -> str:
    """The problem name of a seed: the empty world keeps the paper study's names."""
    middle = f"{kind}" if world == "empty" else f"{world}-{kind}"
    return f"random-{size}x{size}-{family}{n}-{middle}-s{seed}"


def _check_world(world: str, kind: str) -> None:
    if world not in WORLDS:
        raise ValueError(f"unknown world {world!r}; expected one of {', '.join(WORLDS)}")
    if kind not in POOL_KINDS:
        raise ValueError(f"unknown kind {kind!r}; expected one of {', '.join(POOL_KINDS)}")


def world_problem(size: int, family: str, n: int, seed: int, attempt: int = 0, world: str = "empty", kind: str = "reactive") -> Problem:
    """The random instance of ``(size, family, n, seed, attempt)`` in ``world``, as a ``kind`` problem.

    Raises
    ------
    ValueError
        On an unknown family, ``n``, world or kind, or a grid too small for its cells.
    InconsistentProblem
        ``"unreachable"`` if the goal or the agent's column is out of the system's reach
        (fuel worlds): the attempt has no test and is redrawn.
    """
    _check_world(world, kind)
    if world == "empty" and kind != "agent":
        return random_problem(size, family, n, seed, attempt, kind)
    sys_obj, test_obj, props, goal_prop = family_objectives(family, n)
    rng, start, goal, prop_cells = draw_special_cells(size, len(props), seed, attempt)
    taken: set[Cell] = {start, goal, *prop_cells}
    column: list[Cell] = []
    agent_start: Cell | None = None
    if kind == "agent":
        cols = [c for c in range(size) if c not in (start[1], goal[1])]
        col = cols[int(rng.integers(len(cols)))]
        column = [(r, col) for r in range(size)]
        agent_start = (int(rng.integers(size)), col)
    rest = [(r, c) for r in range(size) for c in range(size) if (r, c) not in taken and (r, c) not in column]
    k = blocked_count(size) if world == "blocked" else refuel_count(size) if world == "fuel" else 0
    if k > len(rest):
        raise ValueError(f"a {size}x{size} grid has too few cells for {k} {world} cells")
    drawn = [rest[int(i)] for i in rng.choice(len(rest), size=k, replace=False)] if k else []
    prop_of = dict(zip(prop_cells, props, strict=True))
    tokens: dict[Cell, str] = {c: "t" for c in column}
    if agent_start is not None:
        tokens[agent_start] = "t0"
    tokens |= {start: "S", goal: "T"} | {c: p for c, p in prop_of.items()}
    name = world_problem_name(size, family, n, seed, world, kind)
    description = f"random {world} grid, seed {seed}, attempt {attempt}"
    declared: list[str] = []
    if world == "fuel":
        tokens |= {c: "R" for c in drawn}
        ts = _fuel_world(size, start, goal, goal_prop, prop_of, drawn, tokens)
        sys_obj = f"{sys_obj} & G !{EMPTY_PROPOSITION}"
        # a cell out of the fuel's reach labels no state: its proposition still exists (the
        # attempt is then inconsistent or not, as its objectives say), it is not a typo
        declared = [EMPTY_PROPOSITION, goal_prop, *props]
    else:
        blocked = set(drawn)
        free = [(r, c) for r in range(size) for c in range(size) if (r, c) not in blocked]
        labels: dict[Cell, Iterable[str]] = {goal: [goal_prop]}
        labels.update({c: [p] for c, p in prop_of.items()})
        ts = grid_world(free, size, size, start, [goal], labels, tokens)
    if kind != "agent":
        return make_problem(name, ts, sys_obj, test_obj, kind, tie_places=world == "fuel", description=description, declared_propositions=declared)
    assert agent_start is not None
    agent = _column_agent(ts, column, agent_start)
    return make_problem(name, ts, sys_obj, test_obj, "agent", agent=agent, description=description, declared_propositions=declared)


def _fuel_world(size: int, start: Cell, goal: Cell, goal_prop: str, prop_of: dict[Cell, str], refuel: list[Cell], tokens: dict[Cell, str]) -> TransitionSystem:
    """The fuel grid of a ``fuel`` world (one label per state: goal > empty > proposition)."""

    def label(cell: Cell, fuel: int) -> list[str]:
        if cell == goal:
            return [goal_prop]
        if fuel == 0:
            return [EMPTY_PROPOSITION]
        p = prop_of.get(cell)
        return [p] if p is not None else []

    cells = [(r, c) for r in range(size) for c in range(size)]
    try:
        return fuel_grid_world(cells, size, size, start, fuel_capacity(size), refuel, [goal], label, tokens)
    except ProblemError as exc:  # the goal is out of the fuel's reach: no state of it, none terminal
        raise InconsistentProblem("unreachable", f"the goal is out of the fuel's reach: {exc}") from None


def _column_agent(ts: TransitionSystem, column: list[Cell], start: Cell) -> TestAgent:
    """The test agent of an ``agent`` instance: up/down/stay on its column, parks at both ends."""
    try:
        cells = places_of_cells(ts, column, "random grid agent")
    except ProblemError as exc:  # a fuel grid's cell out of the system's reach
        raise InconsistentProblem("unreachable", f"the test agent's column is out of the system's reach: {exc}") from None
    top, bottom = places_of_cells(ts, [column[0]]), places_of_cells(ts, [column[-1]])
    return make_test_agent(
        ts,
        cells,
        places_of_cells(ts, [start])[0],
        [("top", top), ("bottom", bottom)],
        moves="4-neighbour",
        stay=True,
        first="system",
        max_iterations=AGENT_ITERATIONS,
        where="random grid agent",
    )


def first_accepted(
    size: int,
    family: str,
    n: int,
    seed: int,
    world: str,
    kind: str,
    accept: Callable[[Problem], T],
    max_attempts: int = MAX_ATTEMPTS,
) -> tuple[int, Problem, T]:
    """The first attempt of a seed whose problem ``accept`` takes: ``(attempt, problem, accepted)``.

    ``accept(problem)`` raises :class:`InconsistentProblem` to reject an attempt (any
    other exception propagates); so does drawing an attempt that is inconsistent by
    construction.

    Raises
    ------
    RuntimeError
        If no attempt among ``max_attempts`` is accepted.
    """
    for attempt in range(max_attempts):
        try:
            problem = world_problem(size, family, n, seed, attempt, world, kind)
            value = accept(problem)
        except InconsistentProblem:
            continue
        return attempt, problem, value
    raise RuntimeError(f"no {world} {kind} random grid with a test for seed {seed} in {max_attempts} attempts")
