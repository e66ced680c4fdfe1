"""The NumPy vector env gives exactly the trajectories of the single env.

Every comparison runs the vector env (``vectorization_mode="vector_entry_point"``) next
to a ``SyncVectorEnv`` of the single env (``vectorization_mode="sync"``) on the same
actions: random legal actions, and often any action at all (restricted moves, moves that
do not exist), over many autoresets (short step budgets force truncations too).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

import flowtest_env
from flowtest_env.artifacts import builtin_game
from flowtest_env.compiled import OUTCOMES, compile_test
from flowtest_env.encoding import make_encoder
from flowtest_env.envs import BUILTIN_ENVS, FlowTestEnv
from flowtest_env.vector import PoolVectorEnv

BUILTIN_IDS = [f"FlowTest-{stem}-v0" for stem, _ in BUILTIN_ENVS.values()]
GRID_PROBLEMS = [p for p in BUILTIN_ENVS if builtin_game(p, "instantaneous").is_grid]


def _actions(rng: np.random.Generator, mask: np.ndarray, n_actions: int, p_any: float) -> np.ndarray:
    """Per env: a random legal action, or with probability ``p_any`` any action index."""
    legal = np.argmax(rng.random(mask.shape) * (mask > 0), axis=1)
    anything = rng.integers(n_actions, size=mask.shape[0])
    return np.where(rng.random(mask.shape[0]) < p_any, anything, legal)


def _compare(vec: Any, ref: Any, steps: int, seed: int, p_any: float) -> dict[str, int]:
    """Step both on the same actions; assert every output equal; count episode ends."""
    rng = np.random.default_rng(seed)
    o1, i1 = vec.reset(seed=seed)
    o2, i2 = ref.reset(seed=seed)
    assert o1.dtype == o2.dtype and np.array_equal(o1, o2)
    assert data_equivalence(i1, i2, exact=True)
    n = int(vec.single_action_space.n)
    counts = {"terminated": 0, "truncated": 0, "met": 0, "violated": 0}
    for t in range(steps):
        a = _actions(rng, i1["action_mask"], n, p_any)
        o1, r1, te1, tr1, i1 = vec.step(a)
        o2, r2, te2, tr2, i2 = ref.step(a)
        assert np.array_equal(o1, o2), f"step {t}: observations differ"
        assert r1.dtype == r2.dtype and np.array_equal(r1, r2), f"step {t}: rewards {r1} != {r2}"
        assert np.array_equal(te1, te2) and np.array_equal(tr1, tr2), f"step {t}: terminated/truncated differ"
        assert data_equivalence(i1, i2, exact=True), f"step {t}: infos differ:\n{i1}\n{i2}"
        counts["terminated"] += int(te1.sum())
        counts["truncated"] += int(tr1.sum())
        if "verdict" in i1:
            names = i1["verdict"]["system_objective"][i1["_verdict"]]
            counts["met"] += int(np.sum(names == "met"))
            counts["violated"] += int(np.sum(names == "violated"))
    return counts


def test_every_id_has_a_vector_entry_point() -> None:
    for env_id in flowtest_env.ENV_IDS:
        assert gym.spec(env_id).vector_entry_point is not None, env_id


@pytest.mark.parametrize("env_id", BUILTIN_IDS)
def test_builtin_trajectories_equal_the_single_env(env_id: str) -> None:
    """Every built-in, including the test-agent (maze1, maze2, patrolling) and fuel
    (refueling, mars-exploration, patrolling) problems."""
    kw = {"max_steps": 25}
    vec = gym.make_vec(env_id, num_envs=6, vectorization_mode="vector_entry_point", **kw)
    ref = gym.make_vec(env_id, num_envs=6, vectorization_mode="sync", **kw)
    assert vec.single_observation_space == ref.single_observation_space
    assert vec.single_action_space == ref.single_action_space
    counts = _compare(vec, ref, steps=300, seed=7, p_any=0.3)
    assert counts["terminated"] + counts["truncated"] >= 6  # several autoresets per env


@pytest.mark.parametrize("problem", GRID_PROBLEMS)
def test_grid_observations_equal_the_single_env(problem: str) -> None:
    env_id = f"FlowTest-{BUILTIN_ENVS[problem][0]}-v0"
    kw = {"obs_kind": "grid", "max_steps": 30}
    vec = gym.make_vec(env_id, num_envs=4, vectorization_mode="vector_entry_point", **kw)
    ref = gym.make_vec(env_id, num_envs=4, vectorization_mode="sync", **kw)
    assert vec.single_observation_space == ref.single_observation_space
    _compare(vec, ref, steps=150, seed=3, p_any=0.5)


def test_runs_meet_and_violate_objectives_in_the_comparison() -> None:
    """The comparisons above reach both verdicts, not only truncations: fuel runs out
    on refueling under random moves, and maze2's goal is met with the default budget."""
    vec = gym.make_vec("FlowTest-Refueling-v0", num_envs=8, vectorization_mode="vector_entry_point")
    ref = gym.make_vec("FlowTest-Refueling-v0", num_envs=8, vectorization_mode="sync")
    assert _compare(vec, ref, steps=200, seed=1, p_any=0.2)["violated"] > 0
    vec = gym.make_vec("FlowTest-Example1-v0", num_envs=8, vectorization_mode="vector_entry_point")
    ref = gym.make_vec("FlowTest-Example1-v0", num_envs=8, vectorization_mode="sync")
    assert _compare(vec, ref, steps=200, seed=2, p_any=0.0)["met"] > 0


