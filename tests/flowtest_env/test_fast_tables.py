"""The test game's tables and the compiled tables, built with array operations, are the ones
the per-state reference construction gives, bit for bit (the same dtypes, shapes and values).

The reference below is the construction the fast one replaced: plain Python loops over
states and moves (action slots, the into-place bitmasks), the layered searches of the
permanent walls and of the doomed table, and :func:`compile_test` test by test with its
observations written by the encoder. The sample covers every built-in test (grids, fuel
grids, graphs, static walls, reactive doors, test agents) and tests of every shipped
standard pool, in every observation kind and setting the vector env compiles.
"""

from __future__ import annotations

import mmap
from typing import Any

import numpy as np
import pytest

import flowtest_env.compiled as compiled
import flowtest_env.step_tables as step_tables
from flowtest_env.artifacts import builtin_game
from flowtest_env.compiled import OUTCOMES, CompiledPool, CompiledTest, compile_pool, compile_test
from flowtest_env.encoding import Encoder, make_encoder
from flowtest_env.game import GRID_ACTIONS, RunState, TestGame
from flowtest_env.sources import builtin_names
from flowtest_env.standard_pools import STANDARD_POOLS, load_standard_pool
from synthesis.artifacts.artifact import TestArtifact

PER_POOL = 4


def _sample() -> list[TestArtifact]:
    arts = [builtin_game(name, None, False).artifact for name in builtin_names()]
    for pool in STANDARD_POOLS.values():
        for split in ("test", "validation"):
            if pool.shipped(split) >= PER_POOL:
                arts += load_standard_pool(pool.id, split, PER_POOL, start=7 % pool.shipped(split) // 2, progress=False)
                break
    return arts


SAMPLE = _sample()
IDS = [a.name for a in SAMPLE]


# ------------------------------------------------------------------ the reference


def reference_tables(game: TestGame) -> dict[str, Any]:
    """The game's tables as the per-state loops built them."""
    art, ts = game.artifact, game.ts
    n, n_moves = ts.n_states, ts.n_moves
    out: list[list[int]] = [[] for _ in range(n)]
    for m in range(n_moves):
        out[int(ts.src[m])].append(m)
    if game.is_grid:
        n_slots = len(GRID_ACTIONS)
        slots = [[-1] * n_slots for _ in range(n)]
        for s in range(n):
            for m in out[s]:
                slots[s][GRID_ACTIONS.index(ts.action[m])] = m
    else:
        n_slots = max(1, max((len(o) for o in out), default=1))
        slots = [o + [-1] * (n_slots - len(o)) for o in out]
    slot_move = np.asarray(slots, dtype=np.int64).reshape(n, n_slots)
    exists = slot_move >= 0
    successor = np.where(exists, ts.dst[np.maximum(slot_move, 0)], np.arange(n)[:, None]).astype(np.int64)
    dst_place = np.where(exists, ts.place[successor], -2).astype(np.int64)
    strat = art.strategy
    pad = np.concatenate([game.enforced, np.zeros((game.enforced.shape[0], 1), dtype=bool)], axis=1)
    weights = 1 << np.arange(n_slots + 1, dtype=np.int64)
    restricted_bits = (pad[:, slot_move].astype(np.int64) @ weights[:n_slots]).tolist()
    exists_bits = ((exists.astype(np.int64) @ weights[:n_slots]) + np.where(ts.stay, 1 << n_slots, 0)).tolist()
    static_bits = (np.concatenate([strat.static_obstacles, [False]])[slot_move].astype(np.int64) @ weights[:n_slots]).tolist()
    choosable = np.concatenate([ts.restrictable & ~strat.static_obstacles, [False]])
    choosable_bits = (choosable[slot_move].astype(np.int64) @ weights[:n_slots]).tolist()
    into_bits: list[dict[int, int]] = []
    for s in range(n):
        d: dict[int, int] = {}
        for k in range(n_slots):
            p = int(dst_place[s, k])
            if p >= 0:
                d[p] = d.get(p, 0) | (1 << k)
        into_bits.append(d)
    table = ((np.arange(1 << (n_slots + 1))[:, None] >> np.arange(n_slots + 1)[None, :]) & 1).astype(np.int8)
    letter = ts.letter_of_state(art.letters)
    walls = np.broadcast_to(strat.static_obstacles[None, :], strat.blocked.shape)
    doomed = ~reference_coreachable(art, walls if game.external_tester else game.enforced, letter)
    return {
        "n_slots": n_slots,
        "n_actions": n_slots + 1,
        "stay_action": n_slots,
        "slot_move": slot_move,
        "successor": successor,
        "dst_place": dst_place,
        "permanent_wall": reference_permanent_walls(art),
        "restricted_bits": restricted_bits,
        "exists_bits": exists_bits,
        "static_bits": static_bits,
        "choosable_bits": choosable_bits,
        "into_bits": into_bits,
        "_mask_table": table,
        "next_history": art.histories.delta[:, letter].tolist(),
        "doomed": doomed.tolist(),
        "succ_list": successor.tolist(),
        "slot_list": slot_move.tolist(),
        "place_list": ts.place.tolist(),
    }


def reference_coreachable(art: TestArtifact, enforced: np.ndarray, letter: np.ndarray) -> np.ndarray:
    ts, dba = art.system, art.histories
    nh, n = dba.n_states, ts.n_states
    nxt = dba.delta[:, letter]
    can = np.zeros((nh, n), dtype=bool)
    can[dba.accepting[:, 0], :] = True
    changed = True
    while changed:  # one edge at a time: (s, h) -> (dst, nxt[h, dst]) and the stays
        changed = False
        for h in range(nh):
            for m in range(ts.n_moves):
                if not enforced[h, m] and not can[h, ts.src[m]] and can[nxt[h, ts.dst[m]], ts.dst[m]]:
                    can[h, ts.src[m]] = changed = True
            for s in np.flatnonzero(ts.stay):
                if not can[h, s] and can[nxt[h, s], s]:
                    can[h, s] = changed = True
    return can


def reference_permanent_walls(art: TestArtifact) -> np.ndarray:
    ts, static = art.system, art.strategy.static_obstacles
    reach = {int(ts.initial)}
    todo = [int(ts.initial)]
    while todo:
        s = todo.pop()
        for m in np.flatnonzero((ts.src == s) & ~static):
            d = int(ts.dst[m])
            if d not in reach:
                reach.add(d)
                todo.append(d)
    open_pairs = {(int(ts.place[ts.src[m]]), int(ts.place[ts.dst[m]])) for m in range(ts.n_moves) if int(ts.src[m]) in reach and not static[m]}
    return np.array([bool(static[m]) and (int(ts.place[ts.src[m]]), int(ts.place[ts.dst[m]])) not in open_pairs for m in range(ts.n_moves)], dtype=bool)


def reference_compile(game: TestGame, encoder: Encoder, n_actions: int) -> CompiledTest:
    """:func:`compile_test` by walking the configurations one by one with the game's own
    rules (:meth:`TestGame.step` on a copy of each run)."""
    run0 = game.reset()
    start = (run0.system, run0.history, run0.agent, run0.memory)
    index = {start: 0}
    order = [start]
    runs = {start: run0}
    nxt: list[list[int]] = []
    refused: list[list[bool]] = []
    k = 0
    while k < len(order):
        key = order[k]
        run = runs[key]
        row, ref = [], []
        for action in range(n_actions):
            if run.done:
                row.append(index[key])
                ref.append(action >= game.n_actions or not (game.legal_bits(run) >> action) & 1)
                continue
            after = run.copy()
            after.visited = {after.system}
            before = after.blocked_attempts
            # an action beyond the test's own is invalid: the SUT stays, as with stay
            game.step(after, action if action < game.n_actions else game.stay_action)
            ref.append(action >= game.n_actions or after.blocked_attempts > before)
            k2 = (after.system, after.history, after.agent, after.memory)
            if k2 not in index:
                index[k2] = len(order)
                order.append(k2)
                runs[k2] = RunState(
                    system=after.system, history=after.history, agent=after.agent, memory=after.memory, visited={after.system}, outcome=after.outcome
                )
            row.append(index[k2])
        nxt.append(row)
        refused.append(ref)
        k += 1
    # the compiled tables number configurations in (s, h, a, m) order: renumber ours so
    nh = game.artifact.histories.n_states
    na = max(game.n_agent_states, 1)
    nm = game.agent_controller.n_memory if game.agent_controller is not None else 1
    flat = [((s * nh + h) * na + max(a, 0)) * nm + max(m, 0) for (s, h, a, m) in order]
    perm = np.argsort(flat)
    new_of_old = np.empty(len(order), dtype=np.int64)
    new_of_old[perm] = np.arange(len(order))
    sys_ = np.array([order[i][0] for i in perm], dtype=np.int64)
    hist = np.array([order[i][1] for i in perm], dtype=np.int64)
    agent = np.array([order[i][2] for i in perm], dtype=np.int64)
    memory = np.array([order[i][3] for i in perm], dtype=np.int64)
    rows = [runs[order[i]] for i in perm]
    sha = (sys_ * nh + hist) * na + np.maximum(agent, 0)
    keys, obs_row = np.unique(sha, return_inverse=True)
    first = [int(np.flatnonzero(obs_row == r)[0]) for r in range(keys.size)]
    obs = np.stack([encoder.encode(rows[i]) for i in first])
    outcome = np.array([OUTCOMES.index(r.outcome) for r in rows], dtype=np.int8)
    restricted = np.array([(game.restricted_bits_of(r) & game.exists_bits[r.system]) != 0 for r in rows], dtype=bool)
    mask = np.zeros((len(rows), n_actions), dtype=np.int8)
    for i, r in enumerate(rows):
        if not r.done:
            mask[i, : game.n_actions] = game.action_mask(r)
    return CompiledTest(
        next_z=new_of_old[np.asarray(nxt, dtype=np.int64)[perm]],
        refused=np.asarray(refused, dtype=bool)[perm],
        restricted=restricted,
        outcome=outcome,
        test_realized=np.array([game.test_accepting[r.history] for r in rows], dtype=bool),
        mask=mask,
        obs_row=obs_row.reshape(-1).astype(np.int64),
        obs=obs,
        system=sys_,
        history=hist,
        agent=agent,
        memory=memory,
        initial=int(new_of_old[0]),
    )


def same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and bool(np.array_equal(a, b))
    return type(a) is type(b) and bool(a == b)


# ------------------------------------------------------------------ the tests


@pytest.mark.parametrize("external", [False, True])
@pytest.mark.parametrize("art", SAMPLE, ids=IDS)
def test_game_tables_are_the_reference(art: TestArtifact, external: bool) -> None:
    game = TestGame(art, external_tester=external)
    for name, want in reference_tables(game).items():
        assert same(getattr(game, name), want), name
    assert same(game.restricted_array, np.asarray(game.restricted_bits, dtype=np.int64))
    assert same(game.exists_array, np.asarray(game.exists_bits, dtype=np.int64))
    assert game.next_history_array.tolist() == game.next_history
    assert game.doomed_array.tolist() == game.doomed


@pytest.mark.parametrize("art", SAMPLE, ids=IDS)
def test_compiled_tables_are_the_reference(art: TestArtifact) -> None:
    game = TestGame(art)
    for kind in ("flat", "grid", "padded") if game.is_grid else ("flat",):
        encoder = make_encoder(game, kind, 8)
        for extra in (0, 2):
            got = compile_test(game, encoder, game.n_actions + extra)
            want = reference_compile(game, encoder, game.n_actions + extra)
            for name in CompiledTest.__dataclass_fields__:
                assert same(getattr(got, name), getattr(want, name)), (kind, extra, name)


def _no_shared_memory(*args: Any) -> Any:
    raise OSError("no shared memory here")


@pytest.mark.parametrize("helper", ["one-process", "forked-helper", "no-shared-memory"])
def test_pool_of_many_tests_is_its_tests_one_by_one(helper: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The pool compiled at once (grids of several pools and sizes, a test agent among
    them) holds each test's own tables, offset; the same with a forked helper writing
    half of the observation rows, and where the system has no shared memory for one."""
    games = [TestGame(a) for a in SAMPLE if a.system.layout is not None]
    encoders = [make_encoder(g, "padded", 8) for g in games]
    if helper != "one-process":
        monkeypatch.setattr(compiled, "PARALLEL_FROM", 2)
        if compiled.helpers(len(games)) != 1:
            pytest.skip("no second core, or this process cannot fork")
    if helper == "no-shared-memory":
        monkeypatch.setattr(mmap, "mmap", _no_shared_memory)
    pool: CompiledPool = compile_pool(games, encoders)
    width = pool.n_actions
    for t, (g, e) in enumerate(zip(games, encoders, strict=True)):
        want = compile_test(g, e, width)
        o, n_z = int(pool.offset[t]), want.n_z
        got = pool.tests[t]
        for name in CompiledTest.__dataclass_fields__:
            assert same(getattr(got, name), getattr(want, name)), (t, name)
        assert np.array_equal(pool.next_z.reshape(-1, width)[o : o + n_z], want.next_z + o)
        assert np.array_equal(pool.mask[o : o + n_z], want.mask)
        assert int(pool.initial[t]) == o + want.initial


# ------------------------------------------------------------------ the step's fused tables


def test_step_tables_are_the_pool_tables_fused() -> None:
    """Every entry of the fused tables is what the step read from the pool's own tables
    before: next configuration, reward, end, both counters, mask, observation row."""
    games = [TestGame(a) for a in SAMPLE if a.system.layout is not None]
    pool = compile_pool(games, [make_encoder(g, "padded", 8) for g in games])
    reward = pool.rewards(0.01, 0.05, 1.0, 1.0)
    tab = step_tables.step_tables(pool, reward)
    a_n, z = pool.n_actions, np.arange(pool.n_z)
    here = np.repeat(z, a_n)
    assert np.array_equal(tab.next_z, pool.next_z) and tab.next_z.dtype == np.intp
    assert np.array_equal(tab.reward, reward)
    assert np.array_equal(tab.ends, pool.outcome[pool.next_z] != 0)
    restrictions, blocked = step_tables.split_counts(tab.counts)
    assert np.array_equal(restrictions, pool.restricted[here]) and np.array_equal(blocked, pool.refused)
    assert np.array_equal(tab.mask(z, a_n), pool.mask) and tab.mask(z, a_n).dtype == np.int8
    assert np.array_equal(tab.obs[tab.rows(z)], pool.obs[pool.obs_row])
    assert tab.obs.shape[0] < pool.obs.shape[0]  # rows repeat (the history's test part is not shown)


def test_distinct_rows_keep_the_first_occurrence_order() -> None:
    table = np.array([[0, 1], [1, 0], [0, 1], [1, 1], [1, 0]], dtype=np.float32)
    rows, row_of = step_tables.distinct_rows(table)
    assert rows.tolist() == [[0, 1], [1, 0], [1, 1]] and row_of.tolist() == [0, 1, 0, 2, 1]
    grid = np.arange(24, dtype=np.uint8).reshape(3, 2, 2, 2)  # no repeats: the table itself
    same_rows, identity = step_tables.distinct_rows(grid)
    assert same_rows is grid and identity.tolist() == [0, 1, 2]
