"""The evaluation report as HTML: an outcome matrix first, then the tests, the failing runs
and every number.

Layout, for a reader who has never seen FlowTest:

1. **The matrix**: systems under test (rows) x tests (columns), each cell coloured by
   outcome (every run passed; some runs failed; every run failed; a FlowTest bug) and
   linking to its failing runs. Systems with identical results on every test share one
   row. A glossary says what "met", "realized", "violated" and "open" mean.
2. **The tests**: per test its restrictions per history (the panels ``flowtest synthesize
   --plot`` draws: walls in every panel, the doors each history closes), its propositions
   named in a legend, the system objective the SUT is given, and the test objective,
   hidden from the SUT, behind a "reveal" switch.
3. **Failing runs**: per system and test, one line per way of failing with its seeds
   (:mod:`~experiments.evaluation.explain`: the loop an open run ended in and the moves
   toward the goal the test refused, and why; for a violation the conjunct of the system
   objective that broke, the step and the cell) and the replay command of its first seed, a
   filmstrip of the first failing run (a loop shown once), its whole path, and the replay
   command of every listed failure behind a switch.
4. **All numbers**: one table per system, as in ``report.md``.

Tests are called by their problem's name (a problem file's ``name``, else its file stem;
a registered ID without ``FlowTest-`` and ``-v0``), never by a path; two tests with the same
name get the shortest part of their paths that tells them apart. Every file name and
anchor of a test comes from :func:`file_key`, which is one-to-one: ``probs/a.toml`` and
``probs-a.toml``, ``A.toml`` and ``a.toml`` never share a picture or an anchor.
The page is a grid of cards that wraps at laptop width (1366 px: three tests a row).

The data comes from :mod:`experiments.evaluation.results` (its ``results.json`` records, plus a
:class:`TestInfo` per test from :func:`test_infos`, and each failure's ``violation`` from
:func:`experiments.evaluation.violations.violation_of_trace`); this module lays it out.
"""

from __future__ import annotations

import hashlib
import html
import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from experiments.formatting import MISSING, percent

from .violations import where_words

if TYPE_CHECKING:
    from .episodes import NamedEnv

PROBLEM_SUFFIXES = (".toml", ".json")
"""File suffixes of problems and artifacts given as ``--env``."""


@dataclass(frozen=True)
class TestInfo:
    """What the report shows of a test: its env ID, problem name, kind, objectives, the
    picture of its restrictions per history (a path relative to the report) and the
    propositions of its system with where they hold and their colour in the picture
    (``("hazard", "cells H", "#e377c2")``; no colour on graphs)."""

    __test__ = False  # not a pytest test class

    env_id: str
    problem: str
    kind: str
    system_objective: str
    test_objective: str
    max_steps: int
    picture: str
    propositions: tuple[tuple[str, str, str], ...] = ()
    histories: tuple[tuple[str, str], ...] = ()
    """``(name, meaning)`` of each history the picture has a panel of (``("q2", "saw I1")``):
    the meanings give the hidden test objective away, so the card shows them behind its
    "reveal" switch, and the panels only the names."""


def file_key(text: str) -> str:
    """A file-name and HTML-id fragment of ``text`` that is one-to-one: a readable slug
    (lower-case letters, digits, single ``-``; the last 40 characters) and the first 10
    hex digits of the SHA-256 of the exact text, so ``probs/a.toml`` and ``probs-a.toml``,
    or ``A.toml`` and ``a.toml``, get different keys (on case-blind file systems too).
    Keys never hold ``--``, so ``KEY--KEY`` names a pair unambiguously.

    Example::

        >>> file_key("FlowTest-Maze2-v0")
        'flowtest-maze2-v0-...'
    """
    readable = re.sub(r"[^a-z0-9]+", "-", text.lower())[-40:].strip("-")
    digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:10]
    return f"{readable}-{digest}" if readable else digest


