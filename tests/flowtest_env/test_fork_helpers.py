"""Loading and compiling fork helpers only where the process may have children: inside a
multiprocessing pool's worker (a benchmark trains its runs in one) a fork would fail."""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from flowtest_env.bulk import can_fork
from flowtest_env.compiled import PARALLEL_FROM, helpers


def _in_worker(_: int) -> tuple[int, bool]:
    return helpers(10 * PARALLEL_FROM), can_fork()


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="the platform does not fork")
def test_no_fork_helpers_inside_a_pool_worker() -> None:
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.map(_in_worker, [0]) == [(0, False)]


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="the platform does not fork")
def test_ctrl_c_to_the_process_group_while_a_pool_loads_is_one_line(tmp_path: Path) -> None:
    """A terminal's Ctrl-C reaches the whole process group, the loading helpers too: the
    command still ends with exit 130 and the one line ``flowtest: interrupted`` (the helpers
    turned the signal into a ``KeyboardInterrupt`` traceback of their own)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "HOME": str(tmp_path / "home")}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "experiments.cli.cli",
            "benchmark",
            "--pool",
            "reachability1/5x5-v1",
            "--sut",
            "scripted:replanner",
            "--out",
            str(tmp_path / "out"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert proc.stderr is not None
    for line in proc.stderr:
        if "loading the pool" in line:
            break
    time.sleep(1.0)  # the helpers have started
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "flowtest: interrupted", err
