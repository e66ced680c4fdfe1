"""TorchRL: PPO for ``system_0`` of the PettingZoo game (parallel or AEC) through
``PettingZooWrapper``, masked, the synthesized test holding ``tester_0`` as a fixed policy.

    python docs/recipes/torchrl_pettingzoo.py --api aec --steps 20000

Needs ``pip install -c requirements/lock.txt -e '.[rl,recipes]'``. ``info_kind="numeric"``
gives the infos as numbers (TorchRL stacks them into tensors; the default ``verdict``
dict of strings would crash it at the first episode end); ``use_mask=True`` is required
for the AEC env (one agent acts per step) and harmless for the parallel one.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import PettingZooWrapper
from torchrl.modules import MaskedCategorical, ProbabilisticActor, ValueOperator
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from flowtest_env import multiagent

GROUPS = {"tester": ["tester_0"], "system": ["system_0"]}


def make_env(test: str, api: str, seed: int) -> Any:
    """The PettingZoo game as a TorchRL env (groups ``tester`` and ``system``)."""
    pz = (multiagent.parallel_env if api == "parallel" else multiagent.env)(test=test, info_kind="numeric")
    env = PettingZooWrapper(pz, use_mask=True, categorical_actions=True, group_map=GROUPS, seed=seed)
    return env, multiagent.SynthesizedTester(pz)


class FixedTester(nn.Module):
    """The synthesized tester as a torch module: tester observations to actions."""

    def __init__(self, tester: multiagent.SynthesizedTester) -> None:
        super().__init__()
        self.tester = tester

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        flat = obs.reshape(-1, obs.shape[-1]).numpy()
        return torch.as_tensor(self.tester.actions(flat)).reshape(obs.shape[:-1])


def main(test: str = "small-reactive", api: str = "parallel", steps: int = 8192, frames_per_batch: int = 512, seed: int = 0) -> dict[str, float]:
    """Train the system for ``steps`` env steps; returns what happened (steps/s, episodes, ...)."""
    torch.manual_seed(seed)
    env, tester = make_env(test, api, seed)
    obs_key = ("system", "observation", "observation")
    n_obs = env.observation_spec[obs_key].shape[-1]
    n_act = env.full_action_spec["system", "action"].space.n
    fixed = TensorDictModule(FixedTester(tester), in_keys=[("tester", "observation", "observation")], out_keys=[("tester", "action")])
    logits = TensorDictModule(nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, n_act)), in_keys=[obs_key], out_keys=[("system", "logits")])
    actor = ProbabilisticActor(
        logits,
        in_keys={"logits": ("system", "logits"), "mask": ("system", "action_mask")},
        out_keys=[("system", "action")],
        distribution_class=MaskedCategorical,
        return_log_prob=True,
        log_prob_key=("system", "action_log_prob"),
    )
    value = ValueOperator(nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, 1)), in_keys=[obs_key], out_keys=[("system", "state_value")])
    loss = ClipPPOLoss(actor, value, entropy_coeff=0.01)
    loss.set_keys(
        action=("system", "action"),
        sample_log_prob=("system", "action_log_prob"),
        value=("system", "state_value"),
        reward=("system", "reward"),
        done=("system", "done"),
        terminated=("system", "terminated"),
        advantage=("system", "advantage"),
        value_target=("system", "value_target"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
    optim = torch.optim.Adam(loss.parameters(), lr=3e-3)
    collector = Collector(env, TensorDictSequential(fixed, actor), frames_per_batch=frames_per_batch, total_frames=steps)
    stats = {"steps": 0.0, "episodes": 0.0, "met": 0.0, "test_objective_realized": 0.0}
    start = time.perf_counter()
    for batch in collector:
        with torch.no_grad():
            loss.value_estimator(batch, params=loss.critic_network_params, target_params=loss.target_critic_network_params)
        acted = batch[("system", "mask")].reshape(-1)  # AEC: the steps where the system moved
        flat = batch.reshape(-1)[acted]
        for _ in range(4):
            for mb in flat[torch.randperm(flat.shape[0])].split(128):
                out = loss(mb)
                (out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]).backward()
                optim.step()
                optim.zero_grad()
        ended = batch["next", "done"].reshape(-1)
        info = batch["next", "system", "info"].reshape(-1)[ended]
        stats["steps"] += batch.numel()
        stats["episodes"] += float(ended.sum())
        stats["met"] += float((info["system_objective"] == 1).sum())
        stats["test_objective_realized"] += float(((info["system_objective"] == 1) & (info["test_objective_realized"] == 1)).sum())
    collector.shutdown()
    stats["seconds"] = time.perf_counter() - start
    stats["steps_per_s"] = stats["steps"] / stats["seconds"]
    return stats


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--test", default="small-reactive")
    ap.add_argument("--api", default="parallel", choices=["parallel", "aec"])
    ap.add_argument("--steps", type=int, default=8192)
    a = ap.parse_args()
    torch.set_num_threads(1)
    print(main(a.test, a.api, a.steps))