def test_anchor(env_id: str) -> str:
    """The HTML id of a test's card."""
    return f"test-{file_key(env_id)}"


def failures_anchor(sut: str, column: str) -> str:
    """The HTML id of a system's failing runs on a test column."""
    return f"fail-{file_key(sut)}--{file_key(column)}"


def is_file_name(env_id: str) -> bool:
    """Whether ``--env`` named a file (a problem or an artifact), not an ID or a built-in."""
    return Path(env_id).suffix.lower() in PROBLEM_SUFFIXES or "/" in env_id or "\\" in env_id


def test_title(env_id: str, problem: str = "") -> str:
    """What one test is called: for a file its problem's name (``problem``, the file's
    ``name``) or else its stem, never the path; a registered ID without ``FlowTest-`` and
    ``-v0``; a built-in name as it is."""
    if is_file_name(env_id):
        return problem or Path(env_id).stem
    return _short(env_id)


def test_titles(env_ids: Sequence[str], infos: Sequence[TestInfo] = (), problems: dict[str, str] | None = None) -> dict[str, str]:
    """What each test is called in the report: its problem's name (a file's ``name``, else
    its stem; a registered ID shortened), never a path; tests that would share a name get
    the shortest tail of their paths that tells them apart (``a (x/a.toml)``, ``a (y/a.toml)``).
    The problem's name comes from ``infos``, else from ``problems`` (env ID -> name)."""
    info = {t.env_id: t for t in infos}
    envs = list(dict.fromkeys(env_ids))
    names = {**(problems or {}), **{env: t.problem for env, t in info.items()}}
    titles = {env: test_title(env, names.get(env, "")) for env in envs}
    groups: dict[str, list[str]] = {}
    for env in envs:
        groups.setdefault(titles[env], []).append(env)
    for title, same in groups.items():
        if len(same) < 2:
            continue
        depth = max(len(Path(env).parts) for env in same)
        for k in range(1, depth + 1):
            tails = ["/".join(Path(env).parts[-k:]) for env in same]
            if len(set(tails)) == len(tails):
                break
        else:
            tails = list(same)
        for env, tail in zip(same, tails, strict=True):
            titles[env] = f"{title} ({tail})"
    return titles


def column_titles(records: Sequence[dict[str, Any]], infos: Sequence[TestInfo] = (), problems: dict[str, str] | None = None) -> dict[str, str]:
    """What each matrix column (:func:`test_name`) is called: :func:`test_titles` of its
    test, with the tester when it is not the synthesized one."""
    titles = test_titles([r["env"] for r in records], infos, problems)
    out: dict[str, str] = {}
    for r in records:
        tester = r.get("tester", "synthesized")
        out[test_name(r)] = titles[r["env"]] if tester == "synthesized" else f"{titles[r['env']]} vs {tester}"
    return out


# --------------------------------------------------------------------------- the tests' cards


