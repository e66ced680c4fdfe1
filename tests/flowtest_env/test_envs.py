"""The single-agent FlowTest environments: API checks over the whole registry, the test
game's rules and guarantees, artifacts, rendering.

Fast by default; the artifact-equality tests of the large problems are marked slow.
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import EnvSpec
from gymnasium.utils.env_checker import check_env, data_equivalence

import flowtest_env
from flowtest_env import ActionMaskObservation
from flowtest_env.artifacts import SOLVER_KEY, artifact_path, builtin_game, made_with, synthesize_artifact
from flowtest_env.envs import BUILTIN_ENVS
from flowtest_env.game import MET, RunState, TestGame

ROOT = Path(__file__).resolve().parents[2]


def _problem_of(env_id: str) -> str | None:
    """The built-in problem of a registered ID (``None`` for the random grid)."""
    for name, (stem, _) in BUILTIN_ENVS.items():
        if env_id == f"FlowTest-{stem}-v0":
            return name
    return None


def _no_artifact(name: str) -> pytest.MarkDecorator:
    """Skip mark for a built-in without a shipped artifact: making its env would run the
    synthesis first (minutes for mars-exploration), which a test must not."""
    return pytest.mark.skip(
        reason=f"no shipped artifact flowtest_env/artifacts/{name}.json (its synthesis is too slow for a test run); "
        f"`python -m experiments.tools.build_artifacts {name}` builds it and these tests then run"
    )


def _param(env_id: str) -> Any:
    name = _problem_of(env_id)
    if name is not None and not artifact_path(name).exists():
        return pytest.param(env_id, marks=_no_artifact(name))
    return env_id


IDS = [_param(i) for i in flowtest_env.ENV_IDS]
GRID_IDS = [_param(i) for i in flowtest_env.ENV_IDS if i not in ("FlowTest-BeaverRescue-v0", "FlowTest-MotionPrimitives-v0")]


def _rollout(env: gym.Env, n_steps: int, seed: int) -> list[Any]:
    """``n_steps`` of random masked actions, resetting at episode ends; everything seen."""
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    seen: list[Any] = [(obs, info)]
    for _ in range(n_steps):
        action = int(rng.choice(np.flatnonzero(info["action_mask"])))
        obs, reward, terminated, truncated, info = env.step(action)
        seen.append((action, obs, reward, terminated, truncated, info))
        if terminated or truncated:
            obs, info = env.reset()
            seen.append((obs, info))
    return seen


# ---------------------------------------------------------------- registry-wide API


def test_registry_lists_every_builtin_and_the_random_grid() -> None:
    stems = {stem for stem, _ in BUILTIN_ENVS.values()}
    assert {f"FlowTest-{s}-v0" for s in stems} | {"FlowTest-RandomGrid-v0"} == set(flowtest_env.ENV_IDS)
    assert all(i in gym.registry for i in flowtest_env.ENV_IDS)
    assert len(flowtest_env.ENV_IDS) == 10
    for name, (stem, cls) in BUILTIN_ENVS.items():  # mars-exploration too, shipped or not
        spec = gym.spec(f"FlowTest-{stem}-v0")
        assert spec.entry_point == f"flowtest_env.envs:{cls.__name__}" and spec.kwargs["test"] == name
    for env_id in flowtest_env.ENV_IDS:  # plain-data kwargs
        kwargs = gym.spec(env_id).kwargs
        assert json.loads(json.dumps(kwargs)) == kwargs


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_env_checker(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, render_mode="rgb_array")
        check_env(env.unwrapped, skip_render_check=False)


@pytest.mark.parametrize("env_id", GRID_IDS)
def test_gymnasium_env_checker_grid_observations(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, obs_kind="grid")
        assert env.observation_space.dtype == np.uint8 and len(env.observation_space.shape) == 3
        check_env(env.unwrapped)


@pytest.mark.parametrize("env_id", IDS)
def test_stable_baselines3_env_checker(env_id: str) -> None:
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sb3_checker.check_env(gym.make(env_id), warn=True)
        sb3_checker.check_env(ActionMaskObservation(gym.make(env_id)), warn=True)


def test_stable_baselines3_accepts_grid_images() -> None:
    """The image encoding is uint8 in [0, 255], channel first. sb3's only remarks are
    about its default CnnPolicy, which wants 36x36 pixels and guesses the channel axis
    from the smallest dimension (14 channels on 5x5 cells defeat the guess): a small
    grid needs a custom features extractor, as MiniGrid's 7x7 images do."""
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_checker.check_env(gym.make("FlowTest-Maze2-v0", obs_kind="grid"), warn=True)
    advisory = ("minimal resolution", "Treating image space as channels-last")
    assert caught and all(any(a in str(w.message) for a in advisory) for w in caught)


