"""Filmstrips of test runs: one frame per step that changed something, in reading order.

A failing run is easier to follow as frames than as one path: each frame is the
engineer's view of the run at that step (walls, the restrictions shown now as orange
bars, the test agent, the hidden test cells), titled with the step, the SUT's action and
what the test did (doors opened or closed, walls of the current fuel level shown or gone,
the test agent moved, the action refused).
Frames where nothing changed (waits) are left out; a long run keeps its first and last
frames and an even sample of the others. A run that violated the system objective keeps
the frame where it did, marked in red with the broken conjunct and the cell
(:func:`experiments.evaluation.violations.violation_of`), and the strip's title says it too.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

MAX_FRAMES = 24
"""Frames per filmstrip; longer runs are sampled evenly (first and last kept)."""


def _events(game: Any, states: Sequence[Any], actions: Sequence[int]) -> list[str]:
    """Per state after reset: what changed at that step, as short words."""
    static = game.artifact.strategy.static_obstacles
    out = [""]
    for k in range(1, len(states)):
        a, b = states[k - 1], states[k]
        words = [game.action_name(a.system, actions[k - 1])]
        if b.blocked_attempts > a.blocked_attempts:
            words.append("refused")
        before, after = set(game.shown_moves(a)), set(game.shown_moves(b))
        for moves, door, wall in ((after - before, "door closed", "wall shown"), (before - after, "door opened", "wall gone")):
            if any(not static[m] for m in moves):
                words.append(door)  # a reactive restriction
            if any(static[m] for m in moves):
                words.append(wall)  # a static obstacle of some states of a cell (walls per fuel level)
        if b.agent != a.agent:
            words.append("agent moved")
        out.append(", ".join(words))
    return out


def symbol_legend(game: Any) -> list[Any]:
    """Legend handles for the renderer's symbols in the engineer's view (what a frame
    shows), each proposition of the system objective named by its mark's colour, so a
    hazard reads as ``hazard``, not as unlabelled dots."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from flowtest_env import render
    from flowtest_env.encoding import system_propositions

    def rgb(c: tuple[int, int, int]) -> tuple[float, float, float]:
        return (c[0] / 255, c[1] / 255, c[2] / 255)

    strategy = game.artifact.strategy
    handles: list[Any] = [
        Line2D([], [], marker="o", color=rgb(render.SYSTEM), label="system under test", linestyle="", markersize=9),
        Patch(facecolor=rgb(render.GOAL), label="goal"),
        Line2D([], [], marker="o", markerfacecolor="none", markeredgewidth=2, color=rgb(render.TEST_CELL),
               label="hidden test cell", linestyle="", markersize=9),
    ]
    if game.ts.layout is not None and game.ts.layout.blocked:
        handles.append(Patch(facecolor=rgb(render.BLOCKED), label="blocked cell"))
    if strategy.static_obstacles.any():
        handles.append(Line2D([], [], color=rgb(render.WALL), lw=4, label="wall"))
    if (strategy.restrictions & ~strategy.static_obstacles[None, :]).any():
        handles.append(Line2D([], [], color=rgb(render.DOOR), lw=4, label="door closed now"))
    if game.has_agent:
        handles.append(Line2D([], [], marker="D", color=rgb(render.AGENT), label="test agent", linestyle="", markersize=9))
    if game.ts.kind == "fuel":
        handles.append(Line2D([], [], marker="P", color=rgb(render.REFUEL), label="refuel", linestyle="", markersize=9))
    for i, name in enumerate(system_propositions(game)):
        colour = rgb(render.PALETTE[i % len(render.PALETTE)])
        handles.append(Line2D([], [], marker="o", color=colour, label=name, linestyle="", markersize=6))
    return handles


