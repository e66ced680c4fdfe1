"""The pool of a benchmark: its train, validation and held-out test splits, loaded and the
scored tests written where the report's replay commands find them (protocol step 1,
docs/benchmark-protocol.md)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from experiments.outputs import write_atomically
from synthesis.artifacts.artifact import TestArtifact
from synthesis.model.errors import ProblemError

from .config import SPLIT_NAMES, BenchmarkConfig


@dataclass
class Split:
    """The tests of one split of the pool: artifacts (all loaded), the files the scored
    ones were written to (the first ``len(files)``), and the label of its report column."""

    name: str
    label: str
    seeds: list[int]
    artifacts: list[TestArtifact]
    files: list[Path] = field(default_factory=list)

    @property
    def scored(self) -> list[TestArtifact]:
        """The tests this split is scored on."""
        return self.artifacts[: len(self.files)]


def load_splits(
    config: BenchmarkConfig, out: Path, progress: bool | None = None, source: Callable[[str, str, int], Sequence[TestArtifact]] | None = None
) -> dict[str, Split]:
    """The train, validation and test splits of the pool (``source(pool, split, count)``;
    default :func:`flowtest_env.pools.load_pool`, built on demand and cached), each scored
    test written to ``out/pool/<split>/seed<N>.json``.

    Raises
    ------
    ProblemError
        If the source gives fewer tests than asked.
    """
    from flowtest_env.pools import load_pool, pool_seeds

    def default(pool: str, split: str, count: int) -> Sequence[TestArtifact]:
        return load_pool(pool, split, count, progress=progress)

    load = source or default
    splits = {}
    for name in SPLIT_NAMES:
        count = config.counts()[name]
        seeds = pool_seeds(config.pool, name, count)  # a -v2 split skips the seeds of tests already taken
        arts = list(load(config.pool, name, count))
        if len(arts) < count:
            raise ProblemError(f"--pool {config.pool}: its {name} split has {len(arts)} tests, fewer than the {count} asked")
        what = "held-out tests" if name == "test" else "tests"
        split = Split(name, f"{config.pool} {name} ({config.scored(name)} of {count} {what})", seeds, arts[:count])
        for seed, art in zip(seeds[: config.scored(name)], split.artifacts, strict=False):
            path = (out / "pool" / name / f"seed{seed}.json").resolve()
            write_atomically(path, art.save)
            split.files.append(path)
        splits[name] = split
    return splits


def games_and_budgets(split: Split) -> tuple[list[Any], list[int]]:
    from flowtest_env.envs import default_max_steps
    from flowtest_env.game import TestGame

    games = [TestGame(a) for a in split.scored]
    return games, [default_max_steps(g) for g in games]
