"""The torch vector env (flowtest_env.torch_vector) on torch's CPU device gives exactly the
NumPy env's trajectories.

Every comparison steps the torch env next to a reference on the same actions (random legal
ones, and often any action at all: restricted moves, moves that do not exist), over many
episode ends (short step budgets force truncations too): the NumPy vector env
(``vectorization_mode="vector_entry_point"``) where it has the option, else a
``SyncVectorEnv`` of the single env. Compared at every step: observations (and the compact
form, expanded), rewards (float64 tables: bit for bit), terminated, truncated, masks,
verdicts and the test each env plays. Skipped when torch is not installed.
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

torch = pytest.importorskip("torch")

import flowtest_env  # noqa: E402
from flowtest_env import draws  # noqa: E402
from flowtest_env import torch_vector as tv  # noqa: E402
from flowtest_env.artifacts import builtin_game  # noqa: E402
from flowtest_env.compiled import OUTCOMES  # noqa: E402
from flowtest_env.encoding import make_encoder  # noqa: E402
from flowtest_env.envs import BUILTIN_ENVS  # noqa: E402
from flowtest_env.vector import PoolVectorEnv  # noqa: E402
from flowtest_env.wrappers import position_slice  # noqa: E402

BUILTIN_IDS = [f"FlowTest-{stem}-v0" for stem, _ in BUILTIN_ENVS.values()]
FAMILIES = ("reachability", "reaction", "safety")
WORLDS = ("empty", "blocked", "fuel")
KINDS = ("reactive", "static", "agent")
SPEC_SIZE = {"reachability": 1, "reaction": 2, "safety": 2}
FAST_POOLS = [("reachability", "blocked", "static"), ("reaction", "fuel", "reactive"), ("safety", "empty", "agent")]
"""Every family, world and kind once (a Latin square), 3x3 grids: cheap to synthesize."""

MODES = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP, "disabled": AutoresetMode.DISABLED}


@pytest.fixture(autouse=True, scope="module")
def one_thread() -> Any:
    """One torch thread: tiny batches gain nothing from more, and on a loaded machine
    OpenMP's spinning threads slow every gather down."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _np(x: Any) -> np.ndarray:
    return x.cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


def _actions(rng: np.random.Generator, mask: np.ndarray, n_actions: int, p_any: float) -> np.ndarray:
    """Per env: a random legal action, or with probability ``p_any`` any action index."""
    legal = np.argmax(rng.random(mask.shape) * (mask > 0), axis=1)
    anything = rng.integers(n_actions, size=mask.shape[0])
    return np.where(rng.random(mask.shape[0]) < p_any, anything, legal)


def _rows(a: Any, ended: np.ndarray) -> np.ndarray:
    """The rows of ``ended`` envs (an object array of a ``SyncVectorEnv`` stacked)."""
    a = np.asarray(a)
    return np.stack([np.asarray(a[i]) for i in np.flatnonzero(ended)]) if a.dtype == object else a[ended]


def _same_verdict(ref: dict[str, Any], mine: dict[str, Any], ended: np.ndarray, where: str) -> None:
    names = tv.outcome_names(mine["system_objective"])
    assert list(names[ended]) == list(np.asarray(ref["system_objective"])[ended]), where
    assert all(v is None for v in names[~ended]), where
    for k in ("test_objective_realized", "restrictions", "blocked_attempts", "steps"):
        r, m = np.asarray(ref[k]), _np(mine[k])
        assert np.array_equal(r[ended].astype(m.dtype), m[ended]), (where, k)
        assert not m[~ended].any(), (where, k)


def _tests_played(ref: Any) -> np.ndarray | None:
    """The pool index each env of the reference plays (NumPy env), or ``None``."""
    inner = getattr(ref, "unwrapped", ref)
    return np.asarray(inner.test_index) if hasattr(inner, "test_index") else None


