"""Stable-Baselines3: MaskablePPO (sb3-contrib) on the NumPy vector env through the SB3
``VecEnv`` adapter, so SB3 steps the whole batch at once instead of one env at a time.

    python docs/recipes/sb3_maskable_ppo.py --env FlowTest-Maze2-v0 --num-envs 64 --steps 200000

Needs ``pip install -c requirements/lock.txt -e '.[rl]'``. The adapter resets an ended
env in the same step (``infos[i]["terminal_observation"]``, ``"TimeLimit.truncated"``,
as SB3's own VecEnvs) and MaskablePPO reads the masks through ``env_method("action_masks")``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
import torch
from sb3_contrib import MaskablePPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor

from flowtest_env.adapters.sb3 import make_sb3_vec_env


class Ends(BaseCallback):
    """Counts the episodes that ended and the ones whose system objective was met."""

    def __init__(self) -> None:
        super().__init__()
        self.episodes = self.met = 0

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "verdict" in info:
                self.episodes += 1
                self.met += info["verdict"]["system_objective"] == "met"
        return True


def main(env_id: str = "FlowTest-SmallReactive-v0", num_envs: int = 16, steps: int = 8192, seed: int = 0, **options: Any) -> dict[str, float]:
    """Train for ``steps`` env steps; ``options`` go to the env (``memory``, ``shaping``, ...)."""
    envs = VecMonitor(make_sb3_vec_env(env_id, num_envs, seed=seed, **options))
    model = MaskablePPO("MlpPolicy", envs, n_steps=32, batch_size=128, n_epochs=4, learning_rate=3e-3, seed=seed)
    ends = Ends()
    start = time.perf_counter()
    model.learn(steps, callback=ends)
    seconds = time.perf_counter() - start
    returns = [e["r"] for e in model.ep_info_buffer or []]
    return {"steps": float(model.num_timesteps), "episodes": float(ends.episodes), "met": float(ends.met),
            "mean_return_last_100": float(np.mean(returns)) if returns else float("nan"),
            "seconds": seconds, "steps_per_s": model.num_timesteps / seconds}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="FlowTest-SmallReactive-v0")
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=8192)
    a = ap.parse_args()
    torch.set_num_threads(1)
    print(main(a.env, a.num_envs, a.steps))
