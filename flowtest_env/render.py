"""Pictures of a test run: numpy tiles for grids, node-link pictures for graphs, text.

Every picture FlowTest draws speaks one visual language (:data:`ROLE_COLOURS`): one colour per
role (the start teal, the goal green, the system under test red, the test agent blue, walls
black, doors orange, hidden test cells purple, refuel stations yellow) and one per
proposition name
(:func:`proposition_colours`; a report passes one mapping to all its pictures, so a
proposition keeps its colour from test to test).

Grid frames are assembled from tiles drawn once per tile size and cached (module-level
cache keyed by kind and size): floor, blocked cell, goal, marks for the system's own
cells (refuel, drop-off, ...), hidden test cells (test-engineer view only: purple rings;
on fuel grids pale rings where the test proposition holds only at a lower fuel level),
the test agent and the system under test; walls (black) and restrictions shown now
(orange) are bars on the edge of the cell the move leaves. The engineer's view also draws,
pale and thin, the doors closed now out of the system's view (out of cells it does not
stand in): a door closed the whole run stays drawn. The static background of a
problem is composed once per renderer; a frame is one copy of it plus a few tile blits.
Static obstacles that hold at some states of a cell only (walls per fuel level) are not
walls of the map: they are drawn, black, while the system stands at such a state.

Graph frames: a layout is computed once (Kamada-Kawai, deterministic), the background
(edges, nodes, names) is drawn once with matplotlib's Agg backend into an array, and
frames overlay the system, the agent and the restricted edges with numpy; a restricted
edge is marked on its own arc, so the two directions of a two-way edge stay apart.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from synthesis.model.specs import parse_formula, propositions

from .encoding import system_propositions
from .game import GRID_ACTIONS, RunState, TestGame, printable

RGB = tuple[int, int, int]

FLOOR: RGB = (236, 236, 231)
GRID_LINE: RGB = (190, 190, 185)
BLOCKED: RGB = (70, 70, 75)
START: RGB = (0, 150, 130)
GOAL: RGB = (96, 180, 96)
SYSTEM: RGB = (214, 48, 49)
AGENT: RGB = (40, 96, 200)
WALL: RGB = (30, 30, 30)
DOOR: RGB = (240, 140, 0)
DOOR_OUT_OF_VIEW: RGB = (245, 188, 120)
TEST_CELL: RGB = (170, 60, 200)
TEST_CELL_LATER: RGB = (214, 176, 226)
REFUEL: RGB = (235, 190, 20)
STATUS_BG: RGB = (40, 40, 44)
FUEL_BAR: RGB = REFUEL

ROLE_COLOURS: dict[str, RGB] = {
    "start": START,
    "goal": GOAL,
    "system under test": SYSTEM,
    "test agent": AGENT,
    "wall": WALL,
    "door": DOOR,
    "door out of view": DOOR_OUT_OF_VIEW,
    "hidden test cell": TEST_CELL,
    "hidden test cell later": TEST_CELL_LATER,
    "refuel": REFUEL,
    "blocked cell": BLOCKED,
}
"""One colour per role, the same in every picture: the frames and filmstrips here, the test
pictures of :mod:`experiments.plots`, the report's path plots."""

PALETTE: tuple[RGB, ...] = ((23, 190, 207), (227, 119, 194), (140, 86, 75), (127, 127, 127), (120, 40, 100), (150, 150, 200), (150, 150, 20))
"""The propositions' colours (cyan, pink, brown, grey, plum, lavender, olive): none of them
a role's (:data:`ROLE_COLOURS`), nor near one."""


def proposition_colours(names: Iterable[str]) -> dict[str, RGB]:
    """One colour of :data:`PALETTE` per proposition name, in name order (cycling past seven
    names). Every picture of one report takes the mapping of all its tests' propositions,
    so a proposition has one colour in all of them.

    >>> proposition_colours(["hazard", "bay"])
    {'bay': (23, 190, 207), 'hazard': (227, 119, 194)}
    """
    return {name: PALETTE[i % len(PALETTE)] for i, name in enumerate(sorted(set(names)))}


