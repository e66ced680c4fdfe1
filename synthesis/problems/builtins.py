"""The paper's examples as built-in problems (paper-examples.md).

Grid examples without special rules are written in the TOML format and parsed with
the same loader users get; examples whose labels need code (fuel levels, motion
primitives, test agents) are built in Python.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable

from ..model.agent_system import make_test_agent, places_of_cells
from ..model.systems import Cell, fuel_grid_world, graph_system, grid_world
from .files import problem_from_dict
from .problem import Problem, make_problem

EXAMPLE1 = """
name = "example1"
description = "The paper's running example: a 3x5 grid, two goals, three I cells; static walls."
[system]
grid = '''
T . I . T
. . . . .
I . S . I
'''
start = "S"
terminal = ["T"]
[labels]
goal = ["T"]
I = ["I"]
[objectives]
system = "F goal"
test = "F I"
[environment]
kind = "static"
"""

SMALL_REACTIVE = """
name = "small-reactive"
description = "The paper's second running example: visit I1 and I2 before the goal; reactive doors."
[system]
grid = '''
I1 .  T
S  .  I2
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
kind = "reactive"
"""


def _from_toml(text: str) -> Problem:
    return problem_from_dict(tomllib.loads(text), "built-in")


def example1() -> Problem:
    return _from_toml(EXAMPLE1)


def small_reactive() -> Problem:
    return _from_toml(SMALL_REACTIVE)


def beaver_rescue() -> Problem:
    """Leave the lab through one door, fetch the beaver, come back through the other."""
    states = ["init", "d1", "d2", "beaver", "p1", "p2", "goal"]
    edges = [
        ("init", "d1"),
        ("init", "d2"),
        ("d1", "d2"),
        ("d2", "d1"),
        ("d1", "beaver"),
        ("d2", "beaver"),
        ("beaver", "p1"),
        ("beaver", "p2"),
        ("p1", "p2"),
        ("p2", "p1"),
        ("p1", "goal"),
        ("p2", "goal"),
    ]
    labels = {"d1": ["door1"], "p1": ["door1"], "d2": ["door2"], "p2": ["door2"], "beaver": ["beaver"], "goal": ["goal"]}
    ts = graph_system(states, edges, "init", ["goal"], labels)
    return make_problem(
        "beaver-rescue",
        ts,
        "F(beaver & F goal)",
        "F door1 & F door2",
        "reactive",
        description="A rescue robot must use both doors: out through one, back through the other.",
    )


def motion_primitives() -> Problem:
    """Doors open according to the motion primitives already shown (jump, lie, stand)."""
    states = [
        "init",
        "p1",
        "p2",
        "p3",
        "jump1",
        "stand1",
        "stand2",
        "stand3",
        "lie3",
        "d1_j",
        "d1_s",
        "d2_s",
        "d3_s",
        "d3_l",
        "goal",
    ]
    edges = [
        ("init", "p1"),
        ("init", "p2"),
        ("init", "p3"),
        ("p1", "jump1"),
        ("p1", "stand1"),
        ("p2", "stand2"),
        ("p3", "stand3"),
        ("p3", "lie3"),
        ("jump1", "d1_j"),
        ("stand1", "d1_s"),
        ("stand2", "d2_s"),
        ("stand3", "d3_s"),
        ("lie3", "d3_l"),
        ("d1_s", "p1"),
        ("d1_j", "p1"),
        ("d2_s", "p2"),
        ("d3_s", "p3"),
        ("d3_l", "p3"),
        ("p1", "p2"),
        ("p2", "p1"),
        ("p2", "p3"),
        ("p3", "p2"),
    ]
    edges += [(d, "goal") for d in ("d1_j", "d1_s", "d2_s", "d3_s", "d3_l")]
    labels = {"jump1": ["jump"], "lie3": ["lie"], "stand1": ["stand"], "stand2": ["stand"], "stand3": ["stand"], "goal": ["goal"]}
    ts = graph_system(states, edges, "init", ["goal"], labels)
    return make_problem(
        "motion-primitives",
        ts,
        "F goal",
        "F jump & F lie & F stand",
        "reactive",
        description="A legged robot must show a jump, a lie-down and a stand before the exit opens.",
    )


def _grid_cells(rows: int, cols: int, blocked: frozenset[Cell] | set[Cell] = frozenset()) -> list[Cell]:
    return [(r, c) for r in range(rows) for c in range(cols) if (r, c) not in blocked]


def refueling() -> Problem:
    """5x5 with fuel: the test wants the system low on fuel far from the goal."""
    goal: Cell = (0, 0)
    refuel: Cell = (0, 4)
    low_cells = {(r, c) for r in range(4) for c in range(2, 5)} - {refuel}

    def label(cell: Cell, fuel: int) -> list[str]:
        # one label per state, priority goal > unsafe > low
        if cell == goal:
            return ["goal"]
        if fuel == 0:
            return ["unsafe"]
        if cell in low_cells and fuel == 1:
            return ["low"]
        return []

    tokens = {goal: "T", refuel: "R", (4, 0): "S"} | {c: "L" for c in low_cells}
    ts = fuel_grid_world(_grid_cells(5, 5), 5, 5, (4, 0), 10, [refuel], [goal], label, tokens)
    return make_problem(
        "refueling",
        ts,
        "F goal & G !unsafe",
        "F low",
        "static",
        tie_places="static",
        description="Reach the goal without running dry; walls force a low-fuel detour far from the goal.",
    )


def mars_exploration() -> Problem:
    """6x6 with fuel, samples to drop off, the paper's large static instance."""
    goal: Cell = (0, 0)
    refuel = [(0, 5), (3, 3)]
    ice, rock = (1, 4), (4, 1)
    dropoff = [(3, 0), (4, 5)]

    def label(cell: Cell, fuel: int) -> list[str]:
        if cell == goal:
            return ["goal"]
        r, c = cell
        lab = None  # one label per state, later wins
        if 1 <= fuel <= min(r + c - 2, 9):
            lab = "lowfuel"
        if fuel == 0:
            lab = "unsafe"
        if fuel <= 9:
            if cell == ice:
                lab = "ice"
            if cell == rock:
                lab = "rock"
            if cell in dropoff:
                lab = "dropoff"
        return [lab] if lab else []

    tokens = {goal: "T", ice: "i", rock: "r", (5, 0): "S"} | {c: "R" for c in refuel} | {c: "D" for c in dropoff}
    ts = fuel_grid_world(_grid_cells(6, 6), 6, 6, (5, 0), 10, refuel, [goal], label, tokens)
    return make_problem(
        "mars-exploration",
        ts,
        "F goal & G !unsafe & G((ice | rock) -> F dropoff)",
        "F lowfuel & F ice & F rock",
        "static",
        tie_places="static",
        description="A rover samples ice and rock, drops them off, and is pushed to run low on fuel.",
    )


# ------------------------------------------------------------ dynamic test agents


def maze1() -> Problem:
    """7x5 maze: visit I1, I2 and I3 before the goal; a test agent climbs column 2.

    The agent starts at (6, 2), moves up one row or stays (never down), and leaves the
    grid to a park above (0, 2). On rows 6, 4, 2 and 0 it may not stay: when it is its
    turn there, it moves up (paper-examples.md). The system moves first.
    """
    rows, cols = 7, 5
    blocked = {(1, 0), (1, 1), (1, 3), (3, 1), (3, 3), (3, 4), (5, 0), (5, 1), (5, 3)}
    goal, start = (0, 0), (6, 0)
    special = {(1, 4): "I1", (3, 0): "I2", (5, 4): "I3"}
    column = [(r, 2) for r in range(rows)]
    tokens = {c: "t" for c in column} | {(6, 2): "t0", goal: "T", start: "S"} | special
    labels = {goal: ["goal"]} | {c: [name] for c, name in special.items()}
    ts = grid_world(_grid_cells(rows, cols, blocked), rows, cols, start, [goal], labels, tokens)
    cells = places_of_cells(ts, column, "maze1 agent")
    up = [(places_of_cells(ts, [(r, 2)])[0], places_of_cells(ts, [(r - 1, 2)])[0]) for r in range(1, rows)]
    may_stay = places_of_cells(ts, [(r, 2) for r in (1, 3, 5)])
    agent = make_test_agent(
        ts,
        cells,
        places_of_cells(ts, [(6, 2)])[0],
        [("above", places_of_cells(ts, [(0, 2)]))],
        moves=up,
        stay=may_stay,
        first="system",
        where="maze1 agent",
    )
    return make_problem(
        "maze1",
        ts,
        "F goal",
        "F I1 & F I2 & F I3",
        "agent",
        agent=agent,
        description="A maze with three test cells; a test agent climbing the middle column blocks shortcuts.",
    )


def maze2() -> Problem:
    """5x5 maze, the headline environment: visit I1 and I2 before the goal.

    The test agent lives on the plus (centre row and centre column), starts at (2, 2)
    and moves first: one step along the plus, or stays. Four absorbing parks lie off
    the ends of the plus. Static area: every free cell off the plus.
    """
    rows, cols = 5, 5
    blocked = {(1, 1), (1, 3), (3, 1), (3, 3)}
    goal, start = (0, 4), (4, 0)
    special = {(3, 4): "I1", (1, 0): "I2"}
    plus = [(2, c) for c in range(cols)] + [(r, 2) for r in range(rows) if r != 2]
    tokens = {c: "t" for c in plus} | {(2, 2): "t0", goal: "T", start: "S"} | special
    labels = {goal: ["goal"]} | {c: [name] for c, name in special.items()}
    ts = grid_world(_grid_cells(rows, cols, blocked), rows, cols, start, [goal], labels, tokens)
    cells = places_of_cells(ts, plus, "maze2 agent")
    parks = [
        ("above", places_of_cells(ts, [(0, 2)])),
        ("below", places_of_cells(ts, [(4, 2)])),
        ("left", places_of_cells(ts, [(2, 0)])),
        ("right", places_of_cells(ts, [(2, 4)])),
    ]
    agent = make_test_agent(
        ts,
        cells,
        places_of_cells(ts, [(2, 2)])[0],
        parks,
        moves="4-neighbour",
        stay=True,
        first="agent",
        where="maze2 agent",
    )
    return make_problem(
        "maze2",
        ts,
        "F goal",
        "F I1 & F I2",
        "agent",
        agent=agent,
        description="The headline maze: a test agent on the central plus makes the system visit I1 and I2.",
    )


def patrolling() -> Problem:
    """6x6 with fuel: a test agent patrolling column 2 makes the system run low on fuel.

    Fuel as in refueling (max 10, moves cost 1, R refills); start ((5, 5), 10); goal
    (5, 0). ``empty`` at fuel 0; ``lowfuel`` at ``1 <= f <= min((5 - row) + col - 2, 9)``;
    one label per state, priority goal > empty > lowfuel (as refueling). The agent moves
    one row up or down in column 2 or stays, starts at (5, 2), and parks off the grid
    from row 0 or row 5. Static area: everything off column 2.

    Physical walls, as paper-examples.md asks: the static area's cuts are tied across fuel
    levels and directions (``tie_places="static"``, ``bidirectional_cuts=True``, docs/method.md
    §5 c14), one wall per pair of cells, while the test agent's cuts (moves into column 2)
    stay per move and history. Proven optimal at flow 1, the paper's figure, with 27 cuts
    and its test agent realized after 2 loop rounds (the first cut set traps the system at
    ``((5, 2), 5)``); this MILP is much harder than the per-fuel-level one this built-in
    used before (flow 2, 10 cuts, half a second): minutes of solver time, so the tests load
    the shipped artifact (docs/benchmarks.md, "Patrolling with physical walls").
    """
    rows, cols = 6, 6
    goal, start, refuel = (5, 0), (5, 5), (1, 5)

    def label(cell: Cell, fuel: int) -> list[str]:
        if cell == goal:
            return ["goal"]
        if fuel == 0:
            return ["empty"]
        r, c = cell
        if 1 <= fuel <= min((5 - r) + c - 2, 9):
            return ["lowfuel"]
        return []

    column = [(r, 2) for r in range(rows)]
    tokens = {c: "t" for c in column} | {(5, 2): "t0", goal: "T", start: "S", refuel: "R"}
    ts = fuel_grid_world(_grid_cells(rows, cols), rows, cols, start, 10, [refuel], [goal], label, tokens)
    cells = places_of_cells(ts, column, "patrolling agent")
    parks = [("top", places_of_cells(ts, [(0, 2)])), ("bottom", places_of_cells(ts, [(5, 2)]))]
    agent = make_test_agent(
        ts,
        cells,
        places_of_cells(ts, [(5, 2)])[0],
        parks,
        moves="4-neighbour",
        stay=True,
        first="system",
        where="patrolling agent",
    )
    return make_problem(
        "patrolling",
        ts,
        "F goal & G !empty",
        "F lowfuel",
        "agent",
        agent=agent,
        description="A test agent patrolling column 2 pushes a fuel-limited robot to run low far from the goal.",
        tie_places="static",
        bidirectional_cuts=True,
    )


BUILTINS: dict[str, Callable[[], Problem]] = {
    "example1": example1,
    "small-reactive": small_reactive,
    "beaver-rescue": beaver_rescue,
    "motion-primitives": motion_primitives,
    "refueling": refueling,
    "mars-exploration": mars_exploration,
    "maze1": maze1,
    "maze2": maze2,
    "patrolling": patrolling,
}
