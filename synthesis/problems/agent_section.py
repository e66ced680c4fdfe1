"""The ``[environment.agent]`` table of a problem file (problem-format.md): the test agent."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..model.agent_system import DEFAULT_MAX_ITERATIONS, TestAgent, make_test_agent
from ..model.errors import ProblemError
from ..model.systems import TransitionSystem

_AGENT_KEYS = {"cells", "start", "parks", "moves", "stay", "first", "max_iterations"}
_PARK_KEYS = {"name", "from"}


def agent_from_toml(table: Any, ts: TransitionSystem, cell_of: Callable[[Any, str], list[int]], where: str) -> TestAgent:
    """The test agent of a problem file's ``[environment.agent]`` table.

    The section, for the common case::

        [environment.agent]
        cells = ["t", "t0"]            # tokens or [row, col] cells the agent may occupy
        start = "t0"                   # a cell (or the name of a park)
        parks = [{name = "up", from = [[0, 2]]}]   # absorbing, reached from these cells
        moves = "4-neighbour"          # optional: "4-neighbour" | "system" | [[from, to], ...]
        stay = true                    # optional: true | false | cells where it may stay
        first = "system"               # optional: "system" | "agent" (who moves first)
        max_iterations = 100           # optional: bound on the counterexample-guided loop

    ``cell_of(spec, where)`` resolves tokens and cells to system states (and raises
    :class:`ProblemError`); on a fuel grid a state's cell stands for every fuel level.

    Raises
    ------
    ProblemError
        With what is wrong and where (unknown key, missing ``cells``/``start``/``parks``,
        a bad park, move or value).
    """
    if not isinstance(table, dict):
        raise ProblemError(f"{where} must be a table")
    extra = sorted(set(table) - _AGENT_KEYS)
    if extra:
        raise ProblemError(f"unknown key {extra[0]!r} in {where} (allowed: {', '.join(sorted(_AGENT_KEYS))})")
    for key in ("cells", "start", "parks"):
        if key not in table:
            raise ProblemError(f"missing `{key}` in {where}")

    def places(spec: Any, at: str) -> list[int]:
        return list(dict.fromkeys(int(ts.place[s]) for s in cell_of(spec, at)))

    cells = places(table["cells"], f"{where} cells")
    parks_spec = table["parks"]
    if not isinstance(parks_spec, list) or not parks_spec:
        raise ProblemError(f"{where} parks must be a non-empty list of {{name = ..., from = [...]}} tables")
    parks: list[tuple[str, list[int]]] = []
    for k, item in enumerate(parks_spec):
        at = f"{where} parks[{k}]"
        if not isinstance(item, dict):
            raise ProblemError(f"{at} must be a table {{name = ..., from = [...]}}")
        bad = sorted(set(item) - _PARK_KEYS)
        if bad:
            raise ProblemError(f"unknown key {bad[0]!r} in {at} (allowed: from, name)")
        if "name" not in item or not isinstance(item["name"], str):
            raise ProblemError(f"{at} needs a `name` (a string)")
        if "from" not in item:
            raise ProblemError(f"{at} needs `from`: the cells the park is reached from")
        parks.append((item["name"], places(item["from"], f"{at} from")))
    park_names = {name for name, _ in parks}
    start_spec = table["start"]
    start: int | str
    if isinstance(start_spec, str) and start_spec in park_names:
        start = start_spec
    else:
        got = places(start_spec, f"{where} start")
        if len(got) != 1:
            raise ProblemError(f"{where} start must name exactly one cell, got {len(got)}")
        start = got[0]
    moves_spec = table.get("moves", "4-neighbour")
    moves: str | list[tuple[int, int]]
    if isinstance(moves_spec, str):
        moves = moves_spec
    elif isinstance(moves_spec, list):
        moves = []
        for k, item in enumerate(moves_spec):
            if not (isinstance(item, list) and len(item) == 2):
                raise ProblemError(f"{where} moves[{k}]: {item!r} is not a [from, to] move")
            for u in places(item[0], f"{where} moves[{k}]"):
                for v in places(item[1], f"{where} moves[{k}]"):
                    moves.append((u, v))
    else:
        raise ProblemError(f'{where} moves must be "4-neighbour", "system" or a list of [from, to] moves')
    stay_spec = table.get("stay", True)
    stay: bool | list[int]
    if isinstance(stay_spec, bool):
        stay = stay_spec
    else:
        stay = places(stay_spec, f"{where} stay")
    first = table.get("first", "system")
    if not isinstance(first, str):
        raise ProblemError(f'{where} first must be "system" or "agent"')
    return make_test_agent(
        ts,
        cells,
        start,
        parks,
        moves=moves,
        stay=stay,
        first=first,
        max_iterations=table.get("max_iterations", DEFAULT_MAX_ITERATIONS),
        where=where,
    )
