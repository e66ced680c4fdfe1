"""The paper's random grid-world study (paper-examples.md, "Random grid worlds"), at paper scale.

Usage::

    .venv/bin/python -m experiments.lab.random_grid_study                     # the whole study, paper budget
    .venv/bin/python -m experiments.lab.random_grid_study --sizes 5 10 --time-limit 60
    .venv/bin/python -m experiments.lab.random_grid_study --families reaction:4 --sizes 20 --instances 5
    .venv/bin/python -m experiments.lab.random_grid_study --ray [--ray-address HOST:PORT] [--workers 2]
    .venv/bin/python -m experiments.lab.random_grid_study --gurobi              # vs Gurobi, 5x5..9x9 static
    .venv/bin/python -m experiments.lab.random_grid_study --report DIR [DIR ...]   # tables of earlier runs
    .venv/bin/python -m experiments.lab.random_grid_study --report DIR --compare-to OLD.csv  # shares proven, side by side
    .venv/bin/python -m experiments.lab.random_grid_study --graphs-only         # graph construction only
    .venv/bin/python -m experiments.lab.random_grid_study --backend highs       # one routing solver backend

Every spec family of the paper (:data:`synthesis.problems.random_grid.PAPER_SPECS`) times every
grid size times ``--instances`` seeded instances, each solved with MILP-static and
MILP-reactive through :func:`synthesis.pipeline.synthesize`, whose independent checks
(bypass flow 0, flow, no trapped entry node) must pass: a failed check is recorded as
the outcome ``check-failed`` and counts as a failure.

Instance ``i`` of a cell is seed ``i``; an attempt whose problem is inconsistent on the
product graphs (method.md §5's two cases) is redrawn, so MILP-static and MILP-reactive
solve the same grid.

**Budget.** The paper gave each solve 10 minutes to a first solution and then one more
minute; that is the default here (``SynthesisOptions(time_limit=600, after_first=60)``):
the routing solve (model, both phases, feasibility rounds) stops 60 s after its first
checked test (flow >= 1), or at 600 s without one, a failure. A solve stopped with a test
counts as solved but not proven optimal. ``--time-limit S`` alone is one overall limit
instead; with ``--after-first A`` too, ``S`` is the limit to the first test.

**Backend.** ``--backend NAME`` passes ``SynthesisOptions(backend=NAME)`` (the routing
solver: ``auto``, ``highs``, ``cover``, ``cpsat``; see :mod:`synthesis.pipeline`); without it
the default applies. Each record keeps the option asked for (``backend``) and the backend
the solve reports in its statistics (``solver_backend``), and ``--resume`` keeps the
records of the same backend only.

**Outcomes.** ``optimal`` (a checked test, proven optimal), ``feasible`` (a checked test,
budget ran out before the proof), ``timeout`` (no test within the budget), ``no-test``
(the MILP proved that every routing cut set traps the system), ``check-failed`` (a
FlowTest bug), ``error`` (anything else, with its message). Solved = optimal + feasible.

**Dispatch.** In-process by default; ``--ray`` runs every instance as a Ray task (a local
Ray runtime, or the cluster at ``--ray-address``, whose nodes need FlowTest installed,
``pip install -e '.[bench]'``). The answers (outcome, flow, cut count, a digest of the
cut set) do not depend on the dispatch; only times do.

**Output** (``--out``, default ``random-grid-study/``): ``records.jsonl`` (one line per
finished instance, appended as they finish, read back by ``--resume``), ``results.json``
(configuration, machine load, every record), ``results.csv`` and ``tables.md`` (the
paper's layout: graph construction time, solve time mean ± std, success rate, share
proven optimal). Progress goes to standard error.

**Gurobi** (``--gurobi``, needs ``gurobipy``): sizes 5..9 and MILP-static by default; each
instance is solved by FlowTest on HiGHS and, from the model our builder made (written as
MPS), with the paper's one combined objective on Gurobi and on HiGHS in one phase; see
:mod:`experiments.lab.gurobi_compare`.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import platform
import sys
import time
import traceback
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.model.errors import CheckFailed, InconsistentProblem
from synthesis.pipeline import SynthesisOptions, synthesize
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_grid import FAMILIES, PAPER_SIZES, PAPER_SPECS, first_consistent, paper_ap, random_problem

MILPS: tuple[str, ...] = ("static", "reactive")
PAPER_FIRST_LIMIT = 600.0  # the paper's budget: 10 minutes to a first solution,
PAPER_AFTER_FIRST = 60.0  # then one more minute
GUROBI_SIZES: tuple[int, ...] = (5, 6, 7, 8, 9)
SOLVED = ("optimal", "feasible")
GRAPHS_ONLY = "graphs"  # the pseudo-MILP of --graphs-only: build and time the graphs, solve nothing
_MILP_ORDER = {"static": 0, "reactive": 1, GRAPHS_ONLY: 2}
#: fields that must not depend on how or where an instance ran
ANSWER_FIELDS = ("family", "n", "size", "instance", "milp", "attempt", "outcome", "status", "flow", "n_cuts", "cut_digest")


@dataclass(frozen=True)
class Task:
    """One instance with one MILP: everything a worker needs, nothing else (picklable)."""

    family: str
    n: int
    size: int
    instance: int
    milp: str  # "static", "reactive", or "graphs" (graph construction only, no MILP)
    time_limit: float | None
    threads: int | None
    gurobi: bool = False
    after_first: float | None = None  # see SynthesisOptions.after_first
    backend: str | None = None  # SynthesisOptions.backend; None: the default

    @property
    def key(self) -> tuple[Any, ...]:
        """Identifies the task's record (for ``--resume`` and for ordering)."""
        return (
            self.family,
            self.n,
            self.size,
            self.instance,
            self.milp,
            self.time_limit,
            self.gurobi,
            self.after_first,
            self.backend,
        )


