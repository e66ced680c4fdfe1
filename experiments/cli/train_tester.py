"""``flowtest train-tester PROBLEM --steps N --out PATH``: learn a tester with PPO.

This module parses the arguments, calls the library
(:func:`experiments.training.tester.train_tester`, whose module says what the tester learns and
against whom) and prints where the model is and what the exhaustive fairness check found. It
writes the model (``PATH``, a ``.zip``, usable as ``--tester ppo:PATH``), its training curve
(``.png``) and a summary (``.json``); an existing one is refused unless ``--force``. Needs the
``rl`` extra.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from experiments.outputs import check_output_path
from experiments.training.tester import resolve_problem, train_tester
from synthesis.model.errors import ProblemError

from .arguments import nonnegative_int, positive_int
from .command import Command
from .exits import EXIT_OK


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest train-tester``'s arguments."""
    p.add_argument("PROBLEM", help="a built-in problem with a test agent or reactive doors (maze2, small-reactive, ...) or its env ID")
    p.add_argument("--against", default="scripted:replanner", metavar="POLICY", help="the fixed system the tester trains against (default scripted:replanner)")
    p.add_argument("--steps", type=positive_int, default=20_000, help="tester steps (default 20000)")
    p.add_argument("--out", type=Path, required=True, help="model file (.zip); curve (.png) and summary (.json) next to it")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed (default 0)")
    p.add_argument("--eval-episodes", type=nonnegative_int, default=10, help="runs against --against after training (default 10)")
    p.add_argument(
        "--trap-penalty", type=float, default=0.0, help="reward when the system's objective is still open at the end (default 0: not asked to be fair)"
    )
    p.add_argument("--force", action="store_true", help="overwrite an existing model, curve or summary")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Train, save, check; print where the model is and what the fairness check found."""
    from agents.base import PolicyError

    resolve_problem(args.PROBLEM)  # a bad name is refused before anything else
    out = args.out if args.out.suffix == ".zip" else args.out.with_suffix(".zip")
    for path, what in ((out, "model"), (out.with_suffix(".png"), "curve"), (out.with_suffix(".json"), "training summary")):
        check_output_path(path, args.force, what)
    try:
        s = train_tester(
            args.PROBLEM,
            args.steps,
            out,
            args.against,
            args.seed,
            progress_bar=not args.quiet,
            eval_episodes=args.eval_episodes,
            trap_penalty=args.trap_penalty,
        )
    except PolicyError as exc:
        raise ProblemError(f"--against {args.against}: {exc}") from None
    f = s["fairness"]
    rate = "-" if "realized_before_goal_rate" not in s else f"{100 * s['realized_before_goal_rate']:.0f} %"
    sys.stdout.write(
        f"trained {s['steps']} steps in {s['seconds']:.1f} s; against {s['system']} the test objective was realized "
        f"before the goal in {rate} of {args.eval_episodes} runs\n"
        f"fairness (exhaustive, {f['nodes']} game states): "
        f"{'fair' if f['fair'] else str(f['traps']) + ' trap states'}; "
        f"{'every' if f['guaranteed'] else 'not every'} run meeting the goal realizes the test objective\n"
        f"model: {s['model']} (use --tester ppo:{s['model']})\ncurve: {s['curve']}\n"
    )
    return EXIT_OK


COMMAND = Command("train-tester", "train a PPO tester (tester_0 of the PettingZoo game) against a fixed system", add_arguments, run)
