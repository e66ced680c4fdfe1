"""The settings of a native training run: :class:`NativeArgs` (one line per setting, as
CleanRL's ``Args``), :func:`check_args` (what no run can use) and :func:`resolve_device`.

Example::

    from agents.native.args import NativeArgs, check_args
    args = NativeArgs(algo="recurrent-ppo", num_envs=64, hidden=(128,), gru_hidden=64)
    check_args(args)  # ValueError naming the setting, for one no run can use
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch

from flowtest_env.memory import MEMORY_KINDS

ALGOS = ("ppo", "recurrent-ppo")
"""The native algorithms: masked PPO with an MLP, and with a GRU."""

LEVEL_SAMPLING = ("uniform", "plr")
"""How each episode's test is chosen: the env's own uniform draws, or prioritized level
replay (:class:`LevelSampler`)."""

PLR_SCORES = ("pvl", "gae")
"""PLR's level scores: positive value loss (the mean of the positive GAE advantages of the
level's last run) or the mean GAE magnitude."""

INPUTS = ("varying", "all")
"""The observation entries a network trains on (:mod:`agents.native.inputs`): those that
vary over the train tests' observations (and the memory), or all."""

ENV_BACKENDS = ("auto", "torch", "numpy")
"""Who steps the tests: the NumPy vector env, or its torch twin on the training device
(``auto``: :func:`flowtest_env.torch_vector.preferred_backend`, the NumPy env on the CPU,
where it steps faster, and the torch env on any other device, where the tests stay on the
device; both give the same runs)."""


@dataclass
class NativeArgs:
    """Every setting of a native training run (saved in the checkpoint and the summary)."""

    env_id: str = "FlowTest-RandomGrid-v0"  # a FlowTest ID with a vector entry point
    env_kwargs: dict[str, Any] = field(default_factory=dict)  # its options (pool, split, count, test, ...)
    algo: str = "ppo"  # "ppo" (MLP) or "recurrent-ppo" (GRU)
    total_steps: int = 2_000_000  # env steps of all envs together (rounded up to a multiple of num_envs)
    num_envs: int = 128  # envs stepped together
    num_steps: int = 32  # rollout length per env
    num_minibatches: int = 4  # minibatches per epoch
    update_epochs: int = 4  # passes over each rollout
    learning_rate: float = 3e-3  # Adam's step size (annealed linearly to 0 when anneal_lr)
    anneal_lr: bool = True  # anneal the learning rate
    gamma: float = 0.99  # discount
    gae_lambda: float = 0.95  # GAE's lambda
    clip_coef: float = 0.2  # PPO's ratio clip
    ent_coef: float = 0.01  # entropy bonus
    vf_coef: float = 0.5  # value loss weight
    max_grad_norm: float = 0.5  # gradient clip
    hidden: tuple[int, ...] = (64, 64)  # MLP widths (the GRU variant: its input layers)
    gru_hidden: int = 128  # GRU width (recurrent-ppo)
    memory: str = "visited"  # "visited" (places occupied this episode), "counts" (how often, capped) or "none"
    obs_kind: str = "flat"  # the env's observation: "flat" or "padded"
    inputs: str = "varying"  # the entries the network trains on: "varying" (those that vary over the train tests, and the memory) or "all"
    shaping: float = 0.0  # env option: potential-based shaping scale (0 = off)
    env_backend: str = "auto"  # "torch" (flowtest_env.torch_vector, on the device), "numpy" (flowtest_env.vector); "auto": numpy on the CPU, else torch
    seed: int = 0  # seeds the envs, the network and every sample
    device: str = "auto"  # "auto" (cuda when there is one), "cpu", "cuda", "cuda:1", ...
    threads: int = 1  # torch CPU threads (fixed, so a seed gives the same run)
    eval_every: int = 250_000  # steps between greedy evaluations on the train (and held-out) tests; 0: at the end only
    level_sampling: str = "uniform"  # "uniform" (the env's own draws) or "plr" (prioritized level replay over the train tests)
    plr_score: str = "pvl"  # PLR's level score: "pvl" (positive value loss) or "gae" (mean GAE magnitude)
    plr_temperature: float = 0.1  # PLR's rank temperature (beta)
    plr_staleness: float = 0.1  # PLR's staleness weight (rho)

    def batch_size(self) -> int:
        """Steps per rollout (all envs)."""
        return self.num_envs * self.num_steps


