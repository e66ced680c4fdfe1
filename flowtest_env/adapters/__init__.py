"""Adapters for RL libraries that consume an interface of their own instead of Gymnasium's.

* :mod:`flowtest_env.adapters.sb3`: Stable-Baselines3's ``VecEnv`` over the NumPy vector
  env (:mod:`flowtest_env.vector`), so SB3 and MaskablePPO train at vector speed.

Each adapter imports its library only when it is used (``stable_baselines3`` is the ``rl``
extra), so ``import flowtest_env.adapters`` needs nothing beyond the core::

    >>> from flowtest_env.adapters import make_sb3_vec_env
    >>> envs = make_sb3_vec_env("FlowTest-SmallReactive-v0", num_envs=8)  # doctest: +SKIP

docs/recipes.md shows every library with the interface it takes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .sb3 import FlowTestSB3VecEnv


def make_sb3_vec_env(env_id: str, num_envs: int, seed: int | None = None, **options: Any) -> FlowTestSB3VecEnv:
    """``num_envs`` runs of the FlowTest env ``env_id`` as one Stable-Baselines3 ``VecEnv``
    (:func:`flowtest_env.adapters.sb3.make_sb3_vec_env`; imports ``stable_baselines3``)."""
    from .sb3 import make_sb3_vec_env as make

    return make(env_id, num_envs, seed=seed, **options)


__all__ = ["make_sb3_vec_env"]
