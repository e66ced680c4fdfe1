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


# ---------------------------------------------------------------------- options for RL libraries


def _random_aec_episodes(problem: str, seed: int, episodes: int, **kwargs: Any) -> list[tuple[str, dict[str, Any], int]]:
    """Play ``episodes`` runs of the AEC env with uniformly random legal actions for both
    agents; returns ``(agent, observation, action)`` at every live turn (the tester's
    observation taken before its move)."""
    e = multiagent.env(test=problem, **kwargs)
    rng = np.random.default_rng(seed)
    mask_key = kwargs.get("mask_key", "action_mask")
    out: list[tuple[str, dict[str, Any], int]] = []
    for ep in range(episodes):
        e.reset(seed=seed + ep)
        for agent in e.agent_iter():
            obs, _, term, trunc, _ = e.last()
            if term or trunc:
                e.step(None)
                continue
            action = int(rng.choice(np.flatnonzero(obs[mask_key])))
            out.append((agent, obs, action))
            e.step(action)
    return out


@pytest.mark.parametrize("problem", PROBLEMS)
def test_synthesized_tester_policy_answers_from_the_observation(problem: str) -> None:
    """SynthesizedTester (built apart, from the tester's observation alone) answers what
    the env's synthesized_action() answers at every tester turn of random runs, in the
    AEC and the parallel game, one by one and as a batch, padded spaces included."""
    for kwargs in ({}, {"same_spaces": True, "obs_key": "observations"}):
        e = multiagent.env(test=problem, **kwargs)
        policy = multiagent.SynthesizedTester(e)
        rng = np.random.default_rng(1)
        seen, batch, expected = 0, [], []
        for ep in range(4):
            e.reset(seed=ep)
            for agent in e.agent_iter():
                obs, _, term, trunc, _ = e.last()
                if term or trunc:
                    e.step(None)
                    continue
                if agent == TESTER:
                    want = e.unwrapped.synthesized_action()
                    assert policy(obs) == want
                    batch.append(obs[policy.obs_key])
                    expected.append(want)
                    seen += 1
                    action = want if rng.random() < 0.7 else int(rng.choice(np.flatnonzero(obs[e.unwrapped.mask_key])))
                else:
                    action = int(rng.choice(np.flatnonzero(obs[e.unwrapped.mask_key])))
                e.step(action)
        assert seen > 4
        assert policy(np.stack(batch)).tolist() == expected
    par = multiagent.parallel_env(test=problem)
    policy = multiagent.SynthesizedTester(par)
    obs, _ = par.reset(seed=0)
    rng = np.random.default_rng(2)
    rounds = 0
    while par.agents and rounds < 50:
        want = par.aec_env.synthesized_action()
        assert policy(obs[TESTER]) == want
        sys_mask = obs[SYSTEM]["action_mask"]
        obs, *_ = par.step({TESTER: want, SYSTEM: int(rng.choice(np.flatnonzero(sys_mask)))})
        rounds += 1
    assert rounds > 0


def test_synthesized_tester_policy_refuses_other_shapes() -> None:
    e = multiagent.raw_env(test="small-reactive")
    policy = multiagent.SynthesizedTester(e)
    with pytest.raises(ValueError, match="tester observations"):
        policy(np.zeros(3, dtype=np.float32))
    with pytest.raises(TypeError, match="not a flowtest_env.multiagent environment"):
        multiagent.SynthesizedTester(object())


@pytest.mark.parametrize("problem", ["small-reactive", "maze2", "maze1"])
def test_numeric_infos_hold_the_same_numeric_keys_and_the_verdict(problem: str) -> None:
    """info_kind="numeric": every info of every agent at every reset and step has exactly
    NUMERIC_INFO_KEYS, all ints, and at the end they are the full verdict as numbers
    (played in lockstep with an env of the default infos)."""
    full = multiagent.env(test=problem)
    num = multiagent.env(test=problem, info_kind="numeric")
    rng = np.random.default_rng(0)
    ends = 0
    for ep in range(6):
        full.reset(seed=ep)
        num.reset(seed=ep)
        for agent in full.agent_iter():
            assert num.agent_selection == agent
            obs, _, term, trunc, info = full.last()
            _, _, nterm, ntrunc, ninfo = num.last()
            assert (term, trunc) == (nterm, ntrunc)
            for a in num.agents:
                i = num.infos[a]
                assert tuple(i) == multiagent.NUMERIC_INFO_KEYS
                assert all(type(v) is int for v in i.values()), i
            assert ninfo["system_state"] == full.unwrapped.run.system
            if term or trunc:
                v = info["verdict"]
                assert ninfo["system_objective"] == multiagent.OUTCOME_CODES[v["system_objective"]]
                assert ninfo["test_objective_realized"] == int(v["test_objective_realized"])
                for k in ("restrictions", "blocked_attempts", "steps"):
                    assert ninfo[k] == v[k]
                ends += 1
                full.step(None)
                num.step(None)
                continue
            assert "verdict" not in info
            action = int(rng.choice(np.flatnonzero(obs["action_mask"])))
            full.step(action)
            num.step(action)
    assert ends >= 6