def record_key(rec: dict[str, Any]) -> tuple[Any, ...]:
    """The :attr:`Task.key` of a record."""
    return (
        rec["family"],
        rec["n"],
        rec["size"],
        rec["instance"],
        rec["milp"],
        rec["time_limit"],
        rec["gurobi"],
        rec.get("after_first"),
        rec.get("backend"),
    )


def _digest(test: Any) -> str:
    """A short digest of the answer's restrictions (cut edges of G and static walls)."""
    h = hashlib.sha1()
    h.update(np.asarray(test.routing.cut_edges, dtype=np.int64).tobytes())
    h.update(np.asarray(test.routing.static_moves_cut, dtype=bool).tobytes())
    return h.hexdigest()[:12]


def run_task(task: Task) -> dict[str, Any]:
    """Draw, synthesize and check one instance; a flat record of what happened and how long it took.

    Never raises for a solver or check outcome: each becomes the record's ``outcome``.
    Runs the same way in-process and as a Ray task.
    """
    rec: dict[str, Any] = {
        "family": task.family,
        "n": task.n,
        "ap": paper_ap(task.family, task.n),
        "size": task.size,
        "instance": task.instance,
        "milp": task.milp,
        "time_limit": task.time_limit,
        "after_first": task.after_first,
        "gurobi": task.gurobi,
        "backend": task.backend,
        "solver_backend": None,
        "attempt": None,
        "outcome": "error",
        "status": None,
        "flow": None,
        "n_cuts": None,
        "cut_digest": None,
        "graph_s": None,
        "solve_s": None,
        "check_s": None,
        "total_s": None,
        "g_nodes": None,
        "g_edges": None,
        "bpi_states": None,
        "binary_vars": None,
        "continuous_vars": None,
        "constraints": None,
        "feasibility_rounds": None,
        "mip_gap": None,
        "message": "",
        "load1": os.getloadavg()[0],
        "host": platform.node(),
    }
    try:
        attempt, _, _ = first_consistent(task.size, task.family, task.n, task.instance)
        rec["attempt"] = attempt
        # the graphs do not depend on the environment kind; graphs-only runs build the reactive problem's
        kind = "reactive" if task.milp == GRAPHS_ONLY else task.milp
        problem = random_problem(task.size, task.family, task.n, task.instance, attempt, kind)
        # graph construction timed on its own, so every outcome (timeouts too) reports it
        t_graph = time.perf_counter()
        spec, products = build_graphs(problem)
        rec.update(
            graph_s=time.perf_counter() - t_graph,
            g_nodes=int(products.virtual.n_nodes),
            g_edges=int(products.virtual.n_edges),
            bpi_states=int(spec.dba.n_states),
        )
        del spec, products
    except Exception as exc:  # noqa: BLE001 - recorded, the sweep goes on
        rec["message"] = f"drawing the instance or building its graphs: {exc!r}"
        return rec
    if task.milp == GRAPHS_ONLY:
        rec["outcome"] = GRAPHS_ONLY
        return rec
    stamps: dict[str, float] = {}

    def progress(msg: str) -> None:
        if msg.startswith("checking"):
            stamps.setdefault("check", time.perf_counter())

    backend: dict[str, Any] = {} if task.backend is None else {"backend": task.backend}
    options = SynthesisOptions(time_limit=task.time_limit, after_first=task.after_first, threads=task.threads, progress=progress, **backend)
    capture_ctx = None
    if task.gurobi:
        from .gurobi_compare import capture_models

        capture_ctx = capture_models()
    t0 = time.perf_counter()
    try:
        if capture_ctx is not None:
            with capture_ctx as cap:
                test = synthesize(problem, options)
        else:
            test = synthesize(problem, options)
    except TimeoutError as exc:
        rec.update(outcome="timeout", message=str(exc), total_s=time.perf_counter() - t0)
        return rec
    except InconsistentProblem as exc:
        rec.update(outcome="no-test", message=f"{exc.reason}: {exc}", total_s=time.perf_counter() - t0)
        return rec
    except CheckFailed as exc:
        rec.update(outcome="check-failed", message=str(exc), total_s=time.perf_counter() - t0)
        return rec
    except Exception as exc:  # noqa: BLE001 - recorded, the sweep goes on
        rec.update(message="".join(traceback.format_exception_only(exc)).strip(), total_s=time.perf_counter() - t0)
        return rec
    t_end = time.perf_counter()
    t_check = stamps.get("check", t_end)
    r = test.routing
    if not test.checks.ok:  # synthesize raises on a failed check; belt and braces
        rec.update(outcome="check-failed", message="; ".join(test.checks.problems()))
        return rec
    rec.update(
        outcome=r.status,
        status=r.status,
        flow=int(r.flow),
        n_cuts=int(r.cut_edges.size),
        cut_digest=_digest(test),
        solve_s=float(t_check - t0 - test.graph_seconds),  # model building, every MILP round
        check_s=float(t_end - t_check),
        total_s=float(t_end - t0),
        binary_vars=int(r.stats["binary_vars"]),
        continuous_vars=int(r.stats["continuous_vars"]),
        constraints=int(r.stats["constraints"]),
        feasibility_rounds=int(r.stats.get("feasibility_rounds", 1)),
        mip_gap=float(r.mip_gap),
        solver_backend=r.stats.get("backend"),
    )
    if task.gurobi:
        try:
            rec.update(_gurobi_fields(cap, test, task))
        except Exception as exc:  # noqa: BLE001 - the comparison failed, our answer stands
            rec.update(gurobi_outcome="error", gurobi_message=repr(exc))
    return rec


