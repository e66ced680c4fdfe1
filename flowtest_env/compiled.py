"""Test games compiled to flat tables, for batched stepping (:mod:`flowtest_env.vector`).

A test run is, between two SUT decisions, in a *configuration* ``z = (s, h, a, m)``: the
system's state, the history, the test agent's state and its strategy memory (a single
agent state and memory without a test agent). Everything the single env computes at a
step is a function of the configuration and the action, so a test compiles once into:

* ``next_z[z, action]``: the configuration after the SUT's action and the test agent's
  answer (the rules of :class:`~flowtest_env.game.TestGame`, evaluated for every
  configuration at once with array operations);
* ``refused[z, action]``: the action was restricted or invalid (a blocked attempt);
* per configuration: the outcome (open, met, violated), whether the test objective is
  realized, whether a move out of the SUT's state is restricted (the ``restrictions``
  count), the legal-action mask and the observation row.

Only configurations reachable from the reset configuration are kept (breadth-first
over ``next_z``), and their observations are written once by the single env's own
encoder, so the batch observation of a step is a row gather. Several tests compile into
one :class:`CompiledPool`: their configurations are numbered one after the other and
padded to a common action count and observation shape, so one batch steps different
tests with the same array indexing.
"""

from __future__ import annotations

import mmap
import multiprocessing
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .bulk import can_fork, free_cores, gc_paused, helper_signals
from .encoding import Encoder
from .game import MET, OPEN, VIOLATED, RunState, TestGame

OUTCOMES: tuple[str, str, str] = (OPEN, MET, VIOLATED)
"""Outcome names by code: 0 open, 1 met, 2 violated."""


@dataclass(frozen=True)
class ConfigurationTables:
    """The tables a batch step reads, one row per configuration: what
    :class:`CompiledTest` (one test, local numbering) and :class:`CompiledPool` (a pool,
    global numbering) have in common; their fields are described on :class:`CompiledTest`."""

    next_z: np.ndarray
    refused: np.ndarray
    restricted: np.ndarray
    outcome: np.ndarray
    test_realized: np.ndarray
    mask: np.ndarray
    obs_row: np.ndarray
    obs: np.ndarray


@dataclass(frozen=True)
class CompiledTest(ConfigurationTables):
    """One test as tables over its reachable configurations (local numbering).

    Attributes
    ----------
    next_z
        ``int64[n_z, n_actions]``: the next configuration; a configuration that ended
        the run leads to itself.
    refused
        ``bool[n_z, n_actions]``: the action is restricted now or invalid (counted in
        ``blocked_attempts``, penalised); actions beyond the test's own are invalid.
    restricted
        ``bool[n_z]``: at least one existing move out of the SUT's state is restricted
        (walls, reactive restrictions, the test agent in the way).
    outcome
        ``int8[n_z]``: 0 open, 1 met, 2 violated (:data:`OUTCOMES`).
    test_realized
        ``bool[n_z]``: the history's test part accepts.
    mask
        ``int8[n_z, n_actions]``: the legal actions (all zeros once the run ended).
    obs_row
        ``int64[n_z]``: the configuration's row of :attr:`obs`.
    obs
        ``[n_rows, *obs_shape]``: the observations of the distinct ``(s, h, a)``.
    system, history, agent, memory
        ``int64[n_z]``: the configuration's parts (``agent``/``memory`` ``-1`` without a
        test agent).
    initial
        The reset configuration.
    """

    system: np.ndarray
    history: np.ndarray
    agent: np.ndarray
    memory: np.ndarray
    initial: int

    @property
    def n_z(self) -> int:
        """Number of reachable configurations."""
        return int(self.next_z.shape[0])

    def run_state(self, z: int, steps: int = 0, restrictions: int = 0, blocked_attempts: int = 0) -> RunState:
        """The :class:`RunState` of configuration ``z`` (for rendering and inspection)."""
        s = int(self.system[z])
        return RunState(
            system=s,
            history=int(self.history[z]),
            agent=int(self.agent[z]),
            memory=int(self.memory[z]),
            visited={s},
            steps=steps,
            restrictions=restrictions,
            blocked_attempts=blocked_attempts,
            outcome=OUTCOMES[int(self.outcome[z])],
        )


