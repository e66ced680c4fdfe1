"""Stable-Baselines3's ``VecEnv`` over the NumPy vector env: SB3 at vector speed.

SB3 does not take a Gymnasium ``VectorEnv``: it steps its own ``VecEnv`` (usually a
``DummyVecEnv`` of single envs, one Python ``step`` per env). :class:`FlowTestSB3VecEnv`
gives it the FlowTest vector env (:mod:`flowtest_env.vector`) instead, stepped as one
batch, with SB3's conventions:

* an env whose episode ends is reset in the same step (the vector env's ``SAME_STEP``
  autoreset mode): the observation returned is the new episode's, the ended one's is in
  ``infos[i]["terminal_observation"]``;
* ``infos[i]["TimeLimit.truncated"]`` is ``True`` where the episode was cut by the step
  budget and not ended by the objective (SB3 bootstraps those); ``infos[i]["verdict"]``
  holds the ended episode's verdict, as the single env's infos do;
* ``env_method("action_masks")`` and :meth:`FlowTestSB3VecEnv.action_masks` give the
  legal actions, which is how sb3-contrib's ``MaskablePPO`` reads them.

Example::

    >>> from sb3_contrib import MaskablePPO
    >>> from flowtest_env.adapters.sb3 import make_sb3_vec_env
    >>> envs = make_sb3_vec_env("FlowTest-SmallReactive-v0", num_envs=16, seed=0)
    >>> model = MaskablePPO("MlpPolicy", envs, n_steps=32, seed=0).learn(2_048)  # doctest: +SKIP

Imports ``stable_baselines3`` (the ``rl`` extra); :mod:`flowtest_env.adapters` itself does not.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn

from ..vector import PoolVectorEnv


class FlowTestSB3VecEnv(VecEnv):
    """A FlowTest vector env (``autoreset_mode=SAME_STEP``) as an SB3 ``VecEnv``.

    Parameters
    ----------
    venv
        A :class:`~flowtest_env.vector.PoolVectorEnv` (``gym.make_vec(...,
        vectorization_mode="vector_entry_point", autoreset_mode="SAME_STEP")``, or one of
        its classes) in ``SAME_STEP`` mode; :func:`make_sb3_vec_env` builds one.

    Raises
    ------
    TypeError
        If ``venv`` is not a FlowTest vector env.
    ValueError
        If its autoreset mode is not ``SAME_STEP`` (SB3 expects the reset observation
        in the same step as the episode's end).
    """

    def __init__(self, venv: Any) -> None:
        inner = getattr(venv, "unwrapped", venv)
        if not isinstance(inner, PoolVectorEnv):
            raise TypeError(f"FlowTestSB3VecEnv needs a FlowTest vector env (flowtest_env.vector.PoolVectorEnv), not {type(venv).__name__}")
        if inner.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError(
                f"FlowTestSB3VecEnv needs autoreset_mode SAME_STEP (SB3 resets an env in the step its episode ends), "
                f"not {inner.autoreset_mode.name}: make it with autoreset_mode='SAME_STEP' or use make_sb3_vec_env"
            )
        self.venv: PoolVectorEnv = inner
        super().__init__(inner.num_envs, inner.single_observation_space, inner.single_action_space)
        self.render_mode = inner.render_mode
        self.metadata = dict(inner.metadata)
        self._actions: np.ndarray | None = None

    # ------------------------------------------------------------------ VecEnv API

    def reset(self) -> VecEnvObs:
        """Start a run in every env (the seeds given by :meth:`seed`, used once, as SB3 does)."""
        seeds = list(self._seeds)
        seed: Any = None if all(s is None for s in seeds) else seeds
        obs, infos = self.venv.reset(seed=seed)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions).reshape(self.num_envs)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        obs, reward, terminated, truncated, infos = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        time_limit = truncated & ~terminated
        out: list[dict[str, Any]] = [{"TimeLimit.truncated": bool(t)} for t in time_limit.tolist()]
        if dones.any():
            final_obs = infos["final_obs"]
            verdict = infos["final_info"]["verdict"]
            fields = [k for k in verdict if not k.startswith("_")]
            for i in np.flatnonzero(dones).tolist():
                out[i]["terminal_observation"] = final_obs[i]
                out[i]["verdict"] = {k: _plain(verdict[k][i]) for k in fields}
        return obs, reward.astype(np.float32, copy=False), dones, out

    def close(self) -> None:
        self.venv.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One picture per env (``render_mode="rgb_array"``)."""
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs

    # ------------------------------------------------------------------ masks

    def action_masks(self) -> np.ndarray:
        """``bool[num_envs, n_actions]``: the legal actions of every env now."""
        return self.venv.action_masks()

    # ------------------------------------------------------------------ per-env access

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute, once per env of ``indices`` (the runs of one
        vector env share their attributes)."""
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Refused: the runs of one vector env share their attributes."""
        raise AttributeError(f"cannot set {attr_name!r} per env: the envs of a FlowTest vector env share it (set it on .venv)")

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any) -> list[Any]:
        """``"action_masks"``: each env's mask (what ``MaskablePPO`` calls, one batch
        gather for all envs); another method of the vector env is called once and its
        answer listed per env."""
        idx = list(self._get_indices(indices))
        if method_name == "action_masks":
            masks = self.venv.action_masks()
            return [masks[i] for i in idx]
        answer = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [answer for _ in idx]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        """Always ``False``: the runs are not single envs, nothing wraps them."""
        return [False for _ in self._get_indices(indices)]


def _plain(value: Any) -> Any:
    """A NumPy scalar as the Python value (verdict fields: str, bool, int)."""
    return value.item() if isinstance(value, np.generic) else value


def make_sb3_vec_env(env_id: str, num_envs: int, seed: int | None = None, **options: Any) -> FlowTestSB3VecEnv:
    """``num_envs`` runs of the FlowTest env ``env_id`` (``"FlowTest-Maze2-v0"``, ...)
    as one SB3 ``VecEnv``; ``options`` are the env's (``memory="visited"``,
    ``shaping=...``, ``max_steps``, ...: :class:`~flowtest_env.config.EnvConfig`).
    ``seed``: env ``i`` is seeded with ``seed + i`` at the first ``reset()``."""
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode="SAME_STEP", **options)
    envs = FlowTestSB3VecEnv(venv)
    if seed is not None:
        envs.seed(seed)
    return envs


__all__ = ["FlowTestSB3VecEnv", "make_sb3_vec_env"]
