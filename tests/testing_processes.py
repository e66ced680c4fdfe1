"""Helpers for tests that run a FlowTest command in a child process and signal it."""

from __future__ import annotations

import signal
import subprocess

import pytest

BURNER = "while True:\n    pass\n"
"""A Python program that keeps one core busy (``python -c BURNER``): the tests that load the machine start one per core."""


def start_until(argv: list[str], marker: str, sig: signal.Signals = signal.SIGINT) -> subprocess.Popen[str]:
    """Start ``argv`` (stdout and stderr piped, ``sig`` at its default action even if our
    caller ignores it) and read its standard error until a line holds ``marker``: the
    moment a test sends it a signal. Fails the test if the process ends first."""
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=lambda: signal.signal(sig, signal.SIG_DFL))
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if marker in line:
            return proc
    pytest.fail(f"no line with {marker!r}: " + "".join(seen))
