"""TorchRL: PPO on the FlowTest vector env through TorchRL's plain ``GymWrapper``, masked, in
the ``SAME_STEP`` or ``DISABLED`` autoreset mode (TorchRL refuses ``NEXT_STEP``).

    python docs/recipes/torchrl_vector.py --pool reachability1/5x5-v2 --seed 0 --steps 200000 --save runs/torchrl-seed0.pt
    flowtest benchmark --pool reachability1/5x5-v2 --sut 'torchrl=python:docs/recipes/torchrl_vector.py:load@runs/torchrl-seed*.pt' --out bench

Needs ``pip install -c requirements/lock.txt -e '.[rl,recipes]'`` (torchrl, tensordict).
TorchRL turns every info into a tensor: the env option ``numeric_infos=True`` makes the
vector env's infos numbers (the SUT's state index; the legal-action mask ``action_mask``),
so ``GymWrapper(env)`` takes the env as it is; TorchRL's own ``DTypeCastTransform`` gives the
mask as the booleans ``MaskedCategorical`` reads (Gymnasium's masks are ``int8``). (Without
it ``info["system_state"]`` holds the state as JSON lists, which TorchRL cannot stack:
``'LinkedList' object has no attribute 'dtype'``.) ``--pool`` trains on a standard pool's
shipped tests; ``--memory``/``--shaping`` are env options. The saved file holds the actor's
tensors and the observation's env options; :func:`load` makes it a batched policy
(:class:`agents.batched.LogitsPolicy`) for ``flowtest benchmark``. One torch thread.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs import DTypeCastTransform, GymWrapper, TransformedEnv
from torchrl.modules import MaskedCategorical, ProbabilisticActor, ValueOperator
from torchrl.objectives import ClipPPOLoss
from torchrl.objectives.value import GAE

import flowtest_env  # noqa: F401  (registers the FlowTest IDs)
from agents.batched import OBSERVATION_OPTIONS, LogitsPolicy


def make_env(env_id: str, num_envs: int, mode: str, seed: int, **options: Any) -> Any:
    """The vector env as a TorchRL env (batch size ``[num_envs]``): ``numeric_infos=True``, no adapter."""
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode=mode, numeric_infos=True, **options)
    base = GymWrapper(venv, categorical_action_encoding=True)
    if mode == "DISABLED":
        base.auto_register_info_dict()  # GymWrapper reads the infos by itself only in SAME_STEP mode
    env = TransformedEnv(base, DTypeCastTransform(torch.int8, torch.bool, in_keys=["action_mask"]))  # MaskedCategorical's masks
    env.set_seed(seed)
    return env


def actor_net(n_obs: int, n_act: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, n_act))


def main(
    env_id: str = "FlowTest-SmallReactive-v0",
    mode: str = "SAME_STEP",
    num_envs: int = 16,
    steps: int = 8192,
    frames_per_batch: int = 512,
    seed: int = 0,
    pool: str | None = None,
    count: int = 128,
    save: str | None = None,
    threads: int = 1,
    **options: Any,
) -> dict[str, float]:
    """Train PPO for ``steps`` env steps; ``pool``: a pool's train tests (``FlowTest-RandomGrid-v0``);
    ``options`` go to the env (``memory``, default ``"visited"``, ``shaping``); ``save``: where
    to write the actor. Returns what happened: steps, episodes, the actions taken that the
    mask forbade (never any), steps/s."""
    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    options = {"memory": "visited", **options}
    if pool:
        env_id, options = "FlowTest-RandomGrid-v0", {**options, "pool": pool, "split": "train", "count": count}
    env = make_env(env_id, num_envs, mode, seed, **options)
    n_obs, n_act = env.observation_spec["observation"].shape[-1], env.action_spec.space.n
    net = actor_net(n_obs, n_act)
    logits = TensorDictModule(net, in_keys=["observation"], out_keys=["logits"])
    policy = ProbabilisticActor(
        logits,
        in_keys={"logits": "logits", "mask": "action_mask"},
        out_keys=["action"],
        distribution_class=MaskedCategorical,
        return_log_prob=True,
        spec=env.action_spec,
    )
    value = ValueOperator(nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, 1)), in_keys=["observation"])
    loss = ClipPPOLoss(policy, value, entropy_coeff=0.01)
    advantage = GAE(gamma=0.99, lmbda=0.95, value_network=value)
    optim = torch.optim.Adam(loss.parameters(), lr=3e-3)
    collector = Collector(env, policy, frames_per_batch=frames_per_batch, total_frames=steps)
    stats = {"steps": 0.0, "episodes": 0.0, "illegal_actions": 0.0}
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
        legal = batch["action_mask"].gather(-1, batch["action"].unsqueeze(-1))
        stats["steps"] += batch.numel()
        stats["episodes"] += float(batch["next", "done"].sum())
        stats["illegal_actions"] += float((~legal).sum())
    collector.shutdown()
    stats["seconds"] = time.perf_counter() - start
    stats["steps_per_s"] = stats["steps"] / stats["seconds"]
    if save:
        Path(save).parent.mkdir(parents=True, exist_ok=True)
        observation = {k: v for k, v in options.items() if k in OBSERVATION_OPTIONS}
        torch.save({"actor": net.state_dict(), "obs_size": n_obs, "n_actions": n_act, "env_options": observation}, save)
    return stats


def load(path: str) -> LogitsPolicy:
    """A saved actor as a batched policy (``--sut 'python:docs/recipes/torchrl_vector.py:load@runs/*.pt'``)."""
    saved = torch.load(path, map_location="cpu", weights_only=True)  # tensors and plain data: nothing unpickled
    net = actor_net(int(saved["obs_size"]), int(saved["n_actions"]))
    net.load_state_dict(saved["actor"])
    return LogitsPolicy(net, env_options=saved["env_options"])


load.batched = True  # python:...:load names the loader of a batched policy (agents.batched)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="FlowTest-SmallReactive-v0")
    ap.add_argument("--mode", default="SAME_STEP", choices=["SAME_STEP", "DISABLED"])
    ap.add_argument("--pool", default=None, help="a pool's train tests, e.g. reachability1/5x5-v2")
    ap.add_argument("--count", type=int, default=128, help="tests of the pool's train split")
    ap.add_argument("--memory", default="visited", choices=["none", "visited"])
    ap.add_argument("--shaping", type=float, default=0.0)
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=8192)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1, help="torch CPU threads (one: fastest for small nets on small CPUs)")
    ap.add_argument("--save", default=None, help="actor file (.pt) for flowtest benchmark --sut python:...:load@FILES")
    a = ap.parse_args()
    print(main(a.env, a.mode, a.num_envs, a.steps, seed=a.seed, pool=a.pool, count=a.count, save=a.save, threads=a.threads, memory=a.memory, shaping=a.shaping))
