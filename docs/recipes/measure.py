"""Steps per second of each recipe on this machine: a short training run of each (the
numbers docs/recipes.md lists), and the env alone through each library's interface
with random legal actions (no learning).

    python docs/recipes/measure.py            # every recipe the installed libraries allow
    python docs/recipes/measure.py --only sb3_maskable_ppo cleanrl_ppo

One torch thread (the nets are tiny). RLlib runs in its own venv: run
``.venv-rllib/bin/python docs/recipes/rllib_recipe.py --steps 512`` there.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import flowtest_env  # noqa: F401  (registers the FlowTest IDs)

HERE = Path(__file__).resolve().parent


def recipe(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # as an import does: a dataclass of the recipe looks its module up
    spec.loader.exec_module(module)
    return module


def vector_alone(num_envs: int, steps: int) -> float:
    """The NumPy vector env stepped by hand (random legal actions): the ceiling."""
    envs = gym.make_vec("FlowTest-SmallReactive-v0", num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode="SAME_STEP")
    _, infos = envs.reset(seed=0)
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    for _ in range(steps // num_envs):
        mask = infos["action_mask"].astype(bool)
        actions = np.argmax(rng.random(mask.shape) * mask, axis=1)
        _, _, _, _, infos = envs.step(actions)
    return steps / (time.perf_counter() - start)


def sb3_adapter_alone(num_envs: int, steps: int) -> float:
    from flowtest_env.adapters.sb3 import make_sb3_vec_env

    envs = make_sb3_vec_env("FlowTest-SmallReactive-v0", num_envs, seed=0)
    envs.reset()
    rng = np.random.default_rng(0)
    start = time.perf_counter()
    for _ in range(steps // num_envs):
        mask = envs.action_masks()
        envs.step(np.argmax(rng.random(mask.shape) * mask, axis=1))
    return steps / (time.perf_counter() - start)


def torchrl_vector_alone(mode: str, num_envs: int, steps: int) -> float:
    env = recipe("torchrl_vector").make_env("FlowTest-SmallReactive-v0", num_envs, mode, 0)
    start = time.perf_counter()
    env.rollout(steps // num_envs, break_when_any_done=False)
    return steps / (time.perf_counter() - start)


def torchrl_pettingzoo_alone(api: str, steps: int) -> float:
    env, _ = recipe("torchrl_pettingzoo").make_env("small-reactive", api, 0)
    start = time.perf_counter()
    env.rollout(steps, break_when_any_done=False)
    return steps / (time.perf_counter() - start)


def runs() -> dict[str, Callable[[], dict[str, Any]]]:
    return {
        "numpy_vector_env": lambda: {"env_alone": vector_alone(64, 64 * 500), "env_alone_1024": vector_alone(1024, 1024 * 100)},
        "sb3_maskable_ppo": lambda: {**recipe("sb3_maskable_ppo").main(num_envs=16, steps=4096), "env_alone": sb3_adapter_alone(64, 64 * 300)},
        "cleanrl_ppo": lambda: recipe("cleanrl_ppo").main(num_envs=16, steps=4096),
        "torchrl_vector SAME_STEP": lambda: {
            **recipe("torchrl_vector").main(mode="SAME_STEP", num_envs=16, steps=2048),
            "env_alone": torchrl_vector_alone("SAME_STEP", 64, 64 * 50),
        },
        "torchrl_vector DISABLED": lambda: {
            **recipe("torchrl_vector").main(mode="DISABLED", num_envs=16, steps=2048),
            "env_alone": torchrl_vector_alone("DISABLED", 64, 64 * 50),
        },
        "torchrl_pettingzoo parallel": lambda: {
            **recipe("torchrl_pettingzoo").main(api="parallel", steps=512),
            "env_alone": torchrl_pettingzoo_alone("parallel", 200),
        },
        "torchrl_pettingzoo aec": lambda: {**recipe("torchrl_pettingzoo").main(api="aec", steps=512), "env_alone": torchrl_pettingzoo_alone("aec", 200)},
        "tianshou_aec": lambda: recipe("tianshou_aec").main(steps=1024, num_envs=8),
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", default=None)
    a = ap.parse_args()
    torch.set_num_threads(1)
    for name, run in runs().items():
        if a.only and name.split()[0] not in a.only:
            continue
        try:
            result = run()
        except ImportError as e:
            result = {"skipped": str(e)}
        print(json.dumps({"recipe": name, **{k: round(v, 1) if isinstance(v, float) else v for k, v in result.items()}}), flush=True)
    sys.exit(0)
