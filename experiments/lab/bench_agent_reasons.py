"""Benchmark of the agent loop's generalized counterexamples (issue 18, point 6).

For every problem it runs the counterexample-guided loop twice, excluding each rejected
cut set alone (``reasons=False``, method.md §7 as written) and with its reason
(:mod:`synthesis.test_agent.reasons`, the default), checks that both answers have the same
flow, blocked places and cuts, and reports MILP solves and seconds; then it times the
default ``flowtest synthesize FILE --json`` end to end (a fresh process) for the problem
files.

Usage::

    python -m experiments.lab.bench_agent_reasons [--problems maze1 maze2 patrolling FILE.toml ...]

The default problems are the agent built-ins and the two files of
``docs/data/agent-problems/`` (the tutorial's warehouse and Maze 2's grid, each with a test
agent over every free cell). Prints a Markdown table on standard output.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from synthesis.pipeline import synthesize_agent_test
from synthesis.problems.files import load_problem_file
from synthesis.problems.load import load_problem

FILES = Path(__file__).resolve().parent.parent / "docs" / "data" / "agent-problems"
PROBLEMS = ("maze1", "maze2", "patrolling", str(FILES / "warehouse-agent.toml"), str(FILES / "maze-all-free.toml"))
TARGET_SECONDS = 30.0


def _run(name: str, reasons: bool) -> dict[str, Any]:
    problem = load_problem_file(name) if name.endswith(".toml") else load_problem(name)
    t0 = time.perf_counter()
    test = synthesize_agent_test(problem, reasons=reasons)
    seconds = time.perf_counter() - t0
    assert test.agent is not None
    r = test.routing
    return {
        "answer": (r.flow, len(r.blocked_places), int(r.cut_edges.size)),
        "status": r.status,
        "solves": len(test.agent.iterations),
        "seconds": seconds,
        "milp": test.agent.timings["milp"],
        "reasons": test.agent.timings["reasons"],
    }


def _cli_seconds(path: str) -> tuple[float, dict[str, Any]]:
    """``flowtest synthesize FILE --json`` in a fresh process: wall seconds and its JSON."""
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "experiments", "synthesize", path, "--json", "-q"],
        check=True,
        capture_output=True,
        text=True,
    )
    return time.perf_counter() - t0, json.loads(out.stdout)


def bench(name: str) -> dict[str, Any]:
    """Both loops on one problem, and the CLI for a file."""
    plain, ours = _run(name, False), _run(name, True)
    if plain["answer"] != ours["answer"] or plain["status"] != ours["status"]:
        raise AssertionError(f"{name}: the answers differ: {plain['answer']} vs {ours['answer']}")
    row: dict[str, Any] = {"problem": Path(name).stem, "plain": plain, "reasons": ours, "cli": None}
    if name.endswith(".toml"):
        seconds, summary = _cli_seconds(name)
        row["cli"] = (seconds, summary["agent_strategy"]["iterations"], summary["flow"])
    return row


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The table, one row per problem."""
    lines = [
        "| problem | answer (flow / blocked places / cuts) | MILP solves, cut set alone | seconds | "
        "MILP solves, with reasons | seconds (of which reasons) | `flowtest synthesize FILE --json` s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        p, o = r["plain"], r["reasons"]
        cli = f"{r['cli'][0]:.1f}" if r["cli"] else "—"
        lines.append(
            f"| {r['problem']} | {' / '.join(map(str, o['answer']))} | {p['solves']} | {p['seconds']:.1f} | "
            f"{o['solves']} | {o['seconds']:.1f} ({o['reasons']:.2f}) | {cli} |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--problems", nargs="+", default=list(PROBLEMS), help="built-in names or agent problem files")
    args = parser.parse_args(argv)
    rows = [bench(name) for name in args.problems]
    print(markdown(rows))
    slow = [r["problem"] for r in rows if r["cli"] and r["cli"][0] >= TARGET_SECONDS]
    print(f"\ntarget (< {TARGET_SECONDS:.0f} s from flowtest synthesize FILE --json): " + ("met" if not slow else f"missed by {', '.join(slow)}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
