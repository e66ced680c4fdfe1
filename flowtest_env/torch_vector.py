"""FlowTest's vector env on a torch device (CPU or GPU): the compiled test tables as tensors.

The NumPy vector env (:mod:`flowtest_env.vector`) steps a batch with a handful of gathers
over a pool's compiled tables (:mod:`flowtest_env.compiled`). This module holds the same
tables as torch tensors on any device and steps them with the same gathers, so a batch
of a million test runs steps on one GPU, and a trainer on that GPU never copies an
observation to the host. For the same seeds and actions it gives exactly the NumPy env's
trajectories: observations, rewards, terminated, truncated, masks, verdicts and the test
each episode plays (the counter-based draw of :mod:`flowtest_env.draws`, in int64).

Two ways to use it::

    import torch
    from flowtest_env.torch_vector import make_vec

    envs = make_vec("FlowTest-Maze2-v0", num_envs=4096, device="cuda", memory="visited")
    obs, infos = envs.reset(seed=0)                 # float32[4096, 331] on the GPU
    for _ in range(100):
        mask = infos["action_mask"]                 # bool[4096, 5] (all false after an episode's end)
        actions = torch.argmax(torch.rand(mask.shape, device=mask.device) * mask, dim=1)
        obs, rewards, terminated, truncated, infos = envs.step(actions)

:class:`TorchVectorEnv` is a Gymnasium-like vector env whose arrays are tensors on
``device``; the *functional step* below it (:func:`reset_state`, :func:`step`,
:func:`observe`) is a pure function of ``(tables, state, actions)`` a trainer fuses into
its own loop (no Python loop over envs, no host synchronisation)::

    from flowtest_env import torch_vector as tv

    tables = tv.tables_of(numpy_env, device="cuda")   # or tv.make_tables("FlowTest-Maze2-v0", ...)
    state = tv.reset_state(tables, num_envs=8192, seed=0)
    for t in range(T):
        obs = tv.observe(tables, state)                 # or tv.compact(...) + tv.expand(...)
        mask = tv.action_mask(tables, state)
        state, out = tv.step(tables, state, actions)    # out.reward, out.terminated, ...

**Compact observations.** The padded float observation (901 float32 on a 5x5 pool) is most
of the memory traffic. :func:`compact` gives instead ``int64[N, 1 + W]``: column 0 the row
of the observation table (:attr:`TorchTables.obs`), columns ``1..W`` the visited-places
memory packed 64 places to a word (``W = 0`` without memory); :func:`expand` turns it back
into the float observation on the device (a network's first layer can do that gather:
``tables.obs[rows]`` is an embedding lookup). ``TorchVectorEnv(..., compact=True)`` returns
this form from ``reset`` and ``step``.

**Autoreset.** ``autoreset_mode`` ``"next_step"`` (Gymnasium's default: the step after an
episode ended resets that env, its action ignored, reward 0), ``"same_step"`` (the env
resets within the step that ended it; the observation is the new episode's, the last one is
``infos["final_obs"]``, the verdict is in ``infos["final_info"]``) or ``"disabled"`` (the
caller resets ended envs with ``reset(options={"reset_mask": mask})``), as the NumPy env.
One difference, to stay free of host synchronisation: stepping an env that ended under
``"disabled"`` without resetting it is not refused (the NumPy env raises ``ResetNeeded``):
its run stays where it ended and it reports the end again.

**Infos.** Every step returns ``infos["action_mask"]`` (``bool[N, n_actions]``) and
``infos["verdict"]`` with ``infos["_verdict"]`` (``bool[N]``, the envs whose episode ended
this step): ``system_objective`` (``int8``: 0 open, 1 met, 2 violated,
:data:`~flowtest_env.compiled.OUTCOMES`; ``-1`` where no episode ended),
``test_objective_realized``, ``restrictions``, ``blocked_attempts`` and ``steps`` (0 where
no episode ended). Unlike the NumPy env the verdict is always there (knowing whether any
env ended would need a host synchronisation) and ``system_state`` is not (it is a Python
object: :meth:`TorchVectorEnv.system_states` gathers it on the host).

**Which env where.** On a GPU the torch env keeps the tables and the batch on the device. On
the CPU the NumPy env is the faster of the two (a torch operation costs several times a
NumPy one to launch, and a step is some thirty of them), so a trainer's ``"auto"`` takes
the NumPy env there: :func:`preferred_backend`.

torch is imported here only: ``import flowtest_env`` works without it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector.utils import batch_space

from .compiled import OUTCOMES, CompiledPool, potentials
from .draws import GOLDEN_I64, MAX_TESTS, MIX1_I64, MIX2_I64
from .encoding import make_encoder
from .game import TestGame
from .step_tables import available_memory, distinct_rows, shaped_rewards
from .torch_memory import BatchPlaceMemory, env_memory
from .validation import positive_int
from .wrappers import DistancePotential, shared_position_slice

AUTORESET_MODES: tuple[str, ...] = ("next_step", "same_step", "disabled")
"""The autoreset modes, as Gymnasium's ``AutoresetMode`` values."""

_GYM_MODES = {
    "next_step": gym.vector.AutoresetMode.NEXT_STEP,
    "same_step": gym.vector.AutoresetMode.SAME_STEP,
    "disabled": gym.vector.AutoresetMode.DISABLED,
}


def autoreset_name(mode: Any) -> str:
    """``"next_step"``, ``"same_step"`` or ``"disabled"`` of a Gymnasium ``AutoresetMode``,
    its value (``"NextStep"``) or one of those names.

    Raises
    ------
    ValueError
        For anything else.
    """
    for name, gym_mode in _GYM_MODES.items():
        if mode == gym_mode or mode == gym_mode.value or mode == name:
            return name
    raise ValueError(f"unknown autoreset mode {mode!r}; expected one of {', '.join(AUTORESET_MODES)} or a gymnasium AutoresetMode")


