"""The benchmark's statistics (protocol step 4, docs/benchmark-protocol.md): means with their
t-intervals over seeds, the normalized score between the floor and the ceiling with its
interval (the IQM and the seed-and-test bootstrap, or with fewer than 5 seeds the mean and a
t interval: :func:`flowtest_env.scoring.score_interval`), the tail (the CVaR of the per-test
met shares: :func:`flowtest_env.scoring.tail_score`), each system's entry of the results file
and the per-run score matrices (:func:`score_matrices`). A system is its runs, one per seed,
wherever they come from (training seeds, checkpoints given by ``--sut``, or one run)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .config import SPLIT_NAMES

T95: dict[int, float] = {}
"""The t quantiles computed so far (:func:`t_quantile`)."""


def t_quantile(df: int) -> float:
    """The 0.975 quantile of Student's t with ``df`` degrees of freedom."""
    if df not in T95:
        from scipy.stats import t

        T95[df] = float(t.ppf(0.975, df))
    return T95[df]


def binomial_half_width(p: float, n: int) -> float:
    """The 95 % normal-approximation half-width of a share ``p`` of ``n`` tests."""
    return 1.96 * math.sqrt(max(p * (1 - p), 0.0) / max(n, 1))


def still_rising(shares: Sequence[float], n: int) -> bool:
    """Whether a learning curve of met shares on ``n`` tests had not levelled off: its last
    point is above the one before by more than the last share's
    :func:`binomial_half_width` (so a longer budget would likely score higher)."""
    return len(shares) >= 2 and shares[-1] - shares[-2] > binomial_half_width(shares[-1], n)


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


HEADLINE_MODE = "sampled"
"""The headline's mode (docs/benchmark-protocol.md, *The headline*): a learned policy's
sampled play; a system without one (deterministic: the references, a greedy ``python:``
policy) is its greedy play, which its sampled runs would repeat."""


@dataclass(frozen=True, eq=False)
class Scale:
    """A split's scale: the per-test met shares of the floor (``random``, ``floor_runs``
    runs per test) and of the ceiling (the reference ``ceiling_from``, the best of the
    references on the split; once per test), on the split's scored tests in their order.
    The normalized score's interval resamples them with the system's tests
    (:func:`flowtest_env.scoring.score_interval`)."""

    floor: np.ndarray | None
    ceiling: np.ndarray | None
    ceiling_from: str | None
    floor_runs: int | None

    def to_json(self) -> dict[str, Any]:
        """``floor`` and ``ceiling`` (their met shares), ``ceiling_from``, ``floor_runs``, and
        ``ceiling_is_bound``: whether the reference meets every test (then it is a ceiling;
        below 100 % it is a reference a system can beat)."""
        f = None if self.floor is None else float(self.floor.mean())
        c = None if self.ceiling is None else float(self.ceiling.mean())
        return {"floor": f, "ceiling": c, "ceiling_from": self.ceiling_from, "floor_runs": self.floor_runs, "ceiling_is_bound": None if c is None else c >= 1.0}


def normalized_summary(per_seed_tests: Sequence[Sequence[float]], scale: Scale, reps: int, seed: int = 0) -> dict[str, Any]:
    """The normalized score of one policy on one split from its per-test met shares
    ``[seeds][tests]`` (:func:`flowtest_env.scoring.score_interval`): ``point`` (the IQM over
    seeds with 5 seeds or more, else the mean: ``statistic``), ``low``, ``high`` (its 95 %
    interval: ``interval`` names the procedure), ``preliminary`` (fewer than 5 seeds),
    ``mean``, ``seeds``, ``tests``, and for a t interval ``seed_se``, ``test_se``; ``point``
    ``None`` when there is no scale (no floor or ceiling, or the ceiling not above the floor)."""
    from flowtest_env.scoring import PRELIMINARY_SEEDS, score_interval

    m = np.asarray(per_seed_tests, dtype=np.float64)
    got = None
    if scale.floor is not None and scale.ceiling is not None:
        got = score_interval(m, scale.floor, scale.ceiling, reps=reps, seed=seed)
    if got is None:
        return {
            "point": None,
            "low": None,
            "high": None,
            "statistic": None,
            "interval": None,
            "mean": None,
            "preliminary": m.shape[0] < PRELIMINARY_SEEDS,
            "seeds": int(m.shape[0]),
            "tests": int(m.shape[1]),
        }
    return got.to_json()


@dataclass
class SystemRuns:
    """What one system did: per seed (or once) and split, the metrics of its greedy and
    sampled play (``None`` where it has no such mode)."""

    name: str
    kind: str  # baseline, floor, reference, system
    runs: list[dict[str, Any]]  # {"seed", "sut", split: {"greedy": metrics|None, "sampled": metrics|None}}


def scale_of(systems: Sequence[SystemRuns]) -> dict[str, Scale]:
    """Per split, the :class:`Scale`: the floor (random's per-test met shares) and the
    ceiling (the per-test met of the reference that meets most tests of the split)."""
    scale: dict[str, Scale] = {}
    floor = next((s for s in systems if s.kind == "floor"), None)
    refs = [s for s in systems if s.kind == "reference"]
    for split in SPLIT_NAMES:
        f = floor.runs[0][split]["sampled"] if floor and floor.runs and floor.runs[0].get(split) else None
        best: dict[str, Any] | None = None
        who = None
        for r in refs:
            if r.runs and r.runs[0].get(split):
                mine = r.runs[0][split]["greedy"]
                if best is None or mine["met"] > best["met"]:
                    best, who = mine, r.name
        scale[split] = Scale(
            None if f is None else np.asarray(f["per_test"], dtype=np.float64),
            None if best is None else np.asarray(best["per_test"], dtype=np.float64),
            who,
            None if f is None else int(f["runs"]),
        )
    return scale


