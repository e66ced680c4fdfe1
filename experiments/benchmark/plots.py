"""The benchmark's pictures: the learning curves (``learning-curves.png``) and the
generalization curve (``generalization.png``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .statistics import mean_ci


def _figure(width: float, height: float) -> tuple[Any, Any]:
    """A figure with one axes, drawn off screen."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(width, height))
    return fig, ax


def _save(fig: Any, ax: Any, title: str, path: Path) -> None:
    """Grid, title and legend on ``ax``; ``fig`` written to ``path`` and freed."""
    import matplotlib.pyplot as plt

    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


COLORS = {"maskable-ppo": "#1f77b4", "recurrent-ppo": "#d62728", "plr-ppo": "#9467bd", "counts-ppo": "#2ca02c"}


def plot_learning_curves(doc: dict[str, Any], path: Path) -> None:
    """Share of tests met against time steps, per baseline: on the scored train tests
    (solid) and the validation tests (dashed), the mean over seeds with its 95 % band."""
    fig, ax = _figure(7.5, 4.6)
    for e in doc["systems"]:
        if e["kind"] != "baseline" or not e.get("training"):
            continue
        color = COLORS.get(e["name"], None)
        steps = [p[0] for p in e["training"][0]["curve"]]
        for col, split, style in ((1, "train", "-"), (2, "validation", "--")):
            runs = [[p[col] for p in t["curve"]] for t in e["training"] if len(t["curve"]) == len(steps)]
            stats = [mean_ci([r[k] for r in runs]) for k in range(len(steps))]
            if any(s["mean"] is None for s in stats):
                continue
            mean = np.array([100 * s["mean"] for s in stats])
            ax.plot(steps, mean, style, color=color, lw=2, label=f"{e['name']}, {split} tests")
            if len(runs) > 1:
                half = np.array([100 * (s["ci95"] or 0.0) for s in stats])
                ax.fill_between(steps, np.clip(mean - half, 0, 100), np.clip(mean + half, 0, 100), color=color, alpha=0.12)
    floor = doc["scale"]["validation"]["floor"]
    if floor is not None:
        ax.axhline(100 * floor, color="#7f7f7f", lw=1, ls=":", label="random (validation)")
    ceiling = doc["scale"]["validation"]["ceiling"]
    if ceiling is not None:
        ax.axhline(100 * ceiling, color="#2ca02c", lw=1, ls=":", label="reference (validation)")
    ax.set_xlabel("time steps")
    ax.set_ylabel("tests whose system objective is met (%)")
    ax.set_ylim(-3, 103)
    _save(fig, ax, f"{doc['pool']}: greedy play during training (mean over seeds, 95 % band)", path)


def plot_generalization(doc: dict[str, Any], path: Path) -> None:
    """The held-out normalized score with its 95 % interval against the number of training
    tests (log scale), sampled (the headline) and greedy; a preliminary point (fewer than 5
    seeds: the mean with its t interval, not the IQM) is drawn hollow."""
    pts = doc["generalization"]
    fig, ax = _figure(6.5, 4.2)
    for mode, color in (("sampled", "#ff7f0e"), ("greedy", "#1f77b4")):
        shown = [p for p in pts if p[mode].get("point") is not None]
        if not shown:
            continue
        xs = [p["train_tests"] for p in shown]
        ys = np.array([p[mode]["point"] for p in shown])
        lo = np.array([p[mode]["low"] for p in shown])
        hi = np.array([p[mode]["high"] for p in shown])
        ax.plot(xs, ys, "-", color=color, lw=2, label=f"{pts[0]['algo']}, {mode}")
        ax.fill_between(xs, lo, hi, color=color, alpha=0.15)
        for x, y, p in zip(xs, ys, shown, strict=True):
            ax.plot([x], [y], "o", color=color, mfc="white" if p[mode].get("preliminary") else color)
    ax.axhline(0.0, color="#7f7f7f", lw=1, ls=":", label="random (0)")
    ax.axhline(1.0, color="#2ca02c", lw=1, ls=":", label="reference (1)")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("training tests")
    ax.set_ylabel("held-out normalized score, 95 % CI\n(IQM; hollow: fewer than 5 seeds, mean)")
    _save(fig, ax, f"{doc['pool']}: generalization ({doc['splits']['test']['count']} held-out tests)", path)