def compare(
    ref: Any,
    env: tv.TorchVectorEnv,
    steps: int,
    seed: int,
    p_any: float,
    mode: str = "next_step",
    twin: tv.TorchVectorEnv | None = None,
    names: list[str] | None = None,
) -> dict[str, int]:
    """Step ``ref`` and ``env`` (and ``twin``, the same env with compact observations) on
    the same actions; assert every output equal; count episode ends and verdicts."""
    rng = np.random.default_rng(seed)
    o1, i1 = ref.reset(seed=seed)
    o2, i2 = env.reset(seed=seed)
    if twin is not None:
        c, _ = twin.reset(seed=seed)
        assert torch.equal(twin.expand(c), o2)
    assert np.array_equal(o1, _np(o2)) and _np(o2).dtype == o1.dtype
    assert np.array_equal(i1["action_mask"] > 0, _np(i2["action_mask"]))
    n = env.tables.n_actions
    counts = {"ended": 0, "met": 0, "violated": 0, "tests": 0}
    seen: set[int] = set()
    for t in range(steps):
        played = _tests_played(ref)
        if played is not None:
            assert np.array_equal(played, _np(env.test_index)), f"step {t}: tests differ"
        if names is not None:  # a SyncVectorEnv of pool envs: the test each single env plays
            mine = [names[k] for k in _np(env.test_index).tolist()]
            assert [e.unwrapped.artifact.name for e in ref.envs] == mine, f"step {t}: tests differ"
        seen.update(_np(env.test_index).tolist())
        a = _actions(rng, i1["action_mask"], n, p_any)
        o1, r1, te1, tr1, i1 = ref.step(a)
        o2, r2, te2, tr2, i2 = env.step(torch.as_tensor(a))
        where = f"step {t}"
        assert np.array_equal(o1, _np(o2)), f"{where}: observations differ"
        assert np.array_equal(r1, _np(r2)), f"{where}: rewards {r1} != {_np(r2)}"
        assert np.array_equal(te1, _np(te2)) and np.array_equal(tr1, _np(tr2)), f"{where}: terminated/truncated differ"
        assert np.array_equal(i1["action_mask"] > 0, _np(i2["action_mask"])), f"{where}: masks differ"
        if twin is not None:
            c, rc, tec, trc, _ = twin.step(torch.as_tensor(a))
            assert torch.equal(twin.expand(c), o2) and torch.equal(rc, r2), f"{where}: compact observation differs"
            assert torch.equal(tec, te2) and torch.equal(trc, tr2)
        ended = te1 | tr1
        if mode == "same_step":
            mine_info = i2["final_info"]
            assert np.array_equal(_np(i2["_final_obs"]), ended)
            if ended.any():
                assert np.array_equal(_rows(i1["final_obs"], ended), _np(i2["final_obs"])[ended]), f"{where}: final obs"
                fi = i1["final_info"]
                assert np.array_equal(_rows(fi["action_mask"], ended) > 0, _np(mine_info["action_mask"])[ended])
                _same_verdict(fi["verdict"], mine_info["verdict"], ended, where)
        else:
            mine_info = i2
            if "verdict" in i1:
                _same_verdict(i1["verdict"], i2["verdict"], ended, where)
        assert np.array_equal(_np(mine_info["_verdict"]), ended), f"{where}: which envs ended"
        codes = _np(mine_info["verdict"]["system_objective"])
        counts["ended"] += int(ended.sum())
        counts["met"] += int((codes == 1).sum())
        counts["violated"] += int((codes == 2).sum())
        if mode == "disabled" and ended.any():
            o1, i1 = ref.reset(options={"reset_mask": ended.copy()})
            o2, i2 = env.reset(options={"reset_mask": torch.as_tensor(ended)})
            assert np.array_equal(o1, _np(o2)), f"{where}: observations after the masked reset"
            assert np.array_equal(i1["action_mask"][ended] > 0, _np(i2["action_mask"])[ended])  # infos: the reset envs'
            if twin is not None:
                c, _ = twin.reset(options={"reset_mask": torch.as_tensor(ended)})
                assert torch.equal(twin.expand(c), o2)
    counts["tests"] = len(seen)
    return counts


