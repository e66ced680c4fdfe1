"""What the routing model is built on (docs/method.md §5): the cut groups (the edges of G that
must share one cut value, :func:`cut_groups`: c9, c14 and fuel ties), the moves cut as walls
(:func:`static_moves_of`), the physical restriction each group stands for (a wall or a door,
:func:`physical_items`: what the caps count), and the edges of G the model keeps
(:func:`model_edges`, with the routing heuristic on them). :mod:`synthesis.routing.model`
builds the model on them; the caps' bounds (:mod:`synthesis.routing.caps`) and the hitting
set's separator read them without a model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..graphs.products import Products
from ..model.systems import TransitionSystem
from ..problems.problem import TIE_PLACES
from .options import MODES, MilpOptions


@dataclass(frozen=True)
class CutGroups:
    """Edges of G grouped by shared cut value.

    ``of_edge[e]`` is the group of edge ``e`` (every edge has one; groups of
    unrestrictable edges are never cut), ``keys[g]`` its stable key, ``weight[g]``
    the number of edges of G it stands for, ``restrictable[g]`` whether it may be cut,
    ``static[g]`` whether it is a static (history-independent) group.
    """

    of_edge: np.ndarray
    keys: np.ndarray
    weight: np.ndarray
    restrictable: np.ndarray
    static: np.ndarray
    move_key: np.ndarray  # per move of T, its static tie key


def cut_groups(products: Products, options: MilpOptions) -> CutGroups:
    """Group the edges of G by the cut value they must share (c9, c14, fuel ties).

    A static edge's key is its move's tie key ``a * n_s + b``: ``a``, ``b`` its ends as
    places when ``tie_places`` ties static cuts (``n_s`` places), else as states (sorted
    under c14). A reactive edge's key is ``n_s^2 + history * n_r^2 + a * n_r + b``, its ends
    as places only when ``tie_places`` is ``"all"``. So static keys are below ``n_s^2``, and
    the keys of ``"none"`` and ``"all"`` are what they were before ``"static"`` existed, as
    are those of ``"static"`` and ``"all"`` on a problem without reactive moves.
    """
    ts, g = products.ts, products.virtual
    static_moves = static_moves_of(products, options)
    if options.tie_places not in TIE_PLACES:
        raise ValueError(f"unknown tie_places {options.tie_places!r}; expected one of {TIE_PLACES}")
    states = np.arange(ts.n_states, dtype=np.int32)
    static_place = ts.place if options.tie_places != "none" else states
    reactive_place = ts.place if options.tie_places == "all" else states

    def pair_key(place: np.ndarray) -> tuple[np.ndarray, np.int64]:
        """Each move's key over ``place`` and the size of that key space."""
        n = np.int64(int(place.max()) + 1)
        a = place[ts.src].astype(np.int64)
        b = place[ts.dst].astype(np.int64)
        if options.bidirectional:
            a, b = np.minimum(a, b), np.maximum(a, b)
        return a * n + b, n * n

    move_key, span = pair_key(static_place)  # static tie key of each move
    restrictable = ts.restrictable
    if not options.one_way_walls:
        # walls block both ways: the two directions of a static move share one key, and a
        # static move whose move back is not static cannot be a wall at all
        n_pl = np.int64(int(static_place.max()) + 1)
        a = static_place[ts.src].astype(np.int64)
        b = static_place[ts.dst].astype(np.int64)
        move_key = np.minimum(a, b) * n_pl + np.maximum(a, b)
        restrictable = restrictable & ~(static_moves & _back_not_static(ts, static_moves))
    reactive_key, reactive_span = pair_key(reactive_place)
    is_static = static_moves[g.move]
    history = g.hist[g.src].astype(np.int64)
    key = np.where(is_static, move_key[g.move], span + history * reactive_span + reactive_key[g.move])
    keys, of_edge = np.unique(key, return_inverse=True)
    of_edge = of_edge.ravel()
    n = keys.size
    weight = np.bincount(of_edge, minlength=n)
    unrestrictable = np.bincount(of_edge, weights=~restrictable[g.move], minlength=n) > 0
    return CutGroups(
        of_edge=of_edge,
        keys=keys,
        weight=weight,
        restrictable=~unrestrictable,
        static=keys < span,
        move_key=move_key,
    )