def _agent_bits(game: TestGame, n_agent: int) -> np.ndarray:
    """``int64[n_states, n_agent]``: slots of each SUT state leading into each test
    agent state's place (the moves the agent blocks by standing there)."""
    n = game.ts.n_states
    if not game.has_agent:
        return np.zeros((n, 1), dtype=np.int64)
    place = np.asarray(game.agent_place, dtype=np.int64)  # -1: a park
    into = (game.dst_place[:, None, :] == place[None, :, None]) & (place >= 0)[None, :, None]  # [s, a, slot]
    weights = np.int64(1) << np.arange(game.n_slots, dtype=np.int64)
    bits: np.ndarray = into.astype(np.int64) @ weights
    return bits


def _transitions(game: TestGame, n_actions: int) -> dict[str, np.ndarray]:
    """The rules of :meth:`TestGame.step` for every configuration and action at once.

    Returns the full (unreduced) tables indexed by ``z = ((s*nh + h)*na + a)*nm + m``.
    """
    n = game.ts.n_states
    nh = game.artifact.histories.n_states
    ctl = game.agent_controller
    na = max(game.n_agent_states, 1)
    nm = ctl.n_memory if ctl is not None else 1
    rbits = np.asarray(game.restricted_bits, dtype=np.int64)  # [h, s]
    exists = np.asarray(game.exists_bits, dtype=np.int64)  # [s]
    nxt_hist = np.asarray(game.next_history, dtype=np.int64)  # [h, s]
    sys_acc = np.asarray(game.sys_accepting, dtype=bool)  # [h]
    doomed = np.asarray(game.doomed, dtype=bool)  # [h, s]
    abits = _agent_bits(game, na)  # [s, a]
    stay = game.stay_action
    # successor per action column: the slot's move, itself for stay and beyond the slots
    succ = np.repeat(np.arange(n, dtype=np.int64)[:, None], n_actions, axis=1)
    succ[:, : game.n_slots] = game.successor
    S, H, A, M, X = np.meshgrid(
        np.arange(n),
        np.arange(nh),
        np.arange(na),
        np.arange(nm),
        np.arange(n_actions),
        indexing="ij",
        sparse=True,
    )
    r = rbits[H, S] | abits[S, A]  # [s, h, a, 1, 1]
    ex = exists[S]
    legal = ex & ~r
    bit = np.int64(1) << X
    is_stay = X == stay
    invalid = ((ex & bit) == 0) & ~((legal == 0) & is_stay)
    refused = ((r & bit) != 0) & ~invalid
    moves = ~is_stay & ~invalid & ~refused
    nxt = np.where(moves, succ[S, X], S)  # [s, h, a, m, x]
    h2 = nxt_hist[H, nxt]
    met = sys_acc[h2]
    done = met | doomed[h2, nxt]
    a2 = np.broadcast_to(A, nxt.shape)
    m2 = np.broadcast_to(M, nxt.shape)
    if ctl is not None:
        row = ctl.node_of[nxt * ctl.n_hist + h2].astype(np.int64)
        ok = row >= 0
        rr = np.maximum(row, 0)
        Mb, Ab = np.broadcast_to(M, nxt.shape), np.broadcast_to(A, nxt.shape)
        cand = np.where(ok, ctl.next_agent[Mb, rr, Ab], -1).astype(np.int64)
        cmem = np.where(ok, ctl.next_memory[Mb, rr, Ab], -1).astype(np.int64)
        table = cand >= 0
        fb = ctl.fallback[Ab, ctl.sys_place[nxt]].astype(np.int64)
        a2 = np.where(done, Ab, np.where(table, cand, fb))
        m2 = np.where(done | ~table, Mb, cmem)
    next_z = ((nxt * nh + h2) * na + a2) * nm + m2
    # per configuration (the state after a step, or the reset state)
    Sz, Hz, Az = S[..., 0], H[..., 0], A[..., 0]
    met_z = np.broadcast_to(sys_acc[Hz], (n, nh, na, nm))
    viol_z = ~met_z & doomed[Hz, Sz]
    outcome = np.where(met_z, 1, np.where(viol_z, 2, 0)).astype(np.int8)
    rz = (rbits[Hz, Sz] | abits[Sz, Az]) & exists[Sz]
    legal_z = exists[Sz] & ~(rbits[Hz, Sz] | abits[Sz, Az])
    legal_z = np.where(legal_z == 0, np.int64(1) << stay, legal_z)
    cols = np.arange(n_actions, dtype=np.int64)
    mask = ((legal_z[..., None] >> cols) & 1).astype(np.int8)
    mask = np.where((outcome != 0)[..., None], np.int8(0), np.broadcast_to(mask, (n, nh, na, nm, n_actions)))
    Z = n * nh * na * nm

    def full(x: np.ndarray) -> np.ndarray:
        """A per-configuration value, broadcast over the axes it does not depend on, flat."""
        return np.broadcast_to(x, (n, nh, na, nm)).reshape(Z)

    return {
        "next_z": next_z.reshape(Z, n_actions),
        "refused": (refused | invalid).reshape(Z, n_actions),
        "restricted": full(rz != 0),
        "outcome": full(outcome),
        "test_realized": full(np.asarray(game.test_accepting, dtype=bool)[Hz]),
        "mask": mask.reshape(Z, n_actions),
        "system": full(Sz).astype(np.int64),
        "history": full(Hz).astype(np.int64),
        "agent": full(Az).astype(np.int64) if ctl is not None else np.full(Z, -1, dtype=np.int64),
        "memory": full(M[..., 0]).astype(np.int64) if ctl is not None else np.full(Z, -1, dtype=np.int64),
        "dims": np.array([n, nh, na, nm], dtype=np.int64),
    }


