"""The ``flowtest`` console script: Ctrl-C is quiet from the first instant.

Importing the command line (numpy, scipy, HiGHS, ...) takes a second or two; a Ctrl-C
then would otherwise end in a ``KeyboardInterrupt`` traceback from inside an import. The
handler installed here before those imports exits 130 with the same one line as
:func:`experiments.cli.cli.main`; once they are done, Python's own handler is back and
``main`` maps ``KeyboardInterrupt`` itself. SIGTERM is handled the same way from the first
instant (``main`` then turns it into ``KeyboardInterrupt``: the Ctrl-C path).

Before those imports, too, ``flowtest synthesize`` starts its CP-SAT child
(:mod:`experiments.cli.prestart`), so that both load at once; the child is ended with the
command (and killed by the early Ctrl-C handler).
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType


def _interrupted_while_starting(signum: int, frame: FrameType | None) -> None:
    try:
        pool = sys.modules.get("synthesis.routing.backends.cpsat_pool")
        if pool is not None:  # a prestarted CP-SAT child goes with us
            pool.kill_idle_now()
        sys.stderr.write("flowtest: interrupted\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


def main() -> None:
    """Run ``flowtest`` (the entry point in pyproject.toml)."""
    early = signal.getsignal(signal.SIGINT) is signal.default_int_handler  # not if the caller ignores Ctrl-C
    if early:
        signal.signal(signal.SIGINT, _interrupted_while_starting)
    term = signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None)
    if term:
        signal.signal(signal.SIGTERM, _interrupted_while_starting)
    from experiments.cli.prestart import prestart_for
    from synthesis.routing.backends.cpsat_pool import close_idle_workers

    prestart_for(sys.argv[1:])
    from experiments.cli.cli import main as cli_main

    if early:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if term:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)  # cli_main installs its Ctrl-C path for it
    try:
        code = cli_main()
    finally:
        close_idle_workers()  # a prestarted child the command did not use, reaped
    sys.exit(code)
