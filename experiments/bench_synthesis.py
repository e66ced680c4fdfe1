"""Benchmark: graph construction and solve time, model sizes, for the built-in problems.

Usage::

    .venv/bin/python -m experiments.bench_synthesis [NAME ...] [--repeat N] [--time-limit S]

Prints a Markdown table (the one in docs/benchmarks.md). Each problem is synthesized
``--repeat`` times in this process; the table gives the fastest run's times.
"""

from __future__ import annotations

import argparse
import sys
import time

from synthesis.artifacts.summary import summary_of
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.load import load_problem

DEFAULT = ("example1", "small-reactive", "beaver-rescue", "motion-primitives", "refueling", "mars-exploration")


def bench(name: str, repeat: int, time_limit: float | None) -> dict:
    """Synthesize ``name`` ``repeat`` times; the fastest run's figures."""
    best: dict | None = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        test = synthesize(load_problem(name), SynthesisOptions(time_limit=time_limit))
        total = time.perf_counter() - t0
        s = summary_of(test)
        row = {
            "problem": name,
            "kind": s["environment"],
            "status": s["status"],
            "flow": s["flow"],
            "n_cuts": s["n_cuts"],
            "ts": f"{s['stats']['transition_system']['states']}/{s['stats']['transition_system']['transitions']}",
            "bpi": s["stats"]["automaton"]["states"],
            "graph": f"{s['stats']['graph']['nodes']}/{s['stats']['graph']['edges']}",
            "model": f"{s['stats']['binary_vars']}/{s['stats']['continuous_vars']}/{s['stats']['constraints']}",
            "graph_s": s["stats"]["graph_seconds"],
            "solve_s": s["stats"]["solve_seconds"],
            "total_s": total,
        }
        if best is None or row["total_s"] < best["total_s"]:
            best = row
    assert best is not None
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=list(DEFAULT), choices=sorted(BUILTINS) + [[]], metavar="NAME")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--time-limit", type=float, default=None)
    args = ap.parse_args(argv)
    print("| problem | kind | status | flow | cuts | T states/moves | B_pi | G nodes/edges | MILP bin/cont/rows | graphs s | solve s | total s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.names or DEFAULT:
        r = bench(name, args.repeat, args.time_limit)
        print(
            f"| {r['problem']} | {r['kind']} | {r['status']} | {r['flow']} | {r['n_cuts']} | {r['ts']} | {r['bpi']} "
            f"| {r['graph']} | {r['model']} | {r['graph_s']:.4f} | {r['solve_s']:.2f} | {r['total_s']:.2f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
