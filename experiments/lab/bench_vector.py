"""Throughput of the NumPy vector env next to ``SyncVectorEnv`` of the single env and of
MiniGrid, side by side in one run.

Usage::

    python -m experiments.lab.bench_vector [--envs 1024] [--steps 300] [--sync-steps 20] [--repeat 5] [--out FILE]

Every measurement steps a batch of ``--envs`` envs with a random policy, chosen for the
whole batch at once by the same NumPy code in every row (a random legal action from
``infos["action_mask"]`` for FlowTest, any action for MiniGrid, which has no mask), with
Gymnasium's default next-step autoreset:

* ``FlowTest-Maze2-v0`` through ``gym.make_vec(..., vectorization_mode="vector_entry_point")``
  (flat observations, as ``float32`` and with ``obs_dtype="uint8"``, and grid observations), ``FlowTest-Patrolling-v0`` (test agent and fuel), a mixed
  batch of all nine built-ins (:class:`~flowtest_env.vector.PoolVectorEnv`, flat
  observations padded to the largest) and, with ``--random-grid``, a pool of
  ``FlowTest-RandomGrid-v0`` tests;
* the same Maze 2 env as a ``SyncVectorEnv`` (``vectorization_mode="sync"``);
* ``MiniGrid-Empty-8x8-v0`` as a ``SyncVectorEnv`` (if ``minigrid`` is installed, the
  ``bench`` extra).

Steps per second count env steps (batch steps x envs). Rows are measured round-robin,
``--repeat`` rounds, so every row sees the same load; the best and the median round are
reported. Prints a Markdown table (and writes it to ``--out``).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from experiments.lab.output import publish


def masked_random(rng: np.random.Generator, mask: np.ndarray) -> np.ndarray:
    """One random legal action per row of ``mask`` (``int8[n_envs, n_actions]``)."""
    out: np.ndarray = np.argmax(rng.random(mask.shape) * (mask > 0), axis=1)
    return out


def rate(envs: Any, steps: int, masked: bool, seed: int) -> float:
    """Env steps per second of ``steps`` batch steps of ``envs`` under a random policy."""
    rng = np.random.default_rng(seed)
    n = envs.num_envs
    n_actions = int(envs.single_action_space.n)
    _, infos = envs.reset(seed=seed)
    t = time.perf_counter()
    for _ in range(steps):
        a = masked_random(rng, infos["action_mask"]) if masked else rng.integers(n_actions, size=n)
        _, _, _, _, infos = envs.step(a)
    return float(steps * n / (time.perf_counter() - t))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", type=int, default=1024, help="envs per batch")
    ap.add_argument("--steps", type=int, default=300, help="batch steps per run of a vector env")
    ap.add_argument("--sync-steps", type=int, default=20, help="batch steps per run of a SyncVectorEnv")
    ap.add_argument("--repeat", type=int, default=5, help="rounds (best and median reported)")
    ap.add_argument("--random-grid", action="store_true", help="also a FlowTest-RandomGrid-v0 pool (seeds 0..7; synthesized once)")
    ap.add_argument("--out", help="also write the Markdown to this file")
    args = ap.parse_args(argv)
    if args.envs < 1 or args.steps < 1 or args.sync_steps < 1 or args.repeat < 1:
        print("error: --envs, --steps, --sync-steps and --repeat must be at least 1")
        return 2
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")

    import flowtest_env
    from flowtest_env.artifacts import builtin_game
    from flowtest_env.envs import BUILTIN_ENVS
    from flowtest_env.vector import PoolVectorEnv

    try:
        import minigrid  # registers MiniGrid-*; the optional bench extra

        have_minigrid = True
    except ImportError:
        have_minigrid = False

    n = args.envs
    vec = "vector_entry_point"
    rows: list[tuple[str, str, Callable[[], Any], int, bool]] = [
        ("`FlowTest-Maze2-v0`", "NumPy vector env, flat obs", lambda: gym.make_vec("FlowTest-Maze2-v0", n, vec), args.steps, True),
        (
            "`FlowTest-Maze2-v0`",
            'NumPy vector env, flat obs, `obs_dtype="uint8"`',
            lambda: gym.make_vec("FlowTest-Maze2-v0", n, vec, obs_dtype="uint8"),
            args.steps,
            True,
        ),
        (
            "`FlowTest-Maze2-v0`",
            "NumPy vector env, grid obs",
            lambda: gym.make_vec("FlowTest-Maze2-v0", n, vec, obs_kind="grid"),
            args.steps,
            True,
        ),
        ("`FlowTest-Patrolling-v0`", "NumPy vector env, flat obs", lambda: gym.make_vec("FlowTest-Patrolling-v0", n, vec), args.steps, True),
        (
            "all 9 built-ins in one batch",
            "NumPy `PoolVectorEnv`, flat obs (padded)",
            lambda: PoolVectorEnv(n, [builtin_game(p, "instantaneous") for p in BUILTIN_ENVS], assignment="fixed"),
            args.steps,
            True,
        ),
    ]
    if args.random_grid:
        rows.append(
            ("`FlowTest-RandomGrid-v0` (8 tests)", "NumPy vector env, flat obs", lambda: gym.make_vec("FlowTest-RandomGrid-v0", n, vec), args.steps, True)
        )
    rows.append(
        ("`FlowTest-Maze2-v0`", "`SyncVectorEnv` of the single env, flat obs", lambda: gym.make_vec("FlowTest-Maze2-v0", n, "sync"), args.sync_steps, True)
    )
    if have_minigrid:
        rows.append(
            ("`MiniGrid-Empty-8x8-v0`", "`SyncVectorEnv`, default obs", lambda: gym.make_vec("MiniGrid-Empty-8x8-v0", n, "sync"), args.sync_steps, False)
        )
    built = [make() for _, _, make, _, _ in rows]
    results: list[list[float]] = [[] for _ in rows]
    for r in range(args.repeat):  # round-robin: every row sees the same load
        for i, (_, _, _, steps, masked) in enumerate(rows):
            results[i].append(rate(built[i], steps, masked, seed=r))
    for e in built:
        e.close()

    versions = f"gymnasium {gym.__version__}, numpy {np.__version__}"
    if have_minigrid:
        versions += f", minigrid {minigrid.__version__}"
    lines = [
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, {versions}; "
        f"{n} envs per batch; {args.steps} batch steps per vector-env run, {args.sync_steps} per SyncVectorEnv run; "
        f"{args.repeat} rounds; 1-min load average {load:.1f} before the run.",
        "",
        "| environment | implementation | best steps/s | median steps/s |",
        "| --- | --- | ---: | ---: |",
    ]
    for (name, how, _, _, _), res in zip(rows, results, strict=True):
        lines.append(f"| {name} | {how} | {max(res):,.0f} | {statistics.median(res):,.0f} |")
    sync_best = max(results[[h for _, h, _, _, _ in rows].index("`SyncVectorEnv` of the single env, flat obs")])
    lines += [
        "",
        f"NumPy Maze 2 (flat) over the `SyncVectorEnv` of the same env: {max(results[0]) / sync_best:,.0f}x (best), "
        f"{statistics.median(results[0]) / statistics.median(results[-2 if have_minigrid else -1]):,.0f}x (median).",
    ]
    if have_minigrid:
        lines.append(
            f"NumPy Maze 2 (flat) over MiniGrid's `SyncVectorEnv`: {max(results[0]) / max(results[-1]):,.0f}x (best), "
            f"{statistics.median(results[0]) / statistics.median(results[-1]):,.0f}x (median)."
        )
    publish("\n".join(lines) + "\n", args.out)
    del flowtest_env
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
