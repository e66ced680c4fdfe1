"""Learning a tester with PPO: the library behind ``flowtest train-tester PROBLEM --steps N --out PATH``.

The learned tester plays ``tester_0`` of the PettingZoo game (:mod:`flowtest_env.multiagent`)
by its rules (legal moves only: MaskablePPO with the tester's action mask) against a
fixed system policy (default the correct ``scripted:replanner``), seen through
:class:`agents.testers.TesterView`. Its reward is what a test engineer asks for: +1
when the system meets its objective with the hidden test objective realized on the way,
-1 when it meets it without. Nothing in the reward asks it to be fair: runs the system
could not finish are tracked (the training curve), and whether the tester *can* trap a
correct system is decided exhaustively after training (:mod:`flowtest_env.fairness`).

Writes the model (``PATH``, a ``.zip``, usable as ``--tester ppo:PATH``), its training
curve (``.png``: realized-before-goal and unfinished runs against time steps) and a
summary (``.json``: settings, time, the final deterministic tester's results against
the system it trained with, and the exhaustive fairness check). Seeded; progress bar
on stderr. Needs the ``rl`` extra.
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoint import mark_own_file
from experiments.outputs import write_atomically
from synthesis.model.errors import ProblemError

from .rl import EpisodeCurve, EpisodeEnd, action_masks_of, learn, make_ppo, moving_average, require_rl

DEFAULTS: dict[str, Any] = {
    "n_envs": 4,
    "n_steps": 128,
    "batch_size": 128,
    "learning_rate": 1e-3,
    "gamma": 0.99,
    "ent_coef": 0.02,
    "n_epochs": 10,
    "net_arch": [64, 64],
    "trap_penalty": 0.0,
}
"""PPO settings of a learned tester: 4 envs in one process, rollouts of 4 x 128 steps, a
small network; ``trap_penalty`` (0: not asked to be fair, see the module docstring)."""


def resolve_problem(name: str) -> str:
    """A built-in problem name, or the problem of a built-in env ID (``FlowTest-Maze2-v0``).

    Raises
    ------
    ProblemError
        If ``name`` is neither.
    """
    from agents.base import PolicyError
    from agents.testers import problem_of
    from flowtest_env.artifacts import artifact_path
    from flowtest_env.envs import BUILTIN_ENVS

    if name in BUILTIN_ENVS and artifact_path(name).exists():
        return name
    try:
        return problem_of(name)[0]
    except PolicyError:
        raise ProblemError(f"unknown problem {name!r}; known: {', '.join(BUILTIN_ENVS)} or their env IDs") from None


def make_tester_vec_env(problem: str, system: str, seed: int, settings: dict[str, Any]) -> Any:
    """``settings["n_envs"]`` :class:`~agents.testers.TesterView` envs (seeds ``seed``,
    ``seed + 1``, ...) in one process, masked for MaskablePPO."""
    from sb3_contrib.common.wrappers import ActionMasker
    from stable_baselines3.common.vec_env import DummyVecEnv

    from agents.testers import TesterView

    def make(i: int) -> Any:
        env = TesterView(problem, system, trap_penalty=settings["trap_penalty"])
        env.reset(seed=seed + i)
        env.action_space.seed(seed + i)
        return ActionMasker(env, action_masks_of)

    n = int(settings["n_envs"])
    if n < 1:
        raise ProblemError("n_envs must be at least 1")
    return DummyVecEnv([partial(make, i) for i in range(n)])


def plot_tester_curve(points: list[EpisodeEnd], path: Path, title: str) -> None:
    """Realized-before-goal and unfinished runs (moving averages over 20 episodes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6))
    if points:
        steps = np.array([p.step for p in points])
        realized = moving_average([float(p.met and p.realized) for p in points])
        unfinished = moving_average([float(not p.met) for p in points])
        for share, label, color in ((realized, "met, test objective realized", "#2ca02c"), (unfinished, "not met (stalled or trapped)", "#d62728")):
            ax.plot(steps[len(steps) - len(share) :], 100 * share, color=color, label=label)
    ax.set_ylabel("share of episodes (%)")
    ax.set_xlabel("time steps")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def assess(model_path: str | Path, problem: str, system: str, episodes: int, seed: int = 10_000) -> dict[str, Any]:
    """The saved tester, deterministic, against ``system`` for ``episodes`` seeded runs, and
    its exhaustive fairness check (:func:`flowtest_env.fairness.check_tester`)."""
    from agents.registry import make_policy
    from agents.testers import VersusTesterEnv
    from flowtest_env.fairness import check_tester

    env = VersusTesterEnv(problem, f"ppo:{model_path}")
    out: dict[str, Any] = {"fairness": check_tester(env.ma, env.tester).summary()}
    if episodes:
        policy = make_policy(system, env)
        met = realized = 0
        for i in range(episodes):
            obs, info = env.reset(seed=seed + i)
            policy.reset(seed + i)
            done = False
            while not done:
                obs, _, term, trunc, info = env.step(policy.act(obs, info))
                done = term or trunc
            v = info["verdict"]
            met += v["system_objective"] == "met"
            realized += v["system_objective"] == "met" and v["test_objective_realized"]
        out.update({"episodes": episodes, "met_rate": met / episodes, "realized_before_goal_rate": realized / episodes})
    return out


