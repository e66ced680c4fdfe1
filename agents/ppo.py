"""Saved models as systems under test: ``ppo:PATH``.

Two kinds of file, told apart by their content:

* a **native checkpoint** (:mod:`agents.checkpoint`, written by ``flowtest train``'s
  native trainer, :mod:`agents.native_ppo`): tensors and plain settings, read without
  unpickling; safe to load from anyone;
* a **stable-baselines3 zip** (``MaskablePPO`` or ``RecurrentPPO`` from sb3-contrib, or
  plain ``PPO``; ``flowtest train --trainer sb3``): SB3 unpickles it, which can run code
  stored in the file, so it is loaded only when the user trusts it (``--trust-model``, or
  :func:`agents.checkpoint.trust_pickled_models` from Python), with a warning line;
  otherwise :class:`agents.checkpoint.UntrustedModelError` (invalid input) before any
  of it is unpickled.

:class:`PPOPolicy` plays a model through the single env; :class:`ModelBatchPolicy` plays a
stable-baselines3 model in batches (every test of a split at once, greedy or sampled), as
``flowtest benchmark`` scores it.

Models are loaded lazily, so FlowTest works without the ``rl`` extra until a ``ppo:``
policy is asked for. Maskable models (and every native one) are given
``info["action_mask"]``, so they never pick a restricted action; a plain PPO model may,
and the env then leaves the SUT in place.

**Memory.** A reactive test answers the *history* of the run, which the observation
does not show (the test objective stays hidden), so the observation alone is not
Markov for the SUT: on ``FlowTest-Maze2-v0`` no deterministic policy of the
observation alone meets the system objective (the SUT must pass some cells twice, and
the test agent stands where it stood the first time; an exhaustive search over such
policies finds none). A SUT needs memory of its own run: the public wrapper
:class:`flowtest_env.wrappers.VisitedPlaces` (or the env option ``memory="visited"``)
gives it the smallest useful one, the places it has occupied since the episode began,
taken from its own position in the observations it has seen (never the hidden history).
:func:`experiments.training.system.train` trains with it and records it in the model (attribute
``flowtest_memory``); :class:`PPOPolicy` rebuilds the same memory when it plays, so a
saved model acts exactly as it was trained.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from flowtest_env.encoding import EncodingError, make_encoder
from flowtest_env.memory import PLACE_MEMORIES, PlaceMemory
from flowtest_env.wrappers import MEMORY_KINDS, VisitedPlaces, encoder_of
from flowtest_env.wrappers import VisitedMemory as VisitedMemory  # re-exported: the older place of the visited memory
from flowtest_env.wrappers import position_slice as _position_slice

from .base import Policy, PolicyError, action_mask_of, game_of
from .checkpoint import is_native_checkpoint, is_own_file, pickled_models_trusted, refuse_pickled, warn_pickled


def position_slice(env: Any) -> slice:
    """Where a flat FlowTest observation of ``env`` holds the SUT's own place
    (:func:`flowtest_env.wrappers.position_slice`).

    Raises
    ------
    PolicyError
        For a non-flat observation or a non-FlowTest env.
    """
    try:
        return _position_slice(encoder_of(env))
    except (TypeError, ValueError) as exc:
        raise PolicyError(str(exc)) from None


VisitedObservation = VisitedPlaces
"""The older name of :class:`flowtest_env.wrappers.VisitedPlaces`."""


def with_memory(env: gym.Env, memory: str) -> gym.Env:
    """``env`` wrapped so that its observations carry ``memory`` (one of :data:`MEMORY_KINDS`)."""
    if memory == "none":
        return env
    if memory in PLACE_MEMORIES:
        return VisitedPlaces(env, memory)
    raise PolicyError(f"unknown memory {memory!r}; known: {', '.join(MEMORY_KINDS)}")


MAX_MODEL_BYTES = 1 << 30
"""Largest model file loaded (a FlowTest PPO model is well under a megabyte)."""


def _saved_policy_module(path: Path) -> str:
    """The module of the policy class recorded in a saved SB3 model (``""`` if unknown)."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            data = json.loads(z.read("data"))
        return str(data.get("policy_class", {}).get("__module__", ""))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return ""