def test_infos(tests: Sequence[NamedEnv | str], out: Path, colours: dict[str, tuple[int, int, int]] | None = None) -> list[TestInfo]:
    """Draw each test's restrictions per history (:func:`experiments.plots.plot_artifact`:
    the panels ``flowtest synthesize --plot`` draws, propositions in the legend) to
    ``out/tests/<file_key>.png`` and collect what the report shows of it (problem name,
    kind, objectives, step budget, propositions). A test is the env an evaluation resolved
    (:class:`~experiments.evaluation.episodes.NamedEnv`: its game is drawn, nothing is
    built) or a name (its env built here). Every proposition takes its colour from
    ``colours`` (by name; default one colour per name over these tests,
    :func:`flowtest_env.render.proposition_colours`), in the pictures and the legends alike."""
    from experiments.outputs import write_atomically
    from experiments.plots import proposition_legend
    from flowtest_env.render import all_propositions, hex_colour, proposition_colours

    from .episodes import NamedEnv, resolve_env
    from .filmstrip import test_picture

    (out / "tests").mkdir(parents=True, exist_ok=True)
    named_tests = []
    for test in {(t if isinstance(t, str) else t.env_id): t for t in tests}.values():
        if isinstance(test, NamedEnv):
            named_tests.append(test)
        else:
            named_tests.append(resolve_env(test))
            named_tests[-1].env.close()
    if colours is None:
        colours = proposition_colours(name for t in named_tests for name in all_propositions(t.game))
    hexes = {name: hex_colour(c) for name, c in colours.items()}
    infos = []
    for named in named_tests:
        env_id, game = named.env_id, named.game
        name = f"tests/{file_key(env_id)}.png"
        write_atomically(out / name, partial(test_picture, game, colours=hexes))
        art = game.artifact
        infos.append(
            TestInfo(
                env_id=env_id,
                problem=str(art.name),
                kind=str(art.kind),
                system_objective=str(art.objectives.get("system", "")),
                test_objective=str(art.objectives.get("test", "")),
                max_steps=named.max_steps,
                picture=name,
                propositions=tuple(proposition_legend(art.system, colours=hexes)),
                histories=history_meanings(game),
            )
        )
    return infos


def history_meanings(game: Any) -> tuple[tuple[str, str], ...]:
    """``("q2", "saw I1")`` for every history that closes a door (the panels' neutral names,
    with what they mean: the report shows the meanings behind its "reveal" switch only)."""
    from experiments.plots import artifact_view

    view = artifact_view(game.artifact)
    strategy = game.artifact.strategy
    reactive = strategy.restrictions & ~strategy.static_obstacles[None, :]
    return tuple((view.spec.history_name(q), view.spec.describe(q)) for q in range(strategy.n_hist) if reactive[q].any())


GLOSSARY: tuple[tuple[str, str], ...] = (
    ("met", "the run reached the <b>system objective</b>, the task the system under test (SUT) is given, within the step budget"),
    (
        "realized",
        "the run also satisfied the <b>test objective</b>, hidden from the SUT; the synthesized "
        "test guarantees it for every run that meets the system objective, so anything below 100&nbsp;% "
        "there is a FlowTest bug (a learned tester, --tester ppo:PATH, guarantees nothing)",
    ),
    ("violated", "the run made the system objective impossible (fuel ran out, the wrong goal, an unsafe state): the SUT's failure"),
    (
        "open",
        "the step budget ran out with the system objective neither met nor violated: the SUT's "
        "failure, unless the test closed every way (then it is marked a FlowTest bug; against a learned "
        "tester, a trapped run: an unfair test)",
    ),
)

OUTCOME_CLASSES: tuple[tuple[str, str], ...] = (
    ("pass", "every run met the system objective and realized the test objective"),
    ("some", "some runs failed (violated or open)"),
    ("all", "every run failed"),
    ("bug", "FlowTest bug: a test failed its guarantee"),
)

