"""Pictures of synthesized tests, for people.

:func:`plot_test` draws a :class:`~synthesis.pipeline.SynthesizedTest` so that its
restrictions can be read at a glance:

* **grid** and **fuel** systems are drawn as cells (blocked cells dark, tokens written
  in the cells, the start teal, the goal cells green). Static obstacles are thick black
  walls on the border two cells share; a fuel system's moves between the same two
  cells at any fuel level are one wall. Reactive restrictions (doors) are one-way orange
  markers: an arrow from the source cell toward the border, stopped by a bar on the
  source's side, meaning "from this cell, this way is closed"; a move a test agent blocks
  is the same marker in the agent's blue;
* **graph** systems are node-link pictures in a deterministic layered layout (layers
  are the breadth-first distance from the start, left to right), the start and
  terminal states highlighted, propositions under the nodes, restricted edges orange and
  static obstacles black and dashed.

The colours are the roles' of every FlowTest picture (:data:`flowtest_env.render.ROLE_COLOURS`:
the start teal, the goal green, the test agent blue, walls black, doors orange).

Reactive and mixed tests get one panel per history that restricts something, titled
with the history's name and what it means (``reveal=False``: the name alone, ``q2``, as the
report shows a test whose objective is hidden); static walls appear in every panel. A
test whose restrictions are all static gets a single panel.

On grids every proposition gets a colour of its own (``colours``: a report passes one
mapping to all its pictures, so a proposition keeps its colour from test to test): a small
square in the corner of each cell where it holds, and a legend line saying what it is
(``H = hazard``, or the cells, or the fuel levels at which it holds), so a spill zone reads
as a spill zone.

An optional test-agent overlay shades the agent's cells (and marks its parks); agent
problems pass it automatically through ``test.agent``.

:func:`plot_artifact` draws the same panels from a loaded test artifact (what
``flowtest evaluate``'s report shows of each test).

Drawing uses a private :class:`matplotlib.figure.Figure` rendered by Agg (or the
vector backends for ``.svg``/``.pdf``); pyplot's global state is never touched, so
plotting is safe inside other programs and threads.
"""

from __future__ import annotations

import math
import textwrap
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from flowtest_env import render as roles
from synthesis.model.errors import ProblemError

from .plot_agent import _agent_overlay, _cell_of_place, _cell_points, _extent, _Overlay, _park_cells, fit_font, park_tags

#: File formats :func:`plot_test` writes, chosen by the path's suffix.
FORMATS = ("png", "svg", "pdf")

# colours: one meaning each, the same in every picture (the roles of flowtest_env.render)
FREE = "#ffffff"
BLOCKED = "#3a3a3a"
START = roles.hex_colour(roles.tint(roles.START, 0.6))
GOAL = roles.hex_colour(roles.tint(roles.GOAL, 0.45))
GRID_LINE = "#9a9a9a"
WALL = "#000000"
RESTRICTED = roles.hex_colour(roles.DOOR)
"""A door: a move the test closes in some histories."""
AGENT_BLOCK = roles.hex_colour(roles.AGENT)
"""A move the test agent blocks."""
EDGE = "#9a9a9a"
AGENT = roles.hex_colour(roles.tint(roles.AGENT, 0.6))
"""The test agent's cells and parks."""
TEXT = "#202020"
PROP = "#1f5fa0"
#: one colour per proposition (in name order), none of them a colour with a meaning above
PROP_COLOURS = tuple(roles.hex_colour(c) for c in roles.PALETTE)


def proposition_colours(names: Sequence[str]) -> dict[str, str]:
    """``#rrggbb`` of each proposition (:func:`flowtest_env.render.proposition_colours`)."""
    return {name: roles.hex_colour(c) for name, c in roles.proposition_colours(names).items()}


Cell = tuple[int, int]


def check_plot_format(path: Path) -> str:
    """The format of ``path`` from its suffix; raises ProblemError if unsupported."""
    fmt = path.suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise ProblemError(f"cannot draw {str(path)!r}: use a .png, .svg or .pdf file name")
    return fmt


@dataclass
class Panel:
    """One picture of the system: a title and the moves to mark as restricted."""

    title: str
    restricted: np.ndarray  # bool[n_moves], reactive restrictions only


