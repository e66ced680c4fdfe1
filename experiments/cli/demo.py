"""``flowtest demo``: the main job of the README's first command.

Synthesizes the built-in examples (Maze 2 first), checks each test, and writes into one
output folder a picture and an artifact per example plus a Markdown summary; then runs
the correct, faulty, GR(1) and random systems under test against ``FlowTest-Maze2-v0``
(and a PPO system, trained on it in about ten seconds by the native trainer, when the
``rl`` extra is installed) and writes the evaluation report. A ``ppo-maze2.zip`` already in
the folder is played only if it is a native checkpoint (data, :mod:`agents.checkpoint`);
a stable-baselines3 zip there (code, when loaded) is refused unless ``--trust-model``. The folder is FlowTest's own:
it carries a marker file, and the demo refuses to write into an existing folder without it,
so nothing a user made is overwritten.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from synthesis.artifacts.artifact import artifact_of
from synthesis.artifacts.summary import summary_of
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.load import load_problem

from .arguments import positive_int
from .command import Command
from .evaluate import evaluate, write_report
from .exits import EXIT_OK
from .outputs import json_safe, prepare_output_folder, write_atomically
from .progress import StageProgress
from .train import train_native
from .training import rl_installed

MARKER = ".flowtest-demo"
#: The examples the demo synthesizes, fastest first.
DEMO_PROBLEMS = ("maze2", "small-reactive", "example1", "beaver-rescue", "motion-primitives", "refueling")


DEMO_PPO_STEPS = 16_384
"""Training steps of the demo's PPO system (about ten seconds; ``python -m
experiments.lab.bench_ppo`` measures how many it needs, see docs/benchmarks.md)."""

DEMO_PPO_SETTINGS: dict[str, Any] = {"n_envs": 16, "n_steps": 64, "batch_size": 256, "n_epochs": 4, "device": "cpu"}
"""The native trainer's settings for the demo's small budget (one test: few envs, more epochs)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest demo``'s arguments."""
    p.add_argument("--out", type=Path, default=Path("flowtest-demo"), help="output folder (default: flowtest-demo)")
    p.add_argument(
        "--problems", nargs="+", default=list(DEMO_PROBLEMS), metavar="NAME", help="problems to synthesize"
    )
    p.add_argument("--episodes", type=positive_int, default=5, help="evaluation episodes per system (default 5)")
    p.add_argument("--no-evaluation", action="store_true", help="only synthesize and draw, run no system under test")
    p.add_argument("--trust-model", action="store_true",
                   help="play a stable-baselines3 ppo-maze2.zip found in the folder, which unpickles it (code from the "
                        "file runs); the demo's own model is a native checkpoint and never needs it")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")


def prepare_folder(out: Path) -> None:
    """Create ``out`` as a demo folder, or accept one the demo created before (its marker)."""
    prepare_output_folder(out, MARKER, False, "demo output folder", hint="it was not made by the demo: use --out")


_RESERVED_STEMS = {"summary", "evaluation"}


def file_stems(names: list[str]) -> list[str]:
    """A safe, distinct file stem per problem: its name with anything but letters, digits,
    ``_`` and ``-`` replaced, so a problem given by path (``../x.toml``) or with a name
    holding ``/`` is written inside the demo folder, never next to the user's file."""
    stems: list[str] = []
    for name in names:
        stem = re.sub(r"[^A-Za-z0-9_-]+", "-", name).strip("-") or "problem"
        if stem in _RESERVED_STEMS:
            stem += "-problem"
        base, k = stem, 2
        while stem in stems:
            stem, k = f"{base}-{k}", k + 1
        stems.append(stem)
    return stems


