"""Named test pools with ``train`` / ``validation`` / ``test`` splits.

A pool is a seeded family of random grid problems, named::

    <family><n>/<size>x<size>[/<world>][/<kind>]

* ``<family><n>``: a spec family of :mod:`synthesis.problems.random_grid` and its size,
  ``reachability1`` .. ``reachability8``, ``reaction2`` .. ``reaction8``, ``safety2`` ..
  ``safety8``;
* ``<size>x<size>``: a square grid, ``5x5``, ``7x7``, ``10x10``...;
* ``<world>`` (default: the paper's empty grid): ``blocked`` (a fifth of the cells
  blocked) or ``fuel`` (a fuel grid: capacity ``size``, refuel cells, ``G !empty``);
  see :mod:`synthesis.problems.random_worlds`;
* ``<kind>`` (default ``reactive``): ``reactive`` (reactive doors, opening and closing
  with the history), ``static`` (walls for the whole test) or ``agent`` (a test agent
  patrolling one column, with a GR(1) strategy).

So ``reachability1/5x5`` is the paper's empty grid with reactive doors,
``reaction2/7x7/static`` the same family with static walls, ``reachability2/7x7/blocked``
blocked cells with doors, ``safety2/5x5/fuel/static`` a fuel grid with walls, and
``reachability1/5x5/blocked/agent`` blocked cells with a test agent. A name prints back
in this canonical order (world, then kind; defaults left out); the parts after the grid
may be given in either order.

A split is a range of seeds, and the ranges never overlap: ``train`` holds seeds
``0 .. SPLIT_SPAN - 1``, ``validation`` the next :data:`SPLIT_SPAN`, ``test`` the next. A
policy trained on a pool's train split and scored on its test split never met a test of
the test split (each seed names one test, :mod:`flowtest_env.random_grid`).

:func:`load_pool` gives the checked tests of a split as a plain list of artifacts (built on
demand with deterministic budgets, stored compactly per FlowTest and solver version), so
a vector env can step many of them in one batch.
"""

from __future__ import annotations

from dataclasses import dataclass

from synthesis.artifacts.artifact import TestArtifact
from synthesis.problems.random_grid import FAMILIES, family_objectives
from synthesis.problems.random_worlds import POOL_KINDS, WORLDS

from .random_grid import SPLIT_SPAN, SPLITS, build_pool

__all__ = ["SPLITS", "SPLIT_SPAN", "PoolName", "load_pool", "parse_pool", "random_grid_arguments", "split_seeds"]

FORM = "expected <family><n>/<size>x<size>[/<world>][/<kind>], e.g. reachability1/5x5 or reaction2/7x7/blocked/static"


@dataclass(frozen=True)
class PoolName:
    """A parsed pool name."""

    family: str
    n: int
    size: int
    kind: str = "reactive"
    world: str = "empty"

    def __str__(self) -> str:
        parts = [f"{self.family}{self.n}", f"{self.size}x{self.size}"]
        if self.world != "empty":
            parts.append(self.world)
        if self.kind != "reactive":
            parts.append(self.kind)
        return "/".join(parts)


def parse_pool(name: str) -> PoolName:
    """``"reachability1/5x5"`` -> :class:`PoolName` (grammar in the module docstring).

    Raises
    ------
    ValueError
        Naming what is wrong with the name.
    """
    if not isinstance(name, str):
        raise ValueError(f"a pool name is a string such as 'reachability1/5x5', not {name!r}")
    parts = name.split("/")
    if not 2 <= len(parts) <= 4:
        raise ValueError(f"pool name {name!r}: {FORM}")
    spec, grid, extra = parts[0], parts[1], parts[2:]
    family = spec.rstrip("0123456789")
    digits = spec[len(family):]
    if family not in FAMILIES or not digits:
        raise ValueError(f"pool name {name!r}: unknown family {spec!r}; expected one of {', '.join(FAMILIES)} with a size n; {FORM}")
    rows, x, cols = grid.partition("x")
    if not (x and rows.isdigit() and rows == cols and int(rows) >= 2):
        raise ValueError(f"pool name {name!r}: grid {grid!r} is not a square size such as 5x5; {FORM}")
    worlds = [p for p in extra if p in WORLDS]
    kinds = [p for p in extra if p in POOL_KINDS]
    unknown = [p for p in extra if p not in WORLDS and p not in POOL_KINDS]
    if unknown:
        raise ValueError(
            f"pool name {name!r}: unknown part {unknown[0]!r}; expected a world ({', '.join(WORLDS)}) "
            f"and/or a kind ({', '.join(POOL_KINDS)})"
        )
    if len(worlds) > 1 or len(kinds) > 1:
        twice = "world" if len(worlds) > 1 else "kind"
        raise ValueError(f"pool name {name!r}: more than one {twice} ({', '.join(worlds if twice == 'world' else kinds)}); {FORM}")
    family_objectives(family, int(digits))  # validates n for the family
    return PoolName(family, int(digits), int(rows), kinds[0] if kinds else "reactive", worlds[0] if worlds else "empty")


