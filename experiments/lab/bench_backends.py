"""Benchmark: the routing solver backends (HiGHS, OR-Tools CP-SAT) on the same problems.

Usage::

    nice -n 10 .venv/bin/python -m experiments.lab.bench_backends [--time-limit S] [--work-limit W] [--seeds N]
        [--builtins NAME ...] [--sizes 5 10] [--families reachability reaction:3 ...] [--kinds static reactive]
        [--json FILE] [--backends highs cpsat]

For each problem (built-ins, then seeded random grids of every size, family and kind static /
reactive, the first consistent attempt of seeds 0..N-1) and each backend, one synthesis in this
process under a wall-clock ``--time-limit`` (a benchmark budget: the answers are checked, and a
solve it stops says ``feasible``). Per run: status, flow, cuts, the solve's wall seconds, the
CPU seconds it used (this process's, plus the CP-SAT child's, which it reports), and for CP-SAT
the child's start-up and model transfer (``spawn``: a fresh child each run here, as the first
solve of a process pays; later solves of a process, such as an agent problem's rounds, reuse it;
the figure is the last round's). CPU seconds and CP-SAT's deterministic seconds ("CP-SAT work",
all phases; ``--work-limit`` bounds each phase by them) are the load-independent figures: wall
times on a shared machine are upper bounds. Prints a Markdown table and, per
group, how many runs each backend proved and its total solve time; ``--json`` keeps the rows.
Needs OR-Tools (a core dependency).
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path
from typing import Any

from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.load import load_problem
from synthesis.problems.problem import Problem
from synthesis.problems.random_grid import FAMILIES, first_consistent, random_problem
from synthesis.routing.backends import cpsat

BUILTINS = ("small-reactive", "example1", "beaver-rescue", "motion-primitives", "maze1", "maze2", "patrolling", "refueling", "mars-exploration")
BACKENDS = ("highs", "cpsat")
"""The backends run by default (and the choices of ``--backends``)."""
CHOICES = BACKENDS
KINDS = ("static", "reactive")


def run(problem: Problem, backend: str, time_limit: float | None, work_limit: float | None = None) -> dict[str, Any]:
    """One synthesis of ``problem`` on ``backend``: its answer and costs (``work_limit``:
    CP-SAT's deterministic seconds per phase, a load-independent budget)."""
    cpsat.close_idle_workers()  # every CP-SAT run starts a fresh child: the first solve's cost
    cpu0 = time.process_time() + _children_cpu()
    t0 = time.perf_counter()
    try:
        test = synthesize(problem, SynthesisOptions(backend=backend, time_limit=time_limit, work_limit=work_limit))
    except (TimeoutError, InconsistentProblem) as exc:
        cpsat.close_idle_workers()
        status = exc.reason if isinstance(exc, InconsistentProblem) else "no test"
        return {"status": status, "flow": None, "n_cuts": None, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() + _children_cpu() - cpu0}
    wall = time.perf_counter() - t0
    cpsat.close_idle_workers()  # reaped: its CPU seconds are counted in RUSAGE_CHILDREN
    r = test.routing
    assert test.checks.bypass_flow == 0
    child = r.stats.get("cpsat") or {}
    agent = test.extra_stats.get("agent_seconds")
    return {
        "status": r.status,
        "flow": r.flow,
        "n_cuts": int(r.cut_edges.size),
        "solve_s": agent["milp"] if agent else r.stats["solve_seconds"],
        "wall_s": wall,
        "cpu_s": time.process_time() + _children_cpu() - cpu0,
        "spawn_cpu_s": child.get("spawn_cpu_seconds"),
        "spawn_s": child.get("spawn_seconds"),
        "cpsat_wall_s": child.get("wall_seconds"),
        "cpsat_work": child.get("deterministic_time"),
        "rounds": len(test.agent.iterations) if test.agent is not None else 1,
        "binaries": r.stats["binary_vars"],
        "rows": r.stats["constraints"],
    }


def _children_cpu() -> float:
    """CPU seconds of this process's reaped children (the CP-SAT child, once closed)."""
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return float(ru.ru_utime + ru.ru_stime)


def parse_family(token: str) -> tuple[str, int]:
    """``FAMILY[:N]`` of ``--families`` as ``(family, n)``; ``n`` defaults to 2 (the study's
    ``--families`` spelling, so both scripts name the same instances)."""
    family, _, n = token.partition(":")
    if family not in FAMILIES or (n and not n.isdigit()):
        raise SystemExit(f"error: bad --families entry {token!r}; expected FAMILY[:N] with FAMILY one of {', '.join(FAMILIES)}")
    return family, int(n) if n else 2


def cases(builtins: list[str], sizes: list[int], families: list[str], seeds: int, kinds: tuple[str, ...] = KINDS) -> list[tuple[str, str, Problem]]:
    """``(group, label, problem)`` of every problem benchmarked. The random grids are the
    random grid study's instances (:mod:`experiments.lab.random_grid_study`: seed = instance)."""
    out = [("built-in", name, load_problem(name)) for name in builtins]
    for size in sizes:
        for kind in kinds:
            for family, n in map(parse_family, families):
                for seed in range(seeds):
                    attempt, _, _ = first_consistent(size, family, n, seed)  # the study's draw: the graphs do not depend on the kind
                    problem = random_problem(size, family, n, seed, attempt, kind)
                    out.append((f"{size}x{size} {kind}", f"{family}{n} s{seed}", problem))
    return out


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.2f}"
    return str(v)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--time-limit", type=float, default=120.0, help="wall-clock seconds per synthesis (default 120)")
    ap.add_argument("--seeds", type=int, default=3, help="random instances per (size, kind, family) (default 3)")
    ap.add_argument("--builtins", nargs="*", default=list(BUILTINS))
    ap.add_argument("--sizes", nargs="*", type=int, default=[5, 10])
    ap.add_argument(
        "--families",
        nargs="*",
        default=["reachability", "reaction"],
        metavar="FAMILY[:N]",
        help="random grid spec families, N as in the study (default 2): reachability:3 is |AP| = 4",
    )
    ap.add_argument("--kinds", nargs="*", default=list(KINDS), choices=KINDS, help="random grids' kinds (default both)")
    ap.add_argument("--backends", nargs="*", default=list(BACKENDS), choices=CHOICES)
    ap.add_argument("--work-limit", type=float, default=None, help="CP-SAT's deterministic seconds per phase (SynthesisOptions.work_limit; default none)")
    ap.add_argument("--json", type=Path, default=None, help="write the rows here as JSON")
    args = ap.parse_args(argv)
    if "cpsat" in args.backends:
        cpsat.require()
    rows: list[dict[str, Any]] = []
    work = "" if args.work_limit is None else f", CP-SAT work limit {args.work_limit:g} deterministic s per phase"
    print(f"ortools {cpsat.ortools_version()}, time limit {args.time_limit:g} s per synthesis{work}\n", flush=True)
    head = "| group | problem | backend | status | flow | cuts | solve s | CPU s | child start s | CP-SAT work |"
    print(head)
    print("|---" * (head.count("|") - 1) + "|", flush=True)
    for group, label, problem in cases(args.builtins, args.sizes, args.families, args.seeds, tuple(args.kinds)):
        for backend in args.backends:
            row = {"group": group, "problem": label, "backend": backend, **run(problem, backend, args.time_limit, args.work_limit)}
            rows.append(row)
            print(
                f"| {group} | {label} | {backend} | {row['status']} | {_fmt(row['flow'])} | {_fmt(row['n_cuts'])} | "
                f"{_fmt(row.get('solve_s'))} | {_fmt(row['cpu_s'])} | {_fmt(row.get('spawn_s'))} | "
                f"{_fmt(row.get('cpsat_work'))} |",
                flush=True,
            )
    print("\n| group | backend | runs | proven | same answer as the other backend (both proven) | total solve s | total CPU s |")
    print("|---|---|---|---|---|---|---|")
    for group in dict.fromkeys(r["group"] for r in rows):
        for backend in args.backends:
            mine = [r for r in rows if r["group"] == group and r["backend"] == backend]
            same = 0
            for r in mine:
                other = [o for o in rows if o["group"] == group and o["problem"] == r["problem"] and o["backend"] != backend]
                if other and r["status"] == other[0]["status"] == "optimal" and (r["flow"], r["n_cuts"]) == (other[0]["flow"], other[0]["n_cuts"]):
                    same += 1
            proven = sum(r["status"] == "optimal" for r in mine)
            solve = sum(r.get("solve_s") or r["wall_s"] for r in mine)
            cpu = sum(r["cpu_s"] for r in mine)
            print(f"| {group} | {backend} | {len(mine)} | {proven} | {same} | {solve:.1f} | {cpu:.1f} |")
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
