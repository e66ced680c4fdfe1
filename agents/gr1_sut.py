"""GR(1)-synthesized system under test (``gr1``): in progress."""

from __future__ import annotations

from typing import Any

from .base import Policy, PolicyError, register_policy


@register_policy("gr1")
def _make_gr1(env: Any, arg: str) -> Policy:
    raise PolicyError("the gr1 SUT is not built yet")
