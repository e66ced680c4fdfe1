"""Where environments get their synthesized tests: shipped artifacts and the on-disk cache.

Built-in problems ship their artifacts in ``flowtest_env/artifacts/<name>.json``
(written by ``experiments/tools/build_artifacts.py``), so ``gym.make`` never solves anything.
If an artifact is missing (a development checkout before the build), the problem is
synthesized once and the result cached under :func:`cache_dir`, filed under a key of the
FlowTest and solver versions and the options (:func:`builtin_cache_path`): an answer
computed under another version is recomputed, not reused.

Shipped and cached artifacts are computed with deterministic budgets only
(:func:`artifact_options`: one HiGHS thread, a fixed seed, a node limit per HiGHS run),
never a wall-clock limit, so they are the same on every machine.

Loaded artifacts and their :class:`~flowtest_env.game.TestGame` tables are kept in
memory per process: they are read-only, so every env of a problem shares them.

Nothing loaded here is trusted. A cache entry must carry the digest of its whole content
(:data:`synthesis.artifacts.artifact.DIGEST_KEY`, written when it was made) and is checked
in full on load (:meth:`synthesis.artifacts.artifact.TestArtifact.load`: schema, sizes,
source hash, automata, restrictions against its own product graphs, a test agent's
controller in closed loop). A shipped artifact must have exactly the bytes FlowTest
shipped (:data:`MANIFEST`, the SHA-256 of each file, written by
``experiments/tools/build_artifacts.py``) and its own digest, and is then checked in full like a
cache entry (no solver runs, so this is quick even for mars-exploration, the largest). Both must carry the source
hash of the built-in problem they stand for. An edited file, or one made for another problem, is refused with a message
naming what is wrong (a cache entry is then synthesized again, with a warning).

The cache is a convenience, never a requirement: a cache folder that is missing, a file,
read-only or full, an entry that is a folder, a name the file system refuses, all end in
a warning and the test kept in memory (:func:`write_cache_entry`), never in an error, and
no temporary file is left behind.
"""

from __future__ import annotations

import hashlib
import os
from functools import cache
from pathlib import Path
from typing import Any

from gymnasium import logger

from synthesis.artifacts.artifact import TestArtifact, artifact_of, problem_source_hash, verify_artifact
from synthesis.artifacts.provenance import cache_key, versions
from synthesis.artifacts.summary import summary_of
from synthesis.model.errors import ProblemError
from synthesis.options import SynthesisOptions
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.files import read_limited

from .game import TestGame

ARTIFACT_DIR = Path(__file__).resolve().parent / "artifacts"
"""The shipped artifacts of the built-in problems."""

MANIFEST = ARTIFACT_DIR / "SHA256SUMS"
"""The SHA-256 of every shipped artifact, in ``sha256sum`` format (``sha256sum -c`` reads it)."""

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


ARTIFACT_NODE_LIMIT = 20_000
"""Branch-and-bound nodes per HiGHS run for shipped and cached built-in artifacts: far
above what the built-ins proven optimal need; it bounds mars-exploration, whose fewest
cuts HiGHS does not prove in hours (docs/benchmarks.md)."""


ARTIFACT_NODE_LIMITS: dict[str, int] = {"patrolling": 200_000}
"""Built-ins whose proof needs more branch-and-bound nodes per HiGHS run than
:data:`ARTIFACT_NODE_LIMIT`, with their own (still deterministic) budget: patrolling's
physical walls stop at 20,000 nodes with flow 1 and 27 cuts unproven, and are proven
optimal within 200,000 (docs/benchmarks.md, "Patrolling with physical walls")."""


def artifact_options(node_limit: int | None = None, name: str | None = None) -> dict[str, Any]:
    """The synthesis options of shipped and cached artifacts: deterministic budgets only
    (``node_limit`` defaults to the built-in ``name``'s entry of :data:`ARTIFACT_NODE_LIMITS`,
    else :data:`ARTIFACT_NODE_LIMIT`)."""
    if node_limit is None:
        node_limit = ARTIFACT_NODE_LIMITS.get(name, ARTIFACT_NODE_LIMIT) if name is not None else ARTIFACT_NODE_LIMIT
    return {"threads": 1, "node_limit": int(node_limit)}


