"""Vectorized FlowTest environments: many test runs stepped at once with NumPy.

The ``vector_entry_point`` of every FlowTest ID::

    import gymnasium as gym
    import flowtest_env

    envs = gym.make_vec("FlowTest-Maze2-v0", num_envs=1024, vectorization_mode="vector_entry_point")
    obs, infos = envs.reset(seed=0)
    actions = ...  # int[num_envs]; infos["action_mask"] is int8[num_envs, n_actions]
    obs, rewards, terminated, truncated, infos = envs.step(actions)

Each test is compiled once into flat tables (:mod:`flowtest_env.compiled`); a step is
then a handful of array gathers over the whole batch, the same for every env whatever
test it plays. The trajectories are exactly those of a ``SyncVectorEnv`` of the single
env (observations, rewards, terminated, truncated and infos: ``system_state``,
``action_mask``, and ``verdict`` with its fields at the end of an episode), with
Gymnasium 1.x's default ``AutoresetMode.NEXT_STEP``: the step after an episode ended
resets that env (its action is ignored; reward 0, not terminated, not truncated, the
reset's infos).

A batch may hold different tests of one pool: :class:`RandomGridVectorEnv` draws each
episode's test as :class:`~flowtest_env.envs.RandomGridEnv` does (the counter-based
draws of :mod:`flowtest_env.draws`, env ``i`` keyed ``seed + i`` like ``SyncVectorEnv``), and :class:`PoolVectorEnv`
takes any list of tests, drawn the same way or fixed per env (``assignment="fixed"``:
env ``i`` always plays test ``i % n_tests``). Tests with fewer actions or smaller
observations than the pool's largest are padded: extra actions are invalid (refused,
never in the mask), extra observation entries are zero.

:class:`VectorActionMaskObservation` puts the batched mask into the observation, as
:class:`~flowtest_env.wrappers.ActionMaskObservation` does for one env.

Limits: the ``"instantaneous"`` setting only (the accumulative observation depends on
the states visited, not on the configuration); ``AutoresetMode.NEXT_STEP`` only.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .compiled import OUTCOMES, CompiledPool, compile_pool
from .draws import draw_tests, key_of_seed
from .encoding import make_encoder
from .envs import default_max_steps
from .game import RunState, TestGame
from .pools import random_grid_arguments
from .random_grid import POOL_KINDS, WORLDS, random_pool
from .render import Renderer, make_renderer
from .sources import game_for


class PoolVectorEnv(VectorEnv[np.ndarray, np.ndarray, np.ndarray]):
    """A batch of FlowTest runs over a pool of tests (see the module docstring).

    Parameters
    ----------
    num_envs
        Number of runs in the batch.
    games
        The pool's tests.
    assignment
        ``"random"``: each episode draws its test from the env's generator (as
        :class:`~flowtest_env.envs.RandomGridEnv`); ``"fixed"``: env ``i`` plays test
        ``i % len(games)``.
    max_steps, obs_kind, render_mode, view, tile_size, step_cost, restricted_penalty,
    goal_reward, violation_penalty
        As for :class:`~flowtest_env.envs.FlowTestEnv`.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        games: Sequence[TestGame],
        assignment: str = "random",
        max_steps: int = 100,
        obs_kind: str = "flat",
        render_mode: str | None = None,
        view: str = "system",
        tile_size: int = 32,
        step_cost: float = 0.01,
        restricted_penalty: float = 0.05,
        goal_reward: float = 1.0,
        violation_penalty: float = 1.0,
    ) -> None:
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be at least 1, not {num_envs}")
        if assignment not in ("random", "fixed"):
            raise ValueError(f"unknown assignment {assignment!r}; expected 'random' or 'fixed'")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unknown render_mode {render_mode!r}; expected one of {self.metadata['render_modes']}")
        if view not in ("system", "engineer"):
            raise ValueError(f"unknown view {view!r}; expected 'system' or 'engineer'")
        if int(max_steps) < 1:
            raise ValueError(f"max_steps must be at least 1, not {max_steps}")
        self.games = list(games)
        self.pool: CompiledPool = compile_pool(self.games, [make_encoder(g, obs_kind) for g in self.games])
        p = self.pool
        self.num_envs = int(num_envs)
        self.assignment = assignment
        self.max_steps = int(max_steps)
        self.obs_kind = obs_kind
        self.render_mode = render_mode
        self.view = view
        self.tile_size = int(tile_size)
        dtype = p.obs.dtype
        high = 1.0 if dtype == np.float32 else 255
        self.single_observation_space = spaces.Box(0, high, shape=p.obs_shape, dtype=dtype)
        self.single_action_space = spaces.Discrete(p.n_actions)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._reward = p.rewards(step_cost, restricted_penalty, goal_reward, violation_penalty)
        self._outcome_names = np.array(OUTCOMES, dtype=object)
        self._all = np.ones(self.num_envs, dtype=bool)
        self._z = np.zeros(self.num_envs, dtype=np.int64)
        self._test = np.zeros(self.num_envs, dtype=np.int64)
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self._restrictions = np.zeros(self.num_envs, dtype=np.int64)
        self._blocked = np.zeros(self.num_envs, dtype=np.int64)
        self._prev_done = np.zeros(self.num_envs, dtype=bool)
        self._keys = np.zeros(self.num_envs, dtype=np.uint64)  # the test draws' keys (flowtest_env.draws)
        self._episode = np.zeros(self.num_envs, dtype=np.int64)  # each env's episodes since its key
        self._keyed = False
        self._started = False
        self._renderers: dict[int, Renderer] = {}

    # ------------------------------------------------------------------ tests per episode

    def _choose_tests(self, envs: np.ndarray) -> np.ndarray:
        """The tests of the current episodes of ``envs`` (their keys and episode counters:
        :func:`flowtest_env.draws.draw_tests`)."""
        if self.assignment == "fixed":
            return envs % len(self.games)
        return draw_tests(self._keys[envs], self._episode[envs], len(self.games))

    def _start(self, envs: np.ndarray) -> None:
        tests = self._choose_tests(envs)
        self._test[envs] = tests
        self._z[envs] = self.pool.initial[tests]
        self._steps[envs] = 0
        self._restrictions[envs] = 0
        self._blocked[envs] = 0

    # ------------------------------------------------------------------ API

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a run in every env. ``seed``: an int seeds env ``i`` with ``seed + i``
        (as ``SyncVectorEnv``), a list one seed per env, ``None`` fresh entropy."""
        super().reset(seed=seed if isinstance(seed, int) else None)
        if seed is None or isinstance(seed, int):
            seeds: list[int | None] = [None if seed is None else seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"{len(seeds)} seeds for {self.num_envs} envs")
        if not self._keyed:  # never seeded: keys drawn once, as each single env would
            self._keys[:] = self.np_random.integers(2**63, size=self.num_envs).astype(np.uint64)
            self._episode[:] = -1
            self._keyed = True
        given = np.array([s is not None for s in seeds], dtype=bool)
        self._episode += 1
        if given.any():
            self._keys[given] = [key_of_seed(s) for s in seeds if s is not None]
            self._episode[given] = 0
        envs = np.arange(self.num_envs)
        self._start(envs)
        self._prev_done[:] = False
        self._started = True
        return self._observe(self._z), self._infos(self._z)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Every env takes its action (an env whose episode ended at the last step is
        reset instead and its action ignored).

        Raises
        ------
        gymnasium.error.ResetNeeded
            Before ``reset()``.
        gymnasium.error.InvalidAction
            If ``actions`` is not ``num_envs`` action indices (a masked action is *not*
            an error: it is refused, as in the single env).
        """
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = self._check(actions)
        z = self._z
        flat = z * self.pool.n_actions + a
        z2 = self.pool.next_z[flat]
        reward = self._reward[flat]
        self._steps += 1
        self._restrictions += self.pool.restricted[z]
        self._blocked += self.pool.refused[flat]
        terminated = self.pool.outcome[z2] != 0
        truncated = ~terminated & (self._steps >= self.max_steps)
        if self._prev_done.any():
            envs = np.flatnonzero(self._prev_done)
            self._episode[envs] += 1
            self._start(envs)
            z2[envs] = self._z[envs]
            reward[envs] = 0.0
            terminated[envs] = False
            truncated[envs] = False
        self._z = z2
        ended = terminated | truncated
        self._prev_done = ended
        infos = self._infos(z2)
        if ended.any():
            infos["verdict"], infos["_verdict"] = self._verdict(z2, ended), ended
        return self._observe(z2), reward, terminated, truncated, infos

    def _check(self, actions: Any) -> np.ndarray:
        a = np.asarray(actions)
        if a.shape != (self.num_envs,):
            raise gym.error.InvalidAction(f"expected {self.num_envs} actions, got an array of shape {a.shape}")
        if a.dtype.kind in "iub":
            a = a.astype(np.int64, copy=False)
        elif a.dtype.kind == "f" and bool(np.all(np.isfinite(a) & (a == np.floor(a)))):
            a = a.astype(np.int64)
        else:
            raise gym.error.InvalidAction(f"actions must be integers, not {a.dtype} values")
        if a.size and (int(a.min()) < 0 or int(a.max()) >= self.pool.n_actions):
            bad = int(np.flatnonzero((a < 0) | (a >= self.pool.n_actions))[0])
            raise gym.error.InvalidAction(f"env {bad}: action {int(a[bad])} is outside {self.single_action_space}")
        return a

    def _observe(self, z: np.ndarray) -> np.ndarray:
        obs: np.ndarray = np.take(self.pool.obs, self.pool.obs_row[z], axis=0)  # faster than fancy indexing
        return obs

    def _infos(self, z: np.ndarray) -> dict[str, Any]:
        """``system_state`` (an object array of the single env's values, gathered from one
        table: read them, do not change them in place) and ``action_mask``."""
        return {
            "system_state": self.pool.system_state[z],
            "_system_state": self._all.copy(),
            "action_mask": np.take(self.pool.mask, z, axis=0),
            "_action_mask": self._all.copy(),
        }

    def _verdict(self, z: np.ndarray, ended: np.ndarray) -> dict[str, Any]:
        """The verdict arrays of the envs that ended (zeros/``None`` elsewhere, as a
        ``SyncVectorEnv`` lays out its infos)."""
        names = np.where(ended, self._outcome_names[self.pool.outcome[z]], None)
        zero = np.int64(0)
        return {
            "system_objective": names,
            "_system_objective": ended.copy(),
            "test_objective_realized": self.pool.test_realized[z] & ended,
            "_test_objective_realized": ended.copy(),
            "restrictions": np.where(ended, self._restrictions, zero),
            "_restrictions": ended.copy(),
            "blocked_attempts": np.where(ended, self._blocked, zero),
            "_blocked_attempts": ended.copy(),
            "steps": np.where(ended, self._steps, zero),
            "_steps": ended.copy(),
        }

    # ------------------------------------------------------------------ inspection

    @property
    def test_index(self) -> np.ndarray:
        """``int64[num_envs]``: the pool index of the test each env plays now."""
        return self._test.copy()

    def action_masks(self) -> np.ndarray:
        """``bool[num_envs, n_actions]``: the legal actions now (MaskablePPO's convention)."""
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before action_masks()")
        return self.pool.mask[self._z].astype(bool)

    def verdicts(self) -> dict[str, np.ndarray]:
        """The running verdict of every env (arrays over the batch)."""
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before verdicts()")
        z = self._z
        return {
            "system_objective": self._outcome_names[self.pool.outcome[z]],
            "test_objective_realized": self.pool.test_realized[z].copy(),
            "restrictions": self._restrictions.copy(),
            "blocked_attempts": self._blocked.copy(),
            "steps": self._steps.copy(),
        }

    def run_state(self, i: int) -> RunState:
        """The :class:`~flowtest_env.game.RunState` of env ``i`` now (for pictures)."""
        t, local = self.pool.locate(int(self._z[i]))
        return self.pool.tests[t].run_state(
            local, int(self._steps[i]), int(self._restrictions[i]), int(self._blocked[i])
        )

    def render(self) -> tuple[np.ndarray, ...] | None:
        """``rgb_array``: one picture per env (drawn one by one; not for the hot loop)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to make_vec()")
            return None
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before render()")
        frames = []
        for i in range(self.num_envs):
            t = int(self._test[i])
            r = self._renderers.get(t)
            if r is None:
                r = self._renderers[t] = make_renderer(self.games[t], self.tile_size, self.view)
            frames.append(r.frame(self.run_state(i)))
        return tuple(frames)


class FlowTestVectorEnv(PoolVectorEnv):
    """The vector entry point of ``FlowTest-v0`` and ``FlowTest-<Name>-v0``: ``num_envs``
    runs of one test (``test``: anything :func:`flowtest_env.sources.load_test` takes;
    ``problem`` is its older name); the arguments are those of
    :class:`~flowtest_env.envs.FlowTestEnv`."""

    def __init__(
        self,
        num_envs: int = 1,
        test: Any = "maze2",
        setting: str | None = None,
        max_steps: int | None = None,
        obs_kind: str = "flat",
        problem: Any = None,
        **kwargs: Any,
    ) -> None:
        if problem is not None:
            test = problem
        game = game_for(test, setting)
        steps = max_steps if max_steps is not None else default_max_steps(game)
        super().__init__(num_envs, [game], max_steps=steps, obs_kind=obs_kind, **kwargs)
        self.problem = game.artifact.name


class RandomGridVectorEnv(PoolVectorEnv):
    """The vector entry point of ``FlowTest-RandomGrid-v0``: the arguments of
    :class:`~flowtest_env.envs.RandomGridEnv`; each episode draws its test from the
    pool exactly as the single env does."""

    def __init__(
        self,
        num_envs: int = 1,
        size: int = 5,
        family: str = "reachability",
        n: int | None = None,
        seeds: Sequence[int] = tuple(range(8)),
        kind: str = "reactive",
        setting: str | None = None,
        max_steps: int | None = None,
        obs_kind: str = "flat",
        pool: str | None = None,
        split: str = "train",
        count: int = 8,
        world: str = "empty",
        **kwargs: Any,
    ) -> None:
        size, family, n, seeds, kind, world = random_grid_arguments(pool, split, count, size, family, n, tuple(seeds), kind, world)
        if kind not in POOL_KINDS:
            raise ValueError(f"unknown kind {kind!r}; expected one of {', '.join(map(repr, POOL_KINDS))}")
        if world not in WORLDS:
            raise ValueError(f"unknown world {world!r}; expected one of {', '.join(map(repr, WORLDS))}")
        if not seeds:
            raise ValueError("the seed pool is empty")
        tests = random_pool(size, family, n, seeds, kind, world=world)
        games = [TestGame(a, setting) for a in tests]
        steps = max_steps if max_steps is not None else 4 * size * size
        super().__init__(num_envs, games, max_steps=steps, obs_kind=obs_kind, **kwargs)
        self.problem = f"random-{size}x{size}-{family}{n}" + ("" if world == "empty" else f"-{world}")


class VectorActionMaskObservation(gym.vector.VectorWrapper):
    """Put the batched legal-action mask into the observation, as
    :class:`~flowtest_env.wrappers.ActionMaskObservation` does for one env: a ``Dict``
    with ``"observation"`` (``[num_envs, ...]``) and ``"action_mask"``
    (``int8[num_envs, n_actions]``, taken from ``infos["action_mask"]``)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        if not isinstance(env.single_action_space, spaces.Discrete):
            raise TypeError(f"VectorActionMaskObservation needs a Discrete action space, not {env.single_action_space}")
        n = int(env.single_action_space.n)
        self.single_observation_space = spaces.Dict(
            {"observation": env.single_observation_space, "action_mask": spaces.Box(0, 1, shape=(n,), dtype=np.int8)}
        )
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        # gymnasium 1.4 types VectorEnv.reset's seed as int | None; its vector envs and ours take a list too
        obs, infos = self.env.reset(seed=seed, options=options)  # type: ignore[arg-type]
        return {"observation": obs, "action_mask": infos["action_mask"]}, infos

    def step(self, actions: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, reward, terminated, truncated, infos = self.env.step(actions)
        return {"observation": obs, "action_mask": infos["action_mask"]}, reward, terminated, truncated, infos


__all__ = ["PoolVectorEnv", "FlowTestVectorEnv", "RandomGridVectorEnv", "VectorActionMaskObservation"]