def twins(ref: Any, mode: str = "next_step", **kwargs: Any) -> tuple[tv.TorchVectorEnv, tv.TorchVectorEnv]:
    """The torch env of a NumPy env (float64 rewards) and its compact-observation twin."""
    env = tv.TorchVectorEnv.from_numpy(ref, reward_dtype=torch.float64, autoreset_mode=mode, **kwargs)
    twin = tv.TorchVectorEnv(env.tables, env.num_envs, autoreset_mode=mode, compact=True)
    return env, twin


# ---------------------------------------------------------------- every built-in, against the NumPy env


@pytest.mark.parametrize("env_id", flowtest_env.ENV_IDS)
def test_every_registered_env_steps_like_the_numpy_env(env_id: str) -> None:
    kw: dict[str, Any] = {"max_steps": 25}
    if env_id == "FlowTest-RandomGrid-v0":
        kw.update(seeds=[0, 1, 2], size=3)
    ref = gym.make_vec(env_id, num_envs=6, vectorization_mode="vector_entry_point", **kw)
    env, twin = twins(ref)
    assert env.single_observation_space == ref.single_observation_space
    assert env.single_action_space == ref.single_action_space
    counts = compare(ref, env, steps=130, seed=7, p_any=0.3, twin=twin)
    assert counts["ended"] >= 6
    if env_id == "FlowTest-RandomGrid-v0":
        assert counts["tests"] == 3


def test_both_verdicts_are_reached() -> None:
    """The comparisons reach met and violated, not only truncations."""
    ref = gym.make_vec("FlowTest-Refueling-v0", num_envs=8, vectorization_mode="vector_entry_point")
    assert compare(ref, twins(ref)[0], steps=200, seed=1, p_any=0.2)["violated"] > 0
    ref = gym.make_vec("FlowTest-Example1-v0", num_envs=8, vectorization_mode="vector_entry_point")
    assert compare(ref, twins(ref)[0], steps=200, seed=2, p_any=0.0)["met"] > 0


def test_grid_observations_like_the_numpy_env() -> None:
    ref = gym.make_vec("FlowTest-Patrolling-v0", num_envs=4, vectorization_mode="vector_entry_point", obs_kind="grid", max_steps=30)
    env, twin = twins(ref)
    assert env.tables.obs.dtype == torch.uint8
    compare(ref, env, steps=120, seed=3, p_any=0.5, twin=twin)


def test_mixed_pool_of_every_builtin_with_fixed_assignment() -> None:
    """All built-ins in one batch (actions and observations padded to the largest)."""
    games = [builtin_game(p, "instantaneous") for p in BUILTIN_ENVS]
    ref = PoolVectorEnv(2 * len(games), games, assignment="fixed", max_steps=40)
    env, twin = twins(ref)
    counts = compare(ref, env, steps=150, seed=5, p_any=0.3, twin=twin)
    assert counts["tests"] == len(games) and counts["ended"] > 0


def test_random_assignment_over_a_pool_of_builtins_draws_like_the_numpy_env() -> None:
    games = [builtin_game(p, "instantaneous") for p in ("example1", "maze2", "beaver-rescue", "refueling")]
    ref = PoolVectorEnv(16, games, max_steps=12)
    env, twin = twins(ref)
    counts = compare(ref, env, steps=150, seed=11, p_any=0.3, twin=twin)
    assert counts["tests"] == len(games) and counts["ended"] > 50


# ---------------------------------------------------------------- pool families


def _pool_ref(family: str, world: str, kind: str, num_envs: int = 6, **kw: Any) -> Any:
    return gym.make_vec(
        "FlowTest-RandomGrid-v0",
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        size=3,
        family=family,
        n=SPEC_SIZE[family],
        world=world,
        kind=kind,
        seeds=[0, 1],
        max_steps=15,
        **kw,
    )