def split_seeds(split: str, count: int, start: int = 0) -> range:
    """The seeds ``start .. start + count - 1`` of a split.

    Raises
    ------
    ValueError
        On an unknown split, or seeds beyond the split's range.
    """
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; expected one of {', '.join(SPLITS)}")
    if count < 1 or start < 0 or start + count > SPLIT_SPAN:
        raise ValueError(f"a split holds seeds 0..{SPLIT_SPAN - 1} of its range; got start {start}, count {count}")
    base = SPLITS.index(split) * SPLIT_SPAN
    return range(base + start, base + start + count)


def load_pool(
    name: str,
    split: str = "train",
    count: int = 100,
    start: int = 0,
    parallel: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
) -> list[TestArtifact]:
    """The checked tests of ``count`` seeds of a pool's split, in seed order (built on
    demand, in process or through Ray with ``parallel="ray"``, and cached).

    ``name`` may be a standard pool id (``reachability1/5x5-v1``,
    :mod:`flowtest_env.standard_pools`): its shipped tests are loaded from their records
    (nothing synthesized), and seeds beyond the shipped ones are built on demand as for the
    pool it draws from (same seeds, same budget).

    Examples
    --------
    >>> from flowtest_env.pools import load_pool
    >>> held_out = load_pool("reachability1/5x5-v1", "test", 2)    # a standard pool: shipped, nothing synthesized
    >>> [(t.name, t.kind) for t in held_out]
    [('random-5x5-reachability1-reactive-s2000000', 'reactive'), ('random-5x5-reachability1-reactive-s2000001', 'reactive')]
    """
    from .standard_pools import is_standard, load_standard_pool, standard_pool

    if is_standard(name):
        std = standard_pool(name)
        split_seeds(split, count, start)  # validates split, start and count
        shipped = max(0, min(std.shipped(split) - start, count))
        tests = load_standard_pool(std.id, split, shipped, start) if shipped else []
        if shipped < count:
            tests += load_pool(std.pool, split, count - shipped, start + shipped, parallel, workers, progress)
        return tests
    pool = parse_pool(name)
    seeds = split_seeds(split, count, start)
    return build_pool(
        pool.size, pool.family, pool.n, seeds, pool.kind, parallel=parallel, workers=workers, progress=progress, world=pool.world
    )


def random_grid_arguments(
    pool: str | None,
    split: str,
    count: int,
    size: int,
    family: str,
    n: int | None,
    seeds: tuple[int, ...],
    kind: str,
    world: str = "empty",
) -> tuple[int, str, int, tuple[int, ...], str, str]:
    """``(size, family, n, seeds, kind, world)`` of a random-grid env: from the named
    ``pool``'s ``split`` (its first ``count`` seeds) when one is given, else the explicit
    arguments (``n`` defaults to 1 for reachability, 2 otherwise)."""
    if pool is not None:
        named = parse_pool(pool)
        return named.size, named.family, named.n, tuple(split_seeds(split, count)), named.kind, named.world
    n = n if n is not None else (1 if family == "reachability" else 2)
    return int(size), family, int(n), tuple(int(s) for s in seeds), kind, world
