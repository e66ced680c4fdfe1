"""Patrolling with physical walls (issue 18 point 5): the whole agent synthesis of
``patrolling`` with its static area's cuts tied across fuel levels and directions
(``tie_places="static"``, ``bidirectional_cuts=True``: paper-examples.md's spec, and the
built-in's own setting now), per routing backend; ``--tie none`` is the per-fuel-level
variant the built-in used before.

For each backend it reports the outcome (a checked test with its flow and cuts, or the
loop's proof that none exists), every round of the counterexample loop (flow, cuts,
verdict) and the seconds and CPU seconds (this process and its CP-SAT children).

Usage::

    python -m experiments.lab.bench_patrolling_walls [--backends cpsat highs] [--tie static]
        [--time-limit S]

Prints a Markdown table on standard output, the progress lines on standard error.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.builtins import patrolling
from synthesis.problems.problem import TIE_PLACES, Problem
from synthesis.routing.backends import cpsat


def variant(tie: str) -> Problem:
    """``patrolling`` with ``tie_places=tie`` and c14 (walls in both directions) when tied."""
    return replace(patrolling(), tie_places=tie, bidirectional_cuts=tie != "none")


def _cpu() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def run(backend: str, tie: str, time_limit: float | None) -> dict[str, Any]:
    """One synthesis; the round lines come from the loop's progress messages."""
    rounds: list[str] = []

    def progress(msg: str) -> None:
        print(f"[{backend}] {msg}", file=sys.stderr, flush=True)
        if msg.startswith("agent loop"):
            rounds.append(msg.split(": ", 1)[1])

    problem = variant(tie)
    t0, c0 = time.perf_counter(), _cpu()
    try:
        test = synthesize(problem, SynthesisOptions(backend=backend, time_limit=time_limit, progress=progress))
    except InconsistentProblem as exc:
        outcome = f"no test ({exc.reason})"
        flow = cuts = "-"
    except TimeoutError:
        outcome = "time limit"
        flow = cuts = "-"
    else:
        assert test.checks.ok and test.checks.bypass_flow == 0 and test.agent is not None
        outcome = f"{test.routing.status}, test agent realized"
        flow, cuts = str(test.routing.flow), str(int(test.routing.cut_edges.size))
    cpsat.close_idle_workers()  # reaped: the CP-SAT child's CPU seconds join RUSAGE_CHILDREN
    return {
        "backend": backend,
        "outcome": outcome,
        "flow": flow,
        "cuts": cuts,
        "rounds": len(rounds),
        "verdicts": "; ".join(rounds),
        "seconds": time.perf_counter() - t0,
        "cpu": _cpu() - c0,
    }


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """One line per backend."""
    lines = [
        "| backend | outcome | flow | cuts | loop rounds | verdicts per round | seconds | CPU seconds |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['backend']} | {r['outcome']} | {r['flow']} | {r['cuts']} | {r['rounds']} | {r['verdicts']} | {r['seconds']:.1f} | {r['cpu']:.1f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backends", nargs="+", default=["cpsat", "highs"])
    parser.add_argument("--tie", choices=TIE_PLACES, default="static")
    parser.add_argument("--time-limit", type=float, default=None, help="seconds per synthesis (default: none)")
    args = parser.parse_args(argv)
    rows = [run(b, args.tie, args.time_limit) for b in args.backends]
    print(markdown(rows))


if __name__ == "__main__":
    main()