def synthesize_artifact(name: str, node_limit: int | None = None) -> TestArtifact:
    """Synthesize a built-in problem with :func:`artifact_options` and wrap it as an
    artifact (slow: solves a MILP). A solve stopped by the node limit gives a feasible
    test rather than a proven optimum (its summary says which, with the gap); it is
    checked all the same. The artifact records the options and versions it was made
    under (``extras["provenance"]``).

    Raises
    ------
    KeyError
        If ``name`` is not a built-in problem.
    """
    if name not in BUILTINS:
        raise KeyError(f"unknown built-in problem {name!r}; known: {', '.join(sorted(BUILTINS))}")
    from synthesis.pipeline import synthesize  # the solvers load only when a test is synthesized

    options = artifact_options(node_limit, name)
    test = synthesize(BUILTINS[name](), SynthesisOptions(**options))
    # which solver made it: with ties between optimal answers, another solver or release may
    # pick another one, so a shipped artifact equals a fresh synthesis under the same one
    made = {SOLVER_KEY: made_with(test.routing.stats), "provenance": {"options": options, "versions": versions()}}
    return artifact_of(test, summary_of(test), made)


SOLVER_KEY = "made_with"
"""The key of :attr:`TestArtifact.extras` naming the solver and its version that made a shipped artifact."""


def made_with(stats: dict[str, Any]) -> dict[str, str]:
    """``{"backend": ..., "version": ...}``: the routing solver a synthesis ran (its stats
    name the one ``auto`` chose) and that solver's package version."""
    from synthesis.routing.solve import backend_version  # the backends' table, as synthesizing loads it

    backend = str(stats.get("backend", "highs"))
    return {"backend": backend, "version": backend_version(backend)}


def builtin_cache_path(name: str) -> Path:
    """The cache file of a built-in's artifact synthesized on this machine, under a key
    of its name, the options and the current versions."""
    return cache_dir() / "builtins" / name / f"{cache_key('builtin', {'name': name, 'options': artifact_options(name=name)})}.json"


def file_sha256(path: Path) -> str:
    """The SHA-256 hex digest of a file's bytes (a regular file of at most 16 MiB, its size
    checked before it is read; ProblemError otherwise)."""
    return hashlib.sha256(read_limited(path, "artifact")).hexdigest()


def shipped_digests(folder: Path = ARTIFACT_DIR) -> dict[str, str]:
    """The manifest of the artifacts in ``folder``, ``{file name: SHA-256}`` (empty if none)."""
    manifest = folder / MANIFEST.name
    if not manifest.exists():
        return {}
    out: dict[str, str] = {}
    for line in manifest.read_text().splitlines():
        digest, _, name = line.partition("  ")
        if digest and name:
            out[name] = digest
    return out


