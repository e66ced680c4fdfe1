"""The two-player (tester vs. system) PettingZoo environment."""

from __future__ import annotations

import types
from typing import Any

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, seed_test

from flowtest_env import multiagent
from flowtest_env.artifacts import artifact_path, builtin_game
from flowtest_env.envs import BUILTIN_ENVS
from flowtest_env.game import RunState
from flowtest_env.multiagent import SYSTEM, TESTER, synthesized_tester

# PettingZoo's api_test remarks that Dict observations (observation + action_mask, the
# classic-env convention it asks for) are not plain arrays and differ between agents.
pytestmark = [
    pytest.mark.filterwarnings("ignore:Observation is not a NumPy array:UserWarning"),
    pytest.mark.filterwarnings("ignore:Observations are different shapes:UserWarning"),
    pytest.mark.filterwarnings("ignore:Observation space for each agent:UserWarning"),
    pytest.mark.filterwarnings("ignore:Agents have different observation space sizes:UserWarning"),
]

PROBLEMS = [n for n in BUILTIN_ENVS if artifact_path(n).exists()]


@pytest.mark.parametrize("problem", PROBLEMS)
def test_pettingzoo_api(problem: str) -> None:
    api_test(multiagent.env(problem=problem), num_cycles=300)
    parallel_api_test(multiagent.parallel_env(problem=problem), num_cycles=300)


@pytest.mark.parametrize("problem", PROBLEMS)
def test_pettingzoo_seed(problem: str) -> None:
    seed_test(lambda: multiagent.env(problem=problem), num_cycles=100)


def _moves_to_meet(problem: str) -> int:
    """The fewest system moves from the start to a state that meets the system objective,
    through the static walls only (what a random tester may leave open)."""
    game = builtin_game(problem, None, external_tester=True)
    walls = game.static_bits
    start = game.reset(agent_first_move=False)
    frontier, seen, depth = [start], {(start.system, start.history)}, 0
    while frontier:
        if any(r.outcome == "met" for r in frontier):
            return depth
        nxt = []
        for run in frontier:
            if run.done:
                continue
            for a in range(game.n_slots):
                if game.slot_move[run.system, a] >= 0 and not (walls[run.system] >> a) & 1:
                    r = run.copy()
                    r.agent = -1  # no test agent in the way
                    game.system_step(r, a, restricted=0)
                    if (r.system, r.history) not in seen:
                        seen.add((r.system, r.history))
                        nxt.append(r)
        frontier, depth = nxt, depth + 1
    raise AssertionError(f"{problem}: the objective cannot be met")


MAX_CYCLES = 4  # what pettingzoo.test.max_cycles_test uses


def _max_cycles_param(problem: str) -> Any:
    if _moves_to_meet(problem) < MAX_CYCLES:
        return pytest.param(
            problem,
            marks=pytest.mark.skip(
                reason=f"a random system meets {problem}'s objective in fewer than {MAX_CYCLES} moves when the random "
                "tester leaves the way open, and max_cycles_test then counts fewer cycles by design"
            ),
        )
    return problem


@pytest.mark.parametrize("problem", [_max_cycles_param(p) for p in PROBLEMS])
def test_pettingzoo_max_cycles(problem: str) -> None:
    """PettingZoo's max_cycles_test on every problem, through a module-shaped shim whose
    spaces are seeded (the test samples actions itself)."""

    def seeded(e: Any) -> Any:
        for i, agent in enumerate(e.possible_agents):
            e.action_space(agent).seed(i)
        return e

    shim = types.SimpleNamespace(
        env=lambda **kw: seeded(multiagent.env(problem=problem, **kw)),
        parallel_env=lambda **kw: seeded(multiagent.parallel_env(problem=problem, **kw)),
    )
    max_cycles_test(shim)


def test_pettingzoo_max_cycles_on_the_module() -> None:
    """The test as PettingZoo runs it: on the module itself (its default problem, maze2)."""
    max_cycles_test(multiagent)


def test_max_cycles_runs_on_most_problems() -> None:
    """The skip above is the exception: only the tiny small-reactive is that short."""
    assert [p for p in PROBLEMS if _moves_to_meet(p) < MAX_CYCLES] == ["small-reactive"]


def _play(problem: str, seed: int, n_steps: int) -> list[object]:
    """``n_steps`` AEC steps of seeded random masked actions for both players."""
    env = multiagent.env(problem=problem, max_cycles=40)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    trace: list[object] = []
    for _ in range(n_steps):
        agent = env.agent_selection
        obs, reward, term, trunc, info = env.last()
        trace.append((agent, obs, reward, term, trunc, info))
        if term or trunc:
            env.step(None)
            if not env.agents:
                env.reset()
            continue
        env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    return trace


