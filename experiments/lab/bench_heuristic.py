"""How often the routing heuristic alone gives a first test, with and without the route seed.

Usage::

    .venv/bin/python -m experiments.lab.bench_heuristic                      # the study's reaction rows
    .venv/bin/python -m experiments.lab.bench_heuristic --cells reaction:3:10 reachability:3:20 --instances 20

For each random grid instance of the paper's study (MILP-static: walls tied across
histories), runs :func:`synthesis.routing.bounds.heuristic.guess_routing` on the routing
model's edges twice: the greedy growth alone, and with the place-simple route seed. A
first test (flow >= 1) from the heuristic means the MILP starts from a checked answer,
so a time-limited solve can never come back empty. Prints a Markdown table: instances
with a first test, instances where the heuristic reaches the flow upper bound (phase 1
proven without HiGHS), and the heuristic's time.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_grid import first_consistent, paper_ap
from synthesis.routing.edges import model_edges
from synthesis.routing.groups import cut_groups

DEFAULT_CELLS = ["reaction:2:5", "reaction:3:5", "reaction:4:5", "reaction:2:10", "reaction:3:10", "reaction:4:10", "reaction:4:20"]


def guesses(size: int, family: str, n: int, seed: int) -> tuple[tuple[int, int, float], tuple[int, int, float]]:
    """``(flow, upper bound, seconds)`` of the heuristic without and with the route seed."""
    _, problem, _ = first_consistent(size, family, n, seed, kind="static")
    _, products = build_graphs(problem)
    edges = model_edges(products, cut_groups(products, milp_options(problem, SynthesisOptions())))
    out = []
    for seeded in (False, True):
        t0 = time.perf_counter()
        r = edges.guess(products, route_seed=seeded)
        out.append((r.flow, r.upper_bound, time.perf_counter() - t0))
    return out[0], out[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments.lab.bench_heuristic", description=__doc__.split("\n")[0])
    ap.add_argument("--cells", nargs="*", default=DEFAULT_CELLS, metavar="FAMILY:N:SIZE", help="study cells (family, spec size n as in random_grid, grid size)")
    ap.add_argument("--instances", type=int, default=20, help="seeds 0..N-1 per cell (default 20)")
    args = ap.parse_args(argv)
    print(
        "| spec | \\|AP\\| | grid | first test: greedy alone | first test: with route seed "
        "| flow bound reached: alone / seeded | seeded heuristic s (mean, max) |"
    )
    print("|---|---|---|---|---|---|---|")
    for cell in args.cells:
        family, n_text, size_text = cell.split(":")
        n, size = int(n_text), int(size_text)
        rows = [guesses(size, family, n, seed) for seed in range(args.instances)]
        alone = sum(a[0] >= 1 for a, _ in rows)
        seeded = sum(b[0] >= 1 for _, b in rows)
        bound_a = sum(a[0] == a[1] for a, _ in rows)
        bound_b = sum(b[0] == b[1] for _, b in rows)
        secs = [b[2] for _, b in rows]
        k = args.instances
        print(
            f"| {family} | {paper_ap(family, n)} | {size}x{size} | {alone}/{k} | {seeded}/{k} | {bound_a} / {bound_b} "
            f"| {np.mean(secs):.2f}, {np.max(secs):.2f} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
