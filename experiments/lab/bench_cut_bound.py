"""Benchmark: the walls' cut bound of MILP-static (:mod:`synthesis.routing.bounds.cut_bound`) on random
grids, and what it changes in a solve.

Usage::

    .venv/bin/python -m experiments.lab.bench_cut_bound --sizes 10 --families reachability:1 --instances 5
    nice -n 10 .venv/bin/python -m experiments.lab.bench_cut_bound --sizes 10 --families reachability:1 \\
        --instances 5 --solve --backend cpsat --work-limit 20

For each MILP-static instance (the study's seeded instances, ``first_consistent``) it prints the
model's rows, the routing heuristic's flow, the walls' flow bound, and at each flow level up to
it the cut bound, the cost of its cheapest checked candidate (``-``: none passed the checks)
and the seconds both took. With ``--solve`` it also solves each instance with the cut bound and
without (``MilpOptions.cut_bound``; the flow bound on in both) on ``--backend`` under the budget
given (``--work-limit``: CP-SAT's deterministic seconds per phase, ``--node-limit``: HiGHS's
nodes, both load-independent; ``--time-limit``: wall seconds), checks every answer as
``synthesize`` does, and prints status, flow, cuts, CPU seconds (this process's and the CP-SAT
children's) and whether the cut bound proved phase 2; a summary counts the proven answers
where the bound equals the optimum (tight).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import Problem, build_graphs
from synthesis.routing.certificates import cut_proof
from synthesis.routing.model import build_model
from synthesis.routing.phases import phase2_cost

from .bench_flow_bound import instance_arguments, options_of, print_head, solve, static_instances


def cut_bounds(problem: Problem) -> dict[str, Any]:
    """The model's rows, the heuristic's flow, the walls' flow bound, and per flow level up to it
    ``(cut bound, cheapest checked candidate or None)`` with the seconds they took."""
    _, products = build_graphs(problem)
    opts = milp_options(problem, SynthesisOptions())
    rm = build_model(products, opts, {}, check_consistency(products))
    guess = rm.guess(products)
    top = guess.upper_bound
    cost = phase2_cost(rm, opts)
    levels: dict[int, tuple[float, float | None]] = {}
    t0 = time.process_time()
    for level in range(1, top + 1):
        proof = cut_proof(products, rm, opts, {}, level)
        if proof is None:
            continue
        levels[level] = (proof.bound, None if proof.x is None else float(cost @ proof.x))
    return {"rows": rm.model.n_row, "flow": guess.flow, "walls": top, "levels": levels, "cpu_s": time.process_time() - t0}


def _levels_text(levels: dict[int, tuple[float, float | None]]) -> str:
    if not levels:
        return "-"
    return "; ".join(f"F={f}: {b:g} / {'-' if c is None else f'{c:g}'}" if np.isfinite(b) else f"F={f}: none" for f, (b, c) in levels.items())


def main(argv: list[str] | None = None) -> None:
    families = ["reachability:1", "reachability:2", "reachability:3"]
    args = instance_arguments(__doc__, families, "also solve with and without the cut bound").parse_args(argv)
    options = options_of(args)
    print_head(
        "| instance | rows | heuristic flow | walls' flow bound | per level: cut bound / candidate | s |",
        " with: status, flow, cuts (proof) | CPU s | without: status, flow, cuts | CPU s |" if args.solve else "",
    )
    proven = tight = proven_with = proven_without = total = 0
    for name, problem in static_instances(args):
        b = cut_bounds(problem)
        total += 1
        row = f"| {name} | {b['rows']} | {b['flow']} | {b['walls']} | {_levels_text(b['levels'])} | {b['cpu_s']:.2f} |"
        if args.solve:
            try:
                with_cb = solve(problem, True, options, cut_bound=True)
                without = solve(problem, True, options, cut_bound=False)
            except InconsistentProblem as exc:
                print(f"{row} {exc.reason} | | | |", flush=True)
                continue
            cb = with_cb["cut_bound"] or {}
            mark = "cut bound" if cb.get("proven") else (f"bound {cb['bound']:g}" if cb else "no bound")
            row += f" {with_cb['status']}, {with_cb['flow']}, {with_cb['cuts']} ({mark}) | {with_cb['cpu_s']:.1f} |"
            row += f" {without['status']}, {without['flow']}, {without['cuts']} | {without['cpu_s']:.1f} |"
            proven_with += with_cb["status"] == "optimal"
            proven_without += without["status"] == "optimal"
            for r in (with_cb, without):
                if r["status"] == "optimal":
                    proven += 1
                    level = b["levels"].get(r["flow"])
                    tight += level is not None and level[0] == r["cuts"]
                    break
        print(row, flush=True)
    if args.solve:
        print(
            f"\n{total} instances: proven with the cut bound {proven_with}, without {proven_without}; "
            f"of the {proven} with a proven optimum, the cut bound equals it on {tight}"
        )


if __name__ == "__main__":
    main()