@pytest.mark.parametrize("problem", list(BUILTIN_ENVS))
def test_compiled_tables_follow_the_game_rules(problem: str) -> None:
    """Exhaustive: every reachable configuration and action of the compiled tables
    against :meth:`TestGame.step` (next configuration, refused, outcome, mask)."""
    game = builtin_game(problem, "instantaneous")
    ct = compile_test(game, make_encoder(game, "flat"))
    run0 = game.reset()
    assert ct.run_state(ct.initial).key() == run0.key()
    for z in range(ct.n_z):
        run = ct.run_state(z)
        assert OUTCOMES[int(ct.outcome[z])] == run.outcome
        assert np.array_equal(ct.mask[z], game.action_mask(run))
        if run.done:
            continue
        for a in range(game.n_actions):
            r = run.copy()
            out = game.step(r, a)
            nz = int(ct.next_z[z, a])
            assert ct.run_state(nz).key() == r.key(), (problem, z, a)
            assert bool(ct.refused[z, a]) == (out.restricted or out.invalid)
            assert OUTCOMES[int(ct.outcome[nz])] == r.outcome
            assert bool(ct.restricted[z]) == (r.restrictions == 1)


def test_random_grid_pool_trajectories_equal_the_single_env(pool_cache: Path) -> None:
    """Several random-grid tests in one batch, each episode's test drawn as the single
    env draws it."""
    kw = {"seeds": [0, 1, 2], "max_steps": 20}
    vec = gym.make_vec("FlowTest-RandomGrid-v0", num_envs=6, vectorization_mode="vector_entry_point", **kw)
    ref = gym.make_vec("FlowTest-RandomGrid-v0", num_envs=6, vectorization_mode="sync", **kw)
    seen: set[int] = set()
    rng = np.random.default_rng(0)
    o1, i1 = vec.reset(seed=11)
    o2, i2 = ref.reset(seed=11)
    for t in range(200):
        names = [e.unwrapped.artifact.name for e in ref.envs]
        assert names == [vec.games[k].artifact.name for k in vec.test_index.tolist()], t
        seen.update(vec.test_index.tolist())
        a = _actions(rng, i1["action_mask"], 5, 0.3)
        o1, r1, te1, tr1, i1 = vec.step(a)
        o2, r2, te2, tr2, i2 = ref.step(a)
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
        assert np.array_equal(te1, te2) and np.array_equal(tr1, tr2)
        assert data_equivalence(i1, i2, exact=True)
    assert len(seen) == 3


