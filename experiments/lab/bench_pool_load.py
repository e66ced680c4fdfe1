"""Time loading shipped standard-pool tests and compiling them into one vector env.

Usage::

    .venv/bin/python -m experiments.lab.bench_pool_load                           # every shipped test
    .venv/bin/python -m experiments.lab.bench_pool_load --pools reachability1/5x5-v1 --count 10000
    .venv/bin/python -m experiments.lab.bench_pool_load --check full --count 200  # the full re-check
    .venv/bin/python -m experiments.lab.bench_pool_load --pools reachability1/5x5-v1 safety2/5x5/fuel-v1 --count 10000 --cycle
    .venv/bin/python -m experiments.lab.bench_pool_load --count 2000 --workers 1                # the load in this process only

It loads the shipped records of the given standard pools (every split, train first, up to
``--count`` tests in all) with :func:`flowtest_env.standard_pools.load_standard_pool`
(``--check certificate``, the default, or ``full``; ``--workers``: processes that load, by
default two for a split of 1,000 tests or more where two cores are free), then builds one
:class:`flowtest_env.vector.PoolVectorEnv` holding every test once (``assignment="fixed"``)
and resets it (``--cycle``: where fewer tests are shipped than ``--count``, the shipped ones
are loaded again, each time checked again, until ``--count``; ``rounds`` says how many
times). It prints one JSON object: tests, seconds to read and check the records
(``load_s``), to compile the env (``compile_s``), the total, per test, and the process's
CPU seconds, in all and per phase (this process's), the CPU seconds of the forked helpers
that loaded and compiled beside it (``helpers_cpu_s``; on a loaded machine the wall time
includes waiting for a core), and the machine's one-minute load average before and after
(``load_average``).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

from flowtest_env.standard_pools import STANDARD_POOLS, load_standard_pool, standard_pool

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments.lab.bench_pool_load", description=__doc__.split("\n\n")[0])
    ap.add_argument("--pools", nargs="+", default=list(STANDARD_POOLS), help="standard pool ids (default: all)")
    ap.add_argument("--count", type=int, default=None, help="at most this many tests in all (default: every shipped one)")
    ap.add_argument("--check", choices=("certificate", "full"), default="certificate")
    ap.add_argument("--cycle", action="store_true", help="fewer shipped than --count: load them again until --count (each load checks again)")
    ap.add_argument("--workers", type=int, default=None, help="processes that load a split (default: two from 1,000 tests where two cores are free)")
    args = ap.parse_args(argv)
    from flowtest_env.vector import PoolVectorEnv  # after parsing: --help stays fast

    load_before = os.getloadavg()[0]
    children = os.times()
    wall, cpu = time.perf_counter(), time.process_time()
    tests: list[Any] = []
    per_pool: dict[str, int] = {}
    rounds = 0
    while rounds == 0 or (args.cycle and args.count is not None and 0 < len(tests) < args.count):
        rounds += 1
        for pid in args.pools:
            pool = standard_pool(pid)
            for split in ("train", "validation", "test"):
                left = None if args.count is None else args.count - len(tests)
                have = pool.shipped(split)
                take = have if left is None else min(have, left)
                if take > 0:
                    tests += load_standard_pool(pool.id, split, take, check=args.check, progress=False, workers=args.workers)
                    per_pool[pool.id] = per_pool.get(pool.id, 0) + take
    load_s, load_cpu = time.perf_counter() - wall, time.process_time() - cpu
    if not tests:
        print(json.dumps({"tests": 0, "note": "no shipped tests in these pools"}))
        return 1
    t, c = time.perf_counter(), time.process_time()
    env = PoolVectorEnv(len(tests), tests, assignment="fixed")
    env.reset(seed=0)
    compile_s, compile_cpu = time.perf_counter() - t, time.process_time() - c
    total = time.perf_counter() - wall
    print(
        json.dumps(
            {
                "tests": len(tests),
                "rounds": rounds,
                "per_pool": per_pool,
                "check": args.check,
                "load_s": round(load_s, 2),
                "compile_s": round(compile_s, 2),
                "total_s": round(total, 2),
                "ms_per_test": round(1000 * total / len(tests), 2),
                "cpu_s": round(time.process_time() - cpu, 2),
                "load_cpu_s": round(load_cpu, 2),
                "compile_cpu_s": round(compile_cpu, 2),
                "helpers_cpu_s": round(os.times().children_user + os.times().children_system - children.children_user - children.children_system, 2),
                "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