@pytest.mark.parametrize("family,world,kind", FAST_POOLS)
def test_pool_families_step_like_the_numpy_env(family: str, world: str, kind: str) -> None:
    ref = _pool_ref(family, world, kind)
    env, twin = twins(ref)
    counts = compare(ref, env, steps=150, seed=4, p_any=0.3, twin=twin)
    assert counts["tests"] == 2 and counts["ended"] >= 20


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("world", WORLDS)
@pytest.mark.parametrize("kind", KINDS)
def test_every_pool_family_steps_like_the_numpy_env(family: str, world: str, kind: str) -> None:
    ref = _pool_ref(family, world, kind, num_envs=16)
    env, twin = twins(ref)
    counts = compare(ref, env, steps=400, seed=9, p_any=0.3, twin=twin)
    assert counts["tests"] == 2 and counts["ended"] >= 100


# ---------------------------------------------------------------- autoreset modes, memory, shaping


def _numpy(env_id: str, num_envs: int, mode: str, **kw: Any) -> Any:
    return gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", autoreset_mode=MODES[mode], **kw)


@pytest.mark.parametrize("mode", list(MODES))
@pytest.mark.parametrize("env_id", ["FlowTest-Maze2-v0", "FlowTest-Refueling-v0"])
def test_autoreset_modes_like_the_numpy_env(env_id: str, mode: str) -> None:
    ref = _numpy(env_id, 5, mode, max_steps=20)
    env, twin = twins(ref, mode)
    assert env.autoreset_mode == MODES[mode] == ref.autoreset_mode and env.metadata["autoreset_mode"] == MODES[mode]
    assert compare(ref, env, steps=120, seed=3, p_any=0.3, mode=mode, twin=twin)["ended"] >= 10


@pytest.mark.parametrize("mode", list(MODES))
def test_memory_and_shaping_like_the_numpy_env(mode: str) -> None:
    ref = _numpy("FlowTest-Maze2-v0", 4, mode, memory="visited", shaping=10.0, max_steps=30)
    env, twin = twins(ref, mode)
    assert env.tables.n_places == 25 and env.tables.n_words == 1
    assert env.single_observation_space == ref.single_observation_space
    assert compare(ref, env, steps=150, seed=6, p_any=0.2, mode=mode, twin=twin)["ended"] >= 8


def test_memory_and_shaping_on_a_graph_and_a_padded_pool_like_the_numpy_env() -> None:
    ref = _numpy("FlowTest-MotionPrimitives-v0", 4, "next_step", memory="visited", shaping=3.0, shaping_gamma=0.9, max_steps=20)
    env, twin = twins(ref)
    compare(ref, env, steps=100, seed=2, p_any=0.2, twin=twin)
    kw = {"memory": "visited", "shaping": 10.0, "max_steps": 15, "size": 3, "seeds": [0, 1, 2], "obs_kind": "padded"}
    ref = _numpy("FlowTest-RandomGrid-v0", 6, "same_step", **kw)
    env, twin = twins(ref, "same_step")
    assert env.tables.n_places == 64  # the padded 8x8 system plane
    assert compare(ref, env, steps=120, seed=8, p_any=0.2, mode="same_step", twin=twin)["tests"] == 3


def test_options_match_a_sync_vector_env_of_the_single_env() -> None:
    """The torch env against the single env itself, not only through the NumPy env."""
    kw: dict[str, Any] = {"memory": "visited", "shaping": 10.0, "max_steps": 25}
    ref = gym.make_vec("FlowTest-Maze1-v0", num_envs=4, vectorization_mode="sync", vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP}, **kw)
    env, twin = twins(_numpy("FlowTest-Maze1-v0", 4, "same_step", **kw), "same_step")
    compare(ref, env, steps=100, seed=1, p_any=0.3, mode="same_step", twin=twin)


