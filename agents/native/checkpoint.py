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

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..checkpoint import MAX_DIM, MAX_TENSOR_BYTES, Checkpoint, CheckpointError, declared_tensors, load_checkpoint, save_checkpoint
from .agent import Agent
from .args import NativeArgs
from .evaluation import BatchActor, GreedyActor
from .networks import NETWORK_KINDS, make_agent, network_settings, network_shapes


def checkpoint_settings(args: NativeArgs, env: Any, obs_size: int, n_actions: int, where: slice | None, steps: int) -> dict[str, Any]:
    """The plain settings saved next to the tensors (:mod:`agents.checkpoint`)."""
    import flowtest_env

    training = asdict(args)
    training["hidden"] = list(args.hidden)
    return {
        "algo": args.algo,
        "network": network_settings(args),
        "obs": {"obs_kind": args.obs_kind, "pad_to": 8, "size": obs_size},
        "memory": args.memory,
        "position": [where.start, where.stop] if where else None,
        "obs_size": obs_size + (where.stop - where.start if where else 0),
        "n_actions": n_actions,
        "env": {"id": args.env_id, "options": dict(args.env_kwargs), "problem": str(getattr(env, "problem", ""))},
        "training": training,
        "steps": steps,
        "versions": {"flowtest": getattr(flowtest_env, "__version__", _flowtest_version()), "torch": torch.__version__, "numpy": np.__version__},
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


MAX_LAYERS = 64
"""Most hidden layers a checkpoint's network may declare."""

MAX_PAD_TO = 1024
"""Largest ``obs.pad_to`` read (the grid side of a padded observation; FlowTest writes 8)."""

OBS_KINDS = ("flat", "padded")
"""The observations a native network reads."""

MEMORY_KINDS = ("none", "visited", "counts")
"""The memories a native network keeps (``"visited"``: the places the SUT has occupied;
``"counts"``: how often, capped; :mod:`flowtest_env.memory`)."""


@dataclass(frozen=True)
class NativeSettings:
    """What loading reads from a native checkpoint's settings, each field checked
    (:func:`read_settings`): the network (``kind``, ``hidden`` widths, ``gru_hidden``, its
    input ``obs_size`` and ``n_actions``), the observation it was trained on (``obs_kind``,
    ``pad_to``) and the memory (``memory``, and ``position``: where the SUT's place lies
    in the observation, ``None`` without one)."""

    kind: str
    hidden: tuple[int, ...]
    gru_hidden: int
    obs_size: int
    n_actions: int
    obs_kind: str
    pad_to: int
    memory: str
    position: slice | None

    def shapes(self) -> dict[str, tuple[int, ...]]:
        """The tensor shapes of this network (:func:`agents.native.networks.network_shapes`)."""
        return network_shapes(self.kind, self.obs_size, self.n_actions, self.hidden, self.gru_hidden)


def _refuse(field: str, what: str) -> CheckpointError:
    return CheckpointError(f"settings field {field!r}: {what}", field)


def _whole(value: Any, field: str, low: int = 1, high: int = MAX_DIM) -> int:
    """``value`` if it is a whole number (not a bool, a float or a string) in ``[low, high)``."""
    if type(value) is not int or not low <= value < high:
        raise _refuse(field, f"{value!r} is not a whole number in {low}..{high - 1}")
    return value


def _object(value: Any, field: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _refuse(field, f"{value!r} is not an object")
    return value


def _one_of(value: Any, field: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise _refuse(field, f"{value!r} is not one of {', '.join(allowed)}")
    return str(value)


def read_settings(settings: Mapping[str, Any], budget: int = MAX_TENSOR_BYTES) -> NativeSettings:
    """The settings of a native checkpoint as :class:`NativeSettings`: each field of the
    right type and range, the observation, memory and network sizes consistent with one
    another, and the network's tensors within ``budget`` bytes; computed from the
    numbers alone, nothing allocated.

    Raises
    ------
    CheckpointError
        Naming the field (``settings field 'network.hidden': ...``).
    """
    net = _object(settings.get("network"), "network")
    kind = _one_of(net.get("kind"), "network.kind", NETWORK_KINDS)
    hidden = net.get("hidden")
    if not isinstance(hidden, list) or not 1 <= len(hidden) <= MAX_LAYERS:
        raise _refuse("network.hidden", f"{str(hidden)[:80]} is not a list of 1..{MAX_LAYERS} layer widths")
    widths = tuple(_whole(w, "network.hidden") for w in hidden)
    gru_hidden = _whole(net.get("gru_hidden"), "network.gru_hidden") if kind == "gru" else 0
    obs_size = _whole(settings.get("obs_size"), "obs_size")
    n_actions = _whole(settings.get("n_actions"), "n_actions")
    obs = _object(settings.get("obs", {}), "obs")
    obs_kind = _one_of(obs.get("obs_kind", "flat"), "obs.obs_kind", OBS_KINDS)
    pad_to = _whole(obs.get("pad_to", 8), "obs.pad_to", 1, MAX_PAD_TO + 1)
    env_size = _whole(obs["size"], "obs.size", 1, obs_size + 1) if "size" in obs else None
    if obs_kind == "padded" and env_size is not None and pad_to * pad_to > env_size:
        raise _refuse("obs.pad_to", f"{pad_to} x {pad_to} grid cells do not fit an observation of {env_size}")
    memory = _one_of(settings.get("memory", "none"), "memory", MEMORY_KINDS)
    position = None
    pos = settings.get("position")
    if pos is not None:
        if not isinstance(pos, list) or len(pos) != 2:
            raise _refuse("position", f"{str(pos)[:80]} is not a pair [start, stop]")
        seen = env_size if env_size is not None else obs_size
        start, stop = _whole(pos[0], "position", 0, seen), _whole(pos[1], "position", 1, seen + 1)
        if start >= stop:
            raise _refuse("position", f"[{start}, {stop}] is empty")
        position = slice(start, stop) if memory != "none" else None
    if env_size is not None:
        width = position.stop - position.start if position is not None else 0
        if obs_size != env_size + width:
            raise _refuse("obs_size", f"{obs_size}, but the observation (obs.size {env_size}) and the memory ({width}) make {env_size + width}")
    out = NativeSettings(kind, widths, gru_hidden, obs_size, n_actions, obs_kind, pad_to, memory, position)
    nbytes = 4 * sum(math.prod(shape) for shape in out.shapes().values())
    if nbytes > budget:
        raise _refuse(
            "network",
            f"a {kind} of widths {list(widths)} on {obs_size} inputs and {n_actions} actions holds "
            f"{nbytes:,} bytes of tensors, more than the budget of {budget:,}",
        )
    return out


def _match(want: Mapping[str, tuple[int, ...]], have: Mapping[str, tuple[int, ...]]) -> None:
    """Refuse tensors (name -> shape) that are not the network's."""
    if set(want) != set(have):
        raise _refuse("tensors", f"{sorted(have)} do not match the network the settings describe: {sorted(want)}")
    for name, shape in want.items():
        if tuple(have[name]) != shape:
            raise _refuse(f"tensors.{name}", f"shape {list(have[name])}, the network the settings describe has {list(shape)}")


def check_settings(settings: Mapping[str, Any]) -> None:
    """Refuse settings that do not describe a network their declared tensors fit
    (:func:`read_settings`, then each declared shape): the check
    :func:`load_native` hands :func:`agents.checkpoint.load_checkpoint`, run before any
    tensor is read.

    Raises
    ------
    CheckpointError
        Naming the field.
    """
    _match(read_settings(settings).shapes(), declared_tensors(settings))


def agent_from_checkpoint(ck: Checkpoint) -> Agent:
    """Rebuild the network of a checkpoint and load its tensors, after checking the
    settings (:func:`read_settings`) and that the tensors are the network's.

    Raises
    ------
    CheckpointError
        If the settings do not describe a network these tensors fit.
    """
    net = read_settings(ck.settings)
    _match(net.shapes(), {k: tuple(np.shape(v)) for k, v in ck.tensors.items()})
    agent = make_agent(net.obs_size, net.n_actions, net.hidden, net.kind, net.gru_hidden)
    agent.load_state_dict({k: torch.from_numpy(np.array(v, dtype=np.float32)) for k, v in ck.tensors.items()})
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
        net = read_settings(ck.settings)
        self.agent = agent_from_checkpoint(ck)
        self.recurrent = self.agent.recurrent
        self.flowtest_memory = net.memory
        self.flowtest_obs = {"obs_kind": net.obs_kind, "pad_to": net.pad_to}
        self.observation_space = spaces.Box(0.0, 1.0, shape=(self.agent.obs_size,), dtype=np.float32)
        self._actor = GreedyActor(self.agent, torch.device("cpu"))
        self.position = net.position

    def batch_policy(self, deterministic: bool = True) -> BatchActor:
        """This model as a batched policy of :mod:`flowtest_env.scoring` (greedy, or
        sampled from its masked policy): :class:`BatchActor`."""
        return BatchActor(self.agent, self.position, deterministic, memory=self.flowtest_memory)

    def predict(self, obs: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True, action_masks: Any = None) -> tuple[np.ndarray, Any]:
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
    """A native checkpoint as a :class:`NativeModel` (never unpickled). The settings are
    checked (:func:`check_settings`: every field, the network against the declared
    tensors and the budget) before a tensor is read, and the network is built only then.

    Raises
    ------
    CheckpointError
        If the file is not a valid native checkpoint: one line naming the file and the
        field (``'policy.zip' is not a valid FlowTest policy checkpoint: settings field
        'network': ...``).
    """
    ck = load_checkpoint(path, check=check_settings)
    try:
        return NativeModel(ck)
    except CheckpointError as exc:
        raise CheckpointError(f"{str(path)!r} is not a valid FlowTest policy checkpoint: {exc}", exc.field) from None


__all__ = [
    "MAX_LAYERS",
    "MAX_PAD_TO",
    "NativeModel",
    "NativeSettings",
    "agent_from_checkpoint",
    "check_settings",
    "checkpoint_settings",
    "load_native",
    "read_settings",
    "save_policy",
]
