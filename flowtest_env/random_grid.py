"""Seeded random grid worlds (the paper's scalability study and its extensions) as test pools.

The instances themselves (spec families, worlds with blocked cells or fuel, test agents,
seeded draws, redraws) live in the pure :mod:`synthesis.problems.random_grid` and
:mod:`synthesis.problems.random_worlds`; this module synthesizes them and stores the pools. A pool
instance is the first attempt of its seed for which a test of the pool's kind is
synthesized within the pool budget (an inconsistent attempt, or one without a test
within the budget, is redrawn), so a seed always names the same test.

**Deterministic.** Pools are synthesized with deterministic budgets only
(:func:`pool_options`: one HiGHS thread, a fixed random seed, a node limit per HiGHS run,
the routing heuristic's work budget, at most
:data:`synthesis.problems.random_worlds.AGENT_ITERATIONS` MILP solves for a test agent), never a
wall-clock limit, so a pool is the same on every machine under any load, and every pool
test is bounded in work.

**Stored compactly.** A pool's problems come back from their seeds, so a pool stores only
what does not: one record per seed (:mod:`synthesis.artifacts.pool_records`: the attempt, the cut
edges, the static obstacles, the solver's summary without timings), one JSON line each,
in one file per split (``train.jsonl``, ``validation.jsonl``, ``test.jsonl``; seeds beyond
the three splits in ``block<k>.jsonl``), sorted by seed. Loading rebuilds every test from
its record and checks it as a fresh synthesis is checked (bypass flow 0, the flow, a way
to the goal from every history's entry nodes; a test agent's GR(1) strategy solved
again, checked and tabulated); a record that fails is refused with a warning and
synthesized again. Two builds of the same seeds write byte-identical files.

**Cached by version.** The files live under ``cache_dir()/random-grid/<pool>/<key>`` where
``key`` is :func:`synthesis.artifacts.provenance.cache_key` of the pool's parameters and options
under the current FlowTest, highspy, NumPy and SciPy versions (``key.json`` says which):
a pool built under another version is never reused, it is rebuilt. Within a process
pools are also kept in memory.

**The cache is a convenience.** A cache folder that is missing, a file, read-only or
full, a split file that is a folder or larger than :data:`MAX_POOL_FILE_BYTES`: every fault
is one warning, the tests are synthesized and kept in memory, and no temporary file is
left behind.

**Built in parallel when asked.** :func:`build_pool` synthesizes the missing seeds in
process, or as Ray tasks (``parallel="ray"``, each returns a record); the answers do not
depend on the dispatch. Every build shows its progress on standard error, on a terminal
or not (:class:`BuildProgress`: tests done, rate, time left).
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from gymnasium import logger

from synthesis.artifacts.artifact import TestArtifact
from synthesis.artifacts.pool_records import rebuild_artifact, record_of
from synthesis.artifacts.provenance import cache_key, versions
from synthesis.artifacts.summary import summary_of
from synthesis.model.errors import InconsistentProblem, ProblemError
from synthesis.options import SynthesisOptions
from synthesis.problems.files import read_limited
from synthesis.problems.limits import check_file_size
from synthesis.problems.problem import Problem
from synthesis.problems.random_grid import FAMILIES, MAX_ATTEMPTS, family_objectives, random_problem
from synthesis.problems.random_worlds import AGENT_ITERATIONS, POOL_KINDS, WORLDS, first_accepted, world_problem
from synthesis.synthesized_test import SynthesizedTest

from .artifacts import cache_dir, warn_refused_entry

__all__ = [
    "FAMILIES",
    "MAX_ATTEMPTS",
    "POOL_KINDS",
    "POOL_NODE_LIMIT",
    "POOL_WORK_LIMIT",
    "BuildProgress",
    "PoolName",
    "parse_pool",
    "split_seeds",
    "SPLITS",
    "SPLIT_SPAN",
    "WORLDS",
    "build_pool",
    "changed_params",
    "family_objectives",
    "pool_dir",
    "pool_key",
    "pool_options",
    "pool_path",
    "pool_record",
    "random_artifact",
    "random_pool",
    "random_problem",
    "split_of",
    "stored_records",
    "synthesize_records",
    "world_problem",
]

POOL_FORMAT = 4
POOL_NODE_LIMIT = 1000
"""Branch-and-bound nodes per HiGHS run for pool tests: bounds the work per test (an
8x8 reachability instance whose maximum flow HiGHS cannot prove in minutes stops at it
with a checked, feasible test)."""

POOL_WORK_LIMIT = 10.0
"""CP-SAT's deterministic seconds per phase for pool tests (``SynthesisOptions.work_limit``):
``auto`` runs CP-SAT on static models of 200-15,000 rows and reactive ones of 200-2,500
(:data:`synthesis.routing.backends.rules.AUTO_CPSAT_ROWS`), where the node limit does not apply, so this
bounds their work the same way. 10 leaves a wide margin over what the 5x5 study instances
CP-SAT proves need (docs/benchmarks/solvers.md, "Where each backend wins") and is a few CPU
seconds per phase."""

MAX_POOL_FILE_BYTES = 256 * 1024 * 1024
"""Largest split file read (its size checked before it is read): about 800,000 records."""

SPLITS: tuple[str, ...] = ("train", "validation", "test")
SPLIT_SPAN = 1_000_000
"""Seeds per split: split ``k`` of :data:`SPLITS` holds seeds ``k * SPLIT_SPAN`` onwards."""


FORM = "expected <family><n>/<size>x<size>[/<world>][/<kind>], e.g. reachability1/5x5 or reaction2/7x7/blocked/static"


@dataclass(frozen=True)
class PoolName:
    """A parsed pool name."""

    family: str
    n: int
    size: int
    kind: str = "reactive"
    world: str = "empty"

    def __str__(self) -> str:
        parts = [f"{self.family}{self.n}", f"{self.size}x{self.size}"]
        if self.world != "empty":
            parts.append(self.world)
        if self.kind != "reactive":
            parts.append(self.kind)
        return "/".join(parts)


def parse_pool(name: str) -> PoolName:
    """``"reachability1/5x5"`` -> :class:`PoolName` (grammar: :mod:`flowtest_env.pools`).

    Raises
    ------
    ValueError
        Naming what is wrong with the name.
    """
    if not isinstance(name, str):
        raise ValueError(f"a pool name is a string such as 'reachability1/5x5', not {name!r}")
    parts = name.split("/")
    if not 2 <= len(parts) <= 4:
        raise ValueError(f"pool name {name!r}: {FORM}")
    spec, grid, extra = parts[0], parts[1], parts[2:]
    family = spec.rstrip("0123456789")
    digits = spec[len(family) :]
    if family not in FAMILIES or not digits:
        raise ValueError(f"pool name {name!r}: unknown family {spec!r}; expected one of {', '.join(FAMILIES)} with a size n; {FORM}")
    rows, x, cols = grid.partition("x")
    if not (x and rows.isdigit() and rows == cols and int(rows) >= 2):
        raise ValueError(f"pool name {name!r}: grid {grid!r} is not a square size such as 5x5; {FORM}")
    worlds = [p for p in extra if p in WORLDS]
    kinds = [p for p in extra if p in POOL_KINDS]
    unknown = [p for p in extra if p not in WORLDS and p not in POOL_KINDS]
    if unknown:
        raise ValueError(f"pool name {name!r}: unknown part {unknown[0]!r}; expected a world ({', '.join(WORLDS)}) and/or a kind ({', '.join(POOL_KINDS)})")
    if len(worlds) > 1 or len(kinds) > 1:
        twice = "world" if len(worlds) > 1 else "kind"
        raise ValueError(f"pool name {name!r}: more than one {twice} ({', '.join(worlds if twice == 'world' else kinds)}); {FORM}")
    family_objectives(family, int(digits))  # validates n for the family
    return PoolName(family, int(digits), int(rows), kinds[0] if kinds else "reactive", worlds[0] if worlds else "empty")


def split_seeds(split: str, count: int, start: int = 0) -> range:
    """The seeds ``start .. start + count - 1`` of a split.

    Raises
    ------
    ValueError
        On an unknown split, or seeds beyond the split's range.
    """
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; expected one of {', '.join(SPLITS)}")
    if count < 1 or start < 0 or start + count > SPLIT_SPAN:
        raise ValueError(f"a split holds seeds 0..{SPLIT_SPAN - 1} of its range; got start {start}, count {count}")
    base = SPLITS.index(split) * SPLIT_SPAN
    return range(base + start, base + start + count)


def pool_options() -> SynthesisOptions:
    """The synthesis options of every pool test: deterministic budgets only."""
    return SynthesisOptions(threads=1, node_limit=POOL_NODE_LIMIT, work_limit=POOL_WORK_LIMIT)


def _options_record(options: SynthesisOptions) -> dict[str, Any]:
    """The answer-changing fields of synthesis options, as JSON."""
    d = asdict(options)
    d.pop("progress", None)
    d.pop("control", None)
    return d


def _check_pool(family: str, n: int, kind: str, world: str) -> None:
    family_objectives(family, n)  # validates family and n
    if kind not in POOL_KINDS:
        raise ValueError(f"unknown kind {kind!r}; expected one of {', '.join(map(repr, POOL_KINDS))}")
    if world not in WORLDS:
        raise ValueError(f"unknown world {world!r}; expected one of {', '.join(map(repr, WORLDS))}")


def pool_params(size: int, family: str, n: int, kind: str, world: str = "empty") -> dict[str, Any]:
    """Everything besides the versions that decides a pool's tests."""
    return {
        "format": POOL_FORMAT,
        "size": int(size),
        "family": family,
        "n": int(n),
        "kind": kind,
        "world": world,
        "max_attempts": MAX_ATTEMPTS,
        "agent_iterations": AGENT_ITERATIONS,
        "options": _options_record(pool_options()),
    }


