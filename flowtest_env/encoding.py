"""Observation encoders: what the system under test sees of a test run.

Two encodings, both built once per :class:`~flowtest_env.game.TestGame`:

* ``"grid"`` (grid problems only): an image-like ``uint8[C, H, W]`` array, channel first,
  values ``0`` or ``255`` (fuel scaled to ``0..255``), so stable-baselines3 takes it as an
  image. Channels, in order:

  ====================  =========================================================
  ``free``              the cell is a state of the system (not blocked)
  ``wall_N..wall_W``    a static obstacle on the move out of the cell, per direction:
                        the walls of the map, and the static obstacles that hold only
                        at some states of a cell (walls per fuel level) while shown
  ``door_N..door_W``    a reactive restriction shown now on the move out of the cell
  ``test_agent``        the test agent's cell
  ``system``            the system's own cell
  ``goal``              the goal (terminal) cells
  ``<p>``               one per proposition of the *system* objective other than the
                        goal (e.g. ``ice``, ``rock``, ``dropoff``): cells where it holds
                        at the system's current fuel level
  ``refuel``            refuel cells (fuel problems)
  ``fuel``              constant plane, current fuel / max fuel (fuel problems)
  ``objective_<i>``     constant plane, one-hot progress of the system objective
                        (its automaton state), when it has more than one state
  ====================  =========================================================

* ``"flat"``: a ``float32`` vector in ``[0, 1]``. Grid problems: the spatial channels
  above flattened (``free`` .. ``refuel``), then one entry per action slot (restricted
  now, the test agent's block included), then the fuel fraction (fuel problems), then
  the objective progress one-hot. Graph problems: one-hot of the system's state, the
  test agent's state, the goal states, one block per system proposition, one entry per
  move of the system (restriction shown now), the action slots, the objective progress.

* ``"padded"`` (grid problems up to ``pad_to x pad_to``): one shape for every test, so one
  policy plays many (:class:`PaddedEncoder`).

Never encoded: the test objective's cells or propositions, the history, the
test-objective part of the history, the agent's strategy memory.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from synthesis.model.specs import parse_formula, propositions

from .game import GRID_ACTIONS, RunState, TestGame

DIRS = GRID_ACTIONS


class EncodingError(ValueError):
    """An observation kind the problem does not support."""


@functools.lru_cache(maxsize=256)
def _objective_propositions(text: str) -> tuple[str, ...]:
    """The propositions of an objective, sorted (a pool's tests share a few objectives)."""
    return tuple(sorted(propositions(parse_formula(text))))


def _holds(game: TestGame, props: Sequence[str]) -> np.ndarray:
    """``bool[n_states, len(props)]``: which of ``props`` hold at each state."""
    ts = game.ts
    out = np.zeros((ts.n_states, len(props)), dtype=bool)
    if props:
        col = {p: i for i, p in enumerate(props)}
        for s, label in enumerate(ts.labels):
            for p in label:
                i = col.get(p)
                if i is not None:
                    out[s, i] = True
    return out


def system_propositions(game: TestGame) -> list[str]:
    """Propositions of the system objective worth showing: all but those that hold only at
    terminal (goal) states, sorted."""
    props = _objective_propositions(game.artifact.objectives["system"])
    holds = _holds(game, props)
    somewhere = [bool(v) for v in np.any(holds, axis=0)]
    elsewhere = [bool(v) for v in np.any(holds & ~np.asarray(game.ts.terminal, dtype=bool)[:, None], axis=0)]
    return [p for i, p in enumerate(props) if elsewhere[i] or not somewhere[i]]


@dataclass(frozen=True)
class Segment:
    """One named part of an observation.

    ``obs[start:stop]`` (flat and padded observations) or ``obs[start:stop]`` along the
    channel axis (``"grid"`` observations) holds it; ``shape`` is how to view that part
    (``(H, W)`` for a plane of a flat observation, ``(n,)`` for a vector).
    """

    name: str
    start: int
    stop: int
    shape: tuple[int, ...]
    what: str

    @property
    def size(self) -> int:
        """Number of entries (channels for a ``"grid"`` observation)."""
        return self.stop - self.start

    def of(self, obs: np.ndarray) -> np.ndarray:
        """This part of ``obs`` (one observation, or a batch: the last axes), viewed as
        :attr:`shape`."""
        obs = np.asarray(obs)
        if obs.ndim >= 3 and len(self.shape) == 2 and self.size == 1:  # grid: [..., C, H, W]
            return obs[..., self.start, :, :]
        part = obs[..., self.start : self.stop]
        return part.reshape(*part.shape[:-1], *self.shape)


@dataclass(frozen=True)
class ObservationLayout:
    """Which entries of an observation are which (:func:`flowtest_env.observation_layout`).

    ``kind`` is the ``obs_kind`` (``"flat"``, ``"padded"`` or ``"grid"``); ``shape`` the
    observation's; ``segments`` in order, covering every entry once (a ``"grid"``
    observation's segments are its channels). ``position`` is the segment that holds the
    one-hot of the SUT's own place (the ``system`` plane, or the place block on graphs);
    ``grid`` the ``(rows, cols)`` its planes are laid on (``None`` on graphs).
    """

    kind: str
    shape: tuple[int, ...]
    segments: tuple[Segment, ...]
    position: str
    grid: tuple[int, int] | None

    def __getitem__(self, name: str) -> Segment:
        for seg in self.segments:
            if seg.name == name:
                return seg
        raise KeyError(f"no segment {name!r}; the segments are {', '.join(s.name for s in self.segments)}")

    def names(self) -> list[str]:
        """The segment names, in order."""
        return [s.name for s in self.segments]

    def with_memory(self, size: int, kind: str = "visited") -> ObservationLayout:
        """The layout with the place memory of ``kind`` (``size`` entries, laid out as the
        position segment; :mod:`flowtest_env.memory`) appended, as the segment named
        ``kind`` (``"visited"`` or ``"counts"``)."""
        from .memory import MEANINGS

        pos = self[self.position]
        end = self.segments[-1].stop
        seg = Segment(kind, end, end + size, pos.shape, MEANINGS[kind])
        return ObservationLayout(self.kind, (end + size,), (*self.segments, seg), self.position, self.grid)


Part = tuple[str, int, tuple[int, ...], str]
"""A segment to lay out: name, size, shape, meaning."""


def _segments(parts: list[Part]) -> tuple[Segment, ...]:
    out, i = [], 0
    for name, size, shape, what in parts:
        out.append(Segment(name, i, i + size, shape, what))
        i += size
    return tuple(out)


CHANNEL_MEANINGS: dict[str, str] = {
    "free": "the cell is a state of the system (not blocked)",
    "test_agent": "the test agent's cell",
    "system": "the SUT's own cell",
    "goal": "the goal (terminal) cells",
    "subgoal": "cells of any proposition of the system objective other than the goal",
    "refuel": "refuel cells",
    "fuel": "constant plane: fuel / max fuel",
    **{f"wall_{d}": f"a static obstacle on the move {d} out of the cell" for d in DIRS},
    **{f"door_{d}": f"a reactive restriction shown now on the move {d} out of the cell" for d in DIRS},
}


def _meaning(channel: str) -> str:
    if channel in CHANNEL_MEANINGS:
        return CHANNEL_MEANINGS[channel]
    if channel.startswith("objective_"):
        return f"constant plane: the system objective's automaton is in state {channel[len('objective_') :]}"
    return f"cells where the system objective's proposition {channel!r} holds at the current fuel level"


class Encoder:
    """Common interface of the encoders."""

    obs_kind: str
    space: spaces.Box

    def layout(self) -> ObservationLayout:  # pragma: no cover - interface
        """Which entries of this encoder's observations are which."""
        raise NotImplementedError

    def encode(self, run: RunState) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def position_slice(self) -> slice:  # pragma: no cover - interface
        """Where a flat observation holds the one-hot of the SUT's own place."""
        raise NotImplementedError


class GridEncoder(Encoder):
    """Image-like and flat encodings of a grid problem (see the module docstring)."""

    def __init__(self, game: TestGame, obs_kind: str = "grid") -> None:
        if not game.is_grid:
            raise EncodingError(f"problem {game.artifact.name!r} is a graph: only obs_kind='flat' is available")
        if obs_kind not in ("grid", "flat"):
            raise EncodingError(f"unknown obs_kind {obs_kind!r}; expected 'grid' or 'flat'")
        self.game = game
        self.obs_kind = obs_kind
        ts = game.ts
        lay = ts.layout
        assert lay is not None
        self.rows, self.cols = H, W = lay.rows, lay.cols
        self.fuel = np.array(game.fuel, dtype=np.int64)
        self.max_fuel = int(ts.max_fuel or 0)
        self.sys_props = system_propositions(game)
        names = ["free", *(f"wall_{d}" for d in DIRS), *(f"door_{d}" for d in DIRS), "test_agent", "system", "goal"]
        names += self.sys_props
        self.is_fuel = ts.kind == "fuel"
        if self.is_fuel:
            names.append("refuel")
        self.n_spatial = len(names)
        if self.is_fuel:
            names.append("fuel")
        self.n_qsys = int(game.artifact.system_automaton.n_states)
        if self.n_qsys > 1:
            names += [f"objective_{i}" for i in range(self.n_qsys)]
        self.channels: list[str] = names
        ch = {n: i for i, n in enumerate(names)}
        self.ch = ch
        cell = game.cells
        self.cell_r = np.array([c[0] for c in cell], dtype=np.int64)
        self.cell_c = np.array([c[1] for c in cell], dtype=np.int64)
        base = np.zeros((len(names), H, W), dtype=np.uint8)
        base[ch["free"], self.cell_r, self.cell_c] = 255
        static = game.artifact.strategy.static_obstacles
        for m in np.flatnonzero(game.permanent_wall):  # the other static ones: per step
            p = int(ts.place[ts.src[m]])
            base[ch[f"wall_{ts.action[m]}"], self.cell_r[p], self.cell_c[p]] = 255
        goal_places = np.unique(ts.place[ts.terminal])
        base[ch["goal"], self.cell_r[goal_places], self.cell_c[goal_places]] = 255
        if self.is_fuel:
            refill = ts.dst[self.fuel[ts.dst] == self.max_fuel]
            rp = np.unique(ts.place[refill])
            base[ch["refuel"], self.cell_r[rp], self.cell_c[rp]] = 255
        self.base = base
        # proposition planes per fuel level
        levels = self.max_fuel + 1
        prop_planes = np.zeros((levels, len(self.sys_props), H, W), dtype=np.uint8)
        s_at, i_at = np.nonzero(_holds(game, self.sys_props))
        place_at = ts.place[s_at]
        prop_planes[self.fuel[s_at], i_at, self.cell_r[place_at], self.cell_c[place_at]] = 255
        self.prop_planes = prop_planes
        self.prop_start = ch["goal"] + 1
        self.door_start = ch["door_N"]
        self.wall_start = ch["wall_N"]
        self.dir_of_move = np.array([DIRS.index(a) for a in ts.action], dtype=np.int64)
        self.move_cell = np.stack([self.cell_r[ts.place[ts.src]], self.cell_c[ts.place[ts.src]]], axis=1)
        self.permanent = game.permanent_wall.copy()
        # the plane a shown restriction is written to: -1 a wall of the map (already on the
        # base), a wall plane for a static obstacle of this state only, else a door plane
        plane = np.where(static, self.wall_start + self.dir_of_move, self.door_start + self.dir_of_move)
        self.shown_plane = np.where(self.permanent, -1, plane)
        self.shown_plane_list = self.shown_plane.tolist()
        self.place_list = ts.place.tolist()
        self.cell_r_list = self.cell_r.tolist()
        self.cell_c_list = self.cell_c.tolist()
        self.fuel_list = self.fuel.tolist()
        self.qsys_list = game.q_sys.tolist()
        self.n_slots = game.n_slots
        # flat fast path: the spatial planes as one float vector, written by index
        hw = H * W
        self.hw = hw
        self.flat_base = base[: self.n_spatial].ravel().astype(np.float32) / 255.0
        n_props = len(self.sys_props)
        self.flat_props = prop_planes.reshape(levels, n_props * hw).astype(np.float32) / 255.0 if n_props else None
        self.flat_cell = (self.cell_r * W + self.cell_c).tolist()
        self.move_flat = np.where(self.permanent, -1, self.shown_plane * hw + self.move_cell[:, 0] * W + self.move_cell[:, 1]).tolist()
        self.tail_size = self.n_slots + (1 if self.is_fuel else 0) + self.n_qsys
        if obs_kind == "grid":
            self.space = spaces.Box(0, 255, shape=base.shape, dtype=np.uint8)
        else:
            n = self.n_spatial * H * W + self.n_slots + (1 if self.is_fuel else 0) + self.n_qsys
            self.space = spaces.Box(0.0, 1.0, shape=(n,), dtype=np.float32)

    def position_slice(self) -> slice:
        """The ``system`` plane of the flat observation."""
        start = self.ch["system"] * self.hw
        return slice(start, start + self.hw)

    def layout(self) -> ObservationLayout:
        H, W = self.rows, self.cols
        if self.obs_kind == "grid":
            segs = tuple(Segment(c, i, i + 1, (H, W), _meaning(c)) for i, c in enumerate(self.channels))
            return ObservationLayout("grid", tuple(self.space.shape), segs, "system", (H, W))
        parts: list[Part] = [(c, self.hw, (H, W), _meaning(c)) for c in self.channels[: self.n_spatial]]
        parts.append(("restricted_now", self.n_slots, (self.n_slots,), f"per action slot ({', '.join(DIRS)}): restricted now"))
        if self.is_fuel:
            parts.append(("fuel", 1, (1,), "fuel / max fuel"))
        parts.append(("objective", self.n_qsys, (self.n_qsys,), "one-hot: the system objective's automaton state"))
        return ObservationLayout("flat", tuple(self.space.shape), _segments(parts), "system", (H, W))

    def planes(self, run: RunState) -> np.ndarray:
        """The ``uint8[C, H, W]`` encoding of ``run``."""
        g = self.game
        obs = self.base.copy()
        s = run.system
        # shown restrictions (walls of the map are already on the wall planes)
        for m in g.shown_moves(run):
            k = self.shown_plane_list[m]
            if k >= 0:
                r, c = self.move_cell[m]
                obs[k, r, c] = 255
        ch = self.ch
        if run.agent >= 0:
            ap = g.agent_place[run.agent]
            if ap >= 0:
                obs[ch["test_agent"], self.cell_r_list[ap], self.cell_c_list[ap]] = 255
        p = self.place_list[s]
        obs[ch["system"], self.cell_r_list[p], self.cell_c_list[p]] = 255
        f = self.fuel_list[s]
        if self.sys_props:
            obs[self.prop_start : self.prop_start + len(self.sys_props)] = self.prop_planes[f]
        if self.is_fuel:
            obs[ch["fuel"]] = (255 * f) // max(self.max_fuel, 1)
        if self.n_qsys > 1:
            obs[ch["objective_0"] + self.qsys_list[run.history]] = 255
        return obs

    def encode(self, run: RunState) -> np.ndarray:
        if self.obs_kind == "grid":
            return self.planes(run)
        g, hw, ch = self.game, self.hw, self.ch
        n = self.flat_base.size
        obs = np.zeros(n + self.tail_size, dtype=np.float32)
        obs[:n] = self.flat_base
        for m in g.shown_moves(run):
            i = self.move_flat[m]
            if i >= 0:
                obs[i] = 1.0
        if run.agent >= 0:
            ap = g.agent_place[run.agent]
            if ap >= 0:
                obs[ch["test_agent"] * hw + self.flat_cell[ap]] = 1.0
        s = run.system
        obs[ch["system"] * hw + self.flat_cell[self.place_list[s]]] = 1.0
        f = self.fuel_list[s]
        if self.flat_props is not None:
            start = self.prop_start * hw
            obs[start : start + self.flat_props.shape[1]] = self.flat_props[f]
        if not run.done:
            bits = g.restricted_bits_of(run) & g.exists_bits[s]
            k = 0
            while bits:
                if bits & 1 and k < self.n_slots:
                    obs[n + k] = 1.0
                bits >>= 1
                k += 1
        i = n + self.n_slots
        if self.is_fuel:
            obs[i] = f / max(self.max_fuel, 1)
            i += 1
        obs[i + self.qsys_list[run.history]] = 1.0
        return obs


PADDED_CHANNELS = (
    "free",
    *(f"wall_{d}" for d in DIRS),
    *(f"door_{d}" for d in DIRS),
    "test_agent",
    "system",
    "goal",
    "subgoal",
    "refuel",
)
"""The channels of ``obs_kind="padded"``: the same for every grid test."""


class PaddedEncoder(Encoder):
    """One observation shape for every grid test up to ``pad_to x pad_to`` cells, so one
    policy can play many tests: the ``"grid"`` planes with the test-specific ones merged
    (``subgoal``: any proposition of the system objective other than the goal, at the
    current fuel level), placed in the top-left corner of a ``pad_to x pad_to`` grid
    (cells outside the test are not ``free``), flattened to ``float32`` in ``[0, 1]``,
    then the restricted-now bit of each of the four moves and the fuel fraction (0
    without fuel). Dropped from ``"flat"``: the objective-progress one-hot (its length
    differs between tests) and which sub-goal a ``subgoal`` cell is."""

    def __init__(self, game: TestGame, pad_to: int = 8) -> None:
        if not game.is_grid:
            raise EncodingError(f"problem {game.artifact.name!r} is a graph: obs_kind='padded' needs a grid")
        self.inner = GridEncoder(game, "grid")
        self.game = game
        self.obs_kind = "padded"
        size = int(pad_to)
        if self.inner.rows > size or self.inner.cols > size:
            raise EncodingError(f"problem {game.artifact.name!r} is a {self.inner.rows}x{self.inner.cols} grid: larger than pad_to={size}")
        self.pad_to = size
        self.hw = size * size
        ch = self.inner.ch
        direct = [c for c in PADDED_CHANNELS if c in ch and c != "subgoal"]
        self.src = np.array([ch[c] for c in direct], dtype=np.int64)
        self.dst = np.array([PADDED_CHANNELS.index(c) for c in direct], dtype=np.int64)
        self.sub = np.arange(self.inner.prop_start, self.inner.prop_start + len(self.inner.sys_props))
        self.n_spatial = len(PADDED_CHANNELS) * self.hw
        self.space = spaces.Box(0.0, 1.0, shape=(self.n_spatial + 4 + 1,), dtype=np.float32)

    def position_slice(self) -> slice:
        start = PADDED_CHANNELS.index("system") * self.hw
        return slice(start, start + self.hw)

    def layout(self) -> ObservationLayout:
        S = self.pad_to
        parts: list[Part] = [(c, self.hw, (S, S), _meaning(c)) for c in PADDED_CHANNELS]
        parts.append(("restricted_now", 4, (4,), f"per move ({', '.join(DIRS[:4])}): restricted now"))
        parts.append(("fuel", 1, (1,), "fuel / max fuel (0 without fuel)"))
        return ObservationLayout("padded", tuple(self.space.shape), _segments(parts), "system", (S, S))

    def encode(self, run: RunState) -> np.ndarray:
        inner, S = self.inner, self.pad_to
        planes = inner.planes(run)
        grid = np.zeros((len(PADDED_CHANNELS), S, S), dtype=np.float32)
        H, W = inner.rows, inner.cols
        grid[self.dst, :H, :W] = planes[self.src]
        if self.sub.size:
            grid[PADDED_CHANNELS.index("subgoal"), :H, :W] = planes[self.sub].max(axis=0)
        obs = np.zeros(self.space.shape[0], dtype=np.float32)
        obs[: self.n_spatial] = grid.ravel() / 255.0
        g = self.game
        if not run.done:
            bits = g.restricted_bits_of(run) & g.exists_bits[run.system]
            for k in range(min(4, g.n_slots)):
                if (bits >> k) & 1:
                    obs[self.n_spatial + k] = 1.0
        if inner.is_fuel:
            obs[-1] = inner.fuel_list[run.system] / max(inner.max_fuel, 1)
        return obs


class GraphEncoder(Encoder):
    """Flat encoding of a graph problem (see the module docstring)."""

    def __init__(self, game: TestGame, obs_kind: str = "flat") -> None:
        if obs_kind != "flat":
            raise EncodingError(f"problem {game.artifact.name!r} is a graph: only obs_kind='flat' is available, not {obs_kind!r}")
        self.game = game
        self.obs_kind = obs_kind
        ts = game.ts
        self.n_places = P = len(ts.places)
        self.sys_props = system_propositions(game)
        self.n_qsys = int(game.artifact.system_automaton.n_states)
        self.n_moves = ts.n_moves
        self.n_slots = game.n_slots
        static = np.zeros(P * (3 + len(self.sys_props)), dtype=np.float32)
        goal = np.unique(ts.place[ts.terminal])
        static[2 * P + goal] = 1.0
        for s in range(ts.n_states):
            for i, name in enumerate(self.sys_props):
                if name in ts.labels[s]:
                    static[(3 + i) * P + int(ts.place[s])] = 1.0
        self.static = static
        self.move_off = static.size
        self.slot_off = self.move_off + self.n_moves
        self.q_off = self.slot_off + self.n_slots
        self.size = self.q_off + self.n_qsys
        self.place_list = ts.place.tolist()
        self.qsys_list = game.q_sys.tolist()
        self.space = spaces.Box(0.0, 1.0, shape=(self.size,), dtype=np.float32)

    def position_slice(self) -> slice:
        """The one-hot of the system's place comes first."""
        return slice(0, self.n_places)

    def layout(self) -> ObservationLayout:
        P = self.n_places
        parts: list[Part] = [
            ("system", P, (P,), "one-hot: the SUT's place"),
            ("test_agent", P, (P,), "one-hot: the test agent's place"),
            ("goal", P, (P,), "the goal (terminal) places"),
        ]
        parts += [(f"prop_{p}", P, (P,), _meaning(p)) for p in self.sys_props]
        parts.append(("shown_restriction", self.n_moves, (self.n_moves,), "per move of the system: a restriction shown now"))
        parts.append(("restricted_now", self.n_slots, (self.n_slots,), "per action slot: restricted now"))
        parts.append(("objective", self.n_qsys, (self.n_qsys,), "one-hot: the system objective's automaton state"))
        return ObservationLayout("flat", tuple(self.space.shape), _segments(parts), "system", None)

    def encode(self, run: RunState) -> np.ndarray:
        g = self.game
        obs = np.zeros(self.size, dtype=np.float32)
        obs[: self.move_off] = self.static
        obs[self.place_list[run.system]] = 1.0
        if run.agent >= 0 and g.agent_place[run.agent] >= 0:
            obs[self.n_places + g.agent_place[run.agent]] = 1.0
        for m in g.shown_moves(run):
            obs[self.move_off + m] = 1.0
        if not run.done:
            bits = g.restricted_bits_of(run) & g.exists_bits[run.system]
            for k in range(self.n_slots):
                if (bits >> k) & 1:
                    obs[self.slot_off + k] = 1.0
        obs[self.q_off + self.qsys_list[run.history]] = 1.0
        return obs


OBS_KINDS = ("flat", "grid", "padded")
"""The observation kinds (see the module docstring)."""


def make_encoder(game: TestGame, obs_kind: str, pad_to: int = 8) -> Encoder:
    """The encoder of ``obs_kind`` for ``game`` (``pad_to``: the grid side of ``"padded"``).

    Raises
    ------
    EncodingError
        On an unknown kind, ``"grid"`` or ``"padded"`` for a graph problem, or a grid
        larger than ``pad_to``.
    """
    if obs_kind not in OBS_KINDS:
        raise EncodingError(f"unknown obs_kind {obs_kind!r}; expected one of {', '.join(OBS_KINDS)}")
    if obs_kind == "padded":
        return PaddedEncoder(game, pad_to)
    if game.is_grid:
        return GridEncoder(game, obs_kind)
    return GraphEncoder(game, obs_kind)
