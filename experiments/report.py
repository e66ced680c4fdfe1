"""The evaluation report as HTML: an outcome matrix first, then the tests, the failing runs
and every number.

Layout, for a reader who has never seen FlowTest:

1. **The matrix**: systems under test (rows) x tests (columns), each cell coloured by
   outcome (every run passed; some runs failed; every run failed; a FlowTest bug) and
   linking to its failing runs. Systems with identical results on every test share one
   row. A glossary says what "met", "realized", "violated" and "open" mean.
2. **The tests**: per test a picture at its start (the engineer's view: walls, doors,
   the test agent, the hidden test cells), the system objective the SUT is given, and the
   test objective, hidden from the SUT, behind a "reveal" switch.
3. **Failing runs**: per system and test, the reason, a filmstrip of the first failing
   run (the test agent's moves and the doors as they opened and closed) and the replay
   command of every listed failure.
4. **All numbers**: one table per system, as in ``report.md``.

The data comes from :mod:`experiments.evaluate` (its ``results.json`` records, plus a
:class:`TestInfo` per test); this module only lays it out.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class TestInfo:
    """What the report shows of a test: its env ID, problem, kind, objectives, picture."""

    __test__ = False  # not a pytest test class

    env_id: str
    problem: str
    kind: str
    system_objective: str
    test_objective: str
    max_steps: int
    picture: str


GLOSSARY: tuple[tuple[str, str], ...] = (
    ("met", "the run reached the <b>system objective</b>, the task the system under test (SUT) is given, "
            "within the step budget"),
    ("realized", "the run also satisfied the <b>test objective</b>, hidden from the SUT; the synthesized "
                 "test guarantees it for every run that meets the system objective, so anything below 100&nbsp;% "
                 "there is a FlowTest bug (a learned tester, --tester ppo:PATH, guarantees nothing)"),
    ("violated", "the run made the system objective impossible (fuel ran out, the wrong goal, an unsafe "
                 "state): the SUT's failure"),
    ("open", "the step budget ran out with the system objective neither met nor violated: the SUT's "
             "failure, unless the test closed every way (then it is marked a FlowTest bug; against a learned "
             "tester, a trapped run: an unfair test)"),
)

OUTCOME_CLASSES: tuple[tuple[str, str], ...] = (
    ("pass", "every run met the system objective and realized the test objective"),
    ("some", "some runs failed (violated or open)"),
    ("all", "every run failed"),
    ("bug", "FlowTest bug: a test failed its guarantee"),
)

STYLE = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;max-width:1200px;margin:1.5em auto;padding:0 1em;color:#222;line-height:1.4}
h1{margin-bottom:.2em} h2{margin-top:1.8em;border-bottom:1px solid #ddd;padding-bottom:.2em}
table{border-collapse:collapse;margin:.8em 0}td,th{border:1px solid #ccc;padding:5px 9px;text-align:right;vertical-align:top}
td:first-child,th:first-child{text-align:left}
.matrix td,.matrix th{text-align:center;min-width:7.5em}.matrix td:first-child{text-align:left}.matrix td a{color:inherit;text-decoration:none;display:block}
.matrix th a{color:#1a4d8f}.sut{font-family:ui-monospace,monospace;font-size:.92em}
.pass{background:#cfeccb}.some{background:#ffe2a0}.all{background:#f6b3ad}.bug{background:#6a1b9a;color:#fff}
.notrun{background:#e6e6e6;color:#555}
.big{font-size:1.15em;font-weight:600}.small{font-size:.82em;opacity:.85}
.legend span{display:inline-block;padding:2px 8px;margin:2px 6px 2px 0;border:1px solid #bbb}
dl.glossary{display:grid;grid-template-columns:max-content 1fr;gap:.2em 1em;margin:.6em 0}
dl.glossary dt{font-weight:700}dl.glossary dd{margin:0}
.tests{display:flex;flex-wrap:wrap;gap:1.2em}.test{flex:1 1 330px;border:1px solid #ddd;padding:.6em;max-width:560px}
.test img{max-width:100%;max-height:300px;border:1px solid #ddd}
code{background:#f3f3f3;padding:2px 4px;word-break:break-all}
details summary{cursor:pointer;color:#1a4d8f}
.film{max-width:100%;border:1px solid #ddd}.trace{max-width:48%;border:1px solid #ddd;margin:4px}
.bugbox{background:#b00020;color:#fff;padding:1em;font-weight:bold}.bugbox code{color:#222}
"""


def _short(env_id: str) -> str:
    """``FlowTest-Maze2-v0`` -> ``Maze2`` (and ``... vs TESTER`` kept)."""
    return env_id.replace("FlowTest-", "").replace("-v0", "")


def test_name(r: dict[str, Any]) -> str:
    """A record's matrix column: the env ID, with the tester when it is not the
    synthesized one (``flowtest evaluate --tester``)."""
    tester = r.get("tester", "synthesized")
    return r["env"] if tester == "synthesized" else f"{r['env']} vs {tester}"


