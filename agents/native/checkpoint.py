"""A native agent to and from its checkpoint: :func:`checkpoint_settings` (the plain
settings saved next to the tensors), :func:`save_policy`, :func:`agent_from_checkpoint`
and :func:`load_native` (a :class:`NativeModel`, what ``ppo:PATH`` plays). The file
format itself (a zip of JSON settings and ``.npy`` tensors, never unpickled) is
:mod:`agents.checkpoint`'s.

Example::

    from agents.native.checkpoint import load_native
    model = load_native("policy.zip")
    greedy = model.batch_policy()                  # a batched policy of flowtest_env.scoring
    action, state = model.predict(obs, action_masks=mask)
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..checkpoint import Checkpoint, CheckpointError, load_checkpoint, save_checkpoint
from .agent import Agent
from .args import NativeArgs
from .evaluation import BatchActor, GreedyActor
from .networks import make_agent, network_settings


def checkpoint_settings(args: NativeArgs, env: Any, obs_size: int, n_actions: int, where: slice | None,
                        steps: int) -> dict[str, Any]:
    """The plain settings saved next to the tensors (:mod:`agents.checkpoint`)."""
    import flowtest_env

    training = asdict(args)
    training["hidden"] = list(args.hidden)
    return {
        "algo": args.algo, "network": network_settings(args),
        "obs": {"obs_kind": args.obs_kind, "pad_to": 8, "size": obs_size},
        "memory": args.memory, "position": [where.start, where.stop] if where else None,
        "obs_size": obs_size + (where.stop - where.start if where else 0), "n_actions": n_actions,
        "env": {"id": args.env_id, "options": dict(args.env_kwargs), "problem": str(getattr(env, "problem", ""))},
        "training": training, "steps": steps,
        "versions": {"flowtest": getattr(flowtest_env, "__version__", _flowtest_version()), "torch": torch.__version__,
                     "numpy": np.__version__},
    }


def _flowtest_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("flowtest")
    except PackageNotFoundError:  # pragma: no cover - run from a source tree without install
        return "unknown"


def save_policy(path: str | Path, agent: Agent, settings: dict[str, Any]) -> None:
    """Write ``agent`` as a native checkpoint (atomic)."""
    tensors = {k: v.detach().cpu().numpy() for k, v in agent.state_dict().items()}
    save_checkpoint(path, settings, tensors)


def agent_from_checkpoint(ck: Checkpoint) -> Agent:
    """Rebuild the network of a checkpoint and load its tensors.

    Raises
    ------
    CheckpointError
        If the settings do not describe a network these tensors fit.
    """
    s = ck.settings
    try:
        net = s["network"]
        agent = make_agent(int(s["obs_size"]), int(s["n_actions"]), [int(w) for w in net["hidden"]], str(net["kind"]),
                           int(net["gru_hidden"]))
        want = agent.state_dict()
        if set(want) != set(ck.tensors):
            raise CheckpointError(f"tensors {sorted(ck.tensors)} do not match the network's {sorted(want)}")
        agent.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in ck.tensors.items()})
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(f"the settings do not describe this network ({type(exc).__name__}: {exc})") from None
    agent.eval()
    return agent


class NativeModel:
    """A loaded native checkpoint with the small part of stable-baselines3's model
    interface FlowTest's players use (``predict``, ``observation_space``), so
    :class:`agents.ppo.PPOPolicy` plays it like any saved model. Always masked; recurrent
    for a GRU network. Runs on the CPU."""

    maskable = True

    def __init__(self, ck: Checkpoint) -> None:
        from gymnasium import spaces

        self.checkpoint = ck
        self.settings = ck.settings
        self.agent = agent_from_checkpoint(ck)
        self.recurrent = self.agent.recurrent
        self.flowtest_memory = str(ck.settings.get("memory", "none"))
        obs = ck.settings.get("obs", {})
        self.flowtest_obs = {"obs_kind": str(obs.get("obs_kind", "flat")), "pad_to": int(obs.get("pad_to", 8))}
        self.observation_space = spaces.Box(0.0, 1.0, shape=(self.agent.obs_size,), dtype=np.float32)
        self._actor = GreedyActor(self.agent, torch.device("cpu"))
        pos = ck.settings.get("position")
        self.position = slice(int(pos[0]), int(pos[1])) if self.flowtest_memory == "visited" and pos else None

    def batch_policy(self, deterministic: bool = True) -> BatchActor:
        """This model as a batched policy of :mod:`flowtest_env.scoring` (greedy, or
        sampled from its masked policy): :class:`BatchActor`."""
        return BatchActor(self.agent, self.position, deterministic)

    def predict(self, obs: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True,
                action_masks: Any = None) -> tuple[np.ndarray, Any]:
        """The most likely legal action for one observation or a batch (``state``: the
        GRU state returned by the previous call; ``episode_start``: which rows begin an
        episode). Sampling is not offered: FlowTest plays its policies greedily."""
        x = np.asarray(obs, dtype=np.float32)
        single = x.ndim == 1
        x2 = x[None] if single else x
        n = x2.shape[0]
        masks = np.ones((n, self.agent.n_actions), dtype=bool) if action_masks is None else np.asarray(action_masks, dtype=bool)
        masks = masks.reshape(n, -1)
        starts = np.ones(n, dtype=bool) if episode_start is None else np.asarray(episode_start, dtype=bool).reshape(n)
        self._actor.h = state if isinstance(state, torch.Tensor) and state.shape[0] == n else None
        actions = self._actor(x2, masks, starts)
        return (actions[0] if single else actions), self._actor.h


def load_native(path: str | Path) -> NativeModel:
    """A native checkpoint as a :class:`NativeModel` (never unpickled).

    Raises
    ------
    CheckpointError
        If the file is not a valid native checkpoint.
    """
    return NativeModel(load_checkpoint(path))


__all__ = ["NativeModel", "agent_from_checkpoint", "checkpoint_settings", "load_native", "save_policy"]