def hex_colour(color: RGB) -> str:
    """``#rrggbb`` of a colour (what matplotlib and HTML take)."""
    return f"#{color[0]:02x}{color[1]:02x}{color[2]:02x}"


def tint(color: RGB, amount: float) -> RGB:
    """``color`` mixed with white (``amount`` 0: the colour, 1: white): a role's pale fill."""
    r, g, b = (int(round(c + (255 - c) * amount)) for c in color)
    return r, g, b


def all_propositions(game: TestGame) -> list[str]:
    """Every proposition the test's system labels (name order)."""
    return sorted(set().union(*game.ts.labels)) if game.ts.n_states else []


_TILES: dict[tuple[Any, ...], np.ndarray] = {}


def _disk(size: int, radius: float) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    c = size / 2
    mask: np.ndarray = (yy - c) ** 2 + (xx - c) ** 2 <= (radius * size) ** 2
    return mask


def _diamond(size: int, radius: float) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    c = size / 2
    mask: np.ndarray = np.abs(yy - c) + np.abs(xx - c) <= radius * size
    return mask


def _ring(size: int, outer: float, inner: float) -> np.ndarray:
    mask: np.ndarray = _disk(size, outer) & ~_disk(size, inner)
    return mask


def _square(size: int, margin: float) -> np.ndarray:
    m = int(round(margin * size))
    out = np.zeros((size, size), dtype=bool)
    out[m : size - m, m : size - m] = True
    return out


def _cross(size: int, width: float, length: float) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size] + 0.5
    c = size / 2
    a = (np.abs(yy - c) <= width * size) & (np.abs(xx - c) <= length * size)
    b = (np.abs(xx - c) <= width * size) & (np.abs(yy - c) <= length * size)
    mask: np.ndarray = a | b
    return mask


def shape_mask(kind: str, size: int) -> np.ndarray:
    """A cached ``bool[size, size]`` mask of a tile shape."""
    key = ("shape", kind, size)
    m = _TILES.get(key)
    if m is None:
        makers = {
            "system": lambda: _disk(size, 0.32),
            "agent": lambda: _diamond(size, 0.36),
            "goal": lambda: _square(size, 0.12),
            "mark": lambda: _disk(size, 0.14),
            "test": lambda: _ring(size, 0.44, 0.36),
            "refuel": lambda: _cross(size, 0.07, 0.3),
        }
        m = makers[kind]()
        _TILES[key] = m
    return m


def floor_tile(size: int, color: RGB = FLOOR) -> np.ndarray:
    """A cached ``uint8[size, size, 3]`` cell tile with a one-pixel grid line."""
    key = ("floor", color, size)
    t = _TILES.get(key)
    if t is None:
        t = np.empty((size, size, 3), dtype=np.uint8)
        t[:] = color
        t[0, :] = GRID_LINE
        t[:, 0] = GRID_LINE
        _TILES[key] = t
    return t


def _paint(img: np.ndarray, r: int, c: int, size: int, mask: np.ndarray, color: RGB) -> None:
    view = img[r * size : (r + 1) * size, c * size : (c + 1) * size]
    view[mask] = color


def _edge_bar(img: np.ndarray, r: int, c: int, size: int, direction: str, color: RGB, thick: float) -> None:
    w = max(2, int(round(thick * size)))
    y0, x0 = r * size, c * size
    if direction == "N":
        img[y0 : y0 + w, x0 : x0 + size] = color
    elif direction == "S":
        img[y0 + size - w : y0 + size, x0 : x0 + size] = color
    elif direction == "W":
        img[y0 : y0 + size, x0 : x0 + w] = color
    else:
        img[y0 : y0 + size, x0 + size - w : x0 + size] = color