def load_model(path: str | Path, trust: bool | None = None) -> Any:
    """Load a saved model: a native checkpoint (never unpickled), else a MaskablePPO,
    RecurrentPPO or plain PPO zip (the class is read from the file's recorded policy
    class), which only when trusted: ``trust`` (``None``: the process setting of
    :func:`agents.checkpoint.trust_pickled_models`), or written by this process
    (:func:`agents.checkpoint.mark_own_file`).

    Example::

        policy = PPOPolicy(load_model("policy.zip"), "ppo:policy.zip", env)

    Raises
    ------
    PolicyError
        If the file is missing or cannot be read as a model (or SB3 is missing).
    agents.checkpoint.UntrustedModelError
        For a stable-baselines3 zip without trust (nothing of it unpickled).
    """
    p = Path(path)
    if not p.exists() and not p.with_suffix(".zip").exists():
        raise PolicyError(f"no saved model at {str(p)!r}")
    found = p if p.exists() else p.with_suffix(".zip")
    if not found.is_file():  # a folder, /dev/zero, a pipe: never read it
        raise PolicyError(f"the model {str(found)!r} is not a regular file")
    if found.stat().st_size > MAX_MODEL_BYTES:
        raise PolicyError(f"the model {str(found)!r} is larger than {MAX_MODEL_BYTES >> 20} MiB")
    p = found
    if is_native_checkpoint(p):
        return _load_native(p)
    own = is_own_file(p)
    if not (own or (pickled_models_trusted() if trust is None else trust)):
        if not _is_zip(p):
            raise PolicyError(f"{str(p)!r} is not a saved model (neither a native checkpoint nor a stable-baselines3 zip)")
        raise refuse_pickled(p)
    try:
        from stable_baselines3 import PPO
    except ImportError as exc:  # pragma: no cover
        raise PolicyError("a stable-baselines3 model needs the rl extra: pip install 'flowtest[rl]'") from exc
    if trust is None and not own:
        warn_pickled(p)
    module = _saved_policy_module(p)
    try:
        if "recurrent" in module:
            from sb3_contrib import RecurrentPPO

            return RecurrentPPO.load(str(p), device="cpu")
        if "maskable" in module:
            from sb3_contrib import MaskablePPO

            return MaskablePPO.load(str(p), device="cpu")
        return PPO.load(str(p), device="cpu")
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the user's input, not a bug
        detail = " ".join(str(exc).split())[:200]
        raise PolicyError(f"{str(p)!r} is not a saved PPO model ({type(exc).__name__}: {detail})") from None


def check_trusted(path: str | Path) -> None:
    """Refuse early (before any other work) a model file that loading would unpickle,
    without the user's trust; a missing or native file passes (:func:`load_model` reports it).

    Raises
    ------
    agents.checkpoint.UntrustedModelError
        For a stable-baselines3 zip that is neither trusted nor written by this process.
    """
    p = Path(path)
    found = p if p.exists() else p.with_suffix(".zip")
    if not found.is_file() or is_native_checkpoint(found) or is_own_file(found) or pickled_models_trusted():
        return
    if _is_zip(found):
        raise refuse_pickled(found)


def _is_zip(path: Path) -> bool:
    import zipfile

    return zipfile.is_zipfile(path)


def _load_native(path: Path) -> Any:
    """A native checkpoint as a model (:class:`agents.native.checkpoint.NativeModel`)."""
    from .checkpoint import CheckpointError

    try:
        from .native.checkpoint import load_native
    except ImportError as exc:  # pragma: no cover - torch missing
        raise PolicyError("a FlowTest policy checkpoint needs the rl extra (torch): pip install 'flowtest[rl]'") from exc
    try:
        return load_native(path)
    except CheckpointError as exc:  # its message names the file and the field
        raise PolicyError(str(exc)) from None


