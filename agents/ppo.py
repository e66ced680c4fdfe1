"""Saved stable-baselines3 models as systems under test: ``ppo:PATH``.

The model (``MaskablePPO`` from sb3-contrib, or plain ``PPO``) is loaded lazily, so
FlowTest works without the ``rl`` extra until a ``ppo:`` policy is asked for. Maskable
models are given ``info["action_mask"]``, so they never pick a restricted action; a
plain PPO model may, and the env then leaves the SUT in place.

**Memory.** A reactive test answers the *history* of the run, which the observation
does not show (the test objective stays hidden), so the observation alone is not
Markov for the SUT: on ``FlowTest-Maze2-v0`` no deterministic policy of the
observation alone meets the system objective (the SUT must pass some cells twice, and
the test agent stands where it stood the first time; an exhaustive search over such
policies finds none). A SUT needs memory of its own run. :class:`VisitedMemory` gives
it the smallest useful one: the places it has occupied since the episode began, taken
from its own position in the observations it has seen (never the hidden history).
:func:`experiments.train.train` trains with it (:class:`VisitedObservation`) and
records it in the model (attribute ``flowtest_memory``); :class:`PPOPolicy` rebuilds
the same memory when it plays, so a saved model acts exactly as it was trained.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .base import Policy, PolicyError, action_mask_of, register_policy

MEMORY_KINDS = ("none", "visited")
"""What a trained SUT remembers of its run: nothing, or the places it has occupied."""


def _encoder_of(env: Any) -> Any:
    """The observation encoder behind a FlowTest env (Gymnasium or PettingZoo, wrapped or not)."""
    seen: list[Any] = []
    obj = env
    while obj is not None and len(seen) < 16:
        seen.append(obj)
        enc = getattr(obj, "encoder", None)
        if enc is not None:
            return enc
        obj = getattr(obj, "env", None) or getattr(obj, "aec_env", None)
    enc = getattr(getattr(env, "unwrapped", None), "encoder", None)
    if enc is None:
        raise PolicyError(f"{type(env).__name__} exposes no FlowTest observation encoder")
    return enc


def position_slice(env: Any) -> slice:
    """Where a flat FlowTest observation holds the one-hot of the SUT's own place: the
    ``system`` plane on grids, the first block on graphs (see :mod:`flowtest_env.encoding`).

    Raises
    ------
    PolicyError
        For a non-flat observation.
    """
    enc = _encoder_of(env)
    if enc.obs_kind != "flat":
        raise PolicyError(f"memory needs obs_kind='flat', not {enc.obs_kind!r}")
    if hasattr(enc, "hw"):  # grid: one H*W plane per channel
        start = enc.ch["system"] * enc.hw
        return slice(start, start + enc.hw)
    return slice(0, enc.n_places)  # graph: one-hot of the system's place first


class VisitedMemory:
    """The places the SUT has occupied this episode, as a 0/1 vector appended to the
    observation. Call :meth:`reset` at the start of each episode and :meth:`__call__` on
    every observation, in order."""

    def __init__(self, where: slice) -> None:
        self.where = where
        self.size = where.stop - where.start
        self._seen: np.ndarray | None = None

    def reset(self) -> None:
        self._seen = None

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        here = np.asarray(obs, dtype=np.float32)[self.where]
        self._seen = here.copy() if self._seen is None else np.maximum(self._seen, here)
        return np.concatenate([np.asarray(obs, dtype=np.float32), self._seen])


class VisitedObservation(gym.ObservationWrapper):
    """Append :class:`VisitedMemory` to a flat FlowTest observation (for training)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.memory = VisitedMemory(position_slice(env))
        n = int(env.observation_space.shape[0]) + self.memory.size
        self.observation_space = spaces.Box(0.0, 1.0, shape=(n,), dtype=np.float32)

    def reset(self, **kwargs: Any) -> Any:
        self.memory.reset()
        return super().reset(**kwargs)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return self.memory(observation)