@pytest.mark.parametrize("problem", ["small-reactive", "maze2"])
def test_key_names_and_same_spaces(problem: str) -> None:
    """obs_key/mask_key rename the Dict entries (spaces too); same_spaces gives both
    agents one observation and one action space, the padding zeros and never legal,
    and the game plays exactly as without it."""
    plain = multiagent.raw_env(test=problem)
    e = multiagent.raw_env(test=problem, obs_key="observations", mask_key="mask", same_spaces=True)
    assert set(e.observation_space(TESTER).spaces) == {"observations", "mask"}
    assert e.observation_space(TESTER) == e.observation_space(SYSTEM)
    assert e.action_space(TESTER) == e.action_space(SYSTEM)
    n = int(e.action_space(TESTER).n)
    assert n == max(int(plain.action_space(a).n) for a in (TESTER, SYSTEM))
    for agent, obs, action in _random_aec_episodes(problem, 3, 3, obs_key="observations", mask_key="mask", same_spaces=True):
        assert e.observation_space(agent).contains(obs)
        n_own = int(plain.action_space(agent).n)
        assert not obs["mask"][n_own:].any()
        assert action < n_own
    # same actions, same game: observations are the unpadded ones with zeros after
    plain.reset()
    e.reset()
    rng = np.random.default_rng(4)
    for _ in range(40):
        if not plain.agents:
            break
        agent = plain.agent_selection
        a_obs, b_obs = plain.observe(agent), e.observe(agent)
        flat = a_obs["observation"].reshape(-1)
        np.testing.assert_array_equal(b_obs["observations"][: flat.size], flat)
        assert not b_obs["observations"][flat.size :].any()
        np.testing.assert_array_equal(b_obs["mask"][: a_obs["action_mask"].size], a_obs["action_mask"])
        done = plain.terminations[agent] or plain.truncations[agent]
        act = None if done else int(rng.choice(np.flatnonzero(a_obs["action_mask"])))
        plain.step(act)
        e.step(act)
        assert plain.rewards == e.rewards


def test_pettingzoo_api_with_library_options() -> None:
    kwargs: dict[str, Any] = {"obs_key": "observations", "info_kind": "numeric", "same_spaces": True}
    parallel_api_test(multiagent.parallel_env(test="maze2", **kwargs), num_cycles=100)
    api_test(multiagent.env(test="small-reactive", **kwargs), num_cycles=100)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"info_kind": "strings"}, "info_kind"),
        ({"obs_key": ""}, "obs_key must be a non-empty string"),
        ({"obs_key": "x", "mask_key": "x"}, "must differ"),
        ({"same_spaces": 1}, "same_spaces must be True or False"),
    ],
)
def test_library_options_refuse_bad_values(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        multiagent.raw_env(test="small-reactive", **kwargs)


def test_pettingzoos_render_test_passes_with_human_rendering(monkeypatch: pytest.MonkeyPatch) -> None:
    """PettingZoo's own ``render_test``: the env made with ``render_mode="human"`` (a pygame
    window, here on SDL's dummy driver), then every mode its metadata lists (``human`` among
    them: ``render()`` draws and returns ``None``; ``rgb_array`` pictures; ``ansi`` text)."""
    pytest.importorskip("pygame", reason="render_mode='human' needs the render extra (pygame)")
    from pettingzoo.test import render_test

    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    assert "human" in multiagent.raw_env.metadata["render_modes"]
    render_test(lambda render_mode=None: multiagent.env(test="maze2", render_mode=render_mode))
    shown: list[tuple[int, ...]] = []
    real = multiagent.HumanWindow.show

    def show(self: multiagent.HumanWindow, frame: np.ndarray) -> None:
        shown.append(frame.shape)
        real(self, frame)

    monkeypatch.setattr(multiagent.HumanWindow, "show", show)
    e = multiagent.parallel_env(test="small-reactive", render_mode="human")
    e.reset(seed=0)
    tester = synthesized_tester(e)
    e.step({TESTER: tester(), SYSTEM: 0})
    assert e.render() is None
    e.close()
    assert len(shown) >= 3 and all(len(s) == 3 and s[2] == 3 for s in shown)  # reset, the round's steps, render()


def test_human_rendering_without_pygame_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    import gymnasium

    monkeypatch.setitem(sys.modules, "pygame", None)  # import pygame now fails
    with pytest.raises(gymnasium.error.DependencyNotInstalled, match=r"flowtest\[render\]"):
        multiagent.raw_env(test="small-reactive", render_mode="human")