def panels_of(test: Any, reveal: bool = True) -> list[Panel]:
    """One panel per history with reactive restrictions, or one static panel, titled with
    the history's name and (``reveal``) what it means, which gives the hidden test objective
    away (``history q1: saw I1``; else ``history q1``).

    Reactive restrictions of history ``q`` are ``C(q)`` minus the static obstacles
    (those are drawn in every panel anyway).
    """
    strategy = test.strategy
    static = strategy.static_obstacles
    reactive = strategy.restrictions & ~static[None, :]
    panels = []
    for q in range(strategy.n_hist):
        if reactive[q].any():
            name = test.spec.history_name(q)
            panels.append(Panel(f"history {name}: {test.spec.describe(q)}" if reveal else f"history {name}", reactive[q]))
    if not panels:
        title = "static walls (the whole test)" if static.any() else "no restrictions"
        panels.append(Panel(title, np.zeros_like(static)))
    return panels


def plot_test(
    test: Any,
    path: str | Path,
    *,
    agent: Any = None,
    dpi: int = 110,
    max_cols: int | None = None,
    header: bool = True,
    reveal: bool = True,
    colours: dict[str, str] | None = None,
) -> Path:
    """Draw ``test`` (a :class:`~synthesis.pipeline.SynthesizedTest`) to ``path``.

    Parameters
    ----------
    test
        The synthesized test.
    path
        Output file; ``.png``, ``.svg`` or ``.pdf``. Parent directories must exist.
    agent
        An optional test-agent overlay: any object (or mapping) with ``cells`` (places
        of T, ``(row, col)`` cells or state names: where the agent moves) and optionally
        ``parks`` (see :func:`_agent_overlay`). Defaults to ``test.agent``, then
        ``test.problem.agent`` (a :class:`synthesis.model.agent_system.TestAgent`); objects without
        ``cells`` are ignored.
    dpi
        Resolution of raster output.
    max_cols
        At most this many panels side by side (default: 4 on narrow grids, else 3); the
        report asks for 2 so that a test's picture fits a card at laptop width.
    header
        Title the picture with the problem's name, kind, flow, cuts and objectives (the
        report's cards say these in the page, so they leave it out).
    reveal
        Title each panel with what its history means (which gives the hidden test objective
        away); ``False``: its neutral name alone (``history q2``).
    colours
        The propositions' colours by name (``#rrggbb``; default :func:`proposition_colours`
        of the test's own): a report passes one mapping to all its pictures.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    fmt = check_plot_format(path)
    ts = test.problem.system
    panels = panels_of(test, reveal)
    overlay = _agent_overlay(test, agent)
    if ts.kind in ("grid", "fuel") and ts.layout is not None:
        props = proposition_places(ts)
        fig = _grid_figure(test, panels, overlay, max_cols, header, {**proposition_colours(list(props)), **(colours or {})})
    else:
        fig = _graph_figure(test, panels, overlay, max_cols, header)
    if header:
        fig.suptitle(_header(test), fontsize=10)
    FigureCanvasAgg(fig)
    fig.savefig(path, format=fmt, dpi=dpi)
    return path


@dataclass(frozen=True)
class _Objective:
    text: str


@dataclass(frozen=True)
class _ArtifactProblem:
    name: str
    kind: str
    system: Any
    system_objective: _Objective
    test_objective: _Objective
    agent: Any = None
    static_moves: np.ndarray | None = None  # a mixed test's static area (TestArtifact.static_area)


@dataclass(frozen=True)
class _ArtifactRouting:
    flow: int
    cut_edges: np.ndarray
    status: str


@dataclass(frozen=True)
class _ArtifactSpec:
    """What the panels need of the specification product: history names and meanings."""

    art: Any

    def history_name(self, h: int) -> str:
        return f"q{h}"

    def describe(self, h: int) -> str:
        """As :meth:`synthesis.graphs.automata.SpecificationProduct.describe`."""
        comps = self.art.histories.components
        if comps is None:
            return "start"
        s, t = (int(x) for x in comps[h])
        bits = [b for b in (self.art.system_automaton.names[s], self.art.test_automaton.names[t]) if b]
        return "; ".join(bits) or "start"


@dataclass(frozen=True)
class _ArtifactTest:
    """A loaded artifact seen as the parts of a synthesized test that the pictures read."""

    problem: _ArtifactProblem
    routing: _ArtifactRouting
    strategy: Any
    spec: _ArtifactSpec
    agent: Any = None


def artifact_view(art: Any) -> Any:
    """A :class:`~synthesis.artifacts.artifact.TestArtifact` as the synthesized test that
    :func:`plot_test` and :func:`panels_of` read (problem, routing summary, restrictions,
    history meanings, test agent, a mixed test's static area)."""
    summary = art.summary or {}
    problem = _ArtifactProblem(
        str(art.name),
        str(art.kind),
        art.system,
        _Objective(str(art.objectives.get("system", ""))),
        _Objective(str(art.objectives.get("test", ""))),
        static_moves=getattr(art, "static_area", None),
    )
    routing = _ArtifactRouting(int(summary.get("flow", 0)), np.zeros(int(summary.get("n_cuts", 0))), str(summary.get("status", "unknown")))
    return _ArtifactTest(problem, routing, art.strategy, _ArtifactSpec(art), art.agent)


def plot_artifact(
    art: Any, path: str | Path, *, dpi: int = 110, max_cols: int | None = 2, header: bool = True, reveal: bool = True, colours: dict[str, str] | None = None
) -> Path:
    """Draw a loaded test artifact as :func:`plot_test` draws its synthesized test: one
    panel per history that restricts something, static walls in every panel, the
    propositions in the legend, the test agent's cells and parks.

    Example::

        import gymnasium as gym
        game = gym.make("FlowTest-SmallReactive-v0").unwrapped.game
        plot_artifact(game.artifact, "small-reactive.png")
    """
    return plot_test(artifact_view(art), path, dpi=dpi, max_cols=max_cols, header=header, reveal=reveal, colours=colours)


def proposition_places(ts: Any) -> dict[str, tuple[list[Cell], str]]:
    """Per proposition of a grid or fuel system (name order): the cells where it holds in
    some state, and ``""`` when it holds in every state of those cells, else where exactly
    (``"fuel 0"``: at fuel 0 there; fuel systems label states, not cells)."""
    out: dict[str, tuple[list[Cell], str]] = {}
    states_of: dict[str, list[int]] = {}
    for s in range(ts.n_states):
        for prop in ts.labels[s]:
            states_of.setdefault(prop, []).append(s)
    for prop in sorted(states_of):
        states = states_of[prop]
        cells = sorted({_cell_of_place(ts, int(ts.place[s])) for s in states})
        note = ""
        if ts.kind == "fuel":
            places = {int(ts.place[s]) for s in states}
            every = sum(int(np.count_nonzero(ts.place == p)) for p in places)
            if every != len(states):
                levels = sorted({int(ts.states[s][1]) for s in states})
                note = "fuel " + ",".join(map(str, levels))
        out[prop] = (cells, note)
    return out


def proposition_legend(ts: Any, limit: int = 4, colours: dict[str, str] | None = None) -> list[tuple[str, str, str]]:
    """``(proposition, where it holds, colour)`` for a legend: ``("hazard", "cells H",
    "#e377c2")`` when one token names exactly its cells, else its cells (the first
    ``limit``), and the fuel levels when it holds at some levels only; the colour of its
    squares in the grid pictures (``colours`` by name, default :func:`proposition_colours`
    of the system's propositions). Graph systems: the states, no colour (the pictures
    write the propositions under the nodes)."""
    out: list[tuple[str, str, str]] = []
    if ts.layout is None:
        states_of: dict[str, list[str]] = {}
        for s in range(ts.n_states):
            for prop in ts.labels[s]:
                states_of.setdefault(prop, []).append(str(ts.states[s]))
        for prop in sorted(states_of):
            names = states_of[prop]
            more = f" and {len(names) - limit} more" if len(names) > limit else ""
            out.append((prop, ("state " if len(names) == 1 else "states ") + ", ".join(names[:limit]) + more, ""))
        return out
    tokens = ts.layout.tokens
    places = proposition_places(ts)
    colour_of = {**proposition_colours(list(places)), **(colours or {})}
    for prop, (cells, note) in places.items():
        named = {tokens.get(c) for c in cells}
        token = next(iter(named)) if len(named) == 1 else None
        if token is not None and {c for c, t in tokens.items() if t == token} == set(cells):
            where = f"cell{'s' if len(cells) > 1 else ''} {token}"
        elif ts.kind == "fuel" and note and len(cells) == len({_cell_of_place(ts, p) for p in range(len(ts.places))}):
            where = "every cell"
        else:
            more = f" and {len(cells) - limit} more" if len(cells) > limit else ""
            where = ("cell " if len(cells) == 1 else "cells ") + ", ".join(f"({r}, {c})" for r, c in cells[:limit]) + more
        out.append((prop, f"{where} at {note}" if note else where, colour_of[prop]))
    return out


# --------------------------------------------------------------------------- shared


def _layout_grid(n: int, max_cols: int) -> tuple[int, int]:
    cols = min(n, max_cols)
    return math.ceil(n / cols), cols


def _wrap(text: str, width: int) -> str:
    return "\n".join(textwrap.wrap(text, width)) or text


def _header(test: Any) -> str:
    p, r = test.problem, test.routing
    fuel = f", fuel 0..{p.system.max_fuel}" if p.system.kind == "fuel" else ""
    return (
        f"{p.name}: {p.kind} test{fuel}, flow {r.flow}, {int(r.cut_edges.size)} cuts ({r.status})\n"
        f"system: {p.system_objective.text}      test: {p.test_objective.text}"
    )


# --------------------------------------------------------------------------- grids


def _place_pairs(ts: Any, mask: np.ndarray) -> set[tuple[int, int]]:
    """Directed place pairs of the moves in ``mask`` (fuel levels merged)."""
    m = np.flatnonzero(mask)
    return set(zip(ts.place[ts.src[m]].tolist(), ts.place[ts.dst[m]].tolist(), strict=True))


def _border(a: Cell, b: Cell) -> tuple[tuple[float, float], tuple[float, float]]:
    """The segment (in x=col, y=row coordinates) two adjacent cells share."""
    (r1, c1), (r2, c2) = a, b
    if r1 == r2:
        x = float(max(c1, c2))
        return (x, float(r1)), (x, float(r1 + 1))
    y = float(max(r1, r2))
    return (float(c1), y), (float(c1 + 1), y)


def _adjacent(a: Cell, b: Cell) -> bool:
    return abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1


def _draw_wall(ax: Axes, a: Cell, b: Cell) -> None:
    (x0, y0), (x1, y1) = _border(a, b)
    ax.plot([x0, x1], [y0, y1], color=WALL, linewidth=6, solid_capstyle="butt", zorder=5)


def _draw_restriction(ax: Axes, a: Cell, b: Cell, note: str | None = None, color: str = RESTRICTED) -> None:
    """A one-way marker: arrow from inside ``a`` toward the border with ``b``, then a bar."""
    (r1, c1), (r2, c2) = a, b
    d = np.array([c2 - c1, r2 - r1], dtype=float)  # direction in (x, y)
    n = np.array([-d[1], d[0]])  # along the border
    mid = np.array([max(c1, c2) if r1 == r2 else c1 + 0.5, max(r1, r2) if c1 == c2 else r1 + 0.5], dtype=float)
    bar_c = mid - 0.08 * d
    p0, p1 = bar_c - 0.3 * n, bar_c + 0.3 * n
    ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color=color, linewidth=3.5, solid_capstyle="round", zorder=6)
    tail, head = mid - 0.34 * d, mid - 0.1 * d
    ax.annotate(
        "",
        xy=(head[0], head[1]),
        xytext=(tail[0], tail[1]),
        arrowprops={"arrowstyle": "-|>", "color": color, "lw": 2.0, "mutation_scale": 14, "shrinkA": 0, "shrinkB": 0},
        zorder=6,
    )
    if note:
        at = mid - 0.25 * d + 0.22 * n
        ax.text(at[0], at[1], note, fontsize=6.5, color=color, ha="center", va="center", zorder=7)


