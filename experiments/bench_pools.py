"""Build a random-grid pool from scratch and report its time and its digest.

Usage::

    .venv/bin/python -m experiments.bench_pools --size 8 --seeds 0 1
    .venv/bin/python -m experiments.bench_pools --size 8 --seeds 0 1 --busy 2   # every core busy
    .venv/bin/python -m experiments.bench_pools --size 5 --seeds 0-15 --ray --workers 2

The pool is built into a fresh temporary cache (so every test is synthesized), with
:func:`flowtest_env.random_grid.build_pool`. ``--busy N`` runs N CPU-burning processes
during the build. The digest is the SHA-256 of the pool's files without their timing
fields (``*_seconds``, ``timings``): two builds of one pool, on any machine, under any
load, in process or through Ray, print the same digest (issue 12's acceptance).
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

BURNER = "while True:\n    pass\n"


def without_timings(x: Any) -> Any:
    """A JSON value without its timing fields."""
    if isinstance(x, dict):
        return {k: without_timings(v) for k, v in x.items() if not k.endswith("_seconds") and k != "timings"}
    if isinstance(x, list):
        return [without_timings(v) for v in x]
    return x


def pool_digest(folder: Path) -> str:
    """SHA-256 of every JSON file under ``folder`` (by relative name) without timings."""
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*.json")):
        h.update(str(p.relative_to(folder)).encode() + b"\0")
        h.update(json.dumps(without_timings(json.loads(p.read_text())), sort_keys=True).encode() + b"\0")
    return h.hexdigest()


def seed_list(items: list[str]) -> list[int]:
    """``["0-3", "7"]`` -> ``[0, 1, 2, 3, 7]``."""
    out: list[int] = []
    for item in items:
        lo, _, hi = item.partition("-")
        out.extend(range(int(lo), int(hi or lo) + 1))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=5)
    ap.add_argument("--family", default="reachability")
    ap.add_argument("--n", type=int, default=1)
    ap.add_argument("--kind", default="reactive", choices=["reactive", "static"])
    ap.add_argument("--seeds", nargs="+", default=["0-7"], help="seeds and ranges (0-7)")
    ap.add_argument("--busy", type=int, default=0, metavar="N", help="CPU burners during the build")
    ap.add_argument("--ray", action="store_true", help="build through Ray")
    ap.add_argument("--workers", type=int, default=None, help="Ray CPUs (default: every core)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="flowtest-bench-pools-") as tmp:
        os.environ["FLOWTEST_CACHE_DIR"] = tmp
        from flowtest_env.random_grid import build_pool

        burners = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(args.busy)]
        try:
            t, c = time.perf_counter(), time.process_time()
            pool = build_pool(
                args.size, args.family, args.n, seed_list(args.seeds), args.kind,
                parallel="ray" if args.ray else None, workers=args.workers, progress=True,
            )
            wall, cpu = time.perf_counter() - t, time.process_time() - c
        finally:
            for p in burners:
                p.kill()
                p.wait()
        statuses: dict[str, int] = {}
        for art in pool:
            s = art.summary
            key = s["status"] + (f" ({s['stopped_by']})" if s.get("stopped_by") else "")
            statuses[key] = statuses.get(key, 0) + 1
        print(json.dumps({
            "pool": f"{args.size}x{args.size} {args.family}{args.n} {args.kind}",
            "tests": len(pool),
            "statuses": statuses,
            "wall_seconds": round(wall, 1),
            "cpu_seconds_this_process": round(cpu, 1),
            "busy": args.busy,
            "dispatch": "ray" if args.ray else "in-process",
            "digest": pool_digest(Path(tmp)),
        }))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
