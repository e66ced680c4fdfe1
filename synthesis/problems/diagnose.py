"""Why a problem has no test: the conjunct or the visit to blame, in the user's words.

:func:`~synthesis.graphs.consistency.check_consistency` decides the two inconsistent cases
of docs/method.md §5 on the product graphs. This module says which part of the problem causes
them, by building the product graphs again for parts of the objectives (small problems
only: at most :data:`MAX_DIAGNOSIS_EDGES` edges of G):

* **unreachable**: a visit of the system objective that no way from the start meets (the
  goal is walled off), or the conjunct (``G !hazard``) that no way to the goal keeps;
* **implied**: the system objective already implies the test objective (``test = "F dock"``
  with the dock the goal): every execution that meets the system objective meets the
  test objective too, so a test needs no restriction and there is nothing to route
  (reason ``"unroutable"``, as docs/method.md §5 has it: no execution passes the test
  objective *before* the goal; the message says it is implied);
* **unroutable**: the visit of the test objective (``F bay``) that no execution meeting the
  system objective makes before the goal, and, where one does, the system conjunct that
  forbids it.

Example
-------
>>> check_problem_consistency(problem, products)  # doctest: +SKIP
Traceback (most recent call last):
InconsistentProblem: `G !hazard` makes the goal unreachable: every way from the start to the goal breaks it
"""

from __future__ import annotations

import numpy as np

from ..graphs.automata import specification_product
from ..graphs.consistency import check_consistency
from ..graphs.products import Products, build_products, coreachable, reachable
from ..model.errors import InconsistentProblem
from ..model.specs import Objective, Task
from .problem import Problem

MAX_DIAGNOSIS_EDGES = 2_000_000
"""Largest G (edges) whose inconsistency is explained part by part; beyond it the message of
:func:`~synthesis.graphs.consistency.check_consistency` stands (each part is a graph build)."""


def _objective(tasks: list[Task] | tuple[Task, ...]) -> Objective:
    return Objective(" & ".join(t.text for t in tasks), tuple(tasks))


def _products(problem: Problem, system: Objective, test: Objective) -> Products:
    ts = problem.system
    return build_products(ts, specification_product(system, test, ts.letters()))


def _reaches_goal(problem: Problem, tasks: list[Task]) -> bool:
    """Whether some execution from the start meets the system tasks ``tasks``."""
    p = _products(problem, _objective(tasks), problem.test_objective)
    gs = p.system
    return bool(coreachable(gs.n_nodes, gs.src, gs.dst, p.system_target)[gs.initial])


def _routable(problem: Problem, system: list[Task], test: list[Task]) -> bool:
    """Whether some execution meets the test tasks before it meets the system tasks."""
    p = _products(problem, _objective(system), _objective(test))
    g = p.virtual
    co = coreachable(g.n_nodes, g.src, g.dst, p.target)
    start = np.zeros(g.n_nodes, dtype=bool)
    start[g.initial] = True
    on_way = reachable(g.n_nodes, g.src, g.dst, start) & co
    return bool(np.any(p.intermediate & on_way))


def _quoted(tasks: list[Task]) -> str:
    return " and ".join(f"`{t.text}`" for t in tasks)


def explain_unreachable(problem: Problem) -> str:
    """Which part of the system objective no execution from the start can meet."""
    tasks = list(problem.system_objective.tasks)
    visits = [t for t in tasks if t.is_visit]
    others = [t for t in tasks if not t.is_visit]
    if not _reaches_goal(problem, visits):
        alone = [t for t in visits if not _reaches_goal(problem, [t])]
        if alone:
            return (
                f"{_quoted(alone)} cannot be met: no way from the start gets there, whatever else the "
                "system objective asks (check the grid's walls, the start and the labels)"
            )
        return f"the visits {_quoted(visits)} cannot all be met: no way from the start meets them together"
    blamed = [t for t in others if not _reaches_goal(problem, [*visits, t])]
    goal = _quoted(visits)
    if len(blamed) == 1:
        return f"`{blamed[0].text}` makes the goal unreachable: every way from the start to {goal} breaks it"
    if blamed:
        return f"{_quoted(blamed)} each make the goal unreachable: every way from the start to {goal} breaks them"
    return f"{_quoted(others)} together make the goal unreachable: every way from the start to {goal} breaks one of them"


def explain_unroutable(problem: Problem) -> str:
    """Which visit of the test objective no execution meeting the system objective makes
    before the goal, and the system conjunct that forbids it where there is one."""
    system = list(problem.system_objective.tasks)
    test = list(problem.test_objective.tasks)
    sys_text = f"`{problem.system_objective.text}`"
    blamed = [t for t in test if not _routable(problem, system, [t])]
    if not blamed:
        return f"the visits {_quoted(test)} cannot all be made before the goal by one execution that meets {sys_text}, though each can alone"
    visit = blamed[0]
    visits = [t for t in system if t.is_visit]
    others = [t for t in system if not t.is_visit]
    text = f"the test objective's `{visit.text}` cannot be routed: no execution that meets {sys_text} makes it before the goal"
    if implied(_products(problem, _objective(system), _objective([visit]))):
        text += (
            f" (the system objective already asks for it: every execution that meets {sys_text} meets "
            f"`{visit.text}` by the time it ends; drop it from the test objective)"
        )
    elif others and _routable(problem, visits, [visit]):
        culprits = [t for t in others if not _routable(problem, [*visits, t], [visit])]
        if culprits:
            text += f" (every way through it breaks {_quoted(culprits)})"
    elif not _routable(problem, visits, [visit]):
        text += " (no way from the start makes it and then reaches the goal)"
    if len(blamed) > 1:
        text += f"; nor can {_quoted(blamed[1:])}"
    return text


def implied(products: Products) -> bool:
    """Whether every execution that meets the system objective meets the test objective
    too (by the time it meets the system objective): the test objective is implied.
    True when some goal node is reachable and every reachable goal node of G has the test
    objective met."""
    g = products.virtual
    start = np.zeros(g.n_nodes, dtype=bool)
    start[g.initial] = True
    seen = reachable(g.n_nodes, g.src, g.dst, start)
    goal = seen & products.target
    accepting = products.spec.accepting_test[g.hist]
    return bool(goal.any() and np.all(accepting[goal]))


def check_problem_consistency(problem: Problem, products: Products) -> np.ndarray:
    """:func:`~synthesis.graphs.consistency.check_consistency`, with messages that name the
    cause (see the module docstring). Returns the mask of G's nodes that can reach ``Tgt``.

    Raises
    ------
    InconsistentProblem
        ``"unreachable"`` or ``"unroutable"`` (the test objective implied, too), the message naming the
        conjunct or visit to blame (on problems of at most :data:`MAX_DIAGNOSIS_EDGES`
        edges of G; larger ones keep the general message).
    """
    try:
        return check_consistency(products)
    except InconsistentProblem as exc:
        if exc.reason == "unroutable" and implied(products):
            raise InconsistentProblem(
                "unroutable",
                f"the system objective `{problem.system_objective.text}` already implies the test objective "
                f"`{problem.test_objective.text}`: every execution that meets the one meets the other by the "
                "time it ends, so there is nothing to route: a test of it needs no restriction and every correct "
                "system passes it; ask the test for something the system objective does not",
            ) from None
        if products.virtual.n_edges > MAX_DIAGNOSIS_EDGES:
            raise
        if exc.reason == "unreachable":
            raise InconsistentProblem("unreachable", f"the system objective cannot be met: {explain_unreachable(problem)}") from None
        if exc.reason == "unroutable":
            raise InconsistentProblem("unroutable", explain_unroutable(problem)) from None
        raise
