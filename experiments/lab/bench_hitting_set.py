"""Benchmark: phase 2 of MILP-static by the implicit hitting set (synthesis.routing.backends.hitting_set)
alone, on the random grid study's static instances, in deterministic figures.

Usage::

    nice -n 10 .venv/bin/python -m experiments.lab.bench_hitting_set --size 5 --family reaction:4 \
        --instances 0 1 2 [--flow 1] [--work 60]

Each instance (the study's draw, :mod:`experiments.lab.random_grid_study`, environment ``static``)
gets the routing model ``auto`` builds; the hitting set then solves the fewest cuts at flow
``--flow`` from no incumbent and no lower bound, under ``--work`` deterministic seconds of its
CP-SAT master. Printed per instance: the free groups, the answer (cost = cut edges of G) and
whether it is proven, the rounds, the rows, the master's deterministic seconds and CPU seconds
(the child's), the separation's seconds, and the wall seconds. The deterministic seconds and the
rounds are the same on every machine; the seconds are not (say the load average with them).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace

from synthesis.graphs.consistency import check_consistency
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_grid import first_consistent, random_problem
from synthesis.routing.backends import hitting_set
from synthesis.routing.backends.separator import CoverSeparator
from synthesis.routing.model import build_model


def run(size: int, family: str, n: int, instance: int, flow: int, work: float) -> str:
    """One instance as a table row."""
    attempt, _, _ = first_consistent(size, family, n, instance)
    problem = random_problem(size, family, n, instance, attempt, "static")
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    rm = build_model(products, options, {}, check_consistency(products))
    me = replace(rm.edges, has_var=rm.edges.has_var & ~rm.reductions.fixed_open)
    sep = CoverSeparator(products, options, rm.groups, me, {})
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    r = hitting_set.fewest_cuts(sep, flow, None, hitting_set.HittingSetBudget(rounds=hitting_set.IHS_ROUNDS, work=work))
    wall = time.perf_counter() - t0
    answer = "empty" if r.empty else ("-" if r.cut is None else f"{r.cost:.0f}")
    return (
        f"| {instance} | {sep.n_col} | {answer} | {'yes' if r.proven else 'no'} | {r.bound:.0f} | {r.rounds} | "
        f"{r.rows.get('cover', 0)} / {r.rows.get('flow', 0)} | {r.work:.2f} | {r.master_cpu_seconds:.1f} | "
        f"{r.separation_seconds:.1f} | {wall:.1f} | {load:.1f} |"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=5)
    ap.add_argument("--family", default="reaction:4", help="FAMILY:N as in the study (default reaction:4, |AP| = 7)")
    ap.add_argument("--instances", type=int, nargs="+", default=list(range(20)))
    ap.add_argument("--flow", type=int, default=1, help="the flow level (default 1)")
    ap.add_argument("--work", type=float, default=60.0, help="the master's deterministic seconds (default 60)")
    args = ap.parse_args(argv)
    family, n = args.family.split(":")
    print(
        "| instance | free groups | fewest cuts | proven | bound | rounds | rows cover / flow | master det. s | master CPU s | separation s | wall s | load |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for instance in args.instances:
        print(run(args.size, family, int(n), instance, args.flow, args.work), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
