"""Seeded random grid worlds (the paper's scalability study, paper-examples.md) as test pools.

The instances themselves (spec families, seeded draws, redraws) live in the pure
:mod:`synthesis.problems.random_grid`; this module synthesizes them into artifacts and caches
the pools. A pool instance is the first attempt of its seed for which a test of the
pool's kind is synthesized within the pool budget (an inconsistent attempt, or one
without a test within the budget, is redrawn), so a seed always names the same test.

**Deterministic.** Pools are synthesized with deterministic budgets only
(:func:`pool_options`: one HiGHS thread, a fixed random seed, a node limit per HiGHS run,
the routing heuristic's work budget), never a wall-clock limit, so a pool is the same on
every machine under any load, and every pool test is bounded in work.

**Cached by version.** Each pool lives on disk under ``cache_dir()/random-grid/<pool>/<key>``
where ``key`` is :func:`synthesis.artifacts.provenance.cache_key` of the pool's parameters and
options under the current FlowTest, highspy, NumPy and SciPy versions: a pool built under
another version is never reused, it is rebuilt. Within a process pools are also kept in
memory.

**Built in parallel when asked.** :func:`build_pool` synthesizes the missing seeds in
process, or as Ray tasks (``parallel="ray"``); the answers do not depend on the dispatch.
A progress bar (tqdm, on standard error) counts the seeds.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Iterable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from synthesis.artifacts.artifact import TestArtifact, artifact_of
from synthesis.artifacts.provenance import cache_key, versions
from synthesis.artifacts.summary import summary_of
from synthesis.model.errors import InconsistentProblem, ProblemError
from synthesis.pipeline import SynthesisOptions, SynthesizedTest, synthesize
from synthesis.problems.problem import Problem
from synthesis.problems.random_grid import FAMILIES, MAX_ATTEMPTS, family_objectives, first_consistent, random_problem

from .artifacts import cache_dir, warn_refused_entry

__all__ = [
    "FAMILIES",
    "MAX_ATTEMPTS",
    "POOL_NODE_LIMIT",
    "build_pool",
    "family_objectives",
    "pool_dir",
    "pool_key",
    "pool_options",
    "pool_path",
    "random_artifact",
    "random_pool",
    "random_problem",
]

POOL_FORMAT = 2
POOL_NODE_LIMIT = 1000
"""Branch-and-bound nodes per HiGHS run for pool tests: bounds the work per test (an
8x8 reachability instance whose maximum flow HiGHS cannot prove in minutes stops at it
with a checked, feasible test)."""


def pool_options() -> SynthesisOptions:
    """The synthesis options of every pool test: deterministic budgets only."""
    return SynthesisOptions(threads=1, node_limit=POOL_NODE_LIMIT)


def _options_record(options: SynthesisOptions) -> dict[str, Any]:
    """The answer-changing fields of synthesis options, as JSON."""
    d = asdict(options)
    d.pop("progress", None)
    return d


def pool_params(size: int, family: str, n: int, kind: str) -> dict[str, Any]:
    """Everything besides the versions that decides a pool's tests."""
    return {
        "format": POOL_FORMAT,
        "size": int(size),
        "family": family,
        "n": int(n),
        "kind": kind,
        "max_attempts": MAX_ATTEMPTS,
        "options": _options_record(pool_options()),
    }


def pool_key(size: int, family: str, n: int, kind: str) -> str:
    """The cache key of a pool: its parameters, options and the FlowTest and solver versions."""
    return cache_key("random-grid-pool", pool_params(size, family, n, kind))


def pool_dir(size: int, family: str, n: int, kind: str) -> Path:
    """The cache folder of a pool's tests under the current versions."""
    return cache_dir() / "random-grid" / f"{size}x{size}-{family}{n}-{kind}" / pool_key(size, family, n, kind)


def pool_path(size: int, family: str, n: int, seed: int, kind: str) -> Path:
    """The cache file of one pool test under the current versions."""
    return pool_dir(size, family, n, kind) / f"seed{seed}.json"


def _accept(problem: Problem) -> SynthesizedTest:
    """Synthesize a pool attempt; no test within the budget counts as no test (redraw)."""
    try:
        return synthesize(problem, pool_options())
    except TimeoutError as exc:
        raise InconsistentProblem("budget", f"no test within the pool budget: {exc}") from None


def random_artifact(size: int, family: str, n: int, seed: int, kind: str = "reactive") -> TestArtifact:
    """Synthesize the pool test of a seed: its first attempt with a test within the budget.

    Raises
    ------
    RuntimeError
        If no attempt among :data:`MAX_ATTEMPTS` has one.
    """
    family_objectives(family, n)  # validates before any work
    _, _, test = first_consistent(size, family, n, seed, kind, accept=_accept)
    assert test is not None  # _accept returns a test or raises
    art = artifact_of(test, summary_of(test))
    art.extras["provenance"] = {"pool": pool_params(size, family, n, kind), "versions": versions()}
    return art


def build_artifact_dict(size: int, family: str, n: int, seed: int, kind: str) -> dict[str, Any]:
    """:func:`random_artifact` as a JSON-ready dict (what a Ray task returns)."""
    return random_artifact(size, family, n, seed, kind).to_dict()


