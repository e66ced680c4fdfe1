"""Named test pools with ``train`` / ``validation`` / ``test`` splits (issue 16, point 1).

A pool is a seeded family of random grid problems, named ``<family><n>/<size>x<size>``
with an optional ``/static`` (default reactive), e.g. ``reachability1/5x5`` or
``reaction2/7x7/static``; the families are those of :mod:`synthesis.problems.random_grid`. A split
is a range of seeds, and the ranges never overlap: ``train`` holds seeds
``0 .. SPLIT_SPAN - 1``, ``validation`` the next :data:`SPLIT_SPAN`, ``test`` the next. A
policy trained on a pool's train split and scored on its test split never met a test of
the test split (each seed names one test, :mod:`flowtest_env.random_grid`).

:func:`load_pool` gives the checked tests of a split as a plain list of artifacts (built on
demand with deterministic budgets, cached per FlowTest and solver version), so a vector
env can step many of them in one batch.
"""

from __future__ import annotations

from dataclasses import dataclass

from synthesis.artifacts.artifact import TestArtifact
from synthesis.problems.random_grid import FAMILIES, family_objectives

from .random_grid import build_pool

__all__ = ["SPLITS", "SPLIT_SPAN", "PoolName", "load_pool", "parse_pool", "random_grid_arguments", "split_seeds"]

SPLITS: tuple[str, ...] = ("train", "validation", "test")
SPLIT_SPAN = 1_000_000
"""Seeds per split: split ``k`` of :data:`SPLITS` holds seeds ``k * SPLIT_SPAN`` onwards."""


@dataclass(frozen=True)
class PoolName:
    """A parsed pool name."""

    family: str
    n: int
    size: int
    kind: str = "reactive"

    def __str__(self) -> str:
        base = f"{self.family}{self.n}/{self.size}x{self.size}"
        return base if self.kind == "reactive" else f"{base}/{self.kind}"


def parse_pool(name: str) -> PoolName:
    """``"reachability1/5x5"`` -> :class:`PoolName`.

    Raises
    ------
    ValueError
        Naming what is wrong with the name.
    """
    parts = name.split("/")
    form = "expected <family><n>/<size>x<size>[/static|/reactive], e.g. reachability1/5x5"
    if len(parts) not in (2, 3):
        raise ValueError(f"pool name {name!r}: {form}")
    spec, grid = parts[0], parts[1]
    kind = parts[2] if len(parts) == 3 else "reactive"
    family = spec.rstrip("0123456789")
    digits = spec[len(family):]
    if family not in FAMILIES or not digits:
        raise ValueError(f"pool name {name!r}: unknown family {spec!r}; expected one of {', '.join(FAMILIES)} with a size n; {form}")
    rows, x, cols = grid.partition("x")
    if not (x and rows.isdigit() and rows == cols and int(rows) >= 2):
        raise ValueError(f"pool name {name!r}: grid {grid!r} is not a square size such as 5x5; {form}")
    if kind not in ("reactive", "static"):
        raise ValueError(f"pool name {name!r}: unknown kind {kind!r}; expected reactive or static")
    family_objectives(family, int(digits))  # validates n for the family
    return PoolName(family, int(digits), int(rows), kind)


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
    demand, in process or through Ray with ``parallel="ray"``, and cached)."""
    pool = parse_pool(name)
    seeds = split_seeds(split, count, start)
    return build_pool(pool.size, pool.family, pool.n, seeds, pool.kind, parallel=parallel, workers=workers, progress=progress)


def random_grid_arguments(
    pool: str | None,
    split: str,
    count: int,
    size: int,
    family: str,
    n: int | None,
    seeds: tuple[int, ...],
    kind: str,
) -> tuple[int, str, int, tuple[int, ...], str]:
    """``(size, family, n, seeds, kind)`` of a random-grid env: from the named ``pool``'s
    ``split`` (its first ``count`` seeds) when one is given, else the explicit arguments
    (``n`` defaults to 1 for reachability, 2 otherwise)."""
    if pool is not None:
        named = parse_pool(pool)
        return named.size, named.family, named.n, tuple(split_seeds(split, count)), named.kind
    n = n if n is not None else (1 if family == "reachability" else 2)
    return int(size), family, int(n), tuple(int(s) for s in seeds), kind