def run_evaluation_demo(out_dir: str | Path, episodes: int = 5, progress: Callable[[str], None] | None = None) -> Path:
    """Evaluate the correct, faulty and GR(1) SUTs on ``FlowTest-Maze2-v0``, and, when the
    ``rl`` extra is installed, a PPO SUT: the model at ``<out_dir>/ppo-maze2.zip``, trained
    there first (:data:`DEMO_PPO_STEPS` steps, seed 0) if there is none. Write the report
    and return the path of ``report.html``."""
    out = Path(out_dir)
    suts = ["scripted:replanner", "gr1", "scripted:committed", "scripted:fuel-blind", "scripted:greedy", "random"]
    model = demo_model(out)  # absolute: the replay commands work from anywhere
    if not model.exists() and rl_installed():
        if progress is not None:
            progress(f"training a PPO system under test on FlowTest-Maze2-v0 ({DEMO_PPO_STEPS} steps)")
        train_native("FlowTest-Maze2-v0", DEMO_PPO_STEPS, model, seed=0, progress_bar=False, eval_episodes=0,
                     eval_every=0, **DEMO_PPO_SETTINGS)
    if model.exists():
        suts.append(f"ppo:{model}")
    cells = evaluate(["FlowTest-Maze2-v0"], suts, episodes, 0, progress)
    write_report(cells, out)
    return out / "report.html"


def demo_model(out_dir: Path) -> Path:
    """Where the demo's PPO model lies in its evaluation folder (absolute)."""
    return (Path(out_dir) / "ppo-maze2.zip").resolve()


def check_demo_model(out_dir: Path) -> None:
    """Refuse, before any work, a ``ppo-maze2.zip`` in the evaluation folder that is not a
    native checkpoint (a stable-baselines3 zip runs code when loaded), unless trusted.

    Raises
    ------
    agents.checkpoint.UntrustedModelError
        For such a file without :func:`agents.checkpoint.trust_pickled_models`.
    """
    from agents.checkpoint import is_native_checkpoint, pickled_models_trusted, refuse_pickled

    model = demo_model(out_dir)
    if model.exists() and not is_native_checkpoint(model) and not pickled_models_trusted():
        raise refuse_pickled(model)


def run(args: argparse.Namespace) -> int:
    """Synthesize each demo problem, write its picture, artifact and a summary."""
    from .plots import plot_test

    out: Path = args.out
    problems = [load_problem(name) for name in args.problems]  # every input checked before any work
    if args.trust_model:
        from agents.checkpoint import trust_pickled_models

        trust_pickled_models(True)
    if not args.no_evaluation:
        check_demo_model(out / "evaluation")
    stems = file_stems([p.name for p in problems])
    prepare_folder(out)
    rows = []
    with StageProgress(enabled=not args.quiet) as progress:
        for problem, name in zip(problems, stems, strict=True):
            progress(f"synthesizing {problem.name} ({problem.kind} test)")
            t0 = time.perf_counter()
            test = synthesize(problem, SynthesisOptions(progress=progress))
            seconds = time.perf_counter() - t0
            summary = json_safe(summary_of(test))
            write_atomically(out / f"{name}.json", artifact_of(test, summary).save)
            write_atomically(out / f"{name}.png", partial(plot_test, test))
            rows.append((name, problem.kind, summary, seconds))
        report = None
        if not args.no_evaluation:
            progress("evaluating systems under test against FlowTest-Maze2-v0")
            report = run_evaluation_demo(out / "evaluation", episodes=args.episodes, progress=progress)
        progress.done(f"done in {progress.elapsed():.1f} s")
    lines = [
        "# FlowTest demo",
        "",
        "| problem | environment | status | flow | cuts | bypass flow | seconds | picture |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, kind, s, seconds in rows:
        lines.append(
            f"| {name} | {kind} | {s['status']} | {s['flow']} | {s['n_cuts']} | {s['bypass_flow']} "
            f"| {seconds:.2f} | [{name}.png]({name}.png) |"
        )
    write_atomically(out / "summary.md", lambda tmp: tmp.write_text("\n".join(lines) + "\n"))
    write_atomically(out / "summary.json", lambda tmp: tmp.write_text(json.dumps([s for _, _, s, _ in rows], indent=1) + "\n"))
    sys.stdout.write("\n".join(lines[2:]) + "\n\n")
    sys.stdout.write(f"pictures, artifacts and summary.md are in {out.resolve()}\n")
    if report is not None:
        sys.stdout.write(f"evaluation report (open in a browser): {Path(report).resolve()}\n")
    return EXIT_OK


COMMAND = Command("demo", "synthesize and draw the built-in examples into a folder", add_arguments, run)
