"""``flowtest train ENV --steps N --out PATH``: train a PPO system under test against a test.

``ENV`` is anything ``flowtest evaluate --env`` takes (a registered ID, a built-in name, a
problem file, an artifact file). The algorithm (``--algo``): sb3-contrib's ``MaskablePPO``
(default) with the env's action masks (the SUT never wastes a step on a restricted move;
the masks are what a real SUT observes before committing), or sb3-contrib's
``RecurrentPPO`` (an LSTM policy: its own memory, no masks). Everything it adds to the
environment is an env option, printed at the start and saved with the model:

* ``memory="visited"`` (default here): the places the SUT has occupied this episode
  appended to the observation (:class:`flowtest_env.wrappers.VisitedPlaces`); without
  memory no policy passes a reactive test that makes the SUT pass a cell twice;
* ``shaping=10`` (default here; 0 turns it off): potential-based shaping towards the SUT's
  own objective (:class:`flowtest_env.wrappers.DistanceShaping`);
* ``obs_kind`` and ``pad_to``: the observation (``"padded"`` gives one shape for every grid
  test up to ``pad_to x pad_to``, so one policy plays many tests).

Every setting of :data:`DEFAULTS` is a flag (``--learning-rate``, ``--memory none``, ...).
Writes the model (``PATH``, a ``.zip``), its training curve (``PATH`` with ``.png``:
success rate and episode return against time steps) and ``PATH`` with ``.json``
(settings, time, the curve's data). Load the model as a SUT with ``--sut ppo:PATH``.

Needs the ``rl`` extra (``pip install 'flowtest[rl]'``: torch, stable-baselines3,
sb3-contrib).
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

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


def success_rate(model: Any, env_id: str, episodes: int = 100, seed: int = 10_000) -> float:
    """Share of ``episodes`` seeded runs (deterministic policy) that meet the system objective."""
    from agents.ppo import PPOPolicy

    env = make_env(env_id)
    policy = PPOPolicy(model, "ppo", env)
    met = 0
    for i in range(episodes):
        t = run_episode(env, policy, env_id, "ppo", seed + i, record=False)
        met += t.verdict["system_objective"] == "met"
    env.close()
    return met / episodes


def plot_curve(points: list[EpisodeEnd], path: Path, title: str) -> None:
    """Success rate and return (moving averages over 20 episodes) against time steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    if points:
        steps = np.array([p.step for p in points])
        succ = moving_average([float(p.met) for p in points])
        ret = moving_average([p.ret for p in points])
        a1.plot(steps[len(steps) - len(succ) :], 100 * succ, color="#2ca02c")
        a2.plot(steps[len(steps) - len(ret) :], ret, color="#1f77b4")
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


def train(env_id: str, steps: int, out: str | Path, seed: int = 0, progress_bar: bool = True,
          eval_episodes: int = 100, **overrides: Any) -> dict[str, Any]:
    """Train MaskablePPO on ``env_id`` for ``steps`` time steps (rounded up to whole
    rollouts of ``n_envs x n_steps``); save model, curve, summary. ``overrides`` replace
    entries of :data:`DEFAULTS`.

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


def _flag(key: str) -> str:
    return "--" + key.replace("_", "-")


def _net_arch(text: str) -> list[int]:
    try:
        return [int(w) for w in text.split(",") if w.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected layer widths such as 64,64, not {text!r}") from None


SETTING_HELP: dict[str, str] = {
    "algo": f"algorithm: {', '.join(ALGOS)}",
    "n_envs": "envs stepped together", "n_steps": "rollout steps per env", "batch_size": "minibatch size",
    "learning_rate": "learning rate", "gamma": "discount", "ent_coef": "entropy bonus", "n_epochs": "epochs per rollout",
    "net_arch": "hidden layer widths, comma-separated", "lstm_hidden_size": "LSTM width (recurrent-ppo only)",
    "shaping": "env option: shaping scale, 0 = off",
    "memory": "env option: the SUT's memory, none or visited", "obs_kind": "env option: flat, grid or padded",
    "pad_to": "env option: grid side of obs_kind=padded",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest train``'s arguments."""
    p.add_argument("ENV", help="environment: a registered ID (FlowTest-Maze2-v0), a built-in name (maze2), a problem "
                               "file (mine.toml) or an artifact file")
    p.add_argument("--steps", type=positive_int, default=50_000, help="training time steps (default 50000)")
    p.add_argument("--out", type=Path, required=True, help="model file (.zip); the curve goes next to it (.png)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed (default 0)")
    p.add_argument("--eval-episodes", type=nonnegative_int, default=100, help="evaluation runs after training (default 100)")
    p.add_argument("--force", action="store_true", help="overwrite an existing model, curve or summary")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    g = p.add_argument_group("settings (printed at the start and saved in the .json)")
    for key, default in DEFAULTS.items():
        shown = ",".join(map(str, default)) if isinstance(default, list) else default
        kw: dict[str, Any] = {"default": None, "help": f"{SETTING_HELP[key]} (default {shown})"}
        if isinstance(default, list):
            kw["type"] = _net_arch
        elif isinstance(default, str):
            kw["choices"] = {"algo": ALGOS, "memory": ("none", "visited"), "obs_kind": ("flat", "grid", "padded")}[key]
        else:
            kw["type"] = type(default)
        g.add_argument(_flag(key), dest=key, **kw)


def run(args: argparse.Namespace) -> int:
    """Train, save, evaluate; print the settings used, then where the model and its curve are."""
    overrides = {k: getattr(args, k) for k in DEFAULTS if getattr(args, k) is not None}
    settings = {**DEFAULTS, **overrides}
    check_settings(settings)
    make_env(args.ENV).close()  # a bad environment is refused before anything else
    model_path = args.out if args.out.suffix == ".zip" else args.out.with_suffix(".zip")
    for path, what in ((model_path, "model"), (model_path.with_suffix(".png"), "curve"),
                       (model_path.with_suffix(".json"), "training summary")):
        check_output_path(path, args.force, what)
    shown = {k: ",".join(map(str, v)) if isinstance(v, list) else v for k, v in settings.items()}
    sys.stderr.write("flowtest: training with " + " ".join(f"{_flag(k)} {v}" for k, v in shown.items()) + "\n")
    s = train(args.ENV, args.steps, args.out, args.seed, progress_bar=not args.quiet, eval_episodes=args.eval_episodes,
              **overrides)
    rate = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.0f} %"
    used = ", ".join(f"{k}={v}" for k, v in s["settings"].items())
    sys.stdout.write(
        f"trained {s['steps']} steps in {s['seconds']:.1f} s; system objective met in {rate} of "
        f"{s['eval_episodes']} evaluation runs\nsettings: {used}\n"
        f"model: {s['model']} (use --sut ppo:{s['model']})\ncurve: {s['curve']}\n"
        f"settings and curve data: {Path(s['model']).with_suffix('.json')}\n"
    )
    return EXIT_OK


COMMAND = Command("train", "train a PPO system under test against a synthesized test", add_arguments, run)