# ---------------------------------------------------------------- the draw, the functional step, the API


def test_the_draw_is_the_numpy_recipe_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    keys = rng.integers(-(2**63), 2**63 - 1, size=4000, dtype=np.int64)
    keys[:4] = [0, -1, 2**63 - 1, -(2**63)]
    episodes = rng.integers(0, 2**62, size=4000, dtype=np.int64)
    episodes[:100] = np.arange(100)
    for n in (1, 2, 7, 512, 2**31):
        mine = tv.draw_tests(torch.as_tensor(keys), torch.as_tensor(episodes), n).numpy()
        assert np.array_equal(mine, draws.draw_tests_int64(keys, episodes, n))
        assert np.array_equal(mine, draws.draw_tests(keys.view(np.uint64), episodes, n))
    assert int(tv.draw_tests(torch.tensor([5]), torch.tensor([3]), 9)[0]) == draws.draw_test(5, 3, 9)


def test_the_functional_step_is_pure_and_matches_the_env() -> None:
    tables = tv.make_tables("FlowTest-Maze2-v0")
    state = tv.reset_state(tables, 32, seed=3)
    copy = tv.EnvState(*(x.clone() for x in state))
    a = torch.randint(0, tables.n_actions, (32,), generator=torch.Generator().manual_seed(0))
    s1, out1 = tv.step(tables, state, a)
    s2, out2 = tv.step(tables, state, a)
    assert all(torch.equal(x, y) for x, y in zip(state, copy, strict=True)), "the step changed its input state"
    assert all(torch.equal(x, y) for x, y in zip(s1, s2, strict=True))
    assert torch.equal(out1.reward, out2.reward)
    env = tv.make_vec("FlowTest-Maze2-v0", 32)
    obs, _ = env.reset(seed=3)
    assert torch.equal(obs, tv.observe(tables, state))
    obs, rew, *_ = env.step(a)
    assert torch.equal(obs, tv.observe(tables, s1)) and torch.equal(rew, out1.reward)
    assert torch.equal(tv.expand(tables, tv.compact(tables, s1)), obs)


def test_tables_move_between_devices_and_keep_their_values() -> None:
    tables = tv.make_tables("FlowTest-Maze1-v0")
    moved = tables.to("cpu")
    assert moved.device.type == "cpu" and torch.equal(moved.next_z, tables.next_z) and moved.n_actions == tables.n_actions


def test_bad_use_raises_clear_errors() -> None:
    env = tv.make_vec("FlowTest-Maze2-v0", 3)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(torch.zeros(3, dtype=torch.int64))
    env.reset(seed=0)
    for bad in (torch.tensor([0, 1, 9]), torch.tensor([0, -1, 2]), torch.tensor([0.5, 1.0, 2.0]), torch.zeros(2, dtype=torch.int64)):
        with pytest.raises(gym.error.InvalidAction):
            env.step(bad)
    with pytest.raises(ValueError, match="autoreset"):
        tv.make_vec("FlowTest-Maze2-v0", 3, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="seeds"):
        env.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": torch.ones(2, dtype=torch.bool)})
    with pytest.raises(ValueError, match="num_envs"):
        tv.make_vec("FlowTest-Maze2-v0", 0)
    with pytest.raises(ValueError, match="instantaneous"):  # the NumPy env has the accumulative setting, this one not
        tv.make_vec("FlowTest-SmallReactive-v0", 2, setting="accumulative")


def test_outcome_codes_name_the_outcomes() -> None:
    assert list(tv.outcome_names(torch.tensor([0, 1, 2, -1], dtype=torch.int8))) == [*OUTCOMES, None]