def pool_key(size: int, family: str, n: int, kind: str, world: str = "empty") -> str:
    """The cache key of a pool: its parameters, options and the FlowTest and solver versions."""
    return cache_key("random-grid-pool", pool_params(size, family, n, kind, world))


def pool_dir(size: int, family: str, n: int, kind: str, world: str = "empty") -> Path:
    """The cache folder of a pool's records under the current versions."""
    middle = kind if world == "empty" else f"{world}-{kind}"
    return cache_dir() / "random-grid" / f"{size}x{size}-{family}{n}-{middle}" / pool_key(size, family, n, kind, world)


def split_of(seed: int) -> str:
    """The name of the split (or block of :data:`SPLIT_SPAN` seeds) a seed belongs to."""
    k = int(seed) // SPLIT_SPAN
    return SPLITS[k] if k < len(SPLITS) else f"block{k}"


def pool_path(size: int, family: str, n: int, seed: int, kind: str, world: str = "empty") -> Path:
    """The file that holds the record of one pool seed (its split's file)."""
    return pool_dir(size, family, n, kind, world) / f"{split_of(seed)}.jsonl"


def _accept(problem: Problem) -> SynthesizedTest:
    """Synthesize a pool attempt; no test within the budget counts as no test (redraw)."""
    from synthesis.pipeline import synthesize  # the solvers load when a pool test is synthesized, not to play one

    try:
        return synthesize(problem, pool_options())
    except TimeoutError as exc:
        raise InconsistentProblem("budget", f"no test within the pool budget: {exc}") from None


