"""Build the shipped records of the standard pools (a maintainer's tool).

Usage::

    python -m experiments.tools.build_pools reachability1/5x5-v2              # test, validation, train
    python -m experiments.tools.build_pools safety2/5x5/fuel-v2 --split test  # one split
    python -m experiments.tools.build_pools reachability1/5x5-v1 --split train --count 1024
    python -m experiments.tools.build_pools --list                            # what is shipped
    python -m experiments.tools.build_pools --overlaps reachability1/5x5-v1   # splits compared by content

Each split's records go to ``flowtest_env/data/pools/<slug>/<split>.jsonl.gz``
(:mod:`flowtest_env.standard_pools`), the split's seeds in order. The build:

* **resumes**: it starts after the last record already in the file;
* **draws a ``-v2`` pool disjoint by content**: the splits in turn (test, validation, train),
  each from its seeds in order, a seed skipped when its test's content key is already
  taken; the family's layout count, the birthday bound and the seeds skipped per split
  are written to ``pool.json`` (:func:`draws`);
* **is deterministic**: seeds in order, the pool's deterministic budget
  (:func:`flowtest_env.random_grid.pool_options`), each record fully checked and then
  certified (:func:`synthesis.artifacts.pool_records.certify`), the gzip written without a
  time stamp, so two builds write the same bytes;
* **writes atomically**: the file is rewritten through a temporary file and a rename every
  ``--flush-every`` seconds and at the end, so a crash or Ctrl-C leaves the file as it was
  or with more complete records, never a torn one (Ctrl-C writes what is done, then exits
  with status 130; a plain ``kill``, SIGTERM, does the same);
* **shows progress** on standard error (tests done, rate, time left), on a terminal or not;
* **reuses records**: records of the same seeds already built, shipped with another
  version of the same pool (a ``-v1`` pool's, for its ``-v2``) or on demand (``load_pool``'s
  cache, under any version), are fully checked and certified instead of synthesized again
  (``--no-cache``: not the cache's).

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
from collections.abc import Iterator, Sequence
from typing import Any

from flowtest_env import standard_pools as sp
from flowtest_env.pool_content import birthday, overlaps, split_keys
from flowtest_env.random_grid import SPLIT_SPAN, SPLITS, BuildProgress, PoolName, pool_record, stored_records, synthesize_records
from synthesis.artifacts.pool_records import certify, record_content_key
from synthesis.artifacts.provenance import versions
from synthesis.model.errors import ProblemError
from synthesis.problems.random_worlds import layout_count

ORDER = sp.DRAW_ORDER
"""The order the splits are built in: the held-out split first (a ``-v2`` pool's draw order)."""


def _meta(pool: sp.StandardPool) -> dict[str, Any]:
    return {
        "id": pool.id,
        "pool": pool.pool,
        "version": pool.version,
        "params": pool.params(),
        "splits": dict(pool.splits),
        **({"draw": {"order": list(sp.DRAW_ORDER)}} if pool.draw == "content" else {}),
    }


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
    pool: sp.StandardPool,
    split: str,
    count: int,
    flush_every: float = 30.0,
    reuse_cache: bool = True,
    parallel: str | None = None,
    workers: int | None = None,
) -> int:
    """Extend ``split``'s shipped records to ``count`` tests (seed order), flushing every
    ``flush_every`` seconds; returns the number of tests in the file at the end. Ctrl-C
    flushes what is done, then raises KeyboardInterrupt.

    A ``"content"`` pool (``-v2``) takes the split's seeds in order from the one after its
    last shipped record and skips a seed whose test's content key is already taken (by a
    split drawn before it, :data:`flowtest_env.standard_pools.DRAW_ORDER`, or by the split
    itself); it refuses to start before the splits drawn before it are complete.

    Raises
    ------
    ProblemError
        If the pool's recorded parameters are not today's, or (a ``"content"`` pool) a
        split drawn before this one is not complete.
    """
    records = sp.read_records(pool, split)
    if len(records) >= count:
        print(f"{pool.id} {split}: {len(records)} tests shipped, nothing to build", file=sys.stderr)
        return len(records)
    taken = _taken_keys(pool, split, records)
    check_meta(pool)
    p = pool.name
    base = SPLITS.index(split) * SPLIT_SPAN
    known = _known_records(pool, split, reuse_cache)
    path = pool.path(split)
    bar = BuildProgress(count, len(records), f"{pool.id} {split}")
    last = time.monotonic()
    done_upto = len(records)
    next_seed = records[-1]["seed"] + 1 if records else base
    skipped = next_seed - base - len(records)

    def flush() -> None:
        nonlocal done_upto
        if len(records) > done_upto:
            size = sp.write_records(path, records)
            done_upto = len(records)
            more = f", {skipped} seeds skipped (their test already taken)" if taken is not None else ""
            print(("\n" if bar.tty else "") + f"{path}: {len(records)} tests{more}, {size:,} bytes", file=sys.stderr, flush=True)

    def add(seed: int, rec: dict[str, Any], synthesized: bool) -> None:
        nonlocal last, skipped
        try:
            cert = certify(rec, p.size, p.family, p.n, p.world, p.kind, content=taken is not None)
        except ProblemError:
            if synthesized:
                raise
            cert = certify(
                pool_record(p.size, p.family, p.n, seed, p.kind, p.world), p.size, p.family, p.n, p.world, p.kind, content=taken is not None
            )  # a stale or damaged reused record: synthesized again
        key = record_content_key(cert)
        if taken is not None and key in taken:
            skipped += 1
            bar.desc = f"{pool.id} {split} ({skipped} seeds skipped)"
        else:
            if taken is not None and key is not None:
                taken.add(key)
            records.append(cert)
            bar.update(1)
        if time.monotonic() - last >= flush_every:
            flush()
            last = time.monotonic()

    try:
        while len(records) < count:
            need = count - len(records)
            stop = min(next_seed + need + (need // 4 + 8 if taken is not None else 0), base + SPLIT_SPAN)
            if stop <= next_seed:
                raise ProblemError(f"{pool.id} {split}: the split's seed range ends before {count} tests")
            for seed, rec, synthesized in _in_order(range(next_seed, stop), known, p, parallel, workers):
                if len(records) >= count:
                    break
                add(seed, rec, synthesized)
                next_seed = seed + 1
    finally:
        bar.close()
        flush()
        if taken is not None and records:
            write_draws(pool)
    return len(records)


def _taken_keys(pool: sp.StandardPool, split: str, records: list[dict[str, Any]]) -> set[str] | None:
    """The content keys a ``"content"`` pool's split may not draw again: those of the splits
    drawn before it and its own (``None`` for a ``"seeds"`` pool).

    Raises
    ------
    ProblemError
        If a split drawn before it is not complete (its later tests could take a key this
        split holds).
    """
    if pool.draw != "content":
        return None
    taken: set[str] = set()
    for before in sp.DRAW_ORDER[: sp.DRAW_ORDER.index(split)]:
        have = sp.read_records(pool, before)
        if len(have) < pool.splits[before]:
            raise ProblemError(
                f"{pool.id}: its {before} split has {len(have)} of {pool.splits[before]} tests; a pool disjoint by content draws "
                f"{', '.join(sp.DRAW_ORDER)} in turn: build {before} first"
            )
        taken.update(k for r in have if (k := record_content_key(r)) is not None)
    taken.update(k for r in records if (k := record_content_key(r)) is not None)
    return taken


def _known_records(pool: sp.StandardPool, split: str, reuse_cache: bool) -> dict[int, dict[str, Any]]:
    """Records of the split's seeds built before, by seed: those load_pool's cache holds
    (under any version with the same parameters, with ``reuse_cache``) and those other
    standard pools of the same on-demand pool and parameters ship (a ``-v1`` pool's, for
    its ``-v2``). Each is fully checked again (:func:`certify`) before it is used."""
    p = pool.name
    known = stored_records(p.size, p.family, p.n, split, p.kind, p.world, any_version=True) if reuse_cache else {}
    for other in sp.STANDARD_POOLS.values():
        if other.id != pool.id and other.pool == pool.pool and not sp.changed_params(_recorded_params(other), pool.params()):
            known.update({r["seed"]: r for r in sp.read_records(other, split)})
    return known


def _recorded_params(pool: sp.StandardPool) -> dict[str, Any]:
    """The parameters a shipped pool's ``pool.json`` records (``{}`` where it has none)."""
    try:
        params = json.loads((pool.folder / "pool.json").read_text(encoding="utf-8"))["params"]
    except (OSError, ValueError, KeyError, TypeError):
        return {}
    return params if isinstance(params, dict) else {}


def _in_order(
    seeds: range, known: dict[int, dict[str, Any]], p: PoolName, parallel: str | None, workers: int | None
) -> Iterator[tuple[int, dict[str, Any], bool]]:
    """``(seed, record, synthesized)`` for every seed in order: a known record as soon as
    the seeds before it are given, the others synthesized (in process or as Ray tasks)."""
    ready = {s: known[s] for s in seeds if s in known}
    todo = [s for s in seeds if s not in ready]
    fresh: set[int] = set()
    k = 0
    for seed, rec in synthesize_records(p.size, p.family, p.n, todo, p.kind, p.world, parallel, workers) if todo else ():
        ready[seed] = rec
        fresh.add(seed)
        while k < len(seeds) and seeds[k] in ready:
            yield seeds[k], ready.pop(seeds[k]), seeds[k] in fresh
            k += 1
    while k < len(seeds):
        yield seeds[k], ready.pop(seeds[k]), seeds[k] in fresh
        k += 1


def draws(pool: sp.StandardPool) -> dict[str, Any]:
    """What ``pool.json`` says of a ``"content"`` pool's draw: the family's layout count
    (exact, :func:`synthesis.problems.random_worlds.layout_count`), the birthday bound of
    its planned split sizes (:func:`flowtest_env.pool_content.birthday`), and per split the
    tests shipped, the seeds drawn and the seeds skipped (their test's key already taken)."""
    p = pool.name
    layouts = layout_count(p.size, p.family, p.n, p.world, p.kind)
    bound = birthday(layouts, dict(pool.splits))
    splits = {}
    for split in SPLITS:
        seeds = pool.seeds(split)
        base = SPLITS.index(split) * SPLIT_SPAN
        drawn = seeds[-1] - base + 1 if seeds else 0
        splits[split] = {
            "tests": len(seeds),
            "seeds_drawn": drawn,
            "seeds_skipped": drawn - len(seeds),
            "first_seed": seeds[0] if seeds else None,
            "last_seed": seeds[-1] if seeds else None,
        }
    return {
        "order": list(sp.DRAW_ORDER),
        "layouts": layouts,
        "layouts_how": "exact: start, goal and proposition cells in order, the test agent's column and start row, "
        "the blocked or refuel cells as a set (synthesis.problems.random_worlds.layout_count)",
        "birthday": {
            "repeats": {k: _sig(v) for k, v in bound["repeats"].items()},
            "shared": {k: _sig(v) for k, v in bound["shared"].items()},
            "any_collision": _sig(bound["any_collision"]),
        },
        "splits": splits,
    }


def _sig(x: float) -> float:
    """``x`` to 3 significant digits (a bound of 2e-9 stays 2e-9, not 0)."""
    return float(f"{x:.3g}")


def write_draws(pool: sp.StandardPool) -> None:
    """Record :func:`draws` in the pool's ``pool.json``."""
    path = pool.folder / "pool.json"
    meta = json.loads(path.read_text(encoding="utf-8"))
    meta["draw"] = draws(pool)
    path.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n", encoding="utf-8")


def listing() -> str:
    """A table of the standard pools: tests shipped per split (planned) and bytes."""
    rows = []
    for pool in sp.STANDARD_POOLS.values():
        parts = []
        size = 0
        for split in SPLITS:
            parts.append(f"{split} {pool.shipped(split)}/{pool.splits[split]}")
            size += pool.path(split).stat().st_size if pool.path(split).exists() else 0
        note = f" (superseded by {pool.superseded_by})" if pool.superseded_by else " (disjoint by content)" if pool.draw == "content" else ""
        rows.append(f"{pool.id:38} {', '.join(parts)}; {size:,} bytes{note}")
    return "\n".join(rows)


def overlap_report(pool: sp.StandardPool) -> str:
    """The splits of a shipped pool compared by content (keys read from the records, or
    computed from the rebuilt tests where the records carry none), beside what the
    birthday bound predicts for splits drawn by seed."""
    keys = {s: split_keys(pool, s, progress=True) for s in SPLITS}
    report = overlaps(keys)
    p = pool.name
    layouts = layout_count(p.size, p.family, p.n, p.world, p.kind)
    bound = birthday(layouts, report.sizes)
    lines = [f"{pool.id}: {layouts:,} layouts; " + ("disjoint by content" if report.clean else "NOT disjoint by content")]
    lines += [f"  {line}" for line in report.lines()]
    lines += [f"  chance, splits drawn by seed: {k}: {v:.1f}" for k, v in bound["shared"].items()]
    lines += [f"  chance, splits drawn by seed: {k} repeats: {v:.1f}" for k, v in bound["repeats"].items()]
    return "\n".join(lines)


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
    ap.add_argument("--overlaps", action="store_true", help="compare the shipped splits by content (repeats, tests shared) and exit (default: all pools)")
    args = ap.parse_args(argv)
    if args.list or not (args.pools or args.overlaps):
        print(listing())
        return 0
    try:
        pools = [sp.standard_pool(name) for name in args.pools or (list(sp.STANDARD_POOLS) if args.overlaps else [])]
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.overlaps:
        stop_on_signals()
        try:
            for pool in pools:
                print(overlap_report(pool), flush=True)
        except KeyboardInterrupt:
            return 130
        return 0
    if args.count is not None and args.count < 1:
        print("error: --count must be a positive number of tests", file=sys.stderr)
        return 2
    splits = [s for s in ORDER if s in (args.split or ORDER)]
    stop_on_signals()
    try:
        for pool in pools:
            for split in splits:
                build_split(pool, split, args.count or pool.splits[split], args.flush_every, not args.no_cache, args.parallel, args.workers)
    except KeyboardInterrupt:
        print("interrupted: the records built so far are written; run again to resume", file=sys.stderr)
        return 130
    except ProblemError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


__all__ = ["ORDER", "build_split", "check_meta", "draws", "listing", "main", "overlap_report", "stop_on_signals", "write_draws"]

if __name__ == "__main__":
    sys.exit(main())
