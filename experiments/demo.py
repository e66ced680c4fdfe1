"""``flowtest demo``: the main job of the README's first command.

Synthesizes the built-in examples (Maze 2 first), checks each test, and writes into one
output folder a picture and an artifact per example plus a Markdown summary; then runs
the correct, faulty, GR(1) and random systems under test against ``FlowTest-Maze2-v0``
(and a PPO system, trained on it in about ten seconds, when the ``rl`` extra is
installed) and writes the evaluation report. The folder is FlowTest's own:
it carries a marker file, and the demo refuses to write into an existing folder without it,
so nothing a user made is overwritten.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from synthesis.artifact import artifact_of
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems import load_problem
from synthesis.summary import summary_of

from .cli import EXIT_OK, StageProgress, command, json_safe, write_atomically
from synthesis.errors import ProblemError

MARKER = ".flowtest-demo"
#: The examples the demo synthesizes, fastest first.
DEMO_PROBLEMS = ("maze2", "small-reactive", "example1", "beaver-rescue", "motion-primitives", "refueling")


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", type=Path, default=Path("flowtest-demo"), help="output folder (default: flowtest-demo)")
    p.add_argument(
        "--problems", nargs="+", default=list(DEMO_PROBLEMS), metavar="NAME", help="problems to synthesize"
    )
    p.add_argument("--episodes", type=int, default=5, help="evaluation episodes per system (default 5)")
    p.add_argument("--no-evaluation", action="store_true", help="only synthesize and draw, run no system under test")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")


def prepare_folder(out: Path) -> None:
    """Create ``out`` as a demo folder, or accept one the demo created before."""
    if out.exists():
        if not out.is_dir():
            raise ProblemError(f"demo output {str(out)!r} exists and is not a folder")
        if any(out.iterdir()) and not (out / MARKER).exists():
            raise ProblemError(
                f"demo output folder {str(out)!r} exists and was not made by the demo; "
                "choose another with --out"
            )
    out.mkdir(parents=True, exist_ok=True)
    (out / MARKER).write_text("made by `flowtest demo`; its files may be overwritten by the next demo\n")


@command("demo", "synthesize and draw the built-in examples into a folder", _arguments)
def run_demo(args: argparse.Namespace) -> int:
    """Synthesize each demo problem, write its picture, artifact and a summary."""
    from .plots import plot_test

    out: Path = args.out
    prepare_folder(out)
    rows = []
    with StageProgress(enabled=not args.quiet) as progress:
        for name in args.problems:
            problem = load_problem(name)
            progress(f"synthesizing {name} ({problem.kind} test)")
            t0 = time.perf_counter()
            test = synthesize(problem, SynthesisOptions(progress=progress))
            seconds = time.perf_counter() - t0
            summary = json_safe(summary_of(test))
            write_atomically(out / f"{name}.json", artifact_of(test, summary).save)
            write_atomically(out / f"{name}.png", lambda tmp: plot_test(test, tmp))
            rows.append((name, problem.kind, summary, seconds))
        report = None
        if not args.no_evaluation:
            from .evaluate import run_evaluation_demo

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
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    (out / "summary.json").write_text(json.dumps([s for _, _, s, _ in rows], indent=1) + "\n")
    sys.stdout.write("\n".join(lines[2:]) + "\n\n")
    sys.stdout.write(f"pictures, artifacts and summary.md are in {out.resolve()}\n")
    if report is not None:
        sys.stdout.write(f"evaluation report (open in a browser): {Path(report).resolve()}\n")
    return EXIT_OK