@pytest.mark.parametrize("env_id", IDS)
def test_200_step_determinism(env_id: str) -> None:
    a = _rollout(gym.make(env_id), 200, seed=7)
    b = _rollout(gym.make(env_id), 200, seed=7)
    assert data_equivalence(a, b)


@pytest.mark.parametrize("env_id", IDS)
def test_pickling_keeps_the_run(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    _, info = env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(3):
        _, _, term, trunc, info = env.step(int(rng.choice(np.flatnonzero(info["action_mask"]))))
        if term or trunc:
            _, info = env.reset()
    env.render()
    clone = pickle.loads(pickle.dumps(env))
    for _ in range(20):
        action = int(rng.choice(np.flatnonzero(info["action_mask"])))
        out1, out2 = env.step(action), clone.step(action)
        assert data_equivalence(out1, out2)
        info = out1[4]
        if out1[2] or out1[3]:
            r1, r2 = env.reset(seed=5), clone.reset(seed=5)
            assert data_equivalence(r1, r2)
            info = r1[1]
    assert np.array_equal(env.render(), clone.render())


def _vector_run(env_id: str, mode: str, n_steps: int) -> list[Any]:
    """``n_steps`` of a 2-env vector env of ``mode``: every output, with seeded random
    masked actions (the masks come from the vector env's own infos)."""
    envs = gym.make_vec(env_id, num_envs=2, vectorization_mode=mode)
    rng = np.random.default_rng(0)
    try:
        assert envs.single_action_space == gym.spaces.Discrete(envs.single_action_space.n)
        obs, info = envs.reset(seed=[1, 2])
        assert obs.shape == (2, *envs.single_observation_space.shape)
        seen: list[Any] = [(obs, info)]
        for _ in range(n_steps):
            masks = info["action_mask"]
            actions = np.array([int(rng.choice(np.flatnonzero(m))) if m.any() else 0 for m in masks])
            out = envs.step(actions)
            obs, rew, term, trunc, info = out
            assert obs.shape[0] == 2 and rew.dtype.kind == "f" and term.dtype == bool
            seen.append((actions, *out))
        return seen
    finally:
        envs.close()


@pytest.mark.parametrize("env_id", IDS)
def test_vector_envs_sync_and_async_agree(env_id: str) -> None:
    """Sync and async vector envs (subprocesses: the env and its artifact cross a
    process boundary) play the same 60 steps, episode ends and autoresets included; the
    first sub-env starts as a single env reset with the same seed."""
    sync = _vector_run(env_id, "sync", 60)
    asyn = _vector_run(env_id, "async", 60)
    assert data_equivalence(sync, asyn)
    single_obs, _ = gym.make(env_id).reset(seed=1)
    assert np.array_equal(sync[0][0][0], single_obs)


@pytest.mark.parametrize("env_id", IDS)
def test_spec_round_trips_through_json(env_id: str) -> None:
    env = gym.make(env_id)
    text = env.spec.to_json()
    json.loads(text)
    spec = EnvSpec.from_json(text)
    assert spec == env.spec
    again = gym.make(spec)
    assert again.observation_space == env.observation_space


# ---------------------------------------------------------------- info, masks, rewards


@pytest.mark.parametrize("env_id", IDS)
def test_info_contract_and_three_masks(env_id: str) -> None:
    env = gym.make(env_id)
    wrapped = ActionMaskObservation(gym.make(env_id))
    obs, info = env.reset(seed=0)
    wobs, _ = wrapped.reset(seed=0)
    rng = np.random.default_rng(0)
    game = env.unwrapped.game
    for _ in range(300):
        mask = info["action_mask"]
        assert mask.dtype == np.int8 and mask.shape == (env.action_space.n,)
        assert np.array_equal(mask.astype(bool), env.unwrapped.action_masks())
        assert np.array_equal(mask, wobs["action_mask"]) and np.array_equal(obs, wobs["observation"])
        state = info["system_state"]
        if game.ts.kind == "grid":
            assert isinstance(state, list) and len(state) == 2 and all(isinstance(x, int) for x in state)
        elif game.ts.kind == "fuel":
            assert isinstance(state, list) and isinstance(state[0], list) and isinstance(state[1], int)
        else:
            assert isinstance(state, str)
        action = int(rng.choice(np.flatnonzero(mask)))
        obs, reward, term, trunc, info = env.step(action)
        wobs, _, _, _, _ = wrapped.step(action)
        if term or trunc:
            v = info["verdict"]
            assert set(v) >= {"system_objective", "test_objective_realized", "restrictions", "steps"}
            assert v["system_objective"] in ("met", "violated", "open")
            assert isinstance(v["test_objective_realized"], bool) and isinstance(v["restrictions"], int)
            assert (v["system_objective"] == "open") == trunc
            obs, info = env.reset()
            wobs, _ = wrapped.reset()
        else:
            assert "verdict" not in info


def _path_to(game: TestGame, wanted: Any) -> list[int]:
    """Legal actions from reset to the nearest game state where ``wanted(run)`` holds."""
    from collections import deque

    root = game.reset()
    queue: deque[tuple[RunState, list[int]]] = deque([(root, [])])
    seen = {root.key()}
    while queue:
        run, path = queue.popleft()
        if wanted(run):
            return path
        for a in np.flatnonzero(game.action_mask(run)):
            nxt = run.copy()
            game.step(nxt, int(a))
            if not nxt.done and nxt.key() not in seen:
                seen.add(nxt.key())
                queue.append((nxt, path + [int(a)]))
    raise AssertionError("no such state")


def test_rewards_goal_step_cost_and_refused_moves() -> None:
    env = gym.make("FlowTest-SmallReactive-v0")
    _, info = env.reset(seed=0)
    game = env.unwrapped.game
    path = _path_to(game, lambda r: bool(game.restricted_bits_of(r) & game.exists_bits[r.system]))
    for a in path:
        _, reward, _, _, info = env.step(a)
        assert reward == pytest.approx(-0.01)
    run = env.unwrapped.run
    refused = [a for a in range(game.n_slots) if (game.restricted_bits_of(run) >> a) & 1 and game.slot_move[run.system, a] >= 0]
    before = info["system_state"]
    _, reward, term, _, info = env.step(refused[0])
    assert info["system_state"] == before and not term
    assert reward == pytest.approx(-0.01 - 0.05)
    assert env.unwrapped.verdict()["blocked_attempts"] == 1
    assert env.unwrapped.verdict()["restrictions"] >= 1
    for _ in range(50):
        _, reward, term, trunc, info = env.step(_greedy_to_goal(game, env.unwrapped.run))
        if term:
            break
    assert term and info["verdict"]["system_objective"] == "met" and info["verdict"]["test_objective_realized"]
    assert reward == pytest.approx(1.0 - 0.01)


def _greedy_to_goal(game: TestGame, run: RunState) -> int:
    """A legal action on a shortest path to a met state in the game's state space."""
    from collections import deque

    start = run.copy()
    queue: deque[tuple[RunState, int]] = deque([(start, -1)])
    seen = {start.key()}
    while queue:
        r, first = queue.popleft()
        for a in np.flatnonzero(game.action_mask(r)):
            r2 = r.copy()
            game.step(r2, int(a))
            f = int(a) if first < 0 else first
            if r2.outcome == MET:
                return f
            if not r2.done and r2.key() not in seen:
                seen.add(r2.key())
                queue.append((r2, f))
    raise AssertionError("no way to the goal")


def test_violation_ends_the_run_with_a_penalty() -> None:
    env = gym.make("FlowTest-Refueling-v0")
    _, info = env.reset(seed=0)
    stay = env.unwrapped.game.stay_action
    rng = np.random.default_rng(1)
    for _ in range(100):
        moves = [a for a in np.flatnonzero(info["action_mask"]) if a != stay]
        _, reward, term, trunc, info = env.step(int(rng.choice(moves)) if moves else stay)
        if term:
            break
    assert term and info["verdict"]["system_objective"] in ("violated", "met")
    if info["verdict"]["system_objective"] == "violated":
        assert reward <= -1.0


def test_observations_never_reveal_the_test_history() -> None:
    """Two runs that differ only in the test part of the history look the same."""
    game = builtin_game("maze2")
    from flowtest_env.encoding import make_encoder

    comps = game.artifact.histories.components
    same_sys = [(h1, h2) for h1 in range(len(comps)) for h2 in range(len(comps)) if h1 < h2 and comps[h1][0] == comps[h2][0]]
    assert same_sys
    for kind in ("flat", "grid"):
        enc = make_encoder(game, kind)
        for h1, h2 in same_sys:
            r1 = game.reset()
            r2 = r1.copy()
            r1.history, r2.history = h1, h2
            assert np.array_equal(enc.encode(r1), enc.encode(r2))
        names = getattr(enc, "channels", [])
        assert not any(n.startswith("I") for n in names)


@pytest.mark.parametrize("name", ["example1", "small-reactive", "refueling", "maze2", "patrolling"])
def test_grid_observation_shows_exactly_the_restrictions_in_force(name: str) -> None:
    """At every reachable state, the wall and door planes at the system's cell show
    exactly the moves restricted now (the test agent's block aside: it is the
    ``test_agent`` plane), and the flat encoding carries the same planes. On fuel grids
    the planes must show a static cut only at the fuel levels where it holds."""
    from flowtest_env.encoding import make_encoder

    if not artifact_path(name).exists():
        pytest.skip("artifact not shipped")
    game = builtin_game(name)
    enc = make_encoder(game, "grid")
    flat = make_encoder(game, "flat")
    walls = [enc.ch[f"wall_{d}"] for d in "NSEW"]
    doors = [enc.ch[f"door_{d}"] for d in "NSEW"]
    states, _, _ = _explore(game)
    shown_without_force = 0
    for run in states:
        if run.done:
            continue
        obs = enc.planes(run)
        spatial = obs[: enc.n_spatial].ravel().astype(np.float32) / 255
        assert np.array_equal(flat.encode(run)[: spatial.size], spatial), "flat and grid encodings disagree"
        r, c = game.ts.places[game.place_list[run.system]]
        in_force = game.restricted_bits[run.history][run.system] & game.exists_bits[run.system]
        for k in range(4):
            shown = bool(obs[walls[k], r, c] or obs[doors[k], r, c])
            if game.slot_move[run.system, k] < 0:
                continue  # no move that way: a wall of the map may still be drawn
            assert shown == bool((in_force >> k) & 1), (name, game.state_json(run.system), "NSEW"[k])
            shown_without_force += shown and not (in_force >> k) & 1
    assert shown_without_force == 0


def test_permanent_walls() -> None:
    """Tied walls (refueling, patrolling's physical walls, plain grids) are walls of the map;
    per-fuel-level cuts (patrolling with ``tie_places="none"``, the built-in before it took
    paper-examples.md's physical walls) are not, since the same cell edge is open at other
    reachable fuel levels."""
    from dataclasses import replace

    from synthesis.artifacts.artifact import artifact_of
    from synthesis.artifacts.summary import summary_of
    from synthesis.pipeline import synthesize
    from synthesis.problems.builtins import patrolling

    for name in ("example1", "refueling", "patrolling"):
        game = builtin_game(name)
        assert game.artifact.strategy.static_obstacles.any()
        assert np.array_equal(game.permanent_wall, game.artifact.strategy.static_obstacles)
    per_level = synthesize(replace(patrolling(), tie_places="none", bidirectional_cuts=False))
    game = TestGame(artifact_of(per_level, summary_of(per_level)))
    static = game.artifact.strategy.static_obstacles
    assert static.any() and not game.permanent_wall.any()
    ts = game.ts
    # (5,4) -> W is cut at some fuel levels and open at a reachable other one
    west = [m for m in range(ts.n_moves) if ts.states[ts.src[m]][0] == (5, 4) and ts.action[m] == "W"]
    assert any(static[m] for m in west) and any(not static[m] for m in west)


def test_accumulative_setting_shows_more_but_enforces_the_same() -> None:
    inst = gym.make("FlowTest-SmallReactive-v0", obs_kind="grid")
    acc = gym.make("FlowTest-SmallReactive-v0", obs_kind="grid", setting="accumulative")
    o1, i1 = inst.reset(seed=0)
    o2, i2 = acc.reset(seed=0)
    shown_more = False
    for action in (4, 0, 2, 4, 1, 2, 2, 0, 2):
        if not i1["action_mask"][action]:
            action = 4
        o1, r1, t1, _, i1 = inst.step(action)
        o2, r2, t2, _, i2 = acc.step(action)
        assert np.array_equal(i1["action_mask"], i2["action_mask"]) and r1 == r2 and t1 == t2
        shown_more |= int(o2[5:9].sum()) > int(o1[5:9].sum())
        assert np.all(o2[5:9] >= o1[5:9])
        if t1:
            break
    assert shown_more


# ---------------------------------------------------------------- the guarantees


def _explore(game: TestGame) -> tuple[list[RunState], np.ndarray, np.ndarray]:
    """Every game state the synthesized test can reach against any system behaviour
    (every legal action; refused ones are stays), with the edges between them."""
    root = game.reset()
    index = {root.key(): 0}
    states, stack, src, dst = [root], [root], [], []
    while stack:
        run = stack.pop()
        if run.done:
            continue
        i = index[run.key()]
        for a in np.flatnonzero(game.action_mask(run)):
            nxt = run.copy()
            game.step(nxt, int(a))
            k = nxt.key()
            if k not in index:
                index[k] = len(states)
                states.append(nxt)
                stack.append(nxt)
            src.append(i)
            dst.append(index[k])
    return states, np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64)


