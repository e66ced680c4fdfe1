"""Cache keys: what a cached synthesized test depends on, as one hash.

A cached test is valid only for the input it was synthesized from *and* the code that
synthesized it: the same problem file gives another test after a FlowTest change (a
new artifact format, a fixed MILP) or another HiGHS (a different optimum among equals).
:func:`cache_key` therefore hashes the content together with :func:`versions` and the
options that change the answer, so a stale entry is never found rather than trusted.
"""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from importlib import metadata
from typing import Any

from synthesis.artifact import VERSION as ARTIFACT_VERSION


@lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """The versions a synthesized test depends on: FlowTest, its artifact format, HiGHS
    (``highspy``). A package that is not installed as a distribution counts as
    ``"unknown"`` (a source checkout): its entries are still keyed, just never shared."""

    def dist(name: str) -> str:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return "unknown"

    return {"flowtest": dist("flowtest"), "artifact": str(ARTIFACT_VERSION), "highspy": dist("highspy")}


def cache_key(kind: str, content: bytes, options: dict[str, Any] | None = None) -> str:
    """A hex SHA-256 of ``kind`` (what is cached, e.g. ``"problem"``), the input's bytes,
    :func:`versions` and ``options`` (JSON-serializable; key order does not matter).

    Raises
    ------
    TypeError
        If ``options`` is not JSON-serializable.
    """
    h = hashlib.sha256()
    head = {"kind": kind, "versions": versions(), "options": options or {}}
    h.update(json.dumps(head, sort_keys=True, separators=(",", ":")).encode())
    h.update(b"\0")
    h.update(content)
    return h.hexdigest()