def check_args(a: NativeArgs) -> None:
    """Refuse settings no run can use.

    Raises
    ------
    ValueError
        Naming the setting and the range it must be in.
    """
    if a.algo not in ALGOS:
        raise ValueError(f"unknown algo {a.algo!r}; expected one of {', '.join(ALGOS)}")
    for name in ("total_steps", "num_envs", "num_steps", "num_minibatches", "update_epochs", "gru_hidden", "threads"):
        if int(getattr(a, name)) < 1:
            raise ValueError(f"{name} must be at least 1, not {getattr(a, name)}")
    if a.algo == "recurrent-ppo" and a.num_envs % a.num_minibatches:
        raise ValueError(f"recurrent-ppo splits envs into minibatches: num_envs {a.num_envs} must be a multiple of num_minibatches {a.num_minibatches}")
    if a.algo == "ppo" and a.batch_size() < a.num_minibatches:
        raise ValueError("num_envs x num_steps must be at least num_minibatches")
    for name in ("learning_rate", "clip_coef", "max_grad_norm"):
        if not float(getattr(a, name)) > 0:
            raise ValueError(f"{name} must be positive, not {getattr(a, name)}")
    for name in ("gamma", "gae_lambda"):
        if not 0 < float(getattr(a, name)) <= 1:
            raise ValueError(f"{name} must be in (0, 1], not {getattr(a, name)}")
    for name in ("ent_coef", "vf_coef", "shaping", "eval_every"):
        if float(getattr(a, name)) < 0:
            raise ValueError(f"{name} must not be negative, not {getattr(a, name)}")
    if not a.hidden or any(int(w) < 1 for w in a.hidden):
        raise ValueError(f"hidden must be positive layer widths, not {a.hidden}")
    if a.memory not in MEMORY_KINDS:
        raise ValueError(f"unknown memory {a.memory!r}; expected one of {', '.join(MEMORY_KINDS)}")
    if a.inputs not in INPUTS:
        raise ValueError(f"unknown inputs {a.inputs!r}; expected one of {', '.join(INPUTS)}")
    if a.env_backend not in ENV_BACKENDS:
        raise ValueError(f"unknown env_backend {a.env_backend!r}; expected one of {', '.join(ENV_BACKENDS)}")
    if a.obs_kind not in ("flat", "padded"):
        raise ValueError(f"obs_kind must be 'flat' or 'padded' for the native trainer, not {a.obs_kind!r}")
    if a.level_sampling not in LEVEL_SAMPLING:
        raise ValueError(f"unknown level_sampling {a.level_sampling!r}; expected one of {', '.join(LEVEL_SAMPLING)}")
    if a.plr_score not in PLR_SCORES:
        raise ValueError(f"unknown plr_score {a.plr_score!r}; expected one of {', '.join(PLR_SCORES)}")
    if not float(a.plr_temperature) > 0 or not 0 <= float(a.plr_staleness) <= 1:
        raise ValueError("plr_temperature must be positive and plr_staleness in [0, 1]")
    if a.level_sampling == "plr" and a.env_backend == "torch":
        raise ValueError("level_sampling 'plr' chooses each episode's test in the NumPy env: use env_backend 'numpy' or 'auto'")
    resolve_device(a.device)


def resolve_device(name: str) -> torch.device:
    """``"auto"``: the first CUDA device when torch sees one, else the CPU.

    Raises
    ------
    ValueError
        For a device name torch does not know, or CUDA asked for where there is none.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(name)
    except (RuntimeError, TypeError) as exc:
        raise ValueError(f"unknown device {name!r}: {exc}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {name!r}: torch sees no CUDA device here (use --device cpu or auto)")
    if dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device {name!r}: expected cpu, cuda or auto")
    return dev


__all__ = ["ALGOS", "ENV_BACKENDS", "INPUTS", "LEVEL_SAMPLING", "PLR_SCORES", "NativeArgs", "check_args", "resolve_device"]
