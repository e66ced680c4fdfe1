"""Diagnosis: in which phase a random grid study instance runs out of the paper's budget.

Usage::

    nice -n 5 .venv/bin/python -m experiments.lab.study_phases --size 5 --family reachability:3 --milp reactive \
        --instances 1 3 5 [--backend auto] [--time-limit 600 --after-first 60]

Each instance (the study's draw, :mod:`experiments.lab.random_grid_study`) is synthesized as the
study does it, noting when phase 2 (the fewest cuts at the flow found) began. Phase 1 (the
maximum flow) ends by itself (proven, on either backend) or at the budget's deadline, so a
phase 2 that began well before the solve's end means the flow level was proven and the budget
ran out in the fewest cuts; one that began at the end means it ran out in phase 1. Also
printed: the last status phase 2's solver published (:class:`SolveControl`'s
:class:`~synthesis.routing.solver_control.SolveStatus`: best objective and proven bound; the
final proof of an optimal answer is not published, so that column is informative only for
unproven answers).
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from synthesis.model.errors import InconsistentProblem
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.random_grid import FAMILIES, first_consistent, random_problem
from synthesis.routing.solver_control import SolveControl, SolveStatus

PHASES = ("maximum flow", "fewest cuts")


class RecordingControl(SolveControl):
    """A :class:`SolveControl` that also keeps the last status per phase."""

    def __init__(self) -> None:
        super().__init__()
        self.last: dict[str, SolveStatus] = {}

    def report(self, status: SolveStatus | None) -> None:
        super().report(status)
        if status is not None:
            for phase in PHASES:
                if phase in status.phase:
                    self.last[phase] = status


def _phase_text(status: SolveStatus | None) -> str:
    if status is None:
        return "none published"
    bound = "-" if status.bound is None else f"{status.bound:.4g}"
    return f"best {status.best}, bound {bound}"


def probe(size: int, family: str, n: int, instance: int, milp: str, options: dict[str, Any]) -> str:
    """One instance: its answer and the last status of each phase, as a table row."""
    attempt, _, _ = first_consistent(size, family, n, instance)
    problem = random_problem(size, family, n, instance, attempt, milp)
    control = RecordingControl()
    stamps: dict[str, float] = {}

    def progress(msg: str) -> None:
        if "phase 2 of 2" in msg:
            stamps.setdefault("phase 2", time.perf_counter())

    t0 = time.perf_counter()
    try:
        test = synthesize(problem, SynthesisOptions(control=control, progress=progress, **options))
    except (TimeoutError, InconsistentProblem) as exc:
        answer, backend, rows = f"no test ({exc})", "-", "-"
    else:
        r = test.routing
        answer, backend, rows = f"{r.status}, flow {r.flow}, {r.cut_edges.size} cuts", r.stats["backend"], f"{r.stats['constraints']:,}"
    wall = time.perf_counter() - t0
    began = f"{stamps['phase 2'] - t0:.1f}" if "phase 2" in stamps else "never"
    last = _phase_text(control.last.get("fewest cuts"))
    return f"| {family}:{n} #{instance} {milp} | {rows} | {backend} | {answer} | {wall:.1f} | {began} | {last} |"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--size", type=int, default=5)
    ap.add_argument("--family", required=True, metavar="FAMILY:N", help="a study cell, e.g. reachability:3 (|AP| = 4)")
    ap.add_argument("--milp", choices=("static", "reactive"), required=True)
    ap.add_argument("--instances", type=int, nargs="+", required=True, help="the study's instance numbers (seeds)")
    ap.add_argument("--backend", default="auto")
    ap.add_argument("--time-limit", type=float, default=600.0, help="seconds to a first test (default: the paper's 600)")
    ap.add_argument("--after-first", type=float, default=60.0, help="seconds after the first test (default: the paper's 60)")
    args = ap.parse_args(argv)
    family, _, n = args.family.partition(":")
    if family not in FAMILIES or not n.isdigit():
        ap.error(f"--family: expected FAMILY:N with FAMILY one of {', '.join(FAMILIES)}, not {args.family!r}")
    options = {"time_limit": args.time_limit, "after_first": args.after_first, "backend": args.backend}
    print("| instance | rows | backend | answer | wall s | phase 2 began at s | phase 2's last published status |")
    print("|---|---|---|---|---|---|---|", flush=True)
    for instance in args.instances:
        print(probe(args.size, family, int(n), instance, args.milp, options), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
