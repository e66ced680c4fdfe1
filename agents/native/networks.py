"""The network a run or a checkpoint names: ``network.kind`` (``"mlp"``: :class:`MLPAgent`,
``"gru"``: :class:`GRUAgent`), its widths, and :func:`make_agent`, which builds it.

Example::

    from agents.native.networks import make_agent
    agent = make_agent(obs_size=120, n_actions=5, hidden=[256, 256], kind="mlp")
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .agent import Agent
from .args import NativeArgs
from .gru import GRUAgent
from .mlp import MLPAgent

NETWORK_KINDS = ("mlp", "gru")
"""The ``network.kind`` values: the MLP of ``algo="ppo"``, the GRU of ``"recurrent-ppo"``."""


def make_agent(obs_size: int, n_actions: int, hidden: Sequence[int], kind: str = "mlp", gru_hidden: int = 128) -> Agent:
    """The network of ``kind`` (``gru_hidden``: the GRU's width; the MLP has none).

    Raises
    ------
    ValueError
        For a kind not in :data:`NETWORK_KINDS`.
    """
    if kind == "mlp":
        return MLPAgent(obs_size, n_actions, hidden)
    if kind == "gru":
        return GRUAgent(obs_size, n_actions, hidden, gru_hidden)
    raise ValueError(f"unknown network kind {kind!r}")


def network_shapes(kind: str, obs_size: int, n_actions: int, hidden: Sequence[int], gru_hidden: int = 128) -> dict[str, tuple[int, ...]]:
    """The tensor shapes (``state_dict`` name -> shape) of the network :func:`make_agent`
    would build, computed without building it: what a checkpoint's tensors must be.

    Raises
    ------
    ValueError
        For a kind not in :data:`NETWORK_KINDS`.
    """
    if kind == "mlp":
        return MLPAgent.tensor_shapes(obs_size, n_actions, hidden)
    if kind == "gru":
        return GRUAgent.tensor_shapes(obs_size, n_actions, hidden, gru_hidden)
    raise ValueError(f"unknown network kind {kind!r}")


def network_settings(args: NativeArgs) -> dict[str, Any]:
    """What rebuilds the network: its kind and widths."""
    return {"kind": "gru" if args.algo == "recurrent-ppo" else "mlp", "hidden": [int(w) for w in args.hidden], "gru_hidden": int(args.gru_hidden)}


__all__ = ["NETWORK_KINDS", "make_agent", "network_settings", "network_shapes"]
