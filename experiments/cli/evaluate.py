"""``flowtest evaluate``: run systems under test against synthesized tests and report.

Every SUT (a policy name, :func:`agents.registry.make_policy`; your own planner as
``python:MODULE:NAME`` or ``cmd:COMMAND``, :mod:`agents.external`) plays every env for
``--episodes`` episodes; episode ``i`` uses seed ``S + i`` for both the env and the
policy, so each run can be replayed exactly with
``flowtest evaluate --env ID --sut POLICY --episodes 1 --seed S+i --replay`` (for a
``python:`` or ``cmd:`` planner run from the directory the evaluation ran in: the replay
command starts with ``cd DIR &&``, and carries ``--step-timeout``).

A planner from outside FlowTest that crashes, hangs past ``--step-timeout`` or answers an
action the test does not allow fails that run (a SUT failure whose reason says what
happened and where); the pair stops there (its record's ``stopped`` says so) and every
other pair still runs.

Outputs in ``--out``:

* ``results.json`` — a list, one record per SUT x env: ``env``, ``sut``, ``episodes``,
  ``seed``, ``error`` (``null``, or why this SUT cannot play this env: the pair is
  reported, not run, and the others go on), ``system_objective_met_rate``, ``test_objective_realized_rate`` (among the
  runs that met the system objective; ``null`` if none did), ``violated``, ``open``,
  ``mean_restrictions``, ``mean_steps``, ``test_failures`` and ``failures`` (at most
  :data:`MAX_LISTED` listed, ``n_failures`` counts all; each with ``seed``, ``kind``,
  ``reason``, the ``verdict`` and its ``replay`` command), ``stopped`` (``null``, or why the
  pair ran fewer episodes: its planner failed).
* ``report.html`` — opens with an outcome matrix (systems x tests), then each test's
  picture and objectives, the failing runs as filmstrips with their replay commands, and
  every number (:mod:`experiments.cli.report`); ``report.md`` — the matrix and one table per
  SUT, trace pictures and replay commands.
* ``traces/*.png`` — the trace pictures and filmstrips; ``tests/*.png`` — each test at
  its start.

``--tester`` chooses who plays the test's side: ``synthesized`` (default, the synthesized
test as the single-agent env plays it) or a learned tester ``ppo:PATH``
(:mod:`agents.testers`, played through :class:`agents.testers.VersusTesterEnv`). Records
carry ``tester``, ``trapped`` (runs a tester other than the synthesized one trapped: an
unfair test, not a FlowTest bug), ``sut_failures`` (faults caught: runs the SUT failed
by itself) and ``tester_fairness`` (the tester's exhaustive check,
:func:`flowtest_env.fairness.check_tester`; with more than one tester, or another one);
with several testers the report opens with a side-by-side table.

Two kinds of failure are told apart (:mod:`experiments.cli.episodes`): a **SUT failure** (the
system objective violated, or not met within the step budget: the SUT's fault) and a
**test failure** (a FlowTest bug, reported loudly: a run that met the system objective
without realizing the test objective, or a system the test trapped).
"""

from __future__ import annotations

import argparse
import html
import json
import os
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from synthesis.model.errors import InconsistentProblem, ProblemError

from .arguments import nonnegative_int, positive_int, seconds_at_most
from .command import Command
from .episodes import Trace, make_env, make_tester_env, run_episode, sut_policy
from .exits import EXIT_CHECK_FAILED, EXIT_OK, say
from .outputs import json_safe, prepare_output_folder, write_atomically
from .report import (
    GLOSSARY,
    TestInfo,
    column_titles,
    file_key,
    fold_rows,
    outcome_class,
    render_html,
    test_infos,
    test_name,
    test_title,
)
from .trace_picture import trace_picture
from .violations import violation_of_trace

DEFAULT_STEP_TIMEOUT, MAX_STEP_TIMEOUT = 10.0, 3600.0
"""``--step-timeout``'s default and largest value (:data:`agents.external.DEFAULT_STEP_TIMEOUT`,
:data:`agents.external.MAX_STEP_TIMEOUT`, which the command line does not import before it runs)."""

REPORT_MARKER = ".flowtest-evaluation"
"""The file that marks a report folder as FlowTest's: ``--out`` refuses any other
non-empty folder unless ``--force``."""

