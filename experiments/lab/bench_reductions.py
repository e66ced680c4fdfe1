"""How many cut groups the reductions fix open, on the built-ins and on random grids.

Usage::

    .venv/bin/python -m experiments.lab.bench_reductions                    # built-ins, 5x5 and 10x10 cells
    .venv/bin/python -m experiments.lab.bench_reductions --builtins refueling --sizes 5 --instances 5
    .venv/bin/python -m experiments.lab.bench_reductions --solve patrolling maze1   # solve with and without

Builds each problem's routing model as :func:`synthesis.pipeline.synthesize` would (the
options of :func:`synthesis.pipeline.milp_options`, the feasibility flows a first round
starts with) and prints, per built-in and per random grid cell (MILP-static and
MILP-reactive, the study's seeded instances), the cut groups with a binary and how many
each rule of :mod:`synthesis.routing.bounds.reductions` fixes open, and the seconds the
reductions take. ``--solve NAME ...`` also synthesizes those built-ins with the
reductions on and off (deterministic budget: one thread, no wall clock) and prints the
answers and routing solve times, which must agree on flow and cuts.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np

from synthesis.graphs.consistency import check_consistency
from synthesis.graphs.products import Products
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.builtins import BUILTINS
from synthesis.problems.problem import Problem, build_graphs
from synthesis.problems.random_grid import PAPER_SPECS, first_consistent, paper_ap
from synthesis.routing.model import build_model
from synthesis.routing.options import MilpOptions
from synthesis.routing.result import required_entries
from synthesis.routing.solve import EAGER_FLOW_LIMIT, solve_routing

RULES = ("never_needed", "never_closed", "dominated")


def counts(problem: Problem) -> tuple[str, int, dict[str, int], float]:
    """``(mode, groups with a binary, groups fixed per rule, seconds of the reductions)``."""
    _, products = build_graphs(problem)
    opts = milp_options(problem, SynthesisOptions())
    entries = _first_entries(products, opts)
    keep = check_consistency(products)
    t0 = time.perf_counter()
    rm = build_model(products, opts, entries, keep)
    with_red = time.perf_counter() - t0
    t0 = time.perf_counter()
    build_model(products, replace(opts, reductions=False), entries, keep)
    without = time.perf_counter() - t0
    return opts.mode, int(rm.var_groups.size), rm.reductions.counts(), max(with_red - without, 0.0)


def _first_entries(products: Products, opts: MilpOptions) -> dict[int, np.ndarray]:
    """The feasibility flows the first round of :func:`solve_routing` starts with."""
    required = required_entries(products, opts)
    eager = len(required) * products.system.src.size <= EAGER_FLOW_LIMIT
    return dict(required) if eager else {}


def _row(cells: list[str], n_inst: int, rs: list[tuple[str, int, dict[str, int], float]]) -> str:
    groups = [r[1] for r in rs]
    per = {k: [r[2][k] for r in rs] for k in RULES}
    fired = sum(1 for r in rs if any(r[2].values()))
    secs = [r[3] for r in rs]
    parts = cells + [
        str(len(rs)),
        f"{np.mean(groups):.0f}" + (f" ({min(groups)}-{max(groups)})" if n_inst > 1 else ""),
    ]
    for k in RULES:
        total, gs = sum(per[k]), sum(groups)
        parts.append(f"{total} of {gs}" + (f" ({sum(1 for x in per[k] if x)} inst.)" if n_inst > 1 else ""))
    parts += [f"{fired}" if n_inst > 1 else ("yes" if fired else "no"), f"{np.mean(secs):.3f}, {max(secs):.3f}"]
    return "| " + " | ".join(parts) + " |"


HEAD = (
    "| {what} | MILP | instances | groups with a binary (mean{rng}) | never needed | never closed | dominated "
    "| instances with a fixed group | reductions s (mean, max) |"
)


def solve_both(name: str, node_limit: int | None) -> str:
    """Synthesize a built-in's routing with and without the reductions (deterministic budget)."""
    problem = BUILTINS[name]()
    _, products = build_graphs(problem)
    base = replace(milp_options(problem, SynthesisOptions()), threads=1, node_limit=node_limit)
    out = []
    for on in (True, False):
        t0 = time.perf_counter()
        try:
            r = solve_routing(products, replace(base, reductions=on))
            out.append(f"{r.status} F={r.flow} cuts={r.cut_edges.size} {time.perf_counter() - t0:.2f}s")
        except InconsistentProblem as exc:
            out.append(f"{exc.reason} {time.perf_counter() - t0:.2f}s")
    return f"| {name} | {out[0]} | {out[1]} |"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments.lab.bench_reductions", description=__doc__.split("\n")[0])
    ap.add_argument("--builtins", nargs="*", default=list(BUILTINS), help="built-in problems (default: all)")
    ap.add_argument("--sizes", nargs="*", type=int, default=[5, 10], help="random grid sizes (default 5 10)")
    ap.add_argument("--instances", type=int, default=20, help="seeded instances per random grid cell (default 20)")
    ap.add_argument("--solve", nargs="*", default=[], metavar="NAME", help="also solve these built-ins with and without")
    ap.add_argument("--node-limit", type=int, default=None, help="branch-and-bound nodes per HiGHS run in --solve")
    args = ap.parse_args(argv)
    if args.builtins:
        print(HEAD.format(what="built-in", rng=""))
        print("|---" * 9 + "|")
        for name in args.builtins:
            row = counts(BUILTINS[name]())
            print(_row([name, row[0]], 1, [row]), flush=True)
        print()
    if args.sizes and args.instances > 0:
        print(HEAD.format(what="spec, \\|AP\\|, grid", rng=", range"))
        print("|---" * 9 + "|")
        for size in args.sizes:
            for family, n in PAPER_SPECS:
                for kind in ("static", "reactive"):
                    rs = []
                    for seed in range(args.instances):
                        _, problem, _ = first_consistent(size, family, n, seed, kind=kind)
                        rs.append(counts(problem))
                    print(_row([f"{family}, {paper_ap(family, n)}, {size}x{size}", kind], args.instances, rs), flush=True)
        print()
    if args.solve:
        print("| built-in | with the reductions | without |")
        print("|---|---|---|")
        for name in args.solve:
            print(solve_both(name, args.node_limit), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
