"""The recurrent policy (``algo="recurrent-ppo"``, ``network.kind="gru"``): a shared input
MLP of ``hidden`` widths (tanh), a GRU cell of ``gru_hidden`` units whose state is zeroed at
each episode's first observation, and linear actor and critic heads (the recurrent variant
of CleanRL's ``ppo_atari_lstm.py``, with a GRU cell and FlowTest's flat observations).

The update replays whole env sequences from the rollout's first state
(:func:`agents.native.core.ppo_update` with ``recurrent = True``), so the gradient flows
through the state as it did while acting.

Example::

    from agents.native.gru import GRUAgent
    agent = GRUAgent(obs_size=120, n_actions=5, hidden=(128,), gru_hidden=64)
    h = agent.initial_state(n_envs, device)
    logits, values, h = agent.step(x, h, starts)   # starts: which rows begin an episode
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

from .agent import Agent, layer_init, tanh_layers


class GRUAgent(Agent):
    """An input MLP, a GRU cell (the state, ``gru_hidden`` wide) and two linear heads."""

    kind = "gru"
    recurrent = True

    def __init__(self, obs_size: int, n_actions: int, hidden: Sequence[int], gru_hidden: int = 128) -> None:
        super().__init__(obs_size, n_actions, gru_hidden)
        self.hidden = tuple(int(w) for w in hidden)
        layers, n_in = tanh_layers(obs_size, hidden)
        self.encoder = nn.Sequential(*layers)
        self.gru = nn.GRUCell(n_in, self.state_size)
        self.actor_head = layer_init(self.state_size, n_actions, 0.01)
        self.critic_head = layer_init(self.state_size, 1, 1.0)

    @staticmethod
    def tensor_shapes(obs_size: int, n_actions: int, hidden: Sequence[int], gru_hidden: int) -> dict[str, tuple[int, ...]]:
        """The shapes of the ``state_dict`` such a network has, computed without building it."""
        shapes: dict[str, tuple[int, ...]] = {}
        n_in = obs_size
        for i, w in enumerate(hidden):
            shapes[f"encoder.{2 * i}.weight"], shapes[f"encoder.{2 * i}.bias"] = (w, n_in), (w,)
            n_in = w
        H = gru_hidden
        shapes.update(
            {
                "gru.weight_ih": (3 * H, n_in),
                "gru.weight_hh": (3 * H, H),
                "gru.bias_ih": (3 * H,),
                "gru.bias_hh": (3 * H,),
                "actor_head.weight": (n_actions, H),
                "actor_head.bias": (n_actions,),
                "critic_head.weight": (1, H),
                "critic_head.bias": (1,),
            }
        )
        return shapes

    def settings(self) -> dict[str, Any]:
        return {"kind": self.kind, "hidden": list(self.hidden), "gru_hidden": self.state_size}

    def input_weights(self) -> list[str]:
        return ["encoder.0.weight"] if self.hidden else ["gru.weight_ih"]

    def step(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        h = h * (~start).to(h.dtype).unsqueeze(-1)
        h = self.gru(self.encoder(x), h)
        return self.actor_head(h), self.critic_head(h).squeeze(-1), h

    def replay(self, obs: torch.Tensor, h0: torch.Tensor, starts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = h0
        logit_list, value_list = [], []
        for t in range(obs.shape[0]):
            logits, values, h = self.step(obs[t], h, starts[t])
            logit_list.append(logits)
            value_list.append(values)
        return torch.stack(logit_list), torch.stack(value_list)


__all__ = ["GRUAgent"]
