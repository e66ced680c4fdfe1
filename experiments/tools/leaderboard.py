"""Build docs/leaderboard.md from benchmark result files (a maintainer's tool).

Usage::

    flowtest benchmark --pool reachability1/5x5-v1 --out bench/           # a result: bench/table.json
    python -m experiments.tools.leaderboard --add bench/table.json --label "defaults"
    python -m experiments.tools.leaderboard                               # regenerate only

``--add`` keeps a summary of a ``table.json`` (docs/benchmark-protocol.md: its format) in
``docs/leaderboard/`` (the per-test arrays and learning curves left out, every number the
page shows kept) and regenerates the page from every summary there: per pool, one table per
result (the baselines' held-out normalized scores with their intervals, greedy and sampled,
raw met, the worst 10 %, next to the floor and the references), its command, commit,
machine and times, and the generalization curve when the run has one. The page is only ever
written by this tool, from these files: no number on it is typed by hand.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from experiments.benchmark.table import interval_text, worst_text
from experiments.formatting import MISSING, percent

ROOT = Path(__file__).resolve().parents[2]
RESULTS_DIR = ROOT / "docs" / "leaderboard"
PAGE = ROOT / "docs" / "leaderboard.md"

ENTRY_FORMAT = "flowtest-leaderboard-entry"
ENTRY_VERSION = 1
KIND_ORDER = {"baseline": 0, "system": 1, "floor": 2, "reference": 3}


class LeaderboardError(ValueError):
    """A file that is not a benchmark result (or a summary of one)."""


def summarize(doc: dict[str, Any], label: str = "") -> dict[str, Any]:
    """The leaderboard's summary of a ``table.json`` document: what the page shows, no
    per-test arrays.

    Raises
    ------
    LeaderboardError
        If ``doc`` is not a ``flowtest-benchmark`` results document of version 2.
    """
    if doc.get("format") != "flowtest-benchmark" or doc.get("version") != 2:
        raise LeaderboardError("not a flowtest benchmark result of version 2 (table.json of `flowtest benchmark`)")

    def mode(m: dict[str, Any] | None) -> dict[str, Any] | None:
        if not m:
            return None
        return {"met": m["met"]["mean"], "met_ci95": m["met"]["ci95"], "runs_per_test": m["runs_per_test"],
                "normalized": m["normalized"]}

    systems = []
    for e in doc["systems"]:
        row: dict[str, Any] = {"name": e["name"], "kind": e["kind"], "seeds": [r["seed"] for r in e["runs"]]}
        for split in ("train", "validation", "test"):
            if split in e:
                row[split] = {"met": e[split]["met"]["mean"], "greedy": mode(e[split].get("greedy")),
                              "sampled": mode(e[split].get("sampled"))}
        systems.append(row)
    return {
        "format": ENTRY_FORMAT, "version": ENTRY_VERSION, "label": label,
        "pool": doc["pool"], "command": doc.get("command"), "commit": doc.get("commit"), "machine": doc.get("machine"),
        "splits": doc["splits"], "config": doc["config"], "budget": doc["budget"], "scale": doc["scale"],
        "seconds": doc.get("seconds"), "systems": systems, "generalization": doc.get("generalization", []),
    }


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
    target.write_text(json.dumps(entry, indent=1) + "\n")
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


COLUMNS = ["system", "kind", "seeds", "held-out normalized, greedy: IQM [95 % CI]", "held-out normalized, sampled",
           "held-out met, greedy", "held-out met, sampled", "worst 10 % held-out", "train met"]


def entry_markdown(e: dict[str, Any]) -> list[str]:
    """One result: its settings line, the table, the curve, where it came from."""
    cfg, sp, budget = e["config"], e["splits"], e["budget"]
    title = e["label"] or "run"
    lines = [f"### {title} ({e['file']})", "",
             f"Train {sp['train']['count']:,} tests, validation {sp['validation']['count']:,}, held-out test "
             f"{sp['test']['count']:,}; {len(cfg['seeds'])} training seeds; {cfg['steps']:,} steps per run "
             f"({budget['training_runs']} runs, {budget['training_steps']:,} steps; trainer {cfg['trainer']}); "
             f"{cfg['runs']} sampled runs per test; floor (random) / ceiling on the held-out tests: "
             f"{percent(e['scale']['test']['floor'], 1)} / {percent(e['scale']['test']['ceiling'], 1)}.", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for s in sorted(e["systems"], key=lambda s: (KIND_ORDER.get(s["kind"], 9), s["name"])):
        te = s.get("test") or {}
        g, sm = te.get("greedy"), te.get("sampled")
        seeds = str(len(s["seeds"])) if s["kind"] == "baseline" else MISSING
        lines.append("| " + " | ".join([
            s["name"], s["kind"], seeds, interval_text(g["normalized"] if g else None),
            interval_text(sm["normalized"] if sm else None), percent(g["met"] if g else None, 1),
            percent(sm["met"] if sm else None, 1), worst_text(g or sm), percent((s.get("train") or {}).get("met"), 1)]) + " |")
    if e.get("generalization"):
        lines += ["", "Generalization curve (held-out normalized score, IQM [95 % CI]):", "",
                  "| training tests | seeds | greedy | sampled | train met |", "|---|---|---|---|---|"]
        for p in e["generalization"]:
            lines.append(f"| {p['train_tests']:,} | {len(p['seeds'])} | {interval_text(p['greedy'])} | "
                         f"{interval_text(p['sampled'])} | {percent(p['train_met'], 1)} |")
    m = e.get("machine") or {}
    secs = (e.get("seconds") or {}).get("total")
    lines += ["", f"Command: `{e['command']}`  ", f"Commit: `{(e['commit'] or 'unknown')[:12]}`; machine: "
              f"{m.get('processor', '?')}, {m.get('cpus', '?')} CPUs, load average at the end "
              f"{', '.join(map(str, m.get('load_average') or [])) or '?'}; total time "
              f"{'?' if secs is None else f'{secs:,.0f} s'}.", ""]
    return lines


HEADER = """# Leaderboard

