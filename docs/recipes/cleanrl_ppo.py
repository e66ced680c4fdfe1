"""CleanRL's single-file PPO (``cleanrl/ppo.py``) on FlowTest, written as a CleanRL user writes
it: the same ``Args``, ``make_env``, ``layer_init``, ``Agent`` and loop, with two changes only.

1. **The env id** (``make_env``): FlowTest's batched vector env by its id and options,
   ``gym.make_vec(env_id, num_envs, vectorization_mode="vector_entry_point",
   autoreset_mode="SAME_STEP", **options)``, where CleanRL builds a ``SyncVectorEnv`` of single
   envs; ``--pool`` trains on a standard pool's shipped tests (``FlowTest-RandomGrid-v0``),
   ``--memory``/``--shaping`` are env options. ``SAME_STEP`` is the autoreset CleanRL's loop
   assumes (an ended env's next observation starts its next episode).
2. **The mask**: the env gives the legal actions in ``infos["action_mask"]``; the loop keeps
   them with each observation and the ``Agent`` sets the illegal actions' logits to -inf,
   when acting and when it re-evaluates the rollout.

Run it (one torch thread: the nets are tiny, and on a small CPU torch's default threads make
the loop about 9x slower: docs/recipes.md)::

    python docs/recipes/cleanrl_ppo.py --pool reachability1/5x5-v2 --seed 0 --total-timesteps 500000 --save-model runs/seed0.pt
    flowtest benchmark --pool reachability1/5x5-v2 --sut 'cleanrl=python:docs/recipes/cleanrl_ppo.py:load@runs/*.pt' --out bench

The saved file holds the agent's tensors, its sizes and the env options of its observation
(``torch.load(..., weights_only=True)`` reads it back without unpickling code); :func:`load`
turns it into a batched policy (:class:`agents.batched.LogitsPolicy`) that ``flowtest
benchmark`` plays greedily and sampled, with the memory it was trained with, one seed per
file. Needs ``pip install -c requirements/lock.txt -e '.[rl]'`` (torch).
"""

from __future__ import annotations

import argparse
import dataclasses
import random
import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn, optim
from torch.distributions.categorical import Categorical

import flowtest_env  # noqa: F401  (registers the FlowTest IDs)
from agents.batched import OBSERVATION_OPTIONS, LogitsPolicy


@dataclass
class Args:
    exp_name: str = "cleanrl_ppo"
    """the name of this experiment"""
    seed: int = 1
    """seed of the experiment"""
    torch_deterministic: bool = True
    """if toggled, `torch.backends.cudnn.deterministic=False`"""
    cuda: bool = False
    """use cuda when torch sees one (the nets are tiny: the CPU is as fast)"""
    threads: int = 1
    """torch CPU threads (one: the fastest for small nets on a small CPU)"""
    save_model: str | None = None
    """where to save the trained agent (a file `load` reads; `flowtest benchmark --sut` scores it)"""

    # the env: its id and options (change 1)
    env_id: str = "FlowTest-SmallReactive-v0"
    """the id of the environment (FlowTest-RandomGrid-v0 with --pool)"""
    pool: str | None = None
    """train on a pool's tests (a standard pool id: reachability1/5x5-v2)"""
    count: int = 128
    """tests of the pool's train split"""
    memory: str = "visited"
    """env option: the SUT's memory (none or visited)"""
    shaping: float = 0.0
    """env option: potential-based shaping towards the SUT's objective (0 = off)"""

    # Algorithm specific arguments
    total_timesteps: int = 500_000
    """total timesteps of the experiments"""
    learning_rate: float = 1e-3
    """the learning rate of the optimizer"""
    num_envs: int = 16
    """the number of parallel game environments"""
    num_steps: int = 64
    """the number of steps to run in each environment per policy rollout"""
    anneal_lr: bool = True
    """Toggle learning rate annealing for policy and value networks"""
    gamma: float = 0.99
    """the discount factor gamma"""
    gae_lambda: float = 0.95
    """the lambda for the general advantage estimation"""
    num_minibatches: int = 4
    """the number of mini-batches"""
    update_epochs: int = 4
    """the K epochs to update the policy"""
    norm_adv: bool = True
    """Toggles advantages normalization"""
    clip_coef: float = 0.2
    """the surrogate clipping coefficient"""
    clip_vloss: bool = True
    """Toggles whether or not to use a clipped loss for the value function, as per the paper."""
    ent_coef: float = 0.01
    """coefficient of the entropy"""
    vf_coef: float = 0.5
    """coefficient of the value function"""
    max_grad_norm: float = 0.5
    """the maximum norm for the gradient clipping"""
    target_kl: float | None = None
    """the target KL divergence threshold"""


def env_options(args: Args) -> dict[str, Any]:
    """The env's options: the pool's tests, the memory, the shaping."""
    options: dict[str, Any] = {"memory": args.memory, "shaping": args.shaping}
    if args.pool:
        options.update(pool=args.pool, split="train", count=args.count)
    return options


