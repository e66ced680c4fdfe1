"""A dynamic test agent (method.md §7): its transition system, its controller, and the
counterexample-guided synthesis loop that turns a routing cut set into an agent strategy.

The pieces, in the order :func:`synthesize_agent_test` uses them:

* :class:`TestAgent` — the agent's transition system ``T_TA`` over the *places* of ``T``
  (cells; on a fuel grid the agent occupies a cell, i.e. every fuel level of it), plus
  *park* states outside ``T`` from which it blocks nothing. Built from a problem file's
  ``[environment.agent]`` table (:func:`agent_from_toml`) or in Python
  (:func:`make_test_agent`, used by the built-ins ``maze1``, ``maze2``, ``patrolling``).
* **MILP-agent**: the routing MILP of :mod:`synthesis.routing.milp` in mode ``"mixed"`` with the
  static area ``E_static = {(u, v) in T.E : v not an agent cell}``, the blocked-state
  penalties (``block_states``) and the exclusion rows of rejected cut sets.
* the **test-agent game** of :mod:`synthesis.agent.game`, a GR(1) game solved with
  :mod:`synthesis.agent.gr1`;
* the **counterexample-guided loop**: a cut set the agent cannot realize is excluded
  (``sum_{e in C} d_e <= |C| - 1``) and the MILP solved again;
* **closed-loop verification** (:func:`verify_closed_loop`), independent of the solver;
* :class:`AgentController` — the strategy as an O(1) look-up table, stored in the test
  artifact and stepped by the environments.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence

import numpy as np

from ..model.errors import CheckFailed, InconsistentProblem, ProblemError
from ..model.systems import TransitionSystem

if TYPE_CHECKING:  # imported lazily at run time: pipeline and problems import this module
    from ..graphs.products import Products
    from ..model.strategy import TestStrategy
    from ..pipeline import SynthesisOptions, SynthesizedTest
    from ..problems.problem import Problem
    from .game import AgentGame
    from .gr1 import GR1Strategy

FIRST_PLAYERS = ("system", "agent")
MOVE_RULES = ("4-neighbour", "system")
DEFAULT_MAX_ITERATIONS = 100


# ------------------------------------------------------------------ the test agent


@dataclass(frozen=True)
class Park:
    """A park state of the test agent: outside ``T``, absorbing, reached from ``entries``.

    ``entries`` are agent *cell states* (indices into :attr:`TestAgent.cells`).
    """

    name: str
    entries: tuple[int, ...]


@dataclass
class TestAgent:
    """The test agent's transition system ``T_TA`` (method.md §7).

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
        return ~self.agent_places(len(ts.places))[ts.place[ts.dst]]

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

    def to_dict(self, ts: TransitionSystem) -> dict:
        """Plain data for pictures and the artifact: cells as written in the problem."""
        return {
            "cells": [_place_json(ts, int(p)) for p in self.cells],
            "parks": [
                {"name": p.name, "from": [_place_json(ts, int(self.cells[a])) for a in p.entries]} for p in self.parks
            ],
            "start": self.names[self.start],
            "first": self.first,
            "names": list(self.names),
            "moves": self.moves.tolist(),
        }


def _place_json(ts: TransitionSystem, place: int) -> object:
    """A place of ``T`` as in problem files: ``[row, col]`` for a cell, else the name."""
    p = ts.places[place]
    return list(p) if isinstance(p, tuple) else p


