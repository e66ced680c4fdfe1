"""Benchmark: CP-SAT's searches for phase 1 (maximum flow) of the routing model, one problem.

Usage::

    nice -n 10 .venv/bin/python -m experiments.lab.bench_cpsat_search mars-exploration [--seeds 0 1 2 3]
        [--work-limit 60] [--searches default max-flow]

Builds the routing model :func:`synthesis.routing.model.build_model` gives the problem (with
the feasibility flows of its required entry nodes, as the first solve of
:func:`synthesis.routing.solve.solve_routing` has them) and, in one CP-SAT child
(:class:`synthesis.routing.backends.cpsat.CpSatSession`), asks for a test at the heuristic's flow upper
bound (a feasibility solve, ``reach``) from the heuristic's answer as a hint, once per search
and random seed, each under ``--work-limit`` deterministic seconds: ``default`` is CP-SAT's
default search (with its LP relaxation), ``max-flow`` is
:data:`synthesis.routing.backends.cpsat.MAX_FLOW_SEARCH`. Prints one Markdown row per run: what it
found (``found``: a test at the bound; ``infeasible``: proven none; ``unknown``: the budget
ran out), the deterministic and CPU seconds it took. Deterministic seconds are the
load-independent figure; CPU seconds on a shared machine are upper bounds.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from synthesis.graphs.consistency import check_consistency
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.load import load_problem
from synthesis.problems.problem import build_graphs
from synthesis.routing.backends import cpsat
from synthesis.routing.model import build_model
from synthesis.routing.phases import (
    guess_solution,  # what solve_routing's first solve starts from
    trap_test,
)
from synthesis.routing.result import required_entries

SEARCHES = {"default": None, "max-flow": cpsat.MAX_FLOW_SEARCH}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("problem", help="a built-in name or a problem file")
    ap.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2, 3], help="CP-SAT random seeds (default 0-3)")
    ap.add_argument("--work-limit", type=float, default=60.0, help="deterministic seconds per run (default 60)")
    ap.add_argument("--searches", nargs="*", default=list(SEARCHES), choices=list(SEARCHES))
    args = ap.parse_args(argv)
    cpsat.require()
    problem = load_problem(args.problem)
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions())
    entries = required_entries(products, options)
    rm = build_model(products, options, entries, check_consistency(products))
    guess = rm.guess(products, traps=trap_test(products, rm.groups, entries))
    hint = guess_solution(products, rm, guess, options)
    cost = np.zeros(rm.n_col)
    cost[rm.cols.flow[rm.out_src]] = 1.0
    a = rm.model.matrix().tocsr()
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    print(f"{args.problem}: {rm.model.n_row} rows, heuristic flow {guess.flow}, flow upper bound {guess.upper_bound}; ortools {cpsat.ortools_version()}\n")
    print("| search | seed | outcome | deterministic s | CPU s |")
    print("|---|---|---|---|---|", flush=True)
    with cpsat.CpSatSession(cpsat.ModelArrays(a, row_lo, row_hi, col_lo, col_hi)) as session:
        for name in args.searches:
            for seed in args.seeds:
                ans = session.solve(
                    cost,
                    True,
                    hint,
                    seconds=None,
                    after_first=None,
                    work_limit=args.work_limit,
                    rel_gap=0.0,
                    random_seed=seed,
                    phase="phase 1 (maximum flow)",
                    search=SEARCHES[name],
                    reach=guess.upper_bound,
                )
                outcome = "found" if ans.x is not None else ans.status
                print(f"| {name} | {seed} | {outcome} | {ans.stats['deterministic_time']:.2f} | {ans.stats['cpu_seconds']:.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
