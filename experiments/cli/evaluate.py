"""``flowtest evaluate``: run systems under test against synthesized tests and report.

This module parses the arguments, resolves each ``--env`` test once, checks the systems
against them, calls the library (:mod:`experiments.evaluation`: :func:`~experiments.evaluation.evaluate`
plays every pair, :func:`~experiments.evaluation.write_report` writes ``results.json``,
``report.md``, ``report.html`` and the pictures into ``--out``, as
:mod:`experiments.evaluation.results` describes them; :func:`~experiments.evaluation.replay`
prints one run with ``--replay``) and prints one line per pair.

A problem file among ``--env`` gets its cached test (which ``flowtest synthesize`` fills), else is
synthesized here under ``--time-limit``, with the progress ``flowtest synthesize`` shows (its
stages on stderr, the solver's status on a terminal's live line or every ``--progress`` seconds):
no synthesis runs unseen.

Exit codes: 0, or :data:`EXIT_TEST_FAILED` when a test failed its guarantee in a run (a FlowTest
bug: a run met the system objective without realizing the test objective, or the test trapped
the system); invalid input (an unknown env or system, a system that can play none of the tests,
an ``--out`` folder holding other files without ``--force``) is exit 2 before any run. On Ctrl-C
the pairs played to the end are kept in ``results.json`` and ``report.md``, at once.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from experiments.evaluation import (
    REPORT_MARKER,
    EvaluationInterrupted,
    NamedEnv,
    check_sut_names,
    check_suts_can_play,
    evaluate,
    load_problem_files,
    replay,
    resolve_envs,
    test_failure_records,
    write_partial_report,
    write_report,
)
from experiments.evaluation.results import outcome_lines
from experiments.outputs import prepare_output_folder
from experiments.progress import PROGRESS_EVERY, say, synthesis_progress
from synthesis.model.errors import ProblemError
from synthesis.model.option_rules import SECONDS

from .arguments import add_trust_model, apply_trust_model, int_between, nonnegative_int, option_type, positive_seconds, seconds_at_most
from .command import Command
from .exits import EXIT_CHECK_FAILED, EXIT_OK

if TYPE_CHECKING:
    from synthesis.options import SynthesisOptions

T = TypeVar("T")

DEFAULT_STEP_TIMEOUT, MAX_STEP_TIMEOUT = 10.0, 3600.0
"""``--step-timeout``'s default and largest value (:data:`agents.external.DEFAULT_STEP_TIMEOUT`,
:data:`agents.external.MAX_STEP_TIMEOUT`, which the command line does not import before it runs)."""

MAX_EPISODES = 100_000
"""``--episodes``' largest value: every run of a pair is kept for the report, so a count with no
bound ran until stopped (``--episodes 100000000000000000000``) and grew without limit."""

EXIT_TEST_FAILED = EXIT_CHECK_FAILED
"""A test failure was found (a FlowTest bug), as ``flowtest synthesize``'s failed check."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest evaluate``'s arguments."""
    p.add_argument(
        "--env",
        nargs="+",
        required=True,
        metavar="ENV",
        help="environments: registered IDs (FlowTest-Maze2-v0), built-in names (maze2), problem files "
        "(mine.toml, synthesized once and cached) or artifact files (flowtest synthesize --out)",
    )
    p.add_argument(
        "--sut",
        nargs="+",
        required=True,
        metavar="POLICY",
        help="systems under test: scripted:replanner, scripted:committed, scripted:fuel-blind, "
        "scripted:greedy, random, gr1, ppo:PATH; your own planner: python:MODULE:NAME (a function "
        "act(observation, mask) or a factory, found from the current directory) or "
        'cmd:"COMMAND" (a process speaking JSON lines; docs/runtime.md)',
    )
    p.add_argument(
        "--step-timeout",
        type=seconds_at_most(MAX_STEP_TIMEOUT),
        default=None,
        metavar="SECONDS",
        help="how long a cmd: or python: planner may take to answer one step (default "
        f"{DEFAULT_STEP_TIMEOUT:g}, at most {MAX_STEP_TIMEOUT:g}; a cmd: planner's first answer includes its start)",
    )
    p.add_argument(
        "--tester",
        nargs="+",
        default=["synthesized"],
        metavar="TESTER",
        help="who plays the test: synthesized (default), ppo:PATH (a learned tester, flowtest train-tester); several give a side-by-side comparison",
    )
    p.add_argument(
        "--episodes", type=int_between(1, MAX_EPISODES, "a number of runs"), default=10, help=f"runs per SUT and env (default 10, at most {MAX_EPISODES:,})"
    )
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the first run; run i uses seed+i (default 0)")
    p.add_argument("--out", type=Path, help="report folder (required unless --replay); a folder holding files FlowTest did not write is refused unless --force")
    p.add_argument("--force", action="store_true", help="write into an --out folder that holds other files")
    p.add_argument("--replay", action="store_true", help="print every step of the runs instead of a report")
    add_trust_model(
        p,
        "load stable-baselines3 model zips (--sut ppo:PATH, --tester ppo:PATH), which unpickles them: "
        "code from the file runs; native FlowTest checkpoints never need it",
    )
    p.add_argument(
        "--time-limit",
        metavar="S",
        type=option_type(SECONDS),
        help="solver time limit in seconds of a problem file synthesized here (default: the problem's, "
        "else none); a test cached by an earlier synthesis needs none",
    )
    p.add_argument(
        "--progress",
        metavar="S",
        nargs="?",
        type=positive_seconds,
        const=PROGRESS_EVERY,
        help="also when stderr is not a terminal, print the solver's status on stderr every S seconds while a "
        f"problem file is synthesized (default {PROGRESS_EVERY:g}), as flowtest synthesize --progress",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def run(args: argparse.Namespace) -> int:
    """Evaluate (or replay); exit 4 if a test failed its guarantee (a FlowTest bug)."""
    apply_trust_model(args)
    if args.replay:
        with_synthesis(args, lambda synthesis: load_problem_files(args.env, synthesis))
        bug = False
        for env_id in args.env:
            for tester in args.tester:
                for sut in args.sut:
                    for i in range(args.episodes):
                        trace = replay(env_id, sut, args.seed + i, tester=tester, step_timeout=args.step_timeout)
                        bug |= trace.kind == "test"
        return EXIT_TEST_FAILED if bug else EXIT_OK
    if args.out is None:
        raise ProblemError("--out is required (or use --replay)")
    # refuse bad IDs and SUTs before any run or any file: a SUT that can play none of the
    # tests is bad input (a missing model, a typo); one that cannot play some is a report row
    check_sut_names(args.sut)
    tests = with_synthesis(args, lambda synthesis: resolve_envs(args.env, synthesis))  # each test built once, here, and handed on
    try:
        return _evaluate(args, tests)
    finally:
        for test in tests:
            test.env.close()


def with_synthesis(args: argparse.Namespace, resolve: Callable[[SynthesisOptions | None], T]) -> T:
    """``resolve(synthesis)``: where a problem file is among ``--env``, under the options of its
    synthesis (``--time-limit``) and with the progress ``flowtest synthesize`` shows (its stages,
    the solver's status on a terminal's live line or every ``--progress`` seconds, the cached
    test found), whatever a library prints meanwhile kept off stdout; else with none."""
    from flowtest_env.sources import is_problem_file

    if not any(is_problem_file(env) for env in args.env):
        return resolve(None)
    from synthesis.options import SynthesisOptions
    from synthesis.routing.solver_control import stdout_guard

    with stdout_guard(), synthesis_progress(not args.quiet, args.progress) as (progress, control):
        return resolve(SynthesisOptions(time_limit=args.time_limit, progress=progress, control=control))


def _evaluate(args: argparse.Namespace, tests: list[NamedEnv]) -> int:
    """Evaluate the resolved ``tests``, write the report, print one line per pair."""
    check_suts_can_play(tests, args.sut, args.step_timeout)
    prepare_output_folder(args.out, REPORT_MARKER, args.force, "report folder")

    def progress(msg: str) -> None:
        if not args.quiet:
            sys.stderr.write(msg + "\n")
            sys.stderr.flush()

    try:
        cells = evaluate(tests, args.sut, args.episodes, args.seed, progress, testers=args.tester, step_timeout=args.step_timeout)
    except EvaluationInterrupted as stop:
        # keep the pairs played: results.json and report.md at once (no pictures); none played,
        # they say so (an earlier run's files would otherwise look current)
        write_partial_report(stop.cells, args.out)
        if stop.cells:
            say(
                f"flowtest: {len(stop.cells)} of {stop.total} (system, test) pairs were played to the end; "
                f"{args.out / 'results.json'} and report.md hold them (no pictures, no report.html)"
            )
        else:
            say(f"flowtest: no (system, test) pair was played to the end; {args.out / 'results.json'} and report.md say so")
        raise
    progress("drawing trace pictures")
    records = write_report(cells, args.out)
    for line in outcome_lines(records):
        sys.stdout.write(line + "\n")
    bugs = test_failure_records(records)
    if bugs:
        sys.stderr.write("flowtest: FLOWTEST BUG: a test failed its guarantee; see the report\n")
    sys.stdout.write(f"report: {(args.out / 'report.html').resolve()}\n")
    return EXIT_TEST_FAILED if bugs else EXIT_OK


COMMAND = Command("evaluate", "run systems under test against synthesized tests and write a report", add_arguments, run)
