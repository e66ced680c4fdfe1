"""Pictures of one run (the evaluation report's ``traces/*.png``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .episodes import Trace, game_of_trace
from .filmstrip import symbol_legend, wrap
from .report import test_title
from .violations import violation_of


def _trace_legend(ax: Any, game: Any, colours: Mapping[str, tuple[int, int, int]] | None) -> list[Any]:
    """Legend entries for the path markers and the renderer's symbols (each proposition
    of the system objective named), so a newcomer can read a trace picture without the
    env docs."""
    return list(ax.get_legend_handles_labels()[0]) + symbol_legend(game, colours)


def step_labels(cells: Sequence[tuple[int, int]], limit: int = 3) -> dict[tuple[int, int], str]:
    """One label per cell of a path (the cells at reset and after every step): the steps at
    which the path entered it, a long list shortened to its first two and last steps and
    the count (``2, 4 … 48`` over ``24 visits``), so a loop's steps are not printed on top
    of each other. Waits (staying in a cell) are no new visit."""
    entered: dict[tuple[int, int], list[int]] = {}
    last = None
    for step, cell in enumerate(cells):
        if cell != last:
            entered.setdefault(cell, []).append(step)
        last = cell
    out = {}
    for cell, steps in entered.items():
        if len(steps) <= limit:
            out[cell] = ", ".join(map(str, steps))
        else:
            out[cell] = f"{steps[0]}, {steps[1]} … {steps[-1]}\n{len(steps)} visits"
    return out


def trace_picture(trace: Trace, path: Path, colours: Mapping[str, tuple[int, int, int]] | None = None, explanation: str = "") -> None:
    """Draw a run: on grids the engineer's view (walls, hidden test cells) at the end of
    the run with the SUT's path, each cell labelled once with the steps it was entered at
    (:func:`step_labels`); on graphs a strip of frames. The title names the test by its
    problem (never a path), says what a failing run did (``explanation``, one line) and, for
    a violation, the broken conjunct of the system objective, the step and the cell. The
    propositions take ``colours`` (by name)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from experiments.plot_agent import fit_font
    from flowtest_env import render
    from flowtest_env.render import make_renderer

    game = game_of_trace(trace)
    tile = 48
    renderer = make_renderer(game, tile, "engineer", colours)
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
    elif explanation:
        title += "\n" + "\n".join(wrap(explanation, 95))
    sut = render.hex_colour(render.SYSTEM)
    if game.is_grid:
        rows, cols = game.ts.layout.rows, game.ts.layout.cols
        side = min(6.4 / max(rows, cols), 1.6)  # inches a cell
        gw, gh = cols * side, rows * side
        handles_n = 2 + len(symbol_legend(game, colours))
        legend = 0.2 * -(-handles_n // 3) + 0.15
        head = 0.17 * (title.count("\n") + 1) + 0.2
        fw, fh = max(gw, 6.0) + 0.4, gh + legend + head + 0.2
        fig = plt.figure(figsize=(fw, fh))
        ax = fig.add_axes(((fw - gw) / 2 / fw, (legend + 0.1) / fh, gw / fw, gh / fh))
        ax.imshow(renderer.frame(trace.states[-1]))
        cells = [game.cells[game.place_list[r.system]] for r in trace.states]
        xs = np.array([(c[1] + 0.5) * tile for c in cells], dtype=float)
        ys = np.array([(c[0] + 0.5) * tile for c in cells], dtype=float)
        ax.plot(xs, ys, "-", color=sut, lw=2.5, alpha=0.6, zorder=3)
        ax.plot(xs[0], ys[0], "o", ms=14, color=render.hex_colour(render.START), zorder=4, label="start")
        ax.plot(xs[-1], ys[-1], "X", ms=16, color=sut, markeredgecolor="white", zorder=4, label="end")
        cell_pt = side * 72
        for (r, c), text in step_labels(cells).items():
            size = fit_font(text, cell_pt, 8, 4.0) or 4.0  # inside its cell, however large the floor
            ax.annotate(
                text,
                ((c + 0.5) * tile, (r + 0.05) * tile),
                color="black",
                fontsize=size,
                ha="center",
                va="top",
                zorder=5,
                linespacing=1.0,
                bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.85},
            )
        fig.legend(handles=_trace_legend(ax, game, colours), loc="lower center", ncol=3, fontsize=8, frameon=False)
        ax.set_axis_off()
        fig.suptitle(title, fontsize=9, y=1 - 0.1 / fh, va="top")
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