def pool_record(size: int, family: str, n: int, seed: int, kind: str = "reactive", world: str = "empty") -> dict[str, Any]:
    """Synthesize the pool test of a seed (its first attempt with a test within the budget)
    and give its compact record (:func:`synthesis.artifacts.pool_records.record_of`; what a Ray task
    returns).

    Raises
    ------
    RuntimeError
        If no attempt among :data:`MAX_ATTEMPTS` has one.
    """
    _check_pool(family, n, kind, world)
    attempt, _, test = first_accepted(size, family, n, seed, world, kind, _accept)
    return record_of(seed, attempt, test, summary_of(test))


def _artifact(record: dict[str, Any], size: int, family: str, n: int, kind: str, world: str) -> TestArtifact:
    """The checked test of a record, with its provenance (raises ProblemError)."""
    provenance = {"pool": pool_params(size, family, n, kind, world), "versions": versions()}
    return rebuild_artifact(record, size, family, n, world, kind, {"provenance": provenance})


def random_artifact(size: int, family: str, n: int, seed: int, kind: str = "reactive", world: str = "empty") -> TestArtifact:
    """Synthesize the pool test of a seed, rebuilt from its record and checked.

    Raises
    ------
    RuntimeError
        If no attempt among :data:`MAX_ATTEMPTS` has one.
    """
    return _artifact(pool_record(size, family, n, seed, kind, world), size, family, n, kind, world)