WORD = 64
"""Places per packed memory word."""

LARGE = 4 << 20
"""Bytes of a batch's observations from which the CPU env takes a fresh one from NumPy's
allocator (:meth:`TorchVectorEnv._out`)."""


# ---------------------------------------------------------------- the draw, in int64


def _srl(x: torch.Tensor, s: int) -> torch.Tensor:
    """Logical right shift of int64 words (arithmetic shift, then mask)."""
    return (x >> s) & ((1 << (64 - s)) - 1)


def mix64(x: torch.Tensor) -> torch.Tensor:
    """splitmix64's finalizer on int64 words holding 64-bit words (wrapping arithmetic),
    bit for bit :func:`flowtest_env.draws.mix64`."""
    x = (x ^ _srl(x, 30)) * MIX1_I64
    x = (x ^ _srl(x, 27)) * MIX2_I64
    return x ^ _srl(x, 31)


def draw_tests(keys: torch.Tensor, episodes: torch.Tensor, n_tests: int) -> torch.Tensor:
    """The test each episode plays (:mod:`flowtest_env.draws`): ``keys`` int64 (the key's
    bits), ``episodes`` int64 >= 0 -> int64 test indices in ``[0, n_tests)``.

    >>> import torch
    >>> from flowtest_env.draws import draw_test
    >>> int(draw_tests(torch.tensor([3]), torch.tensor([5]), 8)[0]) == draw_test(3, 5, 8)
    True
    """
    if not 1 <= n_tests <= MAX_TESTS:
        raise ValueError(f"a pool holds 1 to {MAX_TESTS} tests, not {n_tests}")
    h = mix64(mix64(keys) + (episodes + 1) * GOLDEN_I64)
    return (_srl(h, 32) * n_tests) >> 32


def _key_bits(seed: int) -> int:
    """A non-negative seed as the int64 with the bits of its 64-bit key (``seed % 2**64``)."""
    w = int(seed) & ((1 << 64) - 1)
    return w - (1 << 64) if w >= (1 << 63) else w


def _seed_keys(seed: int, n: int, device: torch.device) -> torch.Tensor:
    """``int64[n]``: the keys of envs ``0..n-1`` seeded ``seed + i``."""
    if seed + n <= 2**63:
        return seed + torch.arange(n, dtype=torch.int64, device=device)
    return torch.as_tensor([_key_bits(seed + i) for i in range(n)], dtype=torch.int64, device=device)


# ---------------------------------------------------------------- the tables


@dataclass(frozen=True)
class TorchTables:
    """A compiled pool's tables on a torch device, plus the step's constants.

    ``n_z`` configurations, ``A`` action columns (:class:`~flowtest_env.compiled.CompiledPool`).

    Attributes
    ----------
    next_z, reward, refused
        ``[n_z * A]`` by ``z * A + action``: the next configuration (int64), the reward of
        the step (``reward_dtype``; shaping included: the potential is a function of the
        configuration, so the shaped reward of a step is one of ``(z, action)`` too) and
        whether the action is a blocked attempt (bool).
    restricted, terminal, test_realized, outcome
        ``[n_z]``: a move out of the SUT's state is restricted (bool), the run has ended
        (bool), the test objective is realized (bool), the outcome code (int8).
    mask
        ``bool[n_z, A]``: the legal actions.
    obs_row, obs
        ``int64[n_z]``, ``[n_rows, *obs_shape]``: each configuration's observation row,
        the pool's distinct rows only (:func:`~flowtest_env.step_tables.distinct_rows`; with the
        memory, their last ``n_places`` entries are zero: a gather then writes the memory
        bits into them).
    visited_bits
        ``int64[n_z, W]``: the places the configuration's observation shows the SUT at,
        packed 64 to a word (``W = 0`` without the visited-places memory).
    initial, test_of
        ``int64[n_tests]`` the reset configurations; ``int64[n_z]`` the test of each
        configuration.
    n_tests, n_actions, max_steps, n_places
        The pool's tests, the action columns, the step budget, the places of the memory
        (0 without it).
    assignment
        ``"random"`` (each episode draws its test) or ``"fixed"`` (env ``i`` plays test
        ``i % n_tests``).
    """

    next_z: torch.Tensor
    reward: torch.Tensor
    refused: torch.Tensor
    restricted: torch.Tensor
    terminal: torch.Tensor
    test_realized: torch.Tensor
    outcome: torch.Tensor
    mask: torch.Tensor
    obs_row: torch.Tensor
    obs: torch.Tensor
    visited_bits: torch.Tensor
    initial: torch.Tensor
    test_of: torch.Tensor
    n_tests: int
    n_actions: int
    max_steps: int
    n_places: int
    assignment: str

    @property
    def device(self) -> torch.device:
        """Where the tables live."""
        return self.next_z.device

    @property
    def n_words(self) -> int:
        """``W``: int64 words of the packed visited-places memory."""
        return int(self.visited_bits.shape[1])

    @property
    def obs_shape(self) -> tuple[int, ...]:
        """The shape of one env's full observation (memory included)."""
        return tuple(int(v) for v in self.obs.shape[1:])

    def to(self, device: str | torch.device) -> TorchTables:
        """The same tables on ``device``."""
        moved = {f.name: getattr(self, f.name).to(device) for f in fields(self) if isinstance(getattr(self, f.name), torch.Tensor)}
        return replace(self, **moved)


