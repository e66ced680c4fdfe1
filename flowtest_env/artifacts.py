"""Where environments get their synthesized tests: shipped artifacts and the on-disk cache.

Built-in problems ship their artifacts in ``flowtest_env/artifacts/<name>.json``
(written by ``experiments/build_artifacts.py``), so ``gym.make`` never solves anything.
If an artifact is missing (a development checkout before the build), the problem is
synthesized once and the result cached under :func:`cache_dir`.

Loaded artifacts and their :class:`~flowtest_env.game.TestGame` tables are kept in
memory per process: they are read-only, so every env of a problem shares them.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from synthesis.artifact import TestArtifact

from .game import TestGame

ARTIFACT_DIR = Path(__file__).resolve().parent / "artifacts"
"""The shipped artifacts of the built-in problems."""

CACHE_ENV = "FLOWTEST_CACHE_DIR"


def cache_dir() -> Path:
    """The cache folder: ``$FLOWTEST_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/flowtest``
    (``~/.cache/flowtest``). Created on demand by the writers."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "flowtest"


def artifact_path(name: str) -> Path:
    """The shipped artifact file of a built-in problem."""
    return ARTIFACT_DIR / f"{name}.json"


def synthesize_artifact(name: str, time_limit: float | None = None) -> TestArtifact:
    """Synthesize a built-in problem and wrap it as an artifact (slow: solves a MILP).

    With ``time_limit`` the answer may be feasible rather than proven optimal (its
    summary says which, with the gap); it is checked all the same.

    Raises
    ------
    KeyError
        If ``name`` is not a built-in problem.
    """
    from synthesis.artifact import artifact_of
    from synthesis.builtins import BUILTINS
    from synthesis.pipeline import SynthesisOptions, synthesize
    from synthesis.summary import summary_of

    if name not in BUILTINS:
        raise KeyError(f"unknown built-in problem {name!r}; known: {', '.join(sorted(BUILTINS))}")
    test = synthesize(BUILTINS[name](), SynthesisOptions(time_limit=time_limit))
    return artifact_of(test, summary_of(test))


@lru_cache(maxsize=None)
def load_builtin(name: str) -> TestArtifact:
    """The artifact of a built-in problem: shipped, else cached, else synthesized now."""
    shipped = artifact_path(name)
    if shipped.exists():
        return TestArtifact.load(shipped)
    cached = cache_dir() / "builtins" / f"{name}.json"
    if cached.exists():
        return TestArtifact.load(cached)
    from gymnasium import logger

    logger.warn(
        f"no shipped artifact for {name!r}: synthesizing it now (this can take minutes for large problems); "
        f"`python -m experiments.build_artifacts {name}` ships it, the result is cached in {cached}"
    )
    art = synthesize_artifact(name)
    cached.parent.mkdir(parents=True, exist_ok=True)
    tmp = cached.with_suffix(f".{os.getpid()}.tmp")
    art.save(tmp)
    tmp.replace(cached)
    return art


@lru_cache(maxsize=None)
def builtin_game(name: str, setting: str | None = None, external_tester: bool = False) -> TestGame:
    """The shared :class:`TestGame` of a built-in problem (see :class:`TestGame`)."""
    return TestGame(load_builtin(name), setting, external_tester)
