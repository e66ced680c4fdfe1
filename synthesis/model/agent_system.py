"""The test agent's transition system ``T_TA`` (docs/method.md §7): what an agent problem adds.

:class:`TestAgent` lives on the *places* of ``T`` (cells; on a fuel grid the agent occupies a
cell, i.e. every fuel level of it), plus *park* states outside ``T`` from which it blocks
nothing. It is built in Python (:func:`make_test_agent`, used by the built-ins ``maze1``,
``maze2``, ``patrolling``) or from a problem file's ``[environment.agent]`` table
(:func:`synthesis.problems.agent_section.agent_from_toml`). Its default static area
(:meth:`TestAgent.static_moves`) is the one :class:`~synthesis.problems.problem.Problem`
gives an agent problem without a hand-given one.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from .errors import ProblemError
from .systems import Cell, TransitionSystem

FIRST_PLAYERS = ("system", "agent")
MOVE_RULES = ("4-neighbour", "system")
DEFAULT_MAX_ITERATIONS = 100


@dataclass(frozen=True)
class Park:
    """A park state of the test agent: outside ``T``, absorbing, reached from ``entries``.

    ``entries`` are agent *cell states* (indices into :attr:`TestAgent.cells`).
    """

    name: str
    entries: tuple[int, ...]


@dataclass
class TestAgent:
    """The test agent's transition system ``T_TA`` (docs/method.md §7).

    Agent states are numbered: first the cells (``0 .. n_cells - 1``, each a place of
    ``T``), then the parks. A move ``(a, a')`` of :attr:`moves` is one step of the agent;
    a stay is the move ``(a, a)`` and exists only where the agent may stay (parks are
    absorbing: their only move is the stay).

    Attributes
    ----------
    cells
        ``int32[n_cells]``: the place of ``T`` (index into ``ts.places``) of each cell state.
    parks
        The park states, in order (agent states ``n_cells ..``).
    start
        The agent state the agent starts in.
    moves
        ``int32[k, 2]``: the moves ``(a, a')`` of ``T_TA``, stays included.
    first
        ``"system"`` (the system under test moves first) or ``"agent"``.
    names
        A name per agent state: ``"(r, c)"`` for a grid cell, the state name on a graph,
        the park's name for a park.
    max_iterations
        Bound on the counterexample-guided loop (MILP solves).
    """

    __test__ = False

    cells: np.ndarray
    parks: list[Park]
    start: int
    moves: np.ndarray
    first: str = "system"
    names: list[str] = field(default_factory=list)
    max_iterations: int = DEFAULT_MAX_ITERATIONS

    @property
    def n_cells(self) -> int:
        return int(self.cells.size)

    @property
    def n_states(self) -> int:
        return self.n_cells + len(self.parks)

    @property
    def place_of_state(self) -> np.ndarray:
        """``int64[n_states]``: the place of each agent state, ``-1`` for a park."""
        return np.concatenate([self.cells.astype(np.int64), np.full(len(self.parks), -1, dtype=np.int64)])

    def move_matrix(self) -> np.ndarray:
        """``bool[n_states, n_states]``: ``M[a, a']`` iff ``(a, a')`` is a move of ``T_TA``."""
        m = np.zeros((self.n_states, self.n_states), dtype=bool)
        m[self.moves[:, 0], self.moves[:, 1]] = True
        return m

    def agent_places(self, n_places: int) -> np.ndarray:
        """``bool[n_places]``: the places of ``T`` the agent may occupy (its cells)."""
        mask = np.zeros(n_places, dtype=bool)
        mask[self.cells] = True
        return mask

    def static_moves(self, ts: TransitionSystem) -> np.ndarray:
        """The static area ``E_static = {(u, v) in T.E : v not an agent cell}`` as a move mask."""
        out: np.ndarray = ~self.agent_places(len(ts.places))[ts.place[ts.dst]]
        return out

    def occupiable_states(self) -> np.ndarray:
        """``bool[n_states]``: agent states the agent can be in at a turn of the system.

        The start if the system moves first, else the states after the agent's first
        move; then everything reachable from those along ``T_TA``.
        """
        src, dst = self.moves[:, 0], self.moves[:, 1]
        first = dst[src == self.start] if self.first == "agent" else np.array([self.start])
        seen = np.zeros(self.n_states, dtype=bool)
        seen[first] = True
        frontier = np.unique(first)
        while frontier.size:
            nxt = np.unique(dst[np.isin(src, frontier)])
            nxt = nxt[~seen[nxt]]
            seen[nxt] = True
            frontier = nxt
        return seen

    def to_dict(self, ts: TransitionSystem) -> dict[str, Any]:
        """Plain data for pictures and the artifact: cells as written in the problem."""
        return {
            "cells": [place_json(ts, int(p)) for p in self.cells],
            "parks": [{"name": p.name, "from": [place_json(ts, int(self.cells[a])) for a in p.entries]} for p in self.parks],
            "start": self.names[self.start],
            "first": self.first,
            "names": list(self.names),
            "moves": self.moves.tolist(),
        }


def place_json(ts: TransitionSystem, place: int) -> object:
    """A place of ``T`` as in problem files: ``[row, col]`` for a cell, else the name."""
    p = ts.places[place]
    return list(p) if isinstance(p, tuple) else p


def place_name(ts: TransitionSystem, place: int) -> str:
    """A place of ``T`` for messages and agent state names: ``"(r, c)"`` for a cell, else the name."""
    p = ts.places[place]
    if isinstance(p, tuple):
        return "(" + ", ".join(str(x) for x in p) + ")"
    return str(p)


def places_of_cells(ts: TransitionSystem, cells: Iterable[Any], where: str = "test agent") -> list[int]:
    """Place indices of cells (``(row, col)`` tuples on grids, state names on graphs).

    Raises
    ------
    ProblemError
        If a cell is not a place of the system (blocked or outside the grid).
    """
    index = {p: i for i, p in enumerate(ts.places)}
    out: list[int] = []
    for c in cells:
        key = tuple(c) if isinstance(c, list) else c
        if key not in index:
            shown = list(key) if isinstance(key, tuple) else repr(key)
            raise ProblemError(f"{where}: {shown} is not a free cell of the system")
        out.append(index[key])
    return out


def make_test_agent(
    ts: TransitionSystem,
    cells: Sequence[int],
    start: int | str,
    parks: Sequence[tuple[str, Sequence[int]]],
    moves: str | Sequence[tuple[int, int]] = "4-neighbour",
    stay: bool | Sequence[int] = True,
    first: str = "system",
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    where: str = "test agent",
) -> TestAgent:
    """Build and validate a test agent over the places of ``ts``.

    Parameters
    ----------
    ts
        The system's transition system (the agent lives on its places).
    cells
        Places (indices into ``ts.places``) the agent may occupy; duplicates are merged.
    start
        The start: a place among ``cells``, or the name of a park.
    parks
        ``(name, entry places)``: each park is reachable from its entry places, absorbing.
    moves
        ``"4-neighbour"`` (grid cells at distance one), ``"system"`` (the moves of ``T``
        between agent places), or an explicit list of ``(place, place)`` moves.
    stay
        Whether the agent may stay in a cell: everywhere, nowhere, or on the listed places.
    first
        ``"system"`` or ``"agent"``: who moves first.
    max_iterations
        Bound on the counterexample-guided loop.
    where
        Where the agent was defined, for error messages.

    Raises
    ------
    ProblemError
        On an empty cell list, a start outside the cells or on the system's start, a
        duplicate or empty park name, a park or move endpoint outside the cells, an
        unknown move rule or first player, or a bad iteration bound.
    """
    cell_list = list(dict.fromkeys(int(c) for c in cells))
    if not cell_list:
        raise ProblemError(f"{where}: `cells` is empty; the test agent needs at least one cell")
    state_of = {p: i for i, p in enumerate(cell_list)}
    names = [place_name(ts, p) for p in cell_list]
    park_list: list[Park] = []
    seen_names: set[str] = set()
    for name, entries in parks:
        if not isinstance(name, str) or not name:
            raise ProblemError(f"{where}: every park needs a non-empty `name`")
        if name in seen_names or name in names:
            raise ProblemError(f"{where}: park name {name!r} is used twice")
        seen_names.add(name)
        ent: list[int] = []
        for p in entries:
            if int(p) not in state_of:
                raise ProblemError(f"{where}: park {name!r} is reached from {place_name(ts, int(p))}, which is not an agent cell")
            ent.append(state_of[int(p)])
        if not ent:
            raise ProblemError(f"{where}: park {name!r} has no cell it is reached `from`")
        park_list.append(Park(name, tuple(dict.fromkeys(ent))))
        names.append(name)
    if first not in FIRST_PLAYERS:
        raise ProblemError(f"{where}: `first` must be one of {', '.join(map(repr, FIRST_PLAYERS))}, got {first!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or max_iterations < 1:
        raise ProblemError(f"{where}: `max_iterations` must be a positive integer, got {max_iterations!r}")
    # the start
    if isinstance(start, str):
        if start not in seen_names:
            raise ProblemError(f"{where}: the start {start!r} is not a park")
        start_state = len(cell_list) + [p.name for p in park_list].index(start)
    else:
        if int(start) not in state_of:
            raise ProblemError(f"{where}: the start {place_name(ts, int(start))} is not an agent cell")
        start_state = state_of[int(start)]
        if int(start) == int(ts.place[ts.initial]):
            raise ProblemError(f"{where}: the agent starts on the system's start {place_name(ts, int(start))}; they would collide")
    # moves between cells
    pairs: set[tuple[int, int]] = set()
    if isinstance(moves, str):
        if moves not in MOVE_RULES:
            raise ProblemError(f"{where}: unknown `moves` rule {moves!r}; expected one of {', '.join(MOVE_RULES)} or a list of [from, to] moves")
        if moves == "4-neighbour":
            grid_cells = [ts.places[p] for p in cell_list]
            if not all(isinstance(cell, tuple) and len(cell) == 2 for cell in grid_cells):
                raise ProblemError(f'{where}: `moves = "4-neighbour"` needs a grid; use "system" or a list of moves')
            for i, (r, c) in enumerate(cast(list[Cell], grid_cells)):
                for j, (r2, c2) in enumerate(cast(list[Cell], grid_cells)):
                    if abs(r - r2) + abs(c - c2) == 1:
                        pairs.add((i, j))
        else:
            agent_place = np.zeros(len(ts.places), dtype=bool)
            agent_place[cell_list] = True
            a, b = ts.place[ts.src], ts.place[ts.dst]
            for u, v in zip(a.tolist(), b.tolist(), strict=True):
                if u != v and agent_place[u] and agent_place[v]:
                    pairs.add((state_of[u], state_of[v]))
    else:
        for item in moves:
            u, v = (int(x) for x in item)
            for p in (u, v):
                if p not in state_of:
                    raise ProblemError(f"{where}: the move [{place_name(ts, u)}, {place_name(ts, v)}] leaves the agent's cells")
            if u != v:
                pairs.add((state_of[u], state_of[v]))
    stay_states: list[int] = []
    if isinstance(stay, bool):
        stay_states = list(range(len(cell_list))) if stay else []
    else:
        for p in stay:
            if int(p) not in state_of:
                raise ProblemError(f"{where}: `stay` lists {place_name(ts, int(p))}, which is not an agent cell")
            stay_states.append(state_of[int(p)])
    pairs.update((a, a) for a in stay_states)
    for k, park in enumerate(park_list):
        ps = len(cell_list) + k
        pairs.update((a, ps) for a in park.entries)
        pairs.add((ps, ps))
    move_arr = np.array(sorted(pairs), dtype=np.int32).reshape(-1, 2)
    return TestAgent(
        cells=np.array(cell_list, dtype=np.int32),
        parks=park_list,
        start=start_state,
        moves=move_arr,
        first=first,
        names=names,
        max_iterations=max_iterations,
    )