def _visited_words(obs: np.ndarray, where: slice) -> tuple[np.ndarray, int]:
    """``int64[n_rows, W]`` the places each observation row shows (packed), and the count
    of places. The position entries must be 0 or 1 (a one-hot of the SUT's place)."""
    pos = np.asarray(obs[:, where])
    if pos.ndim != 2:
        raise ValueError("the visited-places memory needs a flat observation")
    if not np.all((pos == 0) | (pos == 1)):
        raise ValueError("the observation's position entries are not 0/1: no visited-places memory")
    n_places = int(pos.shape[1])
    w = max(1, math.ceil(n_places / WORD))
    padded = np.zeros((pos.shape[0], w * WORD), dtype=np.uint64)
    padded[:, :n_places] = pos.astype(np.uint64)
    shifts = np.arange(WORD, dtype=np.uint64)
    words = (padded.reshape(-1, w, WORD) << shifts).sum(axis=2, dtype=np.uint64)
    return words.view(np.int64), n_places


def build_tables(
    pool: CompiledPool,
    games: Sequence[TestGame],
    *,
    max_steps: int,
    step_cost: float = 0.01,
    restricted_penalty: float = 0.05,
    goal_reward: float = 1.0,
    violation_penalty: float = 1.0,
    memory_slice: slice | None = None,
    shaping: float = 0.0,
    shaping_gamma: float = 0.99,
    assignment: str = "random",
    device: str | torch.device = "cpu",
    reward_dtype: torch.dtype = torch.float32,
    obs_dtype: Any = None,
) -> TorchTables:
    """:class:`TorchTables` of a compiled pool (its ``games`` in pool order) with the
    options of :class:`~flowtest_env.envs.FlowTestEnv`: ``memory_slice`` where the flat
    observation holds the SUT's place (the visited-places memory; ``None``: no memory),
    ``shaping`` (0: off) and ``shaping_gamma``; rewards computed in float64 as the single
    env does, then cast to ``reward_dtype``; ``obs_dtype`` the observation table's dtype
    (``None``: the pool's; ``numpy.uint8`` for a NumPy env made with ``obs_dtype="uint8"``,
    whose 0/1 entries it keeps).

    Example::

        tables = build_tables(env.pool, env.games, max_steps=100, device="cuda")
    """
    if assignment not in ("random", "fixed"):
        raise ValueError(f"unknown assignment {assignment!r}; expected 'random' or 'fixed'")
    if int(max_steps) < 1:
        raise ValueError(f"max_steps must be at least 1, not {max_steps}")
    if shaping < 0:
        raise ValueError(f"shaping must be 0 (off) or a positive scale, not {shaping}")
    if len(games) != len(pool.tests):
        raise ValueError(f"{len(games)} games for a pool of {len(pool.tests)} tests")
    if len(pool.tests) > MAX_TESTS:
        raise ValueError(f"a pool holds at most {MAX_TESTS} tests")
    if any(g.setting != "instantaneous" for g in games):
        raise ValueError(
            "the torch env supports setting='instantaneous' only (the accumulative observation depends on the "
            "states visited under the history; the NumPy vector env has it)"
        )
    reward = pool.rewards(step_cost, restricted_penalty, goal_reward, violation_penalty)
    if shaping > 0:
        reward = shaped_rewards(pool, reward, potentials(pool, list(games), DistancePotential(shaping)), shaping_gamma)
    distinct, row_of = distinct_rows(pool.obs)  # the rows that differ: a smaller table to gather from
    obs_row = row_of[pool.obs_row]
    obs = distinct if obs_dtype is None else distinct.astype(obs_dtype, copy=False)
    if memory_slice is not None:
        row_bits, n_places = _visited_words(distinct, memory_slice)
        bits = row_bits[obs_row]
        obs = np.concatenate([obs, np.zeros((obs.shape[0], n_places), dtype=obs.dtype)], axis=1)
    else:
        bits, n_places = np.zeros((pool.n_z, 0), dtype=np.int64), 0
    dev = torch.device(device)

    def t(a: np.ndarray, dtype: torch.dtype) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(a)).to(device=dev, dtype=dtype)

    return TorchTables(
        next_z=t(pool.next_z, torch.int64),
        reward=t(reward, torch.float64).to(reward_dtype),
        refused=t(pool.refused, torch.bool),
        restricted=t(pool.restricted, torch.bool),
        terminal=t(pool.outcome != 0, torch.bool),
        test_realized=t(pool.test_realized, torch.bool),
        outcome=t(pool.outcome, torch.int8),
        mask=t(pool.mask != 0, torch.bool),
        obs_row=t(obs_row, torch.int64),
        obs=torch.as_tensor(np.ascontiguousarray(obs)).to(dev),
        visited_bits=t(bits, torch.int64),
        initial=t(pool.initial, torch.int64),
        test_of=t(pool.test_of, torch.int64),
        n_tests=len(pool.tests),
        n_actions=int(pool.n_actions),
        max_steps=int(max_steps),
        n_places=n_places,
        assignment=assignment,
    )


# ---------------------------------------------------------------- the functional step


class EnvState(NamedTuple):
    """The state of a batch of ``N`` runs (tensors on the tables' device).

    Attributes
    ----------
    z
        ``int64[N]``: each run's configuration.
    steps, restrictions, blocked
        ``int64[N]``: the running verdict's counters.
    key, episode
        ``int64[N]``: the draw's key (the env's seed) and episode counter.
    home
        ``int64[N]``: the env's index (the fixed assignment plays test ``home % n_tests``).
    done
        ``bool[N]``: the episode ended at the last step (``"next_step"``: reset at the next).
    visited
        ``int64[N, W]``: the places occupied this episode, packed.
    """

    z: torch.Tensor
    steps: torch.Tensor
    restrictions: torch.Tensor
    blocked: torch.Tensor
    key: torch.Tensor
    episode: torch.Tensor
    home: torch.Tensor
    done: torch.Tensor
    visited: torch.Tensor


