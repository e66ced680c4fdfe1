"""Benchmark: what offering HiGHS starts costs or saves, with FlowTest's answer checks on.

Usage::

    .venv/bin/python -m experiments.lab.bench_starts [NAME ...] [--repeat N] [--time-limit S]

For each built-in problem, the routing MILP is solved with starts offered (the default:
the heuristic's answer in phase 1, the phase-1 answer in phase 2, each checked against
the model first, and every answer HiGHS returns checked and re-solved without the start
when it disagrees with HiGHS's report) and without any start. Prints a Markdown table
(docs/benchmarks.md) with the solve time (fastest of ``--repeat`` runs), status, flow and
cuts of each, and the installed highspy version.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.load import load_problem
from synthesis.problems.problem import build_graphs
from synthesis.routing.solve import solve_routing
from synthesis.routing.solver_control import solver_version

DEFAULT = ("example1", "small-reactive", "beaver-rescue", "motion-primitives", "patrolling", "refueling")


def bench(name: str, offer_starts: bool, repeat: int, time_limit: float | None) -> tuple[float, str, int, int]:
    """(fastest solve seconds, status, flow, cut edges) of the routing MILP of ``name``."""
    problem = load_problem(name)
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions(time_limit=time_limit)), offer_starts=offer_starts)
    best = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = solve_routing(products, replace(options))
        row = (time.perf_counter() - t0, r.status, r.flow, int(r.cut_edges.size))
        if best is None or row[0] < best[0]:
            best = row
    assert best is not None
    return best


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=list(DEFAULT), metavar="NAME")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--time-limit", type=float, default=None)
    args = ap.parse_args(argv)
    print(f"highspy {solver_version()}\n")
    print("| problem | with starts: s | status, flow, cuts | without starts: s | status, flow, cuts |")
    print("|---|---|---|---|---|")
    for name in args.names or DEFAULT:
        a = bench(name, True, args.repeat, args.time_limit)
        b = bench(name, False, args.repeat, args.time_limit)
        print(f"| {name} | {a[0]:.2f} | {a[1]}, {a[2]}, {a[3]} | {b[0]:.2f} | {b[1]}, {b[2]}, {b[3]} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