Generated by `python -m experiments.tools.leaderboard` from the result summaries in
[docs/leaderboard/](leaderboard/): do not edit by hand. The protocol and every column:
[benchmark-protocol.md](benchmark-protocol.md). The headline is the **held-out normalized score**
(0 = a random policy, 1 = the reference: the scripted replanner / GR(1) system, correct systems that
do not know the test; each table gives the floor and the ceiling, which is below 100 % on the fuel
grids with doors: [why](benchmark-protocol.md)), summarized by its interquartile mean over training seeds with a stratified-bootstrap
95 % interval; *greedy* plays each test once by the most likely action, *sampled* draws the actions.
Each table says the run's settings: a run with fewer seeds, tests or steps than the defaults is
labelled as such and is not the protocol's default result.

## How to add a row

```bash
flowtest benchmark --pool <pool> --out bench/                  # add --algo ... or --sut python:... for yours
python -m experiments.tools.leaderboard --add bench/table.json --label "<what it is>"
git add docs/leaderboard/ docs/leaderboard.md
```

`--add` stores a summary of the result (every number shown here, with its command, commit and
machine) in docs/leaderboard/ and regenerates this page from all of them.
"""


def standard_ids() -> list[str]:
    """The standard pools' ids (:mod:`flowtest_env.standard_pools`), or none where FlowTest has none."""
    try:
        from flowtest_env.standard_pools import STANDARD_POOLS
    except ImportError:
        return []
    return sorted(STANDARD_POOLS)


def page(entries: Sequence[dict[str, Any]], standard: Sequence[str] = ()) -> str:
    """docs/leaderboard.md from the summaries: per pool, each result; then the standard
    pools (``standard``) that have no result yet."""
    lines = [HEADER]
    pools = sorted({e["pool"] for e in entries})
    missing = [p for p in standard if p not in pools]
    if missing:
        lines += ["Standard pools without a result here yet: " + ", ".join(f"`{p}`" for p in missing) + ".", ""]
    if not pools:
        lines += ["No result yet."]
    for pool in pools:
        lines += [f"## {pool}", ""]
        for e in entries:
            if e["pool"] == pool:
                lines += entry_markdown(e)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """The command line (module docstring)."""
    p = argparse.ArgumentParser(prog="python -m experiments.tools.leaderboard", description=__doc__.split("\n")[0])
    p.add_argument("--add", type=Path, action="append", default=[], metavar="TABLE_JSON",
                   help="a benchmark's table.json to add (repeatable)")
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