def _play_parallel(problem: str, seed: int, n_rounds: int) -> list[object]:
    """``n_rounds`` parallel rounds of seeded random masked actions, resetting at run ends."""
    env = multiagent.parallel_env(problem=problem, max_cycles=40)
    obs, infos = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    trace: list[object] = [(obs, infos)]
    for _ in range(n_rounds):
        if not env.agents:
            obs, infos = env.reset()
            trace.append((obs, infos))
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
        out = env.step(actions)
        obs = out[0]
        trace.append((actions, *out, env.state()))
    return trace


@pytest.mark.parametrize("problem", PROBLEMS)
def test_multi_step_determinism(problem: str) -> None:
    """Two AEC envs and two parallel envs, same seeds and actions: identical
    observations, rewards, terminations, truncations and infos over many runs."""
    a, b = _play(problem, 11, 400), _play(problem, 11, 400)
    assert data_equivalence(a, b)
    assert sum(1 for step in a if step[3] or step[4]) >= 2, "several runs ended within the 400 steps"
    assert data_equivalence(_play_parallel(problem, 11, 200), _play_parallel(problem, 11, 200))


@pytest.mark.parametrize("problem", PROBLEMS)
def test_synthesized_tester_matches_the_single_agent_env(problem: str) -> None:
    """The default tester plays exactly the synthesized test of the Gymnasium env."""
    import gymnasium as gym

    stem = BUILTIN_ENVS[problem][0]
    single = gym.make(f"FlowTest-{stem}-v0")
    _, info = single.reset(seed=0)
    aec = multiagent.env(problem=problem)
    aec.reset(seed=0)
    tester = synthesized_tester(aec)
    rng = np.random.default_rng(0)
    for _ in range(60):
        agent = aec.agent_selection
        obs, _, term, trunc, ainfo = aec.last()
        if term or trunc:
            break
        if agent == TESTER:
            action = tester(obs, agent)
            assert obs["action_mask"][action], "the synthesized tester's move is legal"
            aec.step(action)
            continue
        assert np.array_equal(obs["action_mask"], info["action_mask"])
        assert ainfo["system_state"] == info["system_state"]
        a = int(rng.choice(np.flatnonzero(info["action_mask"])))
        aec.step(a)
        _, _, t1, tr1, info = single.step(a)
        if t1 or tr1:
            assert aec.terminations[SYSTEM] == t1
            if t1:
                assert aec.infos[SYSTEM]["verdict"] == info["verdict"]
            break


@pytest.mark.parametrize("problem", ["small-reactive", "maze2", "beaver-rescue", "motion-primitives"])
def test_synthesized_tester_guarantee_against_random_systems(problem: str) -> None:
    """Many random system rollouts against the default tester: every run that meets the
    system objective has realized the test objective; none is violated."""
    par = multiagent.parallel_env(problem=problem, max_cycles=60)
    tester = synthesized_tester(par)
    rng = np.random.default_rng(5)
    met = 0
    for episode in range(150):
        obs, infos = par.reset(seed=episode)
        while par.agents:
            actions = {}
            if TESTER in par.agents:
                actions[TESTER] = tester(obs[TESTER], TESTER)
            # the system chooses knowing only its own observation
            actions[SYSTEM] = int(rng.choice(np.flatnonzero(obs[SYSTEM]["action_mask"])))
            obs, rewards, terms, truncs, infos = par.step(actions)
        verdict = infos[SYSTEM]["verdict"]
        assert verdict["system_objective"] != "violated"
        if verdict["system_objective"] == "met":
            met += 1
            assert verdict["test_objective_realized"]
            assert rewards[TESTER] >= 1.0 or par.possible_agents[0] == SYSTEM
    assert met > 0


#: agent problems whose test agent must step in front of the system right after the
#: system's move (the system moves first): in the parallel game the tester answers the
#: round-start position, one round late, so the system can slip past (patrolling since it
#: took paper-examples.md's physical walls: the agent must block the way into (3, 2))
PARALLEL_LATE = frozenset({"patrolling"})


