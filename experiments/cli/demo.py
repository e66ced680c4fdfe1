"""``flowtest demo``: the main job of the README's first command.

This module parses the arguments, calls the library (:func:`experiments.demo.run_demo`, whose
module says what the demo synthesizes, trains and evaluates) and prints the table and where the
files are. The output folder is the demo's own (a marker file); ``--trust-model`` lets it play a
stable-baselines3 ``ppo-maze2.zip`` found there.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from experiments.demo import DEMO_PROBLEMS, run_demo
from experiments.progress import StageProgress
from synthesis.problems.load import load_problem

from .arguments import add_trust_model, apply_trust_model, positive_int
from .command import Command
from .exits import EXIT_OK


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest demo``'s arguments."""
    p.add_argument("--out", type=Path, default=Path("flowtest-demo"), help="output folder (default: flowtest-demo)")
    p.add_argument("--problems", nargs="+", default=list(DEMO_PROBLEMS), metavar="NAME", help="problems to synthesize")
    p.add_argument("--episodes", type=positive_int, default=5, help="evaluation episodes per system (default 5)")
    p.add_argument("--no-evaluation", action="store_true", help="only synthesize and draw, run no system under test")
    add_trust_model(
        p,
        "play a stable-baselines3 ppo-maze2.zip found in the folder, which unpickles it (code from the "
        "file runs); the demo's own model is a native checkpoint and never needs it",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")


def run(args: argparse.Namespace) -> int:
    """Synthesize each demo problem, write its picture, artifact and a summary, then the
    evaluation report; print the table and where the files are."""
    out: Path = args.out
    problems = [load_problem(name) for name in args.problems]  # every input checked before any work
    apply_trust_model(args)
    with StageProgress(enabled=not args.quiet) as progress:
        result = run_demo(out, problems, episodes=args.episodes, evaluation=not args.no_evaluation, progress=progress)
        progress.done(f"done in {progress.elapsed():.1f} s")
    sys.stdout.write("\n".join(result.lines[2:]) + "\n\n")
    sys.stdout.write(f"pictures, artifacts and summary.md are in {out.resolve()}\n")
    if result.report is not None:
        sys.stdout.write(f"evaluation report (open in a browser): {Path(result.report).resolve()}\n")
    return EXIT_OK


COMMAND = Command("demo", "synthesize and draw the built-in examples into a folder", add_arguments, run)
