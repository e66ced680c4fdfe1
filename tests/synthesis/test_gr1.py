"""Tests for the explicit-state GR(1) solver :mod:`synthesis.test_agent.gr1`.

Cross-checking against omega
----------------------------
Random games are also solved with the independent symbolic solver ``omega``
(0.4, BDD based).  The explicit game is encoded so that both tools decide
exactly the same question:

* variables: ``p`` (system, the current position) and ``c`` (environment,
  the last environment choice; initially the index of the initial group);
* ``EnvNext == \\/_v (p = v /\\ \\/_{c owned by v} c' = c)`` -- the
  environment picks a choice owned by the current position (no disjunct for
  a position without choices, so the environment is stuck there);
* ``SysNext == \\/_c (c' = c /\\ \\/_{u in succ(c)} p' = u)`` -- the system
  answers the choice (no disjunct for a choice without successors);
* ``moore = False`` (Mealy): the system sees ``c'`` before choosing ``p'``,
  which is the "env picks a choice, then sys picks a successor" round;
* ``plus_one = False``: omega's controllable predecessor becomes
  ``\\A c': \\E p': EnvNext => (SysNext /\\ Target')``, i.e. exactly our
  ``cpre`` (a stuck environment makes the implication vacuous -> system
  wins; a stuck system falsifies it -> system loses).  With
  ``plus_one = True`` omega would demand ``SysNext`` even after illegal
  environment moves, which is a different game;
* liveness: omega's Streett game uses persistence sets ``<>[] hold_i`` for
  the environment, so ``hold_i = ~J^e_i`` (``[FALSE]`` if there is no
  assumption) and ``[]<> goal_j = J^s_j`` (``[TRUE]`` if there is none);
* initial condition: ``EnvInit == c \\in 0..(#groups - 1)`` and
  ``SysInit == \\/_g (c = g /\\ p \\in group_g)`` with ``qinit = '\\A \\E'``,
  which omega checks as ``\\A c: \\E p: EnvInit => (SysInit /\\ Win)``: for
  every group some position of it is winning.  This is sound because no
  action or liveness set depends on the unprimed ``c``.

Per-position winning regions are compared with the same automaton using
``EnvInit == c = 0`` and ``SysInit == p = v``.
"""

from __future__ import annotations

import contextlib
import io
import json
import time

import numpy as np
import pytest

from synthesis.test_agent.gr1.game import GR1Game
from synthesis.test_agent.gr1.solver import GR1Result, solve
from synthesis.test_agent.gr1.strategy import GR1Strategy
from synthesis.test_agent.gr1.verify import StrategyError, verify_strategy

omega_gr1 = pytest.importorskip("omega.games.gr1")
omega_temporal = pytest.importorskip("omega.symbolic.temporal")


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------


def _solve_and_check(game: GR1Game) -> GR1Result:
    """Solve ``game`` and verify the strategy whenever one is returned."""
    res = solve(game)
    assert res.winning.dtype == np.bool_ and res.winning.shape == (game.n_positions,)
    if res.realizable:
        assert res.strategy is not None
        verify_strategy(game, res.strategy)
        for g, group in enumerate(game.initial):
            pick = res.strategy.initial_choice(g)
            assert pick in group.tolist() and res.winning[pick]
    else:
        assert res.strategy is None
    return res


def _disj(terms: list[str]) -> str:
    """Disjunction of TLA+ formulas (``FALSE`` if empty)."""
    return "(" + r" \/ ".join(terms) + ")" if terms else "FALSE"


def _pos_set(var: str, positions: np.ndarray | list[int]) -> str:
    """Formula ``var \\in positions`` (positions as a bool mask or index list)."""
    arr = np.asarray(positions)
    idx = np.flatnonzero(arr) if arr.dtype == np.bool_ else arr.astype(int)
    return _disj([f"{var} = {int(v)}" for v in idx])