class Verdict(NamedTuple):
    """The verdict of every env's episode as it stands after the step (read it where the
    episode ended, :attr:`StepOutput.ended`; :func:`masked_verdict` zeroes the others):
    outcome code (``int8``, :data:`~flowtest_env.compiled.OUTCOMES`), test objective
    realized, restrictions, blocked attempts and steps."""

    system_objective: torch.Tensor
    test_objective_realized: torch.Tensor
    restrictions: torch.Tensor
    blocked_attempts: torch.Tensor
    steps: torch.Tensor


class StepOutput(NamedTuple):
    """What one step gives back besides the new state.

    Attributes
    ----------
    reward, terminated, truncated
        As Gymnasium's (``reward`` in the tables' ``reward_dtype``).
    ended
        ``terminated | truncated``.
    verdict
        The verdict of each env's episode (meaningful where ``ended``).
    final_z, final_visited
        The configuration and memory the ended episodes stopped in (``"same_step"``:
        the final observation; equal to the state's elsewhere).
    """

    reward: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    ended: torch.Tensor
    verdict: Verdict
    final_z: torch.Tensor
    final_visited: torch.Tensor


def start_configurations(tables: TorchTables, key: torch.Tensor, episode: torch.Tensor, home: torch.Tensor) -> torch.Tensor:
    """``int64[N]``: the reset configuration of episode ``episode`` of each env."""
    if tables.n_tests == 1:
        return tables.initial[:1].expand(home.shape[0])
    if tables.assignment == "fixed":
        return tables.initial.index_select(0, home % tables.n_tests)
    return tables.initial.index_select(0, draw_tests(key, episode, tables.n_tests))


def reset_state(tables: TorchTables, num_envs: int, seed: int | Sequence[int] | torch.Tensor | None = None, episode: torch.Tensor | None = None) -> EnvState:
    """A fresh state of ``num_envs`` runs. ``seed``: an int gives env ``i`` the key
    ``seed + i`` (as ``SyncVectorEnv`` seeds its envs), a sequence or an int64 tensor one
    key per env, ``None`` fresh entropy. ``episode``: the episode counters (default 0)."""
    dev = tables.device
    n = int(num_envs)
    if n < 1:
        raise ValueError(f"num_envs must be at least 1, not {num_envs}")
    if seed is None:
        keys = torch.as_tensor(np.random.default_rng().integers(-(2**63), 2**63 - 1, size=n, dtype=np.int64), device=dev)
    elif isinstance(seed, torch.Tensor):
        keys = seed.to(device=dev, dtype=torch.int64)
    elif isinstance(seed, (int, np.integer)):
        if seed < 0:
            raise ValueError(f"a seed is a non-negative integer, not {seed}")
        keys = _seed_keys(int(seed), n, dev)
    else:
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"{len(seeds)} seeds for {n} envs")
        if any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0 for s in seeds):
            raise ValueError("seeds must be non-negative integers")
        keys = torch.as_tensor([_key_bits(int(s)) for s in seeds], dtype=torch.int64, device=dev)
    if keys.shape != (n,):
        raise ValueError(f"expected {n} keys, got a tensor of shape {tuple(keys.shape)}")
    ep = torch.zeros(n, dtype=torch.int64, device=dev) if episode is None else episode.to(device=dev, dtype=torch.int64)
    home = torch.arange(n, dtype=torch.int64, device=dev)
    z = start_configurations(tables, keys, ep, home).contiguous()
    zero = torch.zeros(n, dtype=torch.int64, device=dev)
    return EnvState(
        z=z,
        steps=zero,
        restrictions=zero.clone(),
        blocked=zero.clone(),
        key=keys,
        episode=ep,
        home=home,
        done=torch.zeros(n, dtype=torch.bool, device=dev),
        visited=tables.visited_bits.index_select(0, z),
    )


def restart(tables: TorchTables, state: EnvState, which: torch.Tensor, new_key: torch.Tensor | None = None, reseed: torch.Tensor | None = None) -> EnvState:
    """Start a new episode in the envs ``which`` (``bool[N]``) and keep the others. The
    episode counter of a restarted env goes one on, or back to 0 with its key from
    ``new_key`` where ``reseed`` (``bool[N]``, default ``which`` when ``new_key`` is given:
    a reset with a seed). No host synchronisation."""
    ep = state.episode + which  # bool promotes to int64
    key = state.key
    if new_key is not None:
        again = which if reseed is None else (reseed & which)
        key = torch.where(again, new_key, key)
        ep = torch.where(again, torch.zeros_like(ep), ep)
    z0 = start_configurations(tables, key, ep, state.home)
    z = torch.where(which, z0, state.z)
    return EnvState(
        z=z,
        steps=state.steps.masked_fill(which, 0),
        restrictions=state.restrictions.masked_fill(which, 0),
        blocked=state.blocked.masked_fill(which, 0),
        key=key,
        episode=ep,
        home=state.home,
        done=state.done & ~which,
        visited=torch.where(which[:, None], tables.visited_bits.index_select(0, z), state.visited),
    )


