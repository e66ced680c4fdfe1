"""The one front door for tests: whatever names a test becomes a :class:`TestArtifact`.

Every environment (``gymnasium.make("FlowTest-v0", test=...)``, the registered
``FlowTest-<Name>-v0``, :func:`flowtest_env.make_env`, the PettingZoo envs) and every
command that takes an environment gets its test from :func:`load_test`, which accepts

* a **built-in name** (``"maze2"``): its shipped artifact;
* a **problem file** (``mine.toml``): synthesized once, then cached on disk under a key
  of its content, FlowTest's and HiGHS's versions (:func:`synthesis.artifacts.provenance.content_key`);
  only a proven-optimal answer is cached (a time-limited one depends on the machine's
  speed, so it is synthesized again next time, with a warning). A cache entry records the
  SHA-256 of the problem file it was made from (``extras["origin"]``) and must carry its
  digest and the source hash of that file's problem: another problem's entry, or an
  edited one, is refused and synthesized again with a warning. A cache that cannot be
  written (see :func:`flowtest_env.artifacts.write_cache_entry`) is a warning only;
* an **artifact file** (``mine.json``, written by ``flowtest synthesize --out``), checked on
  load like every artifact (:func:`synthesis.artifacts.artifact.verify_artifact`);
* a :class:`~synthesis.problems.problem.Problem`, a :class:`~synthesis.synthesized_test.SynthesizedTest`
  or a :class:`~synthesis.artifacts.artifact.TestArtifact` object.

Every file is read through :func:`synthesis.problems.files.read_limited`: a regular file of
at most 16 MiB, refused before it is read whole.

Loaded tests are kept in memory per process (by content key), so the envs of one test
share one artifact and one :class:`~flowtest_env.game.TestGame`.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path
from typing import Union

from gymnasium import logger

from synthesis.artifacts.artifact import FORMAT, TestArtifact, artifact_of, parse_artifact_json, problem_source_hash, verify_artifact
from synthesis.artifacts.provenance import content_key
from synthesis.artifacts.summary import summary_of
from synthesis.model.errors import ProblemError
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.files import MAX_FILE_BYTES, load_problem_file, read_limited
from synthesis.problems.limits import check_file_size
from synthesis.problems.problem import Problem
from synthesis.synthesized_test import SynthesizedTest

from .artifacts import builtin_game, cache_dir, load_builtin, warn_refused_entry, write_cache_entry
from .game import TestGame

TestLike = Union[str, "os.PathLike[str]", Problem, SynthesizedTest, TestArtifact]
"""Anything :func:`load_test` accepts."""

_LOADED: dict[str, TestArtifact] = {}
_GAMES: dict[tuple[int, str | None, bool], tuple[TestArtifact, TestGame]] = {}


def builtin_names() -> list[str]:
    """The built-in problem names, sorted."""
    return sorted(BUILTINS)


def problem_cache_path(path: Path, raw: bytes) -> Path:
    """Where the synthesized test of a problem file with content ``raw`` is cached: a name of
    at most about 100 characters whatever the file's (its stem cut to 48 safe characters,
    then the content key)."""
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", path.stem)[:48].lstrip(".") or "problem"
    return cache_dir() / "problems" / f"{stem}-{content_key('problem', raw)[:24]}.json"


def _synthesized_artifact(problem: Problem, origin: dict[str, str] | None = None) -> TestArtifact:
    """Synthesize ``problem`` (the solvers are imported here, on the first test that needs
    them: playing a shipped or cached test loads none) and make its artifact."""
    from synthesis.pipeline import synthesize

    test = synthesize(problem)
    return artifact_of(test, summary_of(test), None if origin is None else {"origin": origin})


def _cached_entry(cached: Path, problem: Problem, origin: dict[str, str]) -> TestArtifact | None:
    """The cache entry of a problem file, if it is FlowTest's own (its digest), made from
    that very file (its origin) and a checked test of its problem (its source hash and
    every check); None (with a warning saying why) otherwise."""
    if not (cached.exists() or cached.is_symlink()):
        return None
    try:
        art = TestArtifact.load(cached, verify=False, require_digest=True)
        if art.extras.get("origin") != origin:
            raise ProblemError(f"cache entry {str(cached)!r} was made from another problem file than the one asked for")
        verify_artifact(art, str(cached), problem_source_hash(problem))
    except ProblemError as exc:
        warn_refused_entry(ProblemError(f"{exc}; synthesizing it again"))  # a damaged, edited or foreign entry
        return None
    return art


def _problem_file_artifact(path: Path, raw: bytes) -> TestArtifact:
    """The test of a problem file: from the cache, else synthesized (and cached when
    the answer is proven optimal, i.e. independent of the machine's speed)."""
    problem = load_problem_file(path)
    origin = {"problem_sha256": hashlib.sha256(raw).hexdigest()}
    cached = problem_cache_path(path, raw)
    art = _cached_entry(cached, problem, origin)
    if art is not None:
        return art
    art = _synthesized_artifact(problem, origin)
    if art.summary.get("status") == "optimal":
        write_cache_entry(cached, art)
    else:
        logger.warn(
            f"{path}: the synthesized test is not proven optimal (status {art.summary.get('status')!r}, "
            "a time limit): it is not cached; write it once with `flowtest synthesize --out` and pass that file"
        )
    return art


def load_test(test: TestLike) -> TestArtifact:
    """The synthesized test named by ``test`` (see the module docstring).

    Raises
    ------
    ProblemError
        If ``test`` is a string that is neither a built-in name nor an existing file, or
        the file is not a valid problem or artifact (the message says what and where).
    synthesis.model.errors.InconsistentProblem, synthesis.model.errors.CheckFailed, TimeoutError
        From synthesizing a problem, as ``flowtest synthesize``.

    Examples
    --------
    >>> from flowtest_env import load_test
    >>> artifact = load_test("maze2")          # a built-in: its shipped, checked artifact
    >>> artifact.name, artifact.kind, artifact.summary["status"]
    ('maze2', 'agent', 'optimal')
    """
    if isinstance(test, TestArtifact):
        return test
    if isinstance(test, SynthesizedTest):
        return artifact_of(test, summary_of(test))
    if isinstance(test, Problem):
        return _synthesized_artifact(test)
    if not isinstance(test, (str, os.PathLike)):
        raise ProblemError(
            f"test must be a built-in name, a problem or artifact file, a Problem, a SynthesizedTest or a "
            f"TestArtifact, not {type(test).__name__}"
        )
    text = os.fspath(test)
    if isinstance(test, str) and text in builtin_names():
        return load_builtin(text)
    path = Path(text).expanduser()
    if not path.exists():
        raise ProblemError(
            f"test {text!r} is neither a built-in ({', '.join(builtin_names())}) nor an existing file"
        )
    check_file_size(path, "test file", MAX_FILE_BYTES)  # its size checked before it is read
    raw = read_limited(path, "test file")
    key = content_key("file", raw)
    hit = _LOADED.get(key)
    if hit is not None:
        return hit
    if path.suffix.lower() == ".json":
        data = parse_artifact_json(raw, text)
        if not (isinstance(data, dict) and data.get("format") == FORMAT):
            raise ProblemError(f"{text}: a JSON file that is not a FlowTest test artifact (format {FORMAT!r})")
        art = TestArtifact.from_dict(data, text)  # every check; an edited file is said so
    else:
        art = _problem_file_artifact(path, raw)
    _LOADED[key] = art
    return art


def game_for(test: TestLike, setting: str | None = None, external_tester: bool = False) -> TestGame:
    """The shared :class:`TestGame` of ``test`` (one per artifact, setting and tester)."""
    if isinstance(test, str) and test in builtin_names():
        return builtin_game(test, setting, external_tester)
    art = load_test(test)
    key = (id(art), setting, external_tester)
    hit = _GAMES.get(key)
    if hit is not None and hit[0] is art:
        return hit[1]
    game = TestGame(art, setting, external_tester)
    _GAMES[key] = (art, game)
    return game

