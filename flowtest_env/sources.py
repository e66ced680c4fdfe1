"""The one front door for tests: whatever names a test becomes a :class:`TestArtifact`.

Every environment (``gymnasium.make("FlowTest-v0", test=...)``, the registered
``FlowTest-<Name>-v0``, :func:`flowtest_env.make_env`, the PettingZoo envs) and every
command that takes an environment gets its test from :func:`load_test`, which accepts

* a **built-in name** (``"maze2"``): its shipped artifact;
* a **problem file** (``mine.toml``): synthesized once, then cached on disk under a key
  of its content, the options that decide the answer (:func:`answer_options`) and the
  versions of FlowTest and its solvers (:func:`synthesis.artifacts.provenance.content_key`),
  so a synthesis under other such options (a gap, caps, a setting) never serves nor
  overwrites the default's entry. Only a proven-optimal answer is cached (a time-limited
  one depends on the machine's speed, so it is synthesized again next time, with a
  warning). ``flowtest synthesize mine.toml`` files its answer there too
  (:func:`cache_problem_test`), so ``flowtest evaluate --env mine.toml`` after it does not
  synthesize again. A cache entry records the SHA-256 of the problem file it was made from
  and its answer options (``extras["origin"]``) and must carry its digest and the source
  hash of that file's problem: another problem's entry, or an edited one, is refused and
  synthesized again with a warning. A cache that cannot be written (see
  :func:`flowtest_env.artifacts.write_cache_entry`) is a warning only. With ``options``
  (:func:`load_test`), a synthesis runs under their budgets and says its stages to their
  ``progress``;
* an **artifact file** (``mine.json``, written by ``flowtest synthesize --out``), checked on
  load like every artifact (:func:`synthesis.artifacts.artifact.verify_artifact`);
* a :class:`~synthesis.problems.problem.Problem`, a :class:`~synthesis.synthesized_test.SynthesizedTest`
  or a :class:`~synthesis.artifacts.artifact.TestArtifact` object.

Every file is read through :func:`synthesis.problems.files.read_limited`: a regular file of
at most 16 MiB, refused before it is read whole.

Loaded tests are kept in memory per process (by content key), so the envs of one test
share one artifact and one :class:`~flowtest_env.game.TestGame`.

:func:`stored_test` answers, without synthesizing, whether the test a synthesis would give
is already at hand (a built-in's shipped artifact, a problem file's cache entry):
``flowtest synthesize`` shows such a test rather than solving again when solving took long.
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

from gymnasium import logger

from synthesis.artifacts.artifact import FORMAT, TestArtifact, artifact_of, parse_artifact_json, problem_source_hash, verify_artifact
from synthesis.artifacts.provenance import content_key
from synthesis.artifacts.summary import summary_of
from synthesis.model.errors import ProblemError
from synthesis.options import SynthesisOptions
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.files import MAX_FILE_BYTES, load_problem_file, read_limited
from synthesis.problems.limits import check_file_size
from synthesis.problems.problem import Problem
from synthesis.synthesized_test import SynthesizedTest

from .artifacts import ARTIFACT_DIR, builtin_game, cache_dir, load_builtin, stored_builtin, warn_refused_entry, write_cache_entry
from .game import TestGame

TestLike = Union[str, "os.PathLike[str]", Problem, SynthesizedTest, TestArtifact]
"""Anything :func:`load_test` accepts."""

_LOADED: dict[str, TestArtifact] = {}
_GAMES: dict[tuple[int, str | None, bool], tuple[TestArtifact, TestGame]] = {}


def builtin_names() -> list[str]:
    """The built-in problem names, sorted."""
    return sorted(BUILTINS)


def answer_options(options: SynthesisOptions | None = None) -> dict[str, Any]:
    """The options of a synthesis that decide which test it answers, as plain data: what a
    cached test is filed under besides its problem and the versions (:func:`problem_cache_path`),
    so that a synthesis with other such options (a gap, more threads, another backend, a
    setting, caps) never serves, nor overwrites, the default's entry.

    Left out are what decides only *whether* and *how fast* the answer comes: the budgets that
    stop a search (``time_limit``, ``after_first``, ``node_limit``, ``work_limit``: only a proven
    optimum is cached, and a budget that did not stop the search did not change it), the
    progress and control, and the size refusal (``max_graph_edges``). ``threads=None`` is one
    thread, as a synthesis makes it.

    >>> answer_options() == answer_options(SynthesisOptions(time_limit=60, threads=1, node_limit=200_000))
    True
    >>> answer_options(SynthesisOptions(caps={"max_walls": 3}))["caps"]
    {'max_walls': 3}
    """
    o = options if options is not None else SynthesisOptions()
    return {
        "mip_rel_gap": float(o.mip_rel_gap),
        "threads": 1 if o.threads is None else int(o.threads),
        "random_seed": int(o.random_seed),
        "backend": str(o.backend),
        "closed_loop": bool(o.closed_loop),
        "setting": o.setting,
        "agent_iterations": o.agent_iterations,
        "caps": dict(sorted((o.caps or {}).items())),
    }


def problem_cache_path(path: Path, raw: bytes, options: SynthesisOptions | None = None) -> Path:
    """Where the synthesized test of a problem file with content ``raw`` is cached under
    ``options`` (their :func:`answer_options`): a name of at most about 100 characters whatever
    the file's (its stem cut to 48 safe characters, then the content key of the bytes, the
    answer's options and the versions)."""
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", path.stem)[:48].lstrip(".") or "problem"
    return cache_dir() / "problems" / f"{stem}-{content_key('problem', raw, answer_options(options))[:24]}.json"


