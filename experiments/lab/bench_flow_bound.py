"""Benchmark: the walls' flow bound of MILP-static (:mod:`synthesis.routing.bounds.flow_bound`) on
random grids, and what it changes in a solve.

Usage::

    .venv/bin/python -m experiments.lab.bench_flow_bound --sizes 10 --instances 5
    nice -n 10 .venv/bin/python -m experiments.lab.bench_flow_bound --sizes 10 --instances 3 \\
        --families reachability:1 reachability:2 --solve --backend cpsat --work-limit 20

For each MILP-static instance (the study's seeded instances, ``first_consistent``) it prints
the model's rows, the routing heuristic's flow, its upper bound (maximum flow with every group
open) and the walls' bound; a summary counts the instances where the walls' bound is lower
and where it equals the heuristic's flow (phase 1 then needs no search). With ``--solve`` it
also solves each instance with the bound and without (``MilpOptions.flow_bound``), on
``--backend`` under the budget given (``--work-limit``: CP-SAT's deterministic seconds per
phase, ``--node-limit``: HiGHS's nodes, both load-independent; ``--time-limit``: wall
seconds), checks every answer as ``synthesize`` does (bypass flow 0, the flow its
restrictions let through), and prints status, flow, cuts and CPU seconds (this process's
and the CP-SAT children's).
"""

from __future__ import annotations

import argparse
import resource
import time
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

from synthesis.checks.verify import check_test, restricted_edges, routed_flow
from synthesis.graphs.consistency import check_consistency
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import Problem, build_graphs
from synthesis.problems.random_grid import first_consistent, paper_ap
from synthesis.routing.backends import cpsat
from synthesis.routing.model import build_model
from synthesis.routing.options import BACKENDS
from synthesis.routing.restrictions import strategy_from_routing
from synthesis.routing.solve import solve_routing

DEFAULT_FAMILIES = ("reachability:1", "reachability:2", "reachability:3", "reaction:2", "reaction:3", "safety:2")


def bounds(problem: Problem) -> dict[str, Any]:
    """The model's rows, the heuristic's flow and upper bound, and the walls' bound."""
    _, products = build_graphs(problem)
    opts = milp_options(problem, SynthesisOptions())
    t0 = time.perf_counter()
    rm = build_model(products, opts, {}, check_consistency(products))
    seconds = time.perf_counter() - t0
    guess = rm.edges.guess(products, fixed_open=rm.reductions.fixed_open)
    walls = guess.upper_bound if rm.flow_bound is None else rm.flow_bound  # None: not below the heuristic's
    return {"rows": rm.model.n_row, "flow": guess.flow, "heuristic": guess.upper_bound, "walls": walls, "build_s": seconds}


def _cpu() -> float:
    child = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + child.ru_utime + child.ru_stime


def solve(problem: Problem, with_bound: bool, options: SynthesisOptions, **flags: Any) -> dict[str, Any]:
    """One checked routing solve of ``problem`` with or without the walls' bound (``flags``:
    more :class:`~synthesis.routing.model.MilpOptions` fields, such as ``cut_bound``)."""
    _, products = build_graphs(problem)
    opts = replace(milp_options(problem, options), flow_bound=with_bound, **flags)
    cpsat.close_idle_workers()
    cpu0 = _cpu()
    t0 = time.perf_counter()
    routing = solve_routing(products, opts)
    wall = time.perf_counter() - t0
    strategy = strategy_from_routing(products, routing, "instantaneous")
    flow = routing.flow if routing.status == "optimal" else routed_flow(products, restricted_edges(products, strategy))
    checks = check_test(products, strategy, flow)
    assert checks.bypass_flow == 0 and checks.ok, checks
    cpsat.close_idle_workers()  # reaped: its CPU seconds count in RUSAGE_CHILDREN
    return {
        "status": routing.status,
        "flow": flow,
        "cuts": int(routing.cut_edges.size),
        "wall_s": wall,
        "cpu_s": _cpu() - cpu0,
        "backend": routing.stats["backend"],
        "cut_bound": routing.stats.get("cut_bound"),
    }


def instance_arguments(doc: str, families: list[str], solve_help: str) -> argparse.ArgumentParser:
    """The command line of the bound benchmarks: which static random grids, and how to solve them."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10])
    ap.add_argument("--families", nargs="+", default=families, metavar="FAMILY:N")
    ap.add_argument("--instances", type=int, default=5, help="seeds 0..N-1")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="these seeds instead of 0..N-1")
    ap.add_argument("--solve", action="store_true", help=solve_help)
    ap.add_argument("--backend", default="auto", choices=BACKENDS)
    ap.add_argument("--work-limit", type=float, default=None, help="CP-SAT deterministic seconds per phase")
    ap.add_argument("--node-limit", type=int, default=None, help="HiGHS nodes per run")
    ap.add_argument("--time-limit", type=float, default=None, help="wall seconds per solve")
    return ap


def print_head(columns: str, solved: str) -> None:
    """Print a Markdown table's head: ``columns``, then ``solved`` (the columns of ``--solve``, or empty)."""
    head = columns + solved
    print(head)
    print("|" + "---|" * (head.count("|") - 1))


def options_of(args: argparse.Namespace) -> SynthesisOptions:
    """The solve options the command line asks for."""
    return SynthesisOptions(backend=args.backend, work_limit=args.work_limit, node_limit=args.node_limit, time_limit=args.time_limit)


def static_instances(args: argparse.Namespace) -> Iterator[tuple[str, Problem]]:
    """(name, MILP-static problem) of every size, family and seed the command line asks for."""
    for size in args.sizes:
        for spec in args.families:
            family, n = spec.split(":")
            for seed in args.seeds if args.seeds is not None else range(args.instances):
                _, problem, _ = first_consistent(size, family, int(n), seed, "static")
                yield f"{size}x{size} {family} |AP| {paper_ap(family, int(n))} s{seed}", problem


def main(argv: list[str] | None = None) -> None:
    args = instance_arguments(__doc__, list(DEFAULT_FAMILIES), "also solve with and without the bound").parse_args(argv)
    options = options_of(args)
    print_head(
        "| instance | rows | heuristic flow | heuristic bound | walls' bound |",
        " with bound: status, flow, cuts | CPU s | without: status, flow, cuts | CPU s |" if args.solve else "",
    )
    lower = settled = total = 0
    for name, problem in static_instances(args):
        b = bounds(problem)
        total += 1
        lower += b["walls"] < b["heuristic"]
        settled += b["walls"] == b["flow"] < b["heuristic"]
        row = f"| {name} | {b['rows']} | {b['flow']} | {b['heuristic']} | {b['walls']} |"
        if args.solve:
            for flag in (True, False):
                r = solve(problem, flag, options)
                row += f" {r['status']}, {r['flow']}, {r['cuts']} ({r['backend']}) | {r['cpu_s']:.1f} |"
        print(row, flush=True)
    print(f"\n{total} instances: walls' bound below the heuristic's on {lower}, equal to the heuristic's flow (phase 1 settled) on {settled}")


if __name__ == "__main__":
    main()
