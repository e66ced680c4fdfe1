"""MILP-reactive without (some of) its feasibility flows: what the relaxations say, per phase.

Usage::

    nice -n 10 .venv/bin/python -m experiments.lab.bench_reactive_relaxation --family reaction:4 --instances 0 1 2 \
        --what phase1 lazy cover-rows [--size 5] [--time-limit 60] [--rounds 3]

On the large reactive models (5x5 reaction |AP| = 7: 41,000-43,700 rows, 75-80 % of the
columns in the feasibility flows c6-c8) this measures three ways of seeing the feasibility
flows from the side, each exact as a bound and none used by FlowTest's solve (see
docs/benchmarks.md, "Session 11 (issue 18): MILP-reactive on 5x5 reaction |AP| = 7"):

* ``phase1``: the routing heuristic's flow and its upper bound (the maximum flow with every
  cut group open), against the maximum flow of the relaxation without any feasibility flow
  (HiGHS, phase 1's model otherwise): a relaxation, so its optimum bounds the flow too.
* ``lazy``: phase 2 (fewest cuts at the flow ``F`` the heuristic proves, or ``--flow``) in
  rounds, each with the feasibility flows of the histories the earlier rounds' answers
  trapped (``mu`` and the flows integral, as phase 2 runs): each round's bound is a lower
  bound on the optimum, and a round whose answer traps no entry node has the optimum.
* ``cover-rows``: phase 2's LP relaxation with every feasibility flow, and rounds of
  no-trap rows over distinct cut columns: for a history ``q``, one of its entry nodes ``e``
  and a set ``W`` of ``G_sys`` nodes holding ``e`` and no target, every edge leaving ``W``
  being closable under ``q``, ``sum_{d in D(W)} d <= |D(W)| - 1`` with ``D(W)`` the distinct
  cut columns closing those edges (valid: an open path from ``e`` to ``Tgt_sys`` leaves ``W``
  over an open edge, whose column is 0). ``W`` is what ``e`` reaches over the edges whose
  column is below a threshold; the rows the LP violates are added and the LP re-solved.

One HiGHS thread, its fixed seed; CPU seconds of this process (HiGHS runs in it).
"""

from __future__ import annotations

import argparse
import time

import highspy
import numpy as np

from synthesis.graphs.consistency import check_consistency
from synthesis.graphs.products import Products, reachable
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_grid import first_consistent, random_problem
from synthesis.routing.model import RoutingModel, build_model
from synthesis.routing.options import MilpOptions
from synthesis.routing.phases import phase2_cost, trap_test
from synthesis.routing.result import blocked_of_edges, required_entries
from synthesis.routing.solver_control import quiet_highs
from synthesis.routing.traps import trapped_entries

from .bench_reactive_phase2 import phase2_highs

WHAT = ("phase1", "lazy", "cover-rows")
THRESHOLDS = (0.999, 0.75, 0.5, 0.25, 0.1, 0.01)


