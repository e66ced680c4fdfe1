"""Stable-Baselines3: MaskablePPO (sb3-contrib) on the NumPy vector env through the SB3
``VecEnv`` adapter, so SB3 steps the whole batch at once instead of one env at a time.

    python docs/recipes/sb3_maskable_ppo.py --pool reachability1/5x5-v2 --seed 0 --steps 200000 --save runs/sb3-seed0.zip
    flowtest benchmark --pool reachability1/5x5-v2 --sut 'sb3=ppo:runs/sb3-seed*.zip' --trust-model --out bench

Needs ``pip install -c requirements/lock.txt -e '.[rl]'``. The adapter resets an ended
env in the same step (``infos[i]["terminal_observation"]``, ``"TimeLimit.truncated"``,
as SB3's own VecEnvs) and MaskablePPO reads the masks through ``env_method("action_masks")``.
``--pool`` trains on a standard pool's shipped tests; ``--memory``/``--shaping`` are env
options. The saved zip records the observation options it was trained with
(``flowtest_memory``, ``flowtest_obs``, as ``flowtest train --trainer sb3`` writes them), so
``flowtest benchmark --sut ppo:PATH`` plays it with the same memory; an SB3 zip is unpickled
when loaded, hence ``--trust-model``. One torch thread (the nets are tiny).
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


def main(
    env_id: str = "FlowTest-SmallReactive-v0",
    num_envs: int = 16,
    steps: int = 8192,
    seed: int = 0,
    pool: str | None = None,
    count: int = 128,
    save: str | None = None,
    threads: int = 1,
    **options: Any,
) -> dict[str, float]:
    """Train for ``steps`` env steps; ``pool``: a pool's train tests (``FlowTest-RandomGrid-v0``);
    ``options`` go to the env (``memory``, default ``"visited"``, ``shaping``, ...); ``save``:
    where to write the model. Returns what happened."""
    torch.set_num_threads(threads)
    options = {"memory": "visited", **options}
    if pool:
        env_id, options = "FlowTest-RandomGrid-v0", {**options, "pool": pool, "split": "train", "count": count}
    envs = VecMonitor(make_sb3_vec_env(env_id, num_envs, seed=seed, **options))
    model = MaskablePPO("MlpPolicy", envs, n_steps=32, batch_size=128, n_epochs=4, learning_rate=3e-3, seed=seed, device="cpu")
    ends = Ends()
    start = time.perf_counter()
    model.learn(steps, callback=ends)
    seconds = time.perf_counter() - start
    if save:
        model.flowtest_memory = options["memory"]  # what flowtest benchmark --sut ppo:PATH rebuilds when it plays
        model.flowtest_obs = {"obs_kind": options.get("obs_kind", "flat"), "pad_to": int(options.get("pad_to", 8))}
        model.save(save)
    returns = [e["r"] for e in model.ep_info_buffer or []]
    return {
        "steps": float(model.num_timesteps),
        "episodes": float(ends.episodes),
        "met": float(ends.met),
        "mean_return_last_100": float(np.mean(returns)) if returns else float("nan"),
        "seconds": seconds,
        "steps_per_s": model.num_timesteps / seconds,
    }


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="FlowTest-SmallReactive-v0")
    ap.add_argument("--pool", default=None, help="a pool's train tests, e.g. reachability1/5x5-v2")
    ap.add_argument("--count", type=int, default=128, help="tests of the pool's train split")
    ap.add_argument("--memory", default="visited", choices=["none", "visited"])
    ap.add_argument("--shaping", type=float, default=0.0)
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=8192)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads (one: fastest for small nets on small CPUs)")
    ap.add_argument("--save", default=None, help="model file (.zip) for flowtest benchmark --sut ppo:PATH --trust-model")
    a = ap.parse_args()
    print(main(a.env, a.num_envs, a.steps, a.seed, a.pool, a.count, a.save, a.threads, memory=a.memory, shaping=a.shaping))
