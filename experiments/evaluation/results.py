"""The results of an evaluation, written: ``results.json``, ``report.md``, ``report.html``.

:func:`write_report` writes everything a finished evaluation (:func:`experiments.evaluation.evaluate`)
shows; :func:`write_partial_report` what an interrupted one played, at once. The files in the
report folder:

* ``results.json`` — a list, one record per SUT x env (:meth:`~experiments.evaluation.runs.Cell.record`):
  ``env``, ``sut``, ``episodes``, ``seed``, ``error`` (``null``, or why this SUT cannot play this
  env: the pair is reported, not run, and the others go on), ``system_objective_met_rate``,
  ``test_objective_realized_rate`` (among the runs that met the system objective; ``null`` if
  none did), ``violated``, ``open``, ``mean_restrictions``, ``mean_steps``, ``test_failures``
  and ``failures`` (at most :data:`~experiments.evaluation.runs.MAX_LISTED` listed,
  ``n_failures`` counts all; each with ``seed``, ``kind``, ``reason``, the ``verdict``, its
  ``replay`` command, the ``violation`` (a violated run: conjunct, step, cell) and its
  ``explanation``: what the run did in the floor's terms, :mod:`~experiments.evaluation.explain`),
  ``outcomes`` (every failing run, one entry per way of failing: its ``line``, ``seeds``,
  ``kind`` and the ``replay`` command of its first seed), ``stopped`` (``null``, or why the
  pair ran fewer episodes: its planner failed), ``tester``, ``trapped``, ``sut_failures``,
  ``tester_fairness``, and the ``title`` the report calls its test.
* ``report.html`` — opens with an outcome matrix (systems x tests), then each test's
  picture and objectives, the failing runs (one line per way of failing, with its seeds and a
  replay command, a filmstrip of the first) and every number
  (:mod:`experiments.evaluation.report`); ``report.md`` — the matrix and one table per SUT,
  the failing runs' lines, trace pictures and replay commands.
* ``traces/*.png`` — the trace pictures and filmstrips; ``tests/*.png`` — each test at
  its start.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from functools import partial
from pathlib import Path
from typing import Any

from experiments.formatting import percent
from experiments.outputs import json_safe, write_atomically

from .episodes import Trace, game_of_trace
from .report import (
    GLOSSARY,
    TestInfo,
    column_titles,
    file_key,
    fold_rows,
    outcome_class,
    outcomes_of,
    render_html,
    test_infos,
    test_name,
    test_title,
)
from .runs import Cell
from .trace_picture import trace_picture

REPORT_MARKER = ".flowtest-evaluation"
"""The file that marks a report folder as FlowTest's: ``flowtest evaluate --out`` refuses any
other non-empty folder unless ``--force``
(:func:`experiments.outputs.prepare_output_folder`)."""


def _filmstrip_to(trace: Trace, colours: dict[str, tuple[int, int, int]], path: Path) -> None:
    from .explain import explain
    from .filmstrip import filmstrip

    game = game_of_trace(trace)
    v = trace.verdict
    title = (
        f"{trace.sut} on {test_title(trace.env_id, str(game.artifact.name))}, seed {trace.seed}: "
        f"system objective {v['system_objective']} after {v['steps']} steps"
    )
    why = explain(trace, game)
    filmstrip(game, trace.states, trace.actions, title, path, colours=colours, loop=why.loop, explanation="" if why.what == "violation" else why.text)


def _picture(trace: Trace, colours: dict[str, tuple[int, int, int]], path: Path) -> None:
    from .explain import explain

    trace_picture(trace, path, colours, explain(trace).text if trace.failed else "")


def report_colours(cells: Sequence[Cell]) -> dict[str, tuple[int, int, int]]:
    """One colour per proposition name over every test the cells played
    (:func:`flowtest_env.render.proposition_colours`): every picture of the report takes
    it, so a proposition keeps its colour from test to test."""
    from flowtest_env.render import all_propositions, proposition_colours

    names: set[str] = set()
    for cell in cells:
        games = {id(t.game): t.game for t in cell.traces if t.game is not None}
        if cell.test is not None:
            games[id(cell.test.game)] = cell.test.game
        for game in games.values():
            names.update(all_propositions(game))
    return proposition_colours(names)


def write_report(cells: Sequence[Cell], out: Path, tests: Sequence[TestInfo] | None = None) -> list[dict[str, Any]]:
    """Write ``results.json``, ``report.md``, ``report.html``, the trace pictures and
    filmstrips (``traces/``) and a picture of each test (``tests/``).

    A cell may gather runs of several tests (``flowtest benchmark``: one cell per system
    and pool split): each run's picture and replay command use the run's own
    ``Trace.env_id`` (and the game it was played on), and ``tests`` then describes the cells'
    columns (default: one :class:`TestInfo` per cell ``env_id``, drawn by :func:`test_infos`
    from the test each cell played). Returns the ``results.json`` records.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from experiments.evaluation import evaluate, write_report
    >>> cells = evaluate(["small-reactive"], ["scripted:replanner", "scripted:committed"], episodes=2)
    >>> out = Path(tempfile.mkdtemp()) / "report"
    >>> records = write_report(cells, out)
    >>> [(r["sut"], r["system_objective_met_rate"], r["n_failures"]) for r in records]
    [('scripted:replanner', 1.0, 0), ('scripted:committed', 0.0, 2)]
    >>> sorted(p.name for p in out.iterdir() if p.is_file()), sorted(records[1]["pictures"])
    (['report.html', 'report.md', 'results.json'], ['failing', 'filmstrip'])
    """
    out.mkdir(parents=True, exist_ok=True)
    (out / "traces").mkdir(exist_ok=True)
    colours = report_colours(cells)
    for cell in cells:
        cell_name = test_name({"env": cell.env_id, "tester": cell.tester})
        typical = next((t for t in cell.traces if not t.failed), None)
        failing = next((t for t in cell.traces if t.failed), None)
        for label, tr in (("typical", typical), ("failing", failing)):
            if tr is None:
                continue
            name = f"traces/{file_key(cell.sut)}--{file_key(cell_name)}--{label}.png"
            write_atomically(out / name, partial(_picture, tr, colours))
            cell.pictures[label] = name
        if failing is not None:
            name = f"traces/{file_key(cell.sut)}--{file_key(cell_name)}--filmstrip.png"
            write_atomically(out / name, partial(_filmstrip_to, failing, colours))
            cell.pictures["filmstrip"] = name
    if tests is None:
        tests = test_infos(list({c.env_id: c.test or c.env_id for c in cells}.values()), out, colours)
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
    md = (
        _markdown(records, "FlowTest evaluation (interrupted: the pairs played)")
        if records
        else "# FlowTest evaluation (interrupted before any pair was played to the end)\n"
    )
    write_atomically(out / "report.md", lambda tmp: tmp.write_text(md))
    (out / "report.html").unlink(missing_ok=True)  # an earlier run's, which would now disagree with them
    return records


LISTED_OUTCOMES = 3
"""How many ways of failing :func:`outcome_lines` prints under a pair (the report has all)."""


def outcome_lines(records: Sequence[dict[str, Any]]) -> list[str]:
    """One line per (system, test) pair: met and realized shares and failures, or why the
    pair was not run, and why it stopped early; under a pair with failing runs, what they
    did, runs alike folded (``seeds 0-9 (10 runs): from step 2 on, alternates between ...``,
    at most :data:`LISTED_OUTCOMES`); what ``flowtest evaluate`` prints. The
    columns are as wide as the longest system and test name (the tests as given, ``--env``)."""
    names = [test_name(r) for r in records]
    w_sut = max([24, *(len(r["sut"]) for r in records)])
    w_test = max([30, *(len(n) for n in names)])
    lines = []
    for r, name in zip(records, names, strict=True):
        if r["error"]:
            lines.append(f"{r['sut']:{w_sut}s} {name:{w_test}s} not run: {r['error']}")
            continue
        trapped = f"  trapped {r['trapped']}" if r["tester"] != "synthesized" else ""
        lines.append(
            f"{r['sut']:{w_sut}s} {name:{w_test}s} met {percent(r['system_objective_met_rate']):>6s}  "
            f"realized {percent(r['test_objective_realized_rate']):>6s}  failures {r['n_failures']}{trapped}"
        )
        ways = outcomes_of(r)
        lines += [f"{'':{w_sut}s} {o['line']}" for o in ways[:LISTED_OUTCOMES]]
        if len(ways) > LISTED_OUTCOMES:
            more = len(ways) - LISTED_OUTCOMES
            lines.append(f"{'':{w_sut}s} ... {more} more way{'' if more == 1 else 's'} of failing: see the report")
        if r["stopped"]:
            lines.append(f"{'':{w_sut}s} stopped: {r['stopped']}")
    return lines


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
        rows.append(
            [
                r["env"],
                r.get("tester", "synthesized"),
                r["sut"],
                str(r["episodes"]),
                percent(r["test_objective_realized_rate"]),
                str(r.get("trapped", 0)),
                str(r.get("sut_failures", 0)),
                f"{r['mean_restrictions']:.1f}",
                _fair_text(f),
                guaranteed,
            ]
        )
    return rows


TESTER_COLUMNS = [
    "test",
    "tester",
    "system",
    "runs",
    "realized (among met)",
    "trapped runs",
    "faults caught",
    "restrictions",
    "fairness (exhaustive)",
    "guaranteed (exhaustive)",
]


def tester_comparison_markdown(records: Sequence[dict[str, Any]]) -> list[str]:
    """The testers-side-by-side section of ``report.md`` (no lines for one tester)."""
    rows = tester_comparison_rows(records)
    if not rows:
        return []
    lines = [
        "## Testers side by side",
        "",
        "Realized: share of the runs meeting the system objective that realized the test objective. Trapped: "
        "runs that ended where no system play could still meet the objective against the tester (an unfair "
        "test). Faults caught: runs the system failed by itself. Fairness and guarantee are decided by an "
        "exhaustive search over the tester's choices and all system moves (`flowtest_env.fairness`).",
        "",
        "| " + " | ".join(TESTER_COLUMNS) + " |",
        "|" + "---|" * len(TESTER_COLUMNS),
    ]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines + [""]


def _markdown(records: Sequence[dict[str, Any]], heading: str = "FlowTest evaluation") -> str:
    lines = [f"# {heading}", ""]
    bugs = test_failure_records(records)
    if bugs:
        lines += [
            "> **FLOWTEST BUG: a test failed its guarantee.** A run met the system objective without "
            "realizing the test objective, or the test trapped the system. Please report it with the "
            "replay commands below.",
            "",
        ]
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
        lines += [
            f"## {sut}",
            "",
            "| test | runs | met | realized | violated | open | restrictions | steps | failures |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        rows = [r for r in records if r["sut"] == sut]
        for r in rows:
            if r["error"]:
                lines.append(f"| {r['title']} | 0 | not run: {r['error']} |  |  |  |  |  |  |")
                continue
            lines.append(
                f"| {r['title']} | {r['episodes']} | {percent(r['system_objective_met_rate'])} "
                f"| {percent(r['test_objective_realized_rate'])} | {r['violated']} | {r['open']} "
                f"| {r['mean_restrictions']:.1f} | {r['mean_steps']:.1f} | {r['n_failures']}"
                f"{' (' + str(r['test_failures']) + ' test)' if r['test_failures'] else ''} |"
            )
        lines.append("")
        for r in rows:
            pics = r["pictures"]
            if r.get("stopped"):
                lines += [f"**{r['title']}** — stopped: {r['stopped']}", ""]
            ways = outcomes_of(r)
            if ways:
                lines += [
                    f"**{r['title']}** — {r['n_failures']} of {r['episodes']} runs failed" + (f", in {len(ways)} ways" if len(ways) > 1 else "") + ":",
                    "",
                ]
                for o in ways:
                    bug = " (FlowTest bug)" if o.get("kind") == "test" else ""
                    lines.append(f"- {o['line']}{bug}" + (f" — replay seed {o['seeds'][0]}: `{o['replay']}`" if o.get("replay") else ""))
                lines.append("")
            for label in ("typical", "failing"):
                if label in pics:
                    lines.append(f"![{label} run of {sut} on {r['title']}]({pics[label]})")
            lines.append("")
    return "\n".join(lines) + "\n"