def _omega_automaton(game: GR1Game):
    """Encode ``game`` as an omega Streett(1) automaton (see module docstring)."""
    n, m = game.n_positions, game.n_choices
    n_groups = len(game.initial)
    aut = omega_temporal.Automaton()
    aut.declare_variables(p=(0, max(n - 1, 0)), c=(0, max(m, n_groups, 1) - 1))
    aut.varlist = dict(env=["c"], sys=["p"])
    aut.prime_varlists()
    by_owner: dict[int, list[int]] = {}
    for c, v in enumerate(game.choice_owner.tolist()):
        by_owner.setdefault(v, []).append(c)
    env_terms = []
    for v, cs in by_owner.items():
        picks = _disj([f"c' = {c}" for c in cs])
        env_terms.append(rf"(p = {v} /\ {picks})")
    aut.action["env"] = _disj(env_terms)
    sys_terms = []
    for c in range(m):
        succ = game.successors(c).tolist()
        if succ:
            targets = _pos_set("p'", succ)
            sys_terms.append(rf"(c' = {c} /\ {targets})")
    aut.action["sys"] = _disj(sys_terms)
    aut.win["<>[]"] = [aut.add_expr(f"~ {_pos_set('p', s)}") for s in game.env_liveness] or [aut.false]
    aut.win["[]<>"] = [aut.add_expr(_pos_set("p", s)) for s in game.sys_liveness] or [aut.true]
    aut.moore = False
    aut.plus_one = False
    aut.qinit = r"\A \E"
    return aut


def _omega_realizable(aut, z, env_init: str, sys_init: str) -> bool:
    """omega's own check of the initial condition against its winning set ``z``."""
    aut.init["env"] = env_init
    aut.init["sys"] = sys_init
    with contextlib.redirect_stdout(io.StringIO()):  # omega prints on failure
        return bool(omega_gr1.is_realizable(z, aut))


def omega_solve(game: GR1Game, per_position: bool = False) -> tuple[bool, np.ndarray | None]:
    """Return omega's verdict (and optionally its per-position winning mask)."""
    aut = _omega_automaton(game)
    z, _, _ = omega_gr1.solve_streett_game(aut)
    groups = [rf"(c = {g} /\ {_pos_set('p', grp.tolist())})" for g, grp in enumerate(game.initial)]
    env_init = rf"c \in 0..{len(game.initial) - 1}" if game.initial else "FALSE"
    verdict = _omega_realizable(aut, z, env_init, _disj(groups))
    if not per_position:
        return verdict, None
    mask = np.array(
        [_omega_realizable(aut, z, "c = 0", f"p = {v}") for v in range(game.n_positions)],
        dtype=bool,
    )
    return verdict, mask


def random_game(rng: np.random.Generator, n_min: int = 3, n_max: int = 12) -> GR1Game:
    """A small random game with occasional dead ends of both players."""
    n = int(rng.integers(n_min, n_max + 1))
    choices: list[tuple[int, list[int]]] = []
    for v in range(n):
        k = 0 if rng.random() < 0.07 else int(rng.integers(1, 4))
        for _ in range(k):
            d = 0 if rng.random() < 0.04 else int(rng.integers(1, 4))
            choices.append((v, sorted(rng.choice(n, size=min(d, n), replace=False).tolist())))
    env = [rng.random(n) < rng.uniform(0.2, 0.6) for _ in range(int(rng.integers(0, 3)))]
    sys_ = [rng.random(n) < rng.uniform(0.1, 0.5) for _ in range(int(rng.integers(1, 3)))]
    initial = [rng.choice(n, size=min(int(rng.integers(1, 4)), n), replace=False).tolist() for _ in range(int(rng.integers(1, 4)))]
    return GR1Game.from_lists(n, choices, initial, env, sys_)


def big_random_game(
    n: int,
    seed: int,
    n_env: int = 1,
    n_sys: int = 2,
    p_goal: float = 0.2,
    p_dead: float = 0.02,
    max_deg: int = 3,
) -> GR1Game:
    """A large random game built directly as CSR arrays.

    ``p_goal`` is the density of each guarantee set, ``p_dead`` the fraction
    of choices without successors (sys dead ends); the defaults give winning
    regions that are neither empty nor everything.
    """
    rng = np.random.default_rng(seed)
    owner = np.repeat(np.arange(n), rng.integers(1, 4, size=n))
    deg = rng.integers(1, max_deg + 1, size=owner.size)
    deg[rng.random(owner.size) < p_dead] = 0
    ptr = np.concatenate([[0], np.cumsum(deg)])
    succ = rng.integers(0, n, size=int(ptr[-1]))
    env = [rng.random(n) < 0.3 for _ in range(n_env)]
    sys_ = [rng.random(n) < p_goal for _ in range(n_sys)]
    return GR1Game(n, owner, ptr, succ, [np.arange(min(n, 10))], env, sys_)


