"""Benchmark: phase 1 (the maximum flow) of the routing solve on CP-SAT, per random grid instance.

Usage::

    nice -n 10 .venv/bin/python -m experiments.lab.bench_phase1 --families reaction:4 --seeds 1 3 8 17 --work-limit 120
    nice -n 10 .venv/bin/python -m experiments.lab.bench_phase1 --builtins mars-exploration --families --work-limit 60

For each built-in named (``--builtins``, its own MILP) and each MILP-static instance of the
study (``first_consistent(size, family, n, seed, "static")``) it builds the routing model as :func:`synthesis.routing.solve.solve_routing`'s first
solve does and runs phase 1 alone (:func:`synthesis.routing.backends.cpsat_phases.phase1_cpsat`: the heuristic,
CP-SAT's default search for ``cpsat.PROOF_WORK``, then the level search ``_reach_level``) under
``--work-limit`` deterministic seconds, in one CP-SAT child. Prints one Markdown row per
instance: the model's rows, the heuristic's flow and upper bound, phase 1's outcome (``optimal``:
the maximum flow proven; ``feasible``: the budget ran out; ``unroutable``: flow 0 proven the
maximum, no test at all),
its flow, the deterministic seconds of each CP-SAT run in order and in all, and the wall
seconds. Deterministic seconds are the load-independent figure.
"""

from __future__ import annotations

import argparse
import time

from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, milp_options
from synthesis.problems.load import load_problem
from synthesis.problems.problem import Problem, build_graphs
from synthesis.problems.random_grid import first_consistent, paper_ap
from synthesis.routing.backends import cpsat
from synthesis.routing.backends.contract import Round
from synthesis.routing.backends.cpsat_phases import phase1_cpsat  # phase 1 as solve_routing runs it
from synthesis.routing.model import build_model
from synthesis.routing.phases import trap_test
from synthesis.routing.result import required_entries
from synthesis.routing.solver_control import Clock


def phase1(problem: Problem, name: str, work_limit: float) -> str:
    """One problem's Markdown row."""
    _, products = build_graphs(problem)
    options = milp_options(problem, SynthesisOptions(backend="cpsat", work_limit=work_limit))
    entries = required_entries(products, options)
    rm = build_model(products, options, entries, check_consistency(products))
    guess = rm.guess(products, traps=trap_test(products, rm.groups, entries))
    a = rm.model.matrix().tocsr()
    col_lo, col_hi, row_lo, row_hi = rm.model.bounds()
    t0 = time.perf_counter()
    runs: list[dict[str, float]] = []
    with cpsat.CpSatSession(cpsat.ModelArrays(a, row_lo, row_hi, col_lo, col_hi)) as session:
        real = session.solve

        def record(*args: object, **kwargs: object) -> cpsat.CpSatAnswer:
            answer = real(*args, **kwargs)  # type: ignore[arg-type]
            runs.append(answer.stats)
            return answer

        session.solve = record  # type: ignore[method-assign]
        try:
            first, _ = phase1_cpsat(session, Round(products, rm, options, entries, Clock(None, None)))
            outcome, flow = first.status, str(int(round(rm.flow_of(first.x))))
            if outcome == "optimal" and flow == "0":
                outcome = "unroutable"  # flow 0 proven the maximum: what synthesize reports
        except InconsistentProblem as err:
            outcome, flow = err.reason, "-"
    wall = time.perf_counter() - t0
    dets = [float(r["deterministic_time"]) for r in runs]
    return (
        f"| {name} | {rm.model.n_row} | {guess.flow}, {guess.upper_bound} | {outcome} | {flow} | "
        f"{', '.join(f'{d:.2f}' for d in dets)} | {sum(dets):.2f} | {wall:.1f} |"
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[5])
    ap.add_argument("--families", nargs="*", default=["reaction:3", "reaction:4"], metavar="FAMILY:N")
    ap.add_argument("--instances", type=int, default=20, help="seeds 0..N-1")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="these seeds instead of 0..N-1")
    ap.add_argument("--builtins", nargs="*", default=[], help="built-in problems to run first (any MILP)")
    ap.add_argument("--work-limit", type=float, default=120.0, help="deterministic seconds for phase 1 (default 120)")
    args = ap.parse_args(argv)
    cpsat.require()
    print("| instance | rows | heuristic: flow, bound | phase 1 | flow | deterministic s per CP-SAT run | deterministic s | wall s |")
    print("|---|---|---|---|---|---|---|---|")
    for builtin in args.builtins:
        print(phase1(load_problem(builtin), builtin, args.work_limit), flush=True)
    for size in args.sizes:
        for spec in args.families:
            family, n = spec.split(":")
            for seed in args.seeds if args.seeds is not None else range(args.instances):
                _, problem, _ = first_consistent(size, family, int(n), seed, "static")
                name = f"{size}x{size} {family} \\|AP\\| {paper_ap(family, int(n))} #{seed}"  # a Markdown cell
                print(phase1(problem, name, args.work_limit), flush=True)


if __name__ == "__main__":
    main()
