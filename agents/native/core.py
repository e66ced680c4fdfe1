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

from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn

from flowtest_env.compiled import OUTCOMES
from flowtest_env.torch_memory import BatchPlaceMemory

from .agent import Agent, masked_logits
from .args import NativeArgs
from .batch import Minibatch, Rollout, env_minibatches, minibatch_indices, step_minibatches
from .fused import FusedMLP
from .mlp import MLPAgent
from .optim import FlatAdam

MET_CODE = OUTCOMES.index("met")
"""The outcome code of ``"met"`` in the torch env's verdicts."""


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
        return {
            "episodes": float(len(rows)),
            "return": float(r[:, 0].mean()),
            "met": float(r[:, 1].mean()),
            "realized": float(r[:, 2].mean()),
            "restrictions": float(r[:, 3].mean()),
            "length": float(r[:, 4].mean()),
        }


class Runner:
    """Steps the vector env with the agent and keeps what carries over between rollouts:
    the last observation, masks, episode flags, the memory, the GRU state, returns.
    ``where``: the SUT's place in the observation when the runner keeps the place memory
    of kind ``memory`` itself (``None``: the env appends it, or there is none);
    ``columns``: the entries of the observation (memory included) the agent reads
    (:mod:`agents.native.inputs`; ``None``: all)."""

    def __init__(
        self,
        env: Any,
        agent: Agent,
        where: slice | None,
        device: torch.device,
        seed: int,
        levels: Callable[[], np.ndarray] | None = None,
        memory: str = "visited",
        columns: torch.Tensor | None = None,
    ) -> None:
        self.env, self.agent, self.device = env, agent, device
        self.levels = levels  # the test each env plays now (recorded per step when given)
        self.n = int(env.num_envs)
        self.torch_env = hasattr(env, "tables")  # flowtest_env.torch_vector: tensors in, tensors out
        obs, infos = env.reset(seed=seed)
        self.memory = BatchPlaceMemory(where, memory) if where is not None else None
        self.columns = columns
        self.start = torch.ones(self.n, dtype=torch.bool, device=device)
        self.reset_step = torch.zeros(self.n, dtype=torch.bool, device=device)  # the next step is the autoreset step
        self.x = self._remember(self._tensor(obs))
        self.mask = self._tensor(infos["action_mask"]).bool()
        self.h = agent.initial_state(self.n, device)
        self.ret = torch.zeros(self.n, dtype=torch.float64, device=device)
        self.stats = EpisodeStats()

    def _remember(self, obs: torch.Tensor) -> torch.Tensor:
        x = obs if self.memory is None else self.memory(obs, self.start)
        return x if self.columns is None else x.index_select(1, self.columns)

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
            self.x = self._remember(self._tensor(o))
            self.mask = self._tensor(infos["action_mask"]).bool()
        with torch.no_grad():
            next_value = self.agent.value(self.x, self.h, self.start)
        return Rollout(obs, masks, actions, logprobs, values, rewards, terminated, truncated, valid, starts, h0, next_value, levels)

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


def ppo_loss(args: NativeArgs, mb: Minibatch, logits: torch.Tensor, values: torch.Tensor, want_info: bool = True) -> tuple[torch.Tensor, dict[str, float]]:
    """The clipped PPO loss over the samples of ``mb`` (``logits`` and ``values``: the
    network's on them now), each weighted by ``mb.weight``; the advantages normalized
    over the weighted samples. The loss terms for the log when ``want_info``."""
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
    if not want_info:
        return loss, {}
    with torch.no_grad():
        kl = (((ratio - 1) - torch.log(ratio.clamp(min=1e-12))) * w).sum() / n
    return loss, {"policy_loss": float(pg_loss.detach()), "value_loss": float(v_loss.detach()), "entropy": float(ent.detach()), "approx_kl": float(kl)}


def ppo_update(
    agent: Agent, optimizer: torch.optim.Optimizer | FlatAdam, args: NativeArgs, r: Rollout, generator: torch.Generator | None = None
) -> dict[str, float]:
    """``update_epochs`` passes of minibatch gradient steps over the rollout's valid steps
    (feed-forward: shuffled steps; recurrent: shuffled envs, each replayed from the
    rollout's start). Returns the last minibatch's loss terms, for the log.

    An MLP with the trainer's :class:`~agents.native.optim.FlatAdam` takes its gradient
    from :class:`~agents.native.fused.FusedMLP` (the same loss, written out by hand, no
    autograd); any other network or optimizer from autograd on :func:`ppo_loss`."""
    adv, returns = advantages(r, args.gamma, args.gae_lambda)
    minibatches = env_minibatches if agent.recurrent else step_minibatches
    fused = FusedMLP(agent, optimizer) if isinstance(optimizer, FlatAdam) and isinstance(agent, MLPAgent) else None
    info: dict[str, Any] = {}
    for epoch in range(args.update_epochs):
        batches = list(minibatches(r, adv, returns, args.num_minibatches, generator))
        for i, mb in enumerate(batches):
            last = epoch == args.update_epochs - 1 and i == len(batches) - 1
            if fused is not None:
                assert isinstance(optimizer, FlatAdam)
                info = fused.gradient(args, mb, want_info=last)
                optimizer.clip_grad_norm(args.max_grad_norm)
                optimizer.step()
                continue
            logits, values = agent.replay(mb.obs, mb.h0, mb.starts)
            loss, info = ppo_loss(args, mb, logits, values, want_info=last)
            gradient_step(agent, optimizer, loss, args.max_grad_norm)
    return {k: float(v) for k, v in info.items()}


def gradient_step(agent: Agent, optimizer: torch.optim.Optimizer | FlatAdam, loss: torch.Tensor, max_norm: float) -> None:
    """One optimizer step on ``loss``, the gradient clipped to norm ``max_norm``."""
    if isinstance(optimizer, FlatAdam):  # autograd accumulates into the flat gradient's views
        optimizer.zero_grad()
        loss.backward()  # type: ignore[no-untyped-call]
        optimizer.clip_grad_norm(max_norm)
        optimizer.step()
        return
    optimizer.zero_grad(set_to_none=True)
    loss.backward()  # type: ignore[no-untyped-call]
    nn.utils.clip_grad_norm_(agent.parameters(), max_norm)
    optimizer.step()


__all__ = [
    "MET_CODE",
    "EpisodeStats",
    "Minibatch",
    "Rollout",
    "Runner",
    "advantages",
    "collect_rollout",
    "env_minibatches",
    "gradient_step",
    "minibatch_indices",
    "ppo_loss",
    "ppo_update",
    "sample",
    "step_minibatches",
]