class PPOPolicy:
    """A trained model (native or stable-baselines3, :func:`load_model`) acting
    deterministically (its most likely legal action).

    The model records the observation it was trained on (``model.flowtest_obs``:
    ``obs_kind`` and ``pad_to``) and the SUT's memory (``model.flowtest_memory``). When
    the env shows another observation kind, the policy encodes the env's run itself with
    the model's encoder (the same information the env would show with that option), so a
    model trained with ``obs_kind="padded"`` plays any grid test that fits; the memory is
    rebuilt from the observations. RecurrentPPO models keep their LSTM state over the
    episode.

    Raises
    ------
    PolicyError
        If the model needs memory and no env is given, or if it cannot play the env (an
        observation it cannot encode, or of another shape than it was trained on).
    """

    def __init__(self, model: Any, name: str = "ppo", env: Any = None) -> None:
        self.model = model
        self.name = name
        kind = type(model).__name__
        self.maskable = bool(getattr(model, "maskable", kind == "MaskablePPO"))
        self.recurrent = bool(getattr(model, "recurrent", kind == "RecurrentPPO"))
        self.memory_kind = str(getattr(model, "flowtest_memory", "none"))
        self.obs = dict(getattr(model, "flowtest_obs", None) or {"obs_kind": "flat", "pad_to": 8})
        self.memory: PlaceMemory | None = None
        self.env = env
        self._encoders: dict[int, Any] = {}
        self._state: Any = None
        self._start = True
        if self.memory_kind not in MEMORY_KINDS:
            raise PolicyError(f"model {name!r} uses unknown memory {self.memory_kind!r}")
        if env is None:
            if self.memory_kind != "none":
                raise PolicyError(f"model {name!r} remembers visited places: PPOPolicy needs the env")
            return
        enc = encoder_of(env)
        self.own_encoding = (enc.obs_kind, getattr(enc, "pad_to", self.obs["pad_to"])) != (self.obs["obs_kind"], self.obs["pad_to"])
        if self.own_encoding:
            enc = self._encoder()
        if self.memory_kind in PLACE_MEMORIES:
            try:
                self.memory = PlaceMemory(_position_slice(enc), self.memory_kind)
            except ValueError as exc:
                raise PolicyError(str(exc)) from None
        size = int(enc.space.shape[0]) + (self.memory.size if self.memory else 0)
        want = tuple(model.observation_space.shape)
        if want != (size,):
            raise PolicyError(
                f"model {name!r} was trained on observations of shape {want}; {game_of(env).artifact.name!r} gives "
                f"({size},) (train with obs_kind='padded' to play tests of other sizes)"
            )

    def _encoder(self) -> Any:
        """The model's encoder for the env's current test (the random-grid env switches
        tests at reset)."""
        game = game_of(self.env)
        enc = self._encoders.get(id(game))
        if enc is None:
            try:
                enc = make_encoder(game, self.obs["obs_kind"], int(self.obs["pad_to"]))
            except EncodingError as exc:
                raise PolicyError(f"model {self.name!r} was trained on obs_kind={self.obs['obs_kind']!r}: {exc}") from None
            self._encoders[id(game)] = enc
        return enc

    def reset(self, seed: int | None = None) -> None:
        """Forget the previous episode (memory, LSTM state)."""
        if self.memory is not None:
            self.memory.reset()
        self._state, self._start = None, True

    def act(self, observation: Any, info: dict[str, Any]) -> int:
        if self.env is not None and self.own_encoding:
            obs = self._encoder().encode(self.env.unwrapped.run)
        else:
            obs = observation["observation"] if isinstance(observation, dict) else observation
        if self.memory is not None:
            obs = self.memory(obs)
        if self.recurrent and self.maskable:  # a native GRU policy: its state and the masks
            mask = action_mask_of(observation, info).astype(bool)
            action, self._state = self.model.predict(obs, state=self._state, episode_start=np.array([self._start]), deterministic=True, action_masks=mask)
            self._start = False
        elif self.recurrent:
            action, self._state = self.model.predict(obs, state=self._state, episode_start=np.array([self._start]), deterministic=True)
            self._start = False
        elif self.maskable:
            mask = action_mask_of(observation, info).astype(bool)
            action, _ = self.model.predict(obs, deterministic=True, action_masks=mask)
        else:
            action, _ = self.model.predict(obs, deterministic=True)
        return int(np.asarray(action).item())


def make_ppo(env: Any, arg: str) -> Policy:
    """The saved model ``ppo:<arg>`` as a SUT for ``env``.

    Raises
    ------
    PolicyError
        Without a path, or for a model that cannot be loaded or does not fit ``env``.
    """
    if not arg:
        raise PolicyError("ppo needs a model path: ppo:PATH")
    return PPOPolicy(load_model(arg), f"ppo:{arg}", env)


class ModelBatchPolicy:
    """A saved model (native or stable-baselines3, as :func:`agents.ppo.load_model` gives
    it) as a batched policy of :mod:`flowtest_env.scoring`: greedy (``deterministic``) or
    sampled, adding the visited-places memory when the model has it (``where``: the SUT's
    place in the observation) and carrying a recurrent state. Sampling is seeded by
    ``reset`` (torch's global generator, which stable-baselines3 samples from)."""

    def __init__(self, model: Any, where: slice | None, deterministic: bool = True) -> None:
        kind = type(model).__name__
        self.model, self.where, self.deterministic = model, where, deterministic
        self.recurrent = bool(getattr(model, "recurrent", kind == "RecurrentPPO"))
        self.maskable = bool(getattr(model, "maskable", kind == "MaskablePPO"))
        self.state: Any = None
        self.seen: np.ndarray | None = None

    def reset(self, num_runs: int, seed: int) -> None:
        import torch

        torch.manual_seed(int(seed))
        self.state, self.seen = None, None

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        obs = np.asarray(observations, dtype=np.float32)
        starts = np.full(obs.shape[0], self.seen is None)
        if self.where is not None:
            here = obs[:, self.where]
            self.seen = here.copy() if self.seen is None else np.maximum(self.seen, here)
            obs = np.concatenate([obs, self.seen], axis=1)
        elif self.seen is None:
            self.seen = np.zeros((obs.shape[0], 0), dtype=np.float32)
        kw: dict[str, Any] = {"deterministic": self.deterministic}
        if self.maskable:
            kw["action_masks"] = masks
        if self.recurrent:
            kw["state"], kw["episode_start"] = self.state, starts
        actions, self.state = self.model.predict(obs, **kw)
        return np.asarray(actions)


def model_where(model: Any, games: Sequence[Any], memory: str) -> slice | None:
    """Where the flat observations of ``games`` hold the SUT's place, for a model with the
    visited-places ``memory`` (``None`` for another memory)."""
    from flowtest_env.wrappers import shared_position_slice

    if memory != "visited":
        return None
    return shared_position_slice([make_encoder(g, "flat") for g in games])
