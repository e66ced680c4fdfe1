"""Errors a user can cause, kept apart from programming errors.

The command line turns :class:`ProblemError` into exit code 2 and
:class:`InconsistentProblem` into exit code 3, each as one line on standard error.
:class:`CheckFailed` means a synthesized answer failed an independent check: a
FlowTest bug, never a user mistake, so it is reported loudly.
"""

from __future__ import annotations


class FlowTestError(Exception):
    """Base class of every error FlowTest raises on purpose."""


class ProblemError(FlowTestError, ValueError):
    """Invalid input: the message says what is wrong and where."""


class ProblemTooLarge(ProblemError):
    """The problem is well formed but far beyond what can be solved (see
    :mod:`synthesis.problems.limits`); the message gives the estimate and the way to go on."""


class InconsistentProblem(FlowTestError):
    """The problem is well formed but has no test.

    ``reason`` is ``"unreachable"`` (no execution reaches the system goal),
    ``"unroutable"`` (no execution reaching the goal can be routed through the
    test objective without trapping the system) or ``"infeasible"`` (no test
    agent strategy realizes any routing cut set).
    """

    def __init__(self, reason: str, message: str, source: str | None = None) -> None:
        super().__init__(message)
        self.reason = reason
        self.source = source  # which of several inputs has no test (a command's --env), where it matters


class CheckFailed(FlowTestError, AssertionError):
    """A synthesized test failed an independent check (a FlowTest bug)."""