def slug(text: str) -> str:
    """An HTML id / file-name fragment of ``text``."""
    return "".join(ch if ch.isalnum() else "-" for ch in text).strip("-").lower()


def outcome_class(r: dict[str, Any]) -> str:
    """The matrix colour of a record: ``pass``, ``some``, ``all``, ``bug``, or ``notrun``
    (the system cannot play this test: ``error`` says why)."""
    if r.get("error"):
        return "notrun"
    if r["test_failures"]:
        return "bug"
    if r["n_failures"] == 0:
        return "pass"
    return "all" if r["n_failures"] == r["episodes"] else "some"


def _signature(r: dict[str, Any]) -> tuple[Any, ...]:
    met = round((r["system_objective_met_rate"] or 0) * r["episodes"])
    return (r["episodes"], met, r["test_objective_realized_rate"], r["violated"], r["open"], r["test_failures"], r["n_failures"],
            r.get("error"))


def fold_rows(records: Sequence[dict[str, Any]], envs: Sequence[str]) -> list[list[str]]:
    """Systems grouped by identical results on every test (first-seen order)."""
    by: dict[str, dict[str, dict[str, Any]]] = {}
    for r in records:
        by.setdefault(r["sut"], {})[test_name(r)] = r
    groups: dict[tuple[Any, ...], list[str]] = {}
    for sut, row in by.items():
        key = tuple(_signature(row[e]) if e in row else None for e in envs)
        groups.setdefault(key, []).append(sut)
    return list(groups.values())


def _cell(r: dict[str, Any], anchor: str) -> str:
    if r.get("error"):
        return f"<td class='notrun' title='{html.escape(r['error'], quote=True)}'><span class='small'>not run: " \
               f"{html.escape(r['error'])}</span></td>"
    n = r["episodes"]
    met = round((r["system_objective_met_rate"] or 0) * n)
    cls = outcome_class(r)
    realized = r["test_objective_realized_rate"]
    lines = [f"<span class='big'>{met}/{n} met</span>"]
    if met:
        lines.append(f"<span class='small'>realized {round(realized * met)}/{met}</span>")
    fails = []
    if r["violated"]:
        fails.append(f"{r['violated']} violated")
    if r["open"]:
        fails.append(f"{r['open']} open")
    if r["test_failures"]:
        fails.append(f"{r['test_failures']} FlowTest bug")
    if fails:
        lines.append(f"<span class='small'>{', '.join(fails)}</span>")
    body = "<br>".join(lines)
    if r["n_failures"]:
        body = f"<a href='#{anchor}' title='see the failing runs'>{body}</a>"
    return f"<td class='{cls}'>{body}</td>"