def _line(record: dict[str, Any]) -> str:
    """A record as one canonical JSON line (sorted keys, no spaces)."""
    return json.dumps(record, sort_keys=True, separators=(",", ":")) + "\n"


def _cache_fault(path: Path, exc: OSError) -> None:
    """Say that the pool cache could not be written (the tests stay in memory)."""
    logger.warn(f"could not write the pool cache {str(path)!r} ({exc.strerror or exc}); the tests are kept in memory only")


def _append(path: Path, record: dict[str, Any]) -> None:
    """Append one record to a split file (one write: parallel builders of a pool are safe);
    a file system fault is a warning (:func:`_cache_fault`)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a+b") as f:  # appends go to the end whatever the read position
            end = f.seek(0, os.SEEK_END)
            torn = end > 0 and f.seek(end - 1) >= 0 and f.read(1) != b"\n"  # a damaged last line stays apart
            f.write((b"\n" if torn else b"") + _line(record).encode("utf-8"))
    except OSError as exc:
        _cache_fault(path, exc)


def _read_text(path: Path, warn: bool) -> str | None:
    """A split file's text (None if missing or refused: not a regular file, too large, unreadable)."""
    if not (path.exists() or path.is_symlink()):
        return None
    try:
        check_file_size(path, "pool file", MAX_POOL_FILE_BYTES)
        return read_limited(path, "pool file", MAX_POOL_FILE_BYTES).decode("utf-8", errors="replace")
    except ProblemError as exc:
        if warn:
            warn_refused_entry(ProblemError(f"{exc}; its seeds will be synthesized again"))
        return None


def _read(path: Path, warn: bool = True) -> dict[int, dict[str, Any]]:
    """The records of a split file by seed (a later line wins); a line that is not a
    record of this file's seeds is refused (with a warning if ``warn``)."""
    out: dict[int, dict[str, Any]] = {}
    text_all = _read_text(path, warn)
    if text_all is None:
        return out
    for k, text in enumerate(text_all.splitlines(), 1):
        if not text.strip():
            continue
        try:
            rec = json.loads(text)
            seed = rec["seed"] if isinstance(rec, dict) else None
            if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0 or split_of(seed) != path.stem:
                raise ValueError("not a record of this file's seeds")
        except (ValueError, KeyError, RecursionError) as exc:
            if warn:
                warn_refused_entry(ProblemError(f"{path}, line {k}: {exc}; its seed will be synthesized again"))
            continue
        out[seed] = rec
    return out


def _write_atomic(path: Path, text: str) -> None:
    """Replace ``path`` by ``text`` through a temporary file, best effort (a fault is a
    warning and the temporary file is removed)."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:
        _cache_fault(path, exc)
    finally:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass


def _compact(path: Path) -> None:
    """Rewrite a split file sorted by seed, one line per seed (atomically): the bytes of
    a pool depend on its seeds only, not on the order they were built in."""
    if _read_text(path, warn=False) is None:  # missing or refused: nothing of ours to rewrite
        return
    records = _read(path, warn=False)
    _write_atomic(path, "".join(_line(records[s]) for s in sorted(records)))


def _write_key(folder: Path, params: dict[str, Any]) -> None:
    """The pool's parameters and versions next to its records (atomically, best effort)."""
    path = folder / "key.json"
    if path.exists():
        return
    _write_atomic(path, json.dumps({"params": params, "versions": versions()}, sort_keys=True, separators=(",", ":")))


def _duration(seconds: float) -> str:
    """``42s``, ``3m05s``, ``2h14m``."""
    t = int(round(seconds))
    if t < 60:
        return f"{t}s"
    if t < 3600:
        return f"{t // 60}m{t % 60:02d}s"
    return f"{t // 3600}h{t % 3600 // 60:02d}m"


