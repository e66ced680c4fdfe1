"""What one batch step of a compiled pool reads, built once per vector env
(:class:`~flowtest_env.vector.PoolVectorEnv`, and the torch env's tables,
:mod:`flowtest_env.torch_vector`).

* :class:`StepTables` (:func:`step_tables`): the pool's tables fused by (configuration,
  action), so that each output of a step is one gather over the batch: next configuration,
  reward, end, the verdict's two counters in one word, the mask as 8-byte words, and the
  observation rows;
* :func:`distinct_rows`: the observation table without its repeated rows (most
  configurations of a pool differ in what the observation does not show);
* :func:`shaped_rewards`: potential-based reward shaping folded into the reward table;
* :func:`compact_rows`: the ``uint8`` table of ``obs_dtype="uint8"``;
* :func:`batch_bytes`, :func:`check_batch_memory`: the memory a batch needs, refused beyond
  what the machine has.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .compiled import CompiledPool
from .game import TestGame

COUNT_SHIFT = 32
"""Bits of :attr:`StepTables.counts` below the blocked-attempt count (the restrictions count's)."""


def split_counts(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The restrictions and the blocked attempts packed in ``counts`` (sums of
    :attr:`StepTables.counts`), as ``int64`` arrays."""
    return counts & ((1 << COUNT_SHIFT) - 1), counts >> COUNT_SHIFT


@dataclass(frozen=True)
class StepTables:
    """What one batch step of a pool reads, fused so that each output of the step is one
    gather by ``flat = z * n_actions + action`` (or by ``z``) over the whole batch
    (:class:`~flowtest_env.vector.PoolVectorEnv`; :func:`step_tables` builds them).

    Attributes
    ----------
    next_z
        ``intp[n_z * n_actions]``: the next configuration (:attr:`CompiledPool.next_z`,
        in the index type gathers take without a conversion).
    reward
        ``float64[n_z * n_actions]``: the step's reward (shaping included).
    ends
        ``bool[n_z * n_actions]``: the step ends the run (``terminated``): the outcome of
        the next configuration is met or violated.
    counts
        ``int64[n_z * n_actions]``: what the step adds to the verdict's counters, both in
        one word: ``restricted[z] + (refused[flat] << COUNT_SHIFT)`` (one gather and one
        add a step for the restrictions and the blocked attempts; exact while an episode
        has fewer than ``2**32`` steps).
    mask_words
        ``uint64[n_z, W]``: each configuration's ``int8`` legal-action mask padded with
        zeros to ``8 * W`` columns and viewed as 8-byte words (a gather of whole words
        is several times faster than one of 5-byte rows).
    obs
        The pool's distinct observation rows (:attr:`CompiledPool.obs` without the rows
        that repeat another: configurations that differ in a part the observation does not
        show, e.g. the history's test part, share one), so that the table a step gathers
        from is as small as it can be and stays in the cache (781 of 2,469 rows for 64 tests
        of ``reachability1/5x5-v2``).
    obs_row
        ``intp[n_z]``: the row of :attr:`obs` of each configuration, or ``None`` where it
        is the configuration itself, which spares a gather.
    """

    next_z: np.ndarray
    reward: np.ndarray
    ends: np.ndarray
    counts: np.ndarray
    mask_words: np.ndarray
    obs: np.ndarray
    obs_row: np.ndarray | None

    def mask(self, z: np.ndarray, n_actions: int) -> np.ndarray:
        """``int8[len(z), n_actions]``: the legal-action masks of configurations ``z``,
        fresh: the first ``n_actions`` columns of the gathered padded rows (a view with a
        row stride of ``8 * W`` bytes, contiguous when ``n_actions`` is a multiple of 8:
        making it contiguous would cost more than the gather)."""
        words = np.take(self.mask_words, z, axis=0) if self.mask_words.shape[1] > 1 else self.mask_words.ravel().take(z)
        rows: np.ndarray = words.view(np.int8).reshape(z.shape[0], -1)
        return rows if rows.shape[1] == n_actions else rows[:, :n_actions]

    def rows(self, z: np.ndarray) -> np.ndarray:
        """The observation rows of configurations ``z``."""
        return z if self.obs_row is None else self.obs_row.take(z)


def step_tables(pool: CompiledPool, reward: np.ndarray) -> StepTables:
    """The :class:`StepTables` of ``pool`` with the reward table ``reward``
    (``float64[n_z * n_actions]``, :meth:`CompiledPool.rewards`, shaped or not)."""
    here = np.repeat(np.arange(pool.n_z, dtype=np.intp), pool.n_actions)
    width = -(-pool.n_actions // 8) * 8
    mask = np.zeros((pool.n_z, width), dtype=np.int8)
    mask[:, : pool.n_actions] = pool.mask
    obs, row_of = distinct_rows(pool.obs)
    obs_row = row_of[pool.obs_row]
    identity = bool(np.array_equal(obs_row, np.arange(pool.n_z)))
    return StepTables(
        next_z=pool.next_z.astype(np.intp),
        reward=np.ascontiguousarray(reward, dtype=np.float64),
        ends=pool.outcome[pool.next_z] != 0,
        counts=pool.restricted[here].astype(np.int64) + (pool.refused.astype(np.int64) << COUNT_SHIFT),
        mask_words=mask.view(np.uint64),
        obs=obs,
        obs_row=None if identity else obs_row,
    )


def distinct_rows(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of ``table`` in the order they first occur, and for each row of
    ``table`` its row among them (``intp``): ``distinct[row_of] == table``. The table as it
    is when no row repeats. One pass keyed by each row's bytes (a dict: only the distinct
    rows are kept; three times as fast as sorting the rows)."""
    n = table.shape[0]
    flat = np.ascontiguousarray(table.reshape(n, -1))
    seen: dict[bytes, int] = {}
    first: list[int] = []
    row_of = np.empty(n, dtype=np.intp)
    for i, key in enumerate(map(bytes, flat)):
        j = seen.get(key)
        if j is None:
            j = seen[key] = len(first)
            first.append(i)
        row_of[i] = j
    return (table, row_of) if len(first) == n else (table[first], row_of)


def shaped_rewards(pool: CompiledPool, reward: np.ndarray, phi: np.ndarray, gamma: float) -> np.ndarray:
    """The reward table with potential-based shaping: ``r + (gamma * phi(z') - phi(z))`` for
    every (configuration ``z``, action), ``phi(z') = 0`` when ``z'`` ends the run.

    The single env adds ``gamma * phi' - phi`` to the step's reward, ``phi`` the potential
    of the configuration it steps from (0 only after a terminated step, when it does not step
    again before a reset): a function of the configuration and the action, so it is a table
    too, summed in the single env's order (the same floats).
    """
    phi_end = np.where(pool.outcome != 0, 0.0, phi)
    here = np.repeat(np.arange(pool.n_z, dtype=np.int64), pool.n_actions)
    out: np.ndarray = reward + (float(gamma) * phi_end[pool.next_z] - phi_end[here])
    return out


def compact_rows(obs: np.ndarray, games: Sequence[TestGame]) -> np.ndarray:
    """The observation table ``obs`` as ``uint8`` (``obs_dtype="uint8"``): the same
    numbers where every entry is 0 or 1 (the ``grid`` kind's table, ``uint8`` already, as
    it is).

    Raises
    ------
    ValueError
        If an entry is neither 0 nor 1 (the fuel fraction of a test with fuel).
    """
    if obs.dtype == np.uint8:
        return obs
    if not bool(np.all((obs == 0) | (obs == 1))):
        fuel = [g.artifact.name for g in games if g.ts.kind == "fuel"][:3]
        raise ValueError(
            "obs_dtype='uint8' needs an observation of 0/1 entries; this pool's holds other values"
            + (f" (the fuel fraction of {', '.join(fuel)})" if fuel else "")
            + ": leave obs_dtype at its default"
        )
    out: np.ndarray = obs.astype(np.uint8)
    return out


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``, else the
    physical memory), ``None`` when the system does not say."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def batch_bytes(num_envs: int, pool: CompiledPool, memory_size: int = 0) -> int:
    """An estimate of the bytes a batch of ``num_envs`` runs of ``pool`` needs: the
    tables, and per env a step's observation (gathered, with the memory, returned), the
    memory, the masks and infos and the per-env counters."""
    obs_bytes = (int(np.prod(pool.obs_shape)) * pool.obs.itemsize) + 4 * memory_size
    per_env = 3 * obs_bytes + 4 * memory_size + 4 * pool.n_actions + 256
    names = ("next_z", "refused", "restricted", "outcome", "test_realized", "mask", "obs_row", "obs", "system_state")
    tables = sum(int(getattr(pool, f).nbytes) for f in names)
    fused = pool.next_z.size * 25 + pool.n_z * 8 * -(-pool.n_actions // 8)  # the fused tables (StepTables), rows aside
    return tables + fused + num_envs * per_env


def check_batch_memory(num_envs: int, pool: CompiledPool, memory_size: int = 0) -> None:
    """Refuse a batch that would need more memory than the machine has available.

    Raises
    ------
    ValueError
        Saying how much memory ``num_envs`` runs would need.
    """
    need = batch_bytes(num_envs, pool, memory_size)
    have = available_memory()
    if have is not None and need > have:
        per_env = (need - batch_bytes(0, pool, memory_size)) / num_envs
        raise ValueError(
            f"num_envs={num_envs} would need about {need / 2**30:.1f} GiB of memory ({per_env:.0f} bytes per env "
            f"for its observations and infos, plus the test tables); {have / 2**30:.1f} GiB are available. Use fewer envs."
        )
