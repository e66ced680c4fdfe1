"""Batched policies of your own: the one interface by which ``flowtest benchmark`` asks a
policy for its greedy and its sampled actions.

The benchmark plays every run of every test of a split at once in one vector env
(:mod:`flowtest_env.scoring`). A policy trained outside FlowTest (your own PPO loop, a
TorchRL or CleanRL agent) joins it as a **batched policy**: any object with

``act(observations, masks, deterministic) -> actions``
    ``observations``: ``float32 [n, obs]``, a batch of the vector env's observations, made
    with the policy's ``env_options``; ``masks``: ``bool [n, n_actions]``, the legal
    actions of each row; ``deterministic``: ``True`` for the **greedy** score (the most
    likely legal action), ``False`` for the **sampled** score (an action drawn from the
    policy); returns ``int [n]``, one legal action per row. It is called by keyword
    (``deterministic=...``).

and, optionally,

``reset(num_runs, seed)``
    called before each batch of runs (the greedy batch, then the sampled one): forget any
    memory or recurrent state, and seed the sampling from ``seed`` so the same seed gives
    the same runs (every row starts a run with its first observation);
``env_options``
    a dict of the observation options it was trained with, any of :data:`OBSERVATION_OPTIONS`
    (``{"memory": "visited"}``, ``{"obs_kind": "padded"}``): the scorer builds its batch
    env with them, so the policy sees the observations it learned from (the memory
    included) without rebuilding them itself.

:class:`LogitsPolicy` is that object for the common case, a network from observations to
action logits: FlowTest masks the logits, takes their argmax (greedy) or samples them
with a generator seeded by ``reset`` (sampled).

**On the command line** a batched policy is named by its **loader**, a class or function
marked ``batched = True`` that returns it: ``python:MODULE:NAME`` calls the loader with no
argument, ``python:MODULE:NAME(ARGS)`` with Python literals (:func:`agents.external.split_call`):
``--sut 'python:mypkg.policies:load("runs/seed0.pt")'``. ``flowtest benchmark`` takes
one system with several seeds as ``--sut 'NAME=python:mypkg.policies:load@runs/*.pt'``
(the loader called with each matching file, sorted) or repeated ``NAME=SPEC`` entries
(docs/benchmark-protocol.md, *Your own systems*). Unlike a ``python:`` planner it runs in
FlowTest's own process (it is given whole batches, not one step at a time).

Example::

    import torch
    from agents.batched import LogitsPolicy

    def load(path):                                # --sut 'mine=python:my_train.py:load@runs/*.pt'
        saved = torch.load(path, weights_only=True)   # tensors and plain data only, nothing unpickled
        net = make_actor(saved["obs_size"], saved["n_actions"])
        net.load_state_dict(saved["actor"])
        return LogitsPolicy(net, env_options=saved["env_options"])

    load.batched = True
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from .base import PolicyError

OBSERVATION_OPTIONS: tuple[str, ...] = ("obs_kind", "pad_to", "memory")
"""The env options a batched policy may declare (``env_options``): the ones that shape its
observation. The step budget, the rewards and the test's setting are the protocol's."""


class BatchedPolicy(Protocol):
    """The one interface (module docstring): ``act(observations, masks, deterministic=...)``."""

    def act(self, observations: np.ndarray, masks: np.ndarray, deterministic: bool) -> Any: ...


def is_batched(obj: Any) -> bool:
    """Whether a ``python:`` object is marked as the loader of a batched policy
    (``batched = True``)."""
    return getattr(obj, "batched", False) is True


def declared_options(policy: Any) -> dict[str, Any]:
    """The observation options ``policy`` declares (its ``env_options``; none: ``{}``),
    checked as the envs check them.

    Raises
    ------
    PolicyError
        On an option that is not an observation option, or a value no env takes.
    """
    from flowtest_env.config import EnvConfig

    options = getattr(policy, "env_options", None)
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise PolicyError(f"env_options must be a dict of env options, not a {type(options).__name__}")
    other = sorted(str(k) for k in options if k not in OBSERVATION_OPTIONS)
    if other:
        raise PolicyError(f"env_options {other}: a batched policy declares only the options of its observation ({', '.join(OBSERVATION_OPTIONS)})")
    try:
        EnvConfig(**dict(options))
    except (TypeError, ValueError) as exc:
        raise PolicyError(f"env_options: {exc}") from None
    return {str(k): v for k, v in options.items()}


def check_batched(policy: Any, where: str) -> None:
    """Refuse an object that is not a batched policy (no ``act`` method).

    Raises
    ------
    PolicyError
        Saying what the interface is.
    """
    if not callable(getattr(policy, "act", None)):
        raise PolicyError(
            f"{where} returned a {type(policy).__name__}, not a batched policy: an object with "
            "act(observations, masks, deterministic) -> actions (agents.batched)"
        )
    declared_options(policy)


class ModePolicy:
    """A batched policy in one mode, as :func:`flowtest_env.scoring.play_batch` plays it:
    ``policy(observations, masks)`` calls ``act(..., deterministic=...)``, ``reset`` is
    passed on."""

    def __init__(self, policy: Any, deterministic: bool) -> None:
        self.policy, self.deterministic = policy, bool(deterministic)

    def reset(self, num_runs: int, seed: int) -> None:
        reset = getattr(self.policy, "reset", None)
        if callable(reset):
            reset(num_runs, seed)

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return np.asarray(self.policy.act(observations, masks, deterministic=self.deterministic))


class LogitsPolicy:
    """A network from observations to action logits as a batched policy: the illegal
    actions' logits masked out, then the argmax (greedy) or a draw from the softmax with a
    torch generator that ``reset(num_runs, seed)`` seeds (sampled), on the CPU without
    gradients.

    ``logits``: a torch module or any function of a ``float32`` tensor ``[n, obs]``
    returning ``[n, n_actions]`` logits (a tensor or an array); ``env_options``: the
    observation options it was trained with (module docstring).

    Example::

        >>> import numpy as np, torch
        >>> policy = LogitsPolicy(torch.nn.Linear(4, 3), env_options={"memory": "visited"})
        >>> masks = np.array([[True, False, True]])
        >>> policy.reset(1, seed=0)
        >>> int(policy.act(np.zeros((1, 4), np.float32), masks, deterministic=False)[0]) in (0, 2)
        True
    """

    def __init__(self, logits: Callable[[Any], Any], env_options: Mapping[str, Any] | None = None) -> None:
        import torch

        self.logits = logits
        self.env_options = dict(env_options or {})
        self.generator = torch.Generator().manual_seed(0)

    def reset(self, num_runs: int, seed: int) -> None:
        """Seed the sampling (``seed``): the same seed gives the same sampled runs."""
        import torch

        self.generator = torch.Generator().manual_seed(int(seed))

    def act(self, observations: np.ndarray, masks: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """One legal action per row: the most likely (``deterministic``) or one drawn."""
        import torch

        with torch.no_grad():
            x = torch.as_tensor(np.asarray(observations, dtype=np.float32))
            logits = torch.as_tensor(self.logits(x), dtype=torch.float32).reshape(x.shape[0], -1)
            legal = torch.as_tensor(np.asarray(masks, dtype=bool))
            logits = logits.masked_fill(~legal, -torch.inf)
            if deterministic:
                out = torch.argmax(logits, dim=-1)
            else:  # Gumbel-max: a draw from the masked softmax
                u = torch.rand(logits.shape, generator=self.generator).clamp_(1e-12, 1.0)
                out = torch.argmax(logits - torch.log(-torch.log(u)), dim=-1)
        result: np.ndarray = out.numpy()
        return result