def render_html(
    records: Sequence[dict[str, Any]],
    tests: Sequence[TestInfo],
    comparison: tuple[Sequence[str], Sequence[Sequence[str]]] | None = None,
) -> str:
    """The whole report page (see the module docstring); ``comparison`` is the header and
    rows of the testers-side-by-side table (when runs faced more than one tester)."""
    e = html.escape
    columns = list(dict.fromkeys(test_name(r) for r in records))
    env_of = {test_name(r): r["env"] for r in records}
    envs = list(dict.fromkeys(r["env"] for r in records))
    info = {t.env_id: t for t in tests}
    by = {(r["sut"], test_name(r)): r for r in records}
    suts = list(dict.fromkeys(r["sut"] for r in records))
    runs = sum(r["episodes"] for r in records)
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>FlowTest evaluation</title><style>{STYLE}</style></head><body>",
        "<h1>FlowTest evaluation</h1>",
        f"<p>{len(suts)} system{'s' if len(suts) != 1 else ''} under test x {len(envs)} test{'s' if len(envs) != 1 else ''}, "
        f"{runs} runs. Each test is synthesized so that a correct system can pass it and every run that meets the "
        "system objective also exercises the hidden test objective.</p>",
    ]
    bugs = [r for r in records if r["test_failures"]]
    if bugs:
        parts.append("<div class='bugbox'>FLOWTEST BUG: a test failed its guarantee (a run met the system objective "
                     "without realizing the test objective, or the test trapped the system). Please report it with the "
                     "replay commands:<ul>")
        for r in bugs:
            for f in r["failures"]:
                if f["kind"] == "test":
                    parts.append(f"<li>{e(r['sut'])} on {e(test_name(r))}: {e(f['reason'])} — <code>{e(f['replay'])}</code></li>")
        parts.append("</ul></div>")
    # ---- the matrix
    parts.append("<h2 id='matrix'>Outcomes</h2><table class='matrix'><tr><th>system under test</th>")
    for col in columns:
        parts.append(f"<th><a href='#test-{slug(env_of[col])}' title='the test and its objectives'>{e(_short(col))}</a></th>")
    parts.append("</tr>")
    for group in fold_rows(records, columns):
        label = "<br>".join(f"<span class='sut'>{e(s)}</span>" for s in group)
        if len(group) > 1:
            label += f"<br><span class='small'>{len(group)} systems, identical results</span>"
        parts.append(f"<tr><td>{label}</td>")
        for col in columns:
            found = by.get((group[0], col))
            parts.append(_cell(found, f"fail-{slug(group[0])}--{slug(col)}") if found else "<td>–</td>")
        parts.append("</tr>")
    parts.append("</table><p class='legend'>")
    parts += [f"<span class='{c}'>{e(text)}</span>" for c, text in OUTCOME_CLASSES]
    parts.append("</p><dl class='glossary'>")
    parts += [f"<dt>{word}</dt><dd>{text}</dd>" for word, text in GLOSSARY]
    parts.append("</dl>")
    if comparison is not None and comparison[1]:
        head, table = comparison
        parts.append("<h2 id='testers'>Testers side by side</h2><table><tr>" + "".join(f"<th>{e(c)}</th>" for c in head) + "</tr>")
        parts += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in table]
        parts.append("</table>")
    # ---- the tests
    parts.append("<h2 id='tests'>The tests</h2><div class='tests'>")
    for env in envs:
        t = info.get(env)
        parts.append(f"<div class='test' id='test-{slug(env)}'><h3>{e(_short(env))} <span class='small'>{e(env)}</span></h3>")
        if t is not None:
            parts.append(
                f"<img src='{e(t.picture)}' alt='the {e(t.problem)} test at its start'>"
                f"<p class='small'>{e(t.problem)}: {e(t.kind)} test, {t.max_steps} steps per run. The picture is the "
                "engineer's view: the SUT (red), the goal (green), walls (black), restrictions shown now (orange), the "
                "test agent (blue), hidden test cells (purple rings).</p>"
                f"<p>System objective (given to the SUT): <code>{e(t.system_objective)}</code></p>"
                f"<details><summary>Reveal the test objective (hidden from the SUT)</summary>"
                f"<p><code>{e(t.test_objective)}</code></p></details>"
            )
        parts.append("</div>")
    parts.append("</div>")
    # ---- failing runs
    failing = [r for r in records if r["n_failures"]]
    parts.append("<h2 id='failures'>Failing runs</h2>")
    if not failing:
        parts.append("<p>No run failed.</p>")
    for r in failing:
        f0 = r["failures"][0]
        parts.append(
            f"<h3 id='fail-{slug(r['sut'])}--{slug(test_name(r))}'><span class='sut'>{e(r['sut'])}</span> on {e(_short(test_name(r)))}</h3>"
            f"<p>{r['n_failures']} of {r['episodes']} runs failed. First failure (seed {f0['seed']}, "
            f"{'FlowTest bug' if f0['kind'] == 'test' else 'the SUT'}): {e(f0['reason'])}.</p>"
        )
        pics = r.get("pictures", {})
        if "filmstrip" in pics:
            parts.append(f"<img class='film' src='{e(pics['filmstrip'])}' alt='filmstrip of the first failing run'>")
        for label in ("failing", "typical"):
            if label in pics:
                parts.append(f"<img class='trace' src='{e(pics[label])}' alt='{label} run, whole path'>")
        parts.append("<p>Replay a run step by step:</p><ul>")
        parts += [f"<li>seed {f['seed']}: {e(f['reason'])}<br><code>{e(f['replay'])}</code></li>" for f in r["failures"]]
        if r["n_failures"] > len(r["failures"]):
            parts.append(f"<li>… {r['n_failures'] - len(r['failures'])} more (results.json lists the first {len(r['failures'])})</li>")
        parts.append("</ul>")
    # ---- every number
    parts.append("<h2 id='numbers'>All numbers</h2><p class='small'>Met: share of runs meeting the system objective. "
                 "Realized: share of those runs that realized the hidden test objective (guaranteed 100&nbsp;%). "
                 "Restrictions: mean number of decisions taken while a move was restricted.</p>")
    for sut in suts:
        rows = [r for r in records if r["sut"] == sut]
        parts.append(f"<h3 class='sut'>{e(sut)}</h3><table><tr><th>test</th><th>runs</th><th>met</th><th>realized</th>"
                     "<th>violated</th><th>open</th><th>restrictions</th><th>steps</th><th>failures</th></tr>")
        for r in rows:
            if r.get("error"):
                parts.append(f"<tr class='notrun'><td>{e(test_name(r))}</td><td>0</td>"
                             f"<td colspan='7' style='text-align:left'>not run: {e(r['error'])}</td></tr>")
                continue
            parts.append(
                f"<tr class='{outcome_class(r) if r['n_failures'] else ''}'><td>{e(test_name(r))}</td><td>{r['episodes']}</td>"
                f"<td>{_pct(r['system_objective_met_rate'])}</td><td>{_pct(r['test_objective_realized_rate'])}</td>"
                f"<td>{r['violated']}</td><td>{r['open']}</td><td>{r['mean_restrictions']:.1f}</td>"
                f"<td>{r['mean_steps']:.1f}</td><td>{r['n_failures']}</td></tr>"
            )
        parts.append("</table>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.0f}&nbsp;%"