def test_flowtest_env_imports_without_torch() -> None:
    code = (
        "import sys; sys.modules['torch'] = None\n"
        "import flowtest_env, gymnasium as gym\n"
        "env = gym.make_vec('FlowTest-Maze2-v0', num_envs=2, vectorization_mode='vector_entry_point'); env.reset(seed=0)\n"
        "try:\n    import flowtest_env.torch_vector\nexcept ImportError:\n    print('no torch module')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "no torch module"


def test_the_compact_observation_is_small() -> None:
    """The point of the compact form: a row index and packed memory words, not the floats."""
    ref = PoolVectorEnv(2, ["maze2"])
    game = builtin_game("maze2", "instantaneous")
    where = position_slice(make_encoder(game, "flat"))
    tables = tv.build_tables(ref.pool, ref.games, max_steps=100, memory_slice=where)
    env = tv.TorchVectorEnv(tables, 2, compact=True)
    c, _ = env.reset(seed=0)
    assert c.shape == (2, 2) and c.dtype == torch.int64
    assert env.expand(c).shape == (2, 306 + 25)


def test_copy_false_writes_every_observation_into_one_buffer() -> None:
    fresh = tv.make_vec("FlowTest-Maze2-v0", 4, memory="visited")
    reused = tv.make_vec("FlowTest-Maze2-v0", 4, memory="visited", copy=False)
    o1, _ = fresh.reset(seed=1)
    o2, _ = reused.reset(seed=1)
    first = o2
    for t in range(30):
        assert torch.equal(o1, o2), t
        a = torch.full((4,), t % 5, dtype=torch.int64)
        o1, *_ = fresh.step(a)
        o2, *_ = reused.step(a)
        assert o2 is first  # the same buffer, overwritten


@pytest.mark.slow
def test_the_functional_step_compiles_and_gives_the_eager_results() -> None:
    """``torch.compile`` takes the step as it is (what a GPU trainer does to fuse it)."""
    tables = tv.make_tables("FlowTest-RandomGrid-v0", size=3, seeds=[0, 1, 2], max_steps=10, memory="visited")

    def advance(s: tv.EnvState, a: Any) -> tuple[tv.EnvState, Any, Any]:
        s, out = tv.step(tables, s, a, "same_step")
        return s, out.reward, tv.observe(tables, s)

    fused = torch.compile(advance, dynamic=False)
    eager_state = compiled_state = tv.reset_state(tables, 64, seed=2)
    gen = torch.Generator().manual_seed(0)
    for _ in range(40):
        mask = tv.action_mask(tables, eager_state)
        a = torch.argmax(torch.rand(mask.shape, generator=gen) * mask, dim=1)
        eager_state, r1, o1 = advance(eager_state, a)
        compiled_state, r2, o2 = fused(compiled_state, a)
        assert torch.equal(r1, r2) and torch.equal(o1, o2)
        assert all(torch.equal(x, y) for x, y in zip(eager_state, compiled_state, strict=True))


def test_the_benchmark_script_runs_and_writes_its_figures(tmp_path: Any, capsys: Any) -> None:
    from experiments.lab import gpu_bench

    out = tmp_path / "bench.json"
    code = gpu_bench.main(
        [
            "--cases",
            "maze2-tables",
            "maze2-obs-visited",
            "--devices",
            "numpy",
            "cpu",
            "--sizes",
            "8",
            "--numpy-sizes",
            "8",
            "--seconds",
            "0.05",
            "--out",
            str(out),
        ]
    )
    assert code == 0
    doc = json.loads(out.read_text())
    rows = {(r["case"], r["backend"]): r for r in doc["rows"]}
    assert set(rows) == {(c, b) for c in ("maze2-tables", "maze2-obs-visited") for b in ("numpy", "torch-cpu")}
    assert all(r["steps_per_s"] > 0 and r["num_envs"] == 8 for r in rows.values())
    assert "machine" in doc and "steps/s" in capsys.readouterr().out
    if not torch.cuda.is_available():
        assert gpu_bench.main(["--devices", "cuda"]) == 2
        assert "error: " in capsys.readouterr().err
