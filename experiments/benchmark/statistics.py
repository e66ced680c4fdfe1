"""The benchmark's statistics (protocol step 4, docs/benchmark-protocol.md): means with their
t-intervals over seeds, the normalized score between the floor and the ceiling with its
interquartile mean and stratified-bootstrap interval (:mod:`flowtest_env.scoring`), and each
system's entry of the results file."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .config import SPLIT_NAMES

WORST_SHARE = 0.1
"""The worst share of the held-out tests whose mean score the table shows (CVaR-style)."""

T95: dict[int, float] = {}
"""The t quantiles computed so far (:func:`t_quantile`)."""


def t_quantile(df: int) -> float:
    """The 0.975 quantile of Student's t with ``df`` degrees of freedom."""
    if df not in T95:
        from scipy.stats import t

        T95[df] = float(t.ppf(0.975, df))
    return T95[df]


def mean_ci(values: Sequence[float | None]) -> dict[str, Any]:
    """``mean`` and ``ci95`` (the half-width of the 95 % confidence interval of the mean,
    Student's t; ``None`` for fewer than two values) of the values that are not ``None``,
    with the values themselves."""
    xs = [float(v) for v in values if v is not None]
    if not xs:
        return {"mean": None, "ci95": None, "values": list(values)}
    mean = float(np.mean(xs))
    ci = t_quantile(len(xs) - 1) * float(np.std(xs, ddof=1)) / math.sqrt(len(xs)) if len(xs) > 1 else None
    return {"mean": mean, "ci95": ci, "values": list(values)}


def normalized_summary(per_seed_tests: Sequence[Sequence[float]], floor: float | None, ceiling: float | None,
                       reps: int, seed: int = 0) -> dict[str, Any]:
    """The normalized score of one policy on one split from its per-test met shares
    ``[seeds][tests]``: ``iqm`` (the interquartile mean over seeds of each seed's normalized
    score) with its stratified-bootstrap 95 % interval ``low``, ``high``
    (:func:`flowtest_env.scoring.stratified_bootstrap`), ``mean`` over seeds, the
    ``worst10`` (the mean normalized score of the worst 10 % of the tests, each test's met
    averaged over seeds) and its raw ``worst10_met``; ``None`` values when there is no scale
    (no floor or ceiling, or the ceiling not above the floor)."""
    from flowtest_env.scoring import normalized, stratified_bootstrap, worst_share_mean

    m = np.asarray(per_seed_tests, dtype=np.float64)
    worst = worst_share_mean(m.mean(axis=0), WORST_SHARE)
    out: dict[str, Any] = {"iqm": None, "low": None, "high": None, "mean": None, "worst10": normalized(worst, floor, ceiling),
                           "worst10_met": worst, "seeds": int(m.shape[0]), "tests": int(m.shape[1])}
    if floor is None or ceiling is None or not ceiling > floor:
        return out
    z = (m - floor) / (ceiling - floor)
    point, low, high = stratified_bootstrap(z, reps=reps, seed=seed)
    out.update(iqm=point, low=low, high=high, mean=float(z.mean()))
    return out


@dataclass
class SystemRuns:
    """What one system did: per seed (or once) and split, the metrics of its greedy and
    sampled play (``None`` where it has no such mode)."""

    name: str
    kind: str  # baseline, floor, reference, system
    runs: list[dict[str, Any]]  # {"seed", "sut", split: {"greedy": metrics|None, "sampled": metrics|None}}


def scale_of(systems: Sequence[SystemRuns]) -> dict[str, dict[str, Any]]:
    """Per split, the floor (random's met) and the ceiling (the best reference's met)."""
    scale: dict[str, dict[str, Any]] = {}
    floor = next((s for s in systems if s.kind == "floor"), None)
    refs = [s for s in systems if s.kind == "reference"]
    for split in SPLIT_NAMES:
        f = floor.runs[0][split]["sampled"]["met"] if floor and floor.runs[0].get(split) else None
        best, who = None, None
        for r in refs:
            if r.runs[0].get(split):
                met = r.runs[0][split]["greedy"]["met"]
                if best is None or met > best:
                    best, who = met, r.name
        scale[split] = {"floor": f, "ceiling": best, "ceiling_from": who}
    return scale


def _mode_summary(runs: Sequence[dict[str, Any]], split: str, mode: str, scale: dict[str, Any], reps: int) -> dict[str, Any] | None:
    rows = [r[split][mode] for r in runs if r.get(split) and r[split].get(mode)]
    if not rows:
        return None
    out: dict[str, Any] = {key: mean_ci([r[key] for r in rows]) for key in ("met", "realized", "restrictions", "steps")}
    out["runs_per_test"] = rows[0]["runs"]
    out["test_failures"] = sum(r["test_failures"] for r in rows)
    out["normalized"] = normalized_summary([r["per_test"] for r in rows], scale["floor"], scale["ceiling"], reps)
    return out


def system_entry(s: SystemRuns, scale: dict[str, dict[str, Any]], reps: int) -> dict[str, Any]:
    """A system's entry in ``table.json`` (docs/benchmark-protocol.md, *The results file*)."""
    entry: dict[str, Any] = {"name": s.name, "kind": s.kind, "runs": []}
    for r in s.runs:
        row: dict[str, Any] = {"seed": r["seed"], "sut": r["sut"]}
        for split in SPLIT_NAMES:
            if not r.get(split):
                continue
            main = r[split]["greedy"] or r[split]["sampled"]
            row[split] = {k: main[k] for k in ("met", "realized", "restrictions", "steps", "test_failures")}
            row[split]["greedy"] = r[split]["greedy"]
            row[split]["sampled"] = r[split]["sampled"]
        tr, te = row.get("train"), row.get("test")
        row["gap"] = None if tr is None or te is None or tr["met"] is None or te["met"] is None else tr["met"] - te["met"]
        entry["runs"].append(row)
    for split in SPLIT_NAMES:
        greedy = _mode_summary(s.runs, split, "greedy", scale[split], reps)
        sampled = _mode_summary(s.runs, split, "sampled", scale[split], reps)
        main = greedy or sampled
        if main is None:
            continue
        entry[split] = {k: main[k] for k in ("met", "realized", "restrictions", "steps", "test_failures")}
        entry[split]["headline_mode"] = "greedy" if greedy else "sampled"
        entry[split]["greedy"], entry[split]["sampled"] = greedy, sampled
    entry["gap"] = mean_ci([r["gap"] for r in entry["runs"]])
    return entry
