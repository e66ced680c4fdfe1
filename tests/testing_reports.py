"""Helpers for tests of the evaluation report: a pair's record as ``results.json`` holds it."""

from __future__ import annotations

from typing import Any


def passing_record(env: str, **changes: Any) -> dict[str, Any]:
    """The record of one passing run of system ``s`` on ``env`` (3 steps, nothing failed),
    with ``changes`` over it: what a report draws a card and a matrix cell from."""
    return {
        "env": env,
        "sut": "s",
        "episodes": 1,
        "seed": 0,
        "system_objective_met_rate": 1.0,
        "test_objective_realized_rate": 1.0,
        "violated": 0,
        "open": 0,
        "mean_restrictions": 0.0,
        "mean_steps": 3.0,
        "test_failures": 0,
        "n_failures": 0,
        "failures": [],
        "pictures": {},
        **changes,
    }
