"""The list of ``flowtest`` subcommands, in the order ``flowtest --help`` shows them.

One place names every command (:class:`~experiments.cli.command.Command`, one module each);
adding a command is one import and one entry here.
"""

from __future__ import annotations

from . import benchmark, demo, evaluate, serve, synthesize, train, train_tester
from .command import Command

COMMANDS: tuple[Command, ...] = (
    synthesize.COMMAND,
    demo.COMMAND,
    evaluate.COMMAND,
    train.COMMAND,
    train_tester.COMMAND,
    benchmark.COMMAND,
    serve.COMMAND,
)
"""Every subcommand of ``flowtest``."""