def headline_mode(modes: dict[str, Any]) -> str | None:
    """The mode of a system's headline on a split (:data:`HEADLINE_MODE` where it was played,
    else its greedy play), from its ``{"greedy": ..., "sampled": ...}``; ``None`` if neither."""
    if modes.get(HEADLINE_MODE):
        return HEADLINE_MODE
    return next((m for m in ("greedy", "sampled") if modes.get(m)), None)


def _gap(train: dict[str, Any] | None, test: dict[str, Any] | None) -> float | None:
    """Train met minus held-out met in the same mode (greedy where both have it: the train
    split is played greedily only)."""
    if not train or not test:
        return None
    for mode in ("greedy", "sampled"):
        if train.get(mode) and test.get(mode):
            a, b = train[mode]["met"], test[mode]["met"]
            return None if a is None or b is None else float(a - b)
    return None


def _mode_summary(s: SystemRuns, split: str, mode: str, scale: Scale, reps: int) -> dict[str, Any] | None:
    rows = [r[split][mode] for r in s.runs if r.get(split) and r[split].get(mode)]
    if not rows:
        return None
    from flowtest_env.scoring import TAIL_SHARE, tail_score

    out: dict[str, Any] = {key: mean_ci([r[key] for r in rows]) for key in ("met", "realized", "restrictions", "steps")}
    out["runs_per_test"] = rows[0]["runs"]
    out["test_failures"] = sum(r["test_failures"] for r in rows)
    matrix = [r["per_test"] for r in rows]
    out["normalized"] = normalized_summary(matrix, scale, reps)
    if s.kind == "floor":
        out["normalized"]["defines"] = "floor"  # 0 by definition: its own runs are the floor
    elif s.name == scale.ceiling_from:
        out["normalized"]["defines"] = "ceiling"  # 1 by definition
    out["tail"] = tail_score(matrix, TAIL_SHARE).to_json()
    return out


def system_entry(s: SystemRuns, scale: dict[str, Scale], reps: int) -> dict[str, Any]:
    """A system's entry in ``table.json`` (docs/benchmark-protocol.md, *The results file*):
    per split its headline mode's numbers (:func:`headline_mode`) and both modes' summaries,
    whatever number of seeds (training seeds, checkpoints, or one) its runs come from."""
    entry: dict[str, Any] = {"name": s.name, "kind": s.kind, "runs": []}
    for r in s.runs:
        row: dict[str, Any] = {"seed": r["seed"], "sut": r["sut"]}
        for split in SPLIT_NAMES:
            mode = headline_mode(r.get(split) or {})
            if mode is None:
                continue
            main = r[split][mode]
            row[split] = {k: main[k] for k in ("met", "realized", "restrictions", "steps", "test_failures")}
            row[split]["headline_mode"] = mode
            row[split]["greedy"] = r[split]["greedy"]
            row[split]["sampled"] = r[split]["sampled"]
        row["gap"] = _gap(row.get("train"), row.get("test"))
        entry["runs"].append(row)
    for split in SPLIT_NAMES:
        modes = {m: _mode_summary(s, split, m, scale[split], reps) for m in ("greedy", "sampled")}
        mode = headline_mode(modes)
        if mode is None:
            continue
        main = modes[mode]
        assert main is not None
        entry[split] = {k: main[k] for k in ("met", "realized", "restrictions", "steps", "test_failures")}
        entry[split]["headline_mode"] = mode
        entry[split]["greedy"], entry[split]["sampled"] = modes["greedy"], modes["sampled"]
    entry["gap"] = mean_ci([r["gap"] for r in entry["runs"]])
    return entry


SCORES_FILE = "scores.npz"
"""The per-run score matrices a benchmark writes beside ``table.json`` (:func:`score_matrices`)."""


def score_matrices(doc: dict[str, Any]) -> dict[str, np.ndarray]:
    """Every system's per-run met shares from a results document (``table.json``), as
    rliable reads them: ``"SPLIT/MODE/SYSTEM"`` (``"test/sampled/maskable-ppo"``) ->
    ``float [runs, tests]``, one row per seed (training seed or checkpoint; one row for a
    system scored once), one column per scored test in the split's order, each entry the
    share of that test's runs met (0 or 1 greedy, ``k / K`` of ``K`` sampled runs). The floor
    and the references are there too, so the normalized matrix is
    ``(m - floor.mean()) / (ceiling.mean() - floor.mean())``.

    Example::

        import numpy as np
        z = np.load("bench/scores.npz")
        held_out = {k.split("/", 2)[2]: z[k] for k in z.files if k.startswith("test/sampled/")}
    """
    out: dict[str, np.ndarray] = {}
    for e in doc["systems"]:
        for split in SPLIT_NAMES:
            for mode in ("greedy", "sampled"):
                rows = [r[split][mode]["per_test"] for r in e["runs"] if r.get(split) and r[split].get(mode)]
                if rows:
                    out[f"{split}/{mode}/{e['name']}"] = np.asarray(rows, dtype=np.float64)
    return out
