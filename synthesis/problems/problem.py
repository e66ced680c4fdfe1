"""Test problems: a system, its objectives and the kind of test environment.

Problems come from TOML files (:mod:`synthesis.problems.files`, problem-format.md) or from
the built-in registry (:mod:`synthesis.problems.builtins`, paper-examples.md);
:func:`synthesis.problems.load.load_problem` accepts either a path or a built-in name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..graphs.automata import SpecificationProduct, specification_product
from ..graphs.products import Products, build_products
from ..model.agent_system import TestAgent
from ..model.errors import ProblemError
from ..model.specs import Objective, check_proposition_name, check_propositions, holds, parse_objective
from ..model.strategy import SETTINGS
from ..model.systems import TransitionSystem

KINDS = ("static", "reactive", "mixed", "agent")

CAP_KEYS = ("max_walls", "max_doors", "max_restrictions")
"""The caps on what a test may use: physical walls (static restrictions), doors (reactive
ones, and a test agent's blocks) and both together, each a move of the system between two
places, counted once whichever way and under however many histories it is restricted."""

MAX_CAP = 10**9
"""Largest cap accepted (far above any move count FlowTest can solve)."""


def shown(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters (a number of thousands of digits stays one
    short line in a message)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}... ({len(text)} characters)"


def check_caps(caps: dict[str, Any], where: str) -> dict[str, int]:
    """``caps`` checked: keys of :data:`CAP_KEYS`, values non-negative integers.

    Raises
    ------
    ProblemError
        Naming the key and ``where``.
    """
    out: dict[str, int] = {}
    for key, value in caps.items():
        if key not in CAP_KEYS:
            raise ProblemError(f"unknown cap {key!r}{where}; expected one of {', '.join(CAP_KEYS)}")
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_CAP:
            raise ProblemError(f"`{key}`{where} must be a whole number from 0 to {MAX_CAP}, not {shown(value)}")
        out[key] = int(value)
    return out


TIE_PLACES = ("none", "all", "static")
"""What ``MilpOptions.tie_places`` (and ``Problem.tie_places``) ties across the states of one
place (the fuel levels of a cell): ``"none"`` (every cut is per transition of T), ``"all"``
(every cut group, static and reactive alike, is per pair of places) or ``"static"`` (the
static cuts are per pair of places: walls that do not come and go with the fuel gauge; the
reactive cuts stay per transition of T and history, as a test agent realizes them)."""


@dataclass
class Problem:
    """Everything synthesis needs.

    Attributes
    ----------
    name
        The problem's name (used in outputs).
    system
        The transition system T with labels and harness.
    system_objective, test_objective
        Parsed objectives (``phi_sys``, ``phi_test``).
    kind
        ``"static"``, ``"reactive"``, ``"mixed"`` or ``"agent"``.
    bidirectional_cuts
        c14 (default: true for static problems, false otherwise).
    tie_places
        Which cuts are tied across the states of one place (fuel levels), one of
        :data:`TIE_PLACES`: ``"none"``, ``"all"`` (static and
        reactive cuts) or ``"static"`` (the static area's cuts only: physical walls, one
        per pair of cells, while a test agent's cuts stay per transition and history).
    static_moves
        ``bool`` mask over moves: the static area of a mixed or agent problem. An agent
        problem without one gets its agent's default (:meth:`TestAgent.static_moves`:
        every move into a place the agent never occupies), here and nowhere else.
    time_limit
        Default solver time limit in seconds (``None``: none).
    agent
        The test agent of an agent problem (:mod:`synthesis.model.agent_system`).
    description
        One paragraph for people.
    caps
        Caps on what a test may use (:data:`CAP_KEYS`: ``max_walls``, ``max_doors``,
        ``max_restrictions``), counted as physical restrictions (moves of the system between
        two places, a two-way wall once); absent keys: no cap.
    one_way_walls
        Whether a static restriction may block one direction of a move and leave the move
        back open (``MilpOptions.one_way_walls``). True here (the built-in problems, as
        published); problem files default to false unless a static problem sets
        ``bidirectional_cuts = false``.
    """

    name: str
    system: TransitionSystem
    system_objective: Objective
    test_objective: Objective
    kind: str
    bidirectional_cuts: bool
    tie_places: str = "none"
    static_moves: np.ndarray | None = None
    time_limit: float | None = None
    agent: TestAgent | None = None
    description: str = ""
    extras: dict[str, Any] = field(default_factory=dict)
    caps: dict[str, int] = field(default_factory=dict)
    one_way_walls: bool = True

    def __post_init__(self) -> None:
        if self.kind == "agent" and self.static_moves is None and self.agent is not None:
            self.static_moves = self.agent.static_moves(self.system)


def make_problem(
    name: str,
    system: TransitionSystem,
    system_objective: str,
    test_objective: str,
    kind: str,
    bidirectional_cuts: bool | None = None,
    **kw: Any,
) -> Problem:
    """Validate and assemble a problem.

    ``tie_places`` (in ``kw``) is one of :data:`TIE_PLACES`;
    ``True`` and ``False`` stand for ``"all"`` and ``"none"``.

    Raises
    ------
    ProblemError
        On an unknown kind or ``tie_places``, a formula outside the fragment, an unknown
        proposition, or a system objective whose goal is not at terminal states.

    Examples
    --------
    A fork: the system may reach the goal through ``left`` or ``right``; the test wants it
    through the door on the left, so it closes the way to the right.

    >>> from synthesis import make_problem, synthesize
    >>> from synthesis.model.systems import graph_system
    >>> system = graph_system(
    ...     ["start", "left", "right", "goal"],
    ...     [("start", "left"), ("start", "right"), ("left", "goal"), ("right", "goal")],
    ...     "start", ["goal"], {"left": ["door"], "goal": ["goal"]})
    >>> problem = make_problem("fork", system, "F goal", "F door", "static")
    >>> test = synthesize(problem)
    >>> [(system.states[system.src[m]], system.states[system.dst[m]]) for m in test.strategy.static_obstacles.nonzero()[0]]
    [('start', 'right')]
    """
    if kind not in KINDS:
        raise ProblemError(f"unknown environment kind {kind!r}; expected one of {', '.join(KINDS)}")
    if "tie_places" in kw:
        kw["tie_places"] = _tie_mode(kw["tie_places"])
    if "caps" in kw:
        kw["caps"] = check_caps(dict(kw["caps"]), "")
    sys_obj = parse_objective(system_objective, "system")
    test_obj = parse_objective(test_objective, "test")
    known = system.propositions() | set(kw.pop("declared_propositions", ()))
    for prop in sorted(known, key=str):
        check_proposition_name(prop, "[labels]")
    setting = kw.get("extras", {}).get("setting")
    if setting is not None and setting not in SETTINGS:
        raise ProblemError(f"unknown obstacle setting {setting!r} in [environment]; expected one of {', '.join(SETTINGS)}")
    check_propositions(sys_obj, known, "system")
    check_propositions(test_obj, known, "test")
    _check_goal_terminal(system, sys_obj)
    if bidirectional_cuts is None:
        bidirectional_cuts = kind == "static"
    if kind == "mixed" and kw.get("static_moves") is None:
        raise ProblemError("a mixed problem needs [environment] static = [...] (its static area)")
    return Problem(name, system, sys_obj, test_obj, kind, bool(bidirectional_cuts), **kw)


def _tie_mode(value: object) -> str:
    """``tie_places`` as a mode of :data:`TIE_PLACES` (booleans:
    ``True`` ties every cut, ``False`` none, as the option meant before its modes)."""
    if isinstance(value, bool):
        return "all" if value else "none"
    if isinstance(value, str) and value in TIE_PLACES:
        return value
    raise ProblemError(f"unknown tie_places {value!r}; expected one of {', '.join(TIE_PLACES)} (or true/false)")


def _check_goal_terminal(ts: TransitionSystem, objective: Objective) -> None:
    """docs/method.md §2: some visit task's last proposition holds only at terminal states."""
    for task in objective.tasks:
        if not task.is_visit:
            continue
        last = task.props[-1]
        where = np.array([holds(last, a) for a in ts.labels])
        if where.any() and not np.any(where & ~ts.terminal):
            return
    raise ProblemError(
        "the system objective needs a visit task whose last proposition holds only at terminal "
        "states (the goal); make the goal cells terminal or fix the labels"
    )


def build_graphs(problem: Problem) -> tuple[SpecificationProduct, Products]:
    """Automata and product graphs of a problem (docs/method.md §3-4)."""
    ts = problem.system
    spec = specification_product(problem.system_objective, problem.test_objective, ts.letters())
    return spec, build_products(ts, spec)