MAX_LISTED = 20
"""How many failures a results record lists (``n_failures`` counts all)."""

EXIT_TEST_FAILED = EXIT_CHECK_FAILED
"""A test failure was found (a FlowTest bug), as ``flowtest synthesize``'s failed check."""


# --------------------------------------------------------------------------- runs


EXTERNAL_PREFIXES = ("python:", "cmd:")
"""Systems named from outside FlowTest: their names depend on the working directory."""


class EvaluationInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) during :func:`evaluate`: ``cells`` holds the (system, test) pairs
    played to the end before it, and ``total`` how many there were to play."""

    def __init__(self, cells: list[Cell], total: int) -> None:
        super().__init__()
        self.cells, self.total = cells, total


def _env_named(env_id: str, several: bool) -> Any:
    """:func:`make_env`; among several envs, an inconsistent problem's message names which."""
    try:
        return make_env(env_id)
    except InconsistentProblem as exc:
        if not several:
            raise
        raise InconsistentProblem(exc.reason, str(exc), source=f"--env {env_id}") from None


def replay_command(env_id: str, sut: str, seed: int, tester: str = "synthesized", step_timeout: float | None = None,
                   cwd: str | None = None, trust_model: bool = False) -> str:
    """The command that replays one run exactly (shell-quoted: a model path may hold spaces).

    A ``python:`` or ``cmd:`` planner is found from the directory the evaluation ran in
    (``cwd``, default the current one): its command starts with ``cd DIR &&``, and
    carries ``--step-timeout`` when one was given. With
    ``trust_model`` (the evaluation loaded stable-baselines3 zips, ``--trust-model``) a
    ``ppo:`` system or tester's command carries ``--trust-model`` too."""
    against = "" if tester == "synthesized" else f" --tester {shlex.quote(tester)}"
    timeout = f" --step-timeout {step_timeout:g}" if step_timeout is not None and sut.startswith(("cmd:", "python:")) else ""
    trust = " --trust-model" if trust_model and (sut.startswith("ppo:") or tester.startswith("ppo:")) else ""
    command = (f"flowtest evaluate --env {shlex.quote(env_id)} --sut {shlex.quote(sut)}{against}{timeout}{trust} "
               f"--episodes 1 --seed {seed} --replay")
    if sut.startswith(EXTERNAL_PREFIXES):
        return f"cd {shlex.quote(cwd or os.getcwd())} && {command}"
    return command


def _models_trusted() -> bool:
    """Whether this process loads stable-baselines3 zips (``--trust-model``)."""
    from agents.checkpoint import pickled_models_trusted

    return pickled_models_trusted()


NOT_REPLAYABLE = ("# no replay command: this system was given to evaluate() as a Python object; "
                  "name it python:MODULE:NAME to get one")


def sut_label(sut: Any) -> str:
    """The name a system under test goes by in records and reports: its name, or for a
    Python object the ``python:MODULE:NAME`` that names it (:func:`agents.external.spec_of`),
    its ``name`` attribute, or its type."""
    if isinstance(sut, str):
        return sut
    from agents.external import spec_of

    name = getattr(sut, "name", None)
    if isinstance(name, str) and name:
        return name
    return spec_of(sut) or f"python object {getattr(sut, '__qualname__', type(sut).__name__)}"


def tester_fairness(env_id: str, tester: str) -> dict[str, Any] | None:
    """The exhaustive fairness check of ``tester`` on ``env_id``'s game
    (:func:`flowtest_env.fairness.check_tester`), ``None`` for an env without one fixed game."""
    from agents.base import PolicyError
    from agents.testers import VersusTesterEnv, problem_of
    from flowtest_env.fairness import check_tester

    try:
        problem, _ = problem_of(env_id)
        env = VersusTesterEnv(problem, tester)
    except PolicyError:
        return None
    return check_tester(env.ma, env.tester).summary()


