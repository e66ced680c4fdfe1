"""Build docs/leaderboard.md from benchmark result files (a maintainer's tool).

Usage::

    flowtest benchmark --pool reachability1/5x5-v2 --out bench/           # a result: bench/table.json
    python -m experiments.tools.leaderboard --add bench/table.json --label "defaults"
    python -m experiments.tools.leaderboard                               # regenerate only

``--add`` keeps a summary of a ``table.json`` (docs/benchmark-protocol.md: its format) in
``docs/leaderboard/``: every number the page shows, what the run trained and what it only
scored, and the held-out per-run score matrices (seeds x tests, greedy and sampled, every
system: ``scores``, as met-run counts), so the statistics can be recomputed from the summary
alone (:func:`matrices`); the train and validation per-test arrays and the learning curves are
left out. It regenerates the page from every summary there: per pool, one table per result
(the held-out normalized score, sampled as the headline and greedy beside it, with their
intervals, raw met, the hardest 10 % of the tests, next to the floor and the references), what
it trained and scored, its command, commit, machine and times, and the generalization curve
when the run has one. Summaries of the first format (``version`` 1, results before the crossed
intervals) lack the matrices: they are shown with their old statistics, labelled so. The page
is only ever written by this tool, from these files: no number on it is typed by hand.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from experiments.benchmark.table import PRELIMINARY_MARK, TABLE_COLUMNS, headline_cell, interval_text, ran_text, scale_words, what_ran
from experiments.formatting import MISSING, percent

ROOT = Path(__file__).resolve().parents[2]
RESULTS_DIR = ROOT / "docs" / "leaderboard"
PAGE = ROOT / "docs" / "leaderboard.md"

ENTRY_FORMAT = "flowtest-leaderboard-entry"
ENTRY_VERSION = 2
"""The summary's version: 2 holds the crossed intervals, the tail and the held-out score
matrices; 1 (results of version 2, before them) the old statistics only."""
RESULTS_VERSION = 3
"""The ``table.json`` version ``--add`` takes (docs/benchmark-protocol.md)."""
KIND_ORDER = {"baseline": 0, "system": 1, "floor": 2, "reference": 3}


class LeaderboardError(ValueError):
    """A file that is not a benchmark result (or a summary of one)."""


def summarize(doc: dict[str, Any], label: str = "") -> dict[str, Any]:
    """The leaderboard's summary of a ``table.json`` document: what the page shows and the
    held-out score matrices, no other per-test arrays.

    Raises
    ------
    LeaderboardError
        If ``doc`` is not a ``flowtest-benchmark`` results document of version 3.
    """
    if doc.get("format") != "flowtest-benchmark":
        raise LeaderboardError("not a flowtest benchmark result (table.json of `flowtest benchmark`)")
    if doc.get("version") != RESULTS_VERSION:
        raise LeaderboardError(
            f"a flowtest benchmark result of version {doc.get('version')}, not {RESULTS_VERSION}: its "
            "statistics are the old ones (docs/benchmark-protocol.md); rerun the benchmark"
        )

    def mode(m: dict[str, Any] | None) -> dict[str, Any] | None:
        if not m:
            return None
        return {
            "met": m["met"]["mean"],
            "met_ci95": m["met"]["ci95"],
            "runs_per_test": m["runs_per_test"],
            "normalized": m["normalized"],
            "tail": m.get("tail"),
        }

    systems = []
    scores: dict[str, dict[str, Any]] = {"greedy": {}, "sampled": {}}
    for e in doc["systems"]:
        row: dict[str, Any] = {"name": e["name"], "kind": e["kind"], "seeds": [r["seed"] for r in e["runs"]]}
        for split in ("train", "validation", "test"):
            if split in e:
                row[split] = {
                    "met": e[split]["met"]["mean"],
                    "headline_mode": e[split].get("headline_mode"),
                    "greedy": mode(e[split].get("greedy")),
                    "sampled": mode(e[split].get("sampled")),
                }
        systems.append(row)
        for m in ("greedy", "sampled"):
            runs = [r["test"][m] for r in e["runs"] if r.get("test") and r["test"].get(m)]
            if runs:
                k = int(runs[0]["runs"])
                scores[m][e["name"]] = {"runs_per_test": k, "seeds": row["seeds"], "met_runs": [[int(round(v * k)) for v in r["per_test"]] for r in runs]}
    return {
        "format": ENTRY_FORMAT,
        "version": ENTRY_VERSION,
        "label": label,
        "pool": doc["pool"],
        "command": doc.get("command"),
        "commit": doc.get("commit"),
        "machine": doc.get("machine"),
        "splits": doc["splits"],
        "config": doc["config"],
        "budget": doc["budget"],
        "ran": doc["ran"],
        "scale": doc["scale"],
        "headline": doc["headline"],
        "seconds": doc.get("seconds"),
        "systems": systems,
        "generalization": doc.get("generalization", []),
        "scores": {"test": scores},
    }


def matrices(entry: dict[str, Any], mode: str = "sampled", split: str = "test") -> dict[str, np.ndarray]:
    """A summary's held-out per-run score matrices, as rliable reads them: system ->
    ``float [seeds, tests]`` (each test's met share: met runs / runs per test). Empty for a
    summary of version 1, which did not keep them."""
    stored = (entry.get("scores") or {}).get(split, {}).get(mode, {})
    return {name: np.asarray(m["met_runs"], dtype=np.float64) / m["runs_per_test"] for name, m in stored.items()}


def entry_json(entry: dict[str, Any]) -> str:
    """The summary as indented JSON, each list of numbers on one line (a score matrix is a
    line per seed, not a line per test)."""
    text = json.dumps(entry, indent=1)
    return (
        re.sub(
            r"\[(?:\s*-?\d+(?:\.\d+)?(?:e-?\d+)?,)*\s*-?\d+(?:\.\d+)?(?:e-?\d+)?\s*\]",
            lambda m: "[" + ", ".join(x.strip() for x in m.group(0)[1:-1].split(",")) + "]",
            text,
        )
        + "\n"
    )


def slug(text: str) -> str:
    """A file-name-safe form of a pool name."""
    return re.sub(r"[^A-Za-z0-9.-]+", "-", text).strip("-")


def add(path: Path, label: str = "", results: Path = RESULTS_DIR, commit: str | None = None) -> Path:
    """Store the summary of the result file ``path`` in ``results`` (``commit``: the commit
    the run used, where the file recorded another); return where."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise LeaderboardError(f"cannot read {str(path)!r}: {exc}") from None
    entry = summarize(doc, label)
    if commit:
        entry["commit"] = commit
    results.mkdir(parents=True, exist_ok=True)
    commit = (entry["commit"] or "nocommit")[:8]
    base = f"{slug(entry['pool'])}--{commit}--{slug(label) or 'run'}"
    target = results / f"{base}.json"
    k = 2
    while target.exists():
        target = results / f"{base}-{k}.json"
        k += 1
    target.write_text(entry_json(entry))
    return target


def load_entries(results: Path = RESULTS_DIR) -> list[dict[str, Any]]:
    """Every summary in ``results``, in file-name order."""
    entries = []
    for f in sorted(results.glob("*.json")):
        e = json.loads(f.read_text())
        if e.get("format") != ENTRY_FORMAT:
            raise LeaderboardError(f"{f}: not a leaderboard entry")
        e["file"] = f.name
        entries.append(e)
    return entries


COLUMNS = [c for c in TABLE_COLUMNS if c not in ("validation met", "held-out gap (greedy)", "held-out realized (of met)")]
"""A benchmark table's columns that the leaderboard keeps (:data:`~experiments.benchmark.table.TABLE_COLUMNS`)."""

OLD_COLUMNS = [
    "system",
    "kind",
    "seeds",
    "held-out normalized, greedy: IQM [old interval]",
    "sampled: IQM [old interval]",
    "greedy: mean [t over seed means]",
    "sampled: mean [t over seed means]",
    "held-out met, greedy",
    "held-out met, sampled",
    "worst 10 % held-out (old)",
    "train met",
]

OLD_NOTE = (
    "*v1, old statistics*: this result predates the crossed intervals (its summary is of version 1 and kept no per-run "
    "score matrices, so the new intervals and the tail cannot be recomputed). Its *IQM [old interval]* is the IQM over "
    "seeds with the old per-seed bootstrap (each seed's tests resampled independently, the floor held fixed): too narrow, "
    "most of all with 3 seeds. *mean [t over seed means]* is recomputed exactly from the stored mean and t half-width of "
    "the met share (the floor and the tests held fixed, so it is a lower bound of the new preliminary interval's width). "
    "The old worst-10 % column is of the greedy play."
)


def _sorted_systems(e: dict[str, Any]) -> list[dict[str, Any]]:
    return sorted(e["systems"], key=lambda s: (KIND_ORDER.get(s["kind"], 9), s["name"]))


def _t_over_seeds(m: dict[str, Any] | None, scale: dict[str, Any]) -> str:
    """A version-1 row's normalized mean with the t interval over its seed means, from the
    stored met mean and t half-width (floor and ceiling held at their means)."""
    f, c = scale.get("floor"), scale.get("ceiling")
    if not m or m.get("met") is None or m.get("met_ci95") is None or f is None or c is None or not c > f:
        return MISSING
    mean, half = (m["met"] - f) / (c - f), m["met_ci95"] / (c - f)
    return f"{mean:.2f} [{mean - half:.2f}, {mean + half:.2f}]"


def _ran(e: dict[str, Any]) -> dict[str, Any]:
    """What the run trained and scored: stored, or (version 1) from its settings and systems."""
    if e.get("ran"):
        return dict(e["ran"])
    systems = [
        {"name": s["name"], "kind": s["kind"], "seeds": s["seeds"], "modes": [m for m in ("greedy", "sampled") if (s.get("test") or {}).get(m)]}
        for s in e["systems"]
    ]
    return what_ran(e["config"], e["splits"], e["budget"], systems, e.get("generalization", []))


def entry_markdown(e: dict[str, Any]) -> list[str]:
    """One result: what ran, the scale, the table, the curve, where it came from."""
    sp, sc = e["splits"], e["scale"]["test"]
    old = e.get("version", 1) < 2
    title = e["label"] or "run"
    top = scale_words(sc)
    lines = [f"### {title} ({e['file']})", ""]
    if old:
        lines += [OLD_NOTE, ""]
    lines += [
        *ran_text(_ran(e)),
        "",
        f"Train {sp['train']['count']:,} tests, validation {sp['validation']['count']:,}, held-out test "
        f"{sp['test']['count']:,}; {e['config']['runs']} sampled runs per test; floor (random) / {top} on the held-out "
        f"tests: {percent(sc['floor'], 1)} / {percent(sc['ceiling'], 1)}"
        + ("" if top == "ceiling" else " (the best reference meets fewer than all tests: not a ceiling)")
        + ".",
        "",
    ]
    columns = OLD_COLUMNS if old else COLUMNS
    lines += ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for s in _sorted_systems(e):
        te = s.get("test") or {}
        g, sm = te.get("greedy"), te.get("sampled")
        train = percent((s.get("train") or {}).get("met"), 1)
        if old:
            worst = g or sm
            cells = [
                interval_text(g["normalized"] if g else None),
                interval_text(sm["normalized"] if sm else None),
                _t_over_seeds(g, sc),
                _t_over_seeds(sm, sc),
                percent(g["met"] if g else None, 1),
                percent(sm["met"] if sm else None, 1),
                MISSING
                if not worst or worst["normalized"].get("worst10") is None
                else f"{worst['normalized']['worst10']:.2f} ({percent(worst['normalized']['worst10_met'], 1)} met)",
                train,
            ]
        else:
            cells = [
                headline_cell(s, "normalized"),
                interval_text(g["normalized"] if g else None),
                headline_cell(s, "met", lambda m: percent(m["met"], 1)),
                percent(g["met"] if g else None, 1),
                headline_cell(s, "tail"),
                train,
            ]
        lines.append("| " + " | ".join([s["name"], s["kind"], str(len(s["seeds"])), *cells]) + " |")
    if e.get("generalization"):
        lines += [
            "",
            "Generalization curve (held-out normalized score" + (", IQM [old interval]" if old else "") + "):",
            "",
            "| training tests | seeds | sampled | greedy | train met |",
            "|---|---|---|---|---|",
        ]
        for p in e["generalization"]:
            lines.append(
                f"| {p['train_tests']:,} | {len(p['seeds'])} | {interval_text(p['sampled'])} | {interval_text(p['greedy'])} | {percent(p['train_met'], 1)} |"
            )
    m = e.get("machine") or {}
    secs = (e.get("seconds") or {}).get("total")
    lines += [
        "",
        f"Command: `{e['command']}`  ",
        f"Commit: `{(e['commit'] or 'unknown')[:12]}`; machine: "
        f"{m.get('processor', '?')}, {m.get('cpus', '?')} CPUs, load average at the end "
        f"{', '.join(map(str, m.get('load_average') or [])) or '?'}; total time "
        f"{'?' if secs is None else f'{secs:,.0f} s'}.",
        "",
    ]
    return lines


HEADER = f"""# Leaderboard

Generated by `python -m experiments.tools.leaderboard` from the result summaries in
[docs/leaderboard/](leaderboard/): do not edit by hand. The protocol and every column:
[benchmark-protocol.md](benchmark-protocol.md). The headline is the **held-out normalized score of
the sampled play** (0 = a random policy, 1 = the reference: the scripted replanner / GR(1) system,
correct systems that do not know the test; a deterministic system's is its greedy play; why sampled:
[the protocol](benchmark-protocol.md#the-headline-sampled-play)), the greedy play's beside it. With 5
seeds or more it is the interquartile mean over seeds with the **seed-and-test bootstrap** 95 %
interval (seeds and tests resampled, one test resample shared by every seed, the floor and the
reference, so the floor's and the reference's own sampling error is in it); a row with fewer seeds is
**preliminary** ({PRELIMINARY_MARK}): the mean over seeds with the t interval over the seed means, widened by the tests'
and the floor's error. *Hardest 10 %* is the mean met share of the 10 % of held-out tests a system
meets least often (a CVaR). Where the best reference meets fewer than all tests it is called the
reference, not the ceiling: a system can score above 1. Each result says what it trained and what it
only scored, which model of each training run was scored (since 2026-12-05 the checkpoint with the
best greedy validation met; earlier results scored the final model and say "no model selection")
and whether the runs had reached their validation plateau; a run with fewer seeds, tests or steps
than the defaults is labelled as such and is not the protocol's default result. Results marked *v1, old statistics* predate these intervals and are
shown as they were computed.

## How to add a row

```bash
flowtest benchmark --pool <pool> --out bench/                  # add --algo ... or --sut python:... for yours
python -m experiments.tools.leaderboard --add bench/table.json --label "<what it is>"
git add docs/leaderboard/ docs/leaderboard.md
```

`--add` stores a summary of the result (every number shown here, what it trained and scored, its
command, commit and machine, and the held-out per-run score matrices) in docs/leaderboard/ and
regenerates this page from all of them. `experiments.tools.leaderboard.matrices(entry)` gives a
summary's matrices as rliable reads them.
"""


def standard_ids() -> list[str]:
    """The standard pools' ids (:mod:`flowtest_env.standard_pools`), or none where FlowTest has none."""
    try:
        from flowtest_env.standard_pools import STANDARD_POOLS
    except ImportError:
        return []
    return sorted(STANDARD_POOLS)


def page(entries: Sequence[dict[str, Any]], standard: Sequence[str] = ()) -> str:
    """docs/leaderboard.md from the summaries: per pool, each result (the protocol's
    default results first, labelled ``protocol default...``, then the others, each group in
    file-name order); then the standard pools (``standard``) that have no result yet."""
    lines = [HEADER]
    pools = sorted({e["pool"] for e in entries})
    missing = [p for p in standard if p not in pools]
    if missing:
        lines += ["Standard pools without a result here yet: " + ", ".join(f"`{p}`" for p in missing) + ".", ""]
    if not pools:
        lines += ["No result yet."]
    for pool in pools:
        lines += [f"## {pool}", ""]
        mine = [e for e in entries if e["pool"] == pool]
        for e in sorted(mine, key=lambda e: not str(e.get("label", "")).startswith("protocol default")):
            lines += entry_markdown(e)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module docstring)."""
    p = argparse.ArgumentParser(prog="python -m experiments.tools.leaderboard", description=__doc__.split("\n")[0])
    p.add_argument("--add", type=Path, action="append", default=[], metavar="TABLE_JSON", help="a benchmark's table.json to add (repeatable)")
    p.add_argument("--label", default="", help="what the added run is (e.g. 'defaults', 'small: 3 seeds, 100k steps')")
    p.add_argument("--commit", default=None, help="the commit the added run used (where its file recorded a later one)")
    p.add_argument("--results", type=Path, default=RESULTS_DIR, help="the folder of summaries (default docs/leaderboard/)")
    p.add_argument("--page", type=Path, default=PAGE, help="the page to write (default docs/leaderboard.md)")
    args = p.parse_args(argv)
    try:
        for path in args.add:
            print(f"added {add(path, args.label, args.results, args.commit)}", file=sys.stderr)
        text = page(load_entries(args.results) if args.results.is_dir() else [], standard_ids())
    except LeaderboardError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args.page.write_text(text)
    print(f"wrote {args.page}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
