"""Seeded random grid worlds (the paper's scalability study, paper-examples.md) as test pools.

The instances themselves (spec families, seeded draws, redraws) live in the pure
:mod:`synthesis.random_grid`; this module only synthesizes them into artifacts and
caches the pools. A pool instance is the first attempt of its seed for which a test of
the pool's kind is synthesized (an inconsistent attempt is redrawn), so a seed always
names the same test.

Pools are synthesized once and cached in memory and on disk (:func:`random_pool`).
"""

from __future__ import annotations

import os
from pathlib import Path

from synthesis.artifact import TestArtifact, artifact_of
from synthesis.errors import ProblemError
from synthesis.pipeline import synthesize
from synthesis.random_grid import FAMILIES, MAX_ATTEMPTS, family_objectives, first_consistent, random_problem
from synthesis.summary import summary_of

from .artifacts import cache_dir, warn_refused_entry

__all__ = ["FAMILIES", "MAX_ATTEMPTS", "family_objectives", "random_problem", "random_artifact", "random_pool", "pool_path"]

POOL_FORMAT = 1


def random_artifact(size: int, family: str, n: int, seed: int, kind: str = "reactive") -> TestArtifact:
    """Synthesize the first consistent attempt of a seed.

    Raises
    ------
    RuntimeError
        If no attempt among :data:`MAX_ATTEMPTS` is consistent.
    """
    _, _, test = first_consistent(size, family, n, seed, kind, accept=synthesize)
    assert test is not None  # synthesize returns a test or raises
    return artifact_of(test, summary_of(test))


_POOLS: dict[tuple[int, str, int, tuple[int, ...], str], list[TestArtifact]] = {}


def pool_path(size: int, family: str, n: int, seed: int, kind: str) -> Path:
    """The cache file of one random instance."""
    return cache_dir() / "random-grid" / f"v{POOL_FORMAT}-{size}x{size}-{family}{n}-{kind}-seed{seed}.json"


def random_pool(size: int, family: str, n: int, seeds: tuple[int, ...], kind: str = "reactive") -> list[TestArtifact]:
    """The artifacts of a seed pool, synthesized once per machine (disk cache) and once
    per process (memory cache). Cache writes are atomic, so parallel workers are safe."""
    key = (size, family, n, tuple(seeds), kind)
    pool = _POOLS.get(key)
    if pool is not None:
        return pool
    pool = []
    for seed in seeds:
        path = pool_path(size, family, n, seed, kind)
        art: TestArtifact | None = None
        if path.exists():
            # an entry that fails its checks (edited, damaged, another instance's) is refused,
            # with a warning saying why, and synthesized again
            try:
                art = TestArtifact.load(path)
                if art.name != random_problem(size, family, n, seed, 0, kind).name:
                    raise ProblemError(f"cache entry {str(path)!r} holds the test {art.name!r}, not the instance of seed {seed}")
            except ProblemError as exc:
                warn_refused_entry(ProblemError(f"{exc}; synthesizing it again"))
                art = None
        if art is None:
            art = random_artifact(size, family, n, seed, kind)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            art.save(tmp)
            tmp.replace(path)
        pool.append(art)
    _POOLS[key] = pool
    return pool
