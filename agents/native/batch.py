"""What the PPO update trains on: the rollout (:class:`Rollout`, ``[T, N, ...]`` tensors of
every env's steps) and its minibatches (:class:`Minibatch`; :func:`step_minibatches` for a
feed-forward network, :func:`env_minibatches` for a recurrent one, :func:`minibatch_indices`:
exactly the valid steps, each once).

Example::

    for mb in step_minibatches(rollout, adv, returns, num_minibatches=4, generator=g):
        logits, values = agent.replay(mb.obs, mb.h0, mb.starts)
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch


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
    ``[B, ...]`` shuffled steps; ``weight`` is 1 for a valid step, 0 for an autoreset step
    (``all_valid``: every weight is 1, as in a feed-forward minibatch, which holds the
    valid steps only)."""

    obs: torch.Tensor
    masks: torch.Tensor
    actions: torch.Tensor
    logprobs: torch.Tensor
    adv: torch.Tensor
    returns: torch.Tensor
    weight: torch.Tensor
    h0: torch.Tensor
    starts: torch.Tensor
    all_valid: bool = False


def step_minibatches(
    r: Rollout, adv: torch.Tensor, returns: torch.Tensor, num_minibatches: int, generator: torch.Generator | None = None
) -> Iterator[Minibatch]:
    """The valid steps of ``r`` shuffled into ``num_minibatches`` minibatches
    (:func:`minibatch_indices`), for a feed-forward network."""
    T, N = r.rewards.shape
    flat = {
        k: v.reshape(T * N, *v.shape[2:])
        for k, v in (
            ("obs", r.obs),
            ("masks", r.masks),
            ("actions", r.actions),
            ("logprobs", r.logprobs),
            ("adv", adv),
            ("returns", returns),
            ("starts", r.starts),
        )
    }
    for mb in minibatch_indices(r.valid, num_minibatches, generator):
        x = flat["obs"][mb]
        yield Minibatch(
            x,
            flat["masks"][mb],
            flat["actions"][mb],
            flat["logprobs"][mb],
            flat["adv"][mb],
            flat["returns"][mb],
            torch.ones(mb.numel(), dtype=torch.bool, device=x.device),
            r.h0.new_zeros((mb.numel(), r.h0.shape[1])),
            flat["starts"][mb],
            all_valid=True,
        )


def env_minibatches(
    r: Rollout, adv: torch.Tensor, returns: torch.Tensor, num_minibatches: int, generator: torch.Generator | None = None
) -> Iterator[Minibatch]:
    """The envs of ``r`` shuffled into ``num_minibatches`` groups, each minibatch their
    whole sequences (autoreset steps weighed 0), for a recurrent network."""
    N = r.rewards.shape[1]
    perm = torch.randperm(N, generator=generator).to(r.obs.device)
    for envs in torch.tensor_split(perm, num_minibatches):
        yield Minibatch(
            r.obs[:, envs],
            r.masks[:, envs],
            r.actions[:, envs],
            r.logprobs[:, envs],
            adv[:, envs],
            returns[:, envs],
            r.valid[:, envs],
            r.h0[envs],
            r.starts[:, envs],
        )


__all__ = ["Minibatch", "Rollout", "env_minibatches", "minibatch_indices", "step_minibatches"]
