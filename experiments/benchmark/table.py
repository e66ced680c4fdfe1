"""The benchmark's results: ``table.json``'s document (docs/benchmark-protocol.md, *The results
file*) and ``table.md``, with the commit and the machine they came from."""

from __future__ import annotations

import os
import platform
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from experiments.formatting import MISSING, percent

from .config import SPLIT_NAMES, BenchmarkConfig, baseline_settings, command_of, runs_text
from .pool import Split
from .statistics import HEADLINE_MODE, SCORES_FILE, SystemRuns, binomial_half_width, scale_of, still_rising, system_entry
from .training_runs import TrainedBaseline

RESULTS_FORMAT = "flowtest-benchmark"
RESULTS_VERSION = 3
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
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "load_average": load,
        "python": platform.python_version(),
    }


def benchmark_table(
    config: BenchmarkConfig,
    splits: dict[str, Split],
    systems: Sequence[SystemRuns],
    trained: Sequence[TrainedBaseline],
    curve: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """The benchmark's results document (``table.json``; docs/benchmark-protocol.md)."""
    scales = scale_of(systems)
    entries = [system_entry(s, scales, config.bootstrap) for s in systems]
    for e in entries:
        if e["kind"] != "baseline":
            continue
        mine = [b for b in trained if b.algo == e["name"] and b.train_tests == config.train_count]
        e["settings"] = baseline_settings(e["name"], config.trainer)
        e["training"] = [
            {
                "seed": b.seed,
                "steps": b.steps,
                "seconds": round(b.seconds, 1),
                "curve_seconds": round(b.curve_seconds, 1),
                "model": str(b.path),
                "selected_step": b.selected_step,
                "curve": [[step, rates.get("train"), rates.get("validation")] for step, rates in b.curve],
            }
            for b in mine
        ]
    contenders = [e for e in entries if e["kind"] in CONTENDERS]
    headline = {
        "mode": HEADLINE_MODE,
        "normalized_held_out": {
            e["name"]: {"headline_mode": e["test"]["headline_mode"], **{m: (e["test"][m] or {}).get("normalized") for m in ("greedy", "sampled")}}
            for e in contenders
            if "test" in e
        },
        "tail_held_out": {e["name"]: (e["test"][e["test"]["headline_mode"]] or {}).get("tail") for e in contenders if "test" in e},
        "held_out_gap": {e["name"]: e["gap"] for e in contenders},
    }
    split_doc = {s: {"count": len(sp.artifacts), "scored": len(sp.files), "seeds": [sp.seeds[0], sp.seeds[-1]]} for s, sp in splits.items()}
    cfg = {
        "steps": config.steps,
        "seeds": list(config.seeds),
        "algos": config.baselines(),
        "trainer": config.trainer,
        "select": config.select,
        "runs": config.runs,
        "curve_points": config.curve_points,
        "curve_sizes": config.curve(),
        "curve_seeds": config.curve_seeds,
        "suts": list(config.suts),
        "bootstrap": config.bootstrap,
        "train_eval_count": config.train_eval_count,
        "report_tests": config.report_tests,
    }
    budget = {"steps_per_run": config.steps if trained else None, "training_runs": len(trained), "training_steps": int(sum(b.steps for b in trained))}
    return {
        "format": RESULTS_FORMAT,
        "version": RESULTS_VERSION,
        "pool": config.pool,
        "command": command_of(config),
        "splits": split_doc,
        "config": cfg,
        "budget": budget,
        "ran": what_ran(
            cfg,
            split_doc,
            budget,
            [
                {
                    "name": e["name"],
                    "kind": e["kind"],
                    "seeds": [r["seed"] for r in e["runs"]],
                    "modes": _modes(e),
                    "trained": [
                        {"seed": t["seed"], "steps": t["steps"], "selected_step": t.get("selected_step"), "validation": [p[2] for p in t["curve"]]}
                        for t in e.get("training", [])
                    ],
                }
                for e in entries
            ],
            curve or [],
        ),
        "scale": {split: sc.to_json() for split, sc in scales.items()},
        "headline": headline,
        "systems": entries,
        "generalization": curve or [],
        "commit": commit(),
        "machine": machine(),
    }


CONTENDERS = ("baseline", "system")
"""The kinds of system the headline ranks: the trained baselines and the systems given by
``--sut`` (not the floor and the references, which define the scale)."""


def _modes(e: dict[str, Any]) -> list[str]:
    """The modes a system entry was played in on the held-out tests."""
    test = e.get("test") or {}
    return [m for m in ("greedy", "sampled") if test.get(m)]


def what_ran(
    config: dict[str, Any], splits: dict[str, Any], budget: dict[str, Any], systems: Sequence[dict[str, Any]], curve: Sequence[dict[str, Any]] = ()
) -> dict[str, Any]:
    """What a benchmark trained and what it only scored (``table.json``'s ``ran``), from its
    ``config``, ``splits``, ``budget``, its systems (each ``name``, ``kind``, ``seeds``: one per
    run, ``modes``, and for a baseline ``trained``: ``[{"seed", "steps"}]`` of its training runs
    here; without that key, an older result's, its seeds at ``config["steps"]``) and its
    generalization ``curve``: ``trained`` (per baseline trained here: ``algo``, ``seeds``,
    ``steps`` (the largest run's), ``train_tests``, ``trainer``, ``select`` (which model was
    scored: ``"validation"`` or ``"final"``), ``selected_steps`` (per run, the step of the model
    scored) and ``plateau`` (:func:`validation_plateau` of the runs' validation curves, where
    they were recorded)), ``curve`` (per extra
    training-set size: ``train_tests``, ``seeds``), ``training_runs``, ``training_steps``, and
    ``scored`` (each other system: ``name``, ``kind``, ``seeds`` (how many runs: seeds or
    checkpoints), ``modes``, ``runs_per_test`` of its sampled play)."""
    train_tests = splits["train"]["count"]
    trained, scored = [], []
    for s in systems:
        runs = s.get("trained")
        if runs is None and s["kind"] == "baseline":
            runs = [{"seed": seed, "steps": config["steps"]} for seed in s["seeds"]]
        if runs:
            select = config.get("select", "final")
            trained.append(
                {
                    "algo": s["name"],
                    "seeds": [r["seed"] for r in runs],
                    "steps": max(r["steps"] for r in runs),
                    "train_tests": train_tests,
                    "trainer": config["trainer"],
                    "select": select,
                    "selected_steps": [r.get("selected_step") if select == "validation" else r["steps"] for r in runs],
                    "plateau": validation_plateau([r.get("validation") or [] for r in runs], splits["validation"]["count"]),
                }
            )
            continue
        modes = list(s.get("modes") or [])
        scored.append(
            {"name": s["name"], "kind": s["kind"], "seeds": len(s["seeds"]), "modes": modes, "runs_per_test": config["runs"] if "sampled" in modes else 1}
        )
    extra = [{"train_tests": p["train_tests"], "seeds": list(p["seeds"])} for p in curve if p["train_tests"] != train_tests]
    return {"trained": trained, "curve": extra, "training_runs": budget["training_runs"], "training_steps": budget["training_steps"], "scored": scored}


def validation_plateau(curves: Sequence[Sequence[float | None]], tests: int) -> dict[str, Any] | None:
    """Whether training runs reached their plateau on the validation split: per run, the
    greedy validation met gained from the next-to-last curve evaluation to the last (the last
    ``1 / curve_points`` of the budget), against the 95 % half-width of a met share on
    ``tests`` validation tests at the run's last share: a run whose gain exceeds it is
    **still rising** (:func:`~experiments.benchmark.statistics.still_rising`). ``None`` when fewer than two evaluations were recorded.

    >>> validation_plateau([[0.1, 0.5, 0.52], [0.1, 0.4, 0.6]], 256)["rising"]
    1
    """
    runs = [xs for xs in ([float(x) for x in c if x is not None] for c in curves) if len(xs) >= 2]
    if not runs:
        return None
    return {
        "median_last_gain": float(np.median([xs[-1] - xs[-2] for xs in runs])),
        "median_half_width": float(np.median([binomial_half_width(xs[-1], tests) for xs in runs])),
        "rising": sum(still_rising(xs, tests) for xs in runs),
        "runs": len(runs),
        "validation_tests": int(tests),
    }


def selection_text(t: dict[str, Any]) -> str:
    """What model of each of ``t``'s runs was scored, and whether the runs reached their
    validation plateau (:func:`validation_plateau`)."""
    if t.get("select") == "validation":
        steps = [s for s in t.get("selected_steps") or [] if s is not None]
        last = sum(1 for s in steps if s >= t["steps"])
        text = (
            f"{t['algo']}: each run's checkpoint with the best greedy met on the validation tests is scored"
            f" (selected at the final evaluation in {last} of {len(steps)} runs"
            + (f"; earlier at steps {', '.join(f'{s:,}' for s in sorted(set(steps)) if s < t['steps'])}" if last < len(steps) else "")
            + ")"
        )
    else:
        text = f"{t['algo']}: the final model of every run is scored (no model selection)"
    p = t.get("plateau")
    if p:
        verdict = "at its plateau" if p["rising"] == 0 else f"**still rising in {p['rising']} of {p['runs']} runs**"
        text += (
            f"; validation plateau: the last evaluation gained a median {100 * p['median_last_gain']:+.1f} pp over the one before"
            f" (95 % half-width on {p['validation_tests']:,} tests: {100 * p['median_half_width']:.1f} pp): {verdict}"
        )
    return text + "."


def seeds_text(seeds: Sequence[Any]) -> str:
    """``"0-9"`` for a run of consecutive seeds, else the seeds with commas."""
    xs = list(seeds)
    if len(xs) > 2 and all(isinstance(x, int) for x in xs) and xs == list(range(xs[0], xs[0] + len(xs))):
        return f"{xs[0]}-{xs[-1]}"
    return ", ".join(map(str, xs))


def ran_text(ran: dict[str, Any]) -> list[str]:
    """Two paragraphs: what was **trained** (each baseline's seeds, steps and train tests, the
    curve's runs, the totals) and what was **only scored** (every other system and how many
    seeds or runs each), so that a run that trained nothing says so."""
    trained = ran["trained"]
    if trained:
        parts = [
            f"{t['algo']}, seeds {seeds_text(t['seeds'])} ({len(t['seeds'])} run{'s' if len(t['seeds']) != 1 else ''}), "
            f"{t['steps']:,} time steps each on the first {t['train_tests']:,} train tests (trainer {t['trainer']})"
            for t in trained
        ]
        text = "**Trained**: " + "; ".join(parts)
        if ran["curve"]:
            text += (
                "; for the generalization curve "
                + trained[0]["algo"]
                + " on the first "
                + ", ".join(f"{p['train_tests']:,} ({len(p['seeds'])} seed{'s' if len(p['seeds']) != 1 else ''})" for p in ran["curve"])
                + " train tests"
            )
        text += f"; {ran['training_runs']} runs, {ran['training_steps']:,} time steps in all. " + " ".join(selection_text(t) for t in trained)
    else:
        text = "**Trained**: nothing (no baseline was trained in this run: `--sut` named none)."
    given = [s for s in ran["scored"] if s["kind"] not in ("floor", "reference")]
    words = []
    for s in given:
        modes = " and ".join(s["modes"]) or "no mode"
        runs = f", {s['runs_per_test']} sampled runs per test" if "sampled" in s["modes"] else ""
        words.append(f"`{s['name']}` ({s['seeds']} seed{'s' if s['seeds'] != 1 else ''}: {modes}{runs})")
    floors = [f"`{s['name']}` ({s['runs_per_test']} runs per test)" for s in ran["scored"] if s["kind"] == "floor"]
    refs = [f"`{s['name']}`" for s in ran["scored"] if s["kind"] == "reference"]
    scored = "**Only scored** (as given, not trained here): " + (", ".join(words) if words else "no other system")
    scored += "; the floor " + (", ".join(floors) or MISSING) + " and the references " + (", ".join(refs) or MISSING)
    return [text, "", scored + " (once per test: deterministic)."]


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


PRELIMINARY_MARK = "†"
"""Marks a preliminary score in the tables: fewer than 5 seeds, the mean with a t interval."""


def interval_text(n: dict[str, Any] | None) -> str:
    """A normalized score and its 95 % interval
    (:func:`~experiments.benchmark.statistics.normalized_summary`): ``"0.42 [0.31, 0.55]"``
    (the IQM over 5 or more seeds), ``"0.42 [0.21, 0.63]†"`` (preliminary: the mean over fewer
    seeds with its t interval), ``"0 (floor)"``, ``"1 (ceiling)"`` for the systems that
    define the scale; an older results file's ``iqm`` is shown as it was."""
    if not n:
        return MISSING
    if n.get("defines"):
        return "0 (floor)" if n["defines"] == "floor" else "1 (reference)"
    point = n.get("point", n.get("iqm"))
    if point is None:
        return MISSING
    mark = PRELIMINARY_MARK if n.get("preliminary") else ""
    return f"{point:.2f} [{n['low']:.2f}, {n['high']:.2f}]{mark}"


def tail_text(mode: dict[str, Any] | None) -> str:
    """The tail column of a mode's summary: the mean met share of its hardest 10 % of tests,
    ``"65.2 %"``."""
    if not mode or not mode.get("tail"):
        return MISSING
    return percent(mode["tail"]["point"], 1)


def _mode(e: dict[str, Any], split: str, mode: str) -> dict[str, Any] | None:
    s = e.get(split)
    return None if s is None else s.get(mode)


def headline_cell(e: dict[str, Any], what: str, met_text: Callable[[dict[str, Any]], str] | None = None) -> str:
    """A system's held-out headline: ``what`` is ``"normalized"``, ``"met"`` or ``"tail"`` of
    its headline mode (``met_text`` writes a mode's met, by default its mean and t interval);
    a deterministic system's (greedy) is marked ``(greedy)``."""
    test = e.get("test")
    if not test:
        return MISSING
    mode = test.get("headline_mode") or ("sampled" if test.get("sampled") else "greedy")
    m = test.get(mode)
    if what == "normalized":
        n = m["normalized"] if m else None
        text = interval_text(n)
        if n and n.get("defines"):
            return text
    elif what == "met":
        text = MISSING if not m else (met_text or (lambda x: mean_text(x["met"])))(m)
    else:
        text = tail_text(m)
    return text + (" (greedy)" if mode != HEADLINE_MODE and text != MISSING else "")


TABLE_COLUMNS = [
    "system",
    "kind",
    "seeds",
    "held-out normalized, sampled (headline) [95 % CI]",
    "held-out normalized, greedy",
    "held-out met, sampled",
    "held-out met, greedy",
    "hardest 10 % of held-out tests: met (CVaR)",
    "validation met",
    "train met",
    "held-out gap (greedy)",
    "held-out realized (of met)",
]


def table_rows(doc: dict[str, Any]) -> list[list[str]]:
    """The rows of ``table.md`` (see :data:`TABLE_COLUMNS`)."""
    rows = []
    for e in doc["systems"]:
        g = _mode(e, "test", "greedy")
        rows.append(
            [
                e["name"],
                e["kind"],
                str(len(e["runs"])),
                headline_cell(e, "normalized"),
                interval_text(g["normalized"] if g else None),
                headline_cell(e, "met"),
                mean_text(g["met"] if g else None),
                headline_cell(e, "tail"),
                mean_text(e["validation"]["met"] if "validation" in e else None),
                mean_text(e["train"]["met"] if "train" in e else None),
                _gap(e["gap"]),
                mean_text(e["test"]["realized"] if "test" in e else None),
            ]
        )
    return rows


def headline_text(doc: dict[str, Any]) -> str:
    """One line: each trained baseline's and given system's held-out normalized score, the
    headline (sampled; greedy for a deterministic system) first, greedy beside it."""
    parts = []
    for name, modes in doc["headline"]["normalized_held_out"].items():
        mode = modes.get("headline_mode") or HEADLINE_MODE
        text = f"{name} {interval_text(modes.get(mode))} {mode}"
        if mode != "greedy" and modes.get("greedy"):
            text += f" ({interval_text(modes.get('greedy'))} greedy)"
        parts.append(text)
    return "held-out normalized score, sampled (0 = random, 1 = reference): " + (
        "; ".join(parts) if parts else "no system besides the floor and the references"
    )


def scale_words(scale: dict[str, Any]) -> str:
    """What the top of the scale is called: ``"ceiling"`` where the reference meets every
    test, else ``"reference"`` (below 100 %: a system can beat it)."""
    c = scale.get("ceiling")
    return "ceiling" if c is not None and c >= 1.0 else "reference"


def table_markdown(doc: dict[str, Any]) -> str:
    """``table.md``: the headline, what ran, the table, the curve and what the columns mean."""
    sp, cfg, sc = doc["splits"], doc["config"], doc["scale"]
    tops = ", ".join(f"{s} {percent(sc[s]['ceiling'], 1)}" for s in SPLIT_NAMES)
    bound = all(scale_words(sc[s]) == "ceiling" for s in SPLIT_NAMES)
    lines = [
        f"# FlowTest benchmark: {doc['pool']}",
        "",
        f"**{headline_text(doc)}**",
        "",
        *ran_text(doc["ran"]),
        "",
        f"Splits: train {sp['train']['count']} tests (the first {sp['train']['scored']} scored), validation "
        f"{sp['validation']['count']}, held-out test {sp['test']['count']} (never seen in training). "
        f"Scale per split (met): floor = random ({runs_text(cfg['runs'])} per test) "
        + ", ".join(f"{s} {percent(sc[s]['floor'], 1)}" for s in SPLIT_NAMES)
        + (
            "; ceiling = the best reference " + tops
            if bound
            else "; reference = the best reference " + tops + " (below 100 %: the reference is not a ceiling, a system can score above 1)"
        )
        + ".",
        "",
        "| " + " | ".join(TABLE_COLUMNS) + " |",
        "|" + "---|" * len(TABLE_COLUMNS),
    ]
    lines += ["| " + " | ".join(row) + " |" for row in table_rows(doc)]
    if doc["generalization"]:
        lines += [
            "",
            "## Generalization curve (held-out normalized score against training tests)",
            "",
            "| training tests | seeds | sampled [95 % CI] | greedy [95 % CI] | train met (greedy) |",
            "|---|---|---|---|---|",
        ]
        for p in doc["generalization"]:
            lines.append(
                f"| {p['train_tests']:,} | {len(p['seeds'])} | {interval_text(p['sampled'])} | {interval_text(p['greedy'])} | {percent(p['train_met'], 1)} |"
            )
    lines += ["", COLUMNS_NOTE.format(bootstrap=cfg["bootstrap"], runs=runs_text(cfg["runs"], "seeded "), scores=SCORES_FILE)]
    bugs = [e["name"] for e in doc["systems"] if any(e.get(s, {}).get("test_failures") for s in SPLIT_NAMES)]
    if bugs:
        lines += ["", f"**FLOWTEST BUG: a test failed its guarantee for {', '.join(bugs)}; see report.html.**"]
    return "\n".join(lines) + "\n"


COLUMNS_NOTE = (
    "*Normalized*: (met - floor) / (ceiling - floor) on the split, 0 = random, 1 = the reference. With 5 seeds or more: "
    "the interquartile mean over seeds of each seed's score, [95 % CI] by the seed-and-test bootstrap ({bootstrap} "
    "replicates: seeds resampled, and the tests resampled once per replicate for every seed, the floor and the reference "
    "together, so the interval carries the floor's and the reference's sampling error). † *Preliminary* (fewer than 5 "
    "seeds): the mean over seeds, [95 % CI] the t interval over the seed means widened by the tests' and the floor's "
    "error. *Sampled* (the headline): {runs} per test drawn from the policy; *greedy*: each test played once by the most "
    "likely action; a deterministic system's headline is its greedy play. *Hardest 10 % (CVaR)*: the mean met share of "
    "the 10 % of held-out tests the system met least often (each test's share over seeds and runs; no interval: "
    "docs/benchmark-protocol.md). *Met*: share of runs whose system objective was met (± 95 % t-interval over "
    "seeds). *Realized (of met)*: share of those that also realized the hidden test objective (the synthesized test "
    "guarantees 100 %). *Held-out gap*: train met minus held-out met per seed, greedy. The per-run scores (seeds x "
    "tests, every system) are in {scores}."
)