def with_memory(env: gym.Env, memory: str) -> gym.Env:
    """``env`` wrapped so that its observations carry ``memory`` (one of :data:`MEMORY_KINDS`)."""
    if memory == "none":
        return env
    if memory == "visited":
        return VisitedObservation(env)
    raise PolicyError(f"unknown memory {memory!r}; known: {', '.join(MEMORY_KINDS)}")


MAX_MODEL_BYTES = 1 << 30
"""Largest model file loaded (a FlowTest PPO model is well under a megabyte)."""


def load_model(path: str | Path) -> Any:
    """Load a saved (Maskable)PPO model.

    Raises
    ------
    PolicyError
        If stable-baselines3 is missing or the file cannot be read.
    """
    p = Path(path)
    if not p.exists() and not p.with_suffix(".zip").exists():
        raise PolicyError(f"no saved model at {str(p)!r}")
    found = p if p.exists() else p.with_suffix(".zip")
    if not found.is_file():  # a folder, /dev/zero, a pipe: never read it
        raise PolicyError(f"the model {str(found)!r} is not a regular file")
    if found.stat().st_size > MAX_MODEL_BYTES:
        raise PolicyError(f"the model {str(found)!r} is larger than {MAX_MODEL_BYTES >> 20} MiB")
    try:
        from sb3_contrib import MaskablePPO
    except ImportError:  # pragma: no cover - depends on the rl extra
        MaskablePPO = None
    try:
        from stable_baselines3 import PPO
    except ImportError as exc:  # pragma: no cover
        raise PolicyError("ppo:PATH needs the rl extra: pip install 'flowtest[rl]'") from exc
    if MaskablePPO is not None:
        try:
            return MaskablePPO.load(str(p), device="cpu")
        except Exception:  # noqa: BLE001 - fall back to plain PPO
            pass
    try:
        return PPO.load(str(p), device="cpu")
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's input, not a bug
        detail = " ".join(str(exc).split())[:200]
        raise PolicyError(f"{str(found)!r} is not a saved PPO model ({type(exc).__name__}: {detail})") from None


class PPOPolicy:
    """A trained model acting deterministically (its most likely legal action).

    ``env`` (the env it will play) is needed when the model was trained with memory
    (``model.flowtest_memory``): the memory is rebuilt from the observations.

    Raises
    ------
    PolicyError
        If the model needs memory and no env is given, or if the env's observations do
        not have the shape the model was trained on.
    """

    def __init__(self, model: Any, name: str = "ppo", env: Any = None) -> None:
        self.model = model
        self.name = name
        self.maskable = type(model).__name__ == "MaskablePPO"
        self.memory_kind = str(getattr(model, "flowtest_memory", "none"))
        self.memory: VisitedMemory | None = None
        if self.memory_kind not in MEMORY_KINDS:
            raise PolicyError(f"model {name!r} uses unknown memory {self.memory_kind!r}")
        if self.memory_kind == "visited":
            if env is None:
                raise PolicyError(f"model {name!r} remembers visited places: PPOPolicy needs the env")
            self.memory = VisitedMemory(position_slice(env))
        if env is not None:
            enc = _encoder_of(env)
            size = int(enc.space.shape[0]) + (self.memory.size if self.memory else 0)
            want = tuple(model.observation_space.shape)
            if want != (size,):
                raise PolicyError(
                    f"model {name!r} was trained on observations of shape {want}; this env gives ({size},)"
                    " (train on a test with the same grid and objective to evaluate on it)"
                )

    def reset(self, seed: int | None = None) -> None:
        """Forget the previous episode (the model itself is a stateless MLP)."""
        if self.memory is not None:
            self.memory.reset()

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        obs = observation["observation"] if isinstance(observation, dict) else observation
        if self.memory is not None:
            obs = self.memory(obs)
        if self.maskable:
            mask = action_mask_of(observation, info).astype(bool)
            action, _ = self.model.predict(obs, deterministic=True, action_masks=mask)
        else:
            action, _ = self.model.predict(obs, deterministic=True)
        return int(np.asarray(action).item())


@register_policy("ppo")
def _make_ppo(env: Any, arg: str) -> Policy:
    if not arg:
        raise PolicyError("ppo needs a model path: ppo:PATH")
    return PPOPolicy(load_model(arg), f"ppo:{arg}", env)