def _gurobi_fields(cap: Any, test: Any, task: Task) -> dict[str, Any]:
    """Solve the final routing model with the paper's combined objective on Gurobi and on HiGHS."""
    from .gurobi_compare import compare_on

    models = cap.models()
    out: dict[str, Any] = {"gurobi_model_rounds": len(models)}
    if not models:
        out["gurobi_outcome"] = "no-model"
        return out
    model = models[-1]  # the model of our final answer (the first, unless feasibility rounds were needed)
    out["model_cols"] = int(model.lp.num_col_)
    out["model_rows"] = int(model.lp.num_row_)
    for ans in compare_on(model, test.products.virtual.n_edges, task.time_limit, task.threads):
        p = "gurobi" if ans.solver == "gurobi" else "highs1"
        out[f"{p}_outcome"] = ans.outcome
        out[f"{p}_flow"] = ans.flow
        out[f"{p}_n_cuts"] = ans.n_cuts
        out[f"{p}_s"] = ans.seconds
        if ans.message:
            out[f"{p}_message"] = ans.message
    return out


# ------------------------------------------------------------------------------ dispatch


def run_in_process(tasks: list[Task], on_done: Callable[[dict[str, Any]], None]) -> None:
    """Run the tasks one after the other in this process."""
    for t in tasks:
        on_done(run_task(t))


