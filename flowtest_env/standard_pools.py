"""Standard pools: named, versioned test pools shipped with FlowTest, ready to load.

A standard pool is named like an environment ID: the on-demand pool it draws from
(:mod:`flowtest_env.pools`) and a version, ``reachability1/5x5-v1``. The version changes
whenever a test of the pool could change (the family, the world, the kind, the synthesis
budget, the attempt rules): a result reported on ``reachability1/5x5-v1`` names the same
tests on every machine and in every later FlowTest that still ships ``-v1``.

Each pool has three fixed splits drawn from ranges of seeds as for every pool: ``train``
(at least 4,096 tests planned), ``validation`` (for model selection) and ``test`` (the
held-out tests, at least 1,000 planned; 250 where a family builds slowly).

**Disjoint by content (``-v2``).** The ``-v2`` pools (:data:`StandardPool.draw` ``"content"``)
are drawn so that no test of one split is the same game as a test of another and no split
repeats a test: the splits are drawn in :data:`DRAW_ORDER` (held-out first), each from its
seed range in order, and a seed whose test has a content key already taken
(:func:`synthesis.artifacts.content.content_key`: the game a policy plays, not its name,
seed or statistics) is skipped. Each record carries its content key, checked against its
test on every load; :mod:`flowtest_env.pool_content` checks the splits pairwise. A ``-v2``
split is its shipped tests (the draw depends on every split, so nothing is built on
demand beyond them).

**Superseded (``-v1``).** Split ``s`` of a ``-v1`` pool is the first tests of the on-demand
pool's split ``s`` (``load_standard_pool("reachability1/5x5-v1", "test", 32)`` and
``load_pool("reachability1/5x5", "test", 32)`` are the same tests): disjoint seeds, but
not disjoint by content (a quarter of ``reachability1/5x5-v1``'s held-out tests are also
train tests). They stay loadable, with a :class:`SupersededPoolWarning` naming the
``-v2`` pool.

**Shipped records.** The compact records of each pool
(:mod:`synthesis.artifacts.pool_records`, a few hundred bytes a test) are stored in the
package, one gzipped JSON-lines file per split under ``flowtest_env/data/pools/<slug>/``
with a ``pool.json`` that says what built them. Loading synthesizes nothing: each record's
digest is checked, the test is rebuilt from its seed and cuts, and the restrictions are
compared with the record's certificate (what the full check passed when the pool was
built), with one search for a path that avoids the test objective. A record that fails is
refused with an error naming the file, line and seed. ``check="full"`` runs every check
of a fresh synthesis instead (slower; the test suite runs it on a sample).

Building them is a maintainer's job (``python -m experiments.tools.build_pools``); a
split may ship fewer tests than planned (:meth:`StandardPool.shipped` says how many);
:func:`flowtest_env.pools.load_pool` serves the shipped ones and builds the rest on
demand.

Example::

    from flowtest_env.standard_pools import load_standard_pool, standard_pool

    pool = standard_pool("reachability1/5x5-v2")
    tests = load_standard_pool(pool.id, "test")  # every shipped held-out test, checked
"""

from __future__ import annotations

import gzip
import io
import json
import multiprocessing
import os
import re
import warnings
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from multiprocessing.connection import wait as mp_wait
from pathlib import Path
from typing import Any

from synthesis.artifacts.artifact import TestArtifact
from synthesis.artifacts.pool_records import CHECKS, rebuild_artifact
from synthesis.artifacts.provenance import versions
from synthesis.model.errors import ProblemError

from .bulk import can_fork, free_cores, gc_paused, helper_signals
from .random_grid import SPLIT_SPAN, SPLITS, BuildProgress, PoolName, changed_params, parse_pool, pool_params, split_seeds

__all__ = [
    "DATA_DIR",
    "DRAWS",
    "DRAW_ORDER",
    "PROGRESS_FROM",
    "STANDARD_POOLS",
    "StandardPool",
    "SupersededPoolWarning",
    "changed_params",
    "current",
    "is_standard",
    "load_standard_pool",
    "read_records",
    "standard_pool",
    "warn_superseded",
    "write_records",
]

