"""Training a PPO system under test: the library behind ``flowtest train``.

Two trainers, one call each, both writing the model (``PATH``, a ``.zip``), its training curve
(``PATH`` with ``.png``) and a summary (``PATH`` with ``.json``: every setting, time, the
curve's data), each file whole or not at all:

* :func:`train_native`: FlowTest's own masked PPO (:mod:`agents.native_ppo`), stepping many
  runs at once in the vector env; a native checkpoint (tensors and plain settings, loaded
  without unpickling, :mod:`agents.checkpoint`).
* :func:`train`: sb3-contrib's ``MaskablePPO`` or ``RecurrentPPO`` on a few single envs in one
  process (:func:`make_training_vec_env`, :func:`make_model`); a stable-baselines3 zip, which
  loading unpickles.

Their settings are :mod:`experiments.training.settings`; everything they add to the
environment is an env option (:func:`~experiments.training.settings.env_options`). See
docs/training.md.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from contextlib import AbstractContextManager, nullcontext
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoint import mark_own_file
from experiments.evaluation.episodes import env_named, run_episode
from experiments.outputs import run_log_folder, write_atomically
from synthesis.model.errors import ProblemError

from .rl import EpisodeCurve, EpisodeEnd, action_masks_of, learn, make_ppo, moving_average, require_native, require_rl
from .settings import DEFAULTS, check_settings, env_options, native_args, native_settings


def make_training_env(env_id: str, seed: int, settings: dict[str, Any], env_kwargs: dict[str, Any] | None = None) -> Any:
    """The env with the env options of ``settings`` (:func:`env_options`) and any further
    ``env_kwargs`` (e.g. a named pool's ``pool``, ``split``, ``count``), seeded; wrapped for
    MaskablePPO (:class:`sb3_contrib.common.wrappers.ActionMasker`) unless the algorithm
    is RecurrentPPO."""
    env = env_named(env_id, **env_options(settings), **(env_kwargs or {}))
    env.reset(seed=seed)
    env.action_space.seed(seed)
    if settings["algo"] == "recurrent-ppo":
        return env
    from sb3_contrib.common.wrappers import ActionMasker

    return ActionMasker(env, action_masks_of)


def make_training_vec_env(env_id: str, seed: int, settings: dict[str, Any], env_kwargs: dict[str, Any] | None = None) -> Any:
    """``settings["n_envs"]`` training envs (seeds ``seed``, ``seed + 1``, ...; ``env_kwargs``
    as for :func:`make_training_env`) in one
    process (SB3's ``DummyVecEnv``): the envs step in microseconds, the policy network is
    the cost, and it runs once per step for all of them."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    n = int(settings["n_envs"])
    if n < 1:
        raise ProblemError("n_envs must be at least 1")
    return DummyVecEnv([partial(make_training_env, env_id, seed + i, settings, env_kwargs) for i in range(n)])


def make_model(env: Any, settings: dict[str, Any], seed: int) -> Any:
    """A ``MaskablePPO`` or ``RecurrentPPO`` on ``env`` with ``settings`` (see
    :data:`DEFAULTS`), on the CPU, one torch thread, seeded; it records the env options it
    was trained with, which :class:`agents.ppo.PPOPolicy` rebuilds when it plays."""
    model = make_ppo(env, settings, seed, recurrent=settings["algo"] == "recurrent-ppo")
    model.flowtest_memory = settings["memory"]  # saved with the model, read by PPOPolicy
    model.flowtest_obs = {"obs_kind": settings["obs_kind"], "pad_to": int(settings["pad_to"])}
    return model


def success_rate(model: Any, env_id: str, episodes: int = 100, seed: int = 10_000, env_kwargs: dict[str, Any] | None = None) -> float:
    """Share of ``episodes`` seeded runs (deterministic policy) that meet the system
    objective, each through the single env (``env_kwargs``: e.g. a named pool's options)."""
    from agents.ppo import PPOPolicy

    env = env_named(env_id, **(env_kwargs or {}))
    policy = PPOPolicy(model, "ppo", env)
    met = 0
    for i in range(episodes):
        t = run_episode(env, policy, env_id, "ppo", seed + i, record=False)
        met += t.verdict["system_objective"] == "met"
    env.close()
    return met / episodes


def _curve_axes() -> tuple[Any, tuple[Any, Any]]:
    """A learning-curve figure: met share above, episode return below, one step axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    return fig, (axes[0], axes[1])


def _save_curve(fig: Any, a1: Any, a2: Any, title: str, path: Path) -> None:
    """Label, title and write a :func:`_curve_axes` figure to ``path``, then free it."""
    import matplotlib.pyplot as plt

    a1.set_ylabel("system objective met (%)")
    a1.set_ylim(-5, 105)
    a2.set_ylabel("episode return")
    a2.set_xlabel("time steps")
    for a in (a1, a2):
        a.grid(alpha=0.3)
    a1.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_curve(points: list[EpisodeEnd], path: Path, title: str) -> None:
    """Success rate and return (moving averages over 20 episodes) against time steps."""
    fig, (a1, a2) = _curve_axes()
    if points:
        steps = np.array([p.step for p in points])
        succ = moving_average([float(p.met) for p in points])
        ret = moving_average([p.ret for p in points])
        a1.plot(steps[len(steps) - len(succ) :], 100 * succ, color="#2ca02c")
        a2.plot(steps[len(steps) - len(ret) :], ret, color="#1f77b4")
    _save_curve(fig, a1, a2, title, path)


def train(
    env_id: str,
    steps: int,
    out: str | Path,
    seed: int = 0,
    progress_bar: bool = True,
    eval_episodes: int = 100,
    env_kwargs: dict[str, Any] | None = None,
    heldout: Sequence[Any] = (),
    **overrides: Any,
) -> dict[str, Any]:
    """The ``sb3`` trainer (``flowtest train --trainer sb3``): train MaskablePPO (or
    RecurrentPPO) on ``env_id`` (``env_kwargs``: e.g. a pool's ``pool``, ``split``, ``count``;
    a standard pool id loads its shipped tests) for ``steps`` time steps (rounded up to whole
    rollouts of ``n_envs x n_steps``); save model, curve, summary. On a pool the greedy
    policy then plays its train tests and the ``heldout`` games, all at once, beside the
    random floor of each (``final``, ``floor``). ``overrides`` replace entries of
    :data:`DEFAULTS`. The native trainer's entry point is :func:`train_native`.

    Example::

        s = train("FlowTest-RandomGrid-v0", 50_000, "maskable.zip",
                  env_kwargs={"pool": "reachability1/5x5-v2", "split": "train", "count": 128},
                  heldout=heldout_games("reachability1/5x5-v2", 32))
        s["final"]["heldout"]["met"], s["floor"]["heldout"]    # greedy met, random's met

    Returns
    -------
    dict
        ``env``, ``env_options``, ``steps`` (taken), ``seed``, ``seconds`` (training wall time),
        ``final`` and ``floor`` (on a pool), ``success_rate`` (over ``eval_episodes`` evaluation
        runs, ``None`` if 0), ``model``, ``curve``.
    """
    require_rl()
    if steps < 1:
        raise ProblemError("--steps must be at least 1")
    settings = {**DEFAULTS, **overrides}
    check_settings(settings)
    out = Path(out)
    model_path = out if out.suffix == ".zip" else out.with_suffix(".zip")
    env = make_training_vec_env(env_id, seed, settings, env_kwargs)
    model = make_model(env, settings, seed)
    curve = EpisodeCurve()
    seconds = learn(model, steps, curve, progress_bar)
    write_atomically(model_path, lambda tmp: model.save(str(tmp)))
    mark_own_file(model_path)  # this run wrote it: evaluating it needs no --trust-model
    png = model_path.with_suffix(".png")
    algo = "RecurrentPPO" if settings["algo"] == "recurrent-ppo" else "MaskablePPO"
    write_atomically(png, lambda tmp: plot_curve(curve.points, tmp, f"{algo} on {env_id} (seed {seed})"))
    rate = success_rate(model, env_id, eval_episodes, env_kwargs=env_kwargs) if eval_episodes else None
    final: dict[str, Any] = {}
    if env_kwargs and "pool" in env_kwargs:
        from agents.ppo import ModelBatchPolicy, model_where

        games = {"train": pool_games(env_kwargs), "heldout": list(heldout)}
        where = model_where(model, games["train"], settings["memory"])
        final = {name: greedy_rates(ModelBatchPolicy(model, where, True), g) for name, g in games.items() if g}
    summary = {
        "trainer": "sb3",
        "env": env_id,
        "steps": int(model.num_timesteps),
        "seed": seed,
        "seconds": round(seconds, 2),
        "success_rate": rate,
        "eval_episodes": eval_episodes,
        "settings": settings,
        "env_options": {**(env_kwargs or {}), **env_options(settings)},
        "final": final,
        "floor": pool_floors(env_kwargs, heldout) if final else {},
        "model": str(model_path),
        "curve": str(png),
        "episodes": len(curve.points),
        "points": [[p.step, p.met, round(p.ret, 4)] for p in curve.points],
    }
    write_atomically(model_path.with_suffix(".json"), lambda tmp: tmp.write_text(json.dumps(summary) + "\n"))
    return summary


def vector_env_id(env_id: str, env_kwargs: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The registered ID and options that make ``env_id`` (anything ``--env`` takes) as a
    vector env: a registered ID as it is, else ``FlowTest-v0`` with ``test=env_id``."""
    import gymnasium as gym

    import flowtest_env

    if env_id in gym.registry:
        return env_id, dict(env_kwargs)
    return flowtest_env.ANY_TEST_ID, {"test": env_id, **env_kwargs}


def plot_native_curve(rows: list[dict[str, Any]], path: Path, title: str) -> None:
    """Training episodes' met share and return, and the greedy evaluations, against steps."""
    fig, (a1, a2) = _curve_axes()
    ep = [r for r in rows if "episode/met" in r]
    if ep:
        a1.plot([r["step"] for r in ep], [100 * r["episode/met"] for r in ep], color="#2ca02c", lw=1, label="training episodes (sampled)")
        a2.plot([r["step"] for r in ep], [r["episode/return"] for r in ep], color="#1f77b4")
    for key, label, color in (("eval/train_met", "train tests (greedy)", "#000000"), ("eval/heldout_met", "held-out tests (greedy)", "#d62728")):
        ev = [r for r in rows if key in r]
        if ev:
            a1.plot([r["step"] for r in ev], [100 * r[key] for r in ev], "o-", color=color, lw=1.5, label=label)
    a1.legend(fontsize=8, loc="lower right")
    _save_curve(fig, a1, a2, title, path)


FLOOR_RUNS = 8
"""Random runs per test of the floor printed beside a trained policy's score (the
benchmark's ``--runs``)."""


def pool_games(env_kwargs: dict[str, Any], progress: bool = False) -> list[Any]:
    """The tests a pool's env trains on (its ``pool``, ``split`` and ``count`` options) as games."""
    from flowtest_env.game import TestGame
    from flowtest_env.pools import load_pool

    tests = load_pool(env_kwargs["pool"], env_kwargs.get("split", "train"), int(env_kwargs.get("count", 8)), progress=progress)
    return [TestGame(a) for a in tests]


def greedy_rates(policy: Any, games: Sequence[Any]) -> dict[str, float]:
    """A batched policy playing every test of ``games`` once, all at once
    (:func:`flowtest_env.scoring.play_batch`): the share met, met and realized, and the mean
    restrictions per run (the native trainer's evaluation, :func:`agents.native.evaluation.met_rate`)."""
    from flowtest_env.scoring import play_batch

    v = {k: a[0] for k, a in play_batch(policy, games, 1, 0).items()}
    met = v["system_objective"] == "met"
    return {"met": float(met.mean()), "realized": float((met & v["test_objective_realized"]).mean()), "restrictions": float(v["restrictions"].mean())}


def random_floor(games: Sequence[Any], runs: int = FLOOR_RUNS) -> float:
    """The random floor of ``games``: the share of ``runs`` seeded random runs per test that
    meet the system objective (the benchmark protocol's floor, :func:`flowtest_env.scoring.random_policy`)."""
    from flowtest_env.scoring import play_batch, random_policy

    return float(np.mean(play_batch(random_policy(), games, runs, 0)["system_objective"] == "met"))


def pool_floors(env_kwargs: dict[str, Any] | None, heldout: Sequence[Any]) -> dict[str, float]:
    """The random floors of a pool's train tests (``env_kwargs``) and of the held-out games,
    printed beside the trained policy's greedy met; ``{}`` without a pool."""
    if not env_kwargs or "pool" not in env_kwargs:
        return {}
    floors = {"train": random_floor(pool_games(env_kwargs))}
    if heldout:
        floors["heldout"] = random_floor(heldout)
    return floors


def heldout_games(pool: str, count: int, progress: bool = False) -> list[Any]:
    """The first ``count`` tests of ``pool``'s held-out ``test`` split as games
    (:func:`flowtest_env.pools.load_pool`): what :func:`train_native` evaluates on besides
    its own tests (``heldout``)."""
    from flowtest_env.game import TestGame
    from flowtest_env.pools import load_pool

    return [TestGame(a) for a in load_pool(pool, "test", count, progress=progress)]


def train_native(
    env_id: str,
    steps: int,
    out: str | Path,
    seed: int = 0,
    progress_bar: bool = True,
    eval_episodes: int = 100,
    env_kwargs: dict[str, Any] | None = None,
    heldout: Any = (),
    log_dir: str | Path | None = None,
    eval_every: int = 250_000,
    **overrides: Any,
) -> dict[str, Any]:
    """The native trainer (:mod:`agents.native_ppo`) on ``env_id`` (``env_kwargs``: e.g. a
    pool's ``pool``, ``split``, ``count``) for ``steps`` env steps (rounded up to whole
    rollouts); ``heldout``: tests to evaluate on besides the env's own. Saves the native
    checkpoint, its curve and the summary; ``overrides`` replace :data:`NATIVE_DEFAULTS`.
    With ``log_dir``, the run's logs (``progress.csv``, TensorBoard events) go to a new
    folder inside it named after the model (``log_dir/policy``, or ``policy-2``... when
    taken: :func:`experiments.outputs.new_run_folder`), never into an earlier run's.

    Example::

        s = train_native("FlowTest-RandomGrid-v0", 2_000_000, "policy.zip",
                         env_kwargs={"pool": "reachability1/5x5", "split": "train", "count": 128})
        s["final"]["train"]["met"]   # greedy met on the train tests

    Returns
    -------
    dict
        ``trainer``, ``env``, ``env_options``, ``steps``, ``seed``, ``seconds`` (training,
        evaluations excluded), ``steps_per_second``, ``final`` and ``evaluations`` (greedy met,
        realized and restrictions on the train and held-out tests), ``floor`` (on a pool: the
        random floor's met on the same train and held-out tests), ``success_rate`` (over
        ``eval_episodes`` single-env runs, ``None`` if 0), ``settings``, ``model``, ``curve``,
        ``log_dir`` (the run's log folder, or ``None``).
    """
    require_native()
    if steps < 1:
        raise ProblemError("--steps must be at least 1")
    settings = native_settings(overrides)
    vec_id, vec_kwargs = vector_env_id(env_id, env_kwargs or {})
    args = native_args(settings, vec_id, vec_kwargs, steps, seed, eval_every)
    out = Path(out)
    model_path = out if out.suffix == ".zip" else out.with_suffix(".zip")
    logs: AbstractContextManager[Path | None] = nullcontext() if log_dir is None else run_log_folder(Path(log_dir), model_path.stem)
    with logs as run_logs:
        return _train_native_run(args, settings, env_id, env_kwargs, seed, model_path, heldout, run_logs, progress_bar, eval_episodes)


def _train_native_run(
    args: Any,
    settings: dict[str, Any],
    env_id: str,
    env_kwargs: dict[str, Any] | None,
    seed: int,
    model_path: Path,
    heldout: Any,
    log_dir: Path | None,
    progress_bar: bool,
    eval_episodes: int,
) -> dict[str, Any]:
    """:func:`train_native`'s run, its logs into ``log_dir`` (a new folder of this run):
    train, save the checkpoint, curve and summary."""
    from agents.native_ppo import train as native_train

    ckpt_tmp = model_path.with_name(f".{model_path.stem}.{os.getpid()}.training.zip")
    try:
        result = native_train(args, out=None, heldout=heldout, log_dir=log_dir, progress_bar=progress_bar)
    except ValueError as exc:
        raise ProblemError(str(exc)) from None
    from agents.native.checkpoint import save_policy

    try:
        save_policy(ckpt_tmp, result.agent, {**result.settings, "flowtest_train": {"settings": settings}})
        write_atomically(model_path, lambda tmp: os.replace(ckpt_tmp, tmp))
    finally:
        ckpt_tmp.unlink(missing_ok=True)
    png = model_path.with_suffix(".png")
    rows = result.rows
    title = f"native {settings['algo']} on {env_id} (seed {seed})"
    write_atomically(png, lambda tmp: plot_native_curve(rows, tmp, title))
    rate = None
    if eval_episodes:
        from agents.ppo import load_model

        rate = success_rate(load_model(model_path), env_id, eval_episodes, env_kwargs=env_kwargs)
    summary = {
        "trainer": "native",
        "env": env_id,
        "env_options": {**(env_kwargs or {}), "memory": settings["memory"], "shaping": settings["shaping"], "obs_kind": settings["obs_kind"]},
        "steps": result.steps,
        "seed": seed,
        "seconds": round(result.seconds, 2),
        "eval_seconds": round(result.eval_seconds, 2),
        "steps_per_second": round(result.steps_per_second, 1),
        "device": str(result.settings["trained_on"]),
        "final": result.final,
        "floor": pool_floors(env_kwargs, heldout),
        "evaluations": [[step, rates] for step, rates in result.evaluations],
        "success_rate": rate,
        "eval_episodes": eval_episodes,
        "settings": settings,
        "native_args": result.settings["training"],
        "model": str(model_path),
        "curve": str(png),
        "log_dir": None if log_dir is None else str(log_dir),
        "log": rows,
    }
    write_atomically(model_path.with_suffix(".json"), lambda tmp: tmp.write_text(json.dumps(summary) + "\n"))
    return summary
