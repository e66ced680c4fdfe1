"""What decides a synthesized test besides its problem: versions and options, as a cache key.

A problem, its options and the versions of FlowTest and of the libraries that compute the
answer (HiGHS through highspy, OR-Tools CP-SAT, PySCIPOpt when the ``scip`` extra is installed,
NumPy, SciPy) determine a test when every budget is
deterministic (design.md, "Determinism"). Anything cached or shipped is filed under
:func:`cache_key` of those inputs, so an answer computed under another version is never
served as this version's: it is recomputed.

FlowTest's own version is its package version plus a digest of the ``synthesis`` sources,
so a development checkout that changes the method without bumping the version still
gets fresh answers.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = ["cache_key", "content_key", "source_digest", "versions"]


def _dist_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "unknown"


@lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 (first 16 hex digits) of the ``synthesis`` package's sources (every module of
    every sub-package), by path inside the package."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py"), key=lambda p: p.relative_to(root).as_posix()):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """The versions an answer depends on: FlowTest (package and synthesis sources), highspy,
    OR-Tools (a core dependency; ``"unknown"`` only in a broken install, where ``"auto"``
    falls back to HiGHS; an explicit ``backend`` is part of the options), PySCIPOpt (the ``scip`` extra's
    solver, ``"unknown"`` when not installed), NumPy and SciPy."""
    return {
        "flowtest": _dist_version("flowtest"),
        "flowtest_source": source_digest(),
        "highspy": _dist_version("highspy"),
        "ortools": _dist_version("ortools"),
        "pyscipopt": _dist_version("pyscipopt"),
        "numpy": _dist_version("numpy"),
        "scipy": _dist_version("scipy"),
    }


def cache_key(what: str, params: Mapping[str, Any]) -> str:
    """A key (24 hex digits) for the answer ``what`` computed from ``params`` (the inputs and
    options, JSON-serializable) under the current :func:`versions`.

    Equal keys mean equal inputs, options and versions; change any of them and the key
    changes, so a cache filed under it is rebuilt rather than reused.
    """
    text = json.dumps({"what": what, "params": params, "versions": versions()}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def content_key(what: str, content: bytes, options: Mapping[str, Any] | None = None) -> str:
    """:func:`cache_key` of an input given as bytes (a user's problem file): its SHA-256 and
    ``options`` under the current :func:`versions`."""
    return cache_key(what, {"sha256": hashlib.sha256(content).hexdigest(), "options": dict(options or {})})