@dataclass
class Cell:
    """The results of one SUT on one env."""

    env_id: str
    sut: str
    traces: list[Trace]
    seed: int
    seconds: float
    pictures: dict[str, str] = field(default_factory=dict)
    tester: str = "synthesized"
    fairness: dict[str, Any] | None = None
    error: str | None = None  # why this SUT cannot play this env (no runs then)
    stopped: str | None = None  # why fewer runs than asked (the planner failed)
    replayable: bool = True  # False for a system given as a Python object without a name
    step_timeout: float | None = None
    problem: str = ""  # the test's problem name, for a report written without the tests' pictures
    cwd: str = field(default_factory=os.getcwd)
    trust_model: bool = field(default_factory=lambda: _models_trusted())

    def replay(self, trace: Trace) -> str:
        """The replay command of one of this cell's runs."""
        if not self.replayable:
            return NOT_REPLAYABLE
        return replay_command(trace.env_id, self.sut, trace.seed, self.tester, self.step_timeout, self.cwd,
                              self.trust_model)

    def record(self) -> dict[str, Any]:
        """The ``results.json`` record (``error`` says why a pair has no runs)."""
        n = len(self.traces)
        met = [t for t in self.traces if t.verdict["system_objective"] == "met"]
        fails = [t for t in self.traces if t.failed]
        return {
            "env": self.env_id,
            "sut": self.sut,
            "episodes": n,
            "seed": self.seed,
            "system_objective_met_rate": len(met) / n if n else None,
            "test_objective_realized_rate": (
                sum(t.verdict["test_objective_realized"] for t in met) / len(met) if met else None
            ),
            "violated": sum(t.verdict["system_objective"] == "violated" for t in self.traces),
            "open": sum(t.verdict["system_objective"] == "open" for t in self.traces),
            "mean_restrictions": float(np.mean([t.verdict["restrictions"] for t in self.traces])) if n else None,
            "mean_steps": float(np.mean([t.verdict["steps"] for t in self.traces])) if n else None,
            "test_failures": sum(t.kind == "test" for t in self.traces),
            "tester": self.tester,
            "trapped": sum(t.kind == "trap" for t in self.traces),
            "sut_failures": sum(t.kind == "sut" for t in self.traces),
            "tester_fairness": self.fairness,
            "n_failures": len(fails),
            "failures": [
                {
                    "seed": t.seed,
                    "kind": t.kind,
                    "reason": t.reason,
                    "verdict": t.verdict,
                    "replay": self.replay(t),
                    "violation": violation_of_trace(t),
                }
                for t in fails[:MAX_LISTED]
            ],
            "pictures": self.pictures,
            "seconds": round(self.seconds, 3),
            "error": self.error,
            "stopped": self.stopped,
        }


def check_sut_names(suts: Sequence[Any]) -> None:
    """Reject a SUT name no factory knows (a typo), a ``python:`` module or name that is
    missing, or a ``cmd:`` program that is not found, before anything runs (Python
    objects are checked when they are built).

    Raises
    ------
    ProblemError
        On an unknown or unusable name.
    """
    from agents.base import PolicyError
    from agents.external import check_spec
    from agents.registry import KNOWN, policy_names
    from agents.scripted import SCRIPTED

    known = set(policy_names())
    for sut in suts:
        if not isinstance(sut, str):
            continue
        prefix, _, arg = sut.strip().partition(":")
        if prefix not in known:
            raise ProblemError(f"--sut {sut}: unknown policy; known: {KNOWN}")
        if prefix == "scripted" and (arg or "replanner") not in SCRIPTED:
            raise ProblemError(f"--sut {sut}: unknown scripted SUT {arg!r}; known: {', '.join(SCRIPTED)}")
        try:
            check_spec(prefix, arg)
        except PolicyError as exc:
            raise ProblemError(f"--sut {sut}: {exc}") from None