def frames_to_show(game: Any, states: Sequence[Any], limit: int = MAX_FRAMES, keep_step: int | None = None) -> list[int]:
    """Indices of the states a filmstrip shows: the start, every step where the system,
    the test agent or the shown restrictions changed or an action was refused, the end;
    evenly sampled down to ``limit``, ``keep_step`` (the violation) always kept."""
    keep = [0]
    for k in range(1, len(states)):
        a, b = states[k - 1], states[k]
        if (b.system, b.agent, b.blocked_attempts) != (a.system, a.agent, a.blocked_attempts) or set(
            game.shown_moves(a)
        ) != set(game.shown_moves(b)):
            keep.append(k)
    if keep[-1] != len(states) - 1:
        keep.append(len(states) - 1)
    if len(keep) > limit:
        keep = [keep[int(round(j))] for j in np.linspace(0, len(keep) - 1, limit)]
    if keep_step is not None and 0 <= keep_step < len(states) and keep_step not in keep:
        keep[min(range(1, len(keep) - 1), key=lambda i: abs(keep[i] - keep_step), default=len(keep) - 1)] = keep_step
    return sorted(set(keep))


def filmstrip(game: Any, states: Sequence[Any], actions: Sequence[int], title: str, path: Path, tile: int = 40) -> None:
    """Draw the filmstrip of a run (``states`` after reset and every step) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flowtest_env.render import make_renderer

    from .violations import violation_of

    renderer = make_renderer(game, tile, "engineer")
    broke = violation_of(game.artifact, [r.system for r in states]) if states and states[-1].outcome == "violated" else None
    shown = frames_to_show(game, states, keep_step=None if broke is None else broke.step)
    events = _events(game, states, actions)
    frames = [renderer.frame(states[i]) for i in shown]
    h, w = frames[0].shape[:2]
    n_cols = min(len(frames), 8 if w <= 320 else 4)
    n_rows = (len(frames) + n_cols - 1) // n_cols
    fw = 1.9 if w <= 320 else 3.4
    width = max(fw * n_cols, 8.0)  # room for the title however few frames
    note = "(… : steps left out before this frame, where nothing changed or to keep the strip short)"
    lines = textwrap.wrap(title, int(width * 13))
    if broke is not None:
        lines += textwrap.wrap(broke.text().replace("broke", "The run broke the system objective's conjunct", 1),
                               int(width * 13))
    lines.append(note)
    top = 0.17 * len(lines) + 0.15  # inches of the strip's title
    frame_titles = 0.7 if broke is not None else 0.55  # the broken frame's title has a third line
    handles = symbol_legend(game) if game.is_grid else []
    bottom = 0.2 * -(-len(handles) // 6) + 0.1 if handles else 0.0  # inches of the legend, 6 symbols a row
    height = fw * h / w * n_rows + frame_titles * n_rows + top + bottom
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(width, height), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    prev = 0
    for ax, i, img in zip(axes.ravel(), shown, frames, strict=False):  # spare axes stay blank
        ax.imshow(img)
        label = "start" if i == 0 else events[i]
        quiet = i - prev - 1
        head = ("… " if quiet > 0 else "") + f"step {i}"
        if broke is not None and i == broke.step:
            ax.set_title(f"{head}: {label}\nBROKE {broke.conjunct}\nat {broke.where}", fontsize=8, color="#b00020",
                         fontweight="bold")
            for spine in ax.spines.values():
                spine.set_visible(True)
                spine.set_edgecolor("#b00020")
                spine.set_linewidth(3)
            ax.set_axis_on()
            ax.set_xticks([])
            ax.set_yticks([])
        else:
            ax.set_title(f"{head}\n{label}", fontsize=8)
        prev = i
    fig.suptitle("\n".join(lines), fontsize=9)
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=min(6, len(handles)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, bottom / height, 1, 1 - top / height))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def test_picture(game: Any, path: Path) -> None:
    """The test's restrictions per history, one panel each, its propositions in the legend
    (:func:`experiments.plots.plot_artifact`), to ``path`` (PNG): what the report's test
    card shows. The format follows ``path``'s suffix (``.png``, ``.svg``, ``.pdf``)."""
    from experiments.plots import plot_artifact

    # graphs one panel a row (a node-link panel is wide), grids two
    plot_artifact(game.artifact, path, dpi=90, header=False, max_cols=2 if game.is_grid else 1)


def start_picture(game: Any, path: Path, tile: int = 48) -> None:
    """The test at its start, engineer's view (hidden test cells shown), to ``path`` (PNG)."""
    import matplotlib.image

    from flowtest_env.render import make_renderer

    matplotlib.image.imsave(path, make_renderer(game, tile, "engineer").frame(game.reset()), format="png")
