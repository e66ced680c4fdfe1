"""``flowtest train ENV --steps N --out PATH``: train a PPO system under test against a test.

Uses sb3-contrib's ``MaskablePPO`` with the env's action masks (the SUT never wastes a
step on a restricted move; the masks are what a real SUT observes before committing),
an MLP policy on the flat observation plus the SUT's memory of the places it has
occupied (:mod:`agents.ppo`), several envs stepped together, a progress bar, one seed
for everything. Writes
the model (``PATH``, a ``.zip``), its training curve (``PATH`` with ``.png``: success
rate and episode return against time steps) and ``PATH`` with ``.json`` (settings,
time, the curve's data). Load the model as a SUT with ``--sut ppo:PATH``: train on one
test, evaluate on others with ``flowtest evaluate``.

Needs the ``rl`` extra (``pip install 'flowtest[rl]'``: torch, stable-baselines3,
sb3-contrib).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.errors import ProblemError

from .cli import EXIT_OK, check_output_path, command, nonnegative_int, positive_int, write_atomically

DEFAULTS: dict[str, Any] = {
    "n_envs": 8,
    "n_steps": 128,
    "batch_size": 256,
    "learning_rate": 1e-3,
    "gamma": 0.99,
    "ent_coef": 0.01,
    "n_epochs": 10,
    "net_arch": [64, 64],
    "shaping": 10.0,
    "memory": "visited",
}
"""PPO settings: 8 envs stepped in one process (one batched policy call per step of all
eight), rollouts of 8 x 128 steps, a small network, a high learning rate; the shaping
scale (:func:`_shaped`); the SUT's memory (:mod:`agents.ppo`: without it no
deterministic policy passes a reactive test that makes the SUT pass a cell twice)."""


def _require_rl() -> None:
    try:
        import sb3_contrib  # noqa: F401
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise ProblemError("training needs the rl extra: pip install 'flowtest[rl]'") from None


def _shaped(env: Any, gamma: float, scale: float) -> Any:
    """Potential-based reward shaping (Ng et al. 1999), which keeps the optimal policies:
    ``r + gamma * phi(v') - phi(v)`` with ``phi = -distance / scale``, the distance to
    acceptance on the SUT's own product graph ``G_sys`` past the static walls. It uses
    only what the SUT knows (its map and its objective), never the test objective; the
    sparse goal reward alone is almost never found by random exploration in the mazes."""
    import gymnasium as gym

    from agents.scripted import INF, SystemProduct

    class Shaping(gym.Wrapper):
        def _phi(self) -> float:
            u = self.env.unwrapped
            game = u.game
            prod = self._prods.get(id(game))
            if prod is None:
                prod = self._prods[id(game)] = SystemProduct(game)
            q = int(game.q_sys[u.run.history])
            d = prod.distances()[prod.node(u.run.system, q)]
            return -min(float(d), 4 * scale) / scale if d < INF else -4.0

        def reset(self, **kwargs: Any) -> Any:
            if not hasattr(self, "_prods"):
                self._prods: dict[int, SystemProduct] = {}
            out = self.env.reset(**kwargs)
            self._last = self._phi()
            return out

        def step(self, action: Any) -> Any:
            obs, r, term, trunc, info = self.env.step(action)
            phi = 0.0 if term else self._phi()
            r = float(r) + gamma * phi - self._last
            self._last = phi
            return obs, r, term, trunc, info

    return Shaping(env)


def make_training_env(env_id: str, seed: int, gamma: float = 0.99, shaping: float = 10.0,
                       memory: str = "visited") -> Any:
    """The env wrapped for MaskablePPO (:class:`sb3_contrib.common.wrappers.ActionMasker`),
    with potential-based shaping when ``shaping > 0`` (see :func:`_shaped`) and the SUT's
    ``memory`` in the observation (:func:`agents.ppo.with_memory`)."""
    from sb3_contrib.common.wrappers import ActionMasker

    from agents.ppo import with_memory

    from .evaluate import make_env

    env = make_env(env_id)
    if shaping > 0:
        env = _shaped(env, gamma, shaping)
    env = with_memory(env, memory)
    env.reset(seed=seed)
    env.action_space.seed(seed)
    return ActionMasker(env, lambda e: e.unwrapped.action_masks())


def make_training_vec_env(env_id: str, seed: int, settings: dict[str, Any]) -> Any:
    """``settings["n_envs"]`` training envs (seeds ``seed``, ``seed + 1``, ...) in one
    process (SB3's ``DummyVecEnv``): the envs step in microseconds, the policy network is
    the cost, and it runs once per step for all of them."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    n = int(settings["n_envs"])
    if n < 1:
        raise ProblemError("n_envs must be at least 1")
    return DummyVecEnv([
        (lambda i=i: make_training_env(env_id, seed + i, settings["gamma"], settings["shaping"], settings["memory"]))
        for i in range(n)
    ])


def make_model(env: Any, settings: dict[str, Any], seed: int) -> Any:
    """A ``MaskablePPO`` on ``env`` with ``settings`` (see :data:`DEFAULTS`), on the CPU,
    one torch thread, seeded; it records its memory kind for :class:`agents.ppo.PPOPolicy`."""
    import torch
    from sb3_contrib import MaskablePPO

    torch.manual_seed(seed)
    torch.set_num_threads(1)
    model = MaskablePPO(
        "MlpPolicy", env, seed=seed, verbose=0, device="cpu",
        n_steps=settings["n_steps"], batch_size=settings["batch_size"], learning_rate=settings["learning_rate"],
        gamma=settings["gamma"], ent_coef=settings["ent_coef"], n_epochs=settings["n_epochs"],
        policy_kwargs={"net_arch": list(settings["net_arch"])},
    )
    model.flowtest_memory = settings["memory"]  # saved with the model, read by PPOPolicy
    return model


def _progress_callback(total: int) -> Any:
    """A tqdm progress bar on stderr as an SB3 callback (SB3's own needs ``rich`` too)."""
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    class Bar(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, unit="step", desc="training", file=sys.stderr, mininterval=1.0)

        def _on_step(self) -> bool:
            self.bar.update(self.num_timesteps - self.bar.n)  # one call per step of all envs
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return Bar()


class _Curve:
    """Records (time step, success, return) at every episode end of every training env,
    as an SB3 callback."""

    def __init__(self) -> None:
        from stable_baselines3.common.callbacks import BaseCallback

        curve = self

        class Callback(BaseCallback):
            def __init__(self) -> None:
                super().__init__()
                self.ret: np.ndarray | None = None

            def _on_step(self) -> bool:
                rewards, dones, infos = self.locals["rewards"], self.locals["dones"], self.locals["infos"]
                if self.ret is None:
                    self.ret = np.zeros(len(rewards))
                self.ret += rewards
                for i in np.flatnonzero(dones):
                    verdict = infos[i].get("verdict", {})
                    curve.points.append((self.num_timesteps, verdict.get("system_objective") == "met", float(self.ret[i])))
                    self.ret[i] = 0.0
                return True

        self.points: list[tuple[int, bool, float]] = []
        self.callback = Callback()


def success_rate(model: Any, env_id: str, episodes: int = 100, seed: int = 10_000) -> float:
    """Share of ``episodes`` seeded runs (deterministic policy) that meet the system objective."""
    from agents.ppo import PPOPolicy

    from .evaluate import make_env, run_episode

    env = make_env(env_id)
    policy = PPOPolicy(model, "ppo", env)
    met = 0
    for i in range(episodes):
        t = run_episode(env, policy, env_id, "ppo", seed + i, record=False)
        met += t.verdict["system_objective"] == "met"
    env.close()
    return met / episodes


def plot_curve(points: list[tuple[int, bool, float]], path: Path, title: str) -> None:
    """Success rate and return (moving averages over 20 episodes) against time steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    if points:
        steps = np.array([p[0] for p in points])
        win = min(20, len(points))
        kernel = np.ones(win) / win
        succ = np.convolve([float(p[1]) for p in points], kernel, mode="valid")
        ret = np.convolve([p[2] for p in points], kernel, mode="valid")
        a1.plot(steps[win - 1 :], 100 * succ, color="#2ca02c")
        a2.plot(steps[win - 1 :], ret, color="#1f77b4")
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
    _require_rl()
    if steps < 1:
        raise ProblemError("--steps must be at least 1")
    settings = {**DEFAULTS, **overrides}
    out = Path(out)
    model_path = out if out.suffix == ".zip" else out.with_suffix(".zip")
    env = make_training_vec_env(env_id, seed, settings)
    model = make_model(env, settings, seed)
    curve = _Curve()
    t0 = time.perf_counter()
    callbacks = [curve.callback] + ([_progress_callback(steps)] if progress_bar else [])
    model.learn(total_timesteps=steps, callback=callbacks)
    seconds = time.perf_counter() - t0
    write_atomically(model_path, lambda tmp: model.save(str(tmp)))
    png = model_path.with_suffix(".png")
    write_atomically(png, lambda tmp: plot_curve(curve.points, tmp, f"MaskablePPO on {env_id} (seed {seed})"))
    rate = success_rate(model, env_id, eval_episodes) if eval_episodes else None
    summary = {
        "env": env_id, "steps": int(model.num_timesteps), "seed": seed, "seconds": round(seconds, 2), "success_rate": rate,
        "eval_episodes": eval_episodes, "settings": settings, "model": str(model_path), "curve": str(png),
        "episodes": len(curve.points),
        "points": [[s, bool(m), round(r, 4)] for s, m, r in curve.points],
    }
    write_atomically(model_path.with_suffix(".json"), lambda tmp: tmp.write_text(json.dumps(summary) + "\n"))
    return summary


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("ENV", help="environment: a registered ID (FlowTest-Maze2-v0), a built-in name (maze2), a problem "
                               "file (mine.toml) or an artifact file")
    p.add_argument("--steps", type=positive_int, default=50_000, help="training time steps (default 50000)")
    p.add_argument("--out", type=Path, required=True, help="model file (.zip); the curve goes next to it (.png)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed (default 0)")
    p.add_argument("--eval-episodes", type=nonnegative_int, default=100, help="evaluation runs after training (default 100)")
    p.add_argument("--force", action="store_true", help="overwrite an existing model, curve or summary")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


@command("train", "train a PPO system under test against a synthesized test", _arguments)
def run_train(args: argparse.Namespace) -> int:
    """Train, save, evaluate; print where the model and its curve are."""
    from .evaluate import make_env

    make_env(args.ENV).close()  # a bad ID is refused before anything else
    model_path = args.out if args.out.suffix == ".zip" else args.out.with_suffix(".zip")
    for path, what in ((model_path, "model"), (model_path.with_suffix(".png"), "curve"),
                       (model_path.with_suffix(".json"), "training summary")):
        check_output_path(path, args.force, what)
    s = train(args.ENV, args.steps, args.out, args.seed, progress_bar=not args.quiet, eval_episodes=args.eval_episodes)
    rate = "-" if s["success_rate"] is None else f"{100 * s['success_rate']:.0f} %"
    sys.stdout.write(
        f"trained {s['steps']} steps in {s['seconds']:.1f} s; system objective met in {rate} of "
        f"{s['eval_episodes']} evaluation runs\nmodel: {s['model']} (use --sut ppo:{s['model']})\ncurve: {s['curve']}\n"
    )
    return EXIT_OK