def evaluate(
    env_ids: Sequence[str],
    suts: Sequence[Any],
    episodes: int,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    testers: Sequence[str] = ("synthesized",),
    step_timeout: float | None = None,
) -> list[Cell]:
    """Run every SUT against every env (``episodes`` seeded runs each), once per tester
    (``synthesized``: the synthesized test; ``ppo:PATH``: a learned tester,
    :mod:`agents.testers`). With more than one tester, every cell also carries the
    tester's exhaustive fairness check on the env's game. Each (SUT, test) pair runs on its
    own: a SUT that cannot play an env (a model trained on another observation shape, a
    graph for a grid policy) gives a :class:`Cell` with the reason in ``error``, and a
    planner that fails a run (crashes, hangs past ``step_timeout``, answers an action the
    test does not allow) stops its pair with that run as a failure; the others go on.

    A SUT is a name (``"scripted:replanner"``, ``"python:my_planner:Bfs"``,
    ``"cmd:python3 planner.py"``) or a Python object: a :class:`agents.base.Policy`, or
    a planner (a function ``act(observation, mask)``, a class or factory of planners;
    :mod:`agents.external`).

    Raises
    ------
    ProblemError
        Before anything runs, if an env or a SUT name is invalid input (not a test, an
        unknown policy, a missing module or program), or ``episodes < 1``.
    EvaluationInterrupted
        On Ctrl-C (a ``KeyboardInterrupt``), with the pairs played to the end.

    Examples
    --------
    >>> from experiments.cli.evaluate import evaluate
    >>> def greedy(observation, mask):
    ...     return observation["allowed"][0]
    >>> cells = evaluate(["small-reactive"], [greedy, "scripted:replanner"], episodes=3)
    >>> [(cell.sut, cell.record()["system_objective_met_rate"]) for cell in cells]
    [('python object greedy', 0.0), ('scripted:replanner', 1.0)]
    """
    if episodes < 1:
        raise ProblemError("--episodes must be at least 1")
    check_sut_names(suts)
    envs = {env_id: _env_named(env_id, len(env_ids) > 1) for env_id in dict.fromkeys(env_ids)}
    cells: list[Cell] = []
    for env in envs.values():
        env.close()
    total = len(envs) * len(suts) * len(testers)
    try:
        _play(envs, suts, testers, episodes, seed, progress, step_timeout, cells, total)
    except KeyboardInterrupt:
        raise EvaluationInterrupted(cells, total) from None
    return cells