def make_env(args: Args) -> gym.vector.VectorEnv:
    """Change 1: FlowTest's batched vector env by its id and options (``SAME_STEP`` autoreset)."""
    env_id = "FlowTest-RandomGrid-v0" if args.pool else args.env_id
    envs = gym.make_vec(env_id, num_envs=args.num_envs, vectorization_mode="vector_entry_point", autoreset_mode="SAME_STEP", **env_options(args))
    return gym.wrappers.vector.RecordEpisodeStatistics(envs)


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias_const: float = 0.0) -> nn.Linear:
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    def __init__(self, obs_size: int, n_actions: int) -> None:
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_size, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 1), std=1.0),
        )
        self.actor = nn.Sequential(
            layer_init(nn.Linear(obs_size, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, 64)),
            nn.Tanh(),
            layer_init(nn.Linear(64, n_actions), std=0.01),
        )

    def get_value(self, x: torch.Tensor) -> torch.Tensor:
        out: torch.Tensor = self.critic(x)
        return out

    def get_action_and_value(
        self, x: torch.Tensor, mask: torch.Tensor, action: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        logits = self.actor(x).masked_fill(~mask, -torch.inf)  # change 2: never an illegal action
        probs = Categorical(logits=logits)
        if action is None:
            action = probs.sample()
        return action, probs.log_prob(action), probs.entropy(), self.critic(x)


def train(args: Args) -> dict[str, float]:
    """CleanRL's PPO loop; returns what happened (steps, episodes, met, steps/s)."""
    batch_size = int(args.num_envs * args.num_steps)
    minibatch_size = int(batch_size // args.num_minibatches)
    num_iterations = max(1, args.total_timesteps // batch_size)

    # TRY NOT TO MODIFY: seeding
    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.backends.cudnn.deterministic = args.torch_deterministic
    torch.set_num_threads(args.threads)
    device = torch.device("cuda" if torch.cuda.is_available() and args.cuda else "cpu")

    # env setup
    envs = make_env(args)
    assert isinstance(envs.single_action_space, gym.spaces.Discrete), "only discrete action space is supported"
    obs_shape = envs.single_observation_space.shape or ()
    n_actions = int(envs.single_action_space.n)
    agent = Agent(int(np.prod(obs_shape)), n_actions).to(device)
    optimizer = optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)

    # ALGO Logic: Storage setup
    obs = torch.zeros((args.num_steps, args.num_envs, *obs_shape)).to(device)
    masks = torch.zeros((args.num_steps, args.num_envs, n_actions), dtype=torch.bool).to(device)  # change 2
    actions = torch.zeros((args.num_steps, args.num_envs), dtype=torch.long).to(device)
    logprobs = torch.zeros((args.num_steps, args.num_envs)).to(device)
    rewards = torch.zeros((args.num_steps, args.num_envs)).to(device)
    dones = torch.zeros((args.num_steps, args.num_envs)).to(device)
    values = torch.zeros((args.num_steps, args.num_envs)).to(device)

    # TRY NOT TO MODIFY: start the game
    global_step = 0
    stats = {"episodes": 0.0, "met": 0.0}
    start_time = time.time()
    next_obs_np, infos = envs.reset(seed=args.seed)
    next_obs = torch.Tensor(next_obs_np).to(device)
    next_mask = torch.as_tensor(infos["action_mask"], dtype=torch.bool, device=device)
    next_done = torch.zeros(args.num_envs).to(device)

    for iteration in range(1, num_iterations + 1):
        if args.anneal_lr:
            frac = 1.0 - (iteration - 1.0) / num_iterations
            optimizer.param_groups[0]["lr"] = frac * args.learning_rate

        for step in range(0, args.num_steps):
            global_step += args.num_envs
            obs[step] = next_obs
            dones[step] = next_done
            masks[step] = next_mask

            # ALGO LOGIC: action logic
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(next_obs, next_mask)
                values[step] = value.flatten()
            actions[step] = action
            logprobs[step] = logprob

            # TRY NOT TO MODIFY: execute the game and log data.
            next_obs_np, reward, terminations, truncations, infos = envs.step(action.cpu().numpy())
            next_done_np = np.logical_or(terminations, truncations)
            rewards[step] = torch.tensor(reward).to(device).view(-1)
            next_obs, next_done = torch.Tensor(next_obs_np).to(device), torch.Tensor(next_done_np).to(device)
            next_mask = torch.as_tensor(infos["action_mask"], dtype=torch.bool, device=device)

            if "episode" in infos:
                ended = np.flatnonzero(infos["_episode"])
                stats["episodes"] += len(ended)
                stats["met"] += float(np.sum(infos["final_info"]["verdict"]["system_objective"][ended] == "met"))

        # bootstrap value if not done
        with torch.no_grad():
            next_value = agent.get_value(next_obs).reshape(1, -1)
            advantages = torch.zeros_like(rewards).to(device)
            lastgaelam = torch.zeros(args.num_envs).to(device)
            for t in reversed(range(args.num_steps)):
                if t == args.num_steps - 1:
                    nextnonterminal = 1.0 - next_done
                    nextvalues = next_value
                else:
                    nextnonterminal = 1.0 - dones[t + 1]
                    nextvalues = values[t + 1]
                delta = rewards[t] + args.gamma * nextvalues * nextnonterminal - values[t]
                advantages[t] = lastgaelam = delta + args.gamma * args.gae_lambda * nextnonterminal * lastgaelam
            returns = advantages + values

        # flatten the batch
        b_obs = obs.reshape((-1, *obs_shape))
        b_masks = masks.reshape((-1, n_actions))
        b_logprobs = logprobs.reshape(-1)
        b_actions = actions.reshape(-1)
        b_advantages = advantages.reshape(-1)
        b_returns = returns.reshape(-1)
        b_values = values.reshape(-1)

        # Optimizing the policy and value network
        b_inds = np.arange(batch_size)
        for _epoch in range(args.update_epochs):
            np.random.shuffle(b_inds)
            for start in range(0, batch_size, minibatch_size):
                mb_inds = b_inds[start : start + minibatch_size]

                _, newlogprob, entropy, newvalue = agent.get_action_and_value(b_obs[mb_inds], b_masks[mb_inds], b_actions[mb_inds])
                logratio = newlogprob - b_logprobs[mb_inds]
                ratio = logratio.exp()
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - logratio).mean()

                mb_advantages = b_advantages[mb_inds]
                if args.norm_adv:
                    mb_advantages = (mb_advantages - mb_advantages.mean()) / (mb_advantages.std() + 1e-8)

                # Policy loss
                pg_loss = torch.max(-mb_advantages * ratio, -mb_advantages * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)).mean()

                # Value loss
                newvalue = newvalue.view(-1)
                if args.clip_vloss:
                    v_loss_unclipped = (newvalue - b_returns[mb_inds]) ** 2
                    v_clipped = b_values[mb_inds] + torch.clamp(newvalue - b_values[mb_inds], -args.clip_coef, args.clip_coef)
                    v_loss = 0.5 * torch.max(v_loss_unclipped, (v_clipped - b_returns[mb_inds]) ** 2).mean()
                else:
                    v_loss = 0.5 * ((newvalue - b_returns[mb_inds]) ** 2).mean()

                loss = pg_loss - args.ent_coef * entropy.mean() + v_loss * args.vf_coef
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()

            if args.target_kl is not None and approx_kl > args.target_kl:
                break

    envs.close()
    seconds = time.time() - start_time
    if args.save_model:
        save(agent, args, int(np.prod(obs_shape)), n_actions)
    return {**stats, "steps": float(global_step), "seconds": seconds, "steps_per_s": global_step / seconds}


