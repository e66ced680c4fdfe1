"""Exit codes of every ``flowtest`` command, and the one line that goes with each.

:func:`experiments.cli.cli.main` is the single place that maps FlowTest's exceptions to exit
codes (:func:`exit_code_for`); a command returns :data:`EXIT_OK` (or a code of its own
listed here) and raises the rest, so no command prints a traceback or calls
``sys.exit`` itself.

====  =========================================================================
code  meaning
====  =========================================================================
0     success
1     an unexpected internal error (traceback printed: a FlowTest bug)
2     invalid input (:class:`~synthesis.model.errors.ProblemError`, bad options,
      an output file that exists without ``--force``)
3     inconsistent problem (:class:`~synthesis.model.errors.InconsistentProblem`)
4     a synthesized test failed its independent check
      (:class:`~synthesis.model.errors.CheckFailed`, a FlowTest bug); ``flowtest
      evaluate``: a test failed its guarantee in a run
5     no solution within the time limit (:class:`TimeoutError`)
130   interrupted (Ctrl-C, or SIGTERM, which takes the same path)
====  =========================================================================
"""

from __future__ import annotations

import os
import sys
import traceback

from experiments.progress import say
from synthesis.model.errors import CheckFailed, InconsistentProblem, ProblemError

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_INVALID = 2
EXIT_INCONSISTENT = 3
EXIT_CHECK_FAILED = 4
EXIT_TIMEOUT = 5
EXIT_INTERRUPTED = 130

INCONSISTENT_REASONS: dict[str, str] = {
    "unreachable": "the goal is unreachable",
    "unroutable": "the test objective is unroutable",
    "infeasible": "no test agent strategy is feasible",
}
"""What each :attr:`InconsistentProblem.reason` means, for the one-line error message."""


def error(message: str) -> None:
    """One line ``error: ...`` on stderr (newlines folded so it stays one line)."""
    say("error: " + " ".join(str(message).split()))


def flush_and_exit(code: int) -> None:
    """Flush Python's standard streams and end the process at once (``os._exit``)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(code)


def exit_code_for(exc: Exception) -> int:
    """Say what went wrong (one ``error:`` line; a traceback too for a FlowTest bug) and
    return the exit code of ``exc`` (see the table above)."""
    if isinstance(exc, ProblemError):
        error(str(exc))
        return EXIT_INVALID
    if isinstance(exc, InconsistentProblem):
        meaning = INCONSISTENT_REASONS.get(exc.reason, exc.reason)
        where = f"{exc.source}: " if exc.source else ""
        error(f"{where}inconsistent problem ({exc.reason}): {meaning}: {exc}")
        return EXIT_INCONSISTENT
    if isinstance(exc, CheckFailed):
        error(f"FLOWTEST BUG (please report it with the problem): the synthesized test failed its check: {exc}")
        return EXIT_CHECK_FAILED
    if isinstance(exc, TimeoutError):
        detail = str(exc) or "no solution was found"
        advice = getattr(exc, "advice", None) or "raise --time-limit or accept a gap with --gap"
        error(f"time limit reached: {detail}; {advice}")
        return EXIT_TIMEOUT
    # a bug: keep the traceback, it is what a maintainer needs
    traceback.print_exception(exc)
    error("internal error (a FlowTest bug); the traceback above says where")
    return EXIT_INTERNAL