def test_mixed_pool_of_every_builtin_steps_each_like_its_single_env() -> None:
    """All built-ins in one batch (fixed assignment; actions and flat observations padded
    to the largest): env ``i`` follows a single env of test ``i % 9`` step by step."""
    problems = list(BUILTIN_ENVS)
    games = [builtin_game(p, "instantaneous") for p in problems]
    n_envs = 2 * len(problems)
    vec = PoolVectorEnv(n_envs, games, assignment="fixed", max_steps=40)
    singles = [FlowTestEnv(problems[i % len(problems)], max_steps=40) for i in range(n_envs)]
    rng = np.random.default_rng(5)
    obs, infos = vec.reset(seed=0)
    outs = [e.reset(seed=i) for i, e in enumerate(singles)]
    restarted = 0
    for t in range(200):
        for i, (o, info) in enumerate(outs):
            k = o.size
            assert np.array_equal(obs[i, :k], o) and not obs[i, k:].any(), (t, i)
            m = info["action_mask"]
            assert np.array_equal(infos["action_mask"][i, : m.size], m) and not infos["action_mask"][i, m.size :].any()
        own = np.array([e.game.n_actions for e in singles])
        a = np.minimum(_actions(rng, infos["action_mask"], vec.pool.n_actions, 0.3), own - 1)
        obs, rew, term, trunc, infos = vec.step(a)
        new = []
        for i, e in enumerate(singles):
            if e.run.done or e.run.steps >= e.max_steps:  # the vector env reset it at this step
                o, info = e.reset()
                assert rew[i] == 0.0 and not term[i] and not trunc[i]
                restarted += 1
            else:
                o, r, te, tr, info = e.step(int(a[i]))
                assert (rew[i], term[i], trunc[i]) == (r, te, tr), (t, i)
                if te or tr:
                    assert infos["_verdict"][i]
                    assert {k: infos["verdict"][k][i] for k in info["verdict"]} == info["verdict"]
            new.append((o, info))
        outs = new
    assert restarted > 0


def test_actions_beyond_a_tests_own_are_refused_in_a_mixed_pool() -> None:
    games = [builtin_game("beaver-rescue", "instantaneous"), builtin_game("maze2", "instantaneous")]
    vec = PoolVectorEnv(2, games, assignment="fixed")
    assert vec.single_action_space.n == 5 and games[0].n_actions == 3
    obs, _ = vec.reset(seed=0)
    obs2, rew, _, _, infos = vec.step(np.array([4, 4]))
    assert np.array_equal(obs2[0], obs[0]) and rew[0] == pytest.approx(-0.06)
    assert vec.verdicts()["blocked_attempts"][0] == 1 and infos["action_mask"][0, 3:].sum() == 0


def test_invalid_actions_are_rejected_like_the_single_env() -> None:
    vec = gym.make_vec("FlowTest-Maze2-v0", num_envs=3, vectorization_mode="vector_entry_point")
    with pytest.raises(gym.error.ResetNeeded):
        vec.step(np.zeros(3, dtype=np.int64))
    vec.reset(seed=0)
    for bad in (np.array([0, 1, 9]), np.array([0, -1, 2]), np.array([0.5, 1, 2]), np.array(["N", "S", "E"]), np.zeros(2, dtype=np.int64)):
        with pytest.raises(gym.error.InvalidAction):
            vec.step(bad)
    single = gym.make("FlowTest-Maze2-v0")
    single.reset(seed=0)
    with pytest.raises(gym.error.InvalidAction):
        single.unwrapped.step(9)
    for bad in (np.array([4.0, 4.0, 4.0]), np.array([True, False, True])):  # refused as the single env refuses 1.0 and True
        with pytest.raises(gym.error.InvalidAction):
            vec.step(bad)
    for bad_one in (1.0, True):
        with pytest.raises(gym.error.InvalidAction):
            single.unwrapped.step(bad_one)
    vec.step([4, 4, 4])  # a list of Python integers is integers


@pytest.mark.parametrize("dtype", [np.int8, np.uint8, np.int16, np.int32, np.uint32, np.int64, np.uint64])
def test_actions_of_every_integer_dtype_step_alike(dtype: Any) -> None:
    """The range check reads a signed action as unsigned (one pass): a negative one of any
    width is refused, and every integer dtype steps as int64 does."""
    ref = gym.make_vec("FlowTest-Maze2-v0", num_envs=4, vectorization_mode="vector_entry_point")
    vec = gym.make_vec("FlowTest-Maze2-v0", num_envs=4, vectorization_mode="vector_entry_point")
    ref.reset(seed=3)
    vec.reset(seed=3)
    if np.dtype(dtype).kind == "i":
        with pytest.raises(gym.error.InvalidAction, match="action -1"):
            vec.step(np.array([0, 1, -1, 2], dtype=dtype))
    with pytest.raises(gym.error.InvalidAction, match="action 5"):
        vec.step(np.array([0, 5, 1, 2], dtype=dtype))
    rng = np.random.default_rng(0)
    for _ in range(40):
        a = rng.integers(5, size=4)
        out, expected = vec.step(a.astype(dtype)), ref.step(a)
        assert data_equivalence(out, expected, exact=True)