def write_manifest(folder: Path = ARTIFACT_DIR) -> Path:
    """Write the manifest of every artifact in ``folder`` (``build_artifacts`` does)."""
    lines = [f"{file_sha256(p)}  {p.name}" for p in sorted(folder.glob("*.json"))]
    path = folder / MANIFEST.name
    tmp = path.with_name(f".{MANIFEST.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text("\n".join(lines) + "\n")
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def load_shipped(path: Path, expected_source: str) -> TestArtifact:
    """Load a shipped artifact: its bytes must be those of the manifest (see module docstring).

    Raises
    ------
    ProblemError
        If the file is not the one FlowTest shipped, or fails its checks.
    """
    fix = f"reinstall FlowTest or run `python -m experiments.tools.build_artifacts {path.stem} --force`"
    want = shipped_digests(path.parent).get(path.name)
    if want is None:
        raise ProblemError(f"artifact {path} is not listed in {MANIFEST.name}; {fix}")
    if file_sha256(path) != want:
        raise ProblemError(f"artifact {path} is not the file FlowTest shipped (its SHA-256 differs: edited?); {fix}")
    try:
        art = TestArtifact.load(path, verify=False, require_digest=True)
        verify_artifact(art, str(path), expected_source)  # every check; no solver runs
    except ProblemError as exc:
        raise ProblemError(f"{exc}; {fix}") from None
    return art


def warn_refused_entry(exc: ProblemError) -> None:
    """Say that a cache entry was refused (and why) before it is synthesized again."""
    logger.warn(f"refused a cache entry: {exc}")


def load_checked(path: Path, expected_source: str, what: str) -> TestArtifact:
    """Load an artifact that must stand for the problem of hash ``expected_source``.

    Raises
    ------
    ProblemError
        If the file fails its checks or was made for another problem; the message
        names the file and says how to get a good one (``what``).
    """
    try:
        art = TestArtifact.load(path, verify=False, require_digest=True)
        verify_artifact(art, str(path), expected_source)
    except ProblemError as exc:
        raise ProblemError(f"{exc}; {what}") from None
    return art


def write_cache_entry(path: Path, art: TestArtifact) -> bool:
    """Write ``art`` to the cache file ``path`` through a temporary file, best effort: any
    fault of the file system (the folder missing and not creatable, a file, read-only or
    full; an entry that is a folder; a name too long) is one warning, the temporary file
    is removed, and False is returned (the caller keeps the test in memory)."""
    tmp = path.with_name(f".{path.name[:64]}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        art.save(tmp)
        os.replace(tmp, path)
        return True
    except OSError as exc:
        logger.warn(f"could not write the cache entry {str(path)!r} ({exc.strerror or exc}); the test is kept in memory only")
        return False
    finally:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass


def stored_builtin(name: str) -> tuple[TestArtifact, Path] | None:
    """The stored test of a built-in problem and its file, without synthesizing: the shipped
    artifact (its bytes those of :data:`MANIFEST`, every check passed), else this machine's cache
    entry (:func:`builtin_cache_path`, every check passed; a refused one is said so with a
    warning); ``None`` when neither is there.

    Raises
    ------
    ProblemError
        If ``name`` is not a built-in, or its shipped artifact fails its checks.

    Example
    -------
    >>> art, path = stored_builtin("patrolling")      # shipped: no solver runs
    >>> art.summary["status"], path.name
    ('optimal', 'patrolling.json')
    """
    if name not in BUILTINS:
        raise ProblemError(f"unknown built-in problem {name!r}; known: {', '.join(sorted(BUILTINS))}")
    expected = problem_source_hash(BUILTINS[name]())
    shipped = artifact_path(name)
    if shipped.exists():
        return load_shipped(shipped, expected), shipped
    cached = builtin_cache_path(name)
    if cached.exists() or cached.is_symlink():
        try:
            return load_checked(cached, expected, "synthesizing it again"), cached
        except ProblemError as exc:  # FlowTest's own file: refused, said why, rebuilt
            warn_refused_entry(exc)
    return None


@cache
def load_builtin(name: str) -> TestArtifact:
    """The artifact of a built-in problem: shipped, else cached (:func:`stored_builtin`), else
    synthesized now (and cached).

    Raises
    ------
    ProblemError
        If the shipped artifact or the cache entry fails its checks (see module docstring).
    """
    stored = stored_builtin(name)
    if stored is not None:
        return stored[0]
    cached = builtin_cache_path(name)
    logger.warn(
        f"no shipped artifact for {name!r}: synthesizing it now (this can take minutes for large problems); "
        f"`python -m experiments.tools.build_artifacts {name}` ships it, the result is cached in {cached}"
    )
    art = synthesize_artifact(name)
    write_cache_entry(cached, art)
    return art


class _BuiltinGames:
    """The shared :class:`TestGame` of a built-in problem (see :class:`TestGame`): one per
    name, setting and tester, however the arguments are passed; ``cache_clear()`` forgets
    them (as ``load_builtin.cache_clear()`` does the artifacts)."""

    def __init__(self) -> None:
        self._games: dict[tuple[str, str | None, bool], TestGame] = {}

    def __call__(self, name: str, setting: str | None = None, external_tester: bool = False) -> TestGame:
        key = (name, setting, bool(external_tester))
        game = self._games.get(key)
        if game is None:
            game = self._games[key] = TestGame(load_builtin(name), setting, bool(external_tester))
        return game

    def cache_clear(self) -> None:
        self._games.clear()


builtin_game = _BuiltinGames()
"""``builtin_game(name, setting=None, external_tester=False)``: the shared
:class:`TestGame` of a built-in problem (see :class:`_BuiltinGames`)."""
