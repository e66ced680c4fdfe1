"""The interface of a ``flowtest`` subcommand.

A command lives in its own module (``experiments/cli/synthesize.py``, ``experiments/cli/train.py``,
...) and exposes one value, ``COMMAND``, a :class:`Command`::

    def add_arguments(p: argparse.ArgumentParser) -> None:
        p.add_argument("PROBLEM")

    def run(args: argparse.Namespace) -> int:
        ...
        return EXIT_OK

    COMMAND = Command("demo", "run a scripted system through a test", add_arguments, run)

The command list (:data:`experiments.cli.commands.COMMANDS`) names every command explicitly;
nothing registers itself on import. ``run`` receives the parsed arguments and returns an
exit code (:mod:`experiments.cli.exits`); it raises FlowTest's errors and
:func:`experiments.cli.cli.main` maps them to exit codes, so a command never prints a
traceback or calls ``sys.exit``. A command module parses its arguments and calls the library
(:mod:`experiments.evaluation`, :mod:`experiments.benchmark`, :mod:`experiments.training`, ...);
it imports the parser's plumbing (:mod:`~experiments.cli.exits`, :mod:`~experiments.cli.arguments`),
the shared plumbing (:mod:`experiments.outputs`, :mod:`experiments.progress`) and the library,
never another command module, :mod:`experiments.cli.cli` or :mod:`experiments.cli.commands`
(``tests/docs/test_import_graph.py``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass


@dataclass(frozen=True)
class Command:
    """One subcommand: ``flowtest NAME ...``."""

    name: str
    """What the user types after ``flowtest``."""
    help: str
    """One line, shown by ``flowtest --help`` and as the command's description."""
    add_arguments: Callable[[argparse.ArgumentParser], None]
    """Declares the command's arguments on its sub-parser."""
    run: Callable[[argparse.Namespace], int]
    """The command's body: parsed arguments in, exit code out."""