def marked_places(game: TestGame, prop: str, majority: bool = True) -> list[int]:
    """Non-goal places worth marking with ``prop``: where it holds at some state, and with
    ``majority`` at half of the place's states at least (on fuel grids ``unsafe`` at
    fuel 0 then marks nothing, while ``ice`` at fuel 0..9 marks its cell). Hidden test
    cells in the engineer view use ``majority=False`` (``low`` holds at fuel 1 only)."""
    ts = game.ts
    n_places = len(ts.places)
    total = np.bincount(ts.place, minlength=n_places)
    has = np.array([prop in lab for lab in ts.labels], dtype=bool)
    hits = np.bincount(ts.place[has], minlength=n_places)
    goal = np.zeros(n_places, dtype=bool)
    goal[ts.place[ts.terminal]] = True
    keep = ((2 * hits >= total) if majority else np.ones(n_places, dtype=bool)) & (hits > 0) & ~goal
    return [int(p) for p in np.flatnonzero(keep)]


def hidden_propositions(game: TestGame) -> set[str]:
    """Propositions of the hidden test objective that the system objective does not
    mention (those it does are drawn as the system's own cells)."""
    objectives = game.artifact.objectives
    return propositions(parse_formula(objectives["test"])) - set(system_propositions(game))


def fuel_test_places(game: TestGame, props: set[str]) -> tuple[dict[int, list[int]], dict[int, list[int]]]:
    """Hidden test cells of a fuel grid, per fuel level ``f`` of the system:
    ``(now[f], later[f])``. ``now[f]``: cells where a proposition of ``props`` holds at
    fuel ``f`` (the test is realized by entering one with that fuel); ``later[f]``: cells
    where one holds only at a lower level (refueling's ``low`` is fuel 1 in a region:
    from fuel 8 the region is ``later``). Terminal states are left out."""
    ts = game.ts
    holds: dict[int, set[int]] = {}
    for s in range(ts.n_states):
        if ts.labels[s] & props and not ts.terminal[s]:
            holds.setdefault(game.fuel[s], set()).add(int(ts.place[s]))
    now: dict[int, list[int]] = {}
    later: dict[int, list[int]] = {}
    below: set[int] = set()
    for f in range(int(ts.max_fuel or 0) + 1):
        here = holds.get(f, set())
        now[f] = sorted(here)
        later[f] = sorted(below - here)
        below |= here
    return now, later


