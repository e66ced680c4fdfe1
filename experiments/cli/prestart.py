"""Start the CP-SAT child at the very start of ``flowtest synthesize``, before the command's imports.

A fresh CP-SAT child (:mod:`synthesis.routing.backends.cpsat_worker`) takes a fraction of a second
to start, and importing the command line (NumPy, SciPy, HiGHS, FlowTest) about as long;
one after the other they are a large share of a short command such as refueling's. So the console script
(:mod:`experiments.cli.console`) asks :func:`prestart_for` first thing, with the raw
arguments: when they may lead to a CP-SAT solve (``synthesize`` with ``--backend`` auto
or cpsat), a child starts and loads OR-Tools on the other core while this process
imports. The guess is cheap to get wrong: an unused child costs a small fraction of a CPU second, and
:mod:`experiments.cli.synthesize` ends it as soon as the problem shows that ``auto`` will not
pick CP-SAT, and in any case when the command ends.

This module imports no more than :mod:`synthesis.routing.backends.cpsat_pool` (the standard library).
"""

from __future__ import annotations

from collections.abc import Sequence
from importlib.util import find_spec

from synthesis.routing.backends.cpsat_pool import prestart

BACKENDS_WITH_CPSAT = ("auto", "cpsat")
"""The ``--backend`` values under which ``flowtest synthesize`` may solve on CP-SAT."""


def may_use_cpsat(argv: Sequence[str]) -> bool:
    """Whether the command line ``argv`` (without the program name) may solve on CP-SAT:
    ``synthesize`` (not its help) with ``--backend`` auto (the default) or cpsat, and
    OR-Tools installed. Read without the parser, which is not imported yet; a wrong guess
    only starts (or does not start) a child early."""
    if not argv or argv[0] != "synthesize":
        return False
    args = list(argv[1:])
    if "-h" in args or "--help" in args:
        return False
    backend = "auto"
    for i, arg in enumerate(args):  # the last one counts, as with argparse
        if arg == "--backend" and i + 1 < len(args):
            backend = args[i + 1]
        elif arg.startswith("--backend="):
            backend = arg.partition("=")[2]
    return backend in BACKENDS_WITH_CPSAT and find_spec("ortools") is not None


def prestart_for(argv: Sequence[str]) -> bool:
    """Start an idle CP-SAT child if :func:`may_use_cpsat` (returns whether it did)."""
    if not may_use_cpsat(argv):
        return False
    try:
        prestart()
    except OSError:  # no process to spare now: the solve starts its own child, and says why if it cannot
        return False
    return True


__all__ = ["BACKENDS_WITH_CPSAT", "may_use_cpsat", "prestart_for"]