def train_tester(
    problem: str,
    steps: int,
    out: str | Path,
    system: str = "scripted:replanner",
    seed: int = 0,
    progress_bar: bool = True,
    eval_episodes: int = 10,
    **overrides: Any,
) -> dict[str, Any]:
    """Train a tester on ``problem`` against ``system`` for ``steps`` tester steps (rounded
    up to whole rollouts); save model, curve and summary (see the module docstring).

    Example::

        s = train_tester("maze2", 20_480, "testers/maze2.zip", system="scripted:replanner")
        s["fairness"]["fair"], s["realized_before_goal_rate"]   # the exhaustive check; the runs against it

    Returns
    -------
    dict
        ``problem``, ``system``, ``steps``, ``seed``, ``seconds``, ``model``, ``curve`` and the
        assessment (:func:`assess`).
    """
    require_rl()
    from agents.testers import TESTER_ROLE

    if steps < 1:
        raise ProblemError("--steps must be at least 1")
    problem = resolve_problem(problem)
    settings = {**DEFAULTS, **overrides}
    out = Path(out)
    model_path = out if out.suffix == ".zip" else out.with_suffix(".zip")
    env = make_tester_vec_env(problem, system, seed, settings)
    model = make_ppo(env, settings, seed)
    # saved with the model, read by agents.testers.PPOTester
    model.flowtest_role = TESTER_ROLE
    model.flowtest_problem = problem
    model.flowtest_system = system
    curve = EpisodeCurve()
    seconds = learn(model, steps, curve, progress_bar)
    write_atomically(model_path, lambda tmp: model.save(str(tmp)))
    mark_own_file(model_path)  # assessed below: this run wrote it, so it loads without --trust-model
    png = model_path.with_suffix(".png")
    write_atomically(png, lambda tmp: plot_tester_curve(curve.points, tmp, f"learned tester on {problem} vs {system} (seed {seed})"))
    summary = {
        "problem": problem,
        "system": system,
        "steps": int(model.num_timesteps),
        "seed": seed,
        "seconds": round(seconds, 2),
        "settings": settings,
        "model": str(model_path),
        "curve": str(png),
        "episodes": len(curve.points),
        **assess(model_path, problem, system, eval_episodes),
        "points": [[p.step, p.met and p.realized, not p.met] for p in curve.points],
    }
    write_atomically(model_path.with_suffix(".json"), lambda tmp: tmp.write_text(json.dumps(summary) + "\n"))
    return summary