def _traps(products: Products, rm: RoutingModel, x: np.ndarray, required: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """The entry nodes (per history) that the cuts of solution ``x`` trap."""
    cut = rm.cut_of(x)
    return trapped_entries(products, blocked_of_edges(products, np.flatnonzero(cut[rm.groups.of_edge])), required)


def phase1(products: Products, options: MilpOptions, keep: np.ndarray, time_limit: float) -> str:
    """The heuristic's flow and bound against the relaxation's maximum flow."""
    required = required_entries(products, options)
    full = build_model(products, options, dict(required), keep)
    guess = full.guess(products, traps=trap_test(products, full.groups, dict(required)))
    rm = build_model(products, options, {}, keep)
    cost = np.zeros(rm.n_col)
    cost[rm.cols.flow[rm.out_src]] = 1.0
    h = quiet_highs(1, 0)
    h.setOptionValue("time_limit", time_limit)
    h.setOptionValue("mip_abs_gap", 1.0 - 1e-6)
    h.passModel(rm.model.to_highs(cost, maximize=True))
    c0 = time.process_time()
    h.run()
    info = h.getInfo()
    x = np.asarray(h.getSolution().col_value)
    return (
        f"heuristic flow {guess.flow}, bound {guess.upper_bound} | relaxation: max flow {info.objective_function_value:.0f} "
        f"({h.modelStatusToString(h.getModelStatus())}, {time.process_time() - c0:.1f} CPU s), its answer traps "
        f"{len(_traps(products, rm, x, required))} histories"
    )


def lazy(products: Products, options: MilpOptions, keep: np.ndarray, flow: int | None, time_limit: float, rounds: int) -> list[str]:
    """Phase 2 in rounds, with the feasibility flows of the histories trapped so far."""
    required = required_entries(products, options)
    if flow is None:
        full = build_model(products, options, dict(required), keep)
        guess = full.guess(products, traps=trap_test(products, full.groups, dict(required)))
        if guess.flow != guess.upper_bound:
            return [f"the heuristic does not settle the flow ({guess.flow} of at most {guess.upper_bound}): give --flow"]
        flow = guess.flow
    entries: dict[int, np.ndarray] = {}
    lines = []
    for rnd in range(1, rounds + 1):
        rm = build_model(products, options, dict(entries), keep)
        h = phase2_highs(rm, phase2_cost(rm, options), flow, "binary-flows")
        h.setOptionValue("time_limit", time_limit)
        c0 = time.process_time()
        h.run()
        info = h.getInfo()
        x = np.asarray(h.getSolution().col_value)
        trapped = _traps(products, rm, x, required) if x.size == rm.n_col else {}
        lines.append(
            f"flow {flow}, round {rnd}: {len(entries)} histories' flows, {rm.model.n_row:,} rows: best "
            f"{info.objective_function_value:.0f}, bound {info.mip_dual_bound:.2f}, {info.mip_node_count:,} nodes, "
            f"{time.process_time() - c0:.1f} CPU s, {h.modelStatusToString(h.getModelStatus())}; traps {len(trapped)} histories"
        )
        if not trapped:
            break
        for q in trapped:
            entries[q] = required[q]
    return lines


def cover_rows(products: Products, options: MilpOptions, keep: np.ndarray, flow: int, rounds: int) -> list[str]:
    """Phase 2's LP with every feasibility flow, then rounds of violated no-trap rows."""
    required = required_entries(products, options)
    rm = build_model(products, options, dict(required), keep)
    h = phase2_highs(rm, phase2_cost(rm, options), flow, "continuous")
    cont = np.arange(rm.n_col, dtype=np.int32)
    h.changeColsIntegrality(cont.size, cont, np.full(cont.size, highspy.HighsVarType.kContinuous))
    n, targets = products.system.n_nodes, products.system_target
    seen: set[tuple[int, ...]] = set()
    lines = []
    c0 = time.process_time()
    for rnd in range(rounds):
        h.run()
        x = np.asarray(h.getSolution().col_value)
        added = 0
        for fl in rm.cols.feasibility:
            closable = fl.dcol >= 0
            d = np.where(closable, x[np.maximum(fl.dcol, 0)], 0.0)
            for threshold in THRESHOLDS:
                open_ = ~closable | (d < threshold)
                for e in fl.supply_nodes:
                    start = np.zeros(n, dtype=bool)
                    start[e] = True
                    w = reachable(n, fl.src[open_], fl.dst[open_], start)
                    if np.any(w & targets):
                        continue
                    cols = np.unique(fl.dcol[w[fl.src] & ~w[fl.dst]])
                    key = tuple(int(c) for c in cols)
                    if key in seen or float(np.sum(1.0 - x[cols])) >= 1.0 - 1e-6:
                        continue
                    seen.add(key)
                    h.addRow(-highspy.kHighsInf, cols.size - 1.0, cols.size, cols.astype(np.int32), np.ones(cols.size))
                    added += 1
        lines.append(
            f"flow {flow}, LP round {rnd}: {h.getInfo().objective_function_value:.3f}, violated no-trap rows added {added}, "
            f"{time.process_time() - c0:.1f} CPU s"
        )
        if not added:
            break
    return lines


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=5)
    ap.add_argument("--family", required=True, metavar="FAMILY:N", help="a study cell, e.g. reaction:4 (|AP| = 7)")
    ap.add_argument("--instances", type=int, nargs="+", required=True)
    ap.add_argument("--what", nargs="+", choices=WHAT, default=list(WHAT))
    ap.add_argument("--flow", type=int, default=None, help="phase 2's flow level (default: the heuristic's, where it is proven)")
    ap.add_argument("--time-limit", type=float, default=60.0, help="wall seconds per HiGHS run")
    ap.add_argument("--rounds", type=int, default=3, help="most rounds (lazy, cover-rows)")
    args = ap.parse_args(argv)
    family, _, n = args.family.partition(":")
    for instance in args.instances:
        attempt, _, _ = first_consistent(args.size, family, int(n or 1), instance)
        problem = random_problem(args.size, family, int(n or 1), instance, attempt, "reactive")
        _, products = build_graphs(problem)
        options = milp_options(problem, SynthesisOptions())
        keep = check_consistency(products)
        name = f"{family}:{n} #{instance}"
        if "phase1" in args.what:
            print(f"{name} phase1: {phase1(products, options, keep, args.time_limit)}", flush=True)
        if "lazy" in args.what:
            for line in lazy(products, options, keep, args.flow, args.time_limit, args.rounds):
                print(f"{name} lazy: {line}", flush=True)
        if "cover-rows" in args.what:
            flow = args.flow
            if flow is None:
                rm = build_model(products, options, dict(required_entries(products, options)), keep)
                flow = rm.guess(products).upper_bound
            for line in cover_rows(products, options, keep, flow, args.rounds):
                print(f"{name} cover-rows: {line}", flush=True)


if __name__ == "__main__":
    main()
