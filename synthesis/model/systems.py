"""Transition systems T = (S, A, delta, s0, AP, L): grid worlds, fuel grid worlds, graphs.

A :class:`TransitionSystem` is plain data over integer-indexed arrays. Its moves
exclude the stay self-loop (docs/method.md §2: it can never be restricted and is left
out of every flow network); ``stay[s]`` says whether a state may stay in place.
States keep a user-facing key (``(row, col)``, ``((row, col), fuel)`` or a name) in
a side table; ``place[s]`` is the location a state occupies (its cell, or itself on
a graph), which ties cuts across fuel levels and draws pictures.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from .errors import ProblemError

State = Hashable
Cell = tuple[int, int]
FuelState = tuple[Cell, int]
"""A state of a fuel grid: its cell and its fuel level."""

MOVES: dict[str, Cell] = {"N": (-1, 0), "S": (1, 0), "E": (0, 1), "W": (0, -1)}


@dataclass
class GridLayout:
    """What a picture needs of a grid: its size, blocked cells and named tokens."""

    rows: int
    cols: int
    blocked: frozenset[Cell]
    tokens: dict[Cell, str] = field(default_factory=dict)


@dataclass
class TransitionSystem:
    """A finite, deterministic transition system with labels.

    Attributes
    ----------
    kind
        ``"grid"``, ``"fuel"`` or ``"graph"``: how states are written.
    states
        State keys, by index.
    src, dst
        ``int32[m]``: the moves ``src[e] -> dst[e]`` (stay self-loops excluded).
    action
        Name of the action of each move (``N``/``S``/``E``/``W`` on grids, the
        target's name on graphs).
    stay
        ``bool[n]``: whether the state has a stay self-loop.
    initial
        Index of ``s0``.
    labels
        ``L(s)`` as a frozenset of proposition names, by state.
    terminal
        ``bool[n]``: terminal states have no outgoing moves and no stay.
    restrictable
        ``bool[m]``: the test harness ``H`` as a mask over moves.
    place, places
        ``place[s]`` indexes ``places``: the cell (grids) or the state name (graphs).
    layout
        The grid layout for pictures, ``None`` on graphs.
    """

    kind: str
    states: list[State]
    src: np.ndarray
    dst: np.ndarray
    action: list[str]
    stay: np.ndarray
    initial: int
    labels: list[frozenset[str]]
    terminal: np.ndarray
    restrictable: np.ndarray
    place: np.ndarray
    places: list[Hashable]
    layout: GridLayout | None = None
    max_fuel: int | None = None
    _index: dict[State, int] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._index = {s: i for i, s in enumerate(self.states)}

    @property
    def n_states(self) -> int:
        return len(self.states)

    @property
    def n_moves(self) -> int:
        return int(self.src.size)

    def index(self, state: State) -> int:
        return self._index[state]

    def letters(self) -> tuple[frozenset[str], ...]:
        """The distinct labels, in order of first appearance: the automata's alphabet."""
        return tuple(dict.fromkeys(self.labels))

    def letter_of_state(self, letters: Sequence[frozenset[str]]) -> np.ndarray:
        pos = {a: i for i, a in enumerate(letters)}
        return np.fromiter((pos[a] for a in self.labels), dtype=np.int32, count=self.n_states)

    def propositions(self) -> set[str]:
        return set().union(*self.labels)

    def move_index(self) -> dict[tuple[int, int], int]:
        """``(s, s') -> e`` for every move."""
        return {(int(a), int(b)): e for e, (a, b) in enumerate(zip(self.src, self.dst, strict=True))}

    def to_json_state(self, s: int) -> object:
        """State ``s`` written as in problem-format.md."""
        key = self.states[s]
        if self.kind == "grid":
            r, c = cast(Cell, key)
            return [r, c]
        if self.kind == "fuel":
            (r, c), f = cast(FuelState, key)
            return [[r, c], f]
        return key

    def to_dict(self) -> dict[str, Any]:
        """Plain data for the synthesized-test artifact."""
        return {
            "kind": self.kind,
            "states": [self.to_json_state(s) for s in range(self.n_states)],
            "moves": np.stack([self.src, self.dst], axis=1).tolist(),
            "action": list(self.action),
            "stay": self.stay.astype(int).tolist(),
            "initial": self.initial,
            "labels": [sorted(a) for a in self.labels],
            "terminal": np.flatnonzero(self.terminal).tolist(),
            "restrictable": self.restrictable.astype(int).tolist(),
            "place": self.place.tolist(),
            "places": [list(p) if isinstance(p, tuple) else p for p in self.places],
            "layout": None
            if self.layout is None
            else {
                "rows": self.layout.rows,
                "cols": self.layout.cols,
                "blocked": sorted([list(c) for c in self.layout.blocked]),
                "tokens": [[r, c, t] for (r, c), t in sorted(self.layout.tokens.items())],
            },
            "max_fuel": self.max_fuel,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TransitionSystem:
        kind = d["kind"]
        if kind == "grid":
            states: list[State] = [tuple(s) for s in d["states"]]
        elif kind == "fuel":
            states = [(tuple(s[0]), s[1]) for s in d["states"]]
        else:
            states = list(d["states"])
        moves = np.asarray(d["moves"], dtype=np.int32).reshape(-1, 2)
        n = len(states)
        terminal = np.zeros(n, dtype=bool)
        terminal[d["terminal"]] = True
        lay = d.get("layout")
        layout = None
        if lay is not None:
            layout = GridLayout(
                lay["rows"],
                lay["cols"],
                frozenset(tuple(c) for c in lay["blocked"]),
                {(r, c): t for r, c, t in lay["tokens"]},
            )
        return cls(
            kind=kind,
            states=states,
            src=moves[:, 0].copy(),
            dst=moves[:, 1].copy(),
            action=list(d["action"]),
            stay=np.asarray(d["stay"], dtype=bool),
            initial=int(d["initial"]),
            labels=[frozenset(a) for a in d["labels"]],
            terminal=terminal,
            restrictable=np.asarray(d["restrictable"], dtype=bool),
            place=np.asarray(d["place"], dtype=np.int32),
            places=[tuple(p) if isinstance(p, list) else p for p in d["places"]],
            layout=layout,
            max_fuel=d.get("max_fuel"),
        )


# ------------------------------------------------------------------- constructors


def _finish(
    kind: str,
    states: Sequence[State],
    moves: list[tuple[int, int, str]],
    initial: int,
    labels: list[frozenset[str]],
    terminal: np.ndarray,
    stay: np.ndarray,
    place_of: Callable[[State], Hashable],
    layout: GridLayout | None,
    restrictable: Callable[[int, int, str], bool] | None = None,
    max_fuel: int | None = None,
) -> TransitionSystem:
    if not terminal.any():
        raise ProblemError("the system has no terminal state: a test must be able to end (set `terminal`)")
    src = np.array([m[0] for m in moves], dtype=np.int32)
    dst = np.array([m[1] for m in moves], dtype=np.int32)
    action = [m[2] for m in moves]
    places: dict[Hashable, int] = {}
    place = np.array([places.setdefault(place_of(s), len(places)) for s in states], dtype=np.int32)
    harness = np.ones(len(moves), dtype=bool) if restrictable is None else np.array([restrictable(a, b, n) for a, b, n in moves], dtype=bool)
    stay = stay & ~terminal
    return TransitionSystem(
        kind=kind,
        states=list(states),
        src=src,
        dst=dst,
        action=action,
        stay=stay,
        initial=initial,
        labels=labels,
        terminal=terminal,
        restrictable=harness,
        place=place,
        places=list(places),
        layout=layout,
        max_fuel=max_fuel,
    )


def grid_world(
    free: Iterable[Cell],
    rows: int,
    cols: int,
    start: Cell,
    terminal: Iterable[Cell],
    labels: Mapping[Cell, Iterable[str]],
    tokens: dict[Cell, str] | None = None,
) -> TransitionSystem:
    """A grid world: moves N, S, E, W between free cells, stay on non-terminal cells.

    Raises
    ------
    ProblemError
        If the start is not a free cell, a terminal cell is not free, or there is
        no terminal cell.
    """
    cells = sorted(set(free))
    if not cells:
        raise ProblemError("the grid has no free cell")
    index = {c: i for i, c in enumerate(cells)}
    if start not in index:
        raise ProblemError(f"the start cell {list(start)} is blocked or outside the grid")
    term = np.zeros(len(cells), dtype=bool)
    for cell in terminal:
        if cell not in index:
            raise ProblemError(f"the terminal cell {list(cell)} is blocked or outside the grid")
        term[index[cell]] = True
    moves: list[tuple[int, int, str]] = []
    for i, (r, c) in enumerate(cells):
        if term[i]:
            continue
        for name, (dr, dc) in MOVES.items():
            j = index.get((r + dr, c + dc))
            if j is not None:
                moves.append((i, j, name))
    lab = [frozenset(labels.get(c, ())) for c in cells]
    blocked = frozenset((r, c) for r in range(rows) for c in range(cols)) - set(cells)
    layout = GridLayout(rows, cols, blocked, dict(tokens or {}))
    stay = np.ones(len(cells), dtype=bool)
    return _finish("grid", list(cells), moves, index[start], lab, term, stay, lambda s: s, layout)


def fuel_grid_world(
    free: Iterable[Cell],
    rows: int,
    cols: int,
    start: Cell,
    max_fuel: int,
    refuel: Iterable[Cell],
    goal: Iterable[Cell],
    label: Callable[[Cell, int], Iterable[str]],
    tokens: dict[Cell, str] | None = None,
    start_fuel: int | None = None,
) -> TransitionSystem:
    """A grid world with fuel (paper-examples.md, refueling).

    States are ``((row, col), fuel)``, built from ``((start), start_fuel)`` outward.
    A move costs one unit; staying costs nothing; at fuel 0 only staying is possible;
    entering a refuel cell refills to ``max_fuel`` (so a refuel cell exists only at
    full fuel). Goal cells are terminal at every fuel level.
    """
    cells = set(free)
    refuel_cells = set(refuel)
    goal_cells = set(goal)
    start_fuel = max_fuel if start_fuel is None else start_fuel
    if start not in cells:
        raise ProblemError(f"the start cell {list(start)} is blocked or outside the grid")
    s0 = (start, start_fuel)
    index: dict[FuelState, int] = {s0: 0}
    states: list[FuelState] = [s0]
    moves: list[tuple[int, int, str]] = []
    queue = deque([s0])
    while queue:
        s = queue.popleft()
        (r, c), f = s
        if (r, c) in goal_cells or f == 0:
            continue
        for name, (dr, dc) in MOVES.items():
            n = (r + dr, c + dc)
            if n not in cells:
                continue
            t = (n, max_fuel if n in refuel_cells else f - 1)
            j = index.get(t)
            if j is None:
                j = index[t] = len(states)
                states.append(t)
                queue.append(t)
            moves.append((index[s], j, name))
    term = np.array([s[0] in goal_cells for s in states], dtype=bool)
    lab = [frozenset(label(s[0], s[1])) for s in states]
    blocked = frozenset((r, c) for r in range(rows) for c in range(cols)) - cells
    layout = GridLayout(rows, cols, blocked, dict(tokens or {}))
    stay = np.ones(len(states), dtype=bool)
    return _finish("fuel", states, moves, 0, lab, term, stay, lambda s: cast(FuelState, s)[0], layout, max_fuel=max_fuel)


def graph_system(
    states: Sequence[str],
    edges: Iterable[tuple[str, str]],
    start: str,
    terminal: Iterable[str],
    labels: Mapping[str, Iterable[str]],
    stay: bool = True,
) -> TransitionSystem:
    """An arbitrary directed graph of named states.

    Raises
    ------
    ProblemError
        On an unknown state in ``edges``, ``start`` or ``terminal``, or a duplicate state.
    """
    names = list(states)
    if not names:
        raise ProblemError("the system has no state")
    index: dict[str, int] = {}
    for i, s in enumerate(names):
        if s in index:
            raise ProblemError(f"state {s!r} is listed twice in `states`")
        index[s] = i

    def lookup(s: str, where: str) -> int:
        if s not in index:
            raise ProblemError(f"unknown state {s!r} in {where}")
        return index[s]

    i0 = lookup(start, "`start`")
    term = np.zeros(len(names), dtype=bool)
    for s in terminal:
        term[lookup(s, "`terminal`")] = True
    moves: list[tuple[int, int, str]] = []
    seen: set[tuple[int, int]] = set()
    for a, b in edges:
        i, j = lookup(a, f"edge [{a!r}, {b!r}]"), lookup(b, f"edge [{a!r}, {b!r}]")
        if term[i]:
            raise ProblemError(f"edge [{a!r}, {b!r}] leaves the terminal state {a!r}")
        if i == j or (i, j) in seen:
            continue
        seen.add((i, j))
        moves.append((i, j, b))
    lab = [frozenset(labels.get(s, ())) for s in names]
    stay_arr = np.full(len(names), bool(stay))
    return _finish("graph", names, moves, i0, lab, term, stay_arr, lambda s: s, None)