def _place_name(ts: TransitionSystem, place: int) -> str:
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
    names = [_place_name(ts, p) for p in cell_list]
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
                raise ProblemError(
                    f"{where}: park {name!r} is reached from {_place_name(ts, int(p))}, which is not an agent cell"
                )
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
            raise ProblemError(f"{where}: the start {_place_name(ts, int(start))} is not an agent cell")
        start_state = state_of[int(start)]
        if int(start) == int(ts.place[ts.initial]):
            raise ProblemError(
                f"{where}: the agent starts on the system's start {_place_name(ts, int(start))}; they would collide"
            )
    # moves between cells
    pairs: set[tuple[int, int]] = set()
    if isinstance(moves, str):
        if moves not in MOVE_RULES:
            raise ProblemError(f"{where}: unknown `moves` rule {moves!r}; expected one of {', '.join(MOVE_RULES)} or a list of [from, to] moves")
        if moves == "4-neighbour":
            if not all(isinstance(ts.places[p], tuple) and len(ts.places[p]) == 2 for p in cell_list):
                raise ProblemError(f"{where}: `moves = \"4-neighbour\"` needs a grid; use \"system\" or a list of moves")
            for i, p in enumerate(cell_list):
                r, c = ts.places[p]
                for j, p2 in enumerate(cell_list):
                    r2, c2 = ts.places[p2]
                    if abs(r - r2) + abs(c - c2) == 1:
                        pairs.add((i, j))
        else:
            agent_place = np.zeros(len(ts.places), dtype=bool)
            agent_place[cell_list] = True
            a, b = ts.place[ts.src], ts.place[ts.dst]
            for u, v in zip(a.tolist(), b.tolist()):
                if u != v and agent_place[u] and agent_place[v]:
                    pairs.add((state_of[u], state_of[v]))
    else:
        for item in moves:
            u, v = (int(x) for x in item)
            for p in (u, v):
                if p not in state_of:
                    raise ProblemError(f"{where}: the move [{_place_name(ts, u)}, {_place_name(ts, v)}] leaves the agent's cells")
            if u != v:
                pairs.add((state_of[u], state_of[v]))
    if isinstance(stay, bool):
        stay_states = range(len(cell_list)) if stay else range(0)
    else:
        stay_states = []
        for p in stay:
            if int(p) not in state_of:
                raise ProblemError(f"{where}: `stay` lists {_place_name(ts, int(p))}, which is not an agent cell")
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


_AGENT_KEYS = {"cells", "start", "parks", "moves", "stay", "first", "max_iterations"}
_PARK_KEYS = {"name", "from"}


def agent_from_toml(
    table: Any, ts: TransitionSystem, cell_of: Callable[[Any, str], list[int]], where: str
) -> TestAgent:
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
        raise ProblemError(f"{where} moves must be \"4-neighbour\", \"system\" or a list of [from, to] moves")
    stay_spec = table.get("stay", True)
    stay: bool | list[int]
    if isinstance(stay_spec, bool):
        stay = stay_spec
    else:
        stay = places(stay_spec, f"{where} stay")
    first = table.get("first", "system")
    if not isinstance(first, str):
        raise ProblemError(f"{where} first must be \"system\" or \"agent\"")
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


# ------------------------------------------------------------------ the controller

CONTROLLER_FORMAT = "flowtest.agent-controller"
CONTROLLER_VERSION = 1