def problem_origin(raw: bytes, options: SynthesisOptions | None = None) -> dict[str, Any]:
    """What a problem file's cache entry records it was made from (``extras["origin"]``): the
    SHA-256 of the file's bytes and the :func:`answer_options` it was synthesized under."""
    return {"problem_sha256": hashlib.sha256(raw).hexdigest(), "options": answer_options(options)}


def is_problem_file(test: object) -> bool:
    """Whether :func:`load_test` reads ``test`` as a problem file (synthesized, or its cached
    test): a path (not a built-in name) to an existing file without the ``.json`` suffix."""
    if not isinstance(test, (str, os.PathLike)):
        return False
    text = os.fspath(test)
    if isinstance(test, str) and text in BUILTINS:
        return False
    path = Path(text).expanduser()
    return path.suffix.lower() != ".json" and path.is_file()


def _synthesized_artifact(problem: Problem, origin: dict[str, Any] | None = None, options: SynthesisOptions | None = None) -> TestArtifact:
    """Synthesize ``problem`` under ``options`` (the solvers are imported here, on the first
    test that needs them: playing a shipped or cached test loads none) and make its artifact;
    with a ``progress`` callback among the options, the synthesis is said first."""
    from synthesis.pipeline import synthesize

    if options is not None and options.progress is not None:
        limit = options.time_limit if options.time_limit is not None else problem.time_limit
        bound = f"the time limit of {limit:g} s bounds it" if limit is not None else "no time limit (--time-limit S bounds it)"
        options.progress(f"synthesizing {problem.name} ({problem.kind} test; {bound})")
    test = synthesize(problem, options)
    return artifact_of(test, summary_of(test), None if origin is None else {"origin": origin})


def _cached_entry(cached: Path, problem: Problem, origin: dict[str, Any]) -> TestArtifact | None:
    """The cache entry of a problem file, if it is FlowTest's own (its digest), made from
    that very file under the same answer options (its origin) and a checked test of its
    problem (its source hash and every check); None (with a warning saying why) otherwise."""
    if not (cached.exists() or cached.is_symlink()):
        return None
    try:
        art = TestArtifact.load(cached, verify=False, require_digest=True)
        if art.extras.get("origin") != origin:
            raise ProblemError(f"cache entry {str(cached)!r} was made from another problem file, or under other options, than the one asked for")
        verify_artifact(art, str(cached), problem_source_hash(problem))
    except ProblemError as exc:
        warn_refused_entry(ProblemError(f"{exc}; synthesizing it again"))  # a damaged, edited or foreign entry
        return None
    return art


def cached_problem_test(path: Path, raw: bytes, problem: Problem, options: SynthesisOptions | None = None) -> tuple[TestArtifact, Path] | None:
    """The cached test of the problem file ``path`` (content ``raw``, read as ``problem``) under
    ``options``, and its entry's path: a proven optimum a synthesis with the same
    :func:`answer_options` made from these very bytes, every check passed; ``None`` if there is
    none (a refused entry is said so with a warning)."""
    cached = problem_cache_path(path, raw, options)
    art = _cached_entry(cached, problem, problem_origin(raw, options))
    return None if art is None else (art, cached)


def cache_problem_test(path: Path, raw: bytes, test: SynthesizedTest, options: SynthesisOptions | None = None) -> Path | None:
    """File ``test``, synthesized from the problem file ``path`` (content ``raw``) under
    ``options``, where :func:`load_test` looks for it (``flowtest synthesize`` does, so that
    ``flowtest evaluate --env`` that file does not synthesize it again): only a proven optimum
    (``status`` ``"optimal"``; a time-limited answer depends on the machine's speed), best effort
    (:func:`~flowtest_env.artifacts.write_cache_entry`). Returns the entry's path, or ``None`` when
    nothing was written."""
    summary = summary_of(test)
    if summary.get("status") != "optimal":
        return None
    cached = problem_cache_path(path, raw, options)
    art = artifact_of(test, summary, {"origin": problem_origin(raw, options)})
    return cached if write_cache_entry(cached, art) else None