def test_bad_arguments_raise_clear_errors() -> None:
    with pytest.raises(ValueError, match="instantaneous and the accumulative"):  # one setting per pool
        PoolVectorEnv(2, [builtin_game("small-reactive", "accumulative"), builtin_game("maze2", "instantaneous")])
    with pytest.raises(ValueError, match="obs_kind"):
        gym.make_vec("FlowTest-Maze2-v0", num_envs=2, vectorization_mode="vector_entry_point", obs_kind="pixels")
    with pytest.raises(ValueError, match="num_envs"):
        gym.make_vec("FlowTest-Maze2-v0", num_envs=0, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match="assignment"):
        PoolVectorEnv(2, [builtin_game("maze2", "instantaneous")], assignment="round-robin")
    with pytest.raises(ValueError, match=r"max_steps must be below 2\*\*32"):  # the verdict's 32-bit counters
        PoolVectorEnv(2, ["maze2"], max_steps=2**32)


def test_render_draws_each_env() -> None:
    vec = gym.make_vec("FlowTest-Maze2-v0", num_envs=2, vectorization_mode="vector_entry_point", render_mode="rgb_array")
    vec.reset(seed=0)
    frames = vec.render()
    single = gym.make("FlowTest-Maze2-v0", render_mode="rgb_array")
    single.reset(seed=0)
    assert len(frames) == 2 and np.array_equal(frames[0], single.render())


def test_mask_in_the_observation_like_the_single_env_wrapper() -> None:
    from flowtest_env import ActionMaskObservation
    from flowtest_env.vector import VectorActionMaskObservation

    vec = VectorActionMaskObservation(gym.make_vec("FlowTest-Maze1-v0", num_envs=4, vectorization_mode="vector_entry_point"))
    ref = gym.make_vec("FlowTest-Maze1-v0", num_envs=4, vectorization_mode="sync", wrappers=[ActionMaskObservation])
    assert vec.single_observation_space == ref.single_observation_space
    rng = np.random.default_rng(0)
    o1, _ = vec.reset(seed=4)
    o2, _ = ref.reset(seed=4)
    assert data_equivalence(o1, o2, exact=True)
    for _ in range(120):
        a = _actions(rng, o1["action_mask"], 5, 0.2)
        o1, r1, te1, tr1, _ = vec.step(a)
        o2, r2, te2, tr2, _ = ref.step(a)
        assert data_equivalence((o1, r1, te1, tr1), (o2, r2, te2, tr2), exact=True)


def test_a_test_chooser_picks_each_new_episodes_test() -> None:
    """A trainer's chooser (``set_test_chooser``) decides the test of every episode that starts,
    at reset and at the autoreset after an episode ends; ``None`` gives the choice back; a
    chooser that returns no valid test index is refused with a clear error."""
    env = PoolVectorEnv(4, ["small-reactive", "maze1"], assignment="fixed")
    asked: list[list[int]] = []

    def chooser(envs: np.ndarray) -> np.ndarray:
        asked.append(envs.tolist())
        return np.ones(envs.size, dtype=np.int64)

    env.set_test_chooser(chooser)
    _, infos = env.reset(seed=0)
    assert env.test_index.tolist() == [1, 1, 1, 1] and asked == [[0, 1, 2, 3]]
    rng = np.random.default_rng(0)
    for _ in range(200):  # until some episode ends and the next one starts
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in infos["action_mask"]])
        _, _, term, trunc, infos = env.step(actions)
        if len(asked) > 1:
            break
    assert len(asked) > 1 and env.test_index.tolist() == [1, 1, 1, 1]
    env.set_test_chooser(None)
    env.reset(seed=0)
    assert env.test_index.tolist() == [0, 1, 0, 1]  # the fixed assignment again
    for bad in (lambda e: np.full(e.size, 2), lambda e: np.zeros(1, dtype=np.int64), lambda e: np.full(e.size, 0.5)):
        env.set_test_chooser(bad)
        with pytest.raises(ValueError, match="test chooser must return one test index"):
            env.reset(seed=0)
