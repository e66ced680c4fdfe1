"""``flowtest synthesize PROBLEM``: turn a problem into a checked test.

The problem is a TOML file or a built-in name. The command prints a summary (or, with
``--json``, exactly the JSON object that problem-format.md fixes), and can write the test
artifact (``--out``) and a picture (``--plot``). Progress goes to standard error only, so
standard output stays clean for scripts; whatever a library prints while the solver runs
is kept off it (:func:`synthesis.routing.solver_control.stdout_guard`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from experiments.human_summary import human_summary
from experiments.outputs import check_output_path, json_safe, print_json, write_atomically
from experiments.progress import PROGRESS_EVERY, StageProgress, synthesis_progress
from synthesis import pipeline
from synthesis.model.errors import ProblemError
from synthesis.model.option_rules import GAP, SECONDS, THREADS
from synthesis.problems.limits import MAX_GRAPH_EDGES
from synthesis.routing.backends.cpsat_pool import close_idle_workers
from synthesis.routing.backends.rules import AUTO_CPSAT_ROWS
from synthesis.routing.solver_control import SolveControl, stdout_guard

from .arguments import option_type, positive_seconds
from .command import Command
from .exits import EXIT_OK

if TYPE_CHECKING:
    from flowtest_env.sources import StoredTest
    from synthesis.problems.problem import Problem


def auto_rule() -> str:
    """What ``--backend auto`` runs, written from the rule itself
    (:data:`synthesis.routing.backends.rules.AUTO_CPSAT_ROWS`), so the help cannot drift from it.

    >>> auto_rule().startswith("CP-SAT for static models of ")
    True
    """
    bands = [f"{mode} models of {lo:,}-{hi:,} rows" for mode, (lo, hi) in AUTO_CPSAT_ROWS.items()]
    return f"CP-SAT for {' and '.join(bands)}, else HiGHS"


def machine_threads(text: str) -> int:
    """The type of ``--threads``: at most this machine's CPUs, then the ``threads`` option's rule
    (:data:`synthesis.model.option_rules.THREADS`)."""
    cpus = os.cpu_count() or 1
    try:
        too_many = int(text) > cpus
    except ValueError:
        too_many = False
    if too_many:
        raise argparse.ArgumentTypeError(f"{text} is more than the {cpus} CPUs of this machine")
    threads: int = option_type(THREADS)(text)
    return threads


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest synthesize``'s arguments."""
    from synthesis.model.strategy import SETTINGS
    from synthesis.problems.builtins import BUILTINS
    from synthesis.routing.options import BACKENDS

    p.add_argument(
        "problem",
        metavar="PROBLEM",
        help=f"a TOML problem file, or a built-in problem: {', '.join(BUILTINS)}",
    )
    p.add_argument("--json", action="store_true", help="print the JSON summary of problem-format.md (only it) on stdout")
    p.add_argument("--out", metavar="ARTIFACT", type=Path, help="write the synthesized-test artifact (JSON) here")
    p.add_argument("--plot", metavar="PNG", type=Path, help="draw the test (PNG, SVG or PDF by the file's suffix)")
    p.add_argument("--time-limit", metavar="S", type=option_type(SECONDS), help="solver time limit in seconds (default: the problem's, else none)")
    p.add_argument(
        "--after-first",
        metavar="S",
        type=option_type(SECONDS),
        help="stop S seconds after the first test is found (--time-limit then bounds the time to it; the paper's budget: --time-limit 600 --after-first 60)",
    )
    p.add_argument("--gap", metavar="G", type=option_type(GAP), default=0.0, help="relative MIP gap at which to stop (default 0: prove optimality)")
    p.add_argument(
        "--threads",
        metavar="N",
        type=machine_threads,
        help="solver threads (default 1: the same answer on every machine; at most the machine's CPUs)",
    )
    p.add_argument(
        "--backend",
        choices=BACKENDS,
        default="auto",
        help=f"the solver of the routing model: highs, cpsat (OR-Tools CP-SAT) or auto (default: {auto_rule()})",
    )
    p.add_argument("--setting", choices=SETTINGS, help="how reactive obstacles are shown (default: the problem's, else instantaneous)")
    p.add_argument("--force", action="store_true", help="overwrite existing --out/--plot files")
    p.add_argument(
        "--fresh",
        action="store_true",
        help=f"synthesize even when the same test is at hand (a built-in's shipped test, a problem file's cached one) "
        f"and took {STORED_AFTER:g} s or more to synthesize: it is shown instead by default",
    )
    p.add_argument(
        "--no-size-limit",
        action="store_true",
        help=f"synthesize even a problem whose product graph may exceed {MAX_GRAPH_EDGES:,} edges (refused by default, with an estimate)",
    )
    for cap, what in (("walls", "walls (static restrictions)"), ("doors", "doors (reactive restrictions)"), ("restrictions", "walls and doors together")):
        p.add_argument(
            f"--max-{cap}",
            metavar="N",
            type=cap_count,
            dest=f"max_{cap}",
            help=f"at most N {what}, each a move between two places counted once (replaces the problem's "
            f"max_{cap}); no test within it: exit 3 with the fewest that would do",
        )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument(
        "--progress",
        metavar="S",
        nargs="?",
        type=positive_seconds,
        const=PROGRESS_EVERY,
        help="also when stderr is not a terminal (a log, a pipe), print the solver's status (best "
        f"test, bound, gap) on stderr every S seconds (default {PROGRESS_EVERY:g}); on a terminal "
        "the live line always shows it",
    )