def _reachable(next_z: np.ndarray, start: int) -> np.ndarray:
    """Sorted configurations reachable from ``start`` along ``next_z`` (breadth-first)."""
    return _reachable_from(next_z, np.array([start], dtype=np.int64))


def _reachable_from(next_z: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sorted configurations reachable from any of ``starts`` along ``next_z`` (breadth-first)."""
    seen = np.zeros(next_z.shape[0], dtype=bool)
    seen[starts] = True
    frontier = np.unique(starts)
    while frontier.size:
        succ = next_z[frontier].ravel()
        frontier = np.unique(succ[~seen[succ]])
        seen[frontier] = True
    return np.flatnonzero(seen)


def _check_setting(game: TestGame, accumulative: bool) -> None:
    if game.setting != "instantaneous" and not accumulative:
        raise ValueError(
            f"the vectorized env supports setting='instantaneous' only, not {game.setting!r} "
            "(the accumulative observation depends on the states visited under the history)"
        )


BATCH = 512
"""Tests without a test agent compiled together by :func:`compile_pool` (the array
operations of one batch run over all its configurations at once)."""


@dataclass(frozen=True)
class _Unencoded:
    """A compiled test without its observations yet: the fields of :class:`CompiledTest`
    but ``obs``, and the runs whose observations are its rows, in row order."""

    fields: dict[str, Any]
    rows: list[RunState]


def _batch_tables(games: list[TestGame], n_actions: int) -> list[_Unencoded]:
    """:func:`compile_test` of several games without a test agent at once, but for the
    observations: the rules of :func:`_transitions` as array operations over
    configurations of every game, numbered one game after the other (a configuration is
    ``(s, h)``, ``z = s * n_hist + h`` within its game), a breadth-first search from every
    game's reset configuration that applies them to each layer only (most configurations
    are never reached), then the tables of the configurations reached, cut out game by
    game. The same tables as :func:`compile_test`, game by game; without a test agent
    every configuration is its own observation row."""
    k_games = len(games)
    n = np.array([g.ts.n_states for g in games], dtype=np.int64)
    nh = np.array([g.artifact.histories.n_states for g in games], dtype=np.int64)
    size = n * nh
    zoff = np.concatenate([[0], np.cumsum(size)[:-1]]).astype(np.int64)  # first configuration (and [h, s] entry) of a game
    soff = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64)  # first state of a game
    hoff = np.concatenate([[0], np.cumsum(nh)[:-1]]).astype(np.int64)  # first history of a game
    total = int(size.sum())
    rbits_hs = np.concatenate([g.restricted_array.ravel() for g in games])
    exists_s = np.concatenate([g.exists_array for g in games])
    nxt_hist = np.concatenate([np.asarray(g.next_history_array, dtype=np.int64).ravel() for g in games])
    doomed = np.concatenate([g.doomed_array.ravel() for g in games])
    sys_acc = np.concatenate([g.artifact.histories.accepting[:, 0] for g in games]).astype(bool)
    test_acc = np.concatenate([g.artifact.histories.accepting[:, 1] for g in games]).astype(bool)
    succ = np.empty((int(n.sum()), n_actions), dtype=np.int64)  # per action column: the slot's move, itself beyond
    for g, o in zip(games, soff.tolist(), strict=True):
        succ[o : o + g.ts.n_states, : g.n_slots] = g.successor
        succ[o : o + g.ts.n_states, g.n_slots :] = np.arange(g.ts.n_states, dtype=np.int64)[:, None]
    stay_g = np.array([g.stay_action for g in games], dtype=np.int64)
    X = np.arange(n_actions, dtype=np.int64)[None, :]
    bit = np.int64(1) << X

    def rules(z: np.ndarray) -> dict[str, np.ndarray]:
        """The rules of TestGame.step (no test agent) at configurations ``z`` (global),
        for every action; ``next_z`` global, an ended run staying where it is."""
        gi = np.searchsorted(zoff, z, side="right") - 1
        local = z - zoff[gi]
        nh_z, n_z = nh[gi], n[gi]
        S, H = local // nh_z, local % nh_z
        at_hs = zoff[gi] + H * n_z + S  # entry [h, s] of the game's tables
        at_s = soff[gi] + S
        at_h = hoff[gi] + H
        rb, ex = rbits_hs[at_hs], exists_s[at_s]
        r, e = rb[:, None], ex[:, None]
        legal = e & ~r
        stay = stay_g[gi][:, None]
        is_stay = X == stay
        invalid = ((e & bit) == 0) & ~((legal == 0) & is_stay)
        refused = ((r & bit) != 0) & ~invalid
        moves = ~is_stay & ~invalid & ~refused
        nxt = np.where(moves, succ[at_s[:, None], X], S[:, None])
        h2 = nxt_hist[(zoff[gi] + H * n_z)[:, None] + nxt]
        next_z = zoff[gi][:, None] + nxt * nh_z[:, None] + h2
        met = sys_acc[at_h]
        outcome = np.where(met, 1, np.where(~met & doomed[at_hs], 2, 0)).astype(np.int8)
        ended = outcome != 0
        next_z[ended] = z[ended][:, None]
        legal_z = np.where(legal[:, 0] == 0, np.int64(1) << stay[:, 0], legal[:, 0])
        mask = ((legal_z[:, None] >> X) & 1).astype(np.int8)
        mask[ended] = 0
        return {
            "next_z": next_z,
            "refused": refused | invalid,
            "restricted": (rb & ex) != 0,
            "outcome": outcome,
            "test_realized": test_acc[at_h],
            "mask": mask,
            "system": S,
            "history": H,
            "game": gi,
        }

    # the configurations reached from every game's reset configuration, layer by layer
    starts = np.empty(k_games, dtype=np.int64)
    for i, g in enumerate(games):  # TestGame.reset without a test agent
        starts[i] = zoff[i] + int(g.ts.initial) * nh[i] + g.artifact.initial_history()
    seen = np.zeros(total, dtype=bool)
    seen[starts] = True
    frontier = np.unique(starts)
    while frontier.size:
        succ_z = rules(frontier)["next_z"].ravel()
        frontier = np.unique(succ_z[~seen[succ_z]])
        seen[frontier] = True
    keep = np.flatnonzero(seen)
    t = rules(keep)
    kept_game = t["game"]
    counts = np.bincount(kept_game, minlength=k_games)
    koff = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    renum = np.full(total, -1, dtype=np.int64)
    renum[keep] = np.arange(keep.size, dtype=np.int64) - koff[kept_game]  # each game's own numbering
    k_next = renum[t["next_z"]]
    k_refused, k_restricted, k_outcome = t["refused"], t["restricted"], t["outcome"]
    k_test, k_mask, k_sys, k_hist = t["test_realized"], t["mask"], t["system"], t["history"]
    runs = [
        RunState(system=sv, history=hv, visited={sv}, outcome=OUTCOMES[ov])
        for sv, hv, ov in zip(k_sys.tolist(), k_hist.tolist(), k_outcome.tolist(), strict=True)
    ]
    out: list[_Unencoded] = []
    for i, (lo, c) in enumerate(zip(koff.tolist(), counts.tolist(), strict=True)):
        hi = lo + c
        fields = {
            "next_z": k_next[lo:hi],
            "refused": k_refused[lo:hi],
            "restricted": k_restricted[lo:hi],
            "outcome": k_outcome[lo:hi],
            "test_realized": k_test[lo:hi],
            "mask": k_mask[lo:hi],
            "obs_row": np.arange(c, dtype=np.int64),
            "system": k_sys[lo:hi],
            "history": k_hist[lo:hi],
            "agent": np.full(c, -1, dtype=np.int64),
            "memory": np.full(c, -1, dtype=np.int64),
            "initial": int(renum[starts[i]]),
        }
        out.append(_Unencoded(fields, runs[lo:hi]))
    return out


def compile_test(game: TestGame, encoder: Encoder, n_actions: int | None = None, accumulative: bool = False) -> CompiledTest:
    """Compile ``game`` (observations by ``encoder``) with ``n_actions`` action columns
    (default the game's own; more columns are invalid actions).

    In the accumulative setting the observation also shows the restrictions of the states
    visited under the current history, which no configuration holds: with
    ``accumulative=True`` the rows are those of the current state alone (the
    instantaneous view), and the caller adds the visited states' restrictions (as the
    vector env does, :class:`~flowtest_env.vector.PoolVectorEnv`).

    Raises
    ------
    ValueError
        On the accumulative setting without ``accumulative=True``, or fewer action
        columns than the game has.
    """
    _check_setting(game, accumulative)
    n_actions = game.n_actions if n_actions is None else int(n_actions)
    if n_actions < game.n_actions:
        raise ValueError(f"{n_actions} action columns for a test with {game.n_actions} actions")
    t = _transitions(game, n_actions)
    n, nh, na, nm = (int(v) for v in t["dims"])
    run0 = game.reset()
    a0 = max(run0.agent, 0)
    m0 = max(run0.memory, 0)
    z0 = ((run0.system * nh + run0.history) * na + a0) * nm + m0
    full_next = np.where((t["outcome"] != 0)[:, None], np.arange(t["next_z"].shape[0])[:, None], t["next_z"])
    keep = _reachable(full_next, z0)
    renum = np.full(full_next.shape[0], -1, dtype=np.int64)
    renum[keep] = np.arange(keep.size)
    # observations: one row per distinct (s, h, a), written by the single env's encoder
    sha = (t["system"][keep] * nh + t["history"][keep]) * na + np.maximum(t["agent"][keep], 0)
    keys, obs_row = np.unique(sha, return_inverse=True)
    first = np.zeros(keys.size, dtype=np.int64)
    first[obs_row[::-1]] = np.arange(keep.size)[::-1]  # one configuration per key
    rows = []
    for z in keep[first]:
        run = RunState(
            system=int(t["system"][z]),
            history=int(t["history"][z]),
            agent=int(t["agent"][z]),
            memory=int(t["memory"][z]),
            visited={int(t["system"][z])},
            outcome=OUTCOMES[int(t["outcome"][z])],
        )
        rows.append(encoder.encode(run))
    return CompiledTest(
        next_z=renum[full_next[keep]],
        refused=np.ascontiguousarray(t["refused"][keep]),
        restricted=t["restricted"][keep].copy(),
        outcome=t["outcome"][keep].copy(),
        test_realized=t["test_realized"][keep].copy(),
        mask=np.ascontiguousarray(t["mask"][keep]),
        obs_row=obs_row.reshape(-1).astype(np.int64),
        obs=np.stack(rows),
        system=t["system"][keep].copy(),
        history=t["history"][keep].copy(),
        agent=t["agent"][keep].copy(),
        memory=t["memory"][keep].copy(),
        initial=int(renum[z0]),
    )


PARALLEL_FROM = 1000
"""Tests without a test agent from which :func:`compile_pool` writes observations in two
processes (where :func:`helpers` finds two cores)."""


def helpers(count: int) -> int:
    """Forked helpers (0 or 1) for work on ``count`` tests: one from
    :data:`PARALLEL_FROM` tests on, where this process may run on two cores or more and
    can fork safely: on Linux (macOS's system libraries are not safe to fork), where no
    other Python thread runs (a fork copies no thread, and a lock one of them held would
    stay held in the helper) and this process may have children (a multiprocessing
    pool's worker, one of a trainer's runs, is daemonic and may not)."""
    return 1 if count >= PARALLEL_FROM and can_fork() and free_cores() >= 2 else 0


def _obs_table(rows: int, shape: tuple[int, ...], dtype: np.dtype[Any], shared: bool) -> tuple[np.ndarray, bool]:
    """A zero table of observation rows, and whether it is shared: with ``shared``, in
    memory a forked helper writes to (an anonymous shared mapping) rather than this
    process's own, where the system gives one."""
    if shared:
        count = rows * int(np.prod(shape, dtype=np.int64))
        try:
            buf = mmap.mmap(-1, max(1, count * dtype.itemsize))  # MAP_SHARED | MAP_ANONYMOUS: zero-filled
        except OSError:
            pass
        else:
            return np.frombuffer(buf, dtype=dtype, count=count).reshape(rows, *shape), True
    return np.zeros((rows, *shape), dtype=dtype), False


def _write_rows(todo: list[tuple[Encoder, list[RunState], np.ndarray]]) -> None:
    """Row ``j >= 1`` of each ``(encoder, runs, rows)``: the encoder's observation of ``runs[j]``."""
    for encoder, runs, rows in todo:
        for j in range(1, len(runs)):
            rows[j] = encoder.encode(runs[j])


HELPER_SHARE = 0.6
"""The share of the observation rows :func:`compile_pool`'s helper writes (this process
also assembles the pool meanwhile)."""


class _RowWriter:
    """:func:`_write_rows` of ``todo``, the later :data:`HELPER_SHARE` of the rows in a
    forked helper when ``helper`` (the rows in memory shared with it): started on entry,
    this process's part written by :meth:`write_own`, the helper waited for on exit. A
    helper that cannot start or fails leaves its rows to this process; an exception
    (Ctrl-C) stops it."""

    def __init__(self, todo: list[tuple[Encoder, list[RunState], np.ndarray]], helper: bool) -> None:
        self.mine, self.theirs = todo, todo[len(todo) :]
        self.proc: Any = None
        if helper and len(todo) >= 2:
            sizes = np.cumsum([len(runs) for _, runs, _ in todo])
            cut = min(int(np.searchsorted(sizes, sizes[-1] * (1.0 - HELPER_SHARE))) + 1, len(todo))
            self.mine, self.theirs = todo[:cut], todo[cut:]

    def __enter__(self) -> _RowWriter:
        if self.theirs:
            proc = multiprocessing.get_context("fork").Process(target=_helper, args=(self.theirs,), daemon=True)
            try:
                proc.start()
            except OSError:  # out of processes or memory: this process writes them
                self.mine, self.theirs = self.mine + self.theirs, []
            else:
                self.proc = proc
        return self

    def write_own(self) -> None:
        """This process's rows."""
        _write_rows(self.mine)

    def __exit__(self, kind: object, error: object, trace: object) -> None:
        proc = self.proc
        if proc is None:
            return
        try:
            if kind is None:
                proc.join()
                if proc.exitcode != 0:  # interrupted or broken: this process writes its rows
                    _write_rows(self.theirs)
        finally:
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=1.0)
                if proc.is_alive():
                    proc.kill()
                    proc.join(timeout=1.0)