DATA_DIR = Path(__file__).resolve().parent / "data" / "pools"
"""Where the shipped records live (package data)."""

PROGRESS_FROM = 1000
"""Loads of this many tests or more show their progress unless told not to."""

_ID = re.compile(r"^(?P<pool>.+)-v(?P<version>[1-9][0-9]*)$")

DRAWS: tuple[str, ...] = ("seeds", "content")
"""How a standard pool's splits are drawn: ``"seeds"`` (``-v1``: split ``s`` is the first
seeds of the on-demand pool's split ``s``) or ``"content"`` (``-v2``: disjoint by content,
module docstring)."""

DRAW_ORDER: tuple[str, ...] = ("test", "validation", "train")
"""The order a ``"content"`` pool's splits are drawn in: the held-out split first, so it
never gives up a test to the others."""


class SupersededPoolWarning(UserWarning):
    """A superseded standard pool was loaded (it stays loadable; the warning names the pool
    that replaces it and why)."""


@dataclass(frozen=True)
class StandardPool:
    """A standard pool: its id, the on-demand pool it draws from, its version and the
    number of tests planned per split.

    Attributes
    ----------
    id
        ``<pool>-v<version>``, e.g. ``reachability1/5x5-v1``.
    pool
        The on-demand pool name (:func:`flowtest_env.pools.parse_pool`).
    version
        Changes whenever a test of the pool can change.
    splits
        Tests planned per split (``train``, ``validation``, ``test``).
    about
        What the pool exercises, in a few words.
    slow
        Builds slowly (seconds a test): its held-out split is planned at 250 tests, not
        1,000.
    draw
        How its splits are drawn (:data:`DRAWS`): ``"seeds"`` or ``"content"`` (disjoint by
        content, the seeds of tests already taken skipped).
    superseded_by
        The id of the pool that replaces it (it stays loadable, with a
        :class:`SupersededPoolWarning`), or ``None``.
    """

    id: str
    pool: str
    version: int
    splits: Mapping[str, int] = field(default_factory=lambda: {"train": 4096, "validation": 256, "test": 1000})
    about: str = ""
    slow: bool = False
    draw: str = "seeds"
    superseded_by: str | None = None

    @property
    def name(self) -> PoolName:
        """The parsed on-demand pool name."""
        return parse_pool(self.pool)

    @property
    def slug(self) -> str:
        """The folder name of its records: the id with ``/`` as ``-``."""
        return self.id.replace("/", "-")

    @property
    def folder(self) -> Path:
        """The folder of its shipped records."""
        return DATA_DIR / self.slug

    def path(self, split: str) -> Path:
        """The shipped records file of a split."""
        _check_split(split)
        return self.folder / f"{split}.jsonl.gz"

    def params(self) -> dict[str, Any]:
        """Everything besides the versions that decides its tests (the on-demand pool's
        parameters; a change here needs a new version)."""
        p = self.name
        return pool_params(p.size, p.family, p.n, p.kind, p.world)

    def shipped(self, split: str) -> int:
        """The number of tests of ``split`` shipped (0 if none yet)."""
        path = self.path(split)
        try:
            stat = path.stat()
        except OSError:
            return 0
        return _count_lines(str(path), stat.st_mtime_ns, stat.st_size)

    def shipped_counts(self) -> dict[str, int]:
        """Tests shipped per split."""
        return {s: self.shipped(s) for s in SPLITS}

    def seeds(self, split: str) -> list[int]:
        """The seeds of a split's shipped tests, in order (a ``"seeds"`` pool's are the
        split's first seeds; a ``"content"`` pool's skip the seeds of tests already taken)."""
        path = self.path(split)
        try:
            stat = path.stat()
        except OSError:
            return []
        return list(_shipped_seeds(self.id, split, stat.st_mtime_ns, stat.st_size))


