"""Pictures of one run (the evaluation report's ``traces/*.png``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .episodes import Trace, game_of_trace
from .report import test_title
from .violations import violation_of


def _trace_legend(ax: Any, game: Any) -> list[Any]:
    """Legend entries for the path markers and the renderer's symbols (each proposition
    of the system objective named), so a newcomer can read a trace picture without the
    env docs."""
    from .filmstrip import symbol_legend

    return list(ax.get_legend_handles_labels()[0]) + symbol_legend(game)


def trace_picture(trace: Trace, path: Path) -> None:
    """Draw a run: on grids the engineer's view (walls, hidden test cells) at the end of
    the run with the SUT's path numbered step by step; on graphs a strip of frames. The
    title names the test by its problem (never a path) and, for a violation, the broken
    conjunct of the system objective, the step and the cell."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flowtest_env.render import make_renderer

    game = game_of_trace(trace)
    tile = 48
    renderer = make_renderer(game, tile, "engineer")
    v = trace.verdict
    against = "" if trace.tester == "synthesized" else f" vs tester {trace.tester}"
    name = test_title(trace.env_id, str(game.artifact.name))
    title = (
        f"{trace.sut} on {name}{against} (seed {trace.seed})\n"
        f"system objective {v['system_objective']}, test objective "
        f"{'realized' if v['test_objective_realized'] else 'not realized'}, {v['steps']} steps, "
        f"{v['restrictions']} restricted decisions"
    )
    broke = violation_of(game.artifact, [r.system for r in trace.states]) if v.get("system_objective") == "violated" else None
    if broke is not None:
        title += "\n" + broke.text()
    if game.is_grid:
        fig, ax = plt.subplots(figsize=(7, 7.6))
        ax.imshow(renderer.frame(trace.states[-1]))
        cells = [game.ts.places[int(game.ts.place[r.system])] for r in trace.states]
        xs = np.array([(c[1] + 0.5) * tile for c in cells], dtype=float)
        ys = np.array([(c[0] + 0.5) * tile for c in cells], dtype=float)
        # keep consecutive duplicates (waits) out of the line, jitter revisits slightly
        ax.plot(xs, ys, "-", color="#1f3b99", lw=2.5, alpha=0.8, zorder=3)
        ax.plot(xs[0], ys[0], "o", ms=14, color="#2ca02c", zorder=4, label="start")
        ax.plot(xs[-1], ys[-1], "X", ms=16, color="#d62728" if trace.failed else "#1f3b99", zorder=4, label="end")
        seen: dict[tuple[float, float], int] = {}
        last = None
        for step, (x, y) in enumerate(zip(xs, ys, strict=True)):
            if last == (x, y):
                continue
            last = (x, y)
            n = seen.get((x, y), 0)
            seen[(x, y)] = n + 1
            if n < 3:
                ax.annotate(str(step), (x + (n - 1) * tile * 0.22, y - tile * 0.28), color="black", fontsize=9,
                            ha="center", va="center", zorder=5,
                            bbox={"boxstyle": "round,pad=0.12", "fc": "white", "ec": "none", "alpha": 0.8})
        ax.legend(handles=_trace_legend(ax, game), loc="upper center", bbox_to_anchor=(0.5, -0.01), ncol=4,
                  fontsize=8, frameon=False)
        ax.set_axis_off()
        ax.set_title(title, fontsize=10)
    else:
        # frames where the system moved (plus start and end), at most six, in two rows
        moves = [0] + [i for i in range(1, len(trace.states)) if trace.states[i].system != trace.states[i - 1].system]
        moves.append(len(trace.states) - 1)
        moves = sorted(set(moves))
        if len(moves) > 6:
            moves = [moves[int(round(j))] for j in np.linspace(0, len(moves) - 1, 6)]
        n_cols = min(3, len(moves))
        n_rows = (len(moves) + n_cols - 1) // n_cols
        fig, axes = plt.subplots(n_rows, n_cols, figsize=(4.6 * n_cols, 4.6 * n_rows + 0.8), squeeze=False)
        for ax in axes.ravel():
            ax.set_axis_off()
        for ax, i in zip(axes.ravel(), moves, strict=False):  # spare axes stay blank
            ax.imshow(renderer.frame(trace.states[i]))
            ax.set_title(f"step {i}: at {game.ts.states[trace.states[i].system]}", fontsize=12)
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
