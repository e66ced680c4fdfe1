"""The contract every native policy-and-value network keeps (:class:`Agent`), the masks
(:func:`masked_logits`) and the layers the networks are built from (:func:`layer_init`,
:func:`tanh_layers`, as CleanRL's ``layer_init``: orthogonal weights, zero biases).

Two networks keep it: the MLP (:class:`agents.native.mlp.MLPAgent`) and the GRU
(:class:`agents.native.gru.GRUAgent`); :func:`agents.native.networks.make_agent` builds
the one a checkpoint's ``network.kind`` names. The rollout, the update and the players
(:mod:`agents.native.core`, :mod:`agents.native.evaluation`) see only this contract.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

MASKED_LOGIT = -1e8
"""The logit of an illegal action (its probability is exactly 0 in float32)."""


def masked_logits(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``logits`` with the illegal actions (``mask`` false) at :data:`MASKED_LOGIT`. A row
    with no legal action (a terminal state, seen only on the autoreset step, whose
    action the env ignores) keeps its logits so the distribution stays defined."""
    legal = mask | ~mask.any(dim=-1, keepdim=True)
    return torch.where(legal, logits, torch.full_like(logits, MASKED_LOGIT))


def tanh(x: torch.Tensor) -> torch.Tensor:
    """``tanh(x)`` computed as ``2 sigmoid(2x) - 1``: the same function (within 2e-7 in
    float32) at a third of ``torch.tanh``'s cost on the CPU, where it was a sixth of a small
    network's forward pass."""
    s = torch.sigmoid(2.0 * x)
    if s.requires_grad:  # autograd keeps sigmoid's output for its backward: no in-place
        return s * 2.0 - 1.0
    return s.mul_(2.0).sub_(1.0)


class Tanh(nn.Module):
    """The networks' activation: :func:`tanh` (no parameters: a checkpoint's tensors are
    the same as with ``nn.Tanh``)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return tanh(x)


def layer_init(n_in: int, n_out: int, std: float) -> nn.Linear:
    """A linear layer with orthogonal weights of gain ``std`` and zero biases (CleanRL's
    ``layer_init``; draws from torch's global generator, so the seed fixes it)."""
    layer = nn.Linear(n_in, n_out)
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, 0.0)
    return layer


def tanh_layers(n_in: int, widths: Sequence[int]) -> tuple[list[nn.Module], int]:
    """Linear layers of ``widths`` (gain ``sqrt(2)``), each followed by ``tanh``, and the
    width of the last one (``n_in`` when ``widths`` is empty)."""
    layers: list[nn.Module] = []
    for w in widths:
        layers += [layer_init(n_in, int(w), math.sqrt(2)), Tanh()]
        n_in = int(w)
    return layers, n_in


class Agent(nn.Module, abc.ABC):
    """A policy and value network over one observation per env, with a recurrent state
    of :attr:`state_size` numbers per env (0 for a feed-forward network).

    ``kind`` is the checkpoint's ``network.kind``; ``recurrent`` says how the update draws
    its minibatches (whole env sequences replayed from the rollout's first state, or
    shuffled steps: :func:`agents.native.core.ppo_update`).
    """

    kind: str = ""
    recurrent: bool = False

    def __init__(self, obs_size: int, n_actions: int, state_size: int) -> None:
        super().__init__()
        self.obs_size, self.n_actions, self.state_size = int(obs_size), int(n_actions), int(state_size)

    @abc.abstractmethod
    def settings(self) -> dict[str, Any]:
        """What rebuilds this network (:func:`agents.native.networks.make_agent`): ``kind``,
        ``hidden`` widths, ``gru_hidden``."""

    @abc.abstractmethod
    def input_weights(self) -> list[str]:
        """The ``state_dict`` names of the weights that multiply the observation (their
        columns are its entries: :func:`agents.native.inputs.widen`)."""

    def flat_order(self) -> list[tuple[str, nn.Parameter]]:
        """The parameters in the order of the optimizer's flat buffer
        (:class:`~agents.native.optim.FlatAdam`); by default their own order."""
        return list(self.named_parameters())

    def initial_state(self, n: int, device: torch.device) -> torch.Tensor:
        """The state of ``n`` envs before anything was seen (``[n, state_size]`` zeros)."""
        return torch.zeros(n, self.state_size, device=device)

    @abc.abstractmethod
    def step(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Logits, values and the next state for one observation per env (``x``: ``[n,
        obs_size]``; ``start``: the observation is its episode's first, so a recurrent
        state restarts from zero)."""

    def value(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        """The values of one observation per env."""
        return self.step(x, h, start)[1]

    def policy_logits(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The logits and the next state for one observation per env (acting needs no value)."""
        logits, _, h = self.step(x, h, start)
        return logits, h

    @abc.abstractmethod
    def replay(self, obs: torch.Tensor, h0: torch.Tensor, starts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Logits and values of a minibatch, with gradients: for a recurrent network
        ``obs`` is ``[T, n, obs_size]``, played in order from the states ``h0`` (``[n,
        state_size]``) with the episode starts ``starts`` (``[T, n]``); for a feed-forward
        one any ``[..., obs_size]`` (``h0`` and ``starts`` unused)."""


__all__ = ["MASKED_LOGIT", "Agent", "Tanh", "layer_init", "masked_logits", "tanh", "tanh_layers"]
