"""The FlowTest vector env with numeric infos, for libraries that turn every info into a
tensor (TorchRL's ``GymWrapper``).

The vector env's infos follow the single env's: ``system_state`` (an object array of the
states' JSON values) and, at the end of an episode, ``verdict`` with the outcome as a
string. A library that stacks infos into tensors cannot hold those.
:class:`NumericVectorEnv` keeps Gymnasium's vector API and the autoreset mode of the env
it wraps, and gives

* the same observations (a Box: TorchRL's SAME_STEP reader cannot take a Dict's final
  observations);
* infos with the same numeric keys at every reset and step: ``action_mask``
  (``bool[num_envs, n]``, the mask of the state the observation shows; TorchRL's
  ``MaskedCategorical`` reads it) and the verdict of the episode the step belongs to (the
  ended one where an episode ended, else the running one) as numbers,
  ``system_objective`` (0 open, 1 met, 2 violated), ``test_objective_realized`` (0/1),
  ``restrictions``, ``blocked_attempts``, ``steps``; in ``SAME_STEP`` mode ``final_obs``
  (the ended episodes' observations) and ``final_info`` (their numeric infos, the final
  state's mask included), laid out as Gymnasium's ``SyncVectorEnv`` lays them out.

Example::

    >>> import gymnasium as gym
    >>> from flowtest_env.adapters.numeric import NumericVectorEnv
    >>> envs = NumericVectorEnv(gym.make_vec("FlowTest-Maze2-v0", num_envs=4,
    ...                         vectorization_mode="vector_entry_point", autoreset_mode="SAME_STEP"))
    >>> obs, infos = envs.reset(seed=0)
    >>> sorted(infos)
    ['action_mask', 'blocked_attempts', 'restrictions', 'steps', 'system_objective', 'test_objective_realized']

Needs nothing beyond the core (no TorchRL import); docs/recipes/torchrl_vector.py uses it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper

from ..compiled import OUTCOMES
from ..vector import PoolVectorEnv

VERDICT_KEYS = ("system_objective", "test_objective_realized", "restrictions", "blocked_attempts", "steps")
"""The numeric infos' keys, at every reset and step."""
_CODES = {name: code for code, name in enumerate(OUTCOMES)}


class NumericVectorEnv(VectorWrapper):
    """A FlowTest vector env with numeric infos (see the module docstring); any autoreset
    mode, kept as ``autoreset_mode``.

    Raises
    ------
    TypeError
        If ``env`` is not a FlowTest vector env (:class:`~flowtest_env.vector.PoolVectorEnv`).
    """

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        inner = env.unwrapped
        if not isinstance(inner, PoolVectorEnv):
            raise TypeError(f"NumericVectorEnv needs a FlowTest vector env, not {type(inner).__name__}")
        self.flowtest: PoolVectorEnv = inner
        self.autoreset_mode: AutoresetMode = inner.autoreset_mode
        self.metadata = dict(inner.metadata)

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        obs, _ = self.env.reset(seed=seed, options=options)
        # every env's mask, also after a partial reset (reset_mask), whose infos cover the reset envs only
        return obs, {"action_mask": self.flowtest.action_masks(), **self._numeric(self.flowtest.verdicts())}

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, reward, terminated, truncated, infos = self.env.step(actions)
        out = {"action_mask": infos["action_mask"].astype(bool), **self._numeric(self.flowtest.verdicts())}
        if "final_info" in infos:  # SAME_STEP: the ended episodes' verdicts, observations and masks
            ended = infos["_final_info"]
            final = infos["final_info"]
            done = {"action_mask": final["action_mask"].astype(bool), **self._numeric({k: np.where(ended, final["verdict"][k], 0) for k in VERDICT_KEYS})}
            for k in VERDICT_KEYS:
                out[k] = np.where(ended, done[k], out[k])
            out["final_obs"], out["_final_obs"] = infos["final_obs"], ended.copy()
            out["final_info"], out["_final_info"] = done, ended.copy()
        return obs, reward, terminated, truncated, out

    @staticmethod
    def _numeric(verdict: dict[str, Any]) -> dict[str, Any]:
        """The verdict arrays as numbers (``system_objective`` names to codes)."""
        names = verdict["system_objective"]
        objective = np.array([_CODES.get(x, 0) if isinstance(x, str) else 0 for x in names], dtype=np.int64)
        return {
            "system_objective": objective,
            "test_objective_realized": np.asarray(verdict["test_objective_realized"]).astype(np.int64),
            "restrictions": np.asarray(verdict["restrictions"], dtype=np.int64),
            "blocked_attempts": np.asarray(verdict["blocked_attempts"], dtype=np.int64),
            "steps": np.asarray(verdict["steps"], dtype=np.int64),
        }


__all__ = ["NumericVectorEnv", "VERDICT_KEYS"]