def _helper(todo: list[tuple[Encoder, list[RunState], np.ndarray]]) -> None:
    """A forked helper: its rows written into the shared table, then gone (no exit
    handler of the parent runs; Ctrl-C, sent to the whole process group, is left to the
    parent, which stops it: :func:`~flowtest_env.bulk.helper_signals`)."""
    helper_signals()
    code = 1
    try:
        _write_rows(todo)
        code = 0
    except BaseException:  # the parent writes these rows itself
        pass
    os._exit(code)


@dataclass(frozen=True)
class CompiledPool(ConfigurationTables):
    """Several compiled tests in one global numbering (see the module docstring).

    Attributes
    ----------
    tests
        The compiled tests, in pool order.
    offset
        ``int64[n_tests]``: the first global configuration of each test.
    initial
        ``int64[n_tests]``: each test's reset configuration (global).
    test_of
        ``int64[n_z]``: the test of each global configuration.
    next_z, refused, restricted, outcome, test_realized, mask, obs_row, obs
        As in :class:`CompiledTest`, global; ``next_z`` and ``refused`` flattened to
        ``[n_z * n_actions]`` (index ``z * n_actions + action``), observations padded
        to :attr:`obs_shape`.
    system_state
        ``object[n_z]``: the SUT's state as in ``info["system_state"]`` of the single env.
    """

    tests: tuple[CompiledTest, ...]
    n_actions: int
    obs_shape: tuple[int, ...]
    offset: np.ndarray
    initial: np.ndarray
    test_of: np.ndarray
    system_state: np.ndarray

    @property
    def n_z(self) -> int:
        """Number of configurations of the whole pool."""
        return int(self.outcome.shape[0])

    def rewards(self, step_cost: float, restricted_penalty: float, goal_reward: float, violation_penalty: float) -> np.ndarray:
        """``float64[n_z * n_actions]``: the single env's reward of each (configuration,
        action), summed in the single env's order so the floats are identical."""
        after = self.outcome[self.next_z]
        r = np.full(self.next_z.shape, -float(step_cost), dtype=np.float64)
        r = np.where(self.refused, r - float(restricted_penalty), r)
        return np.where(after == 1, r + float(goal_reward), np.where(after == 2, r - float(violation_penalty), r))

    def locate(self, z: int) -> tuple[int, int]:
        """``(test index, local configuration)`` of global configuration ``z``."""
        t = int(self.test_of[z])
        return t, int(z - self.offset[t])