def with_initial(game: GR1Game, initial: list[np.ndarray]) -> GR1Game:
    """Copy of ``game`` with other initial groups."""
    return GR1Game(
        game.n_positions,
        game.choice_owner,
        game.choice_succ_ptr,
        game.choice_succ,
        initial,
        game.env_liveness,
        game.sys_liveness,
    )


def from_winning(game: GR1Game, k: int = 20) -> GR1Game:
    """``game`` started from (up to ``k``) of its winning positions, one group each."""
    win = np.flatnonzero(solve(game).winning)
    assert win.size, "expected a non-empty winning region"
    return with_initial(game, [np.array([v]) for v in win[:k]])


# ---------------------------------------------------------------------------
# 1. hand-made games
# ---------------------------------------------------------------------------


def _request_game(with_assumption: bool) -> GR1Game:
    # 0 idle: env "wait" -> {0}, env "allow" -> {2}; 2 allowed: -> {0, 1}; 1 goal: -> {0}
    choices = [(0, [0]), (0, [2]), (2, [0, 1]), (1, [0])]
    env = [[2]] if with_assumption else []
    return GR1Game.from_lists(3, choices, [[0]], env, [[1]])


def test_env_can_block_goal() -> None:
    res = _solve_and_check(_request_game(with_assumption=False))
    assert not res.realizable
    assert res.winning.tolist() == [False, False, False]


def test_env_assumption_makes_it_realizable() -> None:
    game = _request_game(with_assumption=True)
    res = _solve_and_check(game)
    assert res.realizable and res.winning.all()
    strat = res.strategy
    assert strat is not None
    assert strat.move(0, 2) == (1, 0)  # from "allowed" go to the goal
    assert strat.move(0, 3) == (0, 0)  # leaving the goal advances the (single) counter


def test_env_stuck_position_is_winning() -> None:
    # position 0 has no environment choice; the goal {1} is never visited
    game = GR1Game.from_lists(2, [(1, [1])], [[0]], [], [[1]])
    res = _solve_and_check(game)
    assert res.realizable and res.winning[0]
    assert res.winning[1]  # 1 -> 1 -> ... visits the goal forever


def test_sys_stuck_choice_is_losing() -> None:
    # at 0 the env may pick a choice without successors; 1 is a safe self-loop
    game = GR1Game.from_lists(2, [(0, [1]), (0, []), (1, [1])], [[0]], [], [])
    res = _solve_and_check(game)
    assert not res.realizable
    assert res.winning.tolist() == [False, True]


def test_initial_group_semantics() -> None:
    choices = [(0, []), (1, [1])]  # 0 losing, 1 winning
    res = _solve_and_check(GR1Game.from_lists(2, choices, [[0, 1]], [], []))
    assert res.realizable and res.strategy is not None
    assert res.strategy.initial_choice(0) == 1
    assert res.strategy.initial_positions().tolist() == [1]
    # the environment may pick the group {0}: unrealizable
    assert not solve(GR1Game.from_lists(2, choices, [[0, 1], [0]], [], [])).realizable
    # an empty group cannot be answered; no group at all is vacuously fine
    assert not solve(GR1Game.from_lists(2, choices, [[]], [], [])).realizable
    assert solve(GR1Game.from_lists(2, choices, [], [], [])).realizable


def test_two_goals_need_memory() -> None:
    # hub 0: env has one choice, sys picks 1 or 2; 1 and 2 go back to 0
    game = GR1Game.from_lists(3, [(0, [1, 2]), (1, [0]), (2, [0])], [[0]], [], [[1], [2]])
    res = _solve_and_check(game)
    assert res.realizable and res.strategy is not None
    strat = res.strategy
    assert strat.n_memory == 2
    pos, mem = strat.initial_choice(0), strat.initial_memory
    seen = []
    for _ in range(8):
        c = {0: 0, 1: 1, 2: 2}[pos]
        pos, mem = strat.move(mem, c)
        seen.append(pos)
    assert {1, 2} <= set(seen)