STYLE = """
*{box-sizing:border-box}
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;max-width:1280px;margin:1.2em auto;padding:0 1em;color:#222;line-height:1.4}
h1{margin-bottom:.2em} h2{margin-top:1.6em;border-bottom:1px solid #ddd;padding-bottom:.2em}
table{border-collapse:collapse;margin:.8em 0}td,th{border:1px solid #ccc;padding:5px 9px;text-align:right;vertical-align:top}
td:first-child,th:first-child{text-align:left}
.scroll{max-width:100%;overflow-x:auto}
.matrix td,.matrix th{text-align:center;min-width:7em;max-width:14em;overflow-wrap:anywhere}.matrix td:first-child{text-align:left}
.matrix td a{color:inherit;text-decoration:none;display:block}
.matrix th a{color:#1a4d8f}.sut{font-family:ui-monospace,monospace;font-size:.92em;overflow-wrap:anywhere}
.pass{background:#cfeccb}.some{background:#ffe2a0}.all{background:#f6b3ad}.bug{background:#6a1b9a;color:#fff}
.notrun{background:#e6e6e6;color:#555}
.big{font-size:1.15em;font-weight:600}.small{font-size:.82em;opacity:.85}
.legend span{display:inline-block;padding:2px 8px;margin:2px 6px 2px 0;border:1px solid #bbb}
dl.glossary{display:grid;grid-template-columns:max-content 1fr;gap:.2em 1em;margin:.6em 0}
dl.glossary dt{font-weight:700}dl.glossary dd{margin:0}
.tests{display:grid;grid-template-columns:repeat(auto-fill,minmax(min(100%,480px),1fr));gap:1em}
.test{border:1px solid #ddd;padding:.6em;min-width:0}.test h3{margin:.1em 0 .3em;overflow-wrap:anywhere}
.test img{max-width:100%;height:auto;border:1px solid #eee;display:block;margin:0 auto}
table.props{margin:.2em 0 .6em;font-size:.88em}p.props{margin:.4em 0 0}table.props td{text-align:left;padding:2px 6px}
table.props td:first-child{font-family:ui-monospace,monospace;white-space:nowrap}
.swatch{display:inline-block;width:.8em;height:.8em;margin-right:.4em;vertical-align:-.05em;border:1px solid #888}
code{background:#f3f3f3;padding:2px 4px;overflow-wrap:anywhere}
details summary{cursor:pointer;color:#1a4d8f}
.broke{background:#fde3e1;border-left:4px solid #b00020;padding:.3em .6em;margin:.2em 0}
ul.outcomes li{margin:.35em 0}
.film{max-width:100%;border:1px solid #ddd}.traces{display:flex;flex-wrap:wrap;gap:8px}
.trace{flex:1 1 300px;max-width:560px;min-width:0}.trace img{width:100%;height:auto;border:1px solid #ddd}
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
    return (r["episodes"], met, r["test_objective_realized_rate"], r["violated"], r["open"], r["test_failures"], r["n_failures"], r.get("error"))


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
        return f"<td class='notrun' title='{html.escape(r['error'], quote=True)}'><span class='small'>not run: {html.escape(r['error'])}</span></td>"
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
    if r.get("stopped"):
        lines.append(f"<span class='small' title='{html.escape(str(r['stopped']), quote=True)}'>stopped early</span>")
    body = "<br>".join(lines)
    if r["n_failures"]:
        body = f"<a href='#{anchor}' title='see the failing runs'>{body}</a>"
    return f"<td class='{cls}'>{body}</td>"


def failure_text(f: dict[str, Any]) -> str:
    """A failure in words: what the run did (its ``explanation``,
    :mod:`~experiments.evaluation.explain`), else for a violation the conjunct, step and cell
    (``violated the system objective: broke G !hazard at step 7 in cell (2, 6)``), else its
    reason. ``f`` is a ``results.json`` failure."""
    why = f.get("explanation")
    if isinstance(why, dict) and isinstance(why.get("text"), str) and why["text"]:
        return str(why["text"])
    v = f.get("violation")
    reason = str(f.get("reason", ""))
    if isinstance(v, dict) and isinstance(v.get("text"), str):
        return f"{reason}: {v['text']}" if reason else str(v["text"])
    return reason


def outcomes_of(r: dict[str, Any]) -> list[dict[str, Any]]:
    """A record's failing runs, one entry per way of failing (``results.json``'s
    ``outcomes``: ``line``, ``seeds``, ``kind``, ``replay``, the first run's ``explanation``);
    a record without them (written by hand, or by an older FlowTest) gets one per listed
    failure."""
    if isinstance(r.get("outcomes"), list):
        return list(r["outcomes"])
    return [
        {
            "kind": f.get("kind", "sut"),
            "seeds": [f["seed"]],
            "steps": [],
            "text": failure_text(f),
            "line": f"seed {f['seed']}: {failure_text(f)}",
            "replay": f.get("replay", ""),
            "explanation": {"violation": f["violation"]} if isinstance(f.get("violation"), dict) else None,
        }
        for f in r.get("failures", [])
    ]


def _outcome_item(o: dict[str, Any]) -> str:
    """One way of failing as a list item: its runs, what happened, its first run's replay
    command; a violation says the conjunct, the step and the cell (class ``broke``)."""
    from .explain import seed_words, steps_words

    e = html.escape
    seeds = [int(x) for x in o.get("seeds", [])]
    who = o["line"][: -len(o["text"]) - 2] if o["line"].endswith(o["text"]) else seed_words(seeds)
    bug = " <b>(FlowTest bug)</b>" if o.get("kind") == "test" else ""
    v = (o.get("explanation") or {}).get("violation")
    if isinstance(v, dict) and "conjunct" in v:
        steps = [int(x) for x in o.get("steps") or [v.get("step", 0)]]
        body = (
            f"<p class='broke'>{e(who[:1].upper() + who[1:])} broke <code>{e(str(v['conjunct']))}</code> of the "
            f"system objective at {e(steps_words(steps))}, {e(where_words(str(v.get('where', ''))))}"
            + ("" if v.get("alone", True) else " (no conjunct alone: they cannot all hold any more)")
            + (": from there it can no longer be met" if v.get("kind") in ("visit", "sequenced", "delayed") else "")
            + ".</p>"
        )
    else:
        body = f"<b>{e(who)}</b>: {e(o['text'])}"
    replay = o.get("replay", "")
    first = f"seed {seeds[0]}" if seeds else "the first run"
    more = " (the others: change --seed)" if len(seeds) > 1 else ""
    tail = f"<span class='small'>Replay {first}{more}:</span> <code>{e(replay)}</code>" if replay else ""
    return f"<li>{body}{bug}{'' if body.endswith('</p>') else '<br>'}{tail}</li>"


CAPTIONS: dict[str, str] = {
    "static": "Static test: the black walls stand for the whole run.",
    "reactive": "Reactive test: one panel per history that closes doors (a history is what the run has seen so far, "
    "named neutrally, q0, q1, ...: the switch below says what each means); an orange bar is a door closed "
    "in that history (one way: the arrow's move is refused).",
    "mixed": "Mixed test: black walls stand for the whole run, and only in the static area the problem gives them "
    "(its borders dashed); one panel per history that closes doors (named neutrally; the switch below says "
    "what each means), an orange bar is a door closed in that history (one way: the arrow's move is refused).",
    "agent": "Agent test: the test agent moves in the pale blue cells and stands in the way; a blue bar is a move it "
    "blocks in that history (one panel per history, named neutrally; the switch below says what each means).",
}
"""What a test card says of its picture, per kind of test."""


def _test_card(env: str, title: str, t: TestInfo | None) -> list[str]:
    e = html.escape
    hint = f" title='{e(Path(env).name, quote=True)}'" if is_file_name(env) else ""
    parts = [f"<div class='test' id='{test_anchor(env)}'><h3{hint}>{e(title)}</h3>"]
    if t is None:
        parts.append("</div>")
        return parts
    parts.append(
        f"<p class='small'>{e(t.kind)} test, a step budget of {t.max_steps} steps a run.</p>"
        f"<a href='{e(t.picture)}' title='open the picture at full size'>"
        f"<img src='{e(t.picture)}' alt='the restrictions of this test, one panel per history' loading='lazy'></a>"
        f"<p class='small'>{e(CAPTIONS.get(t.kind, CAPTIONS['reactive']))} The start is teal, the goal green"
        f"{', the test agent blue' if t.kind == 'agent' else ''}. Click the picture to open it at full size.</p>"
    )
    if t.propositions:
        squares = any(colour for _, _, colour in t.propositions)
        parts.append("<p class='small props'>Propositions" + (" (the coloured squares in the cells)" if squares else "") + ":</p><table class='props'>")
        for name, where, colour in t.propositions:
            swatch = f"<span class='swatch' style='background:{e(colour)}'></span>" if re.fullmatch(r"#[0-9a-fA-F]{6}", colour) else ""
            parts.append(f"<tr><td>{swatch}{e(name)}</td><td>{e(where)}</td></tr>")
        parts.append("</table>")
    meanings = "".join(f"<tr><td>{e(name)}</td><td>{e(meaning)}</td></tr>" for name, meaning in t.histories)
    parts.append(
        f"<p>System objective (given to the SUT): <code>{e(t.system_objective)}</code></p>"
        f"<details><summary>Reveal the test objective (hidden from the SUT)</summary>"
        f"<p><code>{e(t.test_objective)}</code></p>"
        + (f"<p class='small props'>What each history of the panels has seen:</p><table class='props'>{meanings}</table>" if meanings else "")
        + "</details></div>"
    )
    return parts


def render_html(
    records: Sequence[dict[str, Any]],
    tests: Sequence[TestInfo],
    comparison: tuple[Sequence[str], Sequence[Sequence[str]]] | None = None,
) -> str:
    """The whole report page (see the module docstring); ``comparison`` is the header and
    rows of the testers-side-by-side table (when runs faced more than one tester).

    Example::

        page = render_html(records, test_infos(envs, out))
    """
    e = html.escape
    columns = list(dict.fromkeys(test_name(r) for r in records))
    env_of = {test_name(r): r["env"] for r in records}
    envs = list(dict.fromkeys(r["env"] for r in records))
    info = {t.env_id: t for t in tests}
    titles = test_titles(envs, tests)
    col_titles = column_titles(records, tests)
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
        parts.append(
            "<div class='bugbox'>FLOWTEST BUG: a test failed its guarantee (a run met the system objective "
            "without realizing the test objective, or the test trapped the system). Please report it with the "
            "replay commands:<ul>"
        )
        for r in bugs:
            for f in r["failures"]:
                if f["kind"] == "test":
                    parts.append(f"<li>{e(r['sut'])} on {e(col_titles[test_name(r)])}: {e(failure_text(f))} — <code>{e(f['replay'])}</code></li>")
        parts.append("</ul></div>")
    # ---- the matrix
    parts.append("<h2 id='matrix'>Outcomes</h2><div class='scroll'><table class='matrix'><tr><th>system under test</th>")
    for col in columns:
        parts.append(f"<th><a href='#{test_anchor(env_of[col])}' title='the test and its objectives'>{e(col_titles[col])}</a></th>")
    parts.append("</tr>")
    for group in fold_rows(records, columns):
        label = "<br>".join(f"<span class='sut'>{e(s)}</span>" for s in group)
        if len(group) > 1:
            label += f"<br><span class='small'>{len(group)} systems, identical results</span>"
        parts.append(f"<tr><td>{label}</td>")
        for col in columns:
            found = by.get((group[0], col))
            parts.append(_cell(found, failures_anchor(group[0], col)) if found else "<td>–</td>")
        parts.append("</tr>")
    parts.append("</table></div><p class='legend'>")
    parts += [f"<span class='{c}'>{e(text)}</span>" for c, text in OUTCOME_CLASSES]
    parts.append("</p><dl class='glossary'>")
    parts += [f"<dt>{word}</dt><dd>{text}</dd>" for word, text in GLOSSARY]
    parts.append("</dl>")
    if comparison is not None and comparison[1]:
        head, table = comparison
        parts.append("<h2 id='testers'>Testers side by side</h2><div class='scroll'><table><tr>" + "".join(f"<th>{e(c)}</th>" for c in head) + "</tr>")
        parts += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in table]
        parts.append("</table></div>")
    # ---- the tests
    parts.append("<h2 id='tests'>The tests</h2><div class='tests'>")
    for env in envs:
        parts += _test_card(env, titles[env], info.get(env))
    parts.append("</div>")
    # ---- failing runs
    failing = [r for r in records if r["n_failures"]]
    parts.append("<h2 id='failures'>Failing runs</h2>")
    if not failing:
        parts.append("<p>No run failed.</p>")
    for r in failing:
        col = test_name(r)
        ways = outcomes_of(r)
        parts.append(
            f"<h3 id='{failures_anchor(r['sut'], col)}'><span class='sut'>{e(r['sut'])}</span> on "
            f"<a href='#{test_anchor(r['env'])}'>{e(col_titles[col])}</a></h3>"
            f"<p>{r['n_failures']} of {r['episodes']} runs failed" + (f", in {len(ways)} ways" if len(ways) > 1 else "") + ":</p><ul class='outcomes'>"
        )
        parts += [_outcome_item(o) for o in ways]
        parts.append("</ul>")
        if r.get("stopped"):
            parts.append(f"<p>Stopped: {e(str(r['stopped']))}.</p>")
        pics = r.get("pictures", {})
        first = r["failures"][0]["seed"] if r["failures"] else None
        if "filmstrip" in pics:
            parts.append(
                f"<p class='small'>The first failing run (seed {first}), frame by frame; a loop is shown once:</p>"
                f"<a href='{e(pics['filmstrip'])}' title='open the picture at full size'>"
                f"<img class='film' src='{e(pics['filmstrip'])}' alt='filmstrip of the first failing run'></a>"
            )
        traces = [label for label in ("failing", "typical") if label in pics]
        if traces:
            parts.append("<div class='traces'>")
            parts += [
                f"<a class='trace' href='{e(pics[label])}' title='open the picture at full size'><img src='{e(pics[label])}' alt='{label} run, whole path'></a>"
                for label in traces
            ]
            parts.append("</div>")
        parts.append("<details><summary>Replay commands of every listed run</summary><ul>")
        parts += [f"<li>seed {f['seed']}: {e(failure_text(f))}<br><code>{e(f['replay'])}</code></li>" for f in r["failures"]]
        if r["n_failures"] > len(r["failures"]):
            parts.append(f"<li>… {r['n_failures'] - len(r['failures'])} more (results.json lists the first {len(r['failures'])})</li>")
        parts.append("</ul></details>")
    # ---- every number
    parts.append(
        "<h2 id='numbers'>All numbers</h2><p class='small'>Met: share of runs meeting the system objective. "
        "Realized: share of those runs that realized the hidden test objective (guaranteed 100&nbsp;%). "
        "Restrictions: mean number of decisions taken while a move was restricted.</p>"
    )
    for sut in suts:
        rows = [r for r in records if r["sut"] == sut]
        parts.append(
            f"<h3 class='sut'>{e(sut)}</h3><div class='scroll'><table><tr><th>test</th><th>runs</th><th>met</th>"
            "<th>realized</th><th>violated</th><th>open</th><th>restrictions</th><th>steps</th><th>failures</th></tr>"
        )
        for r in rows:
            if r.get("error"):
                parts.append(
                    f"<tr class='notrun'><td>{e(col_titles[test_name(r)])}</td><td>0</td>"
                    f"<td colspan='7' style='text-align:left'>not run: {e(r['error'])}</td></tr>"
                )
                continue
            parts.append(
                f"<tr class='{outcome_class(r) if r['n_failures'] else ''}'><td>{e(col_titles[test_name(r)])}</td>"
                f"<td>{r['episodes']}</td>"
                f"<td>{percent(r['system_objective_met_rate'], space='&nbsp;')}</td><td>{percent(r['test_objective_realized_rate'], space='&nbsp;')}</td>"
                f"<td>{r['violated']}</td><td>{r['open']}</td><td>{_num(r['mean_restrictions'])}</td>"
                f"<td>{_num(r['mean_steps'])}</td><td>{r['n_failures']}</td></tr>"
            )
        parts.append("</table></div>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _num(x: float | None) -> str:
    return MISSING if x is None else f"{x:.1f}"