class BuildProgress:
    """Tests done, rate and time left of a pool build, on standard error, on a terminal
    or not: a line rewritten in place on a terminal, else one line every ``every`` seconds
    and one at the end (so a log shows a long build advancing).

    Example::

        bar = BuildProgress(total=100, initial=0, desc="pool 7x7 reachability2")
        bar.update(1)  # pool 7x7 reachability2: 1/100 tests, 1.4 s/test, 2m19s left
        bar.close()
    """

    WINDOW = 50
    """Tests the rate is measured over (a build whose first tests came from a cache, or
    whose tests slow down, shows the time left at the current pace)."""

    def __init__(self, total: int, initial: int, desc: str, enabled: bool = True, every: float = 10.0, stream: Any = None) -> None:
        self.total, self.n, self.desc, self.enabled, self.every = int(total), int(initial), desc, enabled, float(every)
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.start = self.last = time.monotonic()
        self.first = self.n
        self.marks: deque[tuple[float, int]] = deque([(self.start, self.n)], maxlen=self.WINDOW)
        self.shown = False
        if self.enabled:
            self._show(force=True)

    def text(self) -> str:
        """The progress line: done/total, the recent rate (the last :data:`WINDOW` tests)
        and the time left at that rate."""
        done = self.n - self.first
        now = time.monotonic()
        spent = now - self.start
        line = f"{self.desc}: {self.n}/{self.total} tests"
        if done > 0:
            (t0, n0) = self.marks[0]
            per = (now - t0) / max(self.n - n0, 1) if self.n > n0 else spent / done
            line += f", {per:.2f} s/test" if per < 10 else f", {per:.0f} s/test"
            line += f", {_duration(per * (self.total - self.n))} left" if self.n < self.total else f", {_duration(spent)} in all"
        return line

    def _show(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and not self.tty and now - self.last < self.every:
            return
        self.last = now
        if self.tty:
            print("\r" + self.text(), end="", file=self.stream, flush=True)
        else:
            print(self.text(), file=self.stream, flush=True)
        self.shown = True

    def update(self, k: int = 1) -> None:
        """Count ``k`` more tests done."""
        self.n += k
        self.marks.append((time.monotonic(), self.n))
        if self.enabled:
            self._show(force=self.n >= self.total)

    def close(self) -> None:
        """End the line (on a terminal)."""
        if self.enabled and self.tty and self.shown:
            print(file=self.stream, flush=True)


def build_pool(
    size: int,
    family: str,
    n: int,
    seeds: Iterable[int],
    kind: str = "reactive",
    parallel: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    world: str = "empty",
) -> list[TestArtifact]:
    """The checked pool tests of ``seeds``, rebuilt from the stored records where present,
    else synthesized and stored.

    Parameters
    ----------
    kind, world
        The pool's environment kind (:data:`POOL_KINDS`) and world (:data:`WORLDS`).
    parallel
        ``None``: synthesize the missing seeds in this process; ``"ray"``: as Ray tasks
        (a local Ray runtime with ``workers`` CPUs unless one is running). The tests do
        not depend on this choice.
    progress
        Show the build's progress (tests done, rate, time left) on standard error, on a
        terminal or not (:class:`BuildProgress`); ``False``: silent. Nothing is shown
        when every test is already stored.

    Raises
    ------
    ValueError
        On an unknown family, ``n``, kind, world or ``parallel``.
    RuntimeError
        If a seed has no test in :data:`MAX_ATTEMPTS` draws (the records of the seeds
        built before it are kept: building again resumes).
    """
    _check_pool(family, n, kind, world)
    if parallel not in (None, "ray"):
        raise ValueError(f"unknown parallel backend {parallel!r}; expected None or 'ray'")
    seeds = [int(s) for s in seeds]
    folder = pool_dir(size, family, n, kind, world)
    found: dict[int, TestArtifact] = {}
    files: dict[str, dict[int, dict[str, Any]]] = {}
    for seed in dict.fromkeys(seeds):
        split = split_of(seed)
        if split not in files:
            files[split] = _read(folder / f"{split}.jsonl")
        rec = files[split].get(seed)
        if rec is None:
            continue
        try:
            found[seed] = _artifact(rec, size, family, n, kind, world)
        except ProblemError as exc:
            warn_refused_entry(ProblemError(f"{folder / f'{split}.jsonl'}: {exc}; synthesizing it again"))
    missing = [s for s in dict.fromkeys(seeds) if s not in found]
    if missing:
        _write_key(folder, pool_params(size, family, n, kind, world))
        desc = f"pool {size}x{size} {family}{n} {kind}" + ("" if world == "empty" else f" {world}")
        bar = BuildProgress(len(found) + len(missing), len(found), desc, enabled=progress is not False)
        touched: set[Path] = set()
        try:
            for seed, rec in _synthesize_seeds(size, family, n, missing, kind, world, parallel, workers):
                path = folder / f"{split_of(seed)}.jsonl"
                _append(path, rec)
                touched.add(path)
                found[seed] = _artifact(rec, size, family, n, kind, world)  # checked like any stored record
                bar.update(1)
        finally:
            bar.close()
            for path in sorted(touched):
                _compact(path)
    return [found[s] for s in seeds]


def _synthesize_seeds(
    size: int, family: str, n: int, seeds: list[int], kind: str, world: str, parallel: str | None, workers: int | None
) -> Iterator[tuple[int, dict[str, Any]]]:
    """``(seed, record)`` for every seed, in the order they finish."""
    if parallel is None:
        for seed in seeds:
            yield seed, pool_record(size, family, n, seed, kind, world)
        return
    import ray  # the optional parallel path: Ray is not a core dependency

    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(pool_record)
        pending = {remote.remote(size, family, n, seed, kind, world): seed for seed in seeds}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                yield pending.pop(ref), ray.get(ref)
    finally:
        if started:
            ray.shutdown()


def changed_params(recorded: Mapping[str, Any], current: Mapping[str, Any]) -> list[str]:
    """The parameters (dotted names) recorded with a pool whose value differs now. A
    parameter on one side only is not a change (a new option left at its default, an old
    one retired); a changed value is: a test may differ, the pool needs a new version."""
    out = []
    for key in sorted(set(recorded) & set(current)):
        a, b = recorded[key], current[key]
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            out += [f"{key}.{k}" for k in changed_params(a, b)]
        elif a != b:
            out.append(key)
    return out


def _same_params(key_file: Path, params: dict[str, Any]) -> bool:
    """Whether a cache folder's ``key.json`` records the same pool parameter values."""
    try:
        recorded = json.loads(key_file.read_text(encoding="utf-8"))["params"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    return isinstance(recorded, dict) and not changed_params(recorded, params)


def stored_records(
    size: int, family: str, n: int, split: str, kind: str = "reactive", world: str = "empty", any_version: bool = False
) -> dict[int, dict[str, Any]]:
    """The records of a split stored in the cache under the current versions (with
    ``any_version``: under any version whose pool parameters have the same values,
    :func:`changed_params`; the current ones winning), by seed. Unchecked:
    :func:`synthesis.artifacts.pool_records.rebuild_artifact` checks a record before use."""
    _check_pool(family, n, kind, world)
    here = pool_dir(size, family, n, kind, world)
    folders = [here]
    if any_version and here.parent.is_dir():
        params = pool_params(size, family, n, kind, world)
        others = [d for d in here.parent.iterdir() if d.is_dir() and d != here and _same_params(d / "key.json", params)]
        folders = sorted(others, key=lambda d: d.stat().st_mtime) + folders
    out: dict[int, dict[str, Any]] = {}
    for folder in folders:
        out.update(_read(folder / f"{split}.jsonl", warn=False))
    return out


def synthesize_records(
    size: int,
    family: str,
    n: int,
    seeds: list[int],
    kind: str = "reactive",
    world: str = "empty",
    parallel: str | None = None,
    workers: int | None = None,
) -> Iterator[tuple[int, dict[str, Any]]]:
    """``(seed, record)`` of every seed, synthesized in process or as Ray tasks
    (``parallel="ray"``), in the order they finish."""
    _check_pool(family, n, kind, world)
    if parallel not in (None, "ray"):
        raise ValueError(f"unknown parallel backend {parallel!r}; expected None or 'ray'")
    return _synthesize_seeds(size, family, n, seeds, kind, world, parallel, workers)


_POOLS: dict[tuple[str, tuple[int, ...]], list[TestArtifact]] = {}


def random_pool(
    size: int,
    family: str,
    n: int,
    seeds: tuple[int, ...],
    kind: str = "reactive",
    parallel: str | None = None,
    world: str = "empty",
) -> list[TestArtifact]:
    """The artifacts of a seed pool (:func:`build_pool`), kept in memory per process."""
    key = (str(pool_dir(size, family, n, kind, world)), tuple(int(s) for s in seeds))
    pool = _POOLS.get(key)
    if pool is None:
        pool = _POOLS[key] = build_pool(size, family, n, seeds, kind, parallel=parallel, world=world)
    return pool
