"""The ``flowtest`` console script: Ctrl-C is quiet from the first instant.

Importing the command line (numpy, scipy, HiGHS, ...) takes a second or two; a Ctrl-C
then would otherwise end in a ``KeyboardInterrupt`` traceback from inside an import. The
handler installed here before those imports exits 130 with the same one line as
:func:`experiments.cli.main`; once they are done, Python's own handler is back and
``main`` maps ``KeyboardInterrupt`` itself.
"""

from __future__ import annotations

import os
import signal
import sys
from types import FrameType


def _interrupted_while_starting(signum: int, frame: FrameType | None) -> None:
    try:
        sys.stderr.write("flowtest: interrupted\n")
        sys.stderr.flush()
    finally:
        os._exit(130)


def main() -> None:
    """Run ``flowtest`` (the entry point in pyproject.toml)."""
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not if the caller ignores Ctrl-C
        signal.signal(signal.SIGINT, _interrupted_while_starting)
        from experiments.cli import main as cli_main

        signal.signal(signal.SIGINT, signal.default_int_handler)
    else:
        from experiments.cli import main as cli_main
    sys.exit(cli_main())