def _problem_file_artifact(path: Path, raw: bytes, options: SynthesisOptions | None = None) -> TestArtifact:
    """The test of a problem file: from the cache, else synthesized under ``options`` (and
    cached when the answer is proven optimal, i.e. independent of the machine's speed)."""
    problem = load_problem_file(path)
    hit = cached_problem_test(path, raw, problem, options)
    note = options.progress if options is not None and options.progress is not None else None
    if hit is not None:
        if note is not None:
            note(f"{path}: its cached test {hit[1]} (proven optimal, every check passed)")
        return hit[0]
    art = _synthesized_artifact(problem, problem_origin(raw, options), options)
    if art.summary.get("status") == "optimal":
        cached = problem_cache_path(path, raw, options)
        if write_cache_entry(cached, art) and note is not None:
            note(f"{path}: its test is cached in {cached}")
    else:
        logger.warn(
            f"{path}: the synthesized test is not proven optimal (status {art.summary.get('status')!r}, "
            "a time limit): it is not cached; write it once with `flowtest synthesize --out` and pass that file"
        )
    return art


@dataclass(frozen=True)
class StoredTest:
    """A test at hand for a problem, found without synthesizing (:func:`stored_test`)."""

    artifact: TestArtifact = field(repr=False)
    path: Path
    """Its file: the shipped artifact, or the cache entry."""
    shipped: bool
    """Whether FlowTest shipped it (``flowtest_env/artifacts/``), else this machine's cache holds it."""


def stored_test(name: str, problem: Problem, options: SynthesisOptions | None = None) -> StoredTest | None:
    """The test a synthesis of ``name`` (a built-in name or a problem file, read as ``problem``)
    under ``options`` would answer, if it is at hand as a proven optimum; ``None`` otherwise.

    For a built-in it is its shipped artifact (or this machine's cache entry of it:
    :func:`~flowtest_env.artifacts.stored_builtin`), when ``options`` answer as the default
    synthesis does (their :func:`answer_options` are the default's) and its status is
    ``"optimal"``: a proven optimum under deterministic budgets that did not stop the search,
    which ``tests/flowtest_env/test_envs.py`` holds equal to a fresh synthesis. For a problem file
    it is the cache entry a synthesis under the same answer options made from these very bytes
    (:func:`cached_problem_test`). Every check has passed on either.

    Raises
    ------
    ProblemError
        If a shipped artifact fails its checks.

    Example
    -------
    >>> from synthesis import load_problem
    >>> stored = stored_test("patrolling", load_problem("patrolling"))
    >>> stored.shipped, stored.artifact.summary["status"]
    (True, 'optimal')
    """
    if name in BUILTINS:
        if answer_options(options) != answer_options():
            return None
        found = stored_builtin(name)
        if found is None or found[0].summary.get("status") != "optimal":
            return None
        return StoredTest(found[0], found[1], found[1].parent == ARTIFACT_DIR)
    if not is_problem_file(name):
        return None
    path = Path(name).expanduser()
    hit = cached_problem_test(path, read_limited(path, "problem file"), problem, options)
    return None if hit is None else StoredTest(hit[0], hit[1], False)


def load_test(test: TestLike, options: SynthesisOptions | None = None) -> TestArtifact:
    """The synthesized test named by ``test`` (see the module docstring).

    ``options`` say how a problem is synthesized when its test is not at hand (a problem file
    without a cache entry, a :class:`~synthesis.problems.problem.Problem`): its budgets, and a
    ``progress`` callback that hears what is done (the cached test found, or the synthesis's
    stages). Those that change the answer (:func:`answer_options`) file a problem file's test
    under another cache key. A built-in's shipped test and an artifact file need none.

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
        return _synthesized_artifact(test, options=options)
    if not isinstance(test, (str, os.PathLike)):
        raise ProblemError(
            f"test must be a built-in name, a problem or artifact file, a Problem, a SynthesizedTest or a TestArtifact, not {type(test).__name__}"
        )
    text = os.fspath(test)
    if isinstance(test, str) and text in builtin_names():
        return load_builtin(text)
    path = Path(text).expanduser()
    if not path.exists():
        raise ProblemError(f"test {text!r} is neither a built-in ({', '.join(builtin_names())}) nor an existing file")
    check_file_size(path, "test file", MAX_FILE_BYTES)  # its size checked before it is read
    raw = read_limited(path, "test file")
    json_file = path.suffix.lower() == ".json"
    key = content_key("file", raw, None if json_file else answer_options(options))
    hit = _LOADED.get(key)
    if hit is not None:
        return hit
    if json_file:
        data = parse_artifact_json(raw, text)
        if not (isinstance(data, dict) and data.get("format") == FORMAT):
            raise ProblemError(f"{text}: a JSON file that is not a FlowTest test artifact (format {FORMAT!r})")
        art = TestArtifact.from_dict(data, text)  # every check; an edited file is said so
    else:
        art = _problem_file_artifact(path, raw, options)
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
