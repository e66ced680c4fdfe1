"""Which tests of a standard pool's splits are the same game: content keys, overlaps, and
the birthday bound that predicts them.

A test's content key (:func:`synthesis.artifacts.content.content_key`) names the game a
policy plays in it (transition system, labels, objectives, automata, restrictions, test
agent), not its name, seed or statistics. Two splits are *disjoint by content* when no key
of one is a key of the other, and a split *repeats* a test when one key appears twice in it.

* :func:`split_keys` gives a split's keys: from the shipped records where they carry one
  (the ``-v2`` pools: read in well under a second, each key checked against its test
  whenever the pool is loaded), else from the tests rebuilt from the records (the ``-v1``
  pools: a full load, about 1-10 ms a test).
* :func:`overlaps` counts repeats within each split and shared tests between each pair.
* :func:`birthday` is what chance alone predicts for splits of given sizes drawn
  independently from ``layouts`` equally likely layouts
  (:func:`synthesis.problems.random_worlds.layout_count`): the reason ``reachability1/5x5-v1``
  shares a quarter of its held-out tests with its train split.

Example::

    from flowtest_env.pool_content import overlaps, split_keys
    from flowtest_env.pools import SPLITS
    from flowtest_env.standard_pools import standard_pool

    pool = standard_pool("reachability1/5x5-v2")
    report = overlaps({s: split_keys(pool, s) for s in SPLITS})
    assert report.clean   # no repeats, no test shared between two splits
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations
from typing import Any

from synthesis.artifacts.content import content_key
from synthesis.artifacts.pool_records import record_content_key

from .standard_pools import StandardPool, load_standard_pool, read_records

__all__ = ["Overlaps", "birthday", "overlaps", "split_keys"]


def split_keys(pool: StandardPool, split: str, rebuild: bool | None = None, progress: bool | None = None) -> list[str]:
    """The content keys of a split's shipped tests, in order.

    ``rebuild``: ``None`` reads them from the records where every record carries one and
    rebuilds the tests otherwise; ``False`` reads them (raising where one is missing);
    ``True`` rebuilds every test (:func:`flowtest_env.standard_pools.load_standard_pool`)
    and computes its key. Keys read from records are what the records state (covered by
    their digests; a load checks each against its test).

    Raises
    ------
    ValueError
        With ``rebuild=False``, if a record carries no content key.
    """
    records = read_records(pool, split)
    stated = [record_content_key(r) for r in records]
    if rebuild is None:
        rebuild = any(k is None for k in stated)
    if not rebuild:
        missing = [r["seed"] for r, k in zip(records, stated, strict=True) if k is None]
        if missing:
            raise ValueError(f"{pool.id} {split}: the record of seed {missing[0]} carries no content key (rebuild=True computes them)")
        return [k for k in stated if k is not None]
    if not records:
        return []
    return [content_key(t) for t in load_standard_pool(pool.id, split, len(records), progress=progress)]


@dataclass(frozen=True)
class Overlaps:
    """Repeats and shared tests of a pool's splits.

    Attributes
    ----------
    sizes
        Tests per split.
    repeats
        Per split: tests whose key an earlier test of the same split has.
    shared
        Per pair of splits ``(a, b)``: tests of ``a`` whose key is a key of ``b``.
    """

    sizes: dict[str, int]
    repeats: dict[str, int]
    shared: dict[tuple[str, str], int]

    @property
    def clean(self) -> bool:
        """No split repeats a test and no two splits share one."""
        return not any(self.repeats.values()) and not any(self.shared.values())

    def lines(self) -> list[str]:
        """The report, one line per split and per pair."""
        out = [f"{s}: {n} tests, {n - self.repeats[s]} distinct, {self.repeats[s]} repeats" for s, n in self.sizes.items()]
        out += [f"{a} in {b}: {k} of {self.sizes[a]} tests" for (a, b), k in self.shared.items()]
        return out


def overlaps(keys: Mapping[str, Sequence[str]]) -> Overlaps:
    """Repeats within each split and tests shared by each pair (both directions) of the
    splits' content keys.

    Example::

        overlaps({"train": ["a", "b", "b"], "test": ["b", "c"]}).shared[("test", "train")]   # 1
    """
    sets = {s: set(k) for s, k in keys.items()}
    shared: dict[tuple[str, str], int] = {}
    for a, b in combinations(keys, 2):
        shared[(a, b)] = sum(1 for k in keys[a] if k in sets[b])
        shared[(b, a)] = sum(1 for k in keys[b] if k in sets[a])
    return Overlaps({s: len(k) for s, k in keys.items()}, {s: len(k) - len(sets[s]) for s, k in keys.items()}, shared)


def birthday(layouts: int, sizes: Mapping[str, int]) -> dict[str, Any]:
    """What chance predicts when each split's tests are drawn independently and uniformly
    from ``layouts`` equally likely layouts (the birthday bound):

    * ``repeats[s]``: expected tests of split ``s`` that repeat an earlier one,
      ``n - L (1 - (1 - 1/L)^n)``;
    * ``shared[a in b]``: expected tests of ``a`` that are also in ``b``,
      ``n_a (1 - (1 - 1/L)^n_b)``;
    * ``any_collision``: the probability that two of all the ``M`` tests are one layout,
      ``1 - prod_{i < M} (1 - i/L)`` (about ``1 - exp(-M (M - 1) / 2L)``).

    Rejected layouts (an attempt without a test is redrawn) and layouts drawn more often
    than others only raise the true rates: these are lower bounds on what seed-drawn
    splits share.

    Example::

        birthday(13_800, {"train": 4096, "test": 1000})["shared"]["test in train"]   # about 257
    """
    if layouts < 1:
        raise ValueError(f"layouts must be positive, got {layouts}")

    def hit(n: int) -> float:  # 1 - (1 - 1/L)^n, without cancellation for huge L
        return -math.expm1(n * math.log1p(-1.0 / layouts)) if layouts > 1 else float(n > 0)

    def repeats(n: int) -> float:  # n - L (1 - (1 - 1/L)^n); about n (n - 1) / 2L where that is tiny
        small = n * (n - 1) / (2 * layouts)
        return small if small < 1e-6 else n - layouts * hit(n)

    total = sum(sizes.values())
    # P(no two of the M tests share a layout) = prod_{i < M} (1 - i/L), exactly
    none = 0.0 if total > layouts else math.exp(sum(math.log1p(-i / layouts) for i in range(total)))
    return {
        "layouts": layouts,
        "repeats": {s: repeats(n) for s, n in sizes.items()},
        "shared": {f"{a} in {b}": na * hit(nb) for a, na in sizes.items() for b, nb in sizes.items() if a != b},
        "any_collision": 1.0 - none,
    }
