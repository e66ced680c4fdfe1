"""TorchRL: PPO on the FlowTest vector env through ``GymWrapper``, masked, in the
``SAME_STEP`` or ``DISABLED`` autoreset mode (TorchRL refuses ``NEXT_STEP``).

    python docs/recipes/torchrl_vector.py --mode SAME_STEP --steps 20000

Needs ``pip install -c requirements/lock.txt -e '.[rl,recipes]'`` (torchrl, tensordict).
``NumericVectorEnv`` gives the infos as numbers (TorchRL turns every info into a tensor)
with the legal-action mask as ``action_mask``, which ``MaskedCategorical`` reads.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import GymWrapper
from torchrl.modules import MaskedCategorical, ProbabilisticActor, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

import flowtest_env  # noqa: F401  (registers the FlowTest IDs)
from flowtest_env.adapters.numeric import NumericVectorEnv


def make_env(env_id: str, num_envs: int, mode: str, seed: int, **options: Any) -> Any:
    """The vector env as a TorchRL env (batch size ``[num_envs]``)."""
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode=mode, **options)
    env = GymWrapper(NumericVectorEnv(venv), categorical_action_encoding=True)
    if mode == "DISABLED":
        env.auto_register_info_dict()  # GymWrapper reads the infos by itself only in SAME_STEP mode
    env.set_seed(seed)
    return env


def main(env_id: str = "FlowTest-SmallReactive-v0", mode: str = "SAME_STEP", num_envs: int = 16, steps: int = 8192,
         frames_per_batch: int = 512, seed: int = 0) -> dict[str, float]:
    """Train PPO for ``steps`` env steps; returns what happened (steps/s, episodes, ...)."""
    torch.manual_seed(seed)
    env = make_env(env_id, num_envs, mode, seed)
    n_obs, n_act = env.observation_spec["observation"].shape[-1], env.action_spec.space.n
    logits = TensorDictModule(nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, n_act)), in_keys=["observation"], out_keys=["logits"])
    policy = ProbabilisticActor(logits, in_keys={"logits": "logits", "mask": "action_mask"}, out_keys=["action"],
                                distribution_class=MaskedCategorical, return_log_prob=True, spec=env.action_spec)
    value = ValueOperator(nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, 1)), in_keys=["observation"])
    loss = ClipPPOLoss(policy, value, entropy_coeff=0.01)
    advantage = GAE(gamma=0.99, lmbda=0.95, value_network=value)
    optim = torch.optim.Adam(loss.parameters(), lr=3e-3)
    collector = Collector(env, policy, frames_per_batch=frames_per_batch, total_frames=steps)
    stats = {"steps": 0.0, "episodes": 0.0, "met": 0.0, "blocked_attempts": 0.0}
    start = time.perf_counter()
    for batch in collector:
        with torch.no_grad():
            advantage(batch)
        flat = batch.reshape(-1)
        for _ in range(4):
            for mb in flat[torch.randperm(flat.shape[0])].split(128):
                out = loss(mb)
                (out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]).backward()
                optim.step()
                optim.zero_grad()
        ended = batch["next", "done"].squeeze(-1)
        stats["steps"] += batch.numel()
        stats["episodes"] += float(ended.sum())
        stats["met"] += float((batch["next", "system_objective"][ended] == 1).sum())
        stats["blocked_attempts"] += float(batch["next", "blocked_attempts"][ended].sum())
    collector.shutdown()
    stats["seconds"] = time.perf_counter() - start
    stats["steps_per_s"] = stats["steps"] / stats["seconds"]
    return stats


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="FlowTest-SmallReactive-v0")
    ap.add_argument("--mode", default="SAME_STEP", choices=["SAME_STEP", "DISABLED"])
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=8192)
    a = ap.parse_args()
    print(main(a.env, a.mode, a.num_envs, a.steps))
