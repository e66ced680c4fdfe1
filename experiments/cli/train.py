"""``flowtest train ENV --steps N --out PATH``: train a PPO system under test against a test.

``ENV`` is anything ``flowtest evaluate --env`` takes (a registered ID, a built-in name, a
problem file, an artifact file); ``--pool NAME`` (with ``FlowTest-RandomGrid-v0``) trains
on the first ``--count`` tests of a named pool's ``--split``.

**Two trainers** (``--trainer``):

* ``native`` (default): FlowTest's own masked PPO (:mod:`agents.native_ppo`), stepping
  ``--n-envs`` runs at once in the NumPy vector env, on ``--device`` (``auto``, ``cpu``,
  ``cuda``). ``--algo ppo`` (an MLP with the visited-places memory) or
  ``--algo recurrent-ppo`` (a GRU). It evaluates the greedy policy on the env's own tests
  (a pool's train tests) and, with ``--pool``, on ``--heldout-count`` tests of the pool's
  test split; logs go to ``--log-dir`` (``progress.csv``, and TensorBoard). The model is a
  native checkpoint: tensors and plain settings, loaded without unpickling
  (:mod:`agents.checkpoint`).
* ``sb3``: today's path, unchanged: sb3-contrib's ``MaskablePPO`` (``--algo
  maskable-ppo``) or ``RecurrentPPO`` (``--algo recurrent-ppo``, an LSTM, no masks) on a
  few single envs in one process; the model is a stable-baselines3 zip, which loading
  unpickles (so ``ppo:PATH`` loads it only with ``--trust-model``).

Everything the trainers add to the environment is an env option, printed at the start
and saved with the model:

* ``memory="visited"`` (default here): the places the SUT has occupied this episode
  appended to the observation (:class:`flowtest_env.wrappers.VisitedPlaces`); without
  memory no policy passes a reactive test that makes the SUT pass a cell twice;
* ``shaping`` (sb3: 10 by default here; native: 0, the vector env's option when it has
  one): potential-based shaping towards the SUT's own objective
  (:class:`flowtest_env.wrappers.DistanceShaping`);
* ``obs_kind`` and ``pad_to``: the observation (``"padded"`` gives one shape for every grid
  test up to ``pad_to x pad_to``, so one policy plays many tests).

Every setting of :data:`NATIVE_DEFAULTS` and :data:`DEFAULTS` (sb3) is a flag
(``--learning-rate``, ``--memory none``, ...); a flag of the other trainer is refused.
Writes the model (``PATH``, a ``.zip``), its training curve (``PATH`` with ``.png``) and
``PATH`` with ``.json`` (every setting, time, the curve's data). Load the model as a SUT
with ``--sut ppo:PATH``. See docs/training.md.

Needs the ``rl`` extra (``pip install 'flowtest[rl]'``: torch, stable-baselines3,
sb3-contrib, tensorboard).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoint import mark_own_file
from synthesis.model.errors import ProblemError

from .arguments import nonnegative_int, positive_int
from .command import Command
from .episodes import make_env, run_episode
from .exits import EXIT_OK
from .outputs import check_output_path, write_atomically
from .training import EpisodeCurve, EpisodeEnd, action_masks_of, learn, make_ppo, moving_average, require_rl

ALGOS = ("maskable-ppo", "recurrent-ppo")
"""``--algo`` choices: sb3-contrib's MaskablePPO (MLP policy, action masks) and
RecurrentPPO (LSTM policy, no masks)."""

DEFAULTS: dict[str, Any] = {
    "algo": "maskable-ppo",
    "n_envs": 8,
    "n_steps": 128,
    "batch_size": 256,
    "learning_rate": 1e-3,
    "gamma": 0.99,
    "ent_coef": 0.01,
    "n_epochs": 10,
    "net_arch": [64, 64],
    "lstm_hidden_size": 256,
    "shaping": 10.0,
    "memory": "visited",
    "obs_kind": "flat",
    "pad_to": 8,
}
"""Training settings: the algorithm; 8 envs stepped in one process (one batched policy
call per step of all eight), rollouts of 8 x 128 steps, a small network, a high learning
rate; the LSTM's width (RecurrentPPO only; sb3-contrib's default); the env options: the
shaping scale (0 = off), the SUT's memory, the observation (``pad_to`` is used by
``obs_kind="padded"`` only)."""

ENV_OPTION_KEYS = ("memory", "shaping", "obs_kind", "pad_to")
"""The settings that are env options (the rest configure the algorithm)."""


def env_options(settings: dict[str, Any]) -> dict[str, Any]:
    """The env options of ``settings`` (keyword arguments of :class:`flowtest_env.FlowTestEnv`)."""
    opts: dict[str, Any] = {
        "memory": settings["memory"], "shaping": float(settings["shaping"]), "shaping_gamma": float(settings["gamma"]),
        "obs_kind": settings["obs_kind"],
    }
    if settings["obs_kind"] == "padded":
        opts["pad_to"] = int(settings["pad_to"])
    return opts


def make_training_env(env_id: str, seed: int, settings: dict[str, Any], env_kwargs: dict[str, Any] | None = None) -> Any:
    """The env with the env options of ``settings`` (:func:`env_options`) and any further
    ``env_kwargs`` (e.g. a named pool's ``pool``, ``split``, ``count``), seeded; wrapped for
    MaskablePPO (:class:`sb3_contrib.common.wrappers.ActionMasker`) unless the algorithm
    is RecurrentPPO."""
    env = make_env(env_id, **env_options(settings), **(env_kwargs or {}))
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


def check_settings(settings: dict[str, Any]) -> None:
    """Reject settings no algorithm can use, as invalid input.

    Raises
    ------
    ProblemError
        On an unknown key or algorithm, or a value out of range.
    """
    unknown = set(settings) - set(DEFAULTS)
    if unknown:
        raise ProblemError(f"unknown training settings {sorted(unknown)}; known: {', '.join(DEFAULTS)}")
    if settings["algo"] not in ALGOS:
        raise ProblemError(f"unknown --algo {settings['algo']!r}; expected one of {', '.join(ALGOS)}")
    for key in ("n_envs", "n_steps", "batch_size", "n_epochs", "lstm_hidden_size"):
        if int(settings[key]) < 1:
            raise ProblemError(f"--{key.replace('_', '-')} must be at least 1")
    if not 0 < float(settings["gamma"]) <= 1:
        raise ProblemError("--gamma must be in (0, 1]")
    if float(settings["learning_rate"]) <= 0:
        raise ProblemError("--learning-rate must be positive")
    if float(settings["shaping"]) < 0:
        raise ProblemError("--shaping must be 0 (off) or a positive scale")
    if not settings["net_arch"] or any(int(w) < 1 for w in settings["net_arch"]):
        raise ProblemError("--net-arch must be positive layer widths, e.g. 64,64")


def make_model(env: Any, settings: dict[str, Any], seed: int) -> Any:
    """A ``MaskablePPO`` or ``RecurrentPPO`` on ``env`` with ``settings`` (see
    :data:`DEFAULTS`), on the CPU, one torch thread, seeded; it records the env options it
    was trained with, which :class:`agents.ppo.PPOPolicy` rebuilds when it plays."""
    model = make_ppo(env, settings, seed, recurrent=settings["algo"] == "recurrent-ppo")
    model.flowtest_memory = settings["memory"]  # saved with the model, read by PPOPolicy
    model.flowtest_obs = {"obs_kind": settings["obs_kind"], "pad_to": int(settings["pad_to"])}
    return model


def success_rate(model: Any, env_id: str, episodes: int = 100, seed: int = 10_000,
                 env_kwargs: dict[str, Any] | None = None) -> float:
    """Share of ``episodes`` seeded runs (deterministic policy) that meet the system
    objective, each through the single env (``env_kwargs``: e.g. a named pool's options)."""
    from agents.ppo import PPOPolicy

    env = make_env(env_id, **(env_kwargs or {}))
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


def train(env_id: str, steps: int, out: str | Path, seed: int = 0, progress_bar: bool = True,
          eval_episodes: int = 100, **overrides: Any) -> dict[str, Any]:
    """The ``sb3`` trainer (``flowtest train --trainer sb3``): train MaskablePPO (or
    RecurrentPPO) on ``env_id`` for ``steps`` time steps (rounded up to whole rollouts of
    ``n_envs x n_steps``); save model, curve, summary. ``overrides`` replace entries of
    :data:`DEFAULTS`. The native trainer's entry point is :func:`train_native`.

    Returns
    -------
    dict
        ``env``, ``steps`` (taken), ``seed``, ``seconds`` (training wall time), ``success_rate``
        (over ``eval_episodes`` evaluation runs, ``None`` if 0), ``model``, ``curve``.
    """
    require_rl()
    if steps < 1:
        raise ProblemError("--steps must be at least 1")
    settings = {**DEFAULTS, **overrides}
    check_settings(settings)
    out = Path(out)
    model_path = out if out.suffix == ".zip" else out.with_suffix(".zip")
    env = make_training_vec_env(env_id, seed, settings)
    model = make_model(env, settings, seed)
    curve = EpisodeCurve()
    seconds = learn(model, steps, curve, progress_bar)
    write_atomically(model_path, lambda tmp: model.save(str(tmp)))
    mark_own_file(model_path)  # this run wrote it: evaluating it needs no --trust-model
    png = model_path.with_suffix(".png")
    algo = "RecurrentPPO" if settings["algo"] == "recurrent-ppo" else "MaskablePPO"
    write_atomically(png, lambda tmp: plot_curve(curve.points, tmp, f"{algo} on {env_id} (seed {seed})"))
    rate = success_rate(model, env_id, eval_episodes) if eval_episodes else None
    summary = {
        "env": env_id, "steps": int(model.num_timesteps), "seed": seed, "seconds": round(seconds, 2), "success_rate": rate,
        "eval_episodes": eval_episodes, "settings": settings, "env_options": env_options(settings),
        "model": str(model_path), "curve": str(png),
        "episodes": len(curve.points),
        "points": [[p.step, p.met, round(p.ret, 4)] for p in curve.points],
    }
    write_atomically(model_path.with_suffix(".json"), lambda tmp: tmp.write_text(json.dumps(summary) + "\n"))
    return summary


# --------------------------------------------------------------------------- the native trainer

TRAINERS = ("native", "sb3")
"""``--trainer`` choices: FlowTest's own batched PPO (default) and stable-baselines3."""

NATIVE_ALGOS = ("ppo", "recurrent-ppo")
"""The native trainer's ``--algo`` (``maskable-ppo`` is taken as ``ppo``: both mask)."""

NATIVE_DEFAULTS: dict[str, Any] = {
    "algo": "ppo",
    "n_envs": 128,
    "n_steps": 32,
    "batch_size": 1024,
    "n_epochs": 2,
    "learning_rate": 1e-3,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_range": 0.2,
    "ent_coef": 0.01,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "net_arch": [256, 256],
    "gru_hidden_size": 128,
    "shaping": 0.0,
    "memory": "visited",
    "obs_kind": "flat",
    "pad_to": 8,
    "device": "auto",
    "env_backend": "auto",
    "threads": 1,
}
"""The native trainer's settings: 128 envs x 32 steps per rollout (4,096 steps), minibatches
of 1,024 steps, 2 epochs, Adam at 1e-3 annealed to 0, an MLP of 256 x 256 (actor and critic
each, tanh), the visited-places memory, no shaping, one CPU thread (a seed gives the same
run). ``--algo recurrent-ppo`` changes :data:`NATIVE_RECURRENT` unless given."""

NATIVE_RECURRENT: dict[str, Any] = {"memory": "none", "net_arch": [128]}
"""The recurrent variant's own defaults: its GRU is its memory, one input layer."""


def native_settings(overrides: dict[str, Any]) -> dict[str, Any]:
    """The native trainer's full settings: :data:`NATIVE_DEFAULTS`, the recurrent
    defaults for ``recurrent-ppo``, then ``overrides``.

    Raises
    ------
    ProblemError
        On a setting of the sb3 trainer only, an unknown algorithm or a value out of range.
    """
    unknown = set(overrides) - set(NATIVE_DEFAULTS)
    if unknown:
        flags = ", ".join(_flag(k) for k in sorted(unknown))
        raise ProblemError(f"{flags}: a setting of --trainer sb3, not of the native trainer")
    algo = "ppo" if overrides.get("algo", "ppo") == "maskable-ppo" else overrides.get("algo", "ppo")
    if algo not in NATIVE_ALGOS:
        raise ProblemError(f"--algo {algo}: the native trainer has {', '.join(NATIVE_ALGOS)}")
    settings = {**NATIVE_DEFAULTS, **(NATIVE_RECURRENT if algo == "recurrent-ppo" else {}), **overrides, "algo": algo}
    if settings["obs_kind"] == "grid":
        raise ProblemError("--obs-kind grid: the native trainer reads flat or padded observations")
    if settings["obs_kind"] == "padded" and int(settings["pad_to"]) != 8:
        raise ProblemError("--pad-to: the vector env pads to 8 x 8 only")
    from agents.native.args import check_args

    try:
        check_args(native_args(settings, "FlowTest-v0", {}, 1, 0))
    except ValueError as exc:
        raise ProblemError(f"training settings: {exc}") from None
    return settings


def native_args(settings: dict[str, Any], env_id: str, env_kwargs: dict[str, Any], steps: int, seed: int,
                eval_every: int = 0) -> Any:
    """The :class:`agents.native_ppo.NativeArgs` of ``settings`` (flag names as the sb3
    trainer's: ``n_envs``, ``n_steps``, ``batch_size`` (a minibatch), ``n_epochs``, ``net_arch``)."""
    from agents.native.args import NativeArgs

    n_envs, n_steps = int(settings["n_envs"]), int(settings["n_steps"])
    minibatches = max(1, (n_envs * n_steps) // max(1, int(settings["batch_size"])))
    if settings["algo"] == "recurrent-ppo":  # whole env sequences per minibatch
        minibatches = min(minibatches, n_envs)
        while n_envs % minibatches:
            minibatches -= 1
    return NativeArgs(
        env_id=env_id, env_kwargs=dict(env_kwargs), algo=settings["algo"], total_steps=int(steps), num_envs=n_envs,
        num_steps=n_steps, num_minibatches=minibatches, update_epochs=int(settings["n_epochs"]),
        learning_rate=float(settings["learning_rate"]), gamma=float(settings["gamma"]),
        gae_lambda=float(settings["gae_lambda"]), clip_coef=float(settings["clip_range"]),
        ent_coef=float(settings["ent_coef"]), vf_coef=float(settings["vf_coef"]),
        max_grad_norm=float(settings["max_grad_norm"]), hidden=tuple(int(w) for w in settings["net_arch"]),
        gru_hidden=int(settings["gru_hidden_size"]), memory=settings["memory"], obs_kind=settings["obs_kind"],
        shaping=float(settings["shaping"]), seed=int(seed), device=str(settings["device"]),
        threads=int(settings["threads"]), eval_every=int(eval_every), env_backend=str(settings["env_backend"]),
    )


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
        a1.plot([r["step"] for r in ep], [100 * r["episode/met"] for r in ep], color="#2ca02c", lw=1,
                label="training episodes (sampled)")
        a2.plot([r["step"] for r in ep], [r["episode/return"] for r in ep], color="#1f77b4")
    for key, label, color in (("eval/train_met", "train tests (greedy)", "#000000"),
                              ("eval/heldout_met", "held-out tests (greedy)", "#d62728")):
        ev = [r for r in rows if key in r]
        if ev:
            a1.plot([r["step"] for r in ev], [100 * r[key] for r in ev], "o-", color=color, lw=1.5, label=label)
    a1.legend(fontsize=8, loc="lower right")
    _save_curve(fig, a1, a2, title, path)


def train_native(env_id: str, steps: int, out: str | Path, seed: int = 0, progress_bar: bool = True,
                 eval_episodes: int = 100, env_kwargs: dict[str, Any] | None = None, heldout: Any = (),
                 log_dir: str | Path | None = None, eval_every: int = 250_000, **overrides: Any) -> dict[str, Any]:
    """The native trainer (:mod:`agents.native_ppo`) on ``env_id`` (``env_kwargs``: e.g. a
    pool's ``pool``, ``split``, ``count``) for ``steps`` env steps (rounded up to whole
    rollouts); ``heldout``: tests to evaluate on besides the env's own. Saves the native
    checkpoint, its curve and the summary; ``overrides`` replace :data:`NATIVE_DEFAULTS`.

    Example::

        s = train_native("FlowTest-RandomGrid-v0", 2_000_000, "policy.zip",
                         env_kwargs={"pool": "reachability1/5x5", "split": "train", "count": 128})
        s["final"]["train"]["met"]   # greedy met on the train tests

    Returns
    -------
    dict
        ``trainer``, ``env``, ``env_options``, ``steps``, ``seed``, ``seconds`` (training,
        evaluations excluded), ``steps_per_second``, ``final`` and ``evaluations`` (greedy met,
        realized and restrictions on the train and held-out tests), ``success_rate`` (over
        ``eval_episodes`` single-env runs, ``None`` if 0), ``settings``, ``model``, ``curve``.
    """
    require_native()
    from agents.native_ppo import train as native_train

    if steps < 1:
        raise ProblemError("--steps must be at least 1")
    settings = native_settings(overrides)
    vec_id, vec_kwargs = vector_env_id(env_id, env_kwargs or {})
    args = native_args(settings, vec_id, vec_kwargs, steps, seed, eval_every)
    out = Path(out)
    model_path = out if out.suffix == ".zip" else out.with_suffix(".zip")
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
        "trainer": "native", "env": env_id, "env_options": {**(env_kwargs or {}), "memory": settings["memory"],
                                                            "shaping": settings["shaping"], "obs_kind": settings["obs_kind"]},
        "steps": result.steps, "seed": seed, "seconds": round(result.seconds, 2),
        "eval_seconds": round(result.eval_seconds, 2), "steps_per_second": round(result.steps_per_second, 1),
        "device": str(result.settings["trained_on"]), "final": result.final,
        "evaluations": [[step, rates] for step, rates in result.evaluations],
        "success_rate": rate, "eval_episodes": eval_episodes, "settings": settings,
        "native_args": result.settings["training"], "model": str(model_path), "curve": str(png),
        "log_dir": None if log_dir is None else str(log_dir), "log": rows,
    }
    write_atomically(model_path.with_suffix(".json"), lambda tmp: tmp.write_text(json.dumps(summary) + "\n"))
    return summary


def require_native() -> None:
    """Refuse, as invalid input, to train natively without torch.

    Raises
    ------
    ProblemError
        If torch cannot be imported.
    """
    try:
        import torch  # noqa: F401
    except ImportError:
        raise ProblemError("training needs the rl extra: pip install 'flowtest[rl]'") from None


# --------------------------------------------------------------------------- command line


def _flag(key: str) -> str:
    return "--" + key.replace("_", "-")


def _net_arch(text: str) -> list[int]:
    try:
        return [int(w) for w in text.split(",") if w.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected layer widths such as 64,64, not {text!r}") from None


SETTING_HELP: dict[str, str] = {
    "algo": f"algorithm: native {', '.join(NATIVE_ALGOS)}; sb3 {', '.join(ALGOS)}",
    "n_envs": "envs stepped together", "n_steps": "rollout steps per env", "batch_size": "minibatch size (steps)",
    "learning_rate": "learning rate", "gamma": "discount", "ent_coef": "entropy bonus", "n_epochs": "epochs per rollout",
    "net_arch": "hidden layer widths, comma-separated", "lstm_hidden_size": "LSTM width (sb3 recurrent-ppo only)",
    "gru_hidden_size": "GRU width (native recurrent-ppo)", "gae_lambda": "GAE lambda", "clip_range": "PPO ratio clip",
    "vf_coef": "value loss weight", "max_grad_norm": "gradient clip",
    "device": "auto (cuda when torch sees one), cpu, cuda, cuda:N", "threads": "torch CPU threads",
    "env_backend": "who steps the tests: torch (the torch env on --device), numpy (the NumPy vector env); auto: torch",
    "shaping": "env option: shaping scale, 0 = off",
    "memory": "env option: the SUT's memory, none or visited", "obs_kind": "env option: flat, grid or padded",
    "pad_to": "env option: grid side of obs_kind=padded",
}


def _shown(value: Any) -> str:
    return ",".join(map(str, value)) if isinstance(value, list) else str(value)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest train``'s arguments."""
    p.add_argument("ENV", help="environment: a registered ID (FlowTest-Maze2-v0), a built-in name (maze2), a problem "
                               "file (mine.toml) or an artifact file")
    p.add_argument("--trainer", choices=TRAINERS, default="native",
                   help="native: FlowTest's batched masked PPO (default; a native checkpoint); sb3: stable-baselines3 "
                        "(an SB3 zip, which loading unpickles)")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="training time steps (default: native 1500000, sb3 50000)")
    p.add_argument("--out", type=Path, required=True, help="model file (.zip); the curve goes next to it (.png)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed (default 0)")
    p.add_argument("--pool", metavar="NAME", default=None,
                   help="train on a named pool's tests (FlowTest-RandomGrid-v0), e.g. reachability1/5x5")
    p.add_argument("--split", choices=("train", "validation", "test"), default=None,
                   help="the pool's split to train on (default train)")
    p.add_argument("--count", type=positive_int, default=None, help="tests of the split (default 128)")
    p.add_argument("--heldout-count", type=nonnegative_int, default=None,
                   help="native, with --pool: held-out tests of the pool's test split evaluated during training "
                        "(default 32; 0: none)")
    p.add_argument("--eval-every", type=nonnegative_int, default=250_000,
                   help="native: steps between greedy evaluations (default 250000; 0: at the end only)")
    p.add_argument("--log-dir", type=Path, default=None,
                   help="native: write progress.csv and TensorBoard logs into this folder")
    p.add_argument("--eval-episodes", type=nonnegative_int, default=None,
                   help="single-env evaluation runs after training (default: sb3 100; native 100, 0 with --pool "
                        "(the greedy evaluation on the tests is the score))")
    p.add_argument("--force", action="store_true", help="overwrite an existing model, curve or summary")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    g = p.add_argument_group("settings (printed at the start and saved in the .json; defaults per trainer)")
    keys = list(dict.fromkeys([*NATIVE_DEFAULTS, *DEFAULTS]))
    for key in keys:
        native, sb3 = NATIVE_DEFAULTS.get(key), DEFAULTS.get(key)
        where = "; ".join(f"{name} {_shown(v)}" for name, v in (("native", native), ("sb3", sb3)) if v is not None)
        kw: dict[str, Any] = {"default": None, "help": f"{SETTING_HELP[key]} (default: {where})"}
        default = native if native is not None else sb3
        if isinstance(default, list):
            kw["type"] = _net_arch
        elif key == "algo":
            kw["choices"] = tuple(dict.fromkeys([*NATIVE_ALGOS, *ALGOS]))
        elif key in ("memory", "obs_kind", "env_backend"):
            kw["choices"] = {"memory": ("none", "visited"), "obs_kind": ("flat", "grid", "padded"),
                             "env_backend": ("auto", "torch", "numpy")}[key]
        elif key == "device":
            kw["type"] = str
        else:
            kw["type"] = type(default)
        names = [_flag(key)] + (["--num-envs"] if key == "n_envs" else [])
        g.add_argument(*names, dest=key, **kw)


POOL_ENV = "FlowTest-RandomGrid-v0"
"""The environment whose tests ``--pool`` names (the others take no pool options)."""


def _pool_options(args: argparse.Namespace) -> dict[str, Any]:
    if args.pool is None:
        if args.split is not None or args.count is not None or args.heldout_count:
            raise ProblemError("--split, --count and --heldout-count go with --pool")
        return {}
    from flowtest_env.pools import parse_pool

    try:
        parse_pool(args.pool)
    except ValueError as exc:
        raise ProblemError(f"--pool {args.pool}: {exc}") from None
    return {"pool": args.pool, "split": args.split or "train", "count": args.count or 128}


def run(args: argparse.Namespace) -> int:
    """Train, save, evaluate; print every setting used, then where the model and its curve are."""
    given = {k: getattr(args, k) for k in dict.fromkeys([*NATIVE_DEFAULTS, *DEFAULTS]) if getattr(args, k) is not None}
    pool = _pool_options(args)
    if args.trainer == "sb3":
        if pool or args.log_dir is not None or args.heldout_count is not None:
            raise ProblemError("--pool, --log-dir and --heldout-count go with the native trainer (--trainer native)")
        unknown = set(given) - set(DEFAULTS)
        if unknown:
            raise ProblemError(f"{', '.join(_flag(k) for k in sorted(unknown))}: a setting of the native trainer, "
                               "not of --trainer sb3")
        settings = {**DEFAULTS, **given}
        check_settings(settings)
    else:
        require_native()
        settings = native_settings(given)
    if pool and args.ENV != POOL_ENV:
        raise ProblemError(f"--pool trains on a named pool's tests through {POOL_ENV}, not {args.ENV}: "
                           f"flowtest train {POOL_ENV} --pool {args.pool} ... (or drop --pool to train on {args.ENV})")
    make_env(args.ENV, **pool).close()  # a bad environment is refused before anything else
    model_path = args.out if args.out.suffix == ".zip" else args.out.with_suffix(".zip")
    for path, what in ((model_path, "model"), (model_path.with_suffix(".png"), "curve"),
                       (model_path.with_suffix(".json"), "training summary")):
        check_output_path(path, args.force, what)
    steps = args.steps if args.steps is not None else (50_000 if args.trainer == "sb3" else 1_500_000)
    shown = " ".join(f"{_flag(k)} {_shown(v)}" for k, v in settings.items())
    extra = "".join(f" --{k} {v}" for k, v in pool.items())
    sys.stderr.write(f"flowtest: training with --trainer {args.trainer} --steps {steps} --seed {args.seed}{extra} {shown}\n")
    sys.stderr.flush()
    if args.trainer == "sb3":
        eval_episodes = 100 if args.eval_episodes is None else args.eval_episodes
        s = train(args.ENV, steps, args.out, args.seed, progress_bar=not args.quiet, eval_episodes=eval_episodes,
                  **given)
        rate = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.0f} %"
        used = ", ".join(f"{k}={v}" for k, v in s["settings"].items())
        sys.stdout.write(
            f"trained {s['steps']} steps in {s['seconds']:.1f} s; system objective met in {rate} of "
            f"{s['eval_episodes']} evaluation runs\nsettings: {used}\n"
            f"model: {s['model']} (use --sut ppo:{s['model']})\ncurve: {s['curve']}\n"
            f"settings and curve data: {Path(s['model']).with_suffix('.json')}\n"
        )
        return EXIT_OK
    heldout: list[Any] = []
    if pool:
        n_heldout = 32 if args.heldout_count is None else args.heldout_count
        if n_heldout:
            from flowtest_env.game import TestGame
            from flowtest_env.pools import load_pool

            heldout = [TestGame(a) for a in load_pool(pool["pool"], "test", n_heldout, progress=not args.quiet)]
    eval_episodes = args.eval_episodes if args.eval_episodes is not None else (0 if pool else 100)
    s = train_native(args.ENV, steps, args.out, args.seed, progress_bar=not args.quiet, eval_episodes=eval_episodes,
                     env_kwargs=pool, heldout=heldout, log_dir=args.log_dir, eval_every=args.eval_every, **given)
    lines = [f"trained {s['steps']} steps in {s['seconds']:.1f} s ({s['steps_per_second']:,.0f} steps/s on "
             f"{s['device']}, evaluations {s['eval_seconds']:.1f} s more)"]
    for split, what in (("train", "the train tests" if pool else "the env's tests"), ("heldout", "held-out tests")):
        if split in s["final"]:
            r = s["final"][split]
            lines.append(f"greedy on {what}: system objective met {100 * r['met']:.1f} %, test objective realized "
                         f"{100 * r['realized']:.1f} %, {r['restrictions']:.1f} restrictions per run")
    if s["success_rate"] is not None:
        lines.append(f"system objective met in {100 * s['success_rate']:.0f} % of {s['eval_episodes']} evaluation runs")
    used = ", ".join(f"{k}={_shown(v)}" for k, v in s["settings"].items())
    lines += [f"settings: {used}", f"model: {s['model']} (use --sut ppo:{s['model']})", f"curve: {s['curve']}",
              f"settings and curve data: {Path(s['model']).with_suffix('.json')}"]
    if args.log_dir is not None:
        lines.append(f"logs: {args.log_dir} (progress.csv; tensorboard --logdir {args.log_dir})")
    sys.stdout.write("\n".join(lines) + "\n")
    return EXIT_OK


COMMAND = Command("train", "train a PPO system under test against a synthesized test", add_arguments, run)