def cap_count(text: str) -> int:
    """A cap from the command line: a whole number from 0 (argparse's type)."""
    from synthesis.problems.problem import MAX_CAP

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0 to {MAX_CAP}, not {text[:40]!r}") from None
    if not 0 <= value <= MAX_CAP:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0 to {MAX_CAP}, not {text[:40]!r}")
    return value


def caps_of_args(args: argparse.Namespace) -> dict[str, int]:
    """The caps given on the command line (``--max-walls`` etc.)."""
    caps = {}
    for key in ("max_walls", "max_doors", "max_restrictions"):
        value = getattr(args, key, None)
        if value is not None:
            caps[key] = int(value)
    return caps


def run(args: argparse.Namespace) -> int:
    """``flowtest synthesize``: load, synthesize, check, then print and write outputs."""
    from synthesis.problems.load import load_problem

    outputs: list[tuple[Path, str]] = []
    if args.out is not None:
        outputs.append((args.out, "artifact"))
    if args.plot is not None:
        outputs.append((args.plot, "plot"))
    if len(outputs) == 2 and args.out.resolve() == args.plot.resolve():
        raise ProblemError("--out and --plot name the same file")
    for path, what in outputs:  # refuse before spending time on synthesis
        check_output_path(path, args.force, what)
    if args.plot is not None:
        from experiments.plots import check_plot_format

        check_plot_format(args.plot)

    if args.backend == "cpsat":  # refused before any work when the extra is missing
        from synthesis.routing.backends.cpsat import require

        require()
    from synthesis.problems.files import MAX_GRID_CELLS

    max_cells = None if args.no_size_limit else MAX_GRID_CELLS
    try:
        problem = _load(lambda name: load_problem(name, max_cells), args.problem)
        raw = _problem_bytes(args.problem)  # the bytes synthesized, for the cache entry
        if not args.fresh:
            stored = _stored(args, problem)
            if stored is not None:
                close_idle_workers()  # no solve: the prestarted CP-SAT child is not needed
                return _show_stored(args, problem, stored)
        if not pipeline.may_use_cpsat(problem, args.backend):
            close_idle_workers()  # started by the console script in case; not needed here
        return _synthesize(args, problem, raw)
    finally:
        close_idle_workers()  # the CP-SAT child, prestarted or kept after the solve, ends with the command


STORED_AFTER = 10.0
"""Seconds of synthesis from which ``flowtest synthesize`` shows the same test at hand (a
built-in's shipped artifact, a problem file's cache entry: :func:`flowtest_env.sources.stored_test`)
instead of solving again (``--fresh`` solves anyway): patrolling's shipped test took 146 s, every
other built-in that ships a proven optimum a few seconds at most (docs/benchmarks/solvers.md)."""


