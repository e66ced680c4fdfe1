"""The test suite never writes to the user's real cache or home.

Before any test module (and so any FlowTest module) is imported, ``HOME``, the XDG base
folders and ``FLOWTEST_CACHE_DIR`` are pointed into one temporary folder for the session
(shared by pytest-xdist workers, which inherit the environment, and removed at exit by the
process that made it). ``tests/flowtest_env/test_pools.py`` proves it: a test run with a fresh fake
home leaves that home empty. Helpers shared by test modules live in ``tests/testing_*.py``,
imported by package path (``from tests.testing_processes import start_until``).
"""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest

SANDBOX_ENV = "FLOWTEST_TEST_SANDBOX"
"""Set to the session's temporary folder once the environment points into it."""

REAL_HOME_ENV = "FLOWTEST_TEST_REAL_HOME"
"""The home folder the session started with (for the test that proves it stays untouched)."""


def _sandbox() -> Path:
    existing = os.environ.get(SANDBOX_ENV)
    if existing and Path(existing).is_dir():
        return Path(existing)
    root = Path(tempfile.mkdtemp(prefix="flowtest-tests-"))
    atexit.register(shutil.rmtree, root, ignore_errors=True)
    os.environ.setdefault(REAL_HOME_ENV, os.environ.get("HOME", str(Path.home())))
    home = root / "home"
    for sub in ("home", "home/.cache", "home/.config", "home/.local/share", "mpl"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    os.environ.update(
        {
            SANDBOX_ENV: str(root),
            "HOME": str(home),
            "XDG_CACHE_HOME": str(home / ".cache"),
            "XDG_CONFIG_HOME": str(home / ".config"),
            "XDG_DATA_HOME": str(home / ".local" / "share"),
            "FLOWTEST_CACHE_DIR": str(home / ".cache" / "flowtest"),
            "MPLCONFIGDIR": str(root / "mpl"),
            "SB3_LOGDIR": str(root / "sb3-logs"),  # stable-baselines3 makes an empty log folder per model in /tmp otherwise
        }
    )
    return root


SANDBOX = _sandbox()


@pytest.fixture(scope="module")
def pool_cache(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A private pool cache (never the user's)."""
    mp = pytest.MonkeyPatch()
    path = tmp_path_factory.mktemp("flowtest-cache")
    mp.setenv("FLOWTEST_CACHE_DIR", str(path))
    yield path
    mp.undo()


@pytest.fixture()
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A private test cache folder (not created yet) and empty in-memory caches of loaded
    tests (a module with other needs defines its own ``cache``)."""
    from flowtest_env import sources

    monkeypatch.setenv("FLOWTEST_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(sources, "_LOADED", {})
    monkeypatch.setattr(sources, "_GAMES", {})
    return tmp_path / "cache"
