"""The feed-forward policy (``algo="ppo"``, ``network.kind="mlp"``): separate actor and
critic MLPs of ``hidden`` widths (tanh), as stable-baselines3's ``net_arch`` builds them;
the output layers start small (gain 0.01 for the actor, 1 for the critic), as in CleanRL's
``ppo.py``. Its state is empty: the visited-places memory in the observation is all it
remembers.

Example::

    from agents.native.mlp import MLPAgent
    agent = MLPAgent(obs_size=120, n_actions=5, hidden=(256, 256))
    logits, values, _ = agent.step(x, agent.initial_state(len(x), x.device), starts)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn

from .agent import Agent, layer_init, tanh_layers


def mlp(n_in: int, widths: Sequence[int], n_out: int, out_std: float) -> nn.Sequential:
    """Tanh layers of ``widths`` and a linear output of ``n_out`` (gain ``out_std``)."""
    layers, n_last = tanh_layers(n_in, widths)
    layers.append(layer_init(n_last, n_out, out_std))
    return nn.Sequential(*layers)


class MLPAgent(Agent):
    """Actor and critic MLPs over the observation (state size 0)."""

    kind = "mlp"
    recurrent = False

    def __init__(self, obs_size: int, n_actions: int, hidden: Sequence[int]) -> None:
        super().__init__(obs_size, n_actions, 0)
        self.hidden = tuple(int(w) for w in hidden)
        self.actor = mlp(obs_size, hidden, n_actions, 0.01)
        self.critic = mlp(obs_size, hidden, 1, 1.0)

    @staticmethod
    def tensor_shapes(obs_size: int, n_actions: int, hidden: Sequence[int]) -> dict[str, tuple[int, ...]]:
        """The shapes of the ``state_dict`` such a network has, computed without building it."""
        shapes: dict[str, tuple[int, ...]] = {}
        for head, n_out in (("actor", n_actions), ("critic", 1)):
            n_in = obs_size
            for i, w in enumerate([*hidden, n_out]):
                shapes[f"{head}.{2 * i}.weight"], shapes[f"{head}.{2 * i}.bias"] = (w, n_in), (w,)
                n_in = w
        return shapes

    def settings(self) -> dict[str, Any]:
        return {"kind": self.kind, "hidden": list(self.hidden), "gru_hidden": 0}

    def input_weights(self) -> list[str]:
        return ["actor.0.weight", "critic.0.weight"]

    @property
    def first_width(self) -> int:
        """The width of each head's first layer."""
        first = self.actor[0]
        assert isinstance(first, torch.nn.Linear)
        return first.out_features

    def linear_names(self, head: str) -> list[tuple[str, str]]:
        """The ``(weight, bias)`` names of ``head``'s linear layers (``"actor"`` or
        ``"critic"``), input first."""
        return [(f"{head}.{i}.weight", f"{head}.{i}.bias") for i, m in enumerate(getattr(self, head)) if isinstance(m, nn.Linear)]

    def flat_order(self) -> list[tuple[str, nn.Parameter]]:
        """The parameters in the order of a flat buffer (:class:`~agents.native.optim.FlatAdam`)
        where the actor's and the critic's first layers are adjacent (weights, then biases),
        so one product computes both (:class:`~agents.native.fused.FusedMLP`)."""
        params = dict(self.named_parameters())
        (aw, ab), (cw, cb) = self.linear_names("actor")[0], self.linear_names("critic")[0]
        first = [aw, cw, ab, cb]
        return [(k, params[k]) for k in first] + [(k, p) for k, p in params.items() if k not in first]

    def step(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return self.actor(x), self.critic(x).squeeze(-1), h

    def value(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        v: torch.Tensor = self.critic(x).squeeze(-1)
        return v

    def policy_logits(self, x: torch.Tensor, h: torch.Tensor, start: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.actor(x), h

    def replay(self, obs: torch.Tensor, h0: torch.Tensor, starts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.actor(obs), self.critic(obs).squeeze(-1)


__all__ = ["MLPAgent", "mlp"]
