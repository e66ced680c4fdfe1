"""A plain CleanRL-style PPO loop on the NumPy vector env: no RL library, masked logits,
``memory="visited"`` and reward shaping as env options, ``SAME_STEP`` autoreset.

    python docs/recipes/cleanrl_ppo.py --env FlowTest-Maze2-v0 --num-envs 64 --steps 200000

Needs ``pip install -c requirements/lock.txt -e '.[rl]'`` (torch). The env gives the
legal actions in ``infos["action_mask"]``; illegal logits are set to -inf before sampling.
In ``SAME_STEP`` mode an ended episode's last observation is ``infos["final_obs"][i]``:
the value bootstraps from it where the episode was truncated (not where it terminated).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

import flowtest_env  # noqa: F401  (registers the FlowTest IDs)


def main(env_id: str = "FlowTest-SmallReactive-v0", num_envs: int = 16, steps: int = 8192, n_steps: int = 32, seed: int = 0,
         **options: Any) -> dict[str, float]:
    """Train for ``steps`` env steps; ``options`` go to the env (``memory``, ``shaping``, ...)."""
    options = {"memory": "visited", "shaping": 1.0, **options}
    torch.manual_seed(seed)
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode="SAME_STEP", **options)
    assert isinstance(envs.single_action_space, gym.spaces.Discrete)
    n_obs, n_act = int(np.prod(envs.single_observation_space.shape or ())), int(envs.single_action_space.n)
    actor = nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, n_act))
    critic = nn.Sequential(nn.Linear(n_obs, 64), nn.Tanh(), nn.Linear(64, 1))
    optim = torch.optim.Adam([*actor.parameters(), *critic.parameters()], lr=3e-3)
    gamma, lam, clip = 0.99, 0.95, 0.2
    obs_np, infos = envs.reset(seed=seed)
    stats = {"steps": 0.0, "episodes": 0.0, "met": 0.0}
    start = time.perf_counter()
    while stats["steps"] < steps:
        buf: dict[str, list[torch.Tensor]] = {k: [] for k in ("obs", "mask", "act", "logp", "rew", "val", "next_val", "term", "done")}
        for _ in range(n_steps):
            obs = torch.as_tensor(obs_np, dtype=torch.float32).reshape(num_envs, -1)
            mask = torch.as_tensor(infos["action_mask"], dtype=torch.bool)
            with torch.no_grad():
                dist = torch.distributions.Categorical(logits=actor(obs).masked_fill(~mask, -torch.inf))
                act = dist.sample()
                val = critic(obs).squeeze(-1)
            obs_np, rew, term, trunc, infos = envs.step(act.numpy())
            nxt = torch.as_tensor(obs_np, dtype=torch.float32).reshape(num_envs, -1)
            done = term | trunc
            if done.any():  # bootstrap from the ended episodes' own last observation
                final = np.stack([infos["final_obs"][i] if done[i] else obs_np[i] for i in range(num_envs)])
                nxt = torch.as_tensor(final, dtype=torch.float32).reshape(num_envs, -1)
                stats["episodes"] += float(done.sum())
                stats["met"] += float(np.sum(infos["final_info"]["verdict"]["system_objective"][done] == "met"))
            with torch.no_grad():
                next_val = critic(nxt).squeeze(-1)
            for k, v in (("obs", obs), ("mask", mask), ("act", act), ("logp", dist.log_prob(act)), ("rew", torch.as_tensor(rew, dtype=torch.float32)),
                         ("val", val), ("next_val", next_val), ("term", torch.as_tensor(term)), ("done", torch.as_tensor(done))):
                buf[k].append(v)
        b = {k: torch.stack(v) for k, v in buf.items()}
        adv = torch.zeros_like(b["rew"])
        last = torch.zeros(num_envs)
        for t in reversed(range(n_steps)):  # GAE; a new episode starts after a done
            delta = b["rew"][t] + gamma * b["next_val"][t] * (~b["term"][t]) - b["val"][t]
            last = delta + gamma * lam * (~b["done"][t]) * last
            adv[t] = last
        ret = adv + b["val"]
        flat = {k: v.reshape(n_steps * num_envs, *v.shape[2:]) for k, v in {**b, "adv": adv, "ret": ret}.items()}
        for _ in range(4):
            for idx in torch.split(torch.randperm(n_steps * num_envs), 128):
                logits = actor(flat["obs"][idx]).masked_fill(~flat["mask"][idx], -torch.inf)
                dist = torch.distributions.Categorical(logits=logits)
                ratio = (dist.log_prob(flat["act"][idx]) - flat["logp"][idx]).exp()
                a = (flat["adv"][idx] - flat["adv"][idx].mean()) / (flat["adv"][idx].std() + 1e-8)
                pg = -torch.min(ratio * a, ratio.clamp(1 - clip, 1 + clip) * a).mean()
                v = (critic(flat["obs"][idx]).squeeze(-1) - flat["ret"][idx]).pow(2).mean()
                optim.zero_grad()
                (pg + 0.5 * v - 0.01 * dist.entropy().mean()).backward()
                optim.step()
        stats["steps"] += n_steps * num_envs
    stats["seconds"] = time.perf_counter() - start
    stats["steps_per_s"] = stats["steps"] / stats["seconds"]
    return stats


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--env", default="FlowTest-SmallReactive-v0")
    ap.add_argument("--num-envs", type=int, default=16)
    ap.add_argument("--steps", type=int, default=8192)
    a = ap.parse_args()
    torch.set_num_threads(1)
    print(main(a.env, a.num_envs, a.steps))