def step(tables: TorchTables, state: EnvState, actions: torch.Tensor, autoreset: str = "next_step") -> tuple[EnvState, StepOutput]:
    """One step of every run: a pure function of the tables, the state and the actions
    (``int64[N]`` in ``[0, n_actions)``, not checked here), batched gathers only.

    ``autoreset``: ``"next_step"`` (an env whose episode ended at the last step starts a
    new one instead, its action ignored, reward 0), ``"same_step"`` (an episode that ends
    now is restarted in the returned state; :attr:`StepOutput.final_z` keeps where it
    ended) or ``"disabled"`` (ended envs stay ended; restart them with :func:`restart`).

    Example::

        state, out = step(tables, state, actions)
        obs = observe(tables, state)
    """
    a_n = tables.n_actions
    z = state.z
    flat = z * a_n + actions.to(torch.int64)
    z2 = tables.next_z.index_select(0, flat)
    reward = tables.reward.index_select(0, flat)
    steps = state.steps + 1
    restrictions = state.restrictions + tables.restricted.index_select(0, z)  # bool promotes to int64
    blocked = state.blocked + tables.refused.index_select(0, flat)
    terminated = tables.terminal.index_select(0, z2)
    truncated = ~terminated & (steps >= tables.max_steps)
    visited = state.visited | tables.visited_bits.index_select(0, z2)
    new = EnvState(z2, steps, restrictions, blocked, state.key, state.episode, state.home, state.done, visited)
    if autoreset == "next_step":
        pending = state.done
        new = restart(tables, new, pending)
        reward = reward.masked_fill(pending, 0)
        terminated = terminated & ~pending
        truncated = truncated & ~pending
    elif autoreset not in ("same_step", "disabled"):
        raise ValueError(f"unknown autoreset mode {autoreset!r}; expected one of {', '.join(AUTORESET_MODES)}")
    ended = terminated | truncated
    verdict = Verdict(
        system_objective=tables.outcome.index_select(0, new.z),
        test_objective_realized=tables.test_realized.index_select(0, new.z),
        restrictions=new.restrictions,
        blocked_attempts=new.blocked,
        steps=new.steps,
    )
    final_z, final_visited = new.z, new.visited
    if autoreset == "same_step":
        new = restart(tables, new, ended)
    else:
        new = new._replace(done=ended)
    return new, StepOutput(reward, terminated, truncated, ended, verdict, final_z, final_visited)


def action_mask(tables: TorchTables, state: EnvState) -> torch.Tensor:
    """``bool[N, n_actions]``: the legal actions of every run now (all false once ended)."""
    return tables.mask.index_select(0, state.z)


def _bits(tables: TorchTables, words: torch.Tensor) -> torch.Tensor:
    """``int64[N, n_places]`` 0/1 of packed memory words ``int64[N, W]`` (every word
    shifted by 0..63 at once: faster than picking each place's word)."""
    shifts = torch.arange(WORD, dtype=torch.int64, device=words.device)
    return (words[:, :, None] >> shifts).reshape(words.shape[0], -1)[:, : tables.n_places] & 1


