"""Build the shipped records of the standard pools (a maintainer's tool).

Usage::

    python -m experiments.tools.build_pools reachability1/5x5-v1              # test, validation, train
    python -m experiments.tools.build_pools safety2/7x7/fuel-v1 --split test  # one split
    python -m experiments.tools.build_pools reachability1/5x5-v1 --split train --count 1024
    python -m experiments.tools.build_pools --list                            # what is shipped

Each split's records go to ``flowtest_env/data/pools/<slug>/<split>.jsonl.gz``
(:mod:`flowtest_env.standard_pools`), the split's seeds in order. The build:

* **resumes**: it starts after the last record already in the file;
* **is deterministic**: seeds in order, the pool's deterministic budget
  (:func:`flowtest_env.random_grid.pool_options`), each record fully checked and then
  certified (:func:`synthesis.artifacts.pool_records.certify`), the gzip written without a
  time stamp, so two builds write the same bytes;
* **writes atomically**: the file is rewritten through a temporary file and a rename every
  ``--flush-every`` seconds and at the end, so a crash or Ctrl-C leaves the file as it was
  or with more complete records, never a torn one (Ctrl-C writes what is done, then exits
  with status 130; a plain ``kill``, SIGTERM, does the same);
* **shows progress** on standard error (tests done, rate, time left), on a terminal or not;
* **reuses the cache**: records of the same seeds already built on demand (``load_pool``'s
  cache, under any version) are fully checked and certified instead of synthesized again
  (``--no-cache``: synthesize every seed).

A ``pool.json`` next to the splits records the pool's parameters (budget included) and the
versions that built it; the build refuses to add to a pool whose parameters are not the
current ones (that needs a new version of the pool).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections.abc import Sequence
from typing import Any

from flowtest_env import standard_pools as sp
from flowtest_env.random_grid import SPLITS, BuildProgress, stored_records, synthesize_records
from synthesis.artifacts.pool_records import certify
from synthesis.artifacts.provenance import versions
from synthesis.model.errors import ProblemError

ORDER = ("test", "validation", "train")
"""The order the splits are built in: the held-out split first."""


def _meta(pool: sp.StandardPool) -> dict[str, Any]:
    return {"id": pool.id, "pool": pool.pool, "version": pool.version, "params": pool.params(), "splits": dict(pool.splits)}


def check_meta(pool: sp.StandardPool) -> None:
    """Write ``pool.json`` if missing; refuse a pool whose recorded parameters differ.

    Raises
    ------
    ProblemError
        If the shipped records were built with other parameters.
    """
    path = pool.folder / "pool.json"
    want = _meta(pool)
    if path.exists():
        have = json.loads(path.read_text(encoding="utf-8"))
        if sp.changed_params(have.get("params", {}), want["params"]) or have.get("pool") != want["pool"]:
            raise ProblemError(f"{path}: built with other parameters than {pool.id}'s now; a changed pool needs a new version")
        if have.get("splits") != want["splits"]:  # more tests planned: the same tests, the plan recorded anew
            path.write_text(json.dumps({**have, "splits": want["splits"]}, indent=1, sort_keys=True) + "\n", encoding="utf-8")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({**want, "built_with": versions()}, indent=1, sort_keys=True) + "\n", encoding="utf-8")


def build_split(
    pool: sp.StandardPool, split: str, count: int, flush_every: float = 30.0, reuse_cache: bool = True,
    parallel: str | None = None, workers: int | None = None,
) -> int:
    """Extend ``split``'s shipped records to ``count`` tests (seed order), flushing every
    ``flush_every`` seconds; returns the number of tests in the file at the end. Ctrl-C
    flushes what is done, then raises KeyboardInterrupt."""
    records = sp.read_records(pool, split)
    if len(records) >= count:
        print(f"{pool.id} {split}: {len(records)} tests shipped, nothing to build", file=sys.stderr)
        return len(records)
    check_meta(pool)
    p = pool.name
    base = SPLITS.index(split) * 1_000_000
    seeds = list(range(base + len(records), base + count))
    cached = stored_records(p.size, p.family, p.n, split, p.kind, p.world, any_version=True) if reuse_cache else {}
    path = pool.path(split)
    bar = BuildProgress(count, len(records), f"{pool.id} {split}")
    last = time.monotonic()
    done_upto = len(records)

    def flush() -> None:
        nonlocal done_upto
        if len(records) > done_upto:
            size = sp.write_records(path, records)
            done_upto = len(records)
            print(f"\n{path}: {len(records)} tests, {size:,} bytes" if bar.tty else f"{path}: {len(records)} tests, {size:,} bytes",
                  file=sys.stderr, flush=True)

    def add(rec: dict[str, Any]) -> None:
        nonlocal last
        records.append(certify(rec, p.size, p.family, p.n, p.world, p.kind))
        bar.update(1)
        if time.monotonic() - last >= flush_every:
            flush()
            last = time.monotonic()

    try:
        waiting: dict[int, dict[str, Any]] = {}
        todo: list[int] = []
        for seed in seeds:  # the cached prefix first, in order; the rest synthesized
            if seed in cached and not todo:
                try:
                    add(cached[seed])
                    continue
                except ProblemError:
                    pass  # a stale or damaged cache record: synthesize it
            todo.append(seed)
        for seed, rec in synthesize_records(p.size, p.family, p.n, todo, p.kind, p.world, parallel, workers):
            waiting[seed] = rec
            while waiting and base + len(records) in waiting:  # append in seed order only
                add(waiting.pop(base + len(records)))
    finally:
        bar.close()
        flush()
    return len(records)


def listing() -> str:
    """A table of the standard pools: tests shipped per split (planned) and bytes."""
    rows = []
    for pool in sp.STANDARD_POOLS.values():
        parts = []
        size = 0
        for split in SPLITS:
            parts.append(f"{split} {pool.shipped(split)}/{pool.splits[split]}")
            size += pool.path(split).stat().st_size if pool.path(split).exists() else 0
        rows.append(f"{pool.id:38} {', '.join(parts)}; {size:,} bytes")
    return "\n".join(rows)


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def stop_on_signals() -> None:
    """Ctrl-C, and a plain ``kill`` (SIGTERM), stop a build the same safe way: what is done
    is written, then the process exits (also when started in the background, where a
    shell leaves SIGINT ignored)."""
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments.tools.build_pools", description=__doc__.split("\n\n")[0])
    ap.add_argument("pools", nargs="*", help="standard pool ids (default with --list: all)")
    ap.add_argument("--split", action="append", choices=SPLITS, help="split(s) to build (default: test, validation, train)")
    ap.add_argument("--count", type=int, default=None, help="tests wanted in each split (default: the pool's plan)")
    ap.add_argument("--flush-every", type=float, default=30.0, help="seconds between writes of the file (default 30)")
    ap.add_argument("--no-cache", action="store_true", help="synthesize every seed, ignoring load_pool's cache")
    ap.add_argument("--parallel", choices=("ray",), default=None, help="synthesize as Ray tasks")
    ap.add_argument("--workers", type=int, default=None, help="Ray CPUs (default: all)")
    ap.add_argument("--list", action="store_true", help="show what is shipped and exit")
    args = ap.parse_args(argv)
    if args.list or not args.pools:
        print(listing())
        return 0
    try:
        pools = [sp.standard_pool(name) for name in args.pools]
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.count is not None and args.count < 1:
        print("error: --count must be a positive number of tests", file=sys.stderr)
        return 2
    splits = [s for s in ORDER if s in (args.split or ORDER)]
    stop_on_signals()
    try:
        for pool in pools:
            for split in splits:
                build_split(pool, split, args.count or pool.splits[split], args.flush_every, not args.no_cache,
                            args.parallel, args.workers)
    except KeyboardInterrupt:
        print("interrupted: the records built so far are written; run again to resume", file=sys.stderr)
        return 130
    except ProblemError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


__all__ = ["ORDER", "build_split", "check_meta", "listing", "main", "stop_on_signals"]

if __name__ == "__main__":
    sys.exit(main())