@pytest.mark.parametrize("name", [n if artifact_path(n).exists() else pytest.param(n, marks=_no_artifact(n)) for n in BUILTIN_ENVS])
def test_synthesized_test_keeps_its_guarantees_exhaustively(name: str) -> None:
    """Against every system behaviour (exhaustive over the reachable game states, so over
    every action sequence of any length): every run that meets the system objective has
    realized the test objective, and from every reachable live state the system can
    still meet its objective (no trap). A violation is then always the system's own
    doing (running dry on a fuel grid); without fuel none is reachable at all."""
    game = builtin_game(name)
    states, src, dst = _explore(game)
    met = np.array([s.outcome == MET for s in states])
    live = np.array([not s.done for s in states])
    assert met.any()
    for s in states:
        if s.outcome == MET:
            assert game.test_accepting[s.history], f"{name}: goal reached at {game.state_json(s.system)} without the test objective"
    if game.ts.kind != "fuel":
        assert all(s.outcome != "violated" for s in states), f"{name}: a run is violated"
    else:
        assert any(s.outcome == "violated" for s in states), "the exploration reaches the system's own failures too"
    can = met.copy()
    while True:
        grow = src[can[dst] & ~can[src]]
        if grow.size == 0:
            break
        can[grow] = True
    trapped = [game.state_json(s.system) for s, ok in zip(states, can & live | ~live, strict=True) if not ok]
    assert not trapped, f"{name}: the system is trapped at {trapped[:5]}"