def save(agent: Agent, args: Args, obs_size: int, n_actions: int) -> None:
    """The agent's tensors, its sizes and the options its observation was made with."""
    from pathlib import Path

    assert args.save_model
    Path(args.save_model).parent.mkdir(parents=True, exist_ok=True)
    options = {k: v for k, v in env_options(args).items() if k in OBSERVATION_OPTIONS}
    torch.save({"agent": agent.state_dict(), "obs_size": obs_size, "n_actions": n_actions, "env_options": options}, args.save_model)


def load(path: str) -> LogitsPolicy:
    """A saved agent as a batched policy (``flowtest benchmark --sut 'python:docs/recipes/cleanrl_ppo.py:load@runs/*.pt'``):
    its actor's logits, masked, greedy or sampled, shown the observations it trained on."""
    saved = torch.load(path, map_location="cpu", weights_only=True)  # tensors and plain data: nothing unpickled
    agent = Agent(int(saved["obs_size"]), int(saved["n_actions"]))
    agent.load_state_dict(saved["agent"])
    agent.eval()
    return LogitsPolicy(agent.actor, env_options=saved["env_options"])


load.batched = True  # python:...:load names the loader of a batched policy (agents.batched)


def main(**settings: Any) -> dict[str, float]:
    """Train with :class:`Args` (``settings`` replace its fields; ``steps`` is
    ``total_timesteps``); returns what happened."""
    if "steps" in settings:
        settings["total_timesteps"] = settings.pop("steps")
    return train(Args(**settings))


def parse_args() -> Args:
    """:class:`Args` from the command line (``--total-timesteps 500000``, ``--no-anneal-lr``), as ``tyro.cli(Args)``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    for f in dataclasses.fields(Args):
        flag = "--" + f.name.replace("_", "-")
        if f.type in ("bool", bool):
            ap.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default)
        else:
            kind = {"int": int, "float": float}.get(str(f.type).split(" ")[0], str)
            ap.add_argument(flag, type=kind, default=f.default)
    return Args(**vars(ap.parse_args()))


if __name__ == "__main__":
    print(train(parse_args()))