_FAMILIES: tuple[tuple[str, str, bool], ...] = (
    ("reachability1/5x5", "the paper's empty 5x5 grid, one hidden goal, reactive doors; the continuity pool (a random policy meets about half)", False),
    ("safety2/5x5/fuel", "5x5 fuel grid (capacity 5, refuel cells, never run empty), a goal and a cell to avoid, reactive doors", False),
    ("safety2/5x5/fuel/static", "the same fuel grids with static walls (the whole test) instead of doors", False),
    ("reachability1/5x5/blocked/agent", "5x5 grid, a fifth of the cells blocked, a test agent patrolling one column (a GR(1) strategy)", True),
    ("reachability2/7x7/blocked", "7x7 grid, a fifth of the cells blocked, two hidden goals, reactive doors", False),
)
"""The families of the standard pools: on-demand pool, what it exercises, slow to build."""


def _plan(slow: bool) -> dict[str, int]:
    return {"train": 4096, "validation": 256, "test": 250 if slow else 1000}


STANDARD_POOLS: dict[str, StandardPool] = {
    p.id: p
    for name, about, slow in _FAMILIES
    for p in (
        StandardPool(f"{name}-v1", name, 1, _plan(slow), about, slow, superseded_by=f"{name}-v2"),
        StandardPool(f"{name}-v2", name, 2, _plan(slow), about, slow, draw="content"),
    )
}
"""Every standard pool by id."""


def is_standard(name: str) -> bool:
    """Whether ``name`` is written as a standard pool id (``<pool>-v<N>``)."""
    return isinstance(name, str) and _ID.match(name) is not None


def standard_pool(pool_id: str) -> StandardPool:
    """The standard pool of an id.

    Raises
    ------
    ValueError
        On an id that is not a standard pool (naming the standard pools, or the versions
        of that pool that exist).
    """
    found = STANDARD_POOLS.get(pool_id)
    if found is not None:
        return found
    m = _ID.match(pool_id) if isinstance(pool_id, str) else None
    if m is not None:
        same = sorted(p.id for p in STANDARD_POOLS.values() if p.pool == m.group("pool"))
        if same:
            raise ValueError(f"{pool_id!r} is not a standard pool; this FlowTest ships {', '.join(same)}")
    raise ValueError(f"{pool_id!r} is not a standard pool; expected one of {', '.join(STANDARD_POOLS)}")


def _check_split(split: str) -> None:
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; expected one of {', '.join(SPLITS)}")


def current(pool_id: str) -> StandardPool:
    """The pool that stands for ``pool_id`` today: itself, or the pool that supersedes it."""
    pool = standard_pool(pool_id)
    while pool.superseded_by is not None:
        pool = standard_pool(pool.superseded_by)
    return pool


_WARNED: set[str] = set()


def warn_superseded(pool: StandardPool) -> None:
    """Warn once per process that a superseded pool is being loaded
    (:class:`SupersededPoolWarning`)."""
    if pool.superseded_by is None or pool.id in _WARNED:
        return
    _WARNED.add(pool.id)
    warnings.warn(
        SupersededPoolWarning(
            f"{pool.id} is superseded by {pool.superseded_by}: its splits have disjoint seeds but share tests by content "
            f"(docs/pools.md); it stays loadable to compare with results reported on it"
        ),
        stacklevel=3,
    )


@lru_cache(maxsize=64)
def _shipped_seeds(pool_id: str, split: str, mtime_ns: int, size: int) -> tuple[int, ...]:
    """The seeds of a split file's records (cached per pool, file version and size)."""
    return tuple(int(r["seed"]) for r in read_records(standard_pool(pool_id), split))


@lru_cache(maxsize=64)
def _count_lines(path: str, mtime_ns: int, size: int) -> int:
    """Lines of a gzipped file (cached per path, modification time and size).

    Raises
    ------
    ProblemError
        If the file is not gzipped or ends early, naming the file and the line.
    """
    return len(_read_lines(Path(path)))