@pytest.mark.parametrize("env_id", ["FlowTest-SmallReactive-v0", "FlowTest-Maze2-v0"])
def test_random_systems_through_the_gymnasium_api(env_id: str) -> None:
    """The same guarantee end to end through ``gym.make``, ``step`` and the verdict: 300
    random systems (any action, masked ones included) to the end of the step budget.
    A met run has realized the test objective; none is violated; and the synthesized
    test lets some meet it (it restricts, it does not forbid)."""
    env = gym.make(env_id)
    rng = np.random.default_rng(0)
    outcomes: dict[str, int] = {"met": 0, "open": 0}
    for episode in range(300):
        _, info = env.reset(seed=episode)
        done = False
        while not done:
            _, _, terminated, truncated, info = env.step(int(rng.integers(env.action_space.n)))
            done = terminated or truncated
        v = info["verdict"]
        assert v["system_objective"] in outcomes, v
        outcomes[v["system_objective"]] += 1
        if v["system_objective"] == "met":
            assert v["test_objective_realized"], v
        assert v["steps"] <= env.unwrapped.max_steps
    assert outcomes["met"] > 0


def test_every_system_action_sequence_on_small_reactive() -> None:
    """Literally every action sequence (masked actions included) up to 6 steps."""
    game = builtin_game("small-reactive")
    frontier = [game.reset()]
    ended = 0
    for _ in range(6):
        nxt = []
        for run in frontier:
            for a in range(game.n_actions):
                r = run.copy()
                game.step(r, a)
                if r.done:
                    ended += 1
                    assert r.outcome == MET and game.test_accepting[r.history]
                else:
                    nxt.append(r)
        frontier = nxt
    assert ended > 0


