"""The test agent in the pictures of tests (:mod:`experiments.plots`): its cells and parks
read from whatever describes it, where each park is drawn, and labels sized to fit their
box, so no park name or cell label runs off the grid.

A park is outside the system's cells: it is drawn as a box beside the grid next to a cell it
is entered from; a name too long for its box is written as a tag (``P1``) that the picture's
legend spells out (``P1 = park elevator-lobby``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

Cell = tuple[int, int]


def _cell_of_place(ts: Any, p: int) -> Cell:
    c = ts.places[p]
    return int(c[0]), int(c[1])


@dataclass
class _Park:
    """A park of the test agent: a state outside T, entered from some places of T."""

    name: str
    entries: list[int]  # places of T the park is entered from
    cell: Cell | None = None  # where to draw it, when given explicitly (grids)


@dataclass
class _Overlay:
    """What the picture shows of a test agent: its places of T and its parks."""

    places: set[int]
    parks: list[_Park]


def _get(obj: Any, name: str) -> Any:
    if isinstance(obj, dict):
        return obj.get(name)
    return getattr(obj, name, None)


def _resolve(ts: Any, item: Any) -> tuple[int | None, Cell | None]:
    """A place of T from a place index, a ``(row, col)`` cell or a state name.

    Returns ``(place, cell)``; a cell outside T gives ``(None, cell)``.
    """
    place_index = {p: i for i, p in enumerate(ts.places)}
    if isinstance(item, (int, np.integer)) and not isinstance(item, bool):
        return (int(item), None) if 0 <= int(item) < len(ts.places) else (None, None)
    if isinstance(item, (tuple, list)) and len(item) == 2 and all(isinstance(x, (int, np.integer)) for x in item):
        cell = (int(item[0]), int(item[1]))
        return place_index.get(cell), cell
    if isinstance(item, str) and item in place_index:
        return place_index[item], None
    return None, None


def _agent_overlay(test: Any, agent: Any) -> _Overlay | None:
    """Read a duck-typed agent overlay; ``None`` when there is nothing to draw.

    ``cells`` items are places of T (indices into ``ts.places``, which are the state
    indices on grid and graph systems, as :class:`synthesis.model.agent_system.TestAgent` keeps
    them), ``(row, col)`` cells or state names. ``parks`` items are objects or
    mappings with a ``name`` and ``entries`` (indices into ``cells``) or ``from``
    (cells), or plain places/cells drawn as parks.
    """
    ts = test.problem.system
    candidates = [agent] if agent is not None else [getattr(test, "agent", None), getattr(test.problem, "agent", None)]
    for cand in candidates:
        cells = _get(cand, "cells") if cand is not None else None
        if cells is None:
            continue
        cell_places = [_resolve(ts, item)[0] for item in cells]
        places = {p for p in cell_places if p is not None}
        parks: list[_Park] = []
        for k, item in enumerate(_get(cand, "parks") or ()):
            name, entries = _get(item, "name"), _get(item, "entries")
            if name is not None or entries is not None or _get(item, "from") is not None:
                if entries is not None:
                    ent = [cell_places[int(e)] for e in entries if 0 <= int(e) < len(cell_places)]
                else:
                    ent = [_resolve(ts, c)[0] for c in _get(item, "from") or ()]
                parks.append(_Park(str(name if name is not None else f"park {k}"), [e for e in ent if e is not None]))
                continue
            place, cell = _resolve(ts, item)
            if place is not None:
                parks.append(_Park("P", [place], None if ts.layout is None else _cell_of_place(ts, place)))
            elif cell is not None:
                parks.append(_Park("P", [], cell))
        if places or parks:
            return _Overlay(places, parks)
    return None


def _park_cells(ts: Any, parks: Sequence[_Park]) -> list[tuple[_Park, Cell]]:
    """Where each park is drawn on a grid: its own cell, else beside an entry cell.

    A park beside the grid (just outside an entry cell on the border) reads as "the
    agent leaves the grid here"; failing that, a blocked neighbour; else nothing.
    """
    lay = ts.layout
    out: list[tuple[_Park, Cell]] = []
    for park in parks:
        if park.cell is not None:
            out.append((park, park.cell))
            continue
        outside: list[Cell] = []
        blocked: list[Cell] = []
        for e in park.entries:
            r, c = _cell_of_place(ts, e)
            for n in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
                if not (0 <= n[0] < lay.rows and 0 <= n[1] < lay.cols):
                    outside.append(n)
                elif n in lay.blocked:
                    blocked.append(n)
        taken = {cell for _, cell in out}
        free = [x for x in outside + blocked if x not in taken]
        if free:
            out.append((park, free[0]))
    return out


def fit_font(text: str, box_pt: float, largest: float, smallest: float = 4.5) -> float | None:
    """The largest font size (points, at most ``largest``) at which ``text`` fits a square
    box ``box_pt`` points wide, or ``None`` below ``smallest``: labels stay inside their
    cell however large the floor."""
    lines = text.split("\n")
    size = min(largest, box_pt * 0.9 / (0.64 * max(1, max(len(line) for line in lines))), box_pt * 0.85 / (1.25 * len(lines)))
    return size if size >= smallest else None


def _extent(ts: Any, parks: Sequence[tuple[_Park, Cell]]) -> tuple[int, int, int, int]:
    """``(first row, first column, row after, column after)`` the panel draws: the grid and
    the parks beside it."""
    lay = ts.layout
    lo_r, lo_c, hi_r, hi_c = 0, 0, lay.rows, lay.cols
    for _, (r, c) in parks:
        lo_r, lo_c, hi_r, hi_c = min(lo_r, r), min(lo_c, c), max(hi_r, r + 1), max(hi_c, c + 1)
    return lo_r, lo_c, hi_r, hi_c


def _cell_points(ts: Any, overlay: _Overlay | None, width_in: float) -> float:
    """About how many points a cell's side takes in a panel ``width_in`` inches wide."""
    lo_r, lo_c, hi_r, hi_c = _extent(ts, _park_cells(ts, overlay.parks) if overlay else [])
    return width_in * 72 / max(hi_c - lo_c, (hi_r - lo_r) * 0.8)


def park_tags(overlay: _Overlay | None, cell_pt: float) -> dict[str, str]:
    """What each park's box says: its name where it fits the box, else a tag (``P1``) that
    the legend spells out (``P1 = elevator-lobby``)."""
    if overlay is None:
        return {}
    if all(fit_font(p.name, cell_pt * 0.88, 7, 5.0) for p in overlay.parks):
        return {p.name: p.name for p in overlay.parks}
    return {p.name: f"P{k + 1}" for k, p in enumerate(overlay.parks)}