def _read_lines(path: Path) -> list[str]:
    """The non-blank lines of a gzipped UTF-8 file.

    Raises
    ------
    ProblemError
        If the file is not gzipped, not UTF-8, or stops in the middle (a truncated copy):
        ``file, line N: ...``, N the line where it stops.
    """
    lines: list[str] = []
    try:
        with gzip.open(path, "rt", encoding="utf-8") as f:
            for line in f:
                if line.strip():
                    lines.append(line)
    except EOFError:
        raise ProblemError(
            f"{path}, line {len(lines) + 1}: the file stops in the middle (a truncated copy: {len(lines)} "
            "whole lines before it); reinstall FlowTest or copy the file again"
        ) from None
    except (OSError, UnicodeDecodeError, zlib.error) as exc:
        raise ProblemError(f"{path}, line {len(lines) + 1}: not a gzipped records file ({exc})") from None
    return lines


def read_records(pool: StandardPool, split: str) -> list[dict[str, Any]]:
    """The shipped records of a split, in seed order (``[]`` if none are shipped).

    Raises
    ------
    ProblemError
        If the file is not gzipped JSON lines, or its records are not the split's seeds in
        order (``file, line N: ...``): its first seeds for a ``"seeds"`` pool, increasing
        seeds of the split's range for a ``"content"`` pool.
    """
    path = pool.path(split)
    if not path.exists():
        return []
    lines = _read_lines(path)
    base = SPLITS.index(split) * SPLIT_SPAN
    out: list[dict[str, Any]] = []
    for k, text in enumerate(lines):
        try:
            rec = json.loads(text)
        except ValueError as exc:
            raise ProblemError(f"{path}, line {k + 1}: not JSON ({exc})") from None
        seed = rec.get("seed") if isinstance(rec, dict) else None
        if pool.draw == "content":
            low = out[-1]["seed"] + 1 if out else base
            if isinstance(seed, bool) or not isinstance(seed, int) or not low <= seed < base + SPLIT_SPAN:
                raise ProblemError(f"{path}, line {k + 1}: expected the record of a seed in {low}..{base + SPLIT_SPAN - 1} (the split's seeds, increasing)")
        elif seed != base + k:
            raise ProblemError(f"{path}, line {k + 1}: expected the record of seed {base + k} (the split's seeds in order)")
        out.append(rec)
    return out


def _line(record: Mapping[str, Any]) -> str:
    return json.dumps(record, sort_keys=True, separators=(",", ":")) + "\n"


def write_records(path: Path, records: Iterable[Mapping[str, Any]]) -> int:
    """Write records as gzipped JSON lines, atomically (a temporary file, then a rename)
    and reproducibly (no time or name in the gzip header: the same records give the same
    bytes). Returns the bytes written."""
    buf = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buf, compresslevel=9, mtime=0) as gz:
        for rec in records:
            gz.write(_line(rec).encode("utf-8"))
    data = buf.getvalue()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return len(data)