def run_on_ray(tasks: list[Task], on_done: Callable[[dict[str, Any]], None], address: str | None = None, workers: int | None = None) -> None:
    """Run every task as a Ray task (one CPU each) and hand each record over as it finishes.

    ``address`` ``None`` starts a local Ray runtime with ``workers`` CPUs (Ray's default:
    every core); otherwise connects to that cluster.
    """
    import ray

    from experiments.lab import random_grid_study as mod  # by reference, also when run as __main__

    started = not ray.is_initialized()
    if started:
        if address is None:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(mod.run_task)
        pending = {remote.remote(t): t for t in tasks}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                task = pending.pop(ref)
                try:
                    rec = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - a lost worker is a failed instance, not a lost sweep
                    rec = run_task_failed(task, f"ray: {exc!r}")
                on_done(rec)
    finally:
        if started:
            ray.shutdown()


def run_task_failed(task: Task, message: str) -> dict[str, Any]:
    """The record of a task whose worker died."""
    return {
        "family": task.family,
        "n": task.n,
        "ap": paper_ap(task.family, task.n),
        "size": task.size,
        "instance": task.instance,
        "milp": task.milp,
        "time_limit": task.time_limit,
        "after_first": task.after_first,
        "gurobi": task.gurobi,
        "backend": task.backend,
        "outcome": "error",
        "message": message,
    }


# ------------------------------------------------------------------------------ tables


def _mean_std(xs: list[float]) -> str:
    if not xs:
        return "—"
    m = float(np.mean(xs))
    s = float(np.std(xs, ddof=1)) if len(xs) > 1 else 0.0
    return f"{_fmt(m)} ± {_fmt(s)}"


def _fmt(x: float) -> str:
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 0.1:
        return f"{x:.2f}"
    return f"{x:.3f}"


def _pct(k: int, n: int) -> str:
    return f"{100 * k / n:.0f}%" if n else "—"


