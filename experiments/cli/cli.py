"""The ``flowtest`` command line: the parser built from the command list, and ``main``.

``flowtest COMMAND ...`` runs one of :data:`experiments.cli.commands.COMMANDS` (each in its
own module, see :mod:`experiments.cli.command` for the interface). :func:`main` is the single
place that maps FlowTest's exceptions to exit codes (:mod:`experiments.cli.exits` lists
them); ``python -m experiments``, ``python -m experiments.cli.cli`` and the console script
(:mod:`experiments.cli.console`) all run it.

Layers, each importing only downward::

    cli (parser, main)          this module
    commands (the list)         experiments/cli/commands.py
    one module per command      synthesize, demo, evaluate, train, train_tester, benchmark
    episode running, training   experiments/cli/episodes.py, experiments/cli/training.py
    plumbing                    exits, arguments, outputs, progress, command
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import threading
import warnings
from collections.abc import Sequence
from types import FrameType

from experiments.progress import PROG, say
from synthesis.routing.solver_control import solves_running

from .arguments import ArgumentParser
from .command import Command
from .commands import COMMANDS
from .exits import EXIT_INTERNAL, EXIT_INTERRUPTED, exit_code_for, flush_and_exit

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def build_parser(commands: Sequence[Command] = COMMANDS) -> argparse.ArgumentParser:
    """The argument parser with a sub-parser per command of ``commands``.

    Raises
    ------
    ValueError
        If two commands have the same name.
    """
    names = [cmd.name for cmd in commands]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"subcommands named twice: {', '.join(twice)}")
    parser = ArgumentParser(
        prog=PROG,
        description="Flow-based synthesis of reactive tests for discrete decision-making systems.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for cmd in commands:
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.help)
        cmd.add_arguments(p)
        p.set_defaults(run=cmd.run)
    return parser


def _terminated(signum: int, frame: FrameType | None) -> None:
    """SIGTERM takes the Ctrl-C path: the same unwinding (temporary files removed, no
    partial output), the same line and exit code."""
    raise KeyboardInterrupt


def terminate_as_interrupt() -> None:
    """Make SIGTERM raise :class:`KeyboardInterrupt` in this (main) thread, unless the
    caller set its own handler or ignores it."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
        signal.signal(signal.SIGTERM, _terminated)


def one_line_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int, file: object = None, line: str | None = None) -> None:
    """Show a warning as one plain line on stderr, ``flowtest: warning: ...`` (no source
    line, no colours; gymnasium's ``WARN:`` prefix dropped)."""
    text = _ANSI.sub("", str(message))
    text = text[len("WARN: ") :] if text.startswith("WARN: ") else text
    say(f"{PROG}: warning: " + " ".join(text.split()))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code (see :mod:`experiments.cli.exits`).

    When it runs as the process (``argv`` None), SIGTERM is handled as Ctrl-C: exit
    130 with the one line ``flowtest: interrupted``, outputs written whole or not at all;
    and every warning is one line, ``flowtest: warning: ...``.
    """
    if argv is None:
        terminate_as_interrupt()
        warnings.showwarning = one_line_warning
    try:
        parser = build_parser()
        args = parser.parse_args(argv)  # usage errors exit 2 via argparse
        code = int(args.run(args))
        if argv is None and solves_running():
            # a solver run abandoned at the time limit (solver_control.SolverAbandoned) would be
            # joined at interpreter exit: its answer is not needed, so leave now (outputs are
            # already written whole)
            flush_and_exit(code)
        return code
    except KeyboardInterrupt:
        # the user's own act, not an error: one plain line, no traceback
        say(f"{PROG}: interrupted")
        if argv is None:
            # we are the process (the console script): leave now. Exiting normally would
            # wait at interpreter shutdown for a solver thread that has not yet reached a
            # point where it notices the stop (solver_control.solves_running()), and
            # tearing torch down after a training run can take seconds. Outputs
            # are written atomically and their temporary files removed while the
            # interrupt unwound, so no partial file is left behind.
            flush_and_exit(EXIT_INTERRUPTED)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # stdout closed early (e.g. `| head`): not an error worth a traceback
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return EXIT_INTERNAL
    except Exception as exc:  # FlowTest's errors get their line and code; anything else is a bug
        return exit_code_for(exc)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
