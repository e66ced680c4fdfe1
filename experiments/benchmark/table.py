"""The benchmark's results: ``table.json``'s document (docs/benchmark-protocol.md, *The results
file*) and ``table.md``, with the commit and the machine they came from."""

from __future__ import annotations

import os
import platform
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from experiments.formatting import MISSING, percent

from .config import SPLIT_NAMES, BenchmarkConfig, baseline_settings, command_of, runs_text
from .pool import Split
from .statistics import SystemRuns, scale_of, system_entry
from .training_runs import TrainedBaseline

RESULTS_FORMAT = "flowtest-benchmark"
RESULTS_VERSION = 2
"""``table.json``'s ``format`` and ``version`` (docs/benchmark-protocol.md)."""


def commit() -> str | None:
    try:
        root = Path(__file__).resolve().parents[2]
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=False)
        return out.stdout.strip() or None if out.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def machine() -> dict[str, Any]:
    """Where the benchmark ran: platform, processor, CPU count, load average at the end."""
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "load_average": load, "python": platform.python_version()}


def benchmark_table(config: BenchmarkConfig, splits: dict[str, Split], systems: Sequence[SystemRuns],
                    trained: Sequence[TrainedBaseline], curve: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """The benchmark's results document (``table.json``; docs/benchmark-protocol.md)."""
    scale = scale_of(systems)
    entries = [system_entry(s, scale, config.bootstrap) for s in systems]
    for e in entries:
        if e["kind"] != "baseline":
            continue
        mine = [b for b in trained if b.algo == e["name"] and b.train_tests == config.train_count]
        e["settings"] = baseline_settings(e["name"], config.trainer)
        e["training"] = [
            {"seed": b.seed, "steps": b.steps, "seconds": round(b.seconds, 1), "curve_seconds": round(b.curve_seconds, 1),
             "model": str(b.path), "curve": [[step, rates.get("train"), rates.get("validation")] for step, rates in b.curve]}
            for b in mine
        ]
    baselines = [e for e in entries if e["kind"] == "baseline"]
    headline = {
        "normalized_held_out": {e["name"]: {m: (e["test"][m] or {}).get("normalized") for m in ("greedy", "sampled")}
                                for e in baselines if "test" in e},
        "held_out_gap": {e["name"]: e["gap"] for e in baselines},
    }
    return {
        "format": RESULTS_FORMAT, "version": RESULTS_VERSION,
        "pool": config.pool,
        "command": command_of(config),
        "splits": {s: {"count": len(sp.artifacts), "scored": len(sp.files), "seeds": [sp.seeds[0], sp.seeds[-1]]}
                   for s, sp in splits.items()},
        "config": {"steps": config.steps, "seeds": list(config.seeds), "algos": config.baselines(), "trainer": config.trainer,
                   "runs": config.runs, "curve_points": config.curve_points, "curve_sizes": config.curve(),
                   "curve_seeds": config.curve_seeds, "suts": list(config.suts), "bootstrap": config.bootstrap,
                   "train_eval_count": config.train_eval_count, "report_tests": config.report_tests},
        "budget": {"steps_per_run": config.steps,
                   "training_runs": len(trained),
                   "training_steps": int(sum(b.steps for b in trained))},
        "scale": scale,
        "headline": headline,
        "systems": entries,
        "generalization": curve or [],
        "commit": commit(),
        "machine": machine(),
    }


def mean_text(stat: dict[str, Any] | None) -> str:
    """A share's mean over seeds with its t-interval (:func:`~experiments.benchmark.statistics.mean_ci`):
    ``"61.2 % ± 4.0"``."""
    if not stat or stat["mean"] is None:
        return MISSING
    ci = "" if stat["ci95"] is None else f" ± {100 * stat['ci95']:.1f}"
    return f"{percent(stat['mean'], 1)}{ci}"


def _gap(stat: dict[str, Any]) -> str:
    if stat["mean"] is None:
        return MISSING
    ci = "" if stat["ci95"] is None else f" ± {100 * stat['ci95']:.1f}"
    return f"{100 * stat['mean']:+.1f} pp{ci}"


def interval_text(n: dict[str, Any] | None) -> str:
    """A normalized score's IQM and 95 % interval
    (:func:`~experiments.benchmark.statistics.normalized_summary`): ``"0.42 [0.31, 0.55]"``."""
    if not n or n.get("iqm") is None:
        return MISSING
    return f"{n['iqm']:.2f} [{n['low']:.2f}, {n['high']:.2f}]"


def worst_text(mode: dict[str, Any] | None) -> str:
    """The worst-10 % column of a mode's summary: its normalized score and raw met share,
    ``"-0.50 (12.5 % met)"``."""
    if not mode or mode["normalized"].get("worst10") is None:
        return MISSING
    return f"{mode['normalized']['worst10']:.2f} ({percent(mode['normalized']['worst10_met'], 1)} met)"


def _mode(e: dict[str, Any], split: str, mode: str) -> dict[str, Any] | None:
    s = e.get(split)
    return None if s is None else s.get(mode)


TABLE_COLUMNS = ["system", "kind", "seeds", "held-out normalized, greedy: IQM [95 % CI]", "held-out normalized, sampled",
                 "held-out met, greedy", "held-out met, sampled", "worst 10 % held-out (normalized)", "validation met",
                 "train met", "held-out gap", "held-out realized (of met)"]


def table_rows(doc: dict[str, Any]) -> list[list[str]]:
    """The rows of ``table.md`` (see :data:`TABLE_COLUMNS`)."""
    rows = []
    for e in doc["systems"]:
        seeds = ", ".join(str(r["seed"]) for r in e["runs"]) if e["kind"] == "baseline" else MISSING
        g, s = _mode(e, "test", "greedy"), _mode(e, "test", "sampled")
        rows.append([e["name"], e["kind"], seeds, interval_text(g["normalized"] if g else None),
                     interval_text(s["normalized"] if s else None), mean_text(g["met"] if g else None),
                     mean_text(s["met"] if s else None), worst_text(g or s),
                     mean_text(e["validation"]["met"] if "validation" in e else None),
                     mean_text(e["train"]["met"] if "train" in e else None),
                     _gap(e["gap"]), mean_text(e["test"]["realized"] if "test" in e else None)])
    return rows


def headline_text(doc: dict[str, Any]) -> str:
    """One line: each baseline's held-out normalized score (IQM and interval), greedy."""
    parts = []
    for name, modes in doc["headline"]["normalized_held_out"].items():
        parts.append(f"{name} {interval_text(modes.get('greedy'))} greedy, {interval_text(modes.get('sampled'))} sampled")
    return "held-out normalized score (0 = random, 1 = reference): " + ("; ".join(parts) if parts else "no baseline trained")


def table_markdown(doc: dict[str, Any]) -> str:
    """``table.md``: the headline, the budget, the table, the curve and what the columns mean."""
    sp, cfg, sc = doc["splits"], doc["config"], doc["scale"]

    lines = [
        f"# FlowTest benchmark: {doc['pool']}", "",
        f"**{headline_text(doc)}**", "",
        f"Splits: train {sp['train']['count']} tests (the first {sp['train']['scored']} scored), validation "
        f"{sp['validation']['count']}, held-out test {sp['test']['count']} (never seen in training). "
        f"Scale per split (met): floor = random ({runs_text(cfg['runs'])} per test) "
        + ", ".join(f"{s} {percent(sc[s]['floor'], 1)}" for s in SPLIT_NAMES)
        + "; ceiling = the best reference " + ", ".join(f"{s} {percent(sc[s]['ceiling'], 1)}" for s in SPLIT_NAMES) + ".", "",
        f"**Budget**: {cfg['steps']:,} time steps per training run, {doc['budget']['training_runs']} runs "
        f"({doc['budget']['training_steps']:,} steps in all, trainer {cfg['trainer']}); training seeds "
        f"{', '.join(map(str, cfg['seeds']))}; the final model is scored (no model selection).", "",
        "| " + " | ".join(TABLE_COLUMNS) + " |", "|" + "---|" * len(TABLE_COLUMNS),
    ]
    lines += ["| " + " | ".join(row) + " |" for row in table_rows(doc)]
    if doc["generalization"]:
        lines += ["", "## Generalization curve (held-out normalized score against training tests)", "",
                  "| training tests | seeds | greedy: IQM [95 % CI] | sampled: IQM [95 % CI] | train met (greedy) |",
                  "|---|---|---|---|---|"]
        for p in doc["generalization"]:
            lines.append(f"| {p['train_tests']:,} | {len(p['seeds'])} | {interval_text(p['greedy'])} | {interval_text(p['sampled'])} | "
                         f"{percent(p['train_met'], 1)} |")
    lines += [
        "",
        "*Normalized*: (met - floor) / (ceiling - floor) on the split, 0 = random, 1 = the reference; IQM: the "
        "interquartile mean over training seeds of each seed's score; [95 % CI]: stratified bootstrap (seeds resampled, "
        f"tests resampled within each seed), {cfg['bootstrap']} replicates. *Greedy*: each test played once by the most "
        f"likely action; *sampled*: {runs_text(cfg['runs'], 'seeded ')} per test drawn from the policy. *Worst 10 %*: the mean "
        "over the 10 % of held-out tests the policy met least often. *Met*: share of runs whose system objective was "
        "met (± 95 % t-interval over seeds). *Realized (of met)*: share of those that also realized the hidden test "
        "objective (the synthesized test guarantees 100 %). *Held-out gap*: train met minus held-out met per seed.",
    ]
    bugs = [e["name"] for e in doc["systems"] if any(e.get(s, {}).get("test_failures") for s in SPLIT_NAMES)]
    if bugs:
        lines += ["", f"**FLOWTEST BUG: a test failed its guarantee for {', '.join(bugs)}; see report.html.**"]
    return "\n".join(lines) + "\n"