def test_persistence_of_assumption_violation() -> None:
    # 0 -> trap 1; at 1 env may "stay" (sys must stay) or "release" (sys may
    # reach the goal 2); 2 -> 0.  Env staying forever keeps sys from the goal
    # but visits only 1, which violates the assumption GF {0, 2}.
    choices = [(0, [1]), (1, [1]), (1, [1, 2]), (2, [0])]
    assert not _solve_and_check(GR1Game.from_lists(3, choices, [[0]], [], [[2]])).realizable
    res = _solve_and_check(GR1Game.from_lists(3, choices, [[0]], [[0, 2]], [[2]]))
    assert res.realizable and res.winning.all()
    # an assumption that staying in 1 satisfies does not help
    assert not _solve_and_check(GR1Game.from_lists(3, choices, [[0]], [[1]], [[2]])).realizable


def test_validation_errors() -> None:
    with pytest.raises(ValueError, match="out of range"):
        GR1Game.from_lists(2, [(0, [2])], [[0]], [], [])
    with pytest.raises(ValueError, match="owner"):
        GR1Game.from_lists(2, [(5, [0])], [[0]], [], [])
    with pytest.raises(ValueError, match="pair"):
        GR1Game.from_lists(2, [(0,)], [[0]], [], [])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="initial"):
        GR1Game.from_lists(2, [(0, [1])], [[3]], [], [])
    with pytest.raises(ValueError, match="sys_liveness"):
        GR1Game.from_lists(2, [(0, [1])], [[0]], [], [np.ones(3, dtype=bool)])
    with pytest.raises(ValueError, match="choice_succ_ptr"):
        GR1Game(2, np.array([0]), np.array([0, 2]), np.array([1]), [], [], [])
    with pytest.raises(ValueError, match="boolean"):
        GR1Game(2, np.array([0]), np.array([0, 1]), np.array([1]), [], [np.array([1, 0])], [])
    with pytest.raises(ValueError, match="n_positions"):
        GR1Game.from_lists(-1, [], [], [], [])


def test_strategy_serialisation_roundtrip() -> None:
    game = from_winning(big_random_game(300, seed=3, n_env=2, n_sys=3))
    strat = _solve_and_check(game).strategy
    assert strat is not None and strat.n_memory == 3
    blob = json.dumps(strat.to_dict())
    back = GR1Strategy.from_dict(json.loads(blob))
    assert np.array_equal(back.next_position, strat.next_position)
    assert np.array_equal(back.next_memory, strat.next_memory)
    assert np.array_equal(back.initial_positions(), strat.initial_positions())
    assert back.table["next_position"].dtype == np.int32
    assert back.next_position.shape == (strat.n_memory, game.n_choices)
    for mem in range(strat.n_memory):
        for c in range(strat.n_choices):
            if strat.next_position[mem, c] >= 0:
                assert back.move(mem, c) == strat.move(mem, c)
            else:
                with pytest.raises(ValueError):
                    back.move(mem, c)
    verify_strategy(game, back)
    with pytest.raises(ValueError):
        GR1Strategy.from_dict({**strat.to_dict(), "format": "other"})


def test_long_chain_needs_many_persistence_steps() -> None:
    """Deep rank structure: each chain link is won only via an assumption."""
    k_links = 200
    choices: list[tuple[int, list[int]]] = []
    for k in range(k_links):
        v, hold, mid = 3 * k, 3 * k + 1, 3 * k + 2
        # env may "hold" (cycle v <-> hold, outside J^e) or go forward via mid in J^e
        choices += [(v, [mid]), (v, [hold]), (hold, [v]), (mid, [3 * (k - 1)] if k else [0])]
    n = 3 * k_links
    live = np.zeros(n, dtype=bool)
    live[2::3] = True
    game = GR1Game.from_lists(n, choices, [[n - 3]], [live], [[0]])
    res = _solve_and_check(game)
    assert res.realizable and res.winning.all()
    no_assumption = GR1Game.from_lists(n, choices, [[n - 3]], [], [[0]])
    assert not _solve_and_check(no_assumption).realizable


# ---------------------------------------------------------------------------
# 2. the verifier can fail
# ---------------------------------------------------------------------------


