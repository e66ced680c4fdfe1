"""Shared helpers of the standard-pool tests: a temporary folder in place of the shipped
records, and shipped records copied (and edited) into it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import flowtest_env.standard_pools as sp

REAL_DATA = sp.DATA_DIR
"""The shipped records' folder (taken before any test puts a temporary folder in its place)."""


def empty_data(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty folder in place of the shipped records (for a ``data`` fixture)."""
    folder = tmp_path / "pools"
    monkeypatch.setattr(sp, "DATA_DIR", folder)
    return folder


def copy_split(pool: sp.StandardPool, split: str, data: Path, count: int, edit: Callable[[list[dict[str, Any]]], Any] | None = None) -> Path:
    """The first ``count`` shipped records of a split, copied (``edit(records)`` first) into ``data``."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sp, "DATA_DIR", REAL_DATA)
        records = sp.read_records(pool, split)[:count]
    if edit is not None:
        edit(records)
    target = data / pool.slug / f"{split}.jsonl.gz"
    sp.write_records(target, records)
    return target