def options_of(args: argparse.Namespace, progress: Callable[[str], None] | None = None, control: SolveControl | None = None) -> pipeline.SynthesisOptions:
    """The synthesis options ``args`` ask for, with the ``progress`` and ``control`` of the run."""
    return pipeline.SynthesisOptions(
        time_limit=args.time_limit,
        after_first=args.after_first,
        mip_rel_gap=args.gap,
        threads=args.threads,
        backend=args.backend,
        setting=args.setting,
        progress=progress,
        control=control,
        max_graph_edges=None if args.no_size_limit else MAX_GRAPH_EDGES,
        caps=caps_of_args(args),
    )


def _problem_bytes(name: str) -> bytes | None:
    """The bytes of a problem file (``None`` for a built-in), which its cache entry is filed under."""
    from flowtest_env.sources import is_problem_file
    from synthesis.problems.files import read_limited

    return read_limited(Path(name).expanduser(), "problem file") if is_problem_file(name) else None


def synthesis_seconds(summary: dict[str, Any]) -> float:
    """How long the synthesis of a summary's test took: an agent test's whole loop, else its
    graphs and its solve."""
    stats = summary.get("stats", {})
    loop = stats.get("agent_seconds")
    if isinstance(loop, dict) and "total" in loop:
        return float(loop["total"])
    return float(stats.get("graph_seconds", 0.0)) + float(stats.get("solve_seconds", 0.0))


def _stored(args: argparse.Namespace, problem: Problem) -> StoredTest | None:
    """The test at hand that this synthesis would answer (:func:`flowtest_env.sources.stored_test`),
    if it took :data:`STORED_AFTER` seconds or more to synthesize; else ``None``."""
    from flowtest_env.sources import stored_test

    stored = stored_test(args.problem, problem, options_of(args))
    if stored is None or synthesis_seconds(stored.artifact.summary) < STORED_AFTER:
        return None
    return stored


def _show_stored(args: argparse.Namespace, problem: Problem, stored: StoredTest) -> int:
    """Show a stored test as a synthesis's: say where it comes from (stderr), write ``--out``
    and ``--plot``, print its summary."""
    from synthesis.problems.problem import build_graphs

    art = stored.artifact
    summary = json_safe(art.summary)
    took = synthesis_seconds(summary)
    made = art.extras.get("made_with", {}) or {
        "backend": summary.get("stats", {}).get("backend", "?"),
        "version": summary.get("stats", {}).get("solver_version", "?"),
    }
    where = f"the shipped test {stored.path}" if stored.shipped else f"its cached test {stored.path}"
    # where the test comes from: one whole line (done(), never cut to a terminal's width); every
    # line is ended before the summary
    with StageProgress(enabled=not args.quiet) as progress:
        progress.done(
            f"{problem.name}: {where} (proven optimal, every check passed): the test this synthesis gives, "
            f"not synthesized again; synthesizing it took {took:.0f} s ({made.get('backend')} {made.get('version')}), "
            "--fresh does it again"
        )
        if args.out is not None:
            progress(f"writing the artifact {args.out}")
            check_output_path(args.out, args.force, "artifact")
            write_atomically(args.out, art.save)
        if args.plot is not None:
            from experiments.plots import plot_artifact

            progress(f"drawing {args.plot}")
            check_output_path(args.plot, args.force, "plot")
            write_atomically(args.plot, lambda tmp: plot_artifact(art, tmp, max_cols=None))
    if args.json:
        print_json(summary)
        return EXIT_OK
    spec, products = build_graphs(problem)
    text = human_summary(StoredView(problem, spec, products, art.strategy, art.agent), summary)
    sys.stdout.write(f"{text}\n  stored       {where}, synthesized in {took:.1f} s; not synthesized now (--fresh does)\n")
    sys.stdout.flush()
    return EXIT_OK


@dataclass(frozen=True)
class StoredView:
    """A stored test as the parts of a synthesized test that :func:`~experiments.human_summary.human_summary`
    reads: the problem, its specification product and product graphs (built again: cheap), the
    stored restrictions and test agent."""

    problem: Problem
    spec: Any
    products: Any
    strategy: Any
    agent: Any