class GridRenderer:
    """Frames of a grid problem (see the module docstring).

    Parameters
    ----------
    game
        The test game.
    tile_size
        Pixels per cell.
    view
        ``"system"`` (what the SUT may know) or ``"engineer"`` (also the hidden test cells,
        and the doors closed out of the system's view).
    colours
        The propositions' colours by name (default :func:`proposition_colours` of the
        propositions the view shows: the system objective's, in the engineer's view all).
    """

    def __init__(self, game: TestGame, tile_size: int = 32, view: str = "system", colours: Mapping[str, RGB] | None = None) -> None:
        if view not in ("system", "engineer"):
            raise ValueError(f"unknown view {view!r}; expected 'system' or 'engineer'")
        self.game, self.size, self.view = game, tile_size, view
        self.colours = _colours_of(game, view, colours)
        ts = game.ts
        lay = ts.layout
        assert lay is not None
        self.rows, self.cols = lay.rows, lay.cols
        self.is_fuel = ts.kind == "fuel"
        self.max_fuel = int(ts.max_fuel or 0)
        size = tile_size
        status = size // 3 if self.is_fuel else 0
        img = np.empty((self.rows * size + status, self.cols * size, 3), dtype=np.uint8)
        img[:] = STATUS_BG
        for r in range(self.rows):
            for c in range(self.cols):
                blocked = (r, c) in lay.blocked
                img[r * size : (r + 1) * size, c * size : (c + 1) * size] = floor_tile(size, BLOCKED if blocked else FLOOR)
        cells = game.cells
        for p in np.unique(ts.place[ts.terminal]):
            _paint(img, *cells[int(p)], size, shape_mask("goal", size), GOAL)
        for name in system_propositions(game):
            for p in marked_places(game, name):
                _paint(img, *cells[p], size, shape_mask("mark", size), self.colours[name])
        if self.is_fuel:
            fuel = np.array(game.fuel, dtype=np.int64)
            for p in np.unique(ts.place[ts.dst[fuel[ts.dst] == self.max_fuel]]):
                _paint(img, *cells[int(p)], size, shape_mask("refuel", size), REFUEL)
        # hidden test cells (engineer view): fixed on plain grids; on fuel grids they
        # depend on the fuel level (see fuel_test_places), so frame() draws them
        self.test_now: dict[int, list[int]] = {}
        self.test_later: dict[int, list[int]] = {}
        if view == "engineer":
            test_props = hidden_propositions(game)
            if self.is_fuel:
                self.test_now, self.test_later = fuel_test_places(game, test_props)
            else:
                for name in sorted(test_props):
                    for p in marked_places(game, name, majority=False):
                        _paint(img, *cells[p], size, shape_mask("test", size), TEST_CELL)
        # walls of the map on the background; static obstacles that hold only at some
        # states of their cell (walls per fuel level) are drawn by frame() while they hold
        for m in np.flatnonzero(game.permanent_wall):
            r, c = cells[int(ts.place[ts.src[m]])]
            _edge_bar(img, r, c, size, ts.action[m], WALL, 0.12)
        self.background = img
        self.cells = cells
        self.static = game.artifact.strategy.static_obstacles
        self.permanent = game.permanent_wall

    def frame(self, run: RunState) -> np.ndarray:
        """``uint8[H, W, 3]``: the run now."""
        g, size = self.game, self.size
        ts = g.ts
        img = self.background.copy()
        if self.is_fuel and self.view == "engineer":
            fuel = g.fuel[run.system]
            for p in self.test_later.get(fuel, ()):
                _paint(img, *self.cells[p], size, shape_mask("test", size), TEST_CELL_LATER)
            for p in self.test_now.get(fuel, ()):
                _paint(img, *self.cells[p], size, shape_mask("test", size), TEST_CELL)
        if self.view == "engineer":
            for m in doors_out_of_view(g, run):
                r, c = self.cells[int(ts.place[ts.src[m]])]
                _edge_bar(img, r, c, size, ts.action[m], DOOR_OUT_OF_VIEW, 0.1)
        for m in g.shown_moves(run):
            if not self.permanent[m]:
                r, c = self.cells[int(ts.place[ts.src[m]])]
                if self.static[m]:
                    _edge_bar(img, r, c, size, ts.action[m], WALL, 0.12)
                else:
                    _edge_bar(img, r, c, size, ts.action[m], DOOR, 0.16)
        if run.agent >= 0 and g.agent_place[run.agent] >= 0:
            _paint(img, *self.cells[g.agent_place[run.agent]], size, shape_mask("agent", size), AGENT)
        _paint(img, *self.cells[g.place_list[run.system]], size, shape_mask("system", size), SYSTEM)
        if self.is_fuel:
            fuel = g.fuel[run.system]
            y0 = self.rows * size
            h = img.shape[0] - y0
            width = int(round(img.shape[1] * fuel / max(self.max_fuel, 1)))
            img[y0 + h // 4 : y0 + h - h // 4, :width] = FUEL_BAR
        return img


def _unit_rgb(color: RGB) -> tuple[float, float, float]:
    """A colour as matplotlib's floats in ``[0, 1]``."""
    return color[0] / 255, color[1] / 255, color[2] / 255


ARC_RAD = 0.12
"""Bend of the graph pictures' edges (matplotlib's ``arc3`` connection style)."""


def _arc_middles(disp: np.ndarray, src: np.ndarray, dst: np.ndarray, rad: float, height: int) -> list[np.ndarray]:
    """Pixel points ``int[k, 2]`` (row, column) of the middle 40 % of each edge's arc.

    ``disp`` are the nodes' display coordinates (y up). The arc is matplotlib's
    ``arc3``: a quadratic Bezier from ``a`` to ``b`` with control point
    ``(a + b) / 2 + rad * (dy, -dx)``, ``(dx, dy) = b - a``; so overlays lie on the drawn
    arrow rather than on the straight chord.
    """
    out: list[np.ndarray] = []
    for a, b in zip(disp[src], disp[dst], strict=True):
        d = b - a
        ctl = (a + b) / 2 + rad * np.array([d[1], -d[0]])
        n = max(2, int(np.hypot(*d)))
        t = np.linspace(0.3, 0.7, n)[:, None]
        pts = (1 - t) ** 2 * a + 2 * (1 - t) * t * ctl + t**2 * b
        out.append(np.rint(np.stack([height - pts[:, 1], pts[:, 0]], axis=1)).astype(np.int64))
    return out


def _colours_of(game: TestGame, view: str, colours: Mapping[str, RGB] | None) -> dict[str, RGB]:
    """The propositions' colours a renderer uses: ``colours`` where they name one, else
    :func:`proposition_colours` of what the view shows."""
    shown = all_propositions(game) if view == "engineer" else system_propositions(game)
    return {**proposition_colours(shown), **(colours or {})}


def doors_out_of_view(game: TestGame, run: RunState) -> list[int]:
    """The doors closed now (reactive restrictions of the run's history) out of the system's
    view (not among :meth:`~flowtest_env.game.TestGame.shown_moves`): what the engineer's
    view draws pale, so a door closed the whole run does not seem to open as the system
    walks away from it. None under another tester (its restrictions hold for one step)."""
    if run.override is not None:
        return []
    closed = np.flatnonzero(game.enforced[run.history] & ~game.artifact.strategy.static_obstacles)
    if closed.size == 0:
        return []
    shown = set(game.shown_moves(run))
    return [int(m) for m in closed if int(m) not in shown]


class GraphRenderer:
    """Node-link frames of a graph problem (see the module docstring)."""

    def __init__(self, game: TestGame, tile_size: int = 32, view: str = "system", colours: Mapping[str, RGB] | None = None) -> None:
        if view not in ("system", "engineer"):
            raise ValueError(f"unknown view {view!r}; expected 'system' or 'engineer'")
        self.colours = _colours_of(game, view, colours)
        # matplotlib is imported only when a graph is drawn: it costs start-up time to every env
        import matplotlib

        matplotlib.use("Agg", force=False)
        import networkx as nx
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.game, self.view = game, view
        ts = game.ts
        g = nx.DiGraph()
        g.add_nodes_from(range(ts.n_states))
        g.add_edges_from(zip(ts.src.tolist(), ts.dst.tolist(), strict=True))
        pos = nx.kamada_kawai_layout(g.to_undirected()) if ts.n_states > 1 else {0: np.zeros(2)}
        xy = np.array([pos[i] for i in range(ts.n_states)], dtype=float)
        px = max(240, 15 * tile_size)
        fig = Figure(figsize=(px / 100, px / 100), dpi=100)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_xlim(xy[:, 0].min() - 0.25, xy[:, 0].max() + 0.25)
        ax.set_ylim(xy[:, 1].min() - 0.25, xy[:, 1].max() + 0.25)
        ax.set_aspect("equal")
        ax.axis("off")
        fig.patch.set_facecolor(_unit_rgb(FLOOR))
        for a, b in zip(ts.src.tolist(), ts.dst.tolist(), strict=True):
            ax.annotate(
                "",
                xy=xy[b],
                xytext=xy[a],
                arrowprops={"arrowstyle": "-|>", "color": "0.55", "lw": 1.2, "shrinkA": 14, "shrinkB": 14, "connectionstyle": f"arc3,rad={ARC_RAD}"},
            )
        test_props = hidden_propositions(game) if view == "engineer" else set()
        for s in range(ts.n_states):
            face = _unit_rgb(GOAL) if ts.terminal[s] else "white"
            edge = _unit_rgb(TEST_CELL) if ts.labels[s] & test_props else "0.3"
            ax.scatter(
                [xy[s, 0]],
                [xy[s, 1]],
                s=520,
                c=[face] if not isinstance(face, str) else face,
                edgecolors=[edge] if not isinstance(edge, str) else edge,
                linewidths=2.5,
                zorder=3,
            )
            ax.text(xy[s, 0], xy[s, 1] - 0.13, printable(str(ts.states[s])), ha="center", va="top", fontsize=8, zorder=4)
        # matplotlib ships no type hints for backend_agg (FigureCanvasAgg's methods are untyped)
        canvas.draw()  # type: ignore[no-untyped-call]
        self.background = np.asarray(canvas.buffer_rgba())[:, :, :3].copy()  # type: ignore[no-untyped-call]
        # pixel coordinates of nodes (data -> display, y flipped)
        disp = ax.transData.transform(xy)
        h = self.background.shape[0]
        self.node_px = np.stack([h - disp[:, 1], disp[:, 0]], axis=1)
        self.radius = int(np.sqrt(520) / 2 * 100 / 72)  # marker points -> pixels at dpi 100
        self.src, self.dst = ts.src.copy(), ts.dst.copy()
        self.arc_px = _arc_middles(disp, self.src, self.dst, ARC_RAD, h)
        self.static = game.artifact.strategy.static_obstacles
        self.permanent = game.permanent_wall
        for m in np.flatnonzero(self.permanent):
            self._segment(self.background, int(m), WALL)

    def _disc(self, img: np.ndarray, node: int, radius: int, color: RGB) -> None:
        y, x = self.node_px[node]
        y0, y1 = int(max(0, y - radius)), int(min(img.shape[0], y + radius + 1))
        x0, x1 = int(max(0, x - radius)), int(min(img.shape[1], x + radius + 1))
        yy, xx = np.mgrid[y0:y1, x0:x1]
        mask = (yy - y) ** 2 + (xx - x) ** 2 <= radius**2
        img[y0:y1, x0:x1][mask] = color

    def _segment(self, img: np.ndarray, m: int, color: RGB) -> None:
        """Paint the middle of move ``m``'s arc (5 pixels wide): on the arc, so the two
        directions of a two-way edge, which bend to opposite sides, stay apart."""
        pts = self.arc_px[m]
        for dy in (-2, -1, 0, 1, 2):
            for dx in (-2, -1, 0, 1, 2):
                yy = np.clip(pts[:, 0] + dy, 0, img.shape[0] - 1)
                xx = np.clip(pts[:, 1] + dx, 0, img.shape[1] - 1)
                img[yy, xx] = color

    def frame(self, run: RunState) -> np.ndarray:
        """``uint8[H, W, 3]``: the run now."""
        g = self.game
        img = self.background.copy()
        if self.view == "engineer":
            for m in doors_out_of_view(g, run):
                self._segment(img, m, DOOR_OUT_OF_VIEW)
        for m in g.shown_moves(run):
            if not self.permanent[m]:
                self._segment(img, m, WALL if self.static[m] else DOOR)
        if run.agent >= 0 and g.agent_place[run.agent] >= 0:
            self._disc(img, g.agent_place[run.agent], self.radius, AGENT)
        self._disc(img, run.system, max(5, (2 * self.radius) // 3), SYSTEM)
        return img


Renderer = GridRenderer | GraphRenderer
"""A picture maker of one game (:func:`make_renderer`)."""


def make_renderer(game: TestGame, tile_size: int = 32, view: str = "system", colours: Mapping[str, RGB] | None = None) -> Renderer:
    """The renderer of a game's kind (``colours``: the propositions' colours by name)."""
    if game.is_grid:
        return GridRenderer(game, tile_size, view, colours)
    return GraphRenderer(game, tile_size, view, colours)


def ansi(game: TestGame, run: RunState, view: str = "system") -> str:
    """A text picture of the run: the grid (or the state list), restrictions, status.

    Grid legend: ``@`` system, ``A`` test agent, ``T`` goal, ``#`` blocked, ``.`` free,
    the first letter of a system proposition (``R`` refuel), ``?`` a hidden test cell
    (engineer view; on fuel grids where a test proposition holds at the current fuel
    level, ``~`` where it holds only at a lower one). Below the grid: the static walls and
    the reactive restrictions shown now (out of the system's state; in the accumulative
    setting also out of the states visited under the current history).
    """
    ts = game.ts
    lines: list[str] = []
    ap = game.agent_place[run.agent] if run.agent >= 0 else -1
    props = system_propositions(game)
    test_props = hidden_propositions(game) if view == "engineer" else set()
    if game.is_grid:
        lay = ts.layout
        assert lay is not None
        grid = [["#" if (r, c) in lay.blocked else "." for c in range(lay.cols)] for r in range(lay.rows)]
        cells = game.cells
        for goal in np.flatnonzero(ts.terminal):
            r, c = cells[int(ts.place[goal])]
            grid[r][c] = "T"
        if ts.kind == "fuel":  # as in the pictures: per fuel level, see fuel_test_places
            now, later = fuel_test_places(game, test_props)
            fuel = game.fuel[run.system]
            for mark, places in (("~", later.get(fuel, [])), ("?", now.get(fuel, []))):
                for p in places:
                    r, c = cells[p]
                    grid[r][c] = mark
        else:
            for p in sorted({p for name in test_props for p in marked_places(game, name, majority=False)}):
                r, c = cells[p]
                grid[r][c] = "?"
        for name in props:
            for p in marked_places(game, name):
                r, c = cells[p]
                grid[r][c] = name[0] if name[:1].isprintable() else "?"
        if ts.kind == "fuel":
            fuel_of = np.array(game.fuel, dtype=np.int64)
            for refuel in np.unique(ts.place[ts.dst[fuel_of[ts.dst] == ts.max_fuel]]):
                r, c = cells[int(refuel)]
                grid[r][c] = "R"
        if ap >= 0:
            r, c = cells[ap]
            grid[r][c] = "A"
        r, c = cells[game.place_list[run.system]]
        grid[r][c] = "@"
        lines += [" ".join(row) for row in grid]
    else:
        for s in range(ts.n_states):
            mark = "@" if s == run.system else ("A" if s == ap else " ")
            tag = "T" if ts.terminal[s] else ("?" if ts.labels[s] & test_props else " ")
            lines.append(f"{mark}{tag} {printable(str(ts.states[s]))}")
    shown = game.shown_moves(run)
    static = game.artifact.strategy.static_obstacles
    w = game.state_json
    for label, moves in (("walls", [m for m in shown if static[m]]), ("restricted now", [m for m in shown if not static[m]])):
        if moves:
            lines.append(f"{label}: " + ", ".join(f"{w(int(ts.src[m]))}->{w(int(ts.dst[m]))}" for m in moves))
    status = f"step {run.steps}  state {game.state_json(run.system)}  system objective {run.outcome}"
    if view == "engineer":
        desc = game.artifact.extras.get("history_descriptions")
        hist = printable(str(desc[run.history])) if desc else str(run.history)
        status += f"  history [{hist}]  test objective {'realized' if game.test_accepting[run.history] else 'open'}"
    lines.append(status)
    return "\n".join(lines) + "\n"


__all__ = ["GRID_ACTIONS", "GridRenderer", "GraphRenderer", "make_renderer", "ansi"]
