"""Benchmark: the whole ``flowtest synthesize NAME --json`` command, cold, as a user runs it.

Usage::

    .venv/bin/python -m experiments.lab.bench_command [NAME ...] [--runs N] [--source DIR] [--json FILE]

Runs the console script ``--runs`` times per problem (default 10), one after another, each in
a fresh process with a fresh, empty cache (``XDG_CACHE_HOME`` and ``FLOWTEST_CACHE_DIR`` in a
new temporary folder, so no cached answer is used), and prints a Markdown table: the median,
fastest and slowest wall seconds from the start of the process to its end; the medians, from
each run's JSON stats, of the routing solve (``solve_seconds``), of its wait for the CP-SAT
child (``cpsat.spawn_seconds``: from handing the model over until the child has built it,
the child's start-up included when it was not ready yet), of CP-SAT's search
(``cpsat.wall_seconds``) and of the rest of the command (wall minus routing: start-up,
imports, graphs, model, checks, output); the median CPU seconds of the process and the
children it reaped, and the CP-SAT child's own (``cpsat.child_cpu_seconds``; before the
command reaped its child, only this figure held its CPU time). Every run's
stdout must be the JSON document, and every run's answer (the document without its timings)
the same: the script fails otherwise.

``--source DIR`` runs the command line of another checkout (``DIR``'s ``experiments`` and
``synthesis``, with this interpreter and its packages): how the table's "before" rows were
measured, on a worktree of the commit before the change.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from synthesis.artifacts.summary import without_timings

DEFAULT = ("refueling",)

CONSOLE = "import sys; sys.argv[0] = 'flowtest'; from experiments.cli.console import main; main()"
"""The console script's body, for ``--source`` (run with the checkout as working directory)."""


def command(name: str, source: Path | None) -> tuple[list[str], Path | None]:
    """The command line for ``name`` and the working directory to run it in."""
    if source is None:
        return [str(Path(sys.executable).parent / "flowtest"), "synthesize", name, "--json"], None
    return [sys.executable, "-c", CONSOLE, "synthesize", name, "--json"], source


def one_run(name: str, source: Path | None) -> tuple[float, float, dict[str, Any]]:
    """One cold run: (wall seconds, CPU seconds of the process tree it reaped, the JSON document)."""
    argv, cwd = command(name, source)
    with tempfile.TemporaryDirectory(prefix="flowtest-bench-") as tmp:
        env = {**os.environ, "XDG_CACHE_HOME": str(Path(tmp) / "cache"), "FLOWTEST_CACHE_DIR": str(Path(tmp) / "cache" / "flowtest")}
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{name}: exit {proc.returncode}: {proc.stderr.strip().splitlines()[-1:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads(proc.stdout)


def bench(name: str, runs: int, source: Path | None) -> dict[str, Any]:
    """``runs`` cold runs of ``name``: wall and CPU figures, where the wall time went (from
    each run's JSON stats), and the one answer they all gave."""
    walls, cpus, answers = [], [], []
    parts: dict[str, list[float]] = {"routing_s": [], "child_wait_s": [], "search_s": [], "child_cpu_s": []}
    for _ in range(runs):
        wall, cpu, document = one_run(name, source)
        walls.append(wall)
        cpus.append(cpu)
        answers.append(json.dumps(without_timings(document), sort_keys=True))
        stats, child = document["stats"], document["stats"].get("cpsat", {})
        parts["routing_s"].append(float(stats.get("solve_seconds", 0.0)))
        parts["child_wait_s"].append(float(child.get("spawn_seconds", 0.0)))  # model handed over until the child has built it
        parts["search_s"].append(float(child.get("wall_seconds", 0.0)))
        parts["child_cpu_s"].append(float(child.get("child_cpu_seconds", 0.0)))
    if len(set(answers)) != 1:
        raise SystemExit(f"{name}: the runs gave {len(set(answers))} different answers")
    answer = json.loads(answers[0])
    stats = document["stats"]
    return {
        "problem": name,
        "runs": runs,
        "status": answer["status"],
        "flow": answer["flow"],
        "n_cuts": answer["n_cuts"],
        "backend": stats.get("backend", "-"),
        "median_wall_s": statistics.median(walls),
        "min_wall_s": min(walls),
        "max_wall_s": max(walls),
        "median_cpu_s": statistics.median(cpus),
        **{f"median_{k}": statistics.median(v) for k, v in parts.items()},
        "median_outside_routing_s": statistics.median(w - r for w, r in zip(walls, parts["routing_s"], strict=True)),
        "walls": walls,
        "cpus": cpus,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=list(DEFAULT), metavar="NAME")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--source", type=Path, help="run the command line of this checkout instead of the installed one")
    parser.add_argument("--json", type=Path, help="also write the rows (with every run's figures) here")
    args = parser.parse_args(argv)
    rows = [bench(name, args.runs, args.source) for name in args.names]
    print(
        "| problem | answer | backend | runs | median wall s | min | max | routing | of which: waiting for the child | CP-SAT search | "
        "outside routing | CPU s reaped (process + children) | child CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['problem']} | {r['status']}, flow {r['flow']}, {r['n_cuts']} cuts | {r['backend']} | {r['runs']} | "
            f"{r['median_wall_s']:.2f} | {r['min_wall_s']:.2f} | {r['max_wall_s']:.2f} | {r['median_routing_s']:.2f} | "
            f"{r['median_child_wait_s']:.2f} | {r['median_search_s']:.2f} | {r['median_outside_routing_s']:.2f} | "
            f"{r['median_cpu_s']:.2f} | {r['median_child_cpu_s']:.2f} |"
        )
    print(f"load average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
