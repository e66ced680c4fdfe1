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
test it plays: one gather per output over tables fused by (configuration, action)
(:class:`~flowtest_env.step_tables.StepTables`: next configuration, reward, end, the
verdict's counters), the observation one gather of precomputed rows, the mask one gather
of 8-byte words (so ``infos["action_mask"]`` is a view of rows padded to 8 bytes, not
contiguous unless the action count is a multiple of 8), the env's own state updated in
place. The trajectories are exactly those of a ``SyncVectorEnv`` of the single
env built with the same options and the same autoreset mode (observations, rewards,
terminated, truncated and infos: ``system_state``, ``action_mask``, and ``verdict`` with
its fields at the end of an episode).

**Options.** Every option of the single env (:class:`~flowtest_env.config.EnvConfig`,
checked by the same validator): ``max_steps``, ``obs_kind``, ``pad_to``, the reward
weights, ``memory="visited"`` or ``"counts"`` (the places each env's SUT has occupied, or how often, one bulk array
update a step), ``shaping``/``shaping_gamma`` (the potential compiled into a
per-configuration table), ``render_mode="rgb_array"``, ``view``, ``tile_size``;
``setting`` (the accumulative setting's restrictions of the states visited under the history
kept per env as the single env keeps them).

**Autoreset modes** (``autoreset_mode=``, a :class:`gymnasium.vector.AutoresetMode` or its
name, also through ``gym.make_vec(..., autoreset_mode=...)``), as Gymnasium's
``SyncVectorEnv`` has them:

* ``NEXT_STEP`` (default): the step after an episode ended resets that env (its action
  is ignored; reward 0, not terminated, not truncated, the reset's infos);
* ``SAME_STEP``: an env whose episode ends is reset in the same step; the observation is
  the new episode's, the ended one's is in ``infos["final_obs"]`` (an object array,
  ``None`` for the envs that did not end) and its infos (``verdict`` included) in
  ``infos["final_info"]``;
* ``DISABLED``: nothing is reset by ``step``; reset the envs that ended with
  ``reset(options={"reset_mask": mask})`` (stepping one first raises ``ResetNeeded``).

A ``reset(options={"reset_mask": mask})`` resets only the envs of ``mask`` in every mode
(their infos only; the others keep their runs and observations).

A batch may hold different tests of one pool: :class:`RandomGridVectorEnv` draws each
episode's test as :class:`~flowtest_env.envs.RandomGridEnv` does (the counter-based
draws of :mod:`flowtest_env.draws`, env ``i`` keyed ``seed + i`` like ``SyncVectorEnv``), and
:class:`PoolVectorEnv` takes any list of tests, drawn the same way or fixed per env
(``assignment="fixed"``: env ``i`` always plays test ``i % n_tests``, so each test is
played by the same envs, e.g. to score every test once). Tests with fewer actions or
smaller observations than the pool's largest are padded: extra actions are invalid
(refused, never in the mask), extra observation entries are zero.

:class:`VectorActionMaskObservation` puts the batched mask into the observation, as
:class:`~flowtest_env.wrappers.ActionMaskObservation` does for one env.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .bulk import gc_paused
from .compiled import OUTCOMES, CompiledPool, compile_pool, potentials
from .config import EnvConfig, config_from, with_option_signature
from .draws import draw_tests, key_of_seed
from .encoding import Encoder, ObservationLayout, Segment, make_encoder
from .envs import default_max_steps, random_grid_pool
from .game import RunState, TestGame
from .memory import first_memory, increment_of, remember_into
from .pools import random_grid_tests
from .render import Renderer, make_renderer
from .sources import game_for
from .step_tables import COUNT_SHIFT, StepTables, batch_bytes, check_batch_memory, compact_rows, shaped_rewards, split_counts, step_tables
from .validation import one_of, positive_int
from .wrappers import DistancePotential, shared_position_slice


@with_option_signature()
class PoolVectorEnv(VectorEnv[np.ndarray, np.ndarray, np.ndarray]):
    """A batch of FlowTest runs over a pool of tests (see the module docstring).

    Parameters
    ----------
    num_envs
        Number of runs in the batch (bounded by the memory the batch would need).
    games
        The pool's tests: :class:`~flowtest_env.game.TestGame` objects or anything
        :func:`~flowtest_env.sources.load_test` takes (a built-in name, a problem or
        artifact file, a ``Problem``, ``SynthesizedTest`` or ``TestArtifact``, e.g. the
        list :func:`~flowtest_env.pools.load_pool` returns).
    assignment
        ``"random"``: each episode draws its test (:mod:`flowtest_env.draws`, as
        :class:`~flowtest_env.envs.RandomGridEnv`); ``"fixed"``: env ``i`` plays test
        ``i % len(games)`` in every episode.
    autoreset_mode
        ``NEXT_STEP`` (default), ``SAME_STEP`` or ``DISABLED`` (module docstring).
    obs_dtype
        ``None`` (default): the observation kind's own dtype (``float32`` for ``flat`` and
        ``padded``, ``uint8`` for ``grid``). ``"uint8"``: a ``flat`` or ``padded``
        observation as ``uint8`` ``0``/``1``, the same numbers in a quarter of the bytes
        (``Box(0, 1, uint8)``; the visited-places memory too), for a consumer that converts
        it itself (a trainer on a GPU copies a quarter to the device); a step of a large
        batch gathers and returns a quarter of the memory, about 3x the steps per second
        of ``float32`` at 16,384 envs (docs/benchmarks/environments.md). Only where every
        entry is 0 or 1: a test with fuel, whose observation holds the fuel fraction, is
        refused (``ValueError``). A vector-env option: the single env has ``float32``.
    copy
        ``True`` (default): every ``reset`` and ``step`` returns a fresh observation array.
        ``False``: the observation is gathered into one buffer of the env (``out=``) and
        that buffer is returned, overwritten by the next ``reset`` or ``step`` (as
        Gymnasium's ``copy=False`` and the torch env's): copy what you keep. It pays where
        a fresh array is too large for the allocator to reuse (above 32 MiB glibc maps new
        pages each time, e.g. 16,384 padded observations of a pool, 59 MB); below that a
        fresh array costs about the same.
    config, options
        The env options: an :class:`~flowtest_env.config.EnvConfig`, or its fields as
        keyword arguments (``max_steps``, ``obs_kind``, ``memory``, ``shaping``, ...;
        ``max_steps`` defaults to the largest default budget of the pool's tests).

    Example::

        >>> from flowtest_env.vector import PoolVectorEnv
        >>> envs = PoolVectorEnv(8, ["small-reactive", "maze1"], assignment="fixed")
        >>> obs, infos = envs.reset(seed=0)
        >>> obs.shape, infos["action_mask"].shape, envs.test_index.tolist()
        ((8, 426), (8, 5), [0, 1, 0, 1, 0, 1, 0, 1])
        >>> from flowtest_env.pools import load_pool
        >>> envs = PoolVectorEnv(64, load_pool("reachability1/5x5", count=4), memory="visited")  # doctest: +SKIP
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        games: Any,
        assignment: str = "random",
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        config: EnvConfig | None = None,
        obs_dtype: str | None = None,
        copy: bool = True,
        **options: Any,
    ) -> None:
        num_envs = positive_int("num_envs", num_envs)
        if not isinstance(copy, (bool, np.bool_)):
            raise ValueError(f"copy must be True or False, not {copy!r}")
        one_of("assignment", assignment, ("random", "fixed"))
        one_of("obs_dtype", obs_dtype, (None, "uint8"))
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
        config = config_from(type(self).__name__, config, options)
        if obs_dtype == "uint8" and config.memory not in ("none", "visited"):
            raise ValueError(
                f"obs_dtype='uint8' holds 0/1 entries only; memory={config.memory!r} counts in quarters: use memory='visited' or leave obs_dtype at its default"
            )
        one_of("render_mode", config.render_mode, (None, *self.metadata["render_modes"]))
        with gc_paused():  # many small objects that stay alive: collections would walk them again and again
            self.games: list[TestGame] = pool_games(games, config.setting)
        settings = {g.setting for g in self.games}
        if len(settings) > 1:
            raise ValueError("the pool mixes tests of the instantaneous and the accumulative setting; pass setting= to choose one")
        config = config.with_max_steps(max(default_max_steps(g) for g in self.games))
        assert config.max_steps is not None
        self.config = config
        with gc_paused():
            self.encoders: list[Encoder] = [make_encoder(g, config.obs_kind, config.pad_to) for g in self.games]
        self._mem: slice | None = shared_position_slice(self.encoders) if config.memory != "none" else None
        self._increment = increment_of(config.memory) if self._mem is not None else 1.0  # flowtest_env.memory
        accumulative = settings == {"accumulative"}
        self.pool: CompiledPool = compile_pool(self.games, self.encoders, accumulative)
        p = self.pool
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.num_envs = num_envs
        self.assignment = assignment
        self.max_steps = config.max_steps
        self.obs_kind = config.obs_kind
        self.render_mode = config.render_mode
        self.view = config.view
        self.tile_size = config.tile_size
        mem_size = 0 if self._mem is None else self._mem.stop - self._mem.start
        check_batch_memory(num_envs, p, mem_size)
        if self.max_steps >= 2**COUNT_SHIFT:
            raise ValueError(f"max_steps must be below 2**{COUNT_SHIFT} in the vector env (its verdict counters are 32-bit), not {self.max_steps}")
        reward = p.rewards(config.step_cost, config.restricted_penalty, config.goal_reward, config.violation_penalty)
        if config.shaping > 0:  # potential-based shaping folded into the reward table
            reward = shaped_rewards(p, reward, potentials(p, self.games, DistancePotential(config.shaping)), config.shaping_gamma)
        self._tables: StepTables = step_tables(p, reward)
        rows = compact_rows(self._tables.obs, self.games) if obs_dtype == "uint8" else self._tables.obs
        if self._mem is not None:
            shape = (int(np.prod(p.obs_shape)) + mem_size,)
            self.single_observation_space = spaces.Box(0, 1, shape=shape, dtype=rows.dtype)
        else:
            high = 255 if self.obs_kind == "grid" else 1
            self.single_observation_space = spaces.Box(0, high, shape=p.obs_shape, dtype=rows.dtype)
        self.single_action_space = spaces.Discrete(p.n_actions)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._outcome_names = np.array(OUTCOMES, dtype=object)
        self._state_index = np.concatenate([t.system for t in p.tests]).astype(np.int64)  # numeric_infos' system_state
        self._all = np.ones(self.num_envs, dtype=bool)
        self._z = np.zeros(self.num_envs, dtype=np.intp)
        self._flat = np.zeros(self.num_envs, dtype=np.intp)  # z * n_actions + action, written in place each step
        self._added = np.zeros(self.num_envs, dtype=np.int64)  # the step's counts, written in place
        self._test = np.zeros(self.num_envs, dtype=np.int64)
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self._counts = np.zeros(self.num_envs, dtype=np.int64)  # restrictions + (blocked attempts << COUNT_SHIFT)
        self._seen = np.zeros((self.num_envs, mem_size), dtype=rows.dtype) if self._mem is not None else None
        self._mem_at = int(np.prod(p.obs_shape))
        # accumulative setting: the shown-restriction entries of the states visited under the current history
        self._shown: np.ndarray | slice | None = shared_shown_entries(self.encoders) if accumulative else None
        self._history = np.concatenate([t.history for t in p.tests]).astype(np.int64)
        n_shown = 0 if self._shown is None else int(np.zeros(self._mem_at, dtype=np.int8)[self._shown].size)
        self._shown_now = np.zeros((num_envs, n_shown), dtype=rows.dtype)
        self._shown_h = np.zeros(num_envs, dtype=np.int64)
        # the observation rows, with room for the memory (filled per step) when there is one
        self._obs_table = rows if self._mem is None else np.concatenate([rows, np.zeros((rows.shape[0], mem_size), rows.dtype)], axis=1)
        self._buffer = None if copy else np.zeros((num_envs, *self._obs_table.shape[1:]), dtype=rows.dtype)  # copy=False: the one output
        self._done = np.zeros(self.num_envs, dtype=bool)  # episodes ended and not reset yet
        self._keys = np.zeros(self.num_envs, dtype=np.uint64)  # the test draws' keys (flowtest_env.draws)
        self._episode = np.zeros(self.num_envs, dtype=np.int64)  # each env's episodes since its key
        self._keyed = False
        self._started = False
        self._renderers: dict[int, Renderer] = {}
        self._chooser: Callable[[np.ndarray], np.ndarray] | None = None

    # ------------------------------------------------------------------ episodes

    def set_test_chooser(self, chooser: Callable[[np.ndarray], np.ndarray] | None) -> None:
        """Let ``chooser`` pick the test of every episode that starts from now on, in place of
        the env's own draw (``assignment``): ``chooser(envs)`` gets the indices of the envs
        whose episodes start (``int64[k]``) and returns one pool test index for each
        (``0 <= i < len(env.games)``); ``None`` gives the choice back to the env. This is how
        a curriculum or a level-replay trainer (``agents.native_ppo``'s ``plr``) chooses
        levels; ``env.test_index`` tells which test each env plays.

        Raises
        ------
        ValueError
            Later, at the reset or step that starts an episode, if the chooser returns
            anything but one valid test index per env.

        Examples
        --------
        >>> import numpy as np
        >>> from flowtest_env.vector import PoolVectorEnv
        >>> env = PoolVectorEnv(3, ["small-reactive", "maze1"])
        >>> env.set_test_chooser(lambda envs: np.ones(envs.size, dtype=np.int64))
        >>> _ = env.reset(seed=0)
        >>> env.test_index.tolist()
        [1, 1, 1]
        """
        self._chooser = chooser

    def _choose_tests(self, envs: np.ndarray) -> np.ndarray:
        """The tests of the current episodes of ``envs``: the chooser's
        (:meth:`set_test_chooser`), else by the keys and episode counters of ``envs``
        (:func:`flowtest_env.draws.draw_tests`)."""
        if self._chooser is not None:
            tests = np.asarray(self._chooser(envs))
            if tests.shape != envs.shape or tests.dtype.kind not in "iu" or (tests.size and (int(tests.min()) < 0 or int(tests.max()) >= len(self.games))):
                raise ValueError(
                    f"the test chooser must return one test index in [0, {len(self.games)}) for each of the {envs.size} envs starting an episode, not {tests!r}"
                )
            return tests.astype(np.int64)
        if len(self.games) == 1:  # what the draw gives (no key to mix)
            return np.zeros(envs.size, dtype=np.int64)
        if self.assignment == "fixed":
            return envs % len(self.games)
        return draw_tests(self._keys[envs], self._episode[envs], len(self.games))

    def _start(self, envs: np.ndarray) -> None:
        """Start the current episodes of ``envs`` (their counters already advanced)."""
        tests = self._choose_tests(envs)
        self._test[envs] = tests
        z = self.pool.initial[tests]
        self._z[envs] = z
        self._steps[envs] = 0
        self._counts[envs] = 0
        self._done[envs] = False

    def _observe(self, fresh: np.ndarray | None = None, moved: bool = True) -> np.ndarray:
        """The batch observation now (``fresh``: envs whose episode just started, their
        memory restarts; ``moved=False``: a masked reset, the other envs did not move and
        their memory stays)."""
        # one gather, faster than fancy indexing ("clip": in range by construction; "raise" would buffer an out= array)
        obs: np.ndarray = np.take(self._obs_table, self._tables.rows(self._z), axis=0, out=self._buffer, mode="clip")
        if self._shown is not None:
            self._accumulate(obs, None, fresh)
        if self._seen is None:
            return obs
        if fresh is not None:
            self._seen[fresh] = 0.0
        if moved:
            remember_into(self._seen, obs[:, self._mem], self._increment)
        else:
            self._seen[fresh] = first_memory(obs[fresh][:, self._mem], self._increment)
        obs[:, self._mem_at :] = self._seen
        return obs

    def _observe_envs(self, envs: np.ndarray) -> np.ndarray:
        """The observations of ``envs`` alone, their episodes just started."""
        obs: np.ndarray = np.take(self._obs_table, self._tables.rows(self._z[envs]), axis=0)
        if self._shown is not None:
            self._accumulate(obs, envs, np.arange(envs.size))
        if self._seen is None:
            return obs
        self._seen[envs] = first_memory(obs[:, self._mem], self._increment)
        obs[:, self._mem_at :] = self._seen[envs]
        return obs

    def _accumulate(self, obs: np.ndarray, envs: np.ndarray | None, fresh: np.ndarray | None) -> None:
        """Accumulative setting: add to ``obs`` (the rows of ``envs``) the restrictions
        shown on the states visited under the current history, as the single env's
        ``visited`` set does (restarted when the history changes or the episode starts;
        ``envs``: ``None`` for every env; ``fresh``: the rows whose episode just started)."""
        assert self._shown is not None
        flat = obs.reshape(obs.shape[0], -1)
        every = envs is None
        h = self._history[self._z if every else self._z[envs]]
        restart = h != (self._shown_h if every else self._shown_h[envs])
        if fresh is not None:
            restart[fresh] = True
        acc = self._shown_now if every else self._shown_now[envs]  # every env: updated in place
        acc[restart] = 0
        np.maximum(acc, flat[:, self._shown], out=acc)
        flat[:, self._shown] = acc
        if every:
            self._shown_h = h
        else:
            self._shown_now[envs] = acc
            self._shown_h[envs] = h

    # ------------------------------------------------------------------ API

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a run in every env, or in the envs of ``options["reset_mask"]`` (a
        ``bool[num_envs]`` array with at least one ``True``) only. ``seed``: an int seeds
        env ``i`` with ``seed + i`` (as ``SyncVectorEnv``), a list one seed per env
        (``None``: that env's next episode), ``None`` every env's next episode.

        Raises
        ------
        ValueError, TypeError
            On a seed that is not a non-negative integer, a list of the wrong length, or a
            reset mask that is not a ``bool[num_envs]`` array with a ``True``.
        """
        seeds = self._seeds(seed)
        super().reset(seed=seed if isinstance(seed, int) else None)
        mask = reset_mask_of((options or {}).get("reset_mask"), self.num_envs)
        envs = np.arange(self.num_envs) if mask is None else np.flatnonzero(mask)
        if not self._keyed:  # never seeded: keys drawn once, as each single env would
            self._keys[:] = self.np_random.integers(2**63, size=self.num_envs).astype(np.uint64)
            self._episode[:] = -1
            self._keyed = True
        given = np.array([seeds[i] is not None for i in envs.tolist()], dtype=bool)
        self._episode[envs[~given]] += 1
        if given.any():
            self._keys[envs[given]] = [key_of_seed(s) for s in (seeds[i] for i in envs[given].tolist()) if s is not None]
            self._episode[envs[given]] = 0
        self._start(envs)
        self._started = True
        obs = self._observe(envs, moved=mask is None)
        infos = self._infos(self._z, mask)
        return obs, infos

    def _seeds(self, seed: Any) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
            if seed < 0:
                raise ValueError(f"seed must be a non-negative integer, not {seed!r}")
            return [int(seed) + i for i in range(self.num_envs)]
        if isinstance(seed, (list, tuple)):
            if len(seed) != self.num_envs:
                raise ValueError(f"{len(seed)} seeds for {self.num_envs} envs")
            out: list[int | None] = []
            for s in seed:
                if s is not None and (isinstance(s, (bool, np.bool_)) or not isinstance(s, (int, np.integer)) or s < 0):
                    raise ValueError(f"a seed must be a non-negative integer or None, not {s!r}")
                out.append(None if s is None else int(s))
            return out
        raise ValueError(f"seed must be an integer, a list of one seed per env or None, not {seed!r}")

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Every env takes its action (how an env whose episode ended is reset depends on
        the autoreset mode: module docstring).

        Raises
        ------
        gymnasium.error.ResetNeeded
            Before ``reset()``, or in ``DISABLED`` mode for an env whose episode ended
            and that was not reset.
        gymnasium.error.InvalidAction
            If ``actions`` is not ``num_envs`` integer action indices (booleans and floats
            are refused, as the single env refuses them; a masked action is *not* an
            error: it is refused, as in the single env).
        """
        if not self._started:
            raise gym.error.ResetNeeded("call reset() before step()")
        mode = self.autoreset_mode
        if mode == AutoresetMode.DISABLED and self._done.any():
            ended = np.flatnonzero(self._done)[:8].tolist()
            raise gym.error.ResetNeeded(
                f"envs {ended} ended their episodes; with autoreset_mode DISABLED reset them first: reset(options={{'reset_mask': mask}})"
            )
        a = self._check(actions)
        tab, flat = self._tables, self._flat
        np.multiply(self._z, self.pool.n_actions, out=flat)
        flat += a
        # every gather below writes into a fresh output or a buffer of the env ("clip": the
        # indices are in range by construction, and take buffers an out= array in "raise" mode)
        tab.next_z.take(flat, out=self._z, mode="clip")
        reward = tab.reward.take(flat, mode="clip")
        terminated = tab.ends.take(flat, mode="clip")
        self._counts += tab.counts.take(flat, out=self._added, mode="clip")
        self._steps += 1
        truncated = np.greater_equal(self._steps, self.max_steps)
        np.greater(truncated, terminated, out=truncated)  # and not terminated
        fresh: np.ndarray | None = None
        if mode == AutoresetMode.NEXT_STEP and self._done.any():
            fresh = np.flatnonzero(self._done)
            self._episode[fresh] += 1
            self._start(fresh)
            reward[fresh] = 0.0
            terminated[fresh] = False
            truncated[fresh] = False
        ended = terminated | truncated
        obs = self._observe(fresh)
        if mode == AutoresetMode.SAME_STEP:
            if not ended.any():
                return obs, reward, terminated, truncated, self._infos(self._z)
            idx = np.flatnonzero(ended)
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in idx.tolist():  # Gymnasium's layout: an object array of single observations
                final_obs[i] = obs[i].copy()
            final_info = self._infos(self._z, ended)
            final_info["verdict"], final_info["_verdict"] = self._verdict(self._z, ended), ended.copy()
            self._episode[idx] += 1
            self._start(idx)
            obs[idx] = self._observe_envs(idx)
            infos = self._infos(self._z)
            infos["final_obs"], infos["_final_obs"] = final_obs, ended.copy()
            infos["final_info"], infos["_final_info"] = final_info, ended.copy()
            return obs, reward, terminated, truncated, infos
        self._done = ended
        infos = self._infos(self._z)
        if ended.any():
            infos["verdict"], infos["_verdict"] = self._verdict(self._z, ended), ended.copy()
        return obs, reward, terminated, truncated, infos

    def _check(self, actions: Any) -> np.ndarray:
        a = np.asarray(actions)
        if a.shape != (self.num_envs,):
            raise gym.error.InvalidAction(f"expected {self.num_envs} actions, got an array of shape {a.shape}")
        if a.dtype.kind not in "iu":
            raise gym.error.InvalidAction(f"actions must be integers of {self.single_action_space}, not {a.dtype} values (booleans and floats are refused)")
        # one pass: a negative action, seen as unsigned, is as out of range as a large one
        if a.size and int(a.view(a.dtype.str.replace("i", "u")).max()) >= self.pool.n_actions:
            bad = int(np.flatnonzero((a < 0) | (a >= self.pool.n_actions))[0])
            raise gym.error.InvalidAction(f"env {bad}: action {int(a[bad])} is outside {self.single_action_space}")
        return a if a.dtype.itemsize < 8 or a.dtype.kind == "i" else a.astype(np.intp)  # added to intp in place

    def _infos(self, z: np.ndarray, only: np.ndarray | None = None) -> dict[str, Any]:
        """``system_state`` (an object array of the single env's values, gathered from one
        table: read them, do not change them in place) and ``action_mask``; with ``only``,
        those of the envs of ``only`` (``None``/zeros elsewhere, as ``SyncVectorEnv`` lays
        out the infos of some envs)."""
        states = self._state_index if self.config.numeric_infos else self.pool.system_state
        mask = self._tables.mask(z, self.pool.n_actions)
        if only is None:
            return {
                "system_state": states.take(z),
                "_system_state": self._all.copy(),
                "action_mask": mask,
                "_action_mask": self._all.copy(),
            }
        mask[~only] = 0
        blank: Any = states.dtype.type(0) if self.config.numeric_infos else None
        return {
            "system_state": np.where(only, states.take(z), blank),
            "_system_state": only.copy(),
            "action_mask": mask,
            "_action_mask": only.copy(),
        }

    def _verdict(self, z: np.ndarray, ended: np.ndarray) -> dict[str, Any]:
        """The verdict arrays of the envs that ended (zeros/``None`` elsewhere, as a
        ``SyncVectorEnv`` lays out its infos)."""
        idx = np.flatnonzero(ended)  # usually few: the values are scattered into zeros
        zi, counts = z.take(idx), self._counts.take(idx)

        def scattered(values: np.ndarray, dtype: Any) -> np.ndarray:
            out = np.zeros(self.num_envs, dtype=dtype) if dtype is not object else np.empty(self.num_envs, dtype=object)  # None-filled
            out[idx] = values
            return out

        codes = self.pool.outcome.take(zi)
        restrictions, blocked = split_counts(counts)
        return {
            "system_objective": scattered(codes, np.int64) if self.config.numeric_infos else scattered(self._outcome_names.take(codes), object),
            "_system_objective": ended.copy(),
            "test_objective_realized": scattered(self.pool.test_realized.take(zi), bool),
            "_test_objective_realized": ended.copy(),
            "restrictions": scattered(restrictions, np.int64),
            "_restrictions": ended.copy(),
            "blocked_attempts": scattered(blocked, np.int64),
            "_blocked_attempts": ended.copy(),
            "steps": scattered(self._steps.take(idx), np.int64),
            "_steps": ended.copy(),
        }

    # ------------------------------------------------------------------ inspection

    def observation_layout(self, test: int | None = None) -> ObservationLayout:
        """Which entries of an env's observation are which (:func:`flowtest_env.observation_layout`):
        those of test ``test`` of the pool, or of every test when they all agree.

        Raises
        ------
        ValueError
            If ``test`` is ``None`` and the pool's tests lay out their observations
            differently (``obs_kind="padded"`` gives every grid test one layout).
        """
        layouts = [e.layout() for e in self.encoders] if test is None else [self.encoders[int(test)].layout()]
        if any(lay != layouts[0] for lay in layouts):
            raise ValueError("the pool's tests lay out their observations differently: pass test=i, or use obs_kind='padded'")
        lay = layouts[0]
        size = int(np.prod(self.pool.obs_shape))
        if lay.kind != "grid" and lay.shape[0] < size:  # a smaller test of the pool: zeros at the end
            pad = Segment("padding", lay.shape[0], size, (size - lay.shape[0],), "zeros: the pool's larger tests use them")
            lay = ObservationLayout(lay.kind, (size,), (*lay.segments, pad), lay.position, lay.grid)
        return lay if self._mem is None else lay.with_memory(self._mem.stop - self._mem.start, self.config.memory)

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
        restrictions, blocked = split_counts(self._counts)
        return {
            "system_objective": self._outcome_names[self.pool.outcome[z]],
            "test_objective_realized": self.pool.test_realized[z],
            "restrictions": restrictions,
            "blocked_attempts": blocked,
            "steps": self._steps.copy(),
        }

    def run_state(self, i: int) -> RunState:
        """The :class:`~flowtest_env.game.RunState` of env ``i`` now (for pictures)."""
        t, local = self.pool.locate(int(self._z[i]))
        restrictions, blocked = split_counts(self._counts[i : i + 1])
        return self.pool.tests[t].run_state(local, int(self._steps[i]), int(restrictions[0]), int(blocked[0]))

    def render(self) -> tuple[np.ndarray, ...] | None:
        """``rgb_array``: one picture per env (drawn one by one; not for the hot loop; in the
        accumulative setting the restrictions of the current state only)."""
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


@with_option_signature()
class FlowTestVectorEnv(PoolVectorEnv):
    """The vector entry point of ``FlowTest-v0`` and ``FlowTest-<Name>-v0``: ``num_envs``
    runs of one test (``test``: anything :func:`flowtest_env.sources.load_test` takes;
    ``problem`` is its older name); the options are those of
    :class:`~flowtest_env.envs.FlowTestEnv` (:class:`~flowtest_env.config.EnvConfig`),
    plus ``autoreset_mode``, ``obs_dtype`` and ``copy`` (:class:`PoolVectorEnv`).

    Example::

        >>> import gymnasium as gym
        >>> envs = gym.make_vec("FlowTest-Maze2-v0", num_envs=8, vectorization_mode="vector_entry_point",
        ...                     autoreset_mode="SAME_STEP", memory="visited", shaping=10.0)
        >>> envs.autoreset_mode.name
        'SAME_STEP'
        >>> gym.make_vec("FlowTest-Maze2-v0", num_envs=8, vectorization_mode="vector_entry_point", obs_dtype="uint8").single_observation_space
        Box(0, 1, (306,), uint8)
    """

    def __init__(
        self,
        num_envs: int = 1,
        test: Any = "maze2",
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        problem: Any = None,
        config: EnvConfig | None = None,
        obs_dtype: str | None = None,
        copy: bool = True,
        **options: Any,
    ) -> None:
        if problem is not None:
            test = problem
        config = config_from(type(self).__name__, config, options)
        positive_int("num_envs", num_envs)
        game = game_for(test, config.setting)
        super().__init__(num_envs, [game], autoreset_mode=autoreset_mode, config=config.with_max_steps(default_max_steps(game)), obs_dtype=obs_dtype, copy=copy)
        self.problem = game.artifact.name


@with_option_signature()
class RandomGridVectorEnv(PoolVectorEnv):
    """The vector entry point of ``FlowTest-RandomGrid-v0``: the arguments of
    :class:`~flowtest_env.envs.RandomGridEnv` (checked by the same functions), plus
    ``autoreset_mode``, ``obs_dtype`` and ``copy`` (:class:`PoolVectorEnv`); each episode draws its test from the pool exactly as the single
    env does."""

    def __init__(
        self,
        num_envs: int = 1,
        size: int = 5,
        family: str = "reachability",
        n: int | None = None,
        seeds: Sequence[int] = tuple(range(8)),
        kind: str = "reactive",
        pool: str | None = None,
        split: str = "train",
        count: int = 8,
        world: str = "empty",
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        config: EnvConfig | None = None,
        obs_dtype: str | None = None,
        copy: bool = True,
        **options: Any,
    ) -> None:
        config = config_from(type(self).__name__, config, options)
        positive_int("num_envs", num_envs)
        size, family, n, seeds, kind, world = random_grid_pool(size, family, n, seeds, kind, pool, split, count, world)
        tests = random_grid_tests(pool, split, count, size, family, n, seeds, kind, world)
        games = [TestGame(a, config.setting) for a in tests]
        super().__init__(num_envs, games, autoreset_mode=autoreset_mode, config=config.with_max_steps(4 * size * size), obs_dtype=obs_dtype, copy=copy)
        self.problem = f"random-{size}x{size}-{family}{n}" + ("" if world == "empty" else f"-{world}")


def autoreset_mode_of(mode: Any) -> AutoresetMode:
    """``mode`` as an :class:`~gymnasium.vector.AutoresetMode`: the enum, its value
    (``"NextStep"``) or its name (``"NEXT_STEP"``, any case).

    Raises
    ------
    ValueError
        On anything else.
    """
    if isinstance(mode, AutoresetMode):
        return mode
    if isinstance(mode, str):
        for m in AutoresetMode:
            if mode in (m.value, m.name) or mode.upper() == m.name:
                return m
    names = ", ".join(repr(m.name) for m in AutoresetMode)
    raise ValueError(f"unknown autoreset_mode {mode!r}; expected a gymnasium.vector.AutoresetMode or one of {names}")


def reset_mask_of(mask: Any, num_envs: int) -> np.ndarray | None:
    """The ``reset_mask`` option checked as ``SyncVectorEnv`` checks it (``None``: none)."""
    if mask is None:
        return None
    if not isinstance(mask, np.ndarray):
        raise TypeError(f"options['reset_mask'] must be a numpy array, got {type(mask).__name__}")
    if mask.shape != (num_envs,):
        raise ValueError(f"options['reset_mask'] must have shape ({num_envs},), got {mask.shape}")
    if mask.dtype != np.bool_:
        raise TypeError(f"options['reset_mask'] must have dtype bool, got {mask.dtype}")
    if not mask.any():
        raise ValueError("options['reset_mask'] must hold at least one True")
    return mask.copy()


def pool_games(games: Any, setting: str | None) -> list[TestGame]:
    """The games of a pool given as games or as anything :func:`~flowtest_env.sources.load_test`
    takes (one test, or a list of them).

    Raises
    ------
    ValueError
        On an empty pool.
    """
    if isinstance(games, (str, os.PathLike, TestGame)) or not isinstance(games, Iterable):
        games = [games]
    out = [g if isinstance(g, TestGame) else game_for(g, setting) for g in games]
    if not out:
        raise ValueError("the pool holds no test")
    return out


def shared_shown_entries(encoders: list[Encoder]) -> np.ndarray | slice:
    """The flat indices of the entries a shown restriction sets (the ``wall_*``/``door_*``
    planes, a graph's ``shown_restriction`` block), the same for every encoder of a pool
    (a slice when they are one block).

    Raises
    ------
    ValueError
        If the pool's tests put them at different entries (use ``obs_kind="padded"``).
    """
    found = set()
    for enc in encoders:
        lay = enc.layout()
        plane = int(np.prod(lay.grid)) if lay.kind == "grid" and lay.grid is not None else 1
        idx = [
            np.arange(seg.start * plane, seg.stop * plane) for seg in lay.segments if seg.name.startswith(("wall_", "door_")) or seg.name == "shown_restriction"
        ]
        found.add(tuple(np.concatenate(idx).tolist()) if idx else ())
    if len(found) != 1:
        raise ValueError("the accumulative setting needs the pool's tests to show restrictions at the same entries; these differ (use obs_kind='padded')")
    entries = np.array(found.pop(), dtype=np.int64)
    if entries.size and np.array_equal(entries, np.arange(entries[0], entries[0] + entries.size)):
        return slice(int(entries[0]), int(entries[0]) + entries.size)  # one block (the usual case): views, no copies
    return entries


class VectorActionMaskObservation(gym.vector.VectorWrapper):
    """Put the batched legal-action mask into the observation, as
    :class:`~flowtest_env.wrappers.ActionMaskObservation` does for one env: a ``Dict``
    with ``"observation"`` (``[num_envs, ...]``) and ``"action_mask"``
    (``int8[num_envs, n_actions]``, taken from ``infos["action_mask"]``), in every
    autoreset mode (``SAME_STEP``'s ``final_obs`` become such dicts too)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        if not isinstance(env.single_action_space, spaces.Discrete):
            raise TypeError(f"VectorActionMaskObservation needs a Discrete action space, not {env.single_action_space}")
        n = int(env.single_action_space.n)
        self.single_observation_space = spaces.Dict({"observation": env.single_observation_space, "action_mask": spaces.Box(0, 1, shape=(n,), dtype=np.int8)})
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)
        self._last: np.ndarray | None = None

    @property
    def autoreset_mode(self) -> AutoresetMode:
        """The wrapped env's autoreset mode (libraries such as TorchRL read the attribute)."""
        mode: AutoresetMode = self.env.autoreset_mode  # type: ignore[attr-defined]
        return mode

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        # gymnasium's annotations type VectorEnv.reset's seed as int | None; its vector envs and ours take a list too
        obs, infos = self.env.reset(seed=seed, options=options)  # type: ignore[arg-type]
        return {"observation": obs, "action_mask": self._mask(infos)}, infos

    def step(self, actions: Any) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, reward, terminated, truncated, infos = self.env.step(actions)
        if "final_obs" in infos:  # SAME_STEP: the ended episodes' last observations get their masks too
            final, masks = infos["final_obs"].copy(), infos["final_info"]["action_mask"]
            for i in np.flatnonzero(infos["_final_obs"]).tolist():
                final[i] = {"observation": final[i], "action_mask": masks[i]}
            infos = {**infos, "final_obs": final}
        return {"observation": obs, "action_mask": self._mask(infos)}, reward, terminated, truncated, infos

    def _mask(self, infos: dict[str, Any]) -> np.ndarray:
        """The batch's masks now: from the infos, and for the envs a masked reset left
        alone (absent from its infos) the masks they had."""
        mask: np.ndarray = infos["action_mask"]
        some = infos["_action_mask"]
        if not some.all() and self._last is not None:
            mask = np.where(some[:, None], mask, self._last)
        self._last = mask
        return mask


__all__ = [
    "PoolVectorEnv",
    "FlowTestVectorEnv",
    "RandomGridVectorEnv",
    "VectorActionMaskObservation",
    "autoreset_mode_of",
    "batch_bytes",
    "check_batch_memory",
]
