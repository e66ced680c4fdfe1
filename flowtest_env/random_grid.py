"""Seeded random grid worlds (the paper's scalability study, paper-examples.md) as test pools.

An instance is an empty ``size x size`` grid whose special cells are drawn uniformly
without replacement: first the start, then the goal, then one cell per remaining
proposition. An instance whose problem is inconsistent (no test exists) is redrawn
from the next attempt of the same seed, so a seed always names the same instance.

Spec families for a size parameter ``n``:

* ``reachability``: ``phi_sys = F p0`` (``p0`` the goal), ``phi_test = F p1 & ... & F pn``;
* ``reaction``: ``phi_sys = F p1 & G(p2 -> F q2) & ... & G(pn -> F qn)`` (``p1`` the goal),
  ``phi_test = F p0 & F p2 & ... & F pn``;
* ``safety``: ``phi_sys = F p1 & G !p2 & ... & G !pn`` (``p1`` the goal), ``phi_test = F p0``.

Pools are synthesized once and cached in memory and on disk (:func:`random_pool`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from synthesis.artifact import TestArtifact, artifact_of
from synthesis.errors import InconsistentProblem
from synthesis.pipeline import synthesize
from synthesis.problems import Problem, make_problem
from synthesis.summary import summary_of
from synthesis.systems import grid_world

from .artifacts import cache_dir

FAMILIES: tuple[str, ...] = ("reachability", "reaction", "safety")
MAX_ATTEMPTS = 50
POOL_FORMAT = 1


def family_objectives(family: str, n: int) -> tuple[str, str, list[str], str]:
    """``(phi_sys, phi_test, propositions in drawing order after the goal, goal)``.

    Raises
    ------
    ValueError
        On an unknown family or an ``n`` out of range.
    """
    if family not in FAMILIES:
        raise ValueError(f"unknown spec family {family!r}; expected one of {', '.join(FAMILIES)}")
    low = 1 if family == "reachability" else 2
    if not (low <= n <= 8):
        raise ValueError(f"spec size n={n} out of range {low}..8 for the {family} family")
    if family == "reachability":
        return "F p0", " & ".join(f"F p{i}" for i in range(1, n + 1)), [f"p{i}" for i in range(1, n + 1)], "p0"
    if family == "reaction":
        sys = " & ".join(["F p1"] + [f"G(p{i} -> F q{i})" for i in range(2, n + 1)])
        test = " & ".join(["F p0"] + [f"F p{i}" for i in range(2, n + 1)])
        props = ["p0"] + [f"p{i}" for i in range(2, n + 1)] + [f"q{i}" for i in range(2, n + 1)]
        return sys, test, props, "p1"
    sys = " & ".join(["F p1"] + [f"G !p{i}" for i in range(2, n + 1)])
    return sys, "F p0", ["p0"] + [f"p{i}" for i in range(2, n + 1)], "p1"


def random_problem(size: int, family: str, n: int, seed: int, attempt: int = 0, kind: str = "reactive") -> Problem:
    """The random grid instance of ``(size, family, n, seed, attempt)``.

    Raises
    ------
    ValueError
        If the grid is too small for the special cells.
    """
    sys_obj, test_obj, props, goal_prop = family_objectives(family, n)
    cells = [(r, c) for r in range(size) for c in range(size)]
    if len(cells) < len(props) + 2:
        raise ValueError(f"a {size}x{size} grid has too few cells for {len(props) + 2} special cells")
    rng = np.random.default_rng([seed, attempt])
    pick = rng.choice(len(cells), size=len(props) + 2, replace=False)
    start, goal = cells[int(pick[0])], cells[int(pick[1])]
    labels: dict[tuple[int, int], list[str]] = {goal: [goal_prop]}
    tokens = {start: "S", goal: "T"}
    for p, i in zip(props, pick[2:]):
        labels[cells[int(i)]] = [p]
        tokens[cells[int(i)]] = p
    ts = grid_world(cells, size, size, start, [goal], labels, tokens)
    name = f"random-{size}x{size}-{family}{n}-{kind}-s{seed}"
    return make_problem(name, ts, sys_obj, test_obj, kind, description=f"random grid, seed {seed}, attempt {attempt}")


def random_artifact(size: int, family: str, n: int, seed: int, kind: str = "reactive") -> TestArtifact:
    """Synthesize the first consistent attempt of a seed.

    Raises
    ------
    RuntimeError
        If no attempt among :data:`MAX_ATTEMPTS` is consistent.
    """
    for attempt in range(MAX_ATTEMPTS):
        problem = random_problem(size, family, n, seed, attempt, kind)
        try:
            test = synthesize(problem)
        except InconsistentProblem:
            continue
        return artifact_of(test, summary_of(test))
    raise RuntimeError(f"no consistent random grid for seed {seed} in {MAX_ATTEMPTS} attempts")


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
            try:
                art = TestArtifact.load(path)
            except (OSError, ValueError, KeyError, json.JSONDecodeError):
                art = None  # a damaged cache entry is rebuilt
        if art is None:
            art = random_artifact(size, family, n, seed, kind)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            art.save(tmp)
            tmp.replace(path)
        pool.append(art)
    _POOLS[key] = pool
    return pool