def _play(envs: dict[str, Any], suts: Sequence[Any], testers: Sequence[str], episodes: int, seed: int,
          progress: Callable[[str], None] | None, step_timeout: float | None, cells: list[Cell], total: int) -> None:
    """:func:`evaluate`'s loop: each pair played to the end is appended to ``cells``."""
    from agents.base import PolicyError, game_of
    from agents.external import spec_of
    from agents.registry import make_policy

    k = 0
    for env_id in envs:
        for tester in testers:
            env = make_tester_env(env_id, tester)
            problem = str(game_of(env).artifact.name)
            fairness = tester_fairness(env_id, tester) if len(testers) > 1 or tester != "synthesized" else None
            against = "" if tester == "synthesized" else f" against {tester}"
            for sut in suts:
                k += 1
                label = sut_label(sut)
                replayable = isinstance(sut, str) or (label.startswith("python:") and label == spec_of(sut))
                cell = Cell(env_id, label, [], seed, 0.0, tester=tester, fairness=fairness, replayable=replayable,
                            step_timeout=step_timeout, problem=problem)
                t0 = time.perf_counter()
                try:
                    policy = make_policy(sut, env, step_timeout=step_timeout)
                except PolicyError as exc:
                    cell.error, cell.seconds = str(exc), time.perf_counter() - t0
                    cells.append(cell)
                    if progress is not None:
                        progress(f"[{k}/{total}] {label} on {env_id}{against}: cannot play it: {exc}")
                    continue
                try:
                    for i in range(episodes):
                        trace = run_episode(env, policy, env_id, label, seed + i, tester=tester)
                        cell.traces.append(trace)
                        if trace.planner_error:
                            cell.stopped = (f"the planner failed in run {i + 1} of {episodes} (seed {seed + i}); "
                                            f"the other runs were not played: {trace.planner_error}")
                            if progress is not None:
                                progress(f"[{k}/{total}] {label} on {env_id}{against}: the planner failed: "
                                         f"{trace.planner_error}")
                            break
                        if progress is not None and (i + 1 == episodes or (i + 1) % max(1, episodes // 10) == 0):
                            progress(f"[{k}/{total}] {label} on {env_id}{against}: {i + 1}/{episodes} episodes")
                finally:
                    close = getattr(policy, "close", None)
                    if callable(close) and policy is not sut:
                        close()
                cell.seconds = time.perf_counter() - t0
                cells.append(cell)
            env.close()


# --------------------------------------------------------------------------- pictures


# --------------------------------------------------------------------------- reports


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def _filmstrip(trace: Trace, path: Path) -> None:
    from .filmstrip import filmstrip

    env = make_env(trace.env_id)
    game = env.unwrapped.game
    env.close()
    v = trace.verdict
    title = (f"{trace.sut} on {test_title(trace.env_id, str(game.artifact.name))}, seed {trace.seed}: {trace.reason or v['system_objective']} "
             f"(system objective {v['system_objective']}, {v['steps']} steps)")
    filmstrip(game, trace.states, trace.actions, title, path)


def write_report(cells: Sequence[Cell], out: Path, tests: Sequence[TestInfo] | None = None) -> list[dict[str, Any]]:
    """Write ``results.json``, ``report.md``, ``report.html``, the trace pictures and
    filmstrips (``traces/``) and a picture of each test (``tests/``).

    A cell may gather runs of several tests (``flowtest benchmark``: one cell per system
    and pool split): each run's picture and replay command use the run's own
    ``Trace.env_id``, and ``tests`` then describes the cells' columns (default: one
    :class:`TestInfo` per cell ``env_id``, drawn by :func:`test_infos`)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "traces").mkdir(exist_ok=True)
    for cell in cells:
        cell_name = test_name({"env": cell.env_id, "tester": cell.tester})
        typical = next((t for t in cell.traces if not t.failed), None)
        failing = next((t for t in cell.traces if t.failed), None)
        for label, tr in (("typical", typical), ("failing", failing)):
            if tr is None:
                continue
            name = f"traces/{file_key(cell.sut)}--{file_key(cell_name)}--{label}.png"
            write_atomically(out / name, partial(trace_picture, tr))
            cell.pictures[label] = name
        if failing is not None:
            name = f"traces/{file_key(cell.sut)}--{file_key(cell_name)}--filmstrip.png"
            write_atomically(out / name, partial(_filmstrip, failing))
            cell.pictures["filmstrip"] = name
    if tests is None:
        tests = test_infos(list(dict.fromkeys(c.env_id for c in cells)), out)
    records = _write_results(cells, out, tests)
    md, body = _markdown(records), render_html(records, tests, (TESTER_COLUMNS, tester_comparison_rows(records)))
    write_atomically(out / "report.md", lambda tmp: tmp.write_text(md))
    write_atomically(out / "report.html", lambda tmp: tmp.write_text(body))
    return records


def _write_results(cells: Sequence[Cell], out: Path, tests: Sequence[TestInfo] = (), **extra: Any) -> list[dict[str, Any]]:
    """The cells' records, each with the ``title`` the report calls its test (its problem's
    name, next to its env ID) and ``extra``, written to ``results.json``."""
    records = [{**cell.record(), **extra} for cell in cells]
    titles = column_titles(records, tests, problems={c.env_id: c.problem for c in cells if c.problem})
    for r in records:
        r["title"] = titles[test_name(r)]
    write_atomically(out / "results.json", lambda tmp: tmp.write_text(json.dumps(json_safe(records), indent=1) + "\n"))
    return records


def write_partial_report(cells: Sequence[Cell], out: Path) -> list[dict[str, Any]]:
    """``results.json`` and ``report.md`` of the pairs an interrupted evaluation played, at
    once: no pictures and no ``report.html``, whose drawing would outlast a Ctrl-C."""
    records = _write_results(cells, out, interrupted=True)
    md = (_markdown(records, "FlowTest evaluation (interrupted: the pairs played)") if records
          else "# FlowTest evaluation (interrupted before any pair was played to the end)\n")
    write_atomically(out / "report.md", lambda tmp: tmp.write_text(md))
    (out / "report.html").unlink(missing_ok=True)  # an earlier run's, which would now disagree with them
    return records


def test_failure_records(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records with a test failure (a FlowTest bug)."""
    return [r for r in records if r["test_failures"]]


def _fair_text(f: dict[str, Any] | None) -> str:
    if f is None:
        return "–"
    return "fair" if f["fair"] else f"{f['traps']} trap states"


def tester_comparison_rows(records: Sequence[dict[str, Any]]) -> list[list[str]]:
    """Rows of the testers-side-by-side table (empty unless more than one tester): per
    env, tester and SUT, the test objective realized among successful runs, trapped runs,
    faults caught (runs the SUT failed by itself), mean restrictions, and the tester's
    exhaustive checks (fair: no reachable trap; guaranteed: no run meets the goal without
    the test objective)."""
    testers = list(dict.fromkeys(r.get("tester", "synthesized") for r in records))
    if len(testers) < 2:
        return []
    rows = []
    for r in records:
        f = r.get("tester_fairness")
        guaranteed = "–" if f is None else ("yes" if f["guaranteed"] else "no")
        rows.append([
            r["env"], r.get("tester", "synthesized"), r["sut"], str(r["episodes"]),
            _pct(r["test_objective_realized_rate"]), str(r.get("trapped", 0)), str(r.get("sut_failures", 0)),
            f"{r['mean_restrictions']:.1f}", _fair_text(f), guaranteed,
        ])
    return rows


TESTER_COLUMNS = ["test", "tester", "system", "runs", "realized (among met)", "trapped runs", "faults caught",
                  "restrictions", "fairness (exhaustive)", "guaranteed (exhaustive)"]


def tester_comparison_markdown(records: Sequence[dict[str, Any]]) -> list[str]:
    """The testers-side-by-side section of ``report.md`` (no lines for one tester)."""
    rows = tester_comparison_rows(records)
    if not rows:
        return []
    lines = ["## Testers side by side", "",
             "Realized: share of the runs meeting the system objective that realized the test objective. Trapped: "
             "runs that ended where no system play could still meet the objective against the tester (an unfair "
             "test). Faults caught: runs the system failed by itself. Fairness and guarantee are decided by an "
             "exhaustive search over the tester's choices and all system moves (`flowtest_env.fairness`).", "",
             "| " + " | ".join(TESTER_COLUMNS) + " |", "|" + "---|" * len(TESTER_COLUMNS)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines + [""]


def _markdown(records: Sequence[dict[str, Any]], heading: str = "FlowTest evaluation") -> str:
    lines = [f"# {heading}", ""]
    bugs = test_failure_records(records)
    if bugs:
        lines += ["> **FLOWTEST BUG: a test failed its guarantee.** A run met the system objective without "
                  "realizing the test objective, or the test trapped the system. Please report it with the "
                  "replay commands below.", ""]
        for r in bugs:
            for f in r["failures"]:
                if f["kind"] == "test":
                    lines.append(f"- {r['sut']} on {r['title']}: {f['reason']} — `{f['replay']}`")
        lines.append("")
    envs = list(dict.fromkeys(test_name(r) for r in records))
    by = {(r["sut"], test_name(r)): r for r in records}
    title = {test_name(r): r["title"] for r in records}
    lines += ["| system under test | " + " | ".join(title[e] for e in envs) + " |", "|---" * (len(envs) + 1) + "|"]
    for group in fold_rows(records, envs):
        cells = []
        for env in envs:
            found = by.get((group[0], env))
            if found is None:
                cells.append("–")
                continue
            if found["error"]:
                cells.append("not run (see below)")
                continue
            met = round((found["system_objective_met_rate"] or 0) * found["episodes"])
            cells.append(f"{met}/{found['episodes']} met ({outcome_class(found)})")
        lines.append(f"| {', '.join(group)} | " + " | ".join(cells) + " |")
    lines.append("")
    lines += [f"- **{word}**: {html.unescape(text).replace('<b>', '').replace('</b>', '')}" for word, text in GLOSSARY]
    lines.append("")
    lines += [
        "System objective met: share of runs; test objective realized: share of the runs that met the "
        "system objective (the test guarantees 100 %). Restrictions: mean number of decisions taken "
        "with a restricted move. A failure is the SUT's unless marked *test*.",
        "",
    ]
    lines += tester_comparison_markdown(records)
    for sut in dict.fromkeys(r["sut"] for r in records):
        lines += [f"## {sut}", "", "| test | runs | met | realized | violated | open | restrictions | steps | failures |",
                  "|---|---|---|---|---|---|---|---|---|"]
        rows = [r for r in records if r["sut"] == sut]
        for r in rows:
            if r["error"]:
                lines.append(f"| {r['title']} | 0 | not run: {r['error']} |  |  |  |  |  |  |")
                continue
            lines.append(
                f"| {r['title']} | {r['episodes']} | {_pct(r['system_objective_met_rate'])} "
                f"| {_pct(r['test_objective_realized_rate'])} | {r['violated']} | {r['open']} "
                f"| {r['mean_restrictions']:.1f} | {r['mean_steps']:.1f} | {r['n_failures']}"
                f"{' (' + str(r['test_failures']) + ' test)' if r['test_failures'] else ''} |"
            )
        lines.append("")
        for r in rows:
            pics = r["pictures"]
            if r.get("stopped"):
                lines += [f"**{r['title']}** — stopped: {r['stopped']}", ""]
            if r["failures"]:
                f = r["failures"][0]
                lines += [f"**{r['title']}** — first failure ({f['kind']}): {f['reason']}. Replay:", "",
                          f"    {f['replay']}", ""]
            for label in ("typical", "failing"):
                if label in pics:
                    lines.append(f"![{label} run of {sut} on {r['title']}]({pics[label]})")
            lines.append("")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``flowtest evaluate``'s arguments."""
    p.add_argument("--env", nargs="+", required=True, metavar="ENV",
                   help="environments: registered IDs (FlowTest-Maze2-v0), built-in names (maze2), problem files "
                        "(mine.toml, synthesized once and cached) or artifact files (flowtest synthesize --out)")
    p.add_argument("--sut", nargs="+", required=True, metavar="POLICY",
                   help="systems under test: scripted:replanner, scripted:committed, scripted:fuel-blind, "
                        "scripted:greedy, random, gr1, ppo:PATH; your own planner: python:MODULE:NAME (a function "
                        "act(observation, mask) or a factory, found from the current directory) or "
                        "cmd:\"COMMAND\" (a process speaking JSON lines; docs/runtime.md)")
    p.add_argument("--step-timeout", type=seconds_at_most(MAX_STEP_TIMEOUT), default=None, metavar="SECONDS",
                   help="how long a cmd: or python: planner may take to answer one step (default "
                        f"{DEFAULT_STEP_TIMEOUT:g}, at most {MAX_STEP_TIMEOUT:g}; a cmd: planner's first answer includes its start)")
    p.add_argument("--tester", nargs="+", default=["synthesized"], metavar="TESTER",
                   help="who plays the test: synthesized (default), ppo:PATH (a learned tester, flowtest "
                        "train-tester); several give a side-by-side comparison")
    p.add_argument("--episodes", type=positive_int, default=10, help="runs per SUT and env (default 10)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the first run; run i uses seed+i (default 0)")
    p.add_argument("--out", type=Path, help="report folder (required unless --replay); a folder holding files "
                   "FlowTest did not write is refused unless --force")
    p.add_argument("--force", action="store_true", help="write into an --out folder that holds other files")
    p.add_argument("--replay", action="store_true", help="print every step of the runs instead of a report")
    p.add_argument("--trust-model", action="store_true",
                   help="load stable-baselines3 model zips (--sut ppo:PATH, --tester ppo:PATH), which unpickles them: "
                        "code from the file runs; native FlowTest checkpoints never need it")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def replay(env_id: str, sut: str, seed: int, stream: Any = None, tester: str = "synthesized",
           step_timeout: float | None = None) -> Trace:
    """Replay one run and print it step by step (state, legal actions, action, verdict)
    to ``stream`` (standard output by default)."""
    stream = sys.stdout if stream is None else stream
    env = make_tester_env(env_id, tester)
    policy = sut_policy(sut, env, step_timeout)
    try:
        trace = run_episode(env, policy, env_id, sut, seed, tester=tester)
    finally:
        close = getattr(policy, "close", None)
        if callable(close):
            close()
    game = env.unwrapped.game
    against = "" if tester == "synthesized" else f" against tester {tester}"
    stream.write(f"{sut} on {env_id}{against}, seed {seed}\n")
    for k, a in enumerate(trace.actions):
        r = trace.states[k]
        mask = game.action_mask(r)
        legal = ",".join(game.action_name(r.system, i) for i in np.flatnonzero(mask))
        stream.write(f"step {k:3d}  {json.dumps(game.state_json(r.system))}  legal [{legal}]  -> {game.action_name(r.system, a)}\n")
    stream.write(f"verdict: {json.dumps(trace.verdict)}\n")
    stream.write(f"outcome: {trace.kind}{': ' + trace.reason if trace.reason else ''}\n")
    env.close()
    return trace


def run(args: argparse.Namespace) -> int:
    """Evaluate (or replay); exit 4 if a test failed its guarantee (a FlowTest bug)."""
    if args.trust_model:
        from agents.checkpoint import trust_pickled_models

        trust_pickled_models(True)
    if args.replay:
        bug = False
        for env_id in args.env:
            for tester in args.tester:
                for sut in args.sut:
                    for i in range(args.episodes):
                        trace = replay(env_id, sut, args.seed + i, tester=tester, step_timeout=args.step_timeout)
                        bug |= trace.kind == "test"
        return EXIT_TEST_FAILED if bug else EXIT_OK
    if args.out is None:
        raise ProblemError("--out is required (or use --replay)")
    # refuse bad IDs and SUTs before any run or any file: a SUT that can play none of the
    # tests is bad input (a missing model, a typo); one that cannot play some is a report row
    check_sut_names(args.sut)
    envs = [_env_named(env_id, len(args.env) > 1) for env_id in dict.fromkeys(args.env)]
    for sut in args.sut:
        first: ProblemError | None = None
        for env in envs:
            try:
                close = getattr(sut_policy(sut, env, args.step_timeout), "close", None)
                if callable(close):
                    close()
                break
            except ProblemError as exc:
                first = first or exc
        else:
            assert first is not None
            raise first
    for env in envs:
        env.close()
    prepare_output_folder(args.out, REPORT_MARKER, args.force, "report folder")

    def progress(msg: str) -> None:
        if not args.quiet:
            sys.stderr.write(msg + "\n")
            sys.stderr.flush()

    try:
        cells = evaluate(args.env, args.sut, args.episodes, args.seed, progress, testers=args.tester,
                         step_timeout=args.step_timeout)
    except EvaluationInterrupted as stop:
        # keep the pairs played: results.json and report.md at once (no pictures); none played,
        # they say so (an earlier run's files would otherwise look current)
        write_partial_report(stop.cells, args.out)
        if stop.cells:
            say(f"flowtest: {len(stop.cells)} of {stop.total} (system, test) pairs were played to the end; "
                f"{args.out / 'results.json'} and report.md hold them (no pictures, no report.html)")
        else:
            say(f"flowtest: no (system, test) pair was played to the end; {args.out / 'results.json'} and report.md "
                "say so")
        raise
    progress("drawing trace pictures")
    records = write_report(cells, args.out)
    # the tests as given on the command line (--env), columns as wide as the longest name
    w_sut = max([24, *(len(r["sut"]) for r in records)])
    w_test = max([30, *(len(test_name(r)) for r in records)])
    for r in records:
        if r["error"]:
            sys.stdout.write(f"{r['sut']:{w_sut}s} {test_name(r):{w_test}s} not run: {r['error']}\n")
            continue
        trapped = f"  trapped {r['trapped']}" if r["tester"] != "synthesized" else ""
        sys.stdout.write(
            f"{r['sut']:{w_sut}s} {test_name(r):{w_test}s} met {_pct(r['system_objective_met_rate']):>6s}  "
            f"realized {_pct(r['test_objective_realized_rate']):>6s}  failures {r['n_failures']}{trapped}\n"
        )
        if r["stopped"]:
            sys.stdout.write(f"{'':{w_sut}s} stopped: {r['stopped']}\n")
    bugs = test_failure_records(records)
    if bugs:
        sys.stderr.write("flowtest: FLOWTEST BUG: a test failed its guarantee; see the report\n")
    sys.stdout.write(f"report: {(args.out / 'report.html').resolve()}\n")
    return EXIT_TEST_FAILED if bugs else EXIT_OK


COMMAND = Command("evaluate", "run systems under test against synthesized tests and write a report", add_arguments, run)