# ---------------------------------------------------------------- artifacts


COLD_MAKE = """
import time
cpu = time.thread_time()
import gymnasium, flowtest_env
t = time.perf_counter()
gymnasium.make({env_id!r}).reset(seed=0)
print(time.perf_counter() - t, time.thread_time() - cpu)
"""


@pytest.mark.parametrize("env_id", [_param(i) for i in flowtest_env.ENV_IDS if _problem_of(i) is not None])
def test_make_is_fast_cold(env_id: str) -> None:
    """``make`` + ``reset`` of a built-in env in a fresh interpreter takes under 1 s of
    wall time, and importing ``flowtest_env`` (gymnasium, numpy and synthesis included)
    on top of it under 1 s of CPU time (wall time there depends on what else the two
    shared cores run: a fresh interpreter is retried twice before either bound fails, and
    the best of each clock is kept). Cold as an installed user meets it: Python's compiled bytecode is written and
    used (a ``PYTHONDONTWRITEBYTECODE`` in the developer's environment would make every
    start compile every source again, about 0.3 s of CPU no install pays). The CPU is the
    importing thread's: OpenBLAS's worker threads spin while they start (0.08 s on this
    machine's CPU, none of it FlowTest's work, beside the import rather than after it)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    subprocess.run([sys.executable, "-c", "import gymnasium, flowtest_env"], check=True, cwd=ROOT, env=env)  # writes the bytecode
    made, cpu = float("inf"), float("inf")
    for _ in range(3):  # the best of up to three fresh interpreters: the other core's work slows both clocks
        out = subprocess.run([sys.executable, "-c", COLD_MAKE.format(env_id=env_id)], capture_output=True, text=True, check=True, cwd=ROOT, env=env)
        wall, thread_cpu = map(float, out.stdout.split())
        made, cpu = min(made, wall), min(cpu, thread_cpu)
        if made < 1.0 and cpu < 1.0:
            break
    assert made < 1.0, f"{env_id}: make + reset took {made:.2f} s cold"
    assert cpu < 1.0, f"{env_id}: import + make + reset took {cpu:.2f} s of CPU cold"


def _comparable(art: Any) -> dict[str, Any]:
    """The whole artifact as JSON data, minus what differs between two syntheses of the
    same test: the solver's statistics (``summary["stats"]``: times, node counts, rounds),
    every ``*_seconds`` figure, and the versions it was made under
    (``extras["provenance"]["versions"]``: the synthesis sources' digest changes with any
    edit; ``extras.made_with``: the solver; ``digest``: a hash of all of it, timings included;
    the answer is what is compared)."""

    def strip(x: Any) -> Any:
        if isinstance(x, dict):
            return {k: strip(v) for k, v in x.items() if not k.endswith("_seconds")}
        if isinstance(x, list):
            return [strip(v) for v in x]
        return x

    d = json.loads(json.dumps(art.to_dict()))
    d["summary"].pop("stats", None)
    d["extras"].get("provenance", {}).pop("versions", None)
    d["extras"].pop(SOLVER_KEY, None)  # provenance: which solver made it, not what it is
    d.pop("digest", None)  # over the whole document, timings included: differs whenever they do
    return strip(d)


SLOW_ARTIFACTS = {"refueling", "mars-exploration", "patrolling"}


@pytest.mark.parametrize(
    "name",
    [pytest.param(n, marks=[pytest.mark.slow] + ([] if artifact_path(n).exists() else [_no_artifact(n)])) if n in SLOW_ARTIFACTS else n for n in BUILTIN_ENVS],
)
def test_shipped_artifact_equals_a_fresh_synthesis(name: str) -> None:
    """What ``gym.make`` loads is what the synthesis computes today (the slow problems'
    syntheses are marked slow)."""
    from synthesis.artifacts.artifact import TestArtifact

    art = TestArtifact.load(artifact_path(name))
    if art.summary["status"] != "optimal":
        pytest.skip(f"{name} ships a time-limited answer: test_shipped_artifact_passes_the_checks covers it")
    made = art.extras.get(SOLVER_KEY, {})
    assert made.get("backend") and made.get("version"), f"{name}: the shipped artifact does not record its solver; rebuild with build_artifacts --force"
    fresh_art = synthesize_artifact(name)
    if made != made_with(fresh_art.summary["stats"]):
        # where several answers are optimal, another solver or release may pick another one
        # (maze2 under 1.16.0: 7 counterexamples instead of 3); what must still hold is
        # a proven optimum of the same value (the agent loop's value depends on the
        # order of its counterexamples, so only its status), and the checks, which ran
        assert fresh_art.summary["status"] == "optimal"
        if art.kind != "agent":
            for key in ("flow", "n_cuts"):
                assert fresh_art.summary[key] == art.summary[key], f"{name}: {key} differs from the shipped optimum"
        return
    shipped = _comparable(art)
    fresh = _comparable(fresh_art)
    assert shipped.keys() == fresh.keys()
    for key in shipped:  # one assertion per part, so a failure names the part
        assert shipped[key] == fresh[key], f"{name}: shipped {key!r} differs from a fresh synthesis; rebuild with build_artifacts --force"


@pytest.mark.parametrize("name", [n for n in BUILTIN_ENVS if artifact_path(n).exists()])
def test_shipped_artifact_passes_the_checks(name: str) -> None:
    """Every shipped test, optimal or time-limited, passes the independent checks on
    freshly built product graphs: bypass flow 0, the flow it claims, no trapped entry."""
    from synthesis.artifacts.artifact import TestArtifact
    from synthesis.checks.verify import check_test
    from synthesis.problems.builtins import BUILTINS
    from synthesis.problems.problem import build_graphs

    art = TestArtifact.load(artifact_path(name))
    _, products = build_graphs(BUILTINS[name]())
    assert art.strategy.blocked.shape[0] == products.virtual.n_hist
    report = check_test(products, art.strategy, art.summary["flow"], raise_on_failure=False)
    assert report.ok, f"{name}: " + "; ".join(report.problems())
    assert report.bypass_flow == art.summary["bypass_flow"] == 0


@pytest.fixture
def no_shipped_artifacts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A checkout without shipped artifacts and with an empty cache under ``tmp_path``;
    the per-process memos are emptied before and after."""
    import flowtest_env.artifacts as artifacts

    monkeypatch.setattr(artifacts, "ARTIFACT_DIR", tmp_path / "shipped")
    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path / "cache"))
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()
    yield tmp_path
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()


