"""MILP-reactive's phase 2 (fewest cuts at the maximum flow) alone, on HiGHS, per variant.

Usage::

    nice -n 10 .venv/bin/python -m experiments.lab.bench_reactive_phase2 --family reachability:3 --instances 1 3 5 \
        [--size 5] [--variants continuous binary binary-flows no-feasibility] [--time-limit 120 | --node-limit N] \
        [--flow-rows edge|cut]

Builds each study instance's MILP-reactive model as :func:`synthesis.pipeline.synthesize`
does (the feasibility flows of every history at once, the model's reductions), settles the
flow level ``F`` (the routing heuristic's flow where it attains its upper bound, else a HiGHS
phase 1), and solves phase 2 from scratch (no start: the variants are compared on their
search alone) for each variant:

* ``continuous``: the model as before session 10 (``mu`` and the flows continuous);
* ``binary``: ``mu`` binary, the flows continuous (measured, not used);
* ``binary-flows``: ``mu`` and the flows integral (``MilpOptions.integral_phase2``, what
  phase 2 does now);
* ``no-feasibility``: ``binary-flows`` without the feasibility flows (c6-c8), a relaxation:
  its optimum is a lower bound, and where its cut set traps no entry node it is the optimum.

``--flow-rows cut`` writes the feasibility flows' closing rows per cut column
(``MilpOptions.flow_rows``; the default here is method.md's, per flow edge).

Printed per run: the root LP bound, the objective and bound reached, HiGHS's nodes, CPU
seconds, status. One thread, HiGHS's fixed random seed.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import highspy
import numpy as np

from synthesis.graphs.consistency import check_consistency
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_grid import first_consistent, random_problem
from synthesis.routing.model import RoutingModel, build_model
from synthesis.routing.phases import phase2_cost
from synthesis.routing.result import required_entries
from synthesis.routing.solve import solve_routing
from synthesis.routing.solver_control import quiet_highs

VARIANTS = ("continuous", "binary", "binary-flows", "no-feasibility")


def phase2_highs(rm: RoutingModel, cost: np.ndarray, flow: int, variant: str) -> highspy.Highs:
    """A fresh HiGHS holding phase 2 of ``rm`` at ``flow`` in ``variant``."""
    h = quiet_highs(1, 0)
    h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)
    lp = rm.model.to_highs(cost, maximize=False)
    h.passModel(lp)
    out = rm.cols.flow[rm.out_src].astype(np.int32)
    h.addRow(flow - 0.5, highspy.kHighsInf, out.size, out, np.ones(out.size))
    integral = []
    if variant in ("binary", "binary-flows", "no-feasibility"):
        integral.append(rm.cols.reach[rm.cols.reach >= 0])
    if variant in ("binary-flows", "no-feasibility"):
        integral.append(rm.cols.flow)
    if integral:
        cols = np.concatenate(integral).astype(np.int32)
        h.changeColsIntegrality(cols.size, cols, np.full(cols.size, highspy.HighsVarType.kInteger))
    if variant == "no-feasibility":
        for fl in rm.cols.feasibility:  # free the flow columns: their rows then always hold
            c = fl.cols.astype(np.int32)
            h.changeColsBounds(c.size, c, np.zeros(c.size), np.full(c.size, highspy.kHighsInf))
            h.changeColsCost(c.size, c, np.zeros(c.size))
        _drop_feasibility_rows(h, rm)
    return h


def _drop_feasibility_rows(h: highspy.Highs, rm: RoutingModel) -> None:
    """Delete the rows that hold the feasibility flows' columns (c6-c8)."""
    a = rm.model.matrix().tocsc()
    cols = np.concatenate([fl.cols for fl in rm.cols.feasibility]) if rm.cols.feasibility else np.zeros(0, dtype=np.int64)
    rows = np.unique(a[:, cols].nonzero()[0]).astype(np.int32)
    if rows.size:
        h.deleteRows(rows.size, rows)


def root_bound(h: highspy.Highs) -> float:
    """The LP relaxation's optimum of the model ``h`` holds."""
    lp = h.getLp()
    lp.integrality_ = []
    r = quiet_highs(1, 0)
    r.passModel(lp)
    r.run()
    return float(r.getInfo().objective_function_value)


def run(
    size: int,
    family: str,
    n: int,
    instance: int,
    variants: list[str],
    time_limit: float | None,
    node_limit: int | None,
    flow_rows: str = "edge",
) -> None:
    attempt, _, _ = first_consistent(size, family, n, instance)
    problem = random_problem(size, family, n, instance, attempt, "reactive")
    _, products = build_graphs(problem)
    options = replace(milp_options(problem, SynthesisOptions()), flow_rows=flow_rows)
    required = required_entries(products, options)
    rm = build_model(products, options, dict(required), check_consistency(products))
    guess = rm.guess(products)
    if guess.flow == guess.upper_bound:
        flow, how = guess.flow, "heuristic"
    else:
        first = solve_routing(products, replace(options, backend="highs", time_limit=time_limit or 600.0, after_first=0.01))
        flow, how = first.flow, "phase 1"
    cost = phase2_cost(rm, options)
    for variant in variants:
        h = phase2_highs(rm, cost, flow, variant)
        root = root_bound(h)
        if time_limit is not None:
            h.setOptionValue("time_limit", float(time_limit))
        if node_limit is not None:
            h.setOptionValue("mip_max_nodes", int(node_limit))
        c0, t0 = time.process_time(), time.perf_counter()
        h.run()
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        info = h.getInfo()
        print(
            f"| {family}:{n} #{instance} | {rm.model.n_row:,} | {flow} ({how}) | {variant} | {root:.2f} | "
            f"{info.objective_function_value:.0f} | {info.mip_dual_bound:.2f} | {info.mip_node_count:,} | "
            f"{cpu:.1f} | {wall:.1f} | {h.modelStatusToString(h.getModelStatus())} |",
            flush=True,
        )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=5)
    ap.add_argument("--family", required=True, metavar="FAMILY:N", help="a study cell, e.g. reachability:3 (|AP| = 4)")
    ap.add_argument("--instances", type=int, nargs="+", required=True)
    ap.add_argument("--variants", nargs="+", choices=VARIANTS, default=["continuous", "binary-flows"])
    ap.add_argument("--time-limit", type=float, default=None, help="wall seconds per run")
    ap.add_argument("--node-limit", type=int, default=None, help="HiGHS nodes per run (deterministic)")
    ap.add_argument(
        "--flow-rows",
        choices=("edge", "cut"),
        default="edge",
        help="the feasibility flows' closing rows per flow edge or per cut column (MilpOptions.flow_rows)",
    )
    args = ap.parse_args(argv)
    family, _, n = args.family.partition(":")
    print("| instance | rows | F (settled by) | variant | root LP | best | bound | nodes | CPU s | wall s | status |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for instance in args.instances:
        run(args.size, family, int(n or 1), instance, args.variants, args.time_limit, args.node_limit, args.flow_rows)


if __name__ == "__main__":
    main()
