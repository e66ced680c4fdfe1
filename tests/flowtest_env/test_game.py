"""The rules of a test run (flowtest_env/game.py, its module docstring), held on every shipped
built-in test against a plain re-reading of the artifact, as PettingZoo tests its board apart
from its env.

The reference below reads the artifact's own arrays (the transition system's moves, the
strategy's ``blocked`` table, the histories' transition and acceptance) and applies the rules
one by one, with none of :class:`~flowtest_env.game.TestGame`'s bitmask tables; seeded random
runs of both must agree step for step. The termination rule "violated" is held to a backward
search of its own.
"""

from __future__ import annotations

import random
from collections import deque

import numpy as np
import pytest

from flowtest_env import load_test
from flowtest_env.game import GRID_ACTIONS, MET, OPEN, VIOLATED, GameError, TestGame

BUILTINS = ["small-reactive", "example1", "beaver-rescue", "motion-primitives", "refueling", "maze1", "maze2", "patrolling"]
"""Every kind of test: static (grid, fuel), reactive (grid, graph) and agent (grid, fuel)."""


def moves_out(game: TestGame, state: int) -> list[int]:
    """The moves of the transition system out of ``state``, in the artifact's move order."""
    ts = game.ts
    return [int(m) for m in np.flatnonzero(ts.src == state)]


def move_of_action(game: TestGame, state: int, action: int) -> int | None:
    """The move an action takes from ``state`` by the rule "Moves" (None: no move, or stay)."""
    ts = game.ts
    out = moves_out(game, state)
    if action == game.stay_action:
        return None
    if game.is_grid:
        name = GRID_ACTIONS[action]
        hits = [m for m in out if ts.action[m] == name]
        return hits[0] if hits else None
    return out[action] if action < len(out) else None


def restricted_now(game: TestGame, history: int, state: int, agent_place: int) -> set[int]:
    """The moves out of ``state`` the rule "Restrictions" refuses under ``history``."""
    art, ts = game.artifact, game.ts
    if art.kind == "agent":
        table = art.strategy.static_obstacles
        return {m for m in moves_out(game, state) if table[m] or int(ts.place[ts.dst[m]]) == agent_place}
    return {m for m in moves_out(game, state) if art.strategy.blocked[history, m]}


def doomed_by_search(game: TestGame) -> np.ndarray:
    """``bool[n_hist, n_states]``: no run respecting the enforced restrictions reaches an
    accepting history of the system objective (backward search over (history, state))."""
    ts, art = game.ts, game.artifact
    nh = art.histories.n_states
    letter = ts.letter_of_state(art.letters)
    enforced = game.enforced
    preds: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for h in range(nh):
        for m in range(ts.n_moves):
            if enforced[h, m]:
                continue
            s, t = int(ts.src[m]), int(ts.dst[m])
            preds.setdefault((int(art.histories.delta[h, letter[t]]), t), []).append((h, s))
        for s in range(ts.n_states):
            if ts.stay[s]:
                preds.setdefault((int(art.histories.delta[h, letter[s]]), s), []).append((h, s))
    good = np.zeros((nh, ts.n_states), dtype=bool)
    queue = deque((h, s) for h in range(nh) if art.histories.accepting[h, 0] for s in range(ts.n_states))
    for h, s in queue:
        good[h, s] = True
    while queue:
        node = queue.popleft()
        for p in preds.get(node, []):
            if not good[p]:
                good[p] = True
                queue.append(p)
    return ~good


@pytest.fixture(scope="module", params=BUILTINS)
def game(request: pytest.FixtureRequest) -> TestGame:
    return TestGame(load_test(request.param))


def test_action_slots_follow_the_move_rule(game: TestGame) -> None:
    for s in range(game.ts.n_states):
        for a in range(game.n_actions):
            move = move_of_action(game, s, a)
            want_next = s if move is None else int(game.ts.dst[move])
            if a < game.n_slots:
                assert int(game.successor[s, a]) == want_next
                assert int(game.slot_move[s, a]) == (-1 if move is None else move)


def test_seeded_runs_agree_with_the_rules_read_off_the_artifact(game: TestGame) -> None:
    """Random actions (legal, restricted and invalid alike) on the game and on the reference
    give the same states, histories, counters, masks and outcomes at every step."""
    art, ts = game.artifact, game.ts
    letter = ts.letter_of_state(art.letters)
    doomed = doomed_by_search(game)
    rng = random.Random(7)
    for _ in range(12):
        run = game.reset()
        state, history = int(ts.initial), art.initial_history()
        restrictions = attempts = steps = 0
        assert (run.system, run.history) == (state, history)
        for _ in range(60):
            if run.done:
                break
            agent_place = game.agent_place[run.agent] if game.has_agent else -2
            refused = restricted_now(game, history, state, agent_place)
            legal = {a for a in range(game.n_actions) if (a == game.stay_action and ts.stay[state]) or (move_of_action(game, state, a) not in (None, *refused))}
            mask = game.action_mask(run)
            assert set(np.flatnonzero(mask)) == (legal or {game.stay_action}), "the mask offers exactly the legal actions"
            action = rng.randrange(game.n_actions)
            move = move_of_action(game, state, action)
            if refused:
                restrictions += 1
            if action != game.stay_action and (move is None or move in refused):
                attempts += 1
            elif action == game.stay_action and not ts.stay[state] and legal:
                attempts += 1  # stay is invalid where the state has no stay, unless nothing else is offered
            if move is not None and move not in refused:
                state = int(ts.dst[move])
            history = int(art.histories.delta[history, letter[state]])
            steps += 1
            game.step(run, action)
            assert (run.system, run.history, run.steps) == (state, history, steps)
            assert (run.restrictions, run.blocked_attempts) == (restrictions, attempts)
            want = MET if art.histories.accepting[history, 0] else VIOLATED if doomed[history, state] else OPEN
            assert run.outcome == want
        verdict = game.verdict(run)
        assert verdict["test_objective_realized"] == bool(art.histories.accepting[run.history, 1])
        assert verdict["system_objective"] in (OPEN, MET, VIOLATED)


def test_violated_is_exactly_the_doomed_search(game: TestGame) -> None:
    assert np.array_equal(np.asarray(game.doomed), doomed_by_search(game))


def test_an_ended_run_takes_no_step_and_shows_no_action(game: TestGame) -> None:
    run = game.reset()
    run.outcome = VIOLATED
    assert not game.action_mask(run).any()
    with pytest.raises(GameError, match="has ended"):
        game.system_step(run, 0)


def test_an_action_index_outside_the_space_is_refused(game: TestGame) -> None:
    run = game.reset()
    with pytest.raises(GameError, match="outside"):
        game.system_step(run, game.n_actions)


def test_the_test_agent_never_steps_onto_the_system() -> None:
    """Agent tests: the agent's legal moves never enter the SUT's place, and a move of the SUT
    into the agent's place is refused (rule "Restrictions")."""
    for name in ("maze1", "maze2"):
        game = TestGame(load_test(name))
        rng = random.Random(3)
        for _ in range(10):
            run = game.reset()
            for _ in range(40):
                if run.done:
                    break
                legal = game.agent_legal(run)
                sut_place = game.place_list[run.system]
                assert all(game.agent_place[a] != sut_place for a in np.flatnonzero(legal) if a != run.agent)
                mask = game.action_mask(run)
                for a in np.flatnonzero(mask):
                    if a < game.n_slots:
                        assert game.dst_place[run.system, a] != game.agent_place[run.agent]
                game.step(run, rng.randrange(game.n_actions))