def test_missing_artifact_is_synthesized_once_and_cached(no_shipped_artifacts: Path) -> None:
    """How FlowTest-MarsExploration-v0 works without a shipped artifact, shown on
    small-reactive: the first ``make`` warns and synthesizes, later ones (in a new
    process: here, with the memo emptied) read the cache silently."""
    import flowtest_env.artifacts as artifacts
    from synthesis.artifacts.artifact import TestArtifact

    with pytest.warns(UserWarning, match="no shipped artifact for 'small-reactive'"):
        env = gym.make("FlowTest-SmallReactive-v0")
    cached = artifacts.builtin_cache_path("small-reactive")
    assert no_shipped_artifacts / "cache" / "builtins" / "small-reactive" in cached.parents
    assert cached.exists() and not (no_shipped_artifacts / "shipped").exists()
    artifacts.load_builtin.cache_clear()
    artifacts.builtin_game.cache_clear()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = gym.make("FlowTest-SmallReactive-v0")
    shipped = TestArtifact.load(ROOT / "flowtest_env" / "artifacts" / "small-reactive.json")
    assert _comparable(env.unwrapped.artifact) == _comparable(again.unwrapped.artifact) == _comparable(shipped)
    assert data_equivalence(_rollout(env, 30, seed=1), _rollout(again, 30, seed=1))


