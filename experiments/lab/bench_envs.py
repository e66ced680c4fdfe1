"""Throughput and start-up of the FlowTest environments, next to MiniGrid, in one run.

Usage::

    python -m experiments.lab.bench_envs [--steps 20000] [--repeat 3] [--out FILE]

Measures, on this machine and in this process:

* steps per second of ``FlowTest-Maze2-v0`` (flat and grid observations) under a
  random *masked* policy (``action_space.sample(mask=info["action_mask"])``), through
  ``gymnasium.make`` with its default wrappers, resetting at episode ends;
* the same for MiniGrid's ``MiniGrid-Empty-8x8-v0`` with a random policy (if
  ``minigrid`` is installed; it is not a FlowTest dependency);
* cold ``make`` times: a fresh interpreter imports the package and makes the env
  (import and make reported separately), for every FlowTest ID with a shipped artifact.

Prints a Markdown table (and writes it to ``--out`` if given). The best of
``--repeat`` runs is reported, which is the least disturbed by other load.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from typing import Any

import gymnasium as gym

from experiments.lab.output import publish


def steps_per_second(env_id: str, steps: int, masked: bool, seed: int = 0, **kwargs: Any) -> float:
    """Random-policy steps per second of ``env_id`` (masked by ``info["action_mask"]``)."""
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(seed)
    _, info = env.reset(seed=seed)
    sample = env.action_space.sample
    t = time.perf_counter()
    for _ in range(steps):
        action = sample(mask=info["action_mask"]) if masked else sample()
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            _, info = env.reset()
    elapsed = time.perf_counter() - t
    env.close()
    return steps / elapsed


COLD = """
import time, json
t0 = time.perf_counter()
import gymnasium
import {module}
t1 = time.perf_counter()
env = gymnasium.make({env_id!r})
env.reset(seed=0)
t2 = time.perf_counter()
print(json.dumps([t1 - t0, t2 - t1]))
"""


def cold_make(env_id: str, module: str) -> tuple[float, float]:
    """``(import seconds, make + reset seconds)`` in a fresh interpreter."""
    out = subprocess.run([sys.executable, "-c", COLD.format(module=module, env_id=env_id)], capture_output=True, text=True, check=True)
    imp, make = json.loads(out.stdout.strip().splitlines()[-1])
    return float(imp), float(make)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000, help="steps per throughput run")
    ap.add_argument("--repeat", type=int, default=3, help="runs per measurement (best reported)")
    ap.add_argument("--out", help="also write the Markdown to this file")
    args = ap.parse_args(argv)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")  # other work on the machine

    import flowtest_env
    from flowtest_env.artifacts import artifact_path
    from flowtest_env.envs import BUILTIN_ENVS

    try:
        import minigrid  # registers MiniGrid-*; an optional extra: pip install -e '.[bench]'

        have_minigrid = True
    except ImportError:
        have_minigrid = False

    runs: list[tuple[str, str, float]] = []

    def best(env_id: str, masked: bool, **kw: Any) -> float:
        return max(steps_per_second(env_id, args.steps, masked, seed=i, **kw) for i in range(args.repeat))

    runs.append(("FlowTest-Maze2-v0", "flat obs, random masked policy", best("FlowTest-Maze2-v0", True)))
    runs.append(("FlowTest-Maze2-v0", "grid obs, random masked policy", best("FlowTest-Maze2-v0", True, obs_kind="grid")))
    if have_minigrid:
        runs.append(("MiniGrid-Empty-8x8-v0", "default obs, random policy", best("MiniGrid-Empty-8x8-v0", False)))

    versions = f"gymnasium {gym.__version__}"
    if have_minigrid:
        versions += f", minigrid {minigrid.__version__}"
    lines = [
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, {versions}; "
        f"{args.steps} steps per run, best of {args.repeat}; 1-min load average {load:.1f} before the run.",
        "",
        "| environment | setting | steps/s |",
        "| --- | --- | ---: |",
    ]
    lines += [f"| `{e}` | {s} | {v:,.0f} |" for e, s, v in runs]
    if not have_minigrid:
        lines.append("| `MiniGrid-Empty-8x8-v0` | minigrid not installed | - |")
    lines += ["", "| environment | cold import (s) | cold make + reset (s) |", "| --- | ---: | ---: |"]
    ids = [f"FlowTest-{stem}-v0" for name, (stem, _) in BUILTIN_ENVS.items() if artifact_path(name).exists()]
    for env_id in ids:
        imp, make = min(cold_make(env_id, "flowtest_env") for _ in range(args.repeat))
        lines.append(f"| `{env_id}` | {imp:.2f} | {make:.3f} |")
    if have_minigrid:
        imp, make = min(cold_make("MiniGrid-Empty-8x8-v0", "minigrid") for _ in range(args.repeat))
        lines.append(f"| `MiniGrid-Empty-8x8-v0` | {imp:.2f} | {make:.3f} |")
    publish("\n".join(lines) + "\n", args.out)
    del flowtest_env
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
