"""What a test restricts, counted as a person counts it: physical walls and doors.

A test's strategy restricts moves of the system T, per history (product-graph cuts are
one level further down: one move under several histories, at several fuel levels, is many
cuts). People count the things built on the floor: a **wall** is a static restriction
between two places (cells, or states of a graph), a **door** a reactive one (restricted
under some histories only, or by a test agent), each counted once however many moves
between those two places it blocks, whichever way, under however many histories. A wall
is **one-way** when it blocks a move between its places while a move back is left open.

Counted from the strategy alone, independently of the routing model's cut groups, so the
caps (``max_walls``, ``max_doors``, ``max_restrictions``) are checked here against what
the environment will enforce.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.strategy import TestStrategy
from ..model.systems import TransitionSystem


@dataclass(frozen=True)
class PhysicalCounts:
    """A test's walls and doors, each an ordered pair of place indices ``(a, b)`` with
    ``a <= b``; ``one_way_walls`` the walls that leave a move between their places open."""

    walls: list[tuple[int, int]]
    doors: list[tuple[int, int]]
    one_way_walls: list[tuple[int, int]]

    @property
    def restrictions(self) -> int:
        """Walls and doors together."""
        return len(self.walls) + len(self.doors)

    def as_dict(self) -> dict[str, int]:
        """``{"walls", "doors", "restrictions", "one_way_walls"}`` as counts (the JSON summary's)."""
        return {
            "walls": len(self.walls),
            "doors": len(self.doors),
            "restrictions": self.restrictions,
            "one_way_walls": len(self.one_way_walls),
        }


def _pairs(ts: TransitionSystem, moves: np.ndarray) -> set[tuple[int, int]]:
    """The unordered place pairs of these moves (a blocked stay is the pair ``(a, a)``)."""
    a = ts.place[ts.src[moves]].astype(np.int64)
    b = ts.place[ts.dst[moves]].astype(np.int64)
    return {(int(min(x, y)), int(max(x, y))) for x, y in zip(a, b, strict=True)}


def physical_counts(ts: TransitionSystem, strategy: TestStrategy) -> PhysicalCounts:
    """The walls, doors and one-way walls of a test (see the module docstring).

    Example
    -------
    >>> from synthesis.problems.builtins import load_builtin  # doctest: +SKIP
    >>> physical_counts(test.problem.system, test.strategy).as_dict()  # doctest: +SKIP
    {'walls': 2, 'doors': 0, 'restrictions': 2, 'one_way_walls': 0}
    """
    static = np.asarray(strategy.static_obstacles, dtype=bool)
    reactive = np.asarray(strategy.restrictions, dtype=bool).any(axis=0) & ~static
    walls = _pairs(ts, np.flatnonzero(static))
    doors = _pairs(ts, np.flatnonzero(reactive))
    # a wall is one-way when some move between its two places stays open for the whole test
    between = _open_between(ts, static, walls)
    return PhysicalCounts(sorted(walls), sorted(doors), sorted(between))


def _open_between(ts: TransitionSystem, static: np.ndarray, walls: set[tuple[int, int]]) -> set[tuple[int, int]]:
    """The walls with an unblocked move between their places (either way)."""
    if not walls:
        return set()
    open_moves = np.flatnonzero(~static)
    return walls & _pairs(ts, open_moves)


def cap_count(counts: PhysicalCounts, cap: str) -> int:
    """What a cap (``max_walls``, ``max_doors``, ``max_restrictions``) counts of a test."""
    if cap == "max_walls":
        return len(counts.walls)
    if cap == "max_doors":
        return len(counts.doors)
    if cap == "max_restrictions":
        return counts.restrictions
    raise ValueError(f"unknown cap {cap!r}")