def test_cached_builtin_from_another_version_is_rebuilt(no_shipped_artifacts: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A built-in's cached artifact is filed under the FlowTest and solver versions: under
    another highspy (or FlowTest) version it is synthesized again, not reused."""
    import flowtest_env.artifacts as artifacts
    from synthesis.artifacts import provenance

    with pytest.warns(UserWarning, match="synthesizing it now"):
        artifacts.load_builtin("small-reactive")
    first = artifacts.builtin_cache_path("small-reactive")
    real = provenance.versions()
    for name in ("highspy", "flowtest"):
        monkeypatch.setattr(provenance, "versions", lambda name=name: dict(real, **{name: "0.0.0-other"}))
        artifacts.load_builtin.cache_clear()
        with pytest.warns(UserWarning, match="synthesizing it now"):
            artifacts.load_builtin("small-reactive")
        assert artifacts.builtin_cache_path("small-reactive") != first
    monkeypatch.setattr(provenance, "versions", lambda: real)
    artifacts.load_builtin.cache_clear()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        artifacts.load_builtin("small-reactive")  # the first one's cache again
    assert len(list(first.parent.iterdir())) == 3


TIME_LIMITED_ARTIFACTS = {"mars-exploration"}
"""Known gap (issue 12 pt 6): mars-exploration still ships the answer of a 40-minute
time-limited solve; its rebuild under a node limit is under way. Nothing else may join."""


def test_shipped_artifacts_say_how_they_were_made() -> None:
    """Every shipped artifact was made with deterministic budgets only (no wall clock,
    one HiGHS thread, a node limit) and records the versions it was made under."""
    from synthesis.artifacts.artifact import TestArtifact

    for name in BUILTIN_ENVS:
        if not artifact_path(name).exists() or name in TIME_LIMITED_ARTIFACTS:
            continue
        art = TestArtifact.load(artifact_path(name))
        prov = art.extras.get("provenance")
        assert prov is not None, f"{name}: rebuild with build_artifacts --force"
        assert prov["options"]["threads"] == 1 and prov["options"]["node_limit"] >= 1
        assert set(prov["versions"]) >= {"flowtest", "highspy"}
        assert art.summary["deterministic"] is True and art.summary["stopped_by"] in (None, "node_limit")


def test_build_artifacts_refuses_to_overwrite(tmp_path: Path) -> None:
    from experiments.tools.build_artifacts import main

    (tmp_path / "small-reactive.json").write_text("{}")
    assert main(["small-reactive", "--out", str(tmp_path)]) == 2
    assert (tmp_path / "small-reactive.json").read_text() == "{}"
    assert main(["small-reactive", "--out", str(tmp_path), "--force"]) == 0
    assert json.loads((tmp_path / "small-reactive.json").read_text())["name"] == "small-reactive"
    assert main(["no-such-problem", "--out", str(tmp_path)]) == 1


# ---------------------------------------------------------------- rendering


@pytest.mark.parametrize("env_id", IDS)
def test_render_rgb_array_and_ansi(env_id: str) -> None:
    env = gym.make(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3 and frame.shape[0] >= 32
    text_env = gym.make(env_id, render_mode="ansi")
    text_env.reset(seed=0)
    text = text_env.render()
    assert isinstance(text, str) and "step 0" in text


def test_engineer_view_shows_hidden_test_cells() -> None:
    sys_env = gym.make("FlowTest-Maze2-v0", render_mode="rgb_array")
    eng_env = gym.make("FlowTest-Maze2-v0", render_mode="rgb_array", view="engineer")
    sys_env.reset(seed=0)
    eng_env.reset(seed=0)
    a, b = sys_env.render(), eng_env.render()
    assert a.shape == b.shape and not np.array_equal(a, b)
    t = gym.make("FlowTest-Maze2-v0", render_mode="ansi", view="engineer")
    t.reset(seed=0)
    assert "?" in t.render()
    t2 = gym.make("FlowTest-Maze2-v0", render_mode="ansi")
    t2.reset(seed=0)
    assert "?" not in t2.render()


# ---------------------------------------------------------------- random grids


def test_random_grid_draws_from_its_pool_deterministically() -> None:
    env = gym.make("FlowTest-RandomGrid-v0")
    names = set()
    for seed in range(12):
        env.reset(seed=seed)
        names.add(env.unwrapped.artifact.name)
    assert len(names) > 1
    other = gym.make("FlowTest-RandomGrid-v0")
    env.reset(seed=3)
    other.reset(seed=3)
    assert env.unwrapped.artifact.name == other.unwrapped.artifact.name


def test_bad_arguments_raise_clear_errors() -> None:
    with pytest.raises(ValueError, match="obs_kind"):
        gym.make("FlowTest-Maze2-v0", obs_kind="pixels")
    with pytest.raises(ValueError, match="graph"):
        gym.make("FlowTest-BeaverRescue-v0", obs_kind="grid")
    with pytest.raises(ValueError, match="setting"):
        gym.make("FlowTest-Maze2-v0", setting="sometimes")
    with pytest.raises(ValueError, match="family"):
        gym.make("FlowTest-RandomGrid-v0", family="liveness")
    env = gym.make("FlowTest-Maze2-v0")
    env.reset(seed=0)
    with pytest.raises(gym.error.InvalidAction):
        env.unwrapped.step(9)


def test_human_rendering_through_gymnasium(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("pygame")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium says it applies HumanRendering for us
        env = gym.make("FlowTest-Maze2-v0", render_mode="human")
    assert isinstance(env, gym.wrappers.HumanRendering)
    env.reset(seed=0)
    env.step(4)
    env.close()