def _write(path: Path, data: dict[str, Any]) -> None:
    """Write a cache file atomically (parallel builders of one pool are safe)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, separators=(",", ":")))
    tmp.replace(path)


def _load(path: Path, size: int, family: str, n: int, seed: int, kind: str) -> TestArtifact | None:
    """A cache entry, checked in full; one that fails its checks (edited, damaged, another
    instance's) is refused, with a warning saying why, and ``None`` returned."""
    if not path.exists():
        return None
    try:
        art = TestArtifact.load(path)
        if art.name != random_problem(size, family, n, seed, 0, kind).name:
            raise ProblemError(f"cache entry {str(path)!r} holds the test {art.name!r}, not the instance of seed {seed}")
    except ProblemError as exc:
        warn_refused_entry(ProblemError(f"{exc}; synthesizing it again"))
        return None
    return art


def _progress_bar(total: int, initial: int, desc: str, enabled: bool | None) -> Any:
    """A tqdm bar on standard error (``enabled=None``: only on a terminal); a plain
    line counter on standard error if tqdm is not installed."""
    try:
        from tqdm import tqdm
    except ImportError:  # tqdm comes with the rl extra; the core works without it
        return _LineProgress(total, initial, desc, enabled if enabled is not None else sys.stderr.isatty())
    return tqdm(total=total, initial=initial, desc=desc, unit="test", file=sys.stderr, disable=None if enabled is None else not enabled)


class _LineProgress:
    """The few methods of tqdm this module uses, as one line per finished test."""

    def __init__(self, total: int, initial: int, desc: str, enabled: bool) -> None:
        self.total, self.n, self.desc, self.enabled = total, initial, desc, enabled

    def update(self, k: int = 1) -> None:
        self.n += k
        if self.enabled:
            print(f"{self.desc}: {self.n}/{self.total}", file=sys.stderr, flush=True)

    def close(self) -> None:
        pass


def build_pool(
    size: int,
    family: str,
    n: int,
    seeds: Iterable[int],
    kind: str = "reactive",
    parallel: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
) -> list[TestArtifact]:
    """The pool tests of ``seeds``, from the cache where present, else synthesized and cached.

    Parameters
    ----------
    parallel
        ``None``: synthesize the missing seeds in this process; ``"ray"``: as Ray tasks
        (a local Ray runtime with ``workers`` CPUs unless one is running). The tests do
        not depend on this choice.
    progress
        Show a progress bar on standard error (``None``: only on a terminal).

    Raises
    ------
    ValueError
        On an unknown family, ``n``, kind or ``parallel``.
    """
    if kind not in ("static", "reactive"):
        raise ValueError(f"unknown kind {kind!r}; expected 'static' or 'reactive'")
    if parallel not in (None, "ray"):
        raise ValueError(f"unknown parallel backend {parallel!r}; expected None or 'ray'")
    family_objectives(family, n)
    seeds = [int(s) for s in seeds]
    folder = pool_dir(size, family, n, kind)
    found: dict[int, TestArtifact] = {}
    for seed in dict.fromkeys(seeds):
        art = _load(folder / f"seed{seed}.json", size, family, n, seed, kind)
        if art is not None:
            found[seed] = art
    missing = [s for s in dict.fromkeys(seeds) if s not in found]
    if missing:
        key_file = folder / "key.json"
        if not key_file.exists():
            _write(key_file, {"params": pool_params(size, family, n, kind), "versions": versions()})
        bar = _progress_bar(len(found) + len(missing), len(found), f"pool {size}x{size} {family}{n} {kind}", progress)
        try:
            for seed, data in _synthesize_seeds(size, family, n, missing, kind, parallel, workers):
                _write(folder / f"seed{seed}.json", data)
                found[seed] = TestArtifact.from_dict(data, f"pool test of seed {seed}", verify=False)  # ours, just made
                bar.update(1)
        finally:
            bar.close()
    return [found[s] for s in seeds]


def _synthesize_seeds(
    size: int, family: str, n: int, seeds: list[int], kind: str, parallel: str | None, workers: int | None
) -> Iterable[tuple[int, dict[str, Any]]]:
    """``(seed, artifact dict)`` for every seed, in the order they finish."""
    if parallel is None:
        for seed in seeds:
            yield seed, build_artifact_dict(size, family, n, seed, kind)
        return
    import ray

    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(build_artifact_dict)
        pending = {remote.remote(size, family, n, seed, kind): seed for seed in seeds}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                yield pending.pop(ref), ray.get(ref)
    finally:
        if started:
            ray.shutdown()


_POOLS: dict[tuple[str, tuple[int, ...]], list[TestArtifact]] = {}


def random_pool(
    size: int, family: str, n: int, seeds: tuple[int, ...], kind: str = "reactive", parallel: str | None = None
) -> list[TestArtifact]:
    """The artifacts of a seed pool (:func:`build_pool`), kept in memory per process."""
    key = (str(pool_dir(size, family, n, kind)), tuple(int(s) for s in seeds))
    pool = _POOLS.get(key)
    if pool is None:
        pool = _POOLS[key] = build_pool(size, family, n, seeds, kind, parallel=parallel)
    return pool
