"""The PPO core every native policy shares: the rollout (:class:`Runner`,
:func:`collect_rollout`), the advantages (:func:`advantages`), the minibatches and the
clipped loss (:func:`ppo_loss`), and the update (:func:`ppo_update`), as in CleanRL's
``ppo.py`` between its ``Args`` and its loop.

What it gets right, and where:

* **The autoreset step**: the vector env resets an env on the step *after* its episode
  ended (Gymnasium's ``NEXT_STEP``), ignoring that step's action. Such a step is no
  transition of the policy: :class:`Rollout` marks it (``valid`` is false) and the loss
  never trains on it (the minibatches hold the valid steps only, or weigh the others 0).
* **Truncation vs termination**: a terminated episode bootstraps nothing; a truncated one
  (its step budget ran out) bootstraps the value of its last observation, which the
  ``NEXT_STEP`` env returns at the truncating step (:func:`advantages`).
* **Recurrent state**: a recurrent network's minibatches are whole env sequences replayed
  from the rollout's first state (:func:`env_minibatches`), a feed-forward one's shuffled
  steps (:func:`step_minibatches`).

Example (the loop of :func:`agents.native_ppo.train`, one iteration)::

    rollout = collect_rollout(runner, args.num_steps)
    info = ppo_update(agent, optimizer, args, rollout, generator)
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from flowtest_env.compiled import OUTCOMES

from .agent import Agent, masked_logits
from .args import NativeArgs
from .envs import VisitedBits

MET_CODE = OUTCOMES.index("met")
"""The outcome code of ``"met"`` in the torch env's verdicts."""


@dataclass
class Rollout:
    """``num_steps`` steps of every env (time first: ``[T, N, ...]``).

    ``valid[t, i]`` is false on env ``i``'s autoreset step (its previous step ended an
    episode: the env reset it and ignored the action); the loss never uses those steps.
    ``starts[t, i]``: ``obs[t, i]`` is the first observation of an episode.
    """

    obs: torch.Tensor
    masks: torch.Tensor
    actions: torch.Tensor
    logprobs: torch.Tensor
    values: torch.Tensor
    rewards: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    valid: torch.Tensor
    starts: torch.Tensor
    h0: torch.Tensor
    next_value: torch.Tensor
    levels: np.ndarray | None = None  # int64[T, N]: the test each obs[t, i] belongs to (level sampling only)