def _fuel_note(ts: Any, mask: np.ndarray, a: int, b: int) -> str | None:
    """On fuel systems, the fuel levels at which the move ``a -> b`` is restricted."""
    if ts.kind != "fuel":
        return None
    m = np.flatnonzero(mask)
    m = m[(ts.place[ts.src[m]] == a) & (ts.place[ts.dst[m]] == b)]
    levels = sorted({int(ts.states[int(s)][1]) for s in ts.src[m]})
    all_levels = {int(ts.states[int(s)][1]) for s in ts.src[(ts.place[ts.src] == a) & (ts.place[ts.dst] == b)]}
    if set(levels) == all_levels:
        return None
    return "fuel " + ",".join(map(str, levels))


def _static_area(test: Any) -> set[tuple[int, int]]:
    """The place pairs (each border once) of a mixed test's static area: the moves where its
    problem allows walls, drawn whether or not a wall was put there."""
    problem = getattr(test, "problem", None)
    area = getattr(problem, "static_moves", None)
    if problem is None or getattr(problem, "kind", None) != "mixed" or area is None:
        return set()
    ts = problem.system
    pairs = {(min(a, b), max(a, b)) for a, b in _place_pairs(ts, np.asarray(area, dtype=bool))}
    return {(a, b) for a, b in pairs if _adjacent(_cell_of_place(ts, a), _cell_of_place(ts, b))}


