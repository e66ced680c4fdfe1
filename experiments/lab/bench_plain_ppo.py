"""Plain stable-baselines3 code on a FlowTest env: MaskablePPO with sb3-contrib's defaults and
the documented memory wrapper, nothing from ``flowtest train``.

What a new user writes::

    env = DummyVecEnv([lambda: VisitedPlaces(gymnasium.make("FlowTest-Maze2-v0"))] * 8)
    model = MaskablePPO("MlpPolicy", env, n_steps=128, batch_size=256, learning_rate=1e-3,
                        ent_coef=0.01, policy_kwargs={"net_arch": [64, 64]}, seed=seed)
    model.learn(100_000)

Trains in rounds of ``--chunk`` steps up to ``--max-steps`` and after each round plays
``--episodes`` evaluation runs with the deterministic policy and the env's masks (plain SB3
calls too); records the share of runs that met the system objective. ``--wrappers`` picks the
wrappers (``visited``, ``visited+shaping``, ``none``), ``--hparams`` sb3-contrib's
defaults or the small settings of :data:`HYPERPARAMETERS`. Writes one CSV row per round
(``--csv``) and, with ``--plot``, a figure of every CSV given to ``--plot-from``.

Run: ``python -m experiments.lab.bench_plain_ppo --seed S --csv docs/data/plain-ppo/visited-sS.csv``.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np

import flowtest_env  # noqa: F401  (registers FlowTest-*-v0)
from flowtest_env.wrappers import DistanceShaping, VisitedPlaces

WRAPPERS: dict[str, Callable[[gym.Env], gym.Env]] = {
    "none": lambda env: env,
    "visited": VisitedPlaces,
    "visited+shaping": lambda env: DistanceShaping(VisitedPlaces(env), scale=10.0, gamma=0.99),
}
"""The wrapper stacks the benchmark compares (shaping's gamma is MaskablePPO's default)."""


HYPERPARAMETERS: dict[str, dict[str, Any]] = {
    "defaults": {},
    "small": {"n_steps": 128, "batch_size": 256, "learning_rate": 1e-3, "ent_coef": 0.01, "policy_kwargs": {"net_arch": [64, 64]}},
}
"""MaskablePPO keyword arguments: sb3-contrib's defaults, or short rollouts, a larger step
size and a small network (the settings ``flowtest train`` uses, written as plain SB3 keywords)."""


def make(env_id: str, wrappers: str) -> gym.Env:
    """The env as a user builds it: ``gymnasium.make`` and the documented wrappers."""
    return WRAPPERS[wrappers](gym.make(env_id))


def success_rate(model: Any, env_id: str, wrappers: str, episodes: int, seed: int = 10_000) -> float:
    """Share of seeded runs (deterministic policy, masks from the env) meeting the system objective."""
    env = make(env_id, "visited" if "visited" in wrappers else "none")
    met = 0
    for i in range(episodes):
        obs, info = env.reset(seed=seed + i)
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=True, action_masks=cast(Any, env.unwrapped).action_masks())
            obs, _, term, trunc, info = env.step(int(action))
            done = term or trunc
        met += info["verdict"]["system_objective"] == "met"
    return met / episodes


def run(
    env_id: str, wrappers: str, seed: int, chunk: int, max_steps: int, episodes: int, n_envs: int, out_csv: Path | None, hparams: str = "defaults"
) -> list[dict[str, Any]]:
    """Train and evaluate in rounds; return (and write) one row per round."""
    import torch
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    torch.set_num_threads(1)
    venv = DummyVecEnv([lambda: make(env_id, wrappers)] * n_envs)
    model = MaskablePPO("MlpPolicy", venv, seed=seed, device="cpu", **HYPERPARAMETERS[hparams])
    rows: list[dict[str, Any]] = []
    train_s = 0.0
    while model.num_timesteps < max_steps:
        t0 = time.perf_counter()
        model.learn(total_timesteps=chunk, reset_num_timesteps=False)
        train_s += time.perf_counter() - t0
        rate = success_rate(model, env_id, wrappers, episodes)
        rows.append(
            {
                "env": env_id,
                "wrappers": wrappers,
                "hparams": hparams,
                "seed": seed,
                "steps": model.num_timesteps,
                "train_seconds": round(train_s, 2),
                "met_rate": rate,
            }
        )
        print(f"{wrappers:16s} {hparams:8s} seed {seed}  {model.num_timesteps:7d} steps  {train_s:7.1f} s  met {100 * rate:5.1f} %", flush=True)
    if out_csv is not None:
        out_csv.parent.mkdir(parents=True, exist_ok=True)
        with out_csv.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return rows


def plot(csvs: list[Path], path: Path, title: str) -> None:
    """Share of runs meeting the system objective against training steps, one line per CSV."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {
        "none, defaults": "#d62728",
        "visited, defaults": "#9467bd",
        "visited+shaping, defaults": "#ff7f0e",
        "visited, small": "#1f77b4",
        "visited+shaping, small": "#2ca02c",
        "none, small": "#8c564b",
    }
    fig, ax = plt.subplots(figsize=(7, 4))
    labelled: set[str] = set()
    for c in csvs:
        with c.open() as f:
            rows = list(csv.DictReader(f))
        if not rows:
            continue
        w = f"{rows[0]['wrappers']}, {rows[0]['hparams']}"
        steps = np.array([int(r["steps"]) for r in rows])
        rate = np.array([100 * float(r["met_rate"]) for r in rows])
        ax.plot(steps, rate, color=colors.get(w, "black"), alpha=0.8, label=None if w in labelled else w)
        labelled.add(w)
    ax.axhline(95, color="gray", lw=1, ls="--")
    ax.set_xlabel("training steps")
    ax.set_ylabel("system objective met (%)")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    ax.legend(title="wrappers, hyperparameters")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Train and evaluate (exit 0 if the last round reached ``--target``), or plot CSVs."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--env", default="FlowTest-Maze2-v0")
    p.add_argument("--wrappers", choices=sorted(WRAPPERS), default="visited")
    p.add_argument("--hparams", choices=sorted(HYPERPARAMETERS), default="defaults")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--chunk", type=int, default=8_192)
    p.add_argument("--max-steps", type=int, default=100_000)
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--n-envs", type=int, default=4)
    p.add_argument("--target", type=float, default=0.95)
    p.add_argument("--csv", type=Path)
    p.add_argument("--plot", type=Path, help="draw the CSVs of --plot-from into this PNG instead of training")
    p.add_argument("--plot-from", type=Path, nargs="*", default=[])
    args = p.parse_args(argv)
    if args.plot is not None:
        plot(args.plot_from, args.plot, f"plain MaskablePPO on {args.env}, one line per seed")
        return 0
    rows = run(args.env, args.wrappers, args.seed, args.chunk, args.max_steps, args.episodes, args.n_envs, args.csv, args.hparams)
    reached = [r["steps"] for r in rows if r["met_rate"] >= args.target]
    if reached:
        print(f"first >= {100 * args.target:.0f} % after {reached[0]} steps; last round {100 * rows[-1]['met_rate']:.0f} %")
    else:
        print(f"not reached in {rows[-1]['steps']} steps", file=sys.stderr)
    return 0 if rows[-1]["met_rate"] >= args.target else 1


if __name__ == "__main__":
    raise SystemExit(main())