class EpisodeStats:
    """Episode ends seen while training: return, met, realized, restrictions, steps."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, bool, bool, int, int]] = []

    def take(self) -> dict[str, float]:
        """Means over the episodes since the last call (empty: ``{}``)."""
        rows, self.rows = self.rows, []
        if not rows:
            return {}
        r = np.array(rows, dtype=np.float64)
        return {"episodes": float(len(rows)), "return": float(r[:, 0].mean()), "met": float(r[:, 1].mean()),
                "realized": float(r[:, 2].mean()), "restrictions": float(r[:, 3].mean()), "length": float(r[:, 4].mean())}


class Runner:
    """Steps the vector env with the agent and keeps what carries over between rollouts:
    the last observation, masks, episode flags, the memory, the GRU state, returns."""

    def __init__(self, env: Any, agent: Agent, where: slice | None, device: torch.device, seed: int,
                 levels: Callable[[], np.ndarray] | None = None) -> None:
        self.env, self.agent, self.device = env, agent, device
        self.levels = levels  # the test each env plays now (recorded per step when given)
        self.n = int(env.num_envs)
        self.torch_env = hasattr(env, "tables")  # flowtest_env.torch_vector: tensors in, tensors out
        obs, infos = env.reset(seed=seed)
        self.memory = VisitedBits(where)
        self.start = torch.ones(self.n, dtype=torch.bool, device=device)
        self.reset_step = torch.zeros(self.n, dtype=torch.bool, device=device)  # the next step is the autoreset step
        self.x = self.memory(self._tensor(obs), self.start)
        self.mask = self._tensor(infos["action_mask"]).bool()
        self.h = agent.initial_state(self.n, device)
        self.ret = torch.zeros(self.n, dtype=torch.float64, device=device)
        self.stats = EpisodeStats()

    def _tensor(self, a: Any) -> torch.Tensor:
        return torch.as_tensor(a if isinstance(a, torch.Tensor) else np.asarray(a), device=self.device)

    def collect(self, num_steps: int) -> Rollout:
        """:func:`collect_rollout`."""
        T, N, dev = num_steps, self.n, self.device
        obs = torch.zeros((T, N, self.x.shape[1]), device=dev)
        masks = torch.zeros((T, N, self.mask.shape[1]), dtype=torch.bool, device=dev)
        actions = torch.zeros((T, N), dtype=torch.long, device=dev)
        logprobs, values, rewards = (torch.zeros((T, N), device=dev) for _ in range(3))
        terminated, truncated, valid, starts = (torch.zeros((T, N), dtype=torch.bool, device=dev) for _ in range(4))
        h0 = self.h.clone()
        levels = np.zeros((T, N), dtype=np.int64) if self.levels is not None else None
        for t in range(T):
            obs[t], masks[t], starts[t], valid[t] = self.x, self.mask, self.start, ~self.reset_step
            if levels is not None and self.levels is not None:
                levels[t] = self.levels()
            with torch.no_grad():
                logits, value, self.h = self.agent.step(self.x, self.h, self.start)
                logits = masked_logits(logits, self.mask)
                a = sample(logits)
                logprobs[t] = torch.log_softmax(logits, dim=-1).gather(1, a.unsqueeze(1)).squeeze(1)
            actions[t], values[t] = a, value
            o, r, term, trunc, infos = self.env.step(a if self.torch_env else a.cpu().numpy())
            rewards[t] = self._tensor(r).float()
            terminated[t], truncated[t] = self._tensor(term), self._tensor(trunc)
            done = terminated[t] | truncated[t]
            self._episode_ends(rewards[t], done, infos)
            self.start = self.reset_step  # the autoreset step's observation is a new episode's first
            self.reset_step = done
            self.x = self.memory(self._tensor(o), self.start)
            self.mask = self._tensor(infos["action_mask"]).bool()
        with torch.no_grad():
            next_value = self.agent.value(self.x, self.h, self.start)
        return Rollout(obs, masks, actions, logprobs, values, rewards, terminated, truncated, valid, starts, h0, next_value,
                       levels)

    def _episode_ends(self, r: torch.Tensor, done: torch.Tensor, infos: dict[str, Any]) -> None:
        self.ret += r
        if not bool(done.any()):
            return
        v = infos["verdict"]
        idx = torch.nonzero(done).squeeze(1)
        outcome = v["system_objective"]
        met = (outcome == MET_CODE) if isinstance(outcome, torch.Tensor) else torch.as_tensor(np.asarray(outcome == "met"))
        cols = [self.ret[idx].cpu().numpy(), met.to(self.device)[idx].cpu().numpy()]
        cols += [self._tensor(v[k])[idx].cpu().numpy() for k in ("test_objective_realized", "restrictions", "steps")]
        for ret, m, real, restr, steps in zip(*cols, strict=True):
            self.stats.rows.append((float(ret), bool(m), bool(real), int(restr), int(steps)))
        self.ret[idx] = 0.0


def sample(logits: torch.Tensor) -> torch.Tensor:
    """One action per row from ``softmax(logits)`` (Gumbel-max, torch's seeded generator)."""
    u = torch.rand_like(logits).clamp_(1e-12, 1.0)
    return torch.argmax(logits - torch.log(-torch.log(u)), dim=-1)


def collect_rollout(runner: Runner, num_steps: int) -> Rollout:
    """``num_steps`` steps of every env of ``runner`` with actions sampled from the masked
    policy (see :class:`Rollout` for what is recorded)."""
    return runner.collect(num_steps)


def advantages(r: Rollout, gamma: float, lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """GAE advantages and returns of a rollout.

    ``delta_t = r_t + gamma * V(o_{t+1}) * (1 - terminated_t) - V(o_t)``, and the sum
    ``A_t = delta_t + gamma * lam * (1 - done_t) * A_{t+1}`` stops at every episode end.
    At a truncation ``o_{t+1}`` is the episode's last observation (the ``NEXT_STEP``
    env returns it, and resets at the next, invalid step), so its value is bootstrapped;
    at a termination nothing is. The autoreset steps get numbers too but are never used.
    """
    T = r.rewards.shape[0]
    adv = torch.zeros_like(r.rewards)
    last = torch.zeros_like(r.next_value)
    for t in reversed(range(T)):
        next_v = r.next_value if t == T - 1 else r.values[t + 1]
        term = r.terminated[t].float()
        cont = 1.0 - (r.terminated[t] | r.truncated[t]).float()
        delta = r.rewards[t] + gamma * next_v * (1.0 - term) - r.values[t]
        last = delta + gamma * lam * cont * last
        adv[t] = last
    return adv, adv + r.values


def minibatch_indices(valid: torch.Tensor, num_minibatches: int, generator: torch.Generator | None = None) -> list[torch.Tensor]:
    """The flat indices (into ``[T * N]``) of the steps the MLP's loss trains on, in
    ``num_minibatches`` shuffled minibatches: exactly the valid steps, each once."""
    idx = torch.nonzero(valid.reshape(-1), as_tuple=False).squeeze(1)
    perm = idx[torch.randperm(idx.numel(), generator=generator, device="cpu").to(idx.device)]
    return [chunk for chunk in torch.tensor_split(perm, num_minibatches) if chunk.numel()]



@dataclass(frozen=True)
class Minibatch:
    """The samples of one gradient step: a recurrent network's ``[T, n, ...]`` env
    sequences (``h0``: their states at the rollout's start), or a feed-forward network's
    ``[B, ...]`` shuffled steps; ``weight`` is 1 for a valid step, 0 for an autoreset step."""

    obs: torch.Tensor
    masks: torch.Tensor
    actions: torch.Tensor
    logprobs: torch.Tensor
    adv: torch.Tensor
    returns: torch.Tensor
    weight: torch.Tensor
    h0: torch.Tensor
    starts: torch.Tensor


def step_minibatches(r: Rollout, adv: torch.Tensor, returns: torch.Tensor, num_minibatches: int,
                     generator: torch.Generator | None = None) -> Iterator[Minibatch]:
    """The valid steps of ``r`` shuffled into ``num_minibatches`` minibatches
    (:func:`minibatch_indices`), for a feed-forward network."""
    T, N = r.rewards.shape
    flat = {k: v.reshape(T * N, *v.shape[2:]) for k, v in
            (("obs", r.obs), ("masks", r.masks), ("actions", r.actions), ("logprobs", r.logprobs),
             ("adv", adv), ("returns", returns), ("starts", r.starts))}
    for mb in minibatch_indices(r.valid, num_minibatches, generator):
        x = flat["obs"][mb]
        yield Minibatch(x, flat["masks"][mb], flat["actions"][mb], flat["logprobs"][mb], flat["adv"][mb], flat["returns"][mb],
                        torch.ones(mb.numel(), dtype=torch.bool, device=x.device), r.h0.new_zeros((mb.numel(), r.h0.shape[1])),
                        flat["starts"][mb])


def env_minibatches(r: Rollout, adv: torch.Tensor, returns: torch.Tensor, num_minibatches: int,
                    generator: torch.Generator | None = None) -> Iterator[Minibatch]:
    """The envs of ``r`` shuffled into ``num_minibatches`` groups, each minibatch their
    whole sequences (autoreset steps weighed 0), for a recurrent network."""
    N = r.rewards.shape[1]
    perm = torch.randperm(N, generator=generator).to(r.obs.device)
    for envs in torch.tensor_split(perm, num_minibatches):
        yield Minibatch(r.obs[:, envs], r.masks[:, envs], r.actions[:, envs], r.logprobs[:, envs], adv[:, envs],
                        returns[:, envs], r.valid[:, envs], r.h0[envs], r.starts[:, envs])


def ppo_loss(args: NativeArgs, mb: Minibatch, logits: torch.Tensor, values: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """The clipped PPO loss over the samples of ``mb`` (``logits`` and ``values``: the
    network's on them now), each weighted by ``mb.weight``; the advantages normalized
    over the weighted samples."""
    w = mb.weight.float()
    n = w.sum().clamp(min=1.0)
    logp_all = torch.log_softmax(masked_logits(logits, mb.masks), dim=-1)
    logp = logp_all.gather(-1, mb.actions.unsqueeze(-1)).squeeze(-1)
    adv = mb.adv
    mean = (adv * w).sum() / n
    std = torch.sqrt((((adv - mean) ** 2) * w).sum() / n + 1e-8)
    a = torch.where(w > 0, (adv - mean) / std, torch.zeros_like(adv))
    ratio = torch.exp(torch.where(w > 0, logp - mb.logprobs, torch.zeros_like(logp)))
    pg = torch.maximum(-a * ratio, -a * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef))
    pg_loss = (pg * w).sum() / n
    v_loss = 0.5 * (((values - mb.returns) ** 2) * w).sum() / n
    entropy = -(logp_all.exp() * logp_all).sum(-1)
    ent = (entropy * w).sum() / n
    loss = pg_loss + args.vf_coef * v_loss - args.ent_coef * ent
    with torch.no_grad():
        kl = (((ratio - 1) - torch.log(ratio.clamp(min=1e-12))) * w).sum() / n
    return loss, {"policy_loss": float(pg_loss.detach()), "value_loss": float(v_loss.detach()), "entropy": float(ent.detach()),
                  "approx_kl": float(kl)}


def ppo_update(agent: Agent, optimizer: torch.optim.Optimizer, args: NativeArgs, r: Rollout,
               generator: torch.Generator | None = None) -> dict[str, float]:
    """``update_epochs`` passes of minibatch gradient steps over the rollout's valid steps
    (feed-forward: shuffled steps; recurrent: shuffled envs, each replayed from the
    rollout's start). Returns the last minibatch's loss terms, for the log."""
    adv, returns = advantages(r, args.gamma, args.gae_lambda)
    minibatches = env_minibatches if agent.recurrent else step_minibatches
    info: dict[str, float] = {}
    for _ in range(args.update_epochs):
        for mb in minibatches(r, adv, returns, args.num_minibatches, generator):
            logits, values = agent.replay(mb.obs, mb.h0, mb.starts)
            loss, info = ppo_loss(args, mb, logits, values)
            gradient_step(agent, optimizer, loss, args.max_grad_norm)
    return info


def gradient_step(agent: Agent, optimizer: torch.optim.Optimizer, loss: torch.Tensor, max_norm: float) -> None:
    """One optimizer step on ``loss``, the gradient clipped to norm ``max_norm``."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()  # type: ignore[no-untyped-call]
    nn.utils.clip_grad_norm_(agent.parameters(), max_norm)
    optimizer.step()


__all__ = ["MET_CODE", "EpisodeStats", "Minibatch", "Rollout", "Runner", "advantages", "collect_rollout", "env_minibatches",
           "gradient_step", "minibatch_indices", "ppo_loss", "ppo_update", "sample", "step_minibatches"]
