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
``0 .. SPLIT_SPAN - 1``, ``validation`` the next :data:`SPLIT_SPAN`, ``test`` the next. Each
seed names one test (:mod:`flowtest_env.random_grid`), but two seeds may name the same
game (a 5x5 grid with a start, a goal and one hidden cell has 13,800 layouts): an on-demand
pool's splits are disjoint by seed, not by content. The standard ``-v2`` pools
(:mod:`flowtest_env.standard_pools`) are disjoint by content: no test of one split is the
same game as a test of another, and no split repeats a test.

:func:`load_pool` gives the checked tests of a split as a plain list of artifacts (built on
demand with deterministic budgets, stored compactly per FlowTest and solver version), so
a vector env can step many of them in one batch.
"""

from __future__ import annotations

from synthesis.artifacts.artifact import TestArtifact

from .random_grid import SPLIT_SPAN, SPLITS, PoolName, build_pool, parse_pool, random_pool, split_seeds
from .standard_pools import is_standard, load_standard_pool, standard_pool

__all__ = [
    "SPLITS",
    "SPLIT_SPAN",
    "PoolName",
    "load_pool",
    "parse_pool",
    "pool_seeds",
    "random_grid_arguments",
    "random_grid_tests",
    "split_seeds",
]


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

    ``name`` may be a standard pool id (``reachability1/5x5-v2``,
    :mod:`flowtest_env.standard_pools`): its shipped tests are loaded from their records
    (nothing synthesized). A ``-v2`` pool (disjoint by content) is its shipped tests: more
    is an error. For a ``-v1`` pool, seeds beyond the shipped ones are built on demand as
    for the pool it draws from (same seeds, same budget).

    Examples
    --------
    >>> from flowtest_env.pools import load_pool
    >>> held_out = load_pool("reachability1/5x5-v2", "test", 2)    # a standard pool: shipped, nothing synthesized
    >>> [(t.name, t.kind) for t in held_out]
    [('random-5x5-reachability1-reactive-s2000000', 'reactive'), ('random-5x5-reachability1-reactive-s2000001', 'reactive')]

    Raises
    ------
    ValueError
        On a bad name, split, start or count, or more tests than a ``-v2`` pool ships.
    """
    if is_standard(name):
        std = standard_pool(name)
        split_seeds(split, count, start)  # validates split, start and count
        if std.draw == "content":  # disjoint by content: the shipped tests only
            return load_standard_pool(std.id, split, count, start, progress=progress)
        shipped = max(0, min(std.shipped(split) - start, count))
        tests = load_standard_pool(std.id, split, shipped, start, progress=progress) if shipped else []
        if shipped < count:
            tests += load_pool(std.pool, split, count - shipped, start + shipped, parallel, workers, progress)
        return tests
    pool = parse_pool(name)
    seeds = split_seeds(split, count, start)
    return build_pool(pool.size, pool.family, pool.n, seeds, pool.kind, parallel=parallel, workers=workers, progress=progress, world=pool.world)


def pool_seeds(name: str, split: str, count: int, start: int = 0) -> list[int]:
    """The seeds of tests ``start .. start + count - 1`` of a pool's split: the split's seeds
    in order for an on-demand pool and a ``-v1`` pool, the shipped tests' seeds for a
    ``-v2`` pool (which skip the seeds of tests already taken).

    Example::

        pool_seeds("reachability1/5x5-v2", "test", 3)   # [2000000, 2000001, 2000002]

    Raises
    ------
    ValueError
        On a bad name, split, start or count, or more tests than a ``-v2`` pool ships.
    """
    seeds = list(split_seeds(split, count, start))  # validates split, start and count
    if not is_standard(name):
        parse_pool(name)
        return seeds
    std = standard_pool(name)
    if std.draw == "seeds":
        return seeds
    shipped = std.seeds(split)
    if start + count > len(shipped):
        raise ValueError(f"{std.id} ships {len(shipped)} tests of its {split!r} split; asked for tests {start}..{start + count - 1}")
    return shipped[start : start + count]


def random_grid_tests(
    pool: str | None, split: str, count: int, size: int, family: str, n: int, seeds: tuple[int, ...], kind: str, world: str
) -> list[TestArtifact]:
    """The tests of a random-grid env, from :func:`random_grid_arguments`'s values: a
    standard pool's shipped records where ``pool`` is a standard pool id (nothing
    synthesized; the same tests as its on-demand pool), else built on demand and cached
    (:func:`flowtest_env.random_grid.random_pool`)."""
    if pool is not None and is_standard(pool):
        return load_pool(pool, split, count)
    return random_pool(size, family, n, seeds, kind, world=world)


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
    arguments (``n`` defaults to 1 for reachability, 2 otherwise). A standard pool id
    names its shipped tests' seeds (:func:`pool_seeds`; :func:`random_grid_tests` serves
    them without building)."""
    if pool is not None:
        named = parse_pool(standard_pool(pool).pool if is_standard(pool) else pool)
        return named.size, named.family, named.n, tuple(pool_seeds(pool, split, count)), named.kind, named.world
    n = n if n is not None else (1 if family == "reachability" else 2)
    return int(size), family, int(n), tuple(int(s) for s in seeds), kind, world