@pytest.mark.parametrize("problem", PROBLEMS)
def test_synthesized_tester_keeps_the_guarantees_in_the_parallel_game(problem: str) -> None:
    """Every system behaviour against the synthesized tester in the parallel version,
    where the players of a round choose simultaneously (agent problems: the system does
    not see the agent's move of the round, the tester answers the round-start position
    when the system moves first). Exhaustive over reachable game states, by copying the
    run state: every met run realized the test objective (except in
    :data:`PARALLEL_LATE`, where some met run provably misses it: the documented
    limitation of the parallel version), every live state can still meet the system
    objective."""
    env = multiagent.parallel_env(problem=problem, max_cycles=10**6)
    tester = synthesized_tester(env)

    def at(state: RunState) -> dict[str, Any]:
        """Put the env at a game state (a fresh run's bookkeeping, this run state)."""
        env.reset(seed=0)
        env.aec_env.run = state.copy()
        return {a: env.aec_env.observe(a) for a in env.agents}

    env.reset(seed=0)
    root = env.aec_env.run.copy()
    index = {root.key() + (False,): 0}
    stack = [root]
    src: list[int] = []
    dst: list[int] = []
    met, ended = set(), set()
    missed = 0  # met runs that did not realize the test objective
    while stack:
        state = stack.pop()
        i = index[state.key() + (False,)]
        for a in np.flatnonzero(at(state)[SYSTEM]["action_mask"]):
            obs = at(state)
            actions = {SYSTEM: int(a)}
            if TESTER in env.agents:
                actions[TESTER] = tester(obs[TESTER], TESTER)
            _, _, _, _, infos = env.step(actions)
            run = env.aec_env.run
            key = run.key() + (run.done,)
            if key not in index:
                index[key] = len(index)
                if run.done:
                    ended.add(index[key])
                    if run.outcome == "met":
                        met.add(index[key])
                        missed += not infos[SYSTEM]["verdict"]["test_objective_realized"]
                else:
                    stack.append(run.copy())
            src.append(i)
            dst.append(index[key])
    assert met, f"{problem}: no system behaviour meets the objective"
    if problem in PARALLEL_LATE:
        assert missed > 0, f"{problem}: the parallel game keeps the guarantee after all; drop it from PARALLEL_LATE"
    else:
        assert missed == 0, f"{problem}: {missed} met runs did not realize the test objective"
    can = np.zeros(len(index), dtype=bool)
    can[list(met)] = True
    s, d = np.array(src), np.array(dst)
    while True:
        grow = s[can[d] & ~can[s]]
        if grow.size == 0:
            break
        can[grow] = True
    trapped = [k for k, i in index.items() if i not in ended and not can[i]]
    assert not trapped, f"{problem}: the system is trapped at {trapped[:3]}"


def test_tester_masks_enforce_the_system_assumptions() -> None:
    """Obstacle problems: the tester never restricts a missing move, a static wall or
    every move; agent problems: the agent never steps onto the system."""
    env = multiagent.raw_env(problem="small-reactive")
    env.reset(seed=0)
    game = env.game
    rng = np.random.default_rng(2)
    for _ in range(200):
        if env.terminations[env.agent_selection] or env.truncations[env.agent_selection]:
            env.reset()
        obs = env.observe(env.agent_selection)
        if env.agent_selection == TESTER:
            s = env.run.system
            open_moves = game.exists_bits[s] & ~(1 << game.stay_action) & ~game.static_bits[s]
            for choice in np.flatnonzero(obs["action_mask"]):
                assert choice & ~game.choosable_bits[s] == 0
                assert open_moves == 0 or open_moves & ~choice
        env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
    agent_env = multiagent.raw_env(problem="maze2")
    agent_env.reset(seed=0)
    g = agent_env.game
    for _ in range(200):
        if agent_env.terminations[agent_env.agent_selection] or agent_env.truncations[agent_env.agent_selection]:
            agent_env.reset()
        obs = agent_env.observe(agent_env.agent_selection)
        if agent_env.agent_selection == TESTER:
            for a in np.flatnonzero(obs["action_mask"]):
                assert g.agent_moves[agent_env.run.agent, a]
                assert g.agent_place[a] != g.place_list[agent_env.run.system]
        agent_env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
        assert agent_env.run.agent < 0 or g.agent_place[agent_env.run.agent] != g.place_list[agent_env.run.system]


def test_illegal_tester_action_is_a_penalized_no_op() -> None:
    env = multiagent.raw_env(problem="small-reactive")
    env.reset(seed=0)
    mask = env.observe(TESTER)["action_mask"]
    illegal = int(np.flatnonzero(mask == 0)[0])
    env.step(illegal)
    assert env.rewards[TESTER] < 0
    assert env.run.override == 0


def test_spaces_are_cached() -> None:
    env = multiagent.raw_env(problem="maze2")
    assert env.observation_space(TESTER) is env.observation_space(TESTER)
    assert env.action_space(SYSTEM) is env.action_space(SYSTEM)
    assert builtin_game("maze2", None, external_tester=True) is env.game