def test_verifier_rejects_broken_strategies() -> None:
    # 0: sys may stay at 0 or go to the goal 1; 1 -> 0
    game = GR1Game.from_lists(2, [(0, [0, 1]), (1, [0])], [[0]], [], [[1]])
    good = _solve_and_check(game).strategy
    assert good is not None
    never_goal = GR1Strategy(2, np.array([0]), np.array([[0, 0]]), np.array([[0, 0]]))
    with pytest.raises(StrategyError, match="guarantee 0"):
        verify_strategy(game, never_goal)
    no_move = GR1Strategy(2, np.array([0]), np.array([[-1, 0]]), np.array([[-1, 0]]))
    with pytest.raises(StrategyError, match="no valid move"):
        verify_strategy(game, no_move)
    illegal = GR1Strategy(2, np.array([0]), np.array([[1, 1]]), np.array([[0, 0]]))
    with pytest.raises(StrategyError, match="illegal move"):
        verify_strategy(game, illegal)
    bad_init = GR1Strategy(2, np.array([1]), good.next_position, good.next_memory)
    with pytest.raises(StrategyError, match="initial"):
        verify_strategy(game, bad_init)
    # with an assumption that the cycle 0 -> 0 violates, never_goal becomes fine
    game_assume = GR1Game.from_lists(2, [(0, [0, 1]), (1, [0])], [[0]], [[1]], [[1]])
    verify_strategy(game_assume, never_goal)


def test_verifier_rejects_mutated_random_strategies() -> None:
    """Redirecting moves of a winning strategy to stay out of a goal is caught."""
    rng = np.random.default_rng(11)
    caught = 0
    for _ in range(60):
        game = random_game(rng, 5, 10)
        res = solve(game)
        if not res.realizable or not game.sys_liveness:
            continue
        strat = res.strategy
        assert strat is not None
        goal = game.sys_liveness[0]
        nxt = strat.next_position.copy()
        changed = False
        for mem in range(strat.n_memory):
            for c in range(game.n_choices):
                if nxt[mem, c] >= 0 and goal[nxt[mem, c]]:
                    alt = [u for u in game.successors(c).tolist() if not goal[u]]
                    if alt:
                        nxt[mem, c] = alt[0]
                        changed = True
        if not changed:
            continue
        mutated = GR1Strategy(strat.n_positions, strat.initial, nxt, strat.next_memory)
        try:
            verify_strategy(game, mutated)
        except StrategyError:
            caught += 1
    assert caught >= 5


# ---------------------------------------------------------------------------
# 3. random games against omega
# ---------------------------------------------------------------------------


N_RANDOM = 300


def test_random_games_match_omega() -> None:
    rng = np.random.default_rng(20240601)
    verdicts = []
    for k in range(N_RANDOM):
        game = random_game(rng)
        res = _solve_and_check(game)
        want, want_mask = omega_solve(game, per_position=(k % 3 == 0))
        assert res.realizable == want, f"game #{k}: ours {res.realizable}, omega {want}"
        if want_mask is not None:
            assert np.array_equal(res.winning, want_mask), f"game #{k}: winning regions differ"
        verdicts.append(want)
    # the generator must exercise both outcomes
    assert 0.15 < np.mean(verdicts) < 0.85


def test_random_games_winning_regions_match_omega() -> None:
    rng = np.random.default_rng(99)
    for k in range(60):
        game = random_game(rng, 6, 12)
        res = _solve_and_check(game)
        _, want_mask = omega_solve(game, per_position=True)
        assert np.array_equal(res.winning, want_mask), f"game #{k}"


def test_medium_random_games_strategies_verify() -> None:
    for seed in range(6):
        game = big_random_game(2000, seed=seed, n_env=seed % 3, n_sys=1 + seed % 3)
        res = _solve_and_check(game)
        assert 0 < res.winning.sum() < game.n_positions
        _solve_and_check(from_winning(game))


# ---------------------------------------------------------------------------
# 4. performance smoke test
# ---------------------------------------------------------------------------


def test_performance_smoke() -> None:
    for n in (20_000, 50_000):
        game = big_random_game(n, seed=1, n_env=2, n_sys=3)
        t0 = time.perf_counter()
        res = solve(game)
        dt = time.perf_counter() - t0
        print(f"\n{n} positions / {game.n_choices} choices / {game.n_edges} moves: solved in {dt:.3f}s, |Z|={int(res.winning.sum())}")
        game = from_winning(game, k=50)
        strat = _solve_and_check(game).strategy
        assert strat is not None