def _draw_grid_panel(ax: Axes, test: Any, panel: Panel, overlay: _Overlay | None, colours: dict[str, str], width_in: float = 3.0) -> None:
    ts = test.problem.system
    lay = ts.layout
    start = _cell_of_place(ts, int(ts.place[ts.initial]))
    goals = {_cell_of_place(ts, int(p)) for p in np.unique(ts.place[ts.terminal])}
    agent_cells = {_cell_of_place(ts, p) for p in overlay.places} if overlay else set()
    parks = _park_cells(ts, overlay.parks) if overlay else []
    lo_r, lo_c, hi_r, hi_c = _extent(ts, parks)
    cell_pt = _cell_points(ts, overlay, width_in)
    labels_of: dict[Cell, set[str]] = {}
    if ts.kind == "grid":
        for s in range(ts.n_states):
            labels_of.setdefault(_cell_of_place(ts, int(ts.place[s])), set()).update(ts.labels[s])
    for r in range(lay.rows):
        for c in range(lay.cols):
            cell = (r, c)
            if cell in lay.blocked:
                color = BLOCKED
            elif cell == start:
                color = START
            elif cell in goals:
                color = GOAL
            else:
                color = FREE
            ax.add_patch(Rectangle((c, r), 1, 1, facecolor=color, edgecolor=GRID_LINE, linewidth=1.0, zorder=1))
            if cell in agent_cells:
                ax.add_patch(Rectangle((c, r), 1, 1, facecolor=AGENT, alpha=0.55, edgecolor=GRID_LINE, linewidth=1.0, zorder=2))
            text = lay.tokens.get(cell)
            if cell == start and text is None:
                text = "start"
            if cell in lay.blocked:
                continue
            label = text if text is not None else "\n".join(sorted(labels_of.get(cell, ())))
            size = fit_font(label, cell_pt, 13 if text is not None else 8) if label else None
            if size is not None:
                ax.text(
                    c + 0.5, r + 0.5, label, ha="center", va="center", fontsize=size, fontweight="bold" if text is not None else "normal", color=TEXT, zorder=3
                )
    places = proposition_places(ts)
    marks: dict[Cell, int] = {}  # squares drawn in a cell so far: several propositions line up
    for prop, (cells, _) in places.items():
        colour = colours[prop]
        for r, c in cells:
            if (r, c) in lay.blocked:
                continue
            k = marks[(r, c)] = marks.get((r, c), -1) + 1
            ax.add_patch(Rectangle((c + 0.04 + 0.2 * (k % 4), r + 0.04 + 0.2 * (k // 4)), 0.17, 0.17, facecolor=colour, edgecolor="none", zorder=3))
    tags = park_tags(overlay, cell_pt)
    for park, (r, c) in parks:
        ax.add_patch(Rectangle((c + 0.06, r + 0.06), 0.88, 0.88, facecolor=AGENT, alpha=0.55, hatch="//", edgecolor=AGENT, linewidth=1.5, zorder=3))
        size = fit_font(tags[park.name], cell_pt * 0.88, 7)
        if size is not None:
            ax.text(c + 0.5, r + 0.5, tags[park.name], ha="center", va="center", fontsize=size, fontweight="bold", color=TEXT, zorder=4)
    ax.add_patch(Rectangle((0, 0), lay.cols, lay.rows, fill=False, edgecolor=WALL, linewidth=2.5, zorder=4))
    for a, b in sorted(_static_area(test)):  # where a mixed test may put walls, as the user typed it
        (x0, y0), (x1, y1) = _border(_cell_of_place(ts, a), _cell_of_place(ts, b))
        ax.plot([x0, x1], [y0, y1], color=WALL, linewidth=1.2, linestyle=(0, (2, 2)), alpha=0.6, zorder=4)
    moves = _place_pairs(ts, np.ones(ts.n_moves, dtype=bool))
    static = _place_pairs(ts, test.strategy.static_obstacles)
    for a, b in sorted(static):
        ca, cb = _cell_of_place(ts, a), _cell_of_place(ts, b)
        if not _adjacent(ca, cb):
            continue
        if (b, a) in static or (b, a) not in moves:
            _draw_wall(ax, ca, cb)  # closed both ways (or the way back does not exist)
        else:
            _draw_restriction(ax, ca, cb, color=WALL)  # a one-way static obstacle
    blocked_by = _restriction_colour(test)
    for a, b in sorted(_place_pairs(ts, panel.restricted)):
        ca, cb = _cell_of_place(ts, a), _cell_of_place(ts, b)
        if _adjacent(ca, cb):
            _draw_restriction(ax, ca, cb, _fuel_note(ts, panel.restricted, a, b), color=blocked_by)
    ax.set_xlim(lo_c - 0.05, hi_c + 0.05)
    ax.set_ylim(hi_r + 0.05, lo_r - 0.05)  # row 0 at the top
    ax.set_aspect("equal")
    ax.set_xticks([i + 0.5 for i in range(lay.cols)], [str(i) for i in range(lay.cols)], fontsize=7)
    ax.set_yticks([i + 0.5 for i in range(lay.rows)], [str(i) for i in range(lay.rows)], fontsize=7)
    ax.tick_params(length=0, pad=2, colors="#707070")
    for spine in ax.spines.values():
        spine.set_visible(False)


def _restriction_colour(test: Any) -> str:
    """A door's orange, or on an agent test the agent's blue (the moves it blocks)."""
    return AGENT_BLOCK if getattr(test.problem, "kind", None) == "agent" else RESTRICTED


def _restriction_label(test: Any) -> str:
    if getattr(test.problem, "kind", None) == "agent":
        return "a move the test agent blocks in this history (one way, toward the bar)"
    return "door: closed in this history (one way, toward the bar)"


def _grid_figure(
    test: Any, panels: Sequence[Panel], overlay: _Overlay | None, max_cols: int | None = None, header: bool = True, colours: dict[str, str] | None = None
) -> Figure:
    lay = test.problem.system.layout
    cell = 0.62 if max(lay.rows, lay.cols) <= 8 else max(0.2, 5.0 / max(lay.rows, lay.cols))
    pw = max(lay.cols * cell, 2.6) + 0.5
    ph = (pw - 0.5) * lay.rows / lay.cols + 0.9  # equal aspect: a narrow grid widened to 2.6 in grows as tall
    nrows, ncols = _layout_grid(len(panels), max_cols or (4 if lay.cols <= 4 else 3))
    fig = Figure(figsize=(max(ncols * pw, 6.0), nrows * ph + (1.7 if header else 1.2)), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    width = max(24, int(pw * 11))
    colours = colours or proposition_colours(list(proposition_places(test.problem.system)))
    for ax, panel in zip(axes.flat, panels, strict=False):  # spare axes stay blank
        _draw_grid_panel(ax, test, panel, overlay, colours, pw - 0.5)
        ax.set_title(_wrap(panel.title, width), fontsize=9)
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    handles: list[Artist] = [
        Patch(facecolor=START, edgecolor=GRID_LINE, label="start"),
        Patch(facecolor=GOAL, edgecolor=GRID_LINE, label="goal (terminal)"),
    ]
    if lay.blocked:
        handles.append(Patch(facecolor=BLOCKED, label="blocked cell"))
    if _static_area(test):
        handles.append(Line2D([], [], color=WALL, linewidth=1.2, linestyle=(0, (2, 2)), alpha=0.6, label="static area (walls only here)"))
    if test.strategy.static_obstacles.any():
        handles.append(Line2D([], [], color=WALL, linewidth=5, label="static wall"))
        ts = test.problem.system
        static = _place_pairs(ts, test.strategy.static_obstacles)
        moves = _place_pairs(ts, np.ones(ts.n_moves, dtype=bool))
        if any((b, a) in moves and (b, a) not in static for a, b in static):
            handles.append(Line2D([], [], color=WALL, linewidth=2, marker=">", markersize=7, label="one-way static wall"))
    if any(p.restricted.any() for p in panels):
        handles.append(Line2D([], [], color=_restriction_colour(test), linewidth=2, marker=">", markersize=7, label=_restriction_label(test)))
    if overlay is not None:
        handles.append(Patch(facecolor=AGENT, alpha=0.55, label="test agent cells"))
        if overlay.parks:
            handles.append(Patch(facecolor=AGENT, alpha=0.55, hatch="//", label="test agent park"))
            cell_pt = _cell_points(test.problem.system, overlay, pw - 0.5)
            handles += [
                Patch(facecolor=AGENT, alpha=0.55, hatch="//", label=f"{tag} = park {name}") for name, tag in park_tags(overlay, cell_pt).items() if tag != name
            ]
    for prop, where, colour in proposition_legend(test.problem.system, colours=colours):
        handles.append(Patch(facecolor=colour, label=f"{prop}: {where}"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 2 if max_cols == 2 else 3), fontsize=8, frameon=False)
    return fig


# --------------------------------------------------------------------------- graphs


def layered_positions(ts: Any) -> dict[int, tuple[float, float]]:
    """Deterministic positions of a graph system's places, layered left to right.

    A place's layer is its breadth-first distance from the start (unreachable places
    go in a last layer); within a layer places are ordered by the mean position of
    their predecessors (one barycentre sweep), ties by index, which keeps most edges
    short and uncrossed on the paper's graph examples.
    """
    n = len(ts.places)
    succ: list[list[int]] = [[] for _ in range(n)]
    pred: list[list[int]] = [[] for _ in range(n)]
    for a, b in zip(ts.place[ts.src].tolist(), ts.place[ts.dst].tolist(), strict=True):
        if a != b:
            succ[a].append(b)
            pred[b].append(a)
    start = int(ts.place[ts.initial])
    dist = {start: 0}
    queue = deque([start])
    while queue:
        u = queue.popleft()
        for v in succ[u]:
            if v not in dist:
                dist[v] = dist[u] + 1
                queue.append(v)
    last = max(dist.values()) + 1
    terminal = set(np.unique(ts.place[ts.terminal]).tolist())
    # terminal places go to the far right so the picture reads start -> goal
    far = max([d for p, d in dist.items() if p not in terminal] + [0]) + 1
    layer = {p: (far if p in terminal and p in dist else dist.get(p, last + 1)) for p in range(n)}
    layers: dict[int, list[int]] = {}
    for p in range(n):
        layers.setdefault(layer[p], []).append(p)
    ypos: dict[int, float] = {}
    pos: dict[int, tuple[float, float]] = {}
    for x, key in enumerate(sorted(layers)):
        members = layers[key]

        def barycentre(p: int) -> tuple[float, int]:
            # top of the layer first: the highest mean predecessor position first
            ys = [ypos[q] for q in pred[p] if q in ypos and layer[q] < layer[p]]
            return (-float(np.mean(ys)) if ys else 0.0, p)

        members.sort(key=barycentre)
        k = len(members)
        for i, p in enumerate(members):
            y = (k - 1) / 2.0 - i
            ypos[p] = y
            pos[p] = (float(x), y)
    return pos


def _draw_graph_panel(ax: Axes, test: Any, panel: Panel, overlay: _Overlay | None, pos: dict[int, tuple[float, float]]) -> None:
    ts = test.problem.system
    start = int(ts.place[ts.initial])
    terminal = set(np.unique(ts.place[ts.terminal]).tolist())
    static = _place_pairs(ts, test.strategy.static_obstacles)
    restricted = _place_pairs(ts, panel.restricted)
    pairs = sorted(set(zip(ts.place[ts.src].tolist(), ts.place[ts.dst].tolist(), strict=True)))
    pair_set = set(pairs)
    radius_pt = 19.0  # node radius in points
    for a, b in pairs:
        if a == b:
            continue
        (xa, ya), (xb, yb) = pos[a], pos[b]
        if (b, a) in pair_set:
            rad = 0.18
        elif xb < xa or (xb == xa and abs(yb - ya) > 1.01):
            rad = 0.35  # backward or layer-skipping edges bend around the nodes between
        else:
            rad = 0.0
        if (a, b) in restricted:
            style = {"color": _restriction_colour(test), "lw": 2.6, "zorder": 4}
        elif (a, b) in static:
            style = {"color": WALL, "lw": 2.4, "zorder": 3, "linestyle": "--"}
        else:
            style = {"color": EDGE, "lw": 1.0, "zorder": 2}
        z = style.pop("zorder")
        ax.annotate(
            "",
            xy=(xb, yb),
            xytext=(xa, ya),
            arrowprops={
                "arrowstyle": "-|>",
                "mutation_scale": 12,
                "shrinkA": radius_pt,
                "shrinkB": radius_pt,
                "connectionstyle": f"arc3,rad={rad}",
                **style,
            },
            zorder=z,
        )
    agent_places = overlay.places if overlay else set()
    for p, (x, y) in pos.items():
        if p == start:
            color = START
        elif p in terminal:
            color = GOAL
        else:
            color = FREE
        edge = AGENT if p in agent_places else "#505050"
        ax.scatter([x], [y], s=(2 * radius_pt) ** 2, c=color, edgecolors=edge, linewidths=3.0 if p in agent_places else 1.2, zorder=5)
        name = str(ts.places[p])
        props = sorted(set().union(*(ts.labels[s] for s in np.flatnonzero(ts.place == p))))
        ax.text(x, y + (0.07 if props else 0.0), name, ha="center", va="center", fontsize=7 if len(name) <= 6 else 6, color=TEXT, zorder=6)
        if props:
            ax.text(x, y - 0.11, ",".join(props), ha="center", va="center", fontsize=6.5, fontstyle="italic", color=PROP, zorder=6)
    xs = [x for x, _ in pos.values()]
    ys = [y for _, y in pos.values()]
    for k, park in enumerate(overlay.parks if overlay else []):
        # a park is outside T: a hatched box above its first entry, dashed lines to its entries
        if not park.entries:
            continue
        ex, ey = pos[park.entries[0]]
        px, py = ex + 0.3, ey + 0.55 + 0.25 * k
        for e in park.entries:
            ax.plot([pos[e][0], px], [pos[e][1], py], color=AGENT, linestyle=":", linewidth=1.5, zorder=1)
        ax.text(
            px,
            py,
            park.name,
            ha="center",
            va="center",
            fontsize=7,
            zorder=6,
            bbox={"boxstyle": "square,pad=0.3", "facecolor": AGENT, "edgecolor": AGENT, "hatch": "//", "alpha": 0.7},
        )
        ys.append(py)
        xs.append(px)
    ax.set_xlim(min(xs) - 0.6, max(xs) + 0.6)
    ax.set_ylim(min(ys) - 0.9, max(ys) + 0.7)
    ax.set_axis_off()


def _graph_figure(test: Any, panels: Sequence[Panel], overlay: _Overlay | None, max_cols: int | None = None, header: bool = True) -> Figure:
    ts = test.problem.system
    pos = layered_positions(ts)
    n_layers = len({x for x, _ in pos.values()})
    height = max(sum(1 for x, _ in pos.values() if x == lx) for lx in {x for x, _ in pos.values()})
    pw, ph = max(1.15 * n_layers + 0.6, 3.4), max(0.85 * height + 1.0, 2.4)
    nrows, ncols = _layout_grid(len(panels), max_cols or 3)
    fig = Figure(figsize=(max(ncols * pw, 6.0), nrows * ph + (1.2 if header else 0.8)), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax, panel in zip(axes.flat, panels, strict=False):  # spare axes stay blank
        _draw_graph_panel(ax, test, panel, overlay, pos)
        ax.set_title(_wrap(panel.title, max(26, int(pw * 10))), fontsize=9)
    for ax in list(axes.flat)[len(panels) :]:
        ax.set_visible(False)
    handles: list[Artist] = [
        Line2D([], [], linestyle="", marker="o", markersize=10, markerfacecolor=START, markeredgecolor="#505050", label="start"),
        Line2D([], [], linestyle="", marker="o", markersize=10, markerfacecolor=GOAL, markeredgecolor="#505050", label="terminal"),
        Line2D([], [], color=EDGE, linewidth=1.0, label="transition"),
    ]
    if any(p.restricted.any() for p in panels):
        handles.append(Line2D([], [], color=_restriction_colour(test), linewidth=2.6, label="restricted under this history"))
    if test.strategy.static_obstacles.any():
        handles.append(Line2D([], [], color=WALL, linewidth=2.4, linestyle="--", label="static obstacle"))
    if overlay is not None:
        handles.append(
            Line2D([], [], linestyle="", marker="o", markersize=10, markerfacecolor=FREE, markeredgecolor=AGENT, markeredgewidth=3, label="test agent state")
        )
        if overlay.parks:
            handles.append(Patch(facecolor=AGENT, alpha=0.7, hatch="//", label="test agent park"))
    handles.append(Line2D([], [], linestyle="", marker="$p$", color=PROP, label="propositions (blue italic)"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 3), fontsize=8, frameon=False)
    return fig
