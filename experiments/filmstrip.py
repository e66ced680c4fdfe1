"""Filmstrips of test runs: one frame per step that changed something, in reading order.

A failing run is easier to follow as frames than as one path: each frame is the
engineer's view of the run at that step (walls, the restrictions shown now as orange
bars, the test agent, the hidden test cells), titled with the step, the SUT's action and
what the test did (doors opened or closed, walls of the current fuel level shown or gone,
the test agent moved, the action refused).
Frames where nothing changed (waits) are left out; a long run keeps its first and last
frames and an even sample of the others.
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


def frames_to_show(game: Any, states: Sequence[Any], limit: int = MAX_FRAMES) -> list[int]:
    """Indices of the states a filmstrip shows: the start, every step where the system,
    the test agent or the shown restrictions changed or an action was refused, the end;
    evenly sampled down to ``limit``."""
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
    return sorted(set(keep))


def filmstrip(game: Any, states: Sequence[Any], actions: Sequence[int], title: str, path: Path, tile: int = 40) -> None:
    """Draw the filmstrip of a run (``states`` after reset and every step) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flowtest_env.render import make_renderer

    renderer = make_renderer(game, tile, "engineer")
    shown = frames_to_show(game, states)
    events = _events(game, states, actions)
    frames = [renderer.frame(states[i]) for i in shown]
    h, w = frames[0].shape[:2]
    n_cols = min(len(frames), 8 if w <= 320 else 4)
    n_rows = (len(frames) + n_cols - 1) // n_cols
    fw = 1.9 if w <= 320 else 3.4
    width = max(fw * n_cols, 8.0)  # room for the title however few frames
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(width, fw * h / w * n_rows + 0.55 * n_rows + 0.8), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    prev = 0
    for ax, i, img in zip(axes.ravel(), shown, frames, strict=False):  # spare axes stay blank
        ax.imshow(img)
        label = "start" if i == 0 else events[i]
        quiet = i - prev - 1
        head = ("… " if quiet > 0 else "") + f"step {i}"
        ax.set_title(f"{head}\n{label}", fontsize=8)
        prev = i
    note = "(… : steps left out before this frame, where nothing changed or to keep the strip short)"
    fig.suptitle("\n".join(textwrap.wrap(title, int(width * 13)) + [note]), fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def start_picture(game: Any, path: Path, tile: int = 48) -> None:
    """The test at its start, engineer's view (hidden test cells shown), to ``path`` (PNG)."""
    import matplotlib.image

    from flowtest_env.render import make_renderer

    matplotlib.image.imsave(path, make_renderer(game, tile, "engineer").frame(game.reset()), format="png")
