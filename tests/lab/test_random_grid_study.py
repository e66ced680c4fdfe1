"""The random grid study: the pure instance generator, one checked solve, the outputs, Ray, Gurobi.

The instances are the paper's (paper-examples.md, "Random grid worlds"); the harness is
``experiments.lab.random_grid_study``. Only tiny subsets run here.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from experiments.lab import random_grid_study as study
from experiments.lab.random_grid_study import ANSWER_FIELDS, Task, run_in_process, run_task
from synthesis.graphs.consistency import check_consistency
from synthesis.model.errors import InconsistentProblem
from synthesis.problems.problem import build_graphs
from synthesis.problems.random_grid import PAPER_SPECS, first_consistent, paper_ap, random_problem

#: fast instances (5x5, |AP| = 2): seeds whose both MILPs finish in well under a second
FAST = [Task("reachability", 1, 5, i, m, 60.0, 1) for i in (1, 3) for m in ("static", "reactive")]


def test_generator_is_pure_and_shared_with_the_environments() -> None:
    code = "import sys, synthesis.problems.random_grid; print(any(m.split('.')[0] in ('gymnasium', 'flowtest_env', 'pettingzoo') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
    from flowtest_env import random_grid as env_rg
    from synthesis.problems import random_grid as pure

    assert env_rg.random_problem is pure.random_problem
    assert env_rg.family_objectives is pure.family_objectives


def test_paper_specs_and_their_ap_counts() -> None:
    aps = {fam: [paper_ap(fam, n) for f, n in PAPER_SPECS if f == fam] for fam in ("reachability", "reaction", "safety")}
    assert aps == {"reachability": [2, 3, 4], "reaction": [3, 5, 7], "safety": [3, 4, 5]}


def test_draws_are_seeded_and_kind_independent() -> None:
    a = random_problem(10, "reaction", 3, seed=7, attempt=0, kind="static")
    b = random_problem(10, "reaction", 3, seed=7, attempt=0, kind="reactive")
    c = random_problem(10, "reaction", 3, seed=7, attempt=1, kind="static")
    assert a.system.labels == b.system.labels and a.system.initial == b.system.initial
    assert (a.kind, b.kind) == ("static", "reactive")
    assert a.system.labels != c.system.labels or a.system.initial != c.system.initial


def test_first_consistent_redraws_inconsistent_attempts() -> None:
    seen: list[int] = []

    def reject_two(problem):  # the first two attempts are "inconsistent"
        seen.append(len(seen))
        if len(seen) <= 2:
            raise InconsistentProblem("unroutable", "rejected for the test")
        return "ok"

    attempt, problem, value = first_consistent(5, "safety", 2, seed=0, accept=reject_two)
    assert (attempt, value) == (2, "ok") and "attempt 2" in problem.description
    # the default check is method.md's graph-level consistency, independent of the MILP
    attempt, problem, _ = first_consistent(5, "reachability", 3, seed=4)
    check_consistency(build_graphs(problem)[1])
    with pytest.raises(RuntimeError, match="no consistent"):
        first_consistent(5, "safety", 2, seed=0, accept=reject_two, max_attempts=0)


def test_one_instance_is_solved_and_checked() -> None:
    rec = run_task(FAST[0])
    assert rec["outcome"] == "optimal", rec["message"]
    assert rec["flow"] >= 1 and rec["n_cuts"] >= 1 and rec["cut_digest"]
    assert rec["graph_s"] >= 0 and rec["solve_s"] >= 0 and rec["g_nodes"] > 0
    assert rec["ap"] == 2 and rec["attempt"] is not None


def test_a_failed_check_is_a_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    """A test that fails its independent checks is recorded as ``check-failed``, never as solved."""
    import synthesis.pipeline as pipeline
    from synthesis.model.errors import CheckFailed

    real = pipeline.check_test

    def lying_check(products, strategy, flow, **kw):  # a bypass the MILP missed
        real(products, strategy, flow, **kw)
        raise CheckFailed("synthesized test failed its checks: bypass flow is 1, not 0")

    monkeypatch.setattr(pipeline, "check_test", lying_check)
    rec = run_task(FAST[1])
    assert rec["outcome"] == "check-failed" and "bypass" in rec["message"]
    assert rec["outcome"] not in study.SOLVED


def test_command_line_writes_every_output(tmp_path: Path) -> None:
    out = tmp_path / "run"
    code = study.main(["--families", "reachability:1", "--sizes", "5", "--instances", "1", "--time-limit", "60", "--out", str(out), "-q"])
    assert code == 0
    data = json.loads((out / "results.json").read_text())
    assert [r["milp"] for r in data["records"]] == ["static", "reactive"]
    assert all(r["outcome"] == "optimal" for r in data["records"])
    csv_lines = (out / "results.csv").read_text().splitlines()
    assert len(csv_lines) == 3 and csv_lines[0].startswith("family,n,ap,size")
    table = (out / "tables.md").read_text()
    assert "| reachability | 2 | 5x5 |" in table and "static: solve s" in table and "100% (1/1)" in table
    # --resume keeps what is done and runs nothing new
    assert study.main(["--families", "reachability:1", "--sizes", "5", "--instances", "1", "--time-limit", "60", "--out", str(out), "-q", "--resume"]) == 0
    assert len((out / "records.jsonl").read_text().splitlines()) == 2
    # --report prints the tables of earlier runs without running anything
    assert study.main(["--report", str(out)]) == 0


def test_graphs_only_times_the_graphs_of_large_grids(tmp_path: Path) -> None:
    out = tmp_path / "graphs"
    assert study.main(["--graphs-only", "--families", "reaction:4", "--sizes", "20", "--instances", "1", "--out", str(out), "-q"]) == 0
    (rec,) = json.loads((out / "results.json").read_text())["records"]
    assert rec["outcome"] == "graphs" and rec["g_nodes"] > 10_000 and rec["graph_s"] < 60
    table = (out / "tables.md").read_text()
    assert "20x20: G nodes, graphs s" in table and "| reaction | 7 | " in table


def test_family_option_parsing() -> None:
    assert study.parse_specs(["reaction"]) == [("reaction", 2), ("reaction", 3), ("reaction", 4)]
    assert study.parse_specs(["safety:3", "safety:3"]) == [("safety", 3)]
    assert study.parse_specs(None) == list(PAPER_SPECS)
    with pytest.raises(SystemExit):
        study.parse_specs(["liveness"])


def test_ray_gives_the_same_answers_as_in_process() -> None:
    pytest.importorskip("ray")
    tasks = [t for t in FAST if t.instance == 3]
    local: list[dict] = []
    run_in_process(tasks, local.append)
    remote: list[dict] = []
    study.run_on_ray(tasks, remote.append, workers=1)
    key = lambda r: (r["instance"], r["milp"])  # noqa: E731
    answers = lambda rs: [tuple(r[f] for f in ANSWER_FIELDS) for r in sorted(rs, key=key)]  # noqa: E731
    assert answers(remote) == answers(local)
    assert all(r["outcome"] == "optimal" for r in local)


def test_gurobi_solves_the_same_model_to_the_same_optimum() -> None:
    pytest.importorskip("gurobipy")
    rec = run_task(Task("reachability", 1, 5, 3, "static", 60.0, 1, gurobi=True))
    assert rec["outcome"] == "optimal"
    assert rec["gurobi_outcome"] == "optimal", rec.get("gurobi_message")
    assert (rec["gurobi_flow"], rec["gurobi_n_cuts"]) == (rec["flow"], rec["n_cuts"])
    assert rec["highs1_outcome"] == "optimal"
    assert (rec["highs1_flow"], rec["highs1_n_cuts"]) == (rec["flow"], rec["n_cuts"])


def test_backend_option_reaches_the_solve(tmp_path: Path) -> None:
    """``--backend NAME`` becomes ``SynthesisOptions(backend=NAME)`` and is kept in the record;
    a FlowTest without that option refuses it with one clear error (exit code 2)."""
    from dataclasses import fields

    from synthesis.pipeline import SynthesisOptions

    if "backend" not in {f.name for f in fields(SynthesisOptions)}:
        with pytest.raises(SystemExit) as exc:
            study.main(["--backend", "highs", "--sizes", "5", "--instances", "1", "--out", str(tmp_path), "-q"])
        assert exc.value.code == 2
        return
    task = Task("reachability", 1, 5, 1, "static", 60.0, 1, backend="highs")
    rec = run_task(task)
    assert rec["outcome"] == "optimal" and rec["backend"] == "highs"
    assert rec["solver_backend"] == "highs"


def test_compare_table_puts_shares_side_by_side(tmp_path: Path) -> None:
    """``--report DIR --compare-to CSV``: per cell of the run, proven/finished per MILP, now and before."""

    def rec(i: int, milp: str, outcome: str) -> dict:
        return {"family": "reachability", "n": 1, "size": 5, "instance": i, "milp": milp, "outcome": outcome, "gurobi": False}

    now = [rec(0, "static", "optimal"), rec(1, "static", "feasible"), rec(0, "reactive", "optimal")]
    before = [rec(0, "static", "feasible"), rec(1, "static", "timeout"), rec(0, "reactive", "optimal"), {**rec(0, "static", "optimal"), "size": 10}]
    csv_path = tmp_path / "before.csv"
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=study.CSV_FIELDS, extrasaction="ignore")
        w.writeheader()
        w.writerows(before)
    table = study.compare_table(now, study.read_csv_records(csv_path))
    rows = [line for line in table.splitlines() if line.startswith("| reachability")]
    assert rows == ["| reachability | 2 | 5x5 | 0/2 (0%), solved 1 | 1/2 (50%), solved 2 | 1/1 (100%), solved 1 | 1/1 (100%), solved 1 |"]
