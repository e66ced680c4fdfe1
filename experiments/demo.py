"""The demo: the main job of the README's first command, ``flowtest demo``
(:mod:`experiments.cli.demo` parses its arguments and calls :func:`run_demo`).

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

import json
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from experiments.evaluation import evaluate, write_report
from experiments.outputs import json_safe, prepare_output_folder, write_atomically
from experiments.training import rl_installed, train_native
from synthesis.artifacts.artifact import artifact_of
from synthesis.artifacts.summary import summary_of
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.problem import Problem

MARKER = ".flowtest-demo"
#: The examples the demo synthesizes, fastest first.
DEMO_PROBLEMS = ("maze2", "small-reactive", "example1", "beaver-rescue", "motion-primitives", "refueling")


DEMO_PPO_STEPS = 16_384
"""Training steps of the demo's PPO system (about ten seconds; ``python -m
experiments.lab.bench_ppo`` measures how many it needs, see docs/benchmarks.md)."""

DEMO_PPO_SETTINGS: dict[str, Any] = {"n_envs": 16, "n_steps": 64, "batch_size": 256, "n_epochs": 4, "device": "cpu"}
"""The native trainer's settings for the demo's small budget (one test: few envs, more epochs)."""


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
        train_native("FlowTest-Maze2-v0", DEMO_PPO_STEPS, model, seed=0, progress_bar=False, eval_episodes=0, eval_every=0, **DEMO_PPO_SETTINGS)
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


@dataclass(frozen=True)
class DemoResult:
    """What :func:`run_demo` wrote: the summary table (``summary.md``'s lines) and the
    evaluation report (``None`` without the evaluation)."""

    lines: tuple[str, ...]
    report: Path | None


def run_demo(
    out: Path, problems: Sequence[Problem], episodes: int = 5, evaluation: bool = True, progress: Callable[[str], None] = lambda _: None
) -> DemoResult:
    """Synthesize each of ``problems`` (loaded, every input checked before), write its
    picture, artifact and a summary into the demo folder ``out`` (created, or one the demo
    created before), then, with ``evaluation``, the evaluation report of the systems under
    test on ``FlowTest-Maze2-v0`` (:func:`run_evaluation_demo`) into ``out/evaluation``.

    Raises
    ------
    ProblemError
        If ``out`` is a folder the demo did not make.
    agents.checkpoint.UntrustedModelError
        For a stable-baselines3 ``ppo-maze2.zip`` in the evaluation folder, untrusted.

    Example::

        from synthesis import load_problem
        result = run_demo(Path("flowtest-demo"), [load_problem("maze2")], episodes=2)
        result.report        # flowtest-demo/evaluation/report.html
    """
    from experiments.plots import plot_test

    if evaluation:
        check_demo_model(out / "evaluation")
    stems = file_stems([p.name for p in problems])
    prepare_folder(out)
    rows = []
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
    if evaluation:
        progress("evaluating systems under test against FlowTest-Maze2-v0")
        report = run_evaluation_demo(out / "evaluation", episodes=episodes, progress=progress)
    lines = [
        "# FlowTest demo",
        "",
        "| problem | environment | status | flow | cuts | bypass flow | seconds | picture |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, kind, s, seconds in rows:
        lines.append(f"| {name} | {kind} | {s['status']} | {s['flow']} | {s['n_cuts']} | {s['bypass_flow']} | {seconds:.2f} | [{name}.png]({name}.png) |")
    write_atomically(out / "summary.md", lambda tmp: tmp.write_text("\n".join(lines) + "\n"))
    write_atomically(out / "summary.json", lambda tmp: tmp.write_text(json.dumps([s for _, _, s, _ in rows], indent=1) + "\n"))
    return DemoResult(tuple(lines), report)