def unpack_visited(tables: TorchTables, words: torch.Tensor, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """``[N, n_places]`` 0/1 of packed memory words ``int64[N, W]``."""
    return _bits(tables, words).to(dtype)


def _with_memory(tables: TorchTables, rows: torch.Tensor, words: torch.Tensor) -> torch.Tensor:
    """Gathered observation rows with the memory bits written into their last entries."""
    if tables.n_places:
        rows[:, rows.shape[1] - tables.n_places :] = _bits(tables, words)  # converted by the copy
    return rows


def _rows(tables: TorchTables, rows: torch.Tensor, out: torch.Tensor | None) -> torch.Tensor:
    """``tables.obs[rows]``, into ``out`` when given."""
    if out is None:
        return tables.obs.index_select(0, rows)
    return torch.index_select(tables.obs, 0, rows, out=out)


def observation_of(tables: TorchTables, z: torch.Tensor, visited: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """The full observations of configurations ``z`` with memory ``visited`` (into
    ``out``, ``[N, *obs_shape]`` of the table's dtype, when given: on the CPU a fresh
    tensor of a large batch costs more than the gather, its pages are new each step)."""
    return _with_memory(tables, _rows(tables, tables.obs_row.index_select(0, z), out), visited)


def observe(tables: TorchTables, state: EnvState, out: torch.Tensor | None = None) -> torch.Tensor:
    """The full observation of every run (``[N, *obs_shape]``, memory appended), as the
    NumPy env returns it (into ``out`` when given)."""
    return observation_of(tables, state.z, state.visited, out)


def compact_of(tables: TorchTables, z: torch.Tensor, visited: torch.Tensor) -> torch.Tensor:
    """``int64[N, 1 + W]``: observation row, then the packed memory words."""
    return torch.cat([tables.obs_row.index_select(0, z)[:, None], visited], dim=1)


def compact(tables: TorchTables, state: EnvState) -> torch.Tensor:
    """The compact observation of every run (module docstring): :func:`expand` of it is
    :func:`observe`."""
    return compact_of(tables, state.z, state.visited)


def expand(tables: TorchTables, compact_obs: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """The full observation of compact observations ``int64[N, 1 + W]`` (on the device;
    into ``out`` when given).

    Example::

        obs = expand(tables, compact(tables, state))   # == observe(tables, state)
    """
    return _with_memory(tables, _rows(tables, compact_obs[:, 0], out), compact_obs[:, 1:])


def masked_verdict(verdict: Verdict, ended: torch.Tensor) -> dict[str, torch.Tensor]:
    """The infos' ``verdict`` dict (the single env's keys): the values of the envs that
    ended, ``-1`` (outcome) or zero elsewhere."""
    zero = torch.zeros_like(verdict.steps)
    return {
        "system_objective": torch.where(ended, verdict.system_objective, torch.full_like(verdict.system_objective, -1)),
        "test_objective_realized": verdict.test_objective_realized & ended,
        "restrictions": torch.where(ended, verdict.restrictions, zero),
        "blocked_attempts": torch.where(ended, verdict.blocked_attempts, zero),
        "steps": torch.where(ended, verdict.steps, zero),
    }


# ---------------------------------------------------------------- the Gymnasium-like env


class TorchVectorEnv(gym.vector.VectorEnv):
    """A batch of FlowTest runs whose tables, state and outputs are tensors on ``device``.

    Build it from a NumPy vector env (:meth:`from_numpy`, the tables and options are that
    env's) or with :func:`make_vec`. ``reset(seed=...)`` and ``step(actions)`` as a
    Gymnasium vector env, with tensors (module docstring: infos, autoreset, compact
    observations).

    Parameters
    ----------
    tables
        The compiled pool on the device (:func:`build_tables`, :func:`tables_of`).
    num_envs
        Runs in the batch.
    autoreset_mode
        ``"next_step"``, ``"same_step"`` or ``"disabled"`` (or Gymnasium's ``AutoresetMode``).
        ``"same_step"`` gathers two observations a step (``infos["final_obs"]`` for every
        env, as knowing which ended would need a host synchronisation); a trainer that
        wants only the ended envs' final observations reads :attr:`StepOutput.final_z`
        through the functional step.
    compact
        Return compact observations (``int64[N, 1 + W]``, :func:`expand`).
    copy
        ``False``: write each step's observation into one buffer and return it (the last
        observation is overwritten at the next step, as Gymnasium's ``copy=False``); on
        the CPU a fresh large tensor each step costs more than the gather itself.
    check_actions
        Raise ``InvalidAction`` on an action outside the action space. It needs a host
        synchronisation per step, so by default only on the CPU device; unchecked, an
        out-of-range action is an indexing error.
    single_observation_space, single_action_space
        The spaces of one env (default: from the tables).
    memory
        A place memory the env appends to each observation besides the tables' own
        (``memory="counts"``: :class:`~flowtest_env.torch_memory.BatchPlaceMemory`;
        :meth:`from_numpy` sets it from the NumPy env's options).
    """

    def __init__(
        self,
        tables: TorchTables,
        num_envs: int,
        autoreset_mode: Any = "next_step",
        compact: bool = False,
        copy: bool = True,
        check_actions: bool | None = None,
        single_observation_space: spaces.Space[Any] | None = None,
        single_action_space: spaces.Space[Any] | None = None,
        memory: BatchPlaceMemory | None = None,
    ) -> None:
        mode = autoreset_name(autoreset_mode)
        if memory is not None and compact:
            raise ValueError(f"compact observations hold the packed visited memory only, not memory={memory.kind!r}")
        self.memory = memory
        self.num_envs = positive_int("num_envs", num_envs)  # 2.5 refused (not 2), as the NumPy env does
        per_env = 3 * math.prod(tables.obs_shape) * tables.obs.element_size() + 256  # the spaces' bounds, the buffer, the state
        have = available_memory()
        if have is not None and self.num_envs * per_env > have:
            raise ValueError(
                f"num_envs={self.num_envs} would need about {self.num_envs * per_env / 2**30:.1f} GiB of memory "
                f"({per_env} bytes per env); {have / 2**30:.1f} GiB are available. Use fewer envs."
            )
        self.tables = tables
        self.device = tables.device
        self.mode: str = mode
        self.autoreset_mode = _GYM_MODES[mode]
        self.metadata = {"autoreset_mode": self.autoreset_mode}
        self.compact = bool(compact)
        self.copy = bool(copy)
        self._buffer: torch.Tensor | None = None
        self.check_actions = (self.device.type == "cpu") if check_actions is None else bool(check_actions)
        if single_observation_space is None:
            dtype = tables.obs.dtype
            np_dtype = np.float32 if dtype == torch.float32 else np.uint8
            high = 1.0 if np_dtype == np.float32 else 255
            single_observation_space = spaces.Box(0, high, shape=tables.obs_shape, dtype=np_dtype)
        self.full_observation_space = single_observation_space
        if self.compact:
            high_c = np.iinfo(np.int64).max
            single_observation_space = spaces.Box(np.iinfo(np.int64).min, high_c, shape=(1 + tables.n_words,), dtype=np.int64)
        self.single_observation_space = single_observation_space
        self.single_action_space = single_action_space or spaces.Discrete(tables.n_actions)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.state: EnvState | None = None

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_numpy(
        cls, env: Any, num_envs: int | None = None, device: str | torch.device = "cpu", reward_dtype: torch.dtype = torch.float32, **kwargs: Any
    ) -> TorchVectorEnv:
        """The torch twin of a NumPy :class:`~flowtest_env.vector.PoolVectorEnv` (its
        pool, options and autoreset mode; ``num_envs`` default the same), on ``device``.

        Example::

            np_env = gym.make_vec("FlowTest-Maze2-v0", 8, vectorization_mode="vector_entry_point")
            envs = TorchVectorEnv.from_numpy(np_env, device="cpu")
        """
        env = getattr(env, "unwrapped", env)
        tables = tables_of(env, device=device, reward_dtype=reward_dtype)
        kwargs.setdefault("autoreset_mode", getattr(env, "autoreset_mode", "next_step"))
        kwargs.setdefault("memory", env_memory(env))
        n = env.num_envs if num_envs is None else num_envs
        return cls(tables, n, single_observation_space=env.single_observation_space, **kwargs)

    # ------------------------------------------------------------------ API

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None) -> tuple[torch.Tensor, dict[str, Any]]:
        """Start a run in every env (or, with ``options={"reset_mask": bool[N]}``, in the
        masked envs only), as the NumPy env: ``seed`` an int gives env ``i`` the key
        ``seed + i`` and episode 0, a list one seed per env (``None``: that env's episode
        counter goes one on), ``None`` every env's counter one on (keys from fresh entropy
        the first time)."""
        n = self.num_envs
        mask = None if options is None else options.get("reset_mask")
        which = torch.ones(n, dtype=torch.bool, device=self.device)
        if mask is not None:
            which = torch.as_tensor(mask, device=self.device)
            if which.dtype != torch.bool or tuple(which.shape) != (n,):
                raise ValueError(f"options['reset_mask'] must be bool[{n}], got {which.dtype}[{tuple(which.shape)}]")
        if self.state is None:  # never seeded: keys drawn once
            self.state = reset_state(self.tables, n, None, episode=torch.full((n,), -1, dtype=torch.int64))
            which = torch.ones(n, dtype=torch.bool, device=self.device)
        keys, given = self._keys(seed)
        self.state = restart(self.tables, self.state, which, keys, given)
        obs = self._remember(self._obs(self.state.z, self.state.visited, self._out()), which)
        return obs, {"action_mask": action_mask(self.tables, self.state)}

    def _keys(self, seed: int | Sequence[int | None] | None) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """The keys of a reset's seeds and which envs got one."""
        n = self.num_envs
        if seed is None:
            return None, None
        if isinstance(seed, (int, np.integer)):
            if seed < 0:
                raise ValueError(f"a seed is a non-negative integer, not {seed}")
            return _seed_keys(int(seed), n, self.device), torch.ones(n, dtype=torch.bool, device=self.device)
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"{len(seeds)} seeds for {n} envs")
        for s in seeds:
            if s is not None and (isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0):
                raise ValueError(f"a seed is a non-negative integer or None, not {s!r}")
        keys = torch.as_tensor([0 if s is None else _key_bits(int(s)) for s in seeds], dtype=torch.int64, device=self.device)
        given = torch.as_tensor([s is not None for s in seeds], dtype=torch.bool, device=self.device)
        return keys, given

    def step(self, actions: Any) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        """Every env takes its action (``int[N]``, a tensor or array); see the module
        docstring for the autoreset modes and infos.

        Raises
        ------
        gymnasium.error.ResetNeeded
            Before ``reset()``.
        gymnasium.error.InvalidAction
            If ``actions`` is not ``num_envs`` integers (and, with ``check_actions``, if
            one is outside the action space).
        """
        if self.state is None:
            raise gym.error.ResetNeeded("call reset() before step()")
        a = self._check(actions)
        self.state, out = step(self.tables, self.state, a, self.mode)
        infos: dict[str, Any] = {
            "action_mask": action_mask(self.tables, self.state),
            "verdict": masked_verdict(out.verdict, out.ended),
            "_verdict": out.ended,
        }
        if self.mode == "same_step":
            infos["final_obs"] = self._obs(out.final_z, out.final_visited)
            if self.memory is not None:
                infos["final_obs"] = self.memory.peek(infos["final_obs"])
            infos["_final_obs"] = out.ended
            infos["final_info"] = {
                "action_mask": self.tables.mask.index_select(0, out.final_z),
                "_action_mask": out.ended,
                "verdict": infos.pop("verdict"),
                "_verdict": infos.pop("_verdict"),
            }
            infos["_final_info"] = out.ended
        return self._remember(self._obs(self.state.z, self.state.visited, self._out())), out.reward, out.terminated, out.truncated, infos

    def _check(self, actions: Any) -> torch.Tensor:
        a = actions if isinstance(actions, torch.Tensor) else torch.as_tensor(np.asarray(actions))
        if tuple(a.shape) != (self.num_envs,):
            raise gym.error.InvalidAction(f"expected {self.num_envs} actions, got a tensor of shape {tuple(a.shape)}")
        if a.dtype.is_floating_point or a.dtype.is_complex or a.dtype == torch.bool:
            raise gym.error.InvalidAction(f"actions must be integers, not {a.dtype} values")
        a = a.to(device=self.device, dtype=torch.int64)
        if self.check_actions:
            bad = (a < 0) | (a >= self.tables.n_actions)
            if bool(bad.any()):
                i = int(torch.nonzero(bad)[0, 0])
                raise gym.error.InvalidAction(f"env {i}: action {int(a[i])} is outside {self.single_action_space}")
        return a

    def _out(self) -> torch.Tensor | None:
        """Where the step's observation is gathered to: the one buffer (``copy=False``); with
        ``copy``, for a batch of :data:`LARGE` bytes or more on the CPU, a fresh array of
        NumPy's allocator (torch's gives a large block back to the system when it is freed,
        so a fresh tensor of a large batch page-faults every step, slower than the gather
        itself: 1.6 ms against 0.9 ms for 16,384 Maze 2 observations); else ``None`` (a
        fresh tensor)."""
        if self.compact:
            return None
        if self.copy:
            rows = self.tables.obs
            if self.device.type != "cpu" or self.num_envs * rows[0].nbytes < LARGE:
                return None
            table = rows.numpy()  # a view: the tables are on the CPU
            return torch.from_numpy(np.empty((self.num_envs, *table.shape[1:]), dtype=table.dtype))
        if self._buffer is None:
            t = self.tables
            self._buffer = torch.empty((self.num_envs, *t.obs_shape), dtype=t.obs.dtype, device=self.device)
        return self._buffer

    def _obs(self, z: torch.Tensor, visited: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
        if self.compact:
            return compact_of(self.tables, z, visited)
        return observation_of(self.tables, z, visited, out)

    def _remember(self, obs: torch.Tensor, rows: torch.Tensor | None = None) -> torch.Tensor:
        """``obs`` with :attr:`memory` appended (episodes at step 0 restart it; ``rows``: only
        these envs moved, after a masked reset)."""
        return obs if self.memory is None else self.memory(obs, self._started().steps == 0, rows)

    def expand(self, compact_obs: torch.Tensor) -> torch.Tensor:
        """The full observations of this env's compact ones (:func:`expand`)."""
        return expand(self.tables, compact_obs)

    # ------------------------------------------------------------------ inspection

    def _started(self) -> EnvState:
        if self.state is None:
            raise gym.error.ResetNeeded("call reset() first")
        return self.state

    @property
    def test_index(self) -> torch.Tensor:
        """``int64[N]``: the pool index of the test each env plays now."""
        return self.tables.test_of.index_select(0, self._started().z)

    def action_masks(self) -> torch.Tensor:
        """``bool[N, n_actions]``: the legal actions now."""
        return action_mask(self.tables, self._started())

    def verdicts(self) -> dict[str, torch.Tensor]:
        """The running verdict of every env (tensors over the batch)."""
        s = self._started()
        return {
            "system_objective": self.tables.outcome.index_select(0, s.z),
            "test_objective_realized": self.tables.test_realized.index_select(0, s.z),
            "restrictions": s.restrictions.clone(),
            "blocked_attempts": s.blocked.clone(),
            "steps": s.steps.clone(),
        }

    def system_states(self, pool: CompiledPool) -> np.ndarray:
        """The single env's ``info["system_state"]`` of every env (gathered on the host
        from ``pool``, the pool the tables were built from)."""
        z = self._started().z.cpu().numpy()
        out: np.ndarray = pool.system_state[z]
        return out


def outcome_names(codes: torch.Tensor) -> np.ndarray:
    """Outcome codes as the NumPy env's names (``None`` for ``-1``), on the host."""
    names = np.array([*OUTCOMES, None], dtype=object)
    c = codes.cpu().numpy().astype(np.int64)
    out: np.ndarray = names[np.where(c < 0, len(OUTCOMES), c)]
    return out


# ---------------------------------------------------------------- from the NumPy env


def tables_of(env: Any, device: str | torch.device = "cpu", reward_dtype: torch.dtype = torch.float32) -> TorchTables:
    """:class:`TorchTables` of a NumPy :class:`~flowtest_env.vector.PoolVectorEnv`: its
    pool, step budget, reward weights, memory, shaping and assignment (its
    :class:`~flowtest_env.config.EnvConfig`) and its observation dtype."""
    env = getattr(env, "unwrapped", env)
    cfg = env.config
    where = None
    if cfg.memory == "visited":
        where = shared_position_slice([make_encoder(g, cfg.obs_kind, cfg.pad_to) for g in env.games])
    return build_tables(
        env.pool,
        env.games,
        max_steps=env.max_steps,
        step_cost=cfg.step_cost,
        restricted_penalty=cfg.restricted_penalty,
        goal_reward=cfg.goal_reward,
        violation_penalty=cfg.violation_penalty,
        memory_slice=where,
        shaping=cfg.shaping,
        shaping_gamma=cfg.shaping_gamma,
        assignment=env.assignment,
        device=device,
        reward_dtype=reward_dtype,
        obs_dtype=env.single_observation_space.dtype,
    )


def preferred_backend(device: str | torch.device) -> str:
    """The env a trainer on ``device`` steps when it is left to choose (``env_backend="auto"``):
    ``"numpy"`` (:mod:`flowtest_env.vector`) on the CPU, where it steps faster than this
    module's env at every batch size measured (128 to 16,384 envs: 1.4-3.9x,
    docs/benchmarks/environments.md) and gives the same runs; ``"torch"`` on any other
    device, where the tables and the batch stay on the device.

    >>> preferred_backend("cpu"), preferred_backend("cuda:0")
    ('numpy', 'torch')
    """
    return "numpy" if torch.device(device).type == "cpu" else "torch"


def make_vec(
    env_id: str,
    num_envs: int,
    device: str | torch.device = "cpu",
    *,
    autoreset_mode: Any = "next_step",
    compact: bool = False,
    copy: bool = True,
    check_actions: bool | None = None,
    reward_dtype: torch.dtype = torch.float32,
    **options: Any,
) -> TorchVectorEnv:
    """A :class:`TorchVectorEnv` of a registered FlowTest ID with the NumPy vector env's
    ``options`` (``memory``, ``shaping``, ``max_steps``, ``pool``...), on ``device``; on a
    GPU, e.g. ``make_vec("FlowTest-RandomGrid-v0", 65536, device="cuda", pool="reachability1/5x5", obs_kind="padded")``.

    Examples
    --------
    >>> import torch
    >>> from flowtest_env.torch_vector import make_vec
    >>> envs = make_vec("FlowTest-SmallReactive-v0", 16, device="cpu")
    >>> obs, infos = envs.reset(seed=0)
    >>> obs.shape, infos["action_mask"].shape
    (torch.Size([16, 78]), torch.Size([16, 5]))
    >>> actions = infos["action_mask"].float().multinomial(1, generator=torch.Generator().manual_seed(0)).squeeze(1)
    >>> obs, rewards, terminated, truncated, infos = envs.step(actions)
    >>> rewards.shape, terminated.dtype
    (torch.Size([16]), torch.bool)
    """
    np_env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", **options)
    return TorchVectorEnv.from_numpy(
        np_env,
        num_envs=num_envs,
        device=device,
        reward_dtype=reward_dtype,
        autoreset_mode=autoreset_mode,
        compact=compact,
        copy=copy,
        check_actions=check_actions,
    )


def make_tables(env_id: str, device: str | torch.device = "cpu", reward_dtype: torch.dtype = torch.float32, **options: Any) -> TorchTables:
    """The :class:`TorchTables` of a registered FlowTest ID with ``options`` (for the
    functional step)."""
    np_env = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", **options)
    return tables_of(np_env, device=device, reward_dtype=reward_dtype)


__all__ = [
    "AUTORESET_MODES",
    "EnvState",
    "StepOutput",
    "TorchTables",
    "TorchVectorEnv",
    "Verdict",
    "action_mask",
    "autoreset_name",
    "build_tables",
    "compact",
    "compact_of",
    "draw_tests",
    "expand",
    "make_tables",
    "make_vec",
    "mix64",
    "observation_of",
    "observe",
    "outcome_names",
    "preferred_backend",
    "reset_state",
    "restart",
    "step",
    "tables_of",
    "masked_verdict",
    "unpack_visited",
]