@dataclass
class AgentController:
    """The synthesized test agent as an O(1) look-up table, for environments.

    Protocol: ``agent_state, memory = reset()`` before anyone moved. If
    :attr:`first` is ``"agent"``, call ``respond(agent_state, memory, s0, h0)`` once
    right away with the system's initial state and history: it returns the agent's
    first move. Then, every time the system under test has entered ``sys_state``
    (history ``history``, index into the specification product's states, i.e. the
    artifact's ``histories`` automaton), ``respond`` returns the agent's move and the
    new memory.

    Attributes
    ----------
    agent_places
        Per agent state: the system place (index into ``ts.places``) it occupies, ``None``
        for a park.
    agent_names
        Per agent state: ``"(r, c)"`` or the park's name.
    first
        ``"agent"`` or ``"system"``: who moves first.
    initial_agent, initial_memory
        The agent state and strategy memory at the start.
    n_hist
        Number of histories.
    node_of
        ``int32[n_system_states * n_hist]``: the row of ``(sys_state, history)`` in the
        tables (``sys_state * n_hist + history``), -1 if the table has none.
    next_agent, next_memory
        ``int32[n_memory, n_rows, n_agent]``: the answer, -1 where undefined.
    fallback
        ``int32[n_agent, n_places]``: the move used outside the table (after the test
        ended, or for a configuration the rules of the game never produce): stay if
        allowed, else the first move that avoids the system's place.
    sys_place
        ``int32[n_system_states]``: the place of each system state.
    """

    agent_places: list[int | None]
    agent_names: list[str]
    first: str
    initial_agent: int
    initial_memory: int
    n_hist: int
    node_of: np.ndarray
    next_agent: np.ndarray
    next_memory: np.ndarray
    fallback: np.ndarray
    sys_place: np.ndarray

    @property
    def n_memory(self) -> int:
        return int(self.next_agent.shape[0])

    @property
    def n_entries(self) -> int:
        """Number of defined table entries."""
        return int(np.count_nonzero(self.next_agent >= 0))

    def reset(self) -> tuple[int, int]:
        """``(agent_state, memory)`` at the start, before anyone moved."""
        return self.initial_agent, self.initial_memory

    def respond(self, agent_state: int, memory: int, sys_state: int, history: int) -> tuple[int, int]:
        """The agent's move after the system entered ``sys_state`` with ``history``.

        Returns ``(next_agent_state, next_memory)``; table look-ups only.
        """
        row = int(self.node_of[sys_state * self.n_hist + history])
        if row >= 0:
            a = int(self.next_agent[memory, row, agent_state])
            if a >= 0:
                return a, int(self.next_memory[memory, row, agent_state])
        return int(self.fallback[agent_state, self.sys_place[sys_state]]), memory

    def lookup(self, memory: np.ndarray, sys_state: np.ndarray, history: np.ndarray, agent_state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vectorised table look-up without fallback: ``(-1, -1)`` where the table has no entry."""
        row = self.node_of[sys_state.astype(np.int64) * self.n_hist + history]
        ok = row >= 0
        a = np.full(row.size, -1, dtype=np.int64)
        m = np.full(row.size, -1, dtype=np.int64)
        a[ok] = self.next_agent[memory[ok], row[ok], agent_state[ok]]
        m[ok] = self.next_memory[memory[ok], row[ok], agent_state[ok]]
        return a, m

    def restricted(self, memory: np.ndarray, rows: np.ndarray, agents: np.ndarray) -> "AgentController":
        """A copy whose table keeps only the entries ``(memory, row, agent)`` listed."""
        na = np.full_like(self.next_agent, -1)
        nm = np.full_like(self.next_memory, -1)
        na[memory, rows, agents] = self.next_agent[memory, rows, agents]
        nm[memory, rows, agents] = self.next_memory[memory, rows, agents]
        return replace(self, next_agent=na, next_memory=nm)

    def to_dict(self) -> dict:
        """Compact plain data: only defined entries, over the rows they use."""
        mem, row, agt = np.nonzero(self.next_agent >= 0)
        used, row_new = np.unique(row, return_inverse=True)
        n_sys = self.node_of.size // max(self.n_hist, 1)
        keys = np.flatnonzero(self.node_of >= 0)
        key_of_row = np.full(int(self.node_of.max()) + 1 if keys.size else 0, -1, dtype=np.int64)
        key_of_row[self.node_of[keys]] = keys
        k = key_of_row[used]
        return {
            "format": CONTROLLER_FORMAT,
            "version": CONTROLLER_VERSION,
            "first": self.first,
            "agent_places": list(self.agent_places),
            "agent_names": list(self.agent_names),
            "initial_agent": self.initial_agent,
            "initial_memory": self.initial_memory,
            "n_memory": self.n_memory,
            "n_hist": self.n_hist,
            "n_system_states": int(n_sys),
            "rows": np.stack([k // self.n_hist, k % self.n_hist], axis=1).tolist(),
            "table": {
                "memory": mem.tolist(),
                "row": row_new.ravel().tolist(),
                "agent": agt.tolist(),
                "next_agent": self.next_agent[mem, row, agt].tolist(),
                "next_memory": self.next_memory[mem, row, agt].tolist(),
            },
            "fallback": self.fallback.tolist(),
            "sys_place": self.sys_place.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "AgentController":
        """Rebuild a controller written by :meth:`to_dict`.

        Raises
        ------
        ValueError
            If the format tag or version does not match.
        """
        if d.get("format") != CONTROLLER_FORMAT or d.get("version") != CONTROLLER_VERSION:
            raise ValueError(
                f"not a {CONTROLLER_FORMAT} v{CONTROLLER_VERSION} document: "
                f"format={d.get('format')!r}, version={d.get('version')!r}"
            )
        n_hist, n_sys = int(d["n_hist"]), int(d["n_system_states"])
        n_agent, n_mem = len(d["agent_names"]), int(d["n_memory"])
        rows = np.asarray(d["rows"], dtype=np.int64).reshape(-1, 2)
        node_of = np.full(n_sys * n_hist, -1, dtype=np.int32)
        node_of[rows[:, 0] * n_hist + rows[:, 1]] = np.arange(rows.shape[0], dtype=np.int32)
        t = d["table"]
        na = np.full((n_mem, rows.shape[0], n_agent), -1, dtype=np.int32)
        nm = np.full_like(na, -1)
        idx = (np.asarray(t["memory"], dtype=np.int64), np.asarray(t["row"], dtype=np.int64), np.asarray(t["agent"], dtype=np.int64))
        na[idx] = np.asarray(t["next_agent"], dtype=np.int32)
        nm[idx] = np.asarray(t["next_memory"], dtype=np.int32)
        return cls(
            agent_places=[None if p is None else int(p) for p in d["agent_places"]],
            agent_names=list(d["agent_names"]),
            first=d["first"],
            initial_agent=int(d["initial_agent"]),
            initial_memory=int(d["initial_memory"]),
            n_hist=n_hist,
            node_of=node_of,
            next_agent=na,
            next_memory=nm,
            fallback=np.asarray(d["fallback"], dtype=np.int32).reshape(n_agent, -1),
            sys_place=np.asarray(d["sys_place"], dtype=np.int32),
        )


def _fallback_table(agent: TestAgent, n_places: int) -> np.ndarray:
    """``int32[n_agent, n_places]``: stay if allowed and clear of the system, else the
    first move clear of the system's place, else stay put."""
    places = agent.place_of_state
    moves = agent.move_matrix()
    out = np.empty((agent.n_states, n_places), dtype=np.int32)
    for a in range(agent.n_states):
        succ = [a] if moves[a, a] else []
        succ += [int(b) for b in np.flatnonzero(moves[a]) if b != a]
        for p in range(n_places):
            clear = [b for b in succ if places[b] != p]
            out[a, p] = clear[0] if clear else a
    return out


def controller_from_strategy(
    products: Products, game: AgentGame, strategy: GR1Strategy, agent: TestAgent
) -> AgentController:
    """Tabulate a winning GR(1) strategy of the test-agent game per configuration.

    The game is a safety game, so every winning answer of a configuration ``(v', a)``
    is good whichever position the system came from: the table is keyed by the
    configuration (and the strategy memory), not by the game's choice, which makes the
    environment's look-up independent of the previous state. The closed-loop check
    (:func:`verify_closed_loop`) confirms the table, not the solver.
    """
    g, ts = products.virtual, products.ts
    n, n_agent, n_mem = g.n_nodes, agent.n_states, strategy.n_memory
    next_agent = np.full((n_mem, n, n_agent), -1, dtype=np.int32)
    next_memory = np.full_like(next_agent, -1)
    for m in range(n_mem):
        defined = np.flatnonzero(strategy.next_position[m] >= 0)
        cfg = game.choice_config[defined]
        cfg, first = np.unique(cfg, return_index=True)
        pick = defined[first]
        pos = strategy.next_position[m, pick]
        next_agent[m, cfg // n_agent, cfg % n_agent] = game.position_agent[pos]
        next_memory[m, cfg // n_agent, cfg % n_agent] = strategy.next_memory[m, pick]
    if agent.first == "agent":
        pos = int(strategy.initial[0])
        next_agent[strategy.initial_memory, g.initial, agent.start] = game.position_agent[pos]
        next_memory[strategy.initial_memory, g.initial, agent.start] = strategy.initial_memory
    node_of = np.full(ts.n_states * g.n_hist, -1, dtype=np.int32)
    node_of[g.state.astype(np.int64) * g.n_hist + g.hist] = np.arange(n, dtype=np.int32)
    places = agent.place_of_state
    return AgentController(
        agent_places=[None if p < 0 else int(p) for p in places],
        agent_names=list(agent.names),
        first=agent.first,
        initial_agent=int(agent.start),
        initial_memory=int(strategy.initial_memory),
        n_hist=int(g.n_hist),
        node_of=node_of,
        next_agent=next_agent,
        next_memory=next_memory,
        fallback=_fallback_table(agent, len(ts.places)),
        sys_place=ts.place.astype(np.int32),
    )


# ------------------------------------------------------- closed-loop verification


@dataclass
class ClosedLoopReport:
    """What the exhaustive closed-loop exploration saw.

    ``positions``: reachable configurations at the system's turn; ``transitions``: their
    successors over every system behaviour; ``goal_positions``: those with the system at
    its goal; ``entries``: the table entries ``(memory, row, agent)`` the loop used.
    """

    positions: int
    transitions: int
    goal_positions: int
    entries: tuple[np.ndarray, np.ndarray, np.ndarray]


def verify_closed_loop(
    products: Products, strategy: TestStrategy, agent: TestAgent, controller: AgentController
) -> ClosedLoopReport:
    """Explore the test under the controller against every system behaviour.

    Independent of the GR(1) solver: it reads only G, the routing strategy, the agent's
    moves and the controller's table. The system may take any move of G that is not a
    static obstacle and does not enter the agent's place, or stay; the agent answers
    with the controller. Checks, at every reachable configuration:

    * the agent never collides with the system and moves along ``T_TA``;
    * at the system's turn the blocked moves out of its state are exactly
      ``R(q) ∩ out(s)`` plus the static obstacles (no more, no less);
    * g8: the agent never stays at its turn in a place that blocks every path;
    * the agent never traps the system: from every reachable configuration where the
      test goes on, a configuration with the system at its goal is reachable;
    * every run that reaches the goal passed through the test objective (the last node
      before ``Tgt`` is in ``I``).

    Raises
    ------
    CheckFailed
        With the first violation found (a FlowTest bug).
    """
    from ..graphs.products import coreachable
    from .game import blocking_places, ended_nodes, reactive_restrictions

    g, ts = products.virtual, products.ts
    n, n_agent, n_mem = g.n_nodes, agent.n_states, controller.n_memory
    places = agent.place_of_state
    moves = agent.move_matrix()
    obs = strategy.static_obstacles
    reactive = reactive_restrictions(strategy)
    ended = ended_nodes(products)
    blocking = np.zeros((n, n_agent), dtype=bool)
    cells = np.flatnonzero(places >= 0)
    blocking[:, cells] = blocking_places(products, obs, places[cells])
    node_place = ts.place[g.state].astype(np.int64)
    order = np.argsort(g.src, kind="stable")
    e_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(g.src, minlength=n), out=e_ptr[1:])
    e_dst, e_move = g.dst[order].astype(np.int64), g.move[order].astype(np.int64)

    def where(v: int, a: int) -> str:
        return f"system at {ts.states[int(g.state[v])]} (history q{int(g.hist[v])}), agent at {agent.names[int(a)]}"

    def answer(m: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        na, nm = controller.lookup(m, g.state[v], g.hist[v], a)
        bad = np.flatnonzero(na < 0)
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent controller has no move for {where(int(v[k]), int(a[k]))}")
        bad = np.flatnonzero(~moves[a, na])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent moves from {agent.names[int(a[k])]} to {agent.names[int(na[k])]}, not a move of T_TA ({where(int(v[k]), int(a[k]))})")
        bad = np.flatnonzero(places[na] == node_place[v])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent collides with the system: {where(int(v[k]), int(na[k]))}")
        bad = np.flatnonzero((na == a) & blocking[v, a])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"g8 violated: the agent stays where it blocks every path ({where(int(v[k]), int(a[k]))})")
        return na, nm

    a0, m0 = controller.reset()
    v0 = np.array([g.initial], dtype=np.int64)
    used_m, used_v, used_a = [], [], []
    if controller.first == "agent":
        a_arr, m_arr = answer(np.array([m0]), v0, np.array([a0]))
        used_m.append(np.array([m0])), used_v.append(v0), used_a.append(np.array([a0]))
    else:
        a_arr, m_arr = np.array([a0]), np.array([m0])
    key = lambda v, a, m: (v * n_agent + a) * n_mem + m  # noqa: E731
    visited = np.zeros(n * n_agent * n_mem, dtype=bool)
    frontier = np.unique(key(v0, a_arr, m_arr))
    visited[frontier] = True
    srcs: list[np.ndarray] = []
    dsts: list[np.ndarray] = []
    while frontier.size:
        m = frontier % n_mem
        a = (frontier // n_mem) % n_agent
        v = frontier // (n_mem * n_agent)
        bad = np.flatnonzero(places[a] == node_place[v])
        if bad.size:
            k = int(bad[0])
            raise CheckFailed(f"agent collides with the system: {where(int(v[k]), int(a[k]))}")
        go = ~ended[v]
        fk, m, a, v = frontier[go], m[go], a[go], v[go]
        # the system's view: the moves blocked out of its state
        starts, lens = e_ptr[v], e_ptr[v + 1] - e_ptr[v]
        total = int(lens.sum())
        row = np.repeat(np.arange(v.size), lens)
        idx = np.repeat(starts - (np.cumsum(lens) - lens), lens) + np.arange(total)
        mv, dst = e_move[idx], e_dst[idx]
        blocked = obs[mv] | (node_place[dst] == places[a[row]])
        expected = obs[mv] | reactive[g.hist[v[row]], mv]
        bad = np.flatnonzero(blocked != expected)
        if bad.size:
            k = int(bad[0])
            what = "blocks a move the test does not restrict" if blocked[k] else "leaves open a move the test restricts"
            raise CheckFailed(
                f"the agent {what}: {ts.states[int(ts.src[mv[k]])]} -> {ts.states[int(ts.dst[mv[k]])]} ({where(int(v[row[k]]), int(a[row[k]]))})"
            )
        # every system behaviour: unblocked moves and stays
        open_ = ~blocked
        stay = np.flatnonzero(ts.stay[g.state[v]])
        s_row = np.concatenate([row[open_], stay])
        s_dst = np.concatenate([dst[open_], v[stay]])
        na, nm = answer(m[s_row], s_dst, a[s_row])
        used_m.append(m[s_row]), used_v.append(s_dst), used_a.append(a[s_row])
        nxt = key(s_dst, na, nm)
        srcs.append(fk[s_row])
        dsts.append(nxt)
        new = np.unique(nxt[~visited[nxt]])
        visited[new] = True
        frontier = new
    states = np.flatnonzero(visited)
    src = np.searchsorted(states, np.concatenate(srcs)) if srcs else np.zeros(0, dtype=np.int64)
    dst = np.searchsorted(states, np.concatenate(dsts)) if dsts else np.zeros(0, dtype=np.int64)
    s_node = states // (n_mem * n_agent)
    goal = products.target[s_node]
    alive = coreachable(states.size, src, dst, goal)
    trapped = np.flatnonzero(~ended[s_node] & ~alive)
    if trapped.size:
        k = int(states[trapped[0]])
        raise CheckFailed(
            f"the test traps the system: no way to the goal from {where(k // (n_mem * n_agent), (k // n_mem) % n_agent)}"
        )
    into_goal = goal[dst] & ~goal[src]
    bypass = np.flatnonzero(into_goal & ~products.intermediate[s_node[src]])
    if bypass.size:
        k = int(states[src[bypass[0]]])
        raise CheckFailed(
            f"a run reaches the goal without the test objective, from {where(k // (n_mem * n_agent), (k // n_mem) % n_agent)}"
        )
    entries = tuple(np.concatenate(x) if x else np.zeros(0, dtype=np.int64) for x in (used_m, used_v, used_a))
    return ClosedLoopReport(
        positions=int(states.size), transitions=int(src.size), goal_positions=int(goal.sum()), entries=entries
    )


# ------------------------------------------------------ the counterexample-guided loop


@dataclass
class AgentSynthesis:
    """The synthesized test agent of an agent problem (``SynthesizedTest.agent``).

    Attributes
    ----------
    agent
        The test agent.
    controller
        Its strategy as a look-up table (restricted to the configurations the closed
        loop reaches).
    system
        The system's transition system (to write cells in outputs).
    counterexamples
        Cut sets rejected by the loop (MILP solves minus one).
    iterations
        One record per MILP solve: flow, cuts, blocked places, verdict, seconds.
    game_size
        Positions, choices, moves and configurations of the final game.
    closed_loop
        What the closed-loop verification explored.
    timings
        Seconds: ``graphs``, ``milp`` (every solve), ``game`` (every build),
        ``gr1`` (every solve), ``verify`` (closed loop, GR(1) check, routing checks),
        ``total``.
    """

    agent: TestAgent
    controller: AgentController
    system: TransitionSystem
    counterexamples: int
    iterations: list[dict]
    game_size: dict[str, int]
    closed_loop: ClosedLoopReport
    timings: dict[str, float]

    def summary(self) -> dict:
        """The agent's part of ``flowtest synthesize --json``."""
        return {
            "counterexamples": self.counterexamples,
            "agent_strategy": {
                "agent_states": self.agent.n_states,
                "first": self.agent.first,
                "iterations": len(self.iterations),
                "game": dict(self.game_size),
                "memory": self.controller.n_memory,
                "table_entries": self.controller.n_entries,
                "closed_loop_positions": self.closed_loop.positions,
                "gr1_seconds": self.timings["gr1"],
                "milp_seconds": self.timings["milp"],
                "total_seconds": self.timings["total"],
                "rejected": [
                    {"iteration": r["iteration"], "reason": r["verdict"]} for r in self.iterations if r["verdict"] != "realizable"
                ],
            },
        }

    def to_dict(self) -> dict:
        """``artifact["agent"]``: the controller plus the agent's cells and parks for drawing."""
        return {
            "controller": self.controller.to_dict(),
            **self.agent.to_dict(self.system),
            "counterexamples": self.counterexamples,
        }


def _restrictable_for_agent(ts: TransitionSystem, agent: TestAgent, static: np.ndarray) -> np.ndarray:
    """The harness for MILP-agent: a reactive move into a place the agent can never
    occupy at a turn of the system cannot be restricted (g6 would need the agent there),
    so it is fixed uncut. This only prunes cut sets the game would reject; static moves
    keep their harness."""
    reach = agent.occupiable_states() & (agent.place_of_state >= 0)
    reach_place = np.zeros(len(ts.places), dtype=bool)
    reach_place[agent.place_of_state[reach]] = True
    return ts.restrictable & (static | reach_place[ts.place[ts.dst]])


def _rejected_text(iterations: list[dict], shown: int = 4) -> str:
    """Which restrictions the test agent could not realize: the places each rejected cut
    set needed it to block, and why (it could not be there in time, or the cuts trap the
    system), the last ``shown`` of them."""
    parts = []
    for rec in iterations[-shown:]:
        places = ", ".join(json.dumps(p, separators=(",", ":")) for p in rec["blocked_places"]) or "none"
        why = ("the agent cannot reach them in time" if rec.get("verdict") == "unrealizable"
               else rec.get("verdict", "rejected"))
        parts.append(f"cut set {rec['iteration']} blocks places {places}: {why}")
    more = f" (and {len(iterations) - shown} earlier)" if len(iterations) > shown else ""
    return "rejected" + more + ": " + "; ".join(parts)


def synthesize_agent_test(
    problem: Problem,
    options: SynthesisOptions | None = None,
    max_iterations: int | None = None,
    prefilter: bool = True,
) -> SynthesizedTest:
    """Synthesize a test agent strategy for an agent problem (method.md §7).

    The loop: exclude what no agent can realize (a move into a place the agent can
    never occupy at the system's turn is unrestrictable; cuts it could never hold are
    excluded); solve MILP-agent; reject the cut set if it traps the system somewhere
    reachable (:func:`~synthesis.agent.game.trapped_nodes`); build the test-agent game
    from ``R(q)`` and ``Obs`` and solve it; if the agent cannot win, exclude the cut set
    (``sum_{e in C} d_e <= |C| - 1``) and solve again. The winning strategy is tabulated
    (:class:`AgentController`) and checked in closed loop (:func:`verify_closed_loop`),
    by :func:`synthesis.agent.gr1.verify_strategy` and by the routing checks of
    :mod:`synthesis.checks.verify`.

    Parameters
    ----------
    problem
        A problem of kind ``"agent"`` with ``problem.agent`` a :class:`TestAgent`.
    options
        :class:`synthesis.pipeline.SynthesisOptions` (time limit, gap, threads, progress).
    max_iterations
        Bound on MILP solves; default: ``options.agent_iterations`` if set, else the
        agent's ``max_iterations`` (100 unless the problem says otherwise).
    prefilter
        Exclude, before the first solve, the cuts no agent can hold
        (:func:`~synthesis.agent.game.realizability_exclusions`); this never changes the
        optimum, only which equally good cut set is tried first and how many solves the
        loop needs.

    Returns
    -------
    synthesis.pipeline.SynthesizedTest
        With ``agent`` an :class:`AgentSynthesis`.

    Raises
    ------
    ProblemError
        If the problem has no test agent.
    InconsistentProblem
        ``unreachable``/``unroutable`` when the first MILP says so; ``infeasible`` when no
        cut set remains after counterexamples, or the iteration bound is reached.
    CheckFailed
        If the result fails an independent check (a FlowTest bug).
    """
    from ..checks.verify import check_test
    from ..pipeline import SynthesisOptions, SynthesizedTest, build_graphs, milp_options, strategy_from_routing
    from ..routing.milp import cut_groups, solve_routing
    from . import gr1
    from .game import build_agent_game, realizability_exclusions, trapped_nodes

    options = options or SynthesisOptions()
    note: Callable[[str], None] = options.progress or (lambda msg: None)
    agent = problem.agent
    if not isinstance(agent, TestAgent):
        raise ProblemError(f"problem {problem.name!r} is an agent problem without a test agent; add [environment.agent]")
    bound = max_iterations or options.agent_iterations or agent.max_iterations
    t_start = time.perf_counter()
    timings = {"graphs": 0.0, "milp": 0.0, "game": 0.0, "gr1": 0.0, "verify": 0.0, "total": 0.0}
    note("building automata and product graphs")
    spec, products = build_graphs(problem)
    timings["graphs"] = time.perf_counter() - t_start
    ts = products.ts
    mopts = milp_options(problem, options)
    static = problem.static_moves if problem.static_moves is not None else agent.static_moves(ts)
    mopts.mode, mopts.static_moves, mopts.block_states = "mixed", static, True
    harness = _restrictable_for_agent(ts, agent, static)
    pruned = bool(np.any(ts.restrictable & ~harness))
    milp_products = replace(products, ts=replace(ts, restrictable=harness))
    if prefilter:
        necessary = realizability_exclusions(milp_products, agent, cut_groups(milp_products, mopts))
        mopts.exclusions.extend(necessary)
        pruned = pruned or bool(necessary)
    setting = options.setting or problem.extras.get("setting", "instantaneous")
    iterations: list[dict] = []
    for it in range(1, bound + 1):
        t = time.perf_counter()
        try:
            routing = solve_routing(milp_products, mopts)
        except InconsistentProblem as exc:
            if it == 1 and (exc.reason != "unroutable" or not pruned):
                raise
            if it == 1:
                raise InconsistentProblem(
                    "infeasible",
                    "no test agent strategy exists: no routing cut set restricts only moves into places the "
                    f"test agent can occupy ({exc})",
                ) from None
            raise InconsistentProblem(
                "infeasible",
                f"no test agent strategy exists: after {it - 1} rejected cut set(s) no routing cut set "
                f"remains that the test agent could realize ({exc}); {_rejected_text(iterations)}",
            ) from None
        finally:
            timings["milp"] += time.perf_counter() - t
        strategy = strategy_from_routing(products, routing, setting)
        record: dict[str, Any] = {
            "iteration": it,
            "flow": routing.flow,
            "cuts": int(routing.cut_edges.size),
            "blocked_places": [_place_json(ts, int(p)) for p in routing.blocked_places],
            "milp_seconds": time.perf_counter() - t,
        }
        iterations.append(record)
        trapped = trapped_nodes(products, strategy)
        if trapped.size:
            v = int(trapped[0])
            record["verdict"] = f"traps the system at {ts.states[int(products.virtual.state[v])]}"
        else:
            t = time.perf_counter()
            game = build_agent_game(products, strategy, agent)
            timings["game"] += time.perf_counter() - t
            t = time.perf_counter()
            result = gr1.solve(game.game)
            record["gr1_seconds"] = time.perf_counter() - t
            timings["gr1"] += record["gr1_seconds"]
            record["positions"] = game.n_positions
            record["verdict"] = "realizable" if result.realizable else "unrealizable"
        note(
            f"agent loop {it}/{bound}: flow {routing.flow}, {routing.cut_edges.size} cuts, blocked places "
            f"{record['blocked_places']}: {record['verdict']}"
        )
        if record["verdict"] == "realizable":
            break
        mopts.exclusions.append(list(routing.cut_group_keys))
    else:
        raise InconsistentProblem(
            "infeasible",
            f"no test agent strategy found within the bound of {bound} iterations of the counterexample-guided "
            f"loop ({bound} cut sets rejected; {_rejected_text(iterations)}); raise max_iterations in "
            "[environment.agent] to search further",
        )
    t = time.perf_counter()
    note("checking the agent strategy in closed loop")
    assert result.strategy is not None
    try:
        gr1.verify_strategy(game.game, result.strategy)
    except gr1.StrategyError as exc:
        raise CheckFailed(f"the test agent's GR(1) strategy is not winning: {exc}") from None
    full = controller_from_strategy(products, game, result.strategy, agent)
    report = verify_closed_loop(products, strategy, agent, full)
    controller = full.restricted(*report.entries)
    checks = check_test(products, strategy, routing.flow, closed_loop=options.closed_loop)
    timings["verify"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_start
    solution = AgentSynthesis(
        agent=agent,
        controller=controller,
        system=ts,
        counterexamples=len(iterations) - 1,
        iterations=iterations,
        game_size=game.size(),
        closed_loop=report,
        timings=timings,
    )
    return SynthesizedTest(
        problem, spec, products, routing, strategy, checks, timings["graphs"], agent=solution,
        extra_stats={"agent_seconds": dict(timings)},
    )
