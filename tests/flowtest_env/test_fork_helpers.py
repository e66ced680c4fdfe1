"""Loading and compiling fork helpers only where the process may have children: inside a
multiprocessing pool's worker (a benchmark trains its runs in one) a fork would fail."""

from __future__ import annotations

import multiprocessing

import pytest

from flowtest_env.bulk import can_fork
from flowtest_env.compiled import PARALLEL_FROM, helpers


def _in_worker(_: int) -> tuple[int, bool]:
    return helpers(10 * PARALLEL_FROM), can_fork()


@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="the platform does not fork")
def test_no_fork_helpers_inside_a_pool_worker() -> None:
    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.map(_in_worker, [0]) == [(0, False)]