def load_standard_pool(
    pool_id: str,
    split: str = "test",
    count: int | None = None,
    start: int = 0,
    check: str = "certificate",
    progress: bool | None = None,
    workers: int | None = None,
) -> list[TestArtifact]:
    """The checked tests ``start .. start + count - 1`` of a standard pool's split, from the
    shipped records (nothing is synthesized).

    Parameters
    ----------
    count
        ``None``: every shipped test from ``start`` on.
    check
        ``"certificate"`` (digest, certificate and the bypass search, fast) or ``"full"``
        (every check of a fresh synthesis).
    progress
        Show tests loaded, rate and time left on standard error (``None``: for loads of
        :data:`PROGRESS_FROM` tests or more).
    workers
        Processes that rebuild and check the records, this one included: ``1`` loads in
        this process; more fork helpers that take chunks of :data:`CHUNK` tests as they
        go (the same tests, in the same order, with the same checks; the first record
        refused is the one a load in one process refuses). ``None``: two where
        :func:`auto_workers` finds two cores for a load of :data:`PARALLEL_FROM` tests or
        more, else one.

    Example::

        tests = load_standard_pool("reachability1/5x5-v1", "validation", count=64)

    Raises
    ------
    ValueError
        On an unknown pool, split or check, more tests than are shipped, or fewer than
        one worker.
    ProblemError
        If a shipped record is refused (edited, or no longer the test its certificate
        names), naming the file and line.
    """
    pool = standard_pool(pool_id)
    _check_split(split)
    warn_superseded(pool)
    if check not in CHECKS:
        raise ValueError(f"unknown check {check!r}; expected one of {', '.join(CHECKS)}")
    records = read_records(pool, split)
    if count is None:
        count = len(records) - start
    split_seeds(split, max(count, 1), start)  # validates start and count against the split
    if count < 1 or start + count > len(records):
        raise ValueError(
            f"{pool.id} ships {len(records)} tests of its {split!r} split; asked for tests {start}..{start + count - 1} "
            + (
                "(flowtest_env.pools.load_pool builds the ones beyond on demand)"
                if pool.draw == "seeds"
                else "(a pool disjoint by content is its shipped tests: python -m experiments.tools.build_pools builds more)"
            )
        )
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers must be a positive integer or None, got {workers!r}")
    n_proc = auto_workers(count) if workers is None else min(workers, max(1, -(-count // CHUNK)))
    show = progress if progress is not None else count >= PROGRESS_FROM
    bar = BuildProgress(count, 0, f"loading {pool.id} {split}", enabled=show)
    job = _Job(pool, split, check, records[start : start + count], start)
    try:
        with gc_paused():
            if n_proc > 1 and can_fork():
                tests = _load_forked(job, n_proc, bar)
                if tests is not None:
                    return tests
            out: list[TestArtifact] = []
            for k in range(count):
                out.append(job.load(k))
                bar.update(1)
            return out
    finally:
        bar.close()


CHUNK = 32
"""Tests a helper process of :func:`load_standard_pool` takes at a time."""

PARALLEL_FROM = 1000
"""Loads of this many tests or more use two processes where two cores are free to this
one (:func:`auto_workers`)."""


def auto_workers(count: int) -> int:
    """The processes :func:`load_standard_pool` uses by default for ``count`` tests: two for
    :data:`PARALLEL_FROM` tests or more where this process may run on two cores or more
    and can fork, else one (each process rebuilds whole tests; beyond two, this
    process's share of receiving the others' tests grows)."""
    return 2 if count >= PARALLEL_FROM and free_cores() >= 2 and can_fork() else 1


class _Job:
    """What a load rebuilds: records ``start ..`` of a split (``records[k]`` is line
    ``start + k + 1``), and the provenance every test of it carries."""

    def __init__(self, pool: StandardPool, split: str, check: str, records: list[dict[str, Any]], start: int) -> None:
        self.pool, self.split, self.check, self.records, self.start = pool, split, check, records, start
        self.provenance = {"pool": pool.params(), "standard_pool": pool.id, "versions": versions()}

    def load(self, k: int) -> TestArtifact:
        """The checked test of ``records[k]``.

        Raises
        ------
        ProblemError
            If it is refused, naming the file, line and pool.
        """
        p = self.pool.name
        try:
            return rebuild_artifact(self.records[k], p.size, p.family, p.n, p.world, p.kind, {"provenance": self.provenance}, check=self.check)
        except ProblemError as exc:
            raise ProblemError(f"{self.pool.path(self.split)}, line {self.start + k + 1}: {exc}; the shipped pool {self.pool.id} is refused") from None


def _chunk_tests(job: _Job, c: int) -> tuple[list[TestArtifact], str | None]:
    """The tests of chunk ``c`` up to the first one refused, and the refusal (or None)."""
    out: list[TestArtifact] = []
    for k in range(c * CHUNK, min((c + 1) * CHUNK, len(job.records))):
        try:
            out.append(job.load(k))
        except ProblemError as exc:
            return out, str(exc)
    return out, None


def _next_chunk(counter: Any, n_chunks: int) -> int:
    """Take the next chunk (``n_chunks``: none left)."""
    with counter.get_lock():
        c = int(counter.value)
        if c < n_chunks:
            counter.value = c + 1
        return min(c, n_chunks)


def _helper(job: _Job, counter: Any, n_chunks: int, conn: Any) -> None:
    """A forked helper: chunks taken in turn, each sent back as ``(chunk, tests, refusal)``
    until none is left or one is refused. Ctrl-C (sent to the whole process group) is left
    to the loader, which stops it (:func:`~flowtest_env.bulk.helper_signals`)."""
    helper_signals()
    code = 0
    try:
        while (c := _next_chunk(counter, n_chunks)) < n_chunks:
            tests, refusal = _chunk_tests(job, c)
            conn.send((c, tests, refusal))
            if refusal is not None:
                break
    except KeyboardInterrupt:
        code = 130
    except BaseException as exc:  # a broken helper: said to the loader, which stops
        try:
            conn.send((-1, [], f"a loading process failed: {type(exc).__name__}: {exc}"))
        except (OSError, ValueError):
            pass
        code = 1
    finally:
        conn.close()
    os._exit(code)  # no exit handlers of the parent (they are its own)


def _load_forked(job: _Job, n_proc: int, bar: BuildProgress) -> list[TestArtifact] | None:
    """:func:`load_standard_pool` over ``n_proc`` processes: this one and forked helpers
    take chunks of :data:`CHUNK` tests from a shared counter, this one collects them in
    chunk order. On a refusal no chunk is taken any more; the chunks taken before finish,
    and the refusal of the lowest line is raised (the one a single process meets first).
    ``None`` where the system gives no shared counter (no ``/dev/shm``...); a helper that
    cannot start leaves its chunks to the others."""
    ctx = multiprocessing.get_context("fork")
    n_chunks = -(-len(job.records) // CHUNK)
    try:
        counter = ctx.Value("q", 0)
    except OSError:
        return None
    results: dict[int, list[TestArtifact]] = {}
    refusals: dict[int, str] = {}
    procs: list[Any] = []
    conns: list[Any] = []
    try:
        for _ in range(n_proc - 1):
            try:
                recv, send = ctx.Pipe(duplex=False)
            except OSError:
                break
            proc = ctx.Process(target=_helper, args=(job, counter, n_chunks, send), daemon=True)
            procs.append(proc)  # before it starts: a Ctrl-C right after start() still stops it below
            try:
                proc.start()
            except OSError:  # out of processes or memory: the others take its chunks
                procs.pop()
                recv.close()
                break
            finally:
                send.close()
            conns.append(recv)

        def take(msg: tuple[int, list[TestArtifact], str | None]) -> None:
            c, tests, refusal = msg
            results[c] = tests
            bar.update(len(tests))
            if refusal is not None:
                refusals[c] = refusal
                _stop(counter, n_chunks)

        while (c := _next_chunk(counter, n_chunks)) < n_chunks:  # this process takes chunks too
            tests: list[TestArtifact] = []
            results[c] = tests
            for k in range(c * CHUNK, min((c + 1) * CHUNK, len(job.records))):
                try:
                    tests.append(job.load(k))
                except ProblemError as exc:
                    refusals[c] = str(exc)
                    _stop(counter, n_chunks)
                    break
                bar.update(1)
                for conn in list(conns):  # what the helpers sent meanwhile
                    while conn in conns and conn.poll():
                        _receive(conn, conns, take)
        while conns:
            for conn in mp_wait(conns, timeout=0.5):
                _receive(conn, conns, take)
        if refusals:
            raise ProblemError(refusals[min(refusals)])
        missing = [c for c in range(n_chunks) if c not in results]
        if missing:
            raise ProblemError(f"a loading process stopped before chunk {missing[0]} of {job.pool.id} {job.split} was loaded")
        return [t for c in range(n_chunks) for t in results[c]]
    finally:
        procs = [proc for proc in procs if proc.pid is not None]  # started (a Ctrl-C may come before start())
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=1.0)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=1.0)
        for conn in conns:
            conn.close()


def _stop(counter: Any, n_chunks: int) -> None:
    """No chunk is taken any more."""
    with counter.get_lock():
        counter.value = n_chunks


def _receive(conn: Any, conns: list[Any], take: Any) -> None:
    """One message of a helper (``take`` it), or its end (its pipe leaves ``conns``).

    Raises
    ------
    ProblemError
        If the helper failed other than by refusing a record (it says so, chunk -1).
    """
    try:
        msg = conn.recv()
    except (EOFError, OSError):
        conns.remove(conn)
        conn.close()
        return
    if msg[0] < 0:
        raise ProblemError(msg[2])
    take(msg)