def _back_not_static(ts: TransitionSystem, static_moves: np.ndarray) -> np.ndarray:
    """``bool`` per move: a move back exists (between the same two states) and is not static."""
    n = np.int64(ts.n_states)
    fwd = ts.src.astype(np.int64) * n + ts.dst
    back = ts.dst.astype(np.int64) * n + ts.src
    order = np.argsort(fwd)
    pos = np.minimum(np.searchsorted(fwd[order], back), fwd.size - 1)
    exists = fwd[order][pos] == back
    out: np.ndarray = exists & ~static_moves[order[pos]]
    return out


def static_moves_of(products: Products, options: MilpOptions) -> np.ndarray:
    n = products.ts.n_moves
    if options.mode == "static":
        return np.ones(n, dtype=bool)
    if options.mode == "reactive":
        return np.zeros(n, dtype=bool)
    if options.mode == "mixed":
        if options.static_moves is None:
            raise ValueError("a mixed MILP needs static_moves")
        return np.asarray(options.static_moves, dtype=bool)
    raise ValueError(f"unknown MILP mode {options.mode!r}; expected one of {MODES}")


@dataclass(frozen=True)
class PhysicalItems:
    """The physical restrictions the cut groups stand for: a wall (a static group) or a door
    (a reactive one) on the move between two places, whichever way and under whichever
    history: ``of_group[g]`` is group ``g``'s item, ``is_wall[i]`` whether item ``i`` is a
    wall, ``places[i]`` its two places (the lower index first)."""

    of_group: np.ndarray
    is_wall: np.ndarray
    places: np.ndarray

    def counts(self, cut: np.ndarray) -> dict[str, int]:
        """``{"walls": .., "doors": ..}`` used by a cut set (``bool`` per group)."""
        used = np.zeros(self.is_wall.size, dtype=bool)
        used[self.of_group[cut]] = True
        walls = int((used & self.is_wall).sum())
        return {"walls": walls, "doors": int(used.sum()) - walls}

    def kinds(self, cap: str) -> np.ndarray:
        """``bool`` per item: counted by the cap ``cap`` (a key of :data:`CAP_KEYS`)."""
        if cap == "max_walls":
            return self.is_wall
        if cap == "max_doors":
            out: np.ndarray = ~self.is_wall
            return out
        return np.ones(self.is_wall.size, dtype=bool)

    def n_counted(self, cut: np.ndarray, caps: dict[str, int]) -> int:
        """How many items of the cut set some cap of ``caps`` counts."""
        used = np.zeros(self.is_wall.size, dtype=bool)
        used[self.of_group[cut]] = True
        counted = np.zeros(self.is_wall.size, dtype=bool)
        for cap in caps:
            counted |= self.kinds(cap)
        return int((used & counted).sum())

    def over_cap(self, cut: np.ndarray, caps: dict[str, int]) -> list[tuple[str, np.ndarray]]:
        """The caps a cut set exceeds, each with the items it uses that the cap counts."""
        used = np.zeros(self.is_wall.size, dtype=bool)
        used[self.of_group[cut]] = True
        out = []
        for cap, limit in caps.items():
            items = np.flatnonzero(used & self.kinds(cap))
            if items.size > limit:
                out.append((cap, items))
        return out


def physical_items(products: Products, groups: CutGroups) -> PhysicalItems:
    """The physical restriction of each cut group (:class:`PhysicalItems`). Every edge of a
    group lies over moves between the same two places (its key is a pair of places or of
    states, the states of one place pair), so one edge of each group names its item."""
    ts, g = products.ts, products.virtual
    n = groups.keys.size
    rep = np.zeros(n, dtype=np.int64)
    rep[groups.of_edge] = np.arange(groups.of_edge.size)
    move = g.move[rep]
    a = ts.place[ts.src[move]].astype(np.int64)
    b = ts.place[ts.dst[move]].astype(np.int64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    span = np.int64(int(ts.place.max()) + 1) if ts.place.size else np.int64(1)
    key = (~groups.static).astype(np.int64) * span * span + lo * span + hi
    uniq, of_group = np.unique(key, return_inverse=True)
    return PhysicalItems(
        of_group=of_group.ravel(),
        is_wall=uniq < span * span,
        places=np.stack([(uniq % (span * span)) // span, uniq % span], axis=1),
    )
