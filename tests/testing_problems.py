"""Problem texts the tests edit instead of typing a problem out again."""

from __future__ import annotations


def _small_reactive_toml() -> str:
    from synthesis.problems.builtins import SMALL_REACTIVE

    lines = SMALL_REACTIVE.replace('name = "small-reactive"', 'name = "t"', 1).strip().splitlines()
    return "\n".join(line for line in lines if not line.startswith("description = ")) + "\n"


SMALL_REACTIVE_TOML = _small_reactive_toml()
"""The paper's small-reactive example as a problem file (``name = "t"``, no description):
the built-in's own text (:data:`synthesis.problems.builtins.SMALL_REACTIVE`), which tests
edit line by line instead of typing the problem out again."""
