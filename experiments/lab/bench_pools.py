"""Build a random-grid pool from scratch and report its build rate, its size and its digest.

Usage::

    .venv/bin/python -m experiments.lab.bench_pools --size 8 --seeds 0 1
    .venv/bin/python -m experiments.lab.bench_pools --size 8 --seeds 0 1 --busy 2   # every core busy
    .venv/bin/python -m experiments.lab.bench_pools --size 5 --seeds 0-15 --ray --workers 2
    .venv/bin/python -m experiments.lab.bench_pools --pool reachability1/7x7/blocked/agent --seeds 0-9

The pool (``--pool NAME``, see :mod:`flowtest_env.pools`, or ``--size``, ``--family``,
``--n``, ``--world``, ``--kind``) is built into a fresh temporary cache (so every test is
synthesized), with :func:`flowtest_env.random_grid.build_pool`; ``--cache DIR`` builds into
DIR instead and keeps it (a long build resumes there). ``--busy N`` runs N CPU-burning
processes during the build.

It prints one JSON object: the build's wall and CPU seconds (CPU of this process: use it
for in-process builds), the rate in tests per CPU-second, how many draws (attempts) the
seeds needed (the share of first draws that have a test), the statuses, the stored bytes
per test (the compact records of :mod:`synthesis.artifacts.pool_records`) against the bytes of the
full artifact JSON that the pool stored per test before (format 2), the seconds to load
the pool again (every test rebuilt from its record and checked), and the digest: the
SHA-256 of the pool's files, byte for byte. Two builds of one pool, on any machine, under
any load, in process or through Ray, print the same digest (issue 16's acceptance).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from synthesis.artifacts.summary import without_timings

__all__ = ["BURNER", "main", "pool_digest", "seed_list", "without_timings"]

BURNER = "while True:\n    pass\n"


def pool_digest(folder: Path) -> str:
    """SHA-256 of every file under ``folder``, by relative name and bytes (``*.tmp`` left out)."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.name.endswith(".tmp"):
            h.update(str(p.relative_to(folder)).encode() + b"\0")
            h.update(p.read_bytes() + b"\0")
    return h.hexdigest()


def seed_list(items: list[str]) -> list[int]:
    """``["0-3", "7"]`` -> ``[0, 1, 2, 3, 7]``."""
    out: list[int] = []
    for item in items:
        lo, _, hi = item.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--pool", default=None, help="a pool name, e.g. reachability1/5x5/blocked (overrides the next five)")
    ap.add_argument("--size", type=int, default=5)
    ap.add_argument("--family", default="reachability")
    ap.add_argument("--n", type=int, default=1)
    ap.add_argument("--world", default="empty", choices=["empty", "blocked", "fuel"])
    ap.add_argument("--kind", default="reactive", choices=["reactive", "static", "agent"])
    ap.add_argument("--seeds", nargs="+", default=["0-7"], help="seeds and ranges (0-7)")
    ap.add_argument("--busy", type=int, default=0, metavar="N", help="CPU burners during the build")
    ap.add_argument("--ray", action="store_true", help="build through Ray")
    ap.add_argument("--workers", type=int, default=None, help="Ray CPUs (default: every core)")
    ap.add_argument("--cache", default=None, help="build into this cache folder and keep it (default: a fresh temporary one)")
    args = ap.parse_args(argv)
    if args.pool is not None:
        from flowtest_env.pools import parse_pool

        named = parse_pool(args.pool)
        args.size, args.family, args.n, args.world, args.kind = named.size, named.family, named.n, named.world, named.kind
    with tempfile.TemporaryDirectory(prefix="flowtest-bench-pools-") as tmp:
        cache = Path(args.cache) if args.cache else Path(tmp)
        os.environ["FLOWTEST_CACHE_DIR"] = str(cache)
        import flowtest_env.random_grid as rg

        seeds = seed_list(args.seeds)
        burners = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(args.busy)]
        try:
            t, c = time.perf_counter(), time.process_time()
            pool = rg.build_pool(
                args.size,
                args.family,
                args.n,
                seeds,
                args.kind,
                parallel="ray" if args.ray else None,
                workers=args.workers,
                progress=True,
                world=args.world,
            )
            wall, cpu = time.perf_counter() - t, time.process_time() - c
        finally:
            for p in burners:
                p.kill()
                p.wait()
        rg._POOLS.clear()
        t = time.perf_counter()
        again = rg.build_pool(args.size, args.family, args.n, seeds, args.kind, progress=False, world=args.world)
        load = time.perf_counter() - t
        assert [a.to_dict() for a in again] == [a.to_dict() for a in pool], "a pool loaded back differs from the one built"
        folder = rg.pool_dir(args.size, args.family, args.n, args.kind, args.world)
        records = [json.loads(line) for f in sorted(folder.glob("*.jsonl")) for line in f.read_text().splitlines()]
        draws = [r["attempt"] + 1 for r in records if r["seed"] in set(seeds)]
        statuses: dict[str, int] = {}
        for art in pool:
            s = art.summary
            key = s["status"] + (f" ({s['stopped_by']})" if s.get("stopped_by") else "")
            statuses[key] = statuses.get(key, 0) + 1
        stored = sum(f.stat().st_size for f in folder.glob("*.jsonl"))
        full = sum(len(json.dumps(a.to_dict(), separators=(",", ":"))) for a in pool)
        out: dict[str, Any] = {
            "pool": f"{args.size}x{args.size} {args.family}{args.n} {args.world} {args.kind}",
            "tests": len(pool),
            "statuses": statuses,
            "wall_seconds": round(wall, 1),
            "cpu_seconds_this_process": round(cpu, 1),
            "tests_per_cpu_second": round(len(pool) / cpu, 3) if cpu > 0 and not args.ray else None,
            "draws": sum(draws),
            "first_draw_share": round(sum(d == 1 for d in draws) / len(draws), 3) if draws else None,
            "stored_bytes_per_test": round(stored / max(len(pool), 1)),
            "artifact_bytes_per_test": round(full / max(len(pool), 1)),
            "load_seconds": round(load, 2),
            "busy": args.busy,
            "dispatch": "ray" if args.ray else "in-process",
            "digest": pool_digest(cache / "random-grid"),
        }
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