def potentials(pool: CompiledPool, games: list[TestGame], potential: Callable[[TestGame, RunState], float]) -> np.ndarray:
    """``float64[n_z]``: ``potential(game, run)`` of every configuration of ``pool``.

    Reward shaping's potential (:class:`~flowtest_env.wrappers.DistancePotential`) reads
    the SUT's state and the history only, so it is a function of the configuration: it is
    evaluated once per distinct ``(state, history)`` of each test, by the single env's
    own function, and the vector env gathers it.
    """
    out = np.empty(pool.n_z, dtype=np.float64)
    for t, (ct, game) in enumerate(zip(pool.tests, games, strict=True)):
        nh = int(ct.history.max()) + 1
        key = ct.system * nh + ct.history
        uniq, inverse = np.unique(key, return_inverse=True)
        values = np.array(
            [potential(game, RunState(system=int(k // nh), history=int(k % nh), visited={int(k // nh)})) for k in uniq.tolist()],
            dtype=np.float64,
        )
        o = int(pool.offset[t])
        out[o : o + ct.n_z] = values[inverse.reshape(-1)]
    return out


def compile_pool(games: list[TestGame], encoders: list[Encoder], accumulative: bool = False) -> CompiledPool:
    """Compile every test of a pool into one numbering (action columns and observation
    axes padded to the largest; ``accumulative``: as for :func:`compile_test`).

    The tests without a test agent are compiled in batches of :data:`BATCH`; with
    :data:`PARALLEL_FROM` of them or more and two cores free (:func:`helpers`), a forked
    helper writes half of their observation rows (the single env's encoder, row by row:
    most of the time) straight into the pool's table while this process writes the other
    half. The tables are the same either way."""
    if not games or len(games) != len(encoders):
        raise ValueError("a pool needs at least one test and one encoder per test")
    with gc_paused():
        return _compile_pool(games, encoders, accumulative)


def _compile_pool(games: list[TestGame], encoders: list[Encoder], accumulative: bool) -> CompiledPool:
    n_actions = max(g.n_actions for g in games)
    for g in games:
        _check_setting(g, accumulative)
    done: dict[int, CompiledTest] = {}
    pending: dict[int, _Unencoded] = {}
    plain = [k for k, g in enumerate(games) if not g.has_agent]  # compiled in batches
    for lo in range(0, len(plain), BATCH):
        part = plain[lo : lo + BATCH]
        pending.update(zip(part, _batch_tables([games[k] for k in part], n_actions), strict=True))
    for k, g in enumerate(games):
        if g.has_agent:
            done[k] = compile_test(g, encoders[k], n_actions, accumulative)
    # each test's observation shape (the first row of a test not encoded yet)
    first = {k: encoders[k].encode(u.rows[0]) for k, u in pending.items()}
    shapes = [(done[k].obs if k in done else first[k][None]).shape[1:] for k in range(len(games))]
    ndim = {len(sh) for sh in shapes}
    if len(ndim) != 1:
        raise ValueError("the pool's tests have observations of different ranks (mix of 'grid' and 'flat'?)")
    obs_shape = tuple(int(max(sh[i] for sh in shapes)) for i in range(len(shapes[0])))
    dtypes = {(done[k].obs if k in done else first[k]).dtype for k in range(len(games))}
    if len(dtypes) != 1:
        raise ValueError(f"the pool's observations have different dtypes: {sorted(map(str, dtypes))}")
    row_sizes = np.array([done[k].obs.shape[0] if k in done else len(pending[k].rows) for k in range(len(games))], dtype=np.int64)
    row_offset = np.concatenate([[0], np.cumsum(row_sizes)[:-1]]).astype(np.int64)
    obs, shared = _obs_table(int(row_sizes.sum()), obs_shape, dtypes.pop(), shared=helpers(len(pending)) > 0)
    view = {k: obs[(slice(int(row_offset[k]), int(row_offset[k] + row_sizes[k])), *(slice(0, w) for w in shapes[k]))] for k in range(len(games))}
    for k, ct in done.items():
        view[k][...] = ct.obs
    for k, row in first.items():
        view[k][0] = row
    todo = [(encoders[k], pending[k].rows, view[k]) for k in sorted(pending)]
    with _RowWriter(todo, helper=shared) as writer:  # the helper's rows are written meanwhile
        writer.write_own()
        return _assemble(games, done, pending, view, n_actions, obs_shape, obs)


def _assemble(
    games: list[TestGame],
    done: dict[int, CompiledTest],
    pending: dict[int, _Unencoded],
    view: dict[int, np.ndarray],
    n_actions: int,
    obs_shape: tuple[int, ...],
    obs: np.ndarray,
) -> CompiledPool:
    """The pool of the compiled tests (``done``) and of those compiled but for their rows
    (``pending``, rows in ``view``, which may still be being written)."""
    tests = tuple(done[k] if k in done else CompiledTest(obs=view[k], **pending[k].fields) for k in range(len(games)))
    sizes = np.array([t.n_z for t in tests], dtype=np.int64)
    offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    row_sizes = np.array([t.obs.shape[0] for t in tests], dtype=np.int64)
    row_offset = np.concatenate([[0], np.cumsum(row_sizes)[:-1]]).astype(np.int64)
    states: list[Any] = []
    for g, t in zip(games, tests, strict=True):
        names: dict[int, Any] = {}  # name only the states the test reaches, each once
        for s in t.system.tolist():
            name = names.get(s)
            if name is None:
                name = names[s] = g.state_json(s)
            states.append(name)
    system_state = np.empty(len(states), dtype=object)
    system_state[:] = states
    return CompiledPool(
        tests=tests,
        n_actions=n_actions,
        obs_shape=obs_shape,
        offset=offset,
        initial=offset + np.array([t.initial for t in tests], dtype=np.int64),
        test_of=np.repeat(np.arange(len(tests), dtype=np.int64), sizes),
        next_z=np.concatenate([t.next_z + o for t, o in zip(tests, offset, strict=True)]).reshape(-1),
        refused=np.concatenate([t.refused for t in tests]).reshape(-1),
        restricted=np.concatenate([t.restricted for t in tests]),
        outcome=np.concatenate([t.outcome for t in tests]),
        test_realized=np.concatenate([t.test_realized for t in tests]),
        mask=np.concatenate([t.mask for t in tests]),
        obs_row=np.concatenate([t.obs_row + o for t, o in zip(tests, row_offset, strict=True)]),
        obs=obs,
        system_state=system_state,
    )