def graph_table(records: list[dict[str, Any]]) -> str:
    """Graph construction per spec (rows) and grid size (columns): mean G nodes and seconds (mean ± std)."""
    recs = [r for r in records if r.get("graph_s") is not None and not r.get("gurobi")]
    specs = sorted({(r["family"], r["n"]) for r in recs}, key=lambda c: (FAMILIES.index(c[0]), c[1]))
    sizes = sorted({r["size"] for r in recs})
    head = ["spec", r"\|AP\|"] + [f"{z}x{z}: G nodes, graphs s" for z in sizes]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for fam, n in specs:
        row = [fam, str(paper_ap(fam, n))]
        for z in sizes:
            cell = [r for r in recs if (r["family"], r["n"], r["size"]) == (fam, n, z)]
            row.append(f"{np.mean([r['g_nodes'] for r in cell]):.0f}, {_mean_std([r['graph_s'] for r in cell])}" if cell else "—")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def study_table(records: list[dict[str, Any]]) -> str:
    """The paper's layout: one row per spec (family, |AP|) and grid size, both MILPs side by side.

    Graph construction time over every run of the cell; solve time over the solved
    instances; success and proven-optimal shares over every instance of the cell.
    """
    recs = [r for r in records if not r.get("gurobi")]
    solved_cells = {(r["family"], r["n"], r["size"]) for r in recs if r["milp"] in MILPS}
    cell_set = solved_cells or {(r["family"], r["n"], r["size"]) for r in recs}  # graphs-only: every cell
    cells = sorted(cell_set, key=lambda c: (FAMILIES.index(c[0]), c[1], c[2]))
    milps = [m for m in MILPS if any(r["milp"] == m for r in recs)]  # graphs-only runs fill the graph columns only
    head = ["spec", r"\|AP\|", "grid", "G nodes (mean)", "graphs s"]
    for m in milps:
        head += [f"{m}: solve s", f"{m}: solved", f"{m}: optimal", f"{m}: failures"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for fam, n, size in cells:
        cell = [r for r in recs if (r["family"], r["n"], r["size"]) == (fam, n, size)]
        nodes = [r["g_nodes"] for r in cell if r.get("g_nodes") is not None]
        graphs = [r["graph_s"] for r in cell if r.get("graph_s") is not None]
        row = [fam, str(paper_ap(fam, n)), f"{size}x{size}", f"{np.mean(nodes):.0f}" if nodes else "—", _mean_std(graphs)]
        for m in milps:
            rs = [r for r in cell if r["milp"] == m]
            ok = [r for r in rs if r["outcome"] in SOLVED]
            opt = [r for r in rs if r["outcome"] == "optimal"]
            fails: dict[str, int] = {}
            for r in rs:
                if r["outcome"] not in SOLVED:
                    fails[r["outcome"]] = fails.get(r["outcome"], 0) + 1
            row += [
                _mean_std([r["solve_s"] for r in ok]),
                f"{_pct(len(ok), len(rs))} ({len(ok)}/{len(rs)})",
                _pct(len(opt), len(rs)),
                ", ".join(f"{k} {v}" for k, v in sorted(fails.items())) or "0",
            ]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def gurobi_table(records: list[dict[str, Any]]) -> str:
    """FlowTest (HiGHS, two phases) next to the paper's combined MILP on Gurobi and on HiGHS.

    Times: FlowTest's over its solved instances, Gurobi's and one-phase HiGHS's over the
    instances they solved. The time ratio and the optima are compared on the instances
    that both FlowTest and Gurobi proved optimal (a budget-capped time says nothing).
    Gurobi runs on the model of FlowTest's final answer, so not where FlowTest found none.
    """
    recs = [r for r in records if r.get("gurobi")]
    cells = sorted({(r["size"], r["family"], r["n"]) for r in recs}, key=lambda c: (c[0], FAMILIES.index(c[1]), c[2]))
    head = [
        "grid",
        "spec",
        r"\|AP\|",
        "instances",
        "model cols/rows (mean)",
        "FlowTest (HiGHS) s",
        "Gurobi s",
        "HiGHS one-phase s",
        "both proven optimal",
        "identical optima",
        "Gurobi / FlowTest time (both optimal)",
        "Gurobi not run",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for size, fam, n in cells:
        rs = [r for r in recs if (r["size"], r["family"], r["n"]) == (size, fam, n)]
        ours = [r["solve_s"] for r in rs if r["outcome"] in SOLVED]
        gur = [r["gurobi_s"] for r in rs if r.get("gurobi_outcome") in SOLVED]
        h1 = [r["highs1_s"] for r in rs if r.get("highs1_outcome") in SOLVED]
        proven = [r for r in rs if r["outcome"] == "optimal" and r.get("gurobi_outcome") == "optimal"]
        same = [r for r in proven if (r["gurobi_flow"], r["gurobi_n_cuts"]) == (r["flow"], r["n_cuts"])]
        ratio = "—"
        if proven:
            t_g = float(np.mean([r["gurobi_s"] for r in proven]))
            t_o = float(np.mean([r["solve_s"] for r in proven]))
            ratio = f"{t_g / max(t_o, 1e-9):.2f} ({_fmt(t_g)} / {_fmt(t_o)})"
        skipped: dict[str, int] = {}
        for r in rs:
            o = r.get("gurobi_outcome") or f"FlowTest {r['outcome']}"
            if o not in SOLVED:
                skipped[o] = skipped.get(o, 0) + 1
        cols = [r["model_cols"] for r in rs if r.get("model_cols")]
        rows = [r["model_rows"] for r in rs if r.get("model_rows")]
        lines.append(
            "| "
            + " | ".join(
                [
                    f"{size}x{size}",
                    fam,
                    str(paper_ap(fam, n)),
                    str(len(rs)),
                    f"{np.mean(cols):.0f}/{np.mean(rows):.0f}" if cols else "—",
                    _mean_std(ours),
                    _mean_std(gur),
                    _mean_std(h1),
                    str(len(proven)),
                    f"{len(same)}/{len(proven)}",
                    ratio,
                    ", ".join(f"{k} {v}" for k, v in sorted(skipped.items())) or "0",
                ]
            )
            + " |"
        )
    return "\n".join(lines)


def compare_table(records: list[dict[str, Any]], baseline: list[dict[str, Any]]) -> str:
    """Per cell of ``records``: the share solved and proven optimal, per MILP, next to the
    same cell of ``baseline`` (earlier records, e.g. a ``results.csv`` under another budget or
    backend); cells of ``records`` only, and a cell counts only its finished instances."""

    def shares(recs: list[dict[str, Any]], cell: tuple[Any, ...], milp: str) -> str:
        rs = [r for r in recs if (r["family"], int(r["n"]), int(r["size"])) == cell and r["milp"] == milp]
        if not rs:
            return "—"
        ok = sum(r["outcome"] in SOLVED for r in rs)
        opt = sum(r["outcome"] == "optimal" for r in rs)
        return f"{opt}/{len(rs)} ({_pct(opt, len(rs))}), solved {ok}"

    recs = [r for r in records if not r.get("gurobi") and r["milp"] in MILPS]
    base = [r for r in baseline if str(r.get("gurobi")) in ("False", "", "None") and r["milp"] in MILPS]
    cells = sorted({(r["family"], int(r["n"]), int(r["size"])) for r in recs}, key=lambda c: (c[2], FAMILIES.index(c[0]), c[1]))
    head = ["spec", r"\|AP\|", "grid"]
    for m in MILPS:
        head += [f"{m}: optimal before", f"{m}: optimal now"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for cell in cells:
        row = [cell[0], str(paper_ap(cell[0], cell[1])), f"{cell[2]}x{cell[2]}"]
        for m in MILPS:
            row += [shares(base, cell, m), shares(recs, cell, m)]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def read_csv_records(path: Path) -> list[dict[str, Any]]:
    """The records of a ``results.csv`` (values as text, enough for :func:`compare_table`)."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


# ------------------------------------------------------------------------------ output


CSV_FIELDS = [
    "family",
    "n",
    "ap",
    "size",
    "instance",
    "milp",
    "time_limit",
    "after_first",
    "backend",
    "solver_backend",
    "attempt",
    "outcome",
    "status",
    "flow",
    "n_cuts",
    "cut_digest",
    "graph_s",
    "solve_s",
    "check_s",
    "total_s",
    "g_nodes",
    "g_edges",
    "bpi_states",
    "binary_vars",
    "continuous_vars",
    "constraints",
    "feasibility_rounds",
    "mip_gap",
    "load1",
    "host",
    "gurobi",
    "model_cols",
    "model_rows",
    "gurobi_model_rounds",
    "gurobi_outcome",
    "gurobi_flow",
    "gurobi_n_cuts",
    "gurobi_s",
    "highs1_outcome",
    "highs1_flow",
    "highs1_n_cuts",
    "highs1_s",
    "message",
]


def write_outputs(out: Path, records: list[dict[str, Any]], config: dict[str, Any]) -> None:
    """``results.json``, ``results.csv`` and ``tables.md`` from every record so far."""
    records = sorted(records, key=_order)
    (out / "results.json").write_text(json.dumps({"config": config, "records": records}, indent=1, default=str))
    with open(out / "results.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS, extrasaction="ignore")
        w.writeheader()
        for r in records:
            w.writerow(r)
    parts = [f"<!-- {config['command']} -->"]
    if any(not r.get("gurobi") for r in records):
        parts += ["## Graph construction", "", graph_table(records), ""]
        if any(r["milp"] in MILPS for r in records):
            parts += ["## Random grid study", "", study_table(records), ""]
    if any(r.get("gurobi") for r in records):
        parts += ["## MILP-static: FlowTest on HiGHS vs the paper's formulation on Gurobi", "", gurobi_table(records), ""]
    (out / "tables.md").write_text("\n".join(parts) + "\n")


def _order(r: dict[str, Any]) -> tuple[Any, ...]:
    return (FAMILIES.index(r["family"]), r["n"], r["size"], r["instance"], _MILP_ORDER[r["milp"]], bool(r.get("gurobi")))


def read_records(path: Path) -> list[dict[str, Any]]:
    """The records of ``records.jsonl`` (a torn last line from a killed run is skipped)."""
    out = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return out


# ------------------------------------------------------------------------------ command line


def parse_specs(tokens: Iterable[str] | None) -> list[tuple[str, int]]:
    """``reaction`` (every paper |AP| of the family) or ``reaction:3`` (one ``n``) -> (family, n) pairs."""
    if not tokens:
        return list(PAPER_SPECS)
    out: list[tuple[str, int]] = []
    for tok in tokens:
        fam, _, n = tok.partition(":")
        if fam not in FAMILIES:
            raise SystemExit(f"error: unknown family {fam!r} in --families; expected one of {', '.join(FAMILIES)}")
        if n:
            if not n.isdigit():
                raise SystemExit(f"error: bad spec size in --families {tok!r}: use FAMILY or FAMILY:N")
            out.append((fam, int(n)))
        else:
            out += [s for s in PAPER_SPECS if s[0] == fam]
    return list(dict.fromkeys(out))


def make_tasks(
    specs: list[tuple[str, int]],
    sizes: list[int],
    instances: int,
    milps: list[str],
    time_limit: float | None,
    threads: int | None,
    gurobi: bool,
    after_first: float | None = None,
    backend: str | None = None,
) -> list[Task]:
    """Every (spec, size, instance, MILP), small grids first so the table fills from the top."""
    return [
        Task(fam, n, size, i, m, time_limit, threads, gurobi, after_first, backend)
        for size in sizes
        for fam, n in specs
        for i in range(instances)
        for m in milps
    ]


class Progress:
    """One line per finished instance on standard error, with counts and an estimate of the time left."""

    def __init__(self, total: int, quiet: bool = False) -> None:
        self.total, self.quiet = total, quiet
        self.done = 0
        self.counts: dict[str, int] = {}
        self.t0 = time.perf_counter()

    def __call__(self, rec: dict[str, Any]) -> None:
        self.done += 1
        self.counts[rec["outcome"]] = self.counts.get(rec["outcome"], 0) + 1
        if self.quiet:
            return
        el = time.perf_counter() - self.t0
        eta = el / self.done * (self.total - self.done)
        what = f"{rec['family']}|AP|={rec['ap']} {rec['size']}x{rec['size']} #{rec['instance']} {rec['milp']}"
        if rec["outcome"] == GRAPHS_ONLY:
            res = f"G {rec['g_nodes']} nodes / {rec['g_edges']} edges, graphs {rec['graph_s']:.3f}s"
        elif rec["outcome"] in SOLVED:
            res = f"{rec['outcome']} F={rec['flow']} cuts={rec['n_cuts']} graphs {rec['graph_s']:.2f}s solve {rec['solve_s']:.2f}s"
        else:
            res = f"{rec['outcome'].upper()} {str(rec.get('message', ''))[:80]}"
        if rec.get("gurobi_outcome"):
            g = rec["gurobi_outcome"]
            res += f" | gurobi {g}" + (f" {rec['gurobi_s']:.2f}s F={rec['gurobi_flow']} cuts={rec['gurobi_n_cuts']}" if g in SOLVED else "")
        tally = " ".join(f"{k}:{v}" for k, v in sorted(self.counts.items()))
        print(
            f"[{self.done}/{self.total} {el / 60:.1f}min, ~{eta / 60:.0f}min left] {what}: {res}  ({tally})",
            file=sys.stderr,
            flush=True,
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m experiments.lab.random_grid_study",
        description="The paper's random grid-world study: every spec family x grid size x seeded instances, "
        "MILP-static and MILP-reactive, checked answers, tables in the paper's layout.",
    )
    ap.add_argument("--families", nargs="*", metavar="FAMILY[:N]", help="spec families (default: all nine of the paper)")
    ap.add_argument("--sizes", nargs="*", type=int, help="grid sizes (default 5 10 15 20; with --gurobi 5 6 7 8 9)")
    ap.add_argument("--instances", type=int, default=20, help="seeded instances per cell (seeds 0..N-1; default 20)")
    ap.add_argument("--milps", nargs="*", choices=MILPS, help="default: both (with --gurobi: static)")
    ap.add_argument(
        "--time-limit",
        type=float,
        default=None,
        help="seconds per solve, 0 for none; with --after-first: seconds to a first test (default: the paper's "
        f"budget, {PAPER_FIRST_LIMIT:.0f} s to a first test, then {PAPER_AFTER_FIRST:.0f} s more)",
    )
    ap.add_argument(
        "--after-first",
        type=float,
        default=None,
        help="seconds of improvement once a first test is found (default: the paper's budget, see --time-limit)",
    )
    ap.add_argument("--threads", type=int, default=1, help="solver threads per instance (default 1)")
    ap.add_argument(
        "--backend",
        default=None,
        metavar="NAME",
        help="routing solver backend (SynthesisOptions.backend: auto, highs, cover, cpsat; default: FlowTest's default)",
    )
    ap.add_argument("--out", type=Path, default=Path("random-grid-study"), help="output directory")
    ap.add_argument("--resume", action="store_true", help="keep the records already in OUT/records.jsonl, run the rest")
    ap.add_argument("--ray", action="store_true", help="dispatch the instances as Ray tasks")
    ap.add_argument("--ray-address", default=None, help="a Ray cluster's address (implies --ray)")
    ap.add_argument("--workers", type=int, default=None, help="CPUs of a local Ray runtime (default: every core)")
    ap.add_argument("--gurobi", action="store_true", help="also solve the paper's MILP-static formulation on Gurobi")
    ap.add_argument(
        "--graphs-only",
        action="store_true",
        help="only draw the instances and time their graph construction (no MILP)",
    )
    ap.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    ap.add_argument(
        "--report",
        nargs="+",
        type=Path,
        metavar="DIR",
        help="run nothing: print the tables of the records in these output directories together",
    )
    ap.add_argument(
        "--compare-to",
        type=Path,
        metavar="CSV",
        help="with --report: also the shares proven optimal per cell next to those of this earlier results.csv",
    )
    args = ap.parse_args(argv)

    if args.report:
        recs = [r for d in args.report for r in read_records(d / "records.jsonl")]
        recs.sort(key=_order)
        if any(not r.get("gurobi") for r in recs):
            print(graph_table(recs) + "\n")
            if any(r["milp"] in MILPS for r in recs):
                print(study_table(recs) + "\n")
        if any(r.get("gurobi") for r in recs):
            print(gurobi_table(recs))
        if args.compare_to is not None:
            print("\n" + compare_table(recs, read_csv_records(args.compare_to)))
        return 0

    if args.instances < 1:
        ap.error("--instances must be at least 1")
    specs = parse_specs(args.families)
    sizes = args.sizes or list(GUROBI_SIZES if args.gurobi else PAPER_SIZES)
    milps = args.milps or (["static"] if args.gurobi else list(MILPS))
    if args.graphs_only:
        if args.gurobi:
            ap.error("--graphs-only solves nothing: it does not combine with --gurobi")
        milps = [GRAPHS_ONLY]
    if args.gurobi and "reactive" in milps:
        ap.error("--gurobi compares the MILP-static formulation only")
    if args.gurobi:
        try:
            import gurobipy  # noqa: F401
        except ImportError:
            ap.error("--gurobi needs gurobipy: pip install -e '.[bench]'")
    if args.backend is not None and "backend" not in {f.name for f in fields(SynthesisOptions)}:
        ap.error("--backend: this FlowTest has no solver backend option (SynthesisOptions.backend)")
    if args.time_limit is None and args.after_first is None:
        time_limit: float | None = PAPER_FIRST_LIMIT
        after_first: float | None = PAPER_AFTER_FIRST
    else:
        time_limit = args.time_limit if args.time_limit and args.time_limit > 0 else None
        after_first = args.after_first if args.after_first is not None and args.after_first >= 0 else None
    tasks = make_tasks(specs, sizes, args.instances, milps, time_limit, args.threads, args.gurobi, after_first, args.backend)

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    log = out / "records.jsonl"
    records: list[dict[str, Any]] = []
    if args.resume:
        wanted = {t.key for t in tasks}
        records = [r for r in read_records(log) if record_key(r) in wanted]
        have = {record_key(r) for r in records}
        tasks = [t for t in tasks if t.key not in have]
    elif log.exists():
        log.unlink()
    use_ray = args.ray or args.ray_address is not None
    config = {
        "command": "python -m experiments.lab.random_grid_study " + " ".join(argv if argv is not None else sys.argv[1:]),
        "specs": specs,
        "sizes": sizes,
        "instances": args.instances,
        "milps": milps,
        "time_limit": time_limit,
        "after_first": after_first,
        "backend": args.backend,
        "threads": args.threads,
        "dispatch": ("ray " + (args.ray_address or "local")) if use_ray else "in-process",
        "machine": {"cpus": os.cpu_count(), "load_at_start": os.getloadavg(), "python": platform.python_version()},
    }
    progress = Progress(len(tasks), args.quiet)
    print(f"{len(tasks)} solves to run ({len(records)} already done), dispatch: {config['dispatch']}", file=sys.stderr)
    last_write = [time.perf_counter()]

    def on_done(rec: dict[str, Any]) -> None:
        records.append(rec)
        with open(log, "a") as f:
            f.write(json.dumps(rec, default=str) + "\n")
        progress(rec)
        if time.perf_counter() - last_write[0] > 60:
            write_outputs(out, records, config)
            last_write[0] = time.perf_counter()

    if use_ray:
        run_on_ray(tasks, on_done, args.ray_address, args.workers)
    else:
        run_in_process(tasks, on_done)
    config["machine"]["load_at_end"] = os.getloadavg()
    write_outputs(out, records, config)
    print((out / "tables.md").read_text())
    bad = sum(1 for r in records if r["outcome"] in ("check-failed", "error"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
