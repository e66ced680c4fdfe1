"""Benchmark of the dynamic test agent built-ins (issue 3's performance targets).

For each of ``maze1``, ``maze2`` and ``patrolling`` it runs the whole agent synthesis
(graphs, every MILP of the counterexample-guided loop, every game build and GR(1)
solve, closed-loop verification and routing checks) several times and reports the
median seconds of each part, then times GR(1) synthesis alone on the final game.
Targets: under 5 s end to end, under 0.5 s for GR(1).

Usage::

    python -m experiments.lab.bench_agent [--repeat 3] [--problems maze1 maze2 patrolling]

Prints a Markdown table on standard output.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence

from synthesis.pipeline import synthesize
from synthesis.problems.load import load_problem
from synthesis.test_agent.game import build_agent_game
from synthesis.test_agent.gr1.solver import solve as solve_gr1

PROBLEMS = ("maze1", "maze2", "patrolling")
END_TO_END_TARGET = 5.0
GR1_TARGET = 0.5


def bench(name: str, repeat: int) -> dict[str, float | int | str]:
    """Median timings of ``repeat`` full syntheses of built-in ``name``."""
    runs: list[dict[str, float]] = []
    wall: list[float] = []
    test = agent = None
    for _ in range(repeat):
        problem = load_problem(name)
        t0 = time.perf_counter()
        test = synthesize(problem)
        wall.append(time.perf_counter() - t0)
        agent = test.agent
        if agent is None or test.problem.agent is None:
            raise SystemExit(f"error: {name} is not a test-agent problem")
        runs.append(dict(agent.timings))
    assert test is not None and agent is not None and test.problem.agent is not None
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    game = build_agent_game(test.products, test.strategy, test.problem.agent)
    solo: list[float] = []
    for _ in range(max(repeat, 5)):
        t0 = time.perf_counter()
        solve_gr1(game.game)
        solo.append(time.perf_counter() - t0)
    return {
        "problem": name,
        "end_to_end": statistics.median(wall),
        "graphs": med["graphs"],
        "milp": med["milp"],
        "game": med["game"],
        "gr1_loop": med["gr1"],
        "verify": med["verify"],
        "gr1_final": statistics.median(solo),
        "iterations": len(agent.iterations),
        "counterexamples": agent.counterexamples,
        "positions": game.n_positions,
        "moves": game.game.n_edges,
        "g_nodes": test.products.virtual.n_nodes,
    }


def markdown(rows: Sequence[dict[str, float | int | str]]) -> str:
    """The table, one row per problem."""
    head = (
        "| problem | end to end (s) | graphs | MILP (all solves) | game build | GR(1) (all solves) | "
        "verify | GR(1) final game | MILP solves | counterexamples | G nodes | game positions | game moves |"
    )
    sep = "|" + "|".join(["---"] * (head.count("|") - 1)) + "|"
    lines = [head, sep]
    for r in rows:
        lines.append(
            f"| {r['problem']} | {r['end_to_end']:.2f} | {r['graphs']:.3f} | {r['milp']:.2f} | {r['game']:.3f} | "
            f"{r['gr1_loop']:.4f} | {r['verify']:.3f} | {r['gr1_final']:.4f} | {r['iterations']} | "
            f"{r['counterexamples']} | {r['g_nodes']} | {r['positions']} | {r['moves']} |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per problem (median reported)")
    parser.add_argument("--problems", nargs="+", default=list(PROBLEMS), choices=PROBLEMS)
    args = parser.parse_args(argv)
    rows = [bench(name, args.repeat) for name in args.problems]
    print(markdown(rows))
    slow = [str(r["problem"]) for r in rows if float(r["end_to_end"]) >= END_TO_END_TARGET]
    slow_gr1 = [str(r["problem"]) for r in rows if float(r["gr1_final"]) >= GR1_TARGET]
    print()
    print(
        f"targets: end to end < {END_TO_END_TARGET} s: {'met' if not slow else 'missed by ' + ', '.join(slow)}; "
        f"GR(1) < {GR1_TARGET} s: {'met' if not slow_gr1 else 'missed by ' + ', '.join(slow_gr1)}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