def _synthesize(args: argparse.Namespace, problem: Problem, raw: bytes | None = None) -> int:
    """Synthesize ``problem`` as ``args`` ask, then print and write the outputs; a problem
    file's proven optimum (its bytes ``raw``) is filed where ``flowtest evaluate`` looks for it."""
    from synthesis.artifacts.artifact import artifact_of
    from synthesis.artifacts.summary import summary_of

    every = getattr(args, "progress", None)
    # stdout is ours: whatever a library prints meanwhile (HiGHS's banner, a C printf)
    # goes to /dev/null, and only our summary reaches the real stdout, after
    with stdout_guard(), synthesis_progress(not args.quiet, every) as (progress, control):
        large = large_problem_note(problem, args)
        if large:
            progress(large)
        progress(f"synthesizing {problem.name} ({problem.kind} test)")
        options = options_of(args, progress, control)
        test = pipeline.synthesize(problem, options)
        summary = json_safe(summary_of(test))
        if raw is not None:
            _cache(Path(args.problem).expanduser(), raw, test, options, progress)
        if args.out is not None:
            progress(f"writing the artifact {args.out}")
            check_output_path(args.out, args.force, "artifact")
            write_atomically(args.out, artifact_of(test, summary).save)
        if args.plot is not None:
            progress(f"drawing {args.plot}")
            from experiments.plots import plot_test

            check_output_path(args.plot, args.force, "plot")
            write_atomically(args.plot, lambda tmp: plot_test(test, tmp))
        progress.done(f"done in {progress.elapsed():.1f} s")

    if args.json:
        print_json(summary)
    else:
        sys.stdout.write(human_summary(test, summary) + "\n")
        sys.stdout.flush()
    return EXIT_OK


def _cache(path: Path, raw: bytes, test: Any, options: pipeline.SynthesisOptions, progress: Callable[[str], None]) -> None:
    """File a problem file's test where ``flowtest evaluate --env`` that file looks for it
    (:func:`flowtest_env.sources.cache_problem_test`), and say so: a proven optimum only."""
    from flowtest_env.sources import cache_problem_test
    from synthesis.artifacts.summary import summary_of

    status = summary_of(test).get("status")
    if status != "optimal":
        progress(f"not cached: the test is not proven optimal ({status}); flowtest evaluate takes the --out file as it is")
        return
    entry = cache_problem_test(path, raw, test, options)
    if entry is not None:
        progress(f"cached for flowtest evaluate --env {path}: {entry}")


LARGE_EDGES = 5_000
"""Product-graph edges (the cheap upper bound of :func:`synthesis.problems.limits.estimate_size`)
from which a solve may run for minutes: mars-exploration's 7,759 edges take HiGHS minutes to
its flow 2 (docs/benchmarks.md); the problems that solve in seconds have a few hundred."""


def large_problem_note(problem: Problem, args: argparse.Namespace) -> str | None:
    """The line said at the start of a problem large enough that its solve may run for
    minutes (at least :data:`LARGE_EDGES` product-graph edges by the cheap bound): its size
    and the options that bound the solve; ``None`` for a smaller one.

    Example: ``warehouse is large (T: 900 states, 3,480 moves; up to 27,840 product-graph
    edges): the solve may run for minutes; no time limit set: --time-limit S bounds it ...``"""
    from synthesis.problems.limits import estimate_size

    est = estimate_size(problem)
    if est.edges < LARGE_EDGES:
        return None
    limit = args.time_limit if args.time_limit is not None else problem.time_limit
    bound = (
        f"the time limit of {limit:g} s bounds it (the best test by then, with its gap)"
        if limit is not None
        else "no time limit set: --time-limit S bounds it (the best test by then, with its gap)"
    )
    caps = {**problem.caps, **caps_of_args(args)}
    capped = "caps " + ", ".join(f"{k} = {v}" for k, v in caps.items()) if caps else "--max-walls/--max-doors/--max-restrictions N bound what the test may use"
    return (
        f"{problem.name} is large (T: {est.states:,} states, {est.moves:,} moves; up to {est.edges:,} product-graph "
        f"edges): the solve may run for minutes; {bound}; {capped}"
    )


def _load(load_problem: Callable[[str], Any], name: str) -> Any:
    """Load a problem; prefix errors with the file name when the message lacks it."""
    try:
        return load_problem(name)
    except ProblemError as exc:
        message = str(exc)
        if name not in message and Path(name).name not in message and Path(name).exists():
            raise ProblemError(f"{name}: {message}") from None
        raise


COMMAND = Command("synthesize", "synthesize a test for a problem (TOML file or built-in name)", add_arguments, run)
