"""The torch vector env checks ``num_envs`` at its entry point as the NumPy env does (issue 43):
``2.5`` was silently 2 envs, ``2**40`` a ``MemoryError`` from a 312 TiB allocation; now each is
one ``ValueError`` that says what is wrong, before anything is allocated."""

from __future__ import annotations

import time
import tracemalloc
from typing import Any

import gymnasium as gym
import pytest

torch_vector = pytest.importorskip("flowtest_env.torch_vector")

ENV = "FlowTest-SmallReactive-v0"


@pytest.mark.parametrize("num_envs", [2.5, 0, -3, True, "4"])
def test_a_count_that_is_not_a_positive_integer_is_refused_as_by_the_numpy_env(num_envs: Any) -> None:
    with pytest.raises(ValueError) as numpy_error:
        gym.make_vec(ENV, num_envs=num_envs, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError) as torch_error:
        torch_vector.make_vec(ENV, num_envs)
    assert str(torch_error.value) == str(numpy_error.value) == f"num_envs must be a positive integer, not {num_envs!r}"


def test_a_batch_larger_than_the_memory_is_refused_before_any_allocation() -> None:
    tracemalloc.start()
    try:
        t0 = time.perf_counter()
        with pytest.raises(ValueError, match=r"num_envs=1099511627776 would need about .* GiB of memory .* Use fewer envs"):
            torch_vector.make_vec(ENV, 2**40)
        elapsed = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20 and elapsed < 10
    assert torch_vector.make_vec(ENV, 3).num_envs == 3  # a sound count still builds
