"""Filmstrips of test runs: one frame per step that changed something, in reading order.

A failing run is easier to follow as frames than as one path: each frame is the
engineer's view of the run at that step (walls; the doors closed now, orange where the
system sees them and pale out of its view; the test agent; the hidden test cells), titled
with the step, the SUT's action and what changed on the floor (a door closed or opened,
the test agent moved, the action refused). Walls never change: no caption speaks of them.
Frames where nothing changed (waits) are left out; a run that ended in a loop
(:func:`experiments.evaluation.explain.find_loop`) shows one round of it and says how long
it lasted; a long run keeps its first and last frames and an even sample of the others. A
run that violated the system objective keeps the frame where it did, marked in red with
the broken conjunct and the cell (:func:`experiments.evaluation.violations.violation_of`),
and the strip's title says it too.
"""

from __future__ import annotations

import re
import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

MAX_FRAMES = 24
"""Frames per filmstrip; longer runs are sampled evenly (first and last kept)."""


def floor_doors(game: Any, run: Any) -> frozenset[int]:
    """The doors closed on the floor now, wherever the system stands: the reactive
    restrictions the test enforces under the run's history (none under another tester,
    whose restrictions hold for one step, nor on an agent test, whose agent is drawn)."""
    if run.override is not None:
        return frozenset()
    static = game.artifact.strategy.static_obstacles
    return frozenset(int(m) for m in np.flatnonzero(game.enforced[run.history] & ~static))


def _door_words(game: Any, moves: set[int], what: str) -> str:
    """``door (0, 1) -> (0, 2) closed``, or ``3 doors closed``."""
    from .explain import place_name

    if len(moves) > 1:
        return f"{len(moves)} doors {what}"
    (m,) = moves
    ts = game.ts
    return f"door {place_name(game, int(ts.src[m]))} -> {place_name(game, int(ts.dst[m]))} {what}"


def agent_place_name(game: Any, agent: int) -> str:
    """Where the test agent is: its cell (grids), its state's name (graphs), or its park."""
    from .explain import place_name

    place = game.agent_place[agent] if 0 <= agent < len(game.agent_place) else -1
    if place < 0:
        return "its park"
    return place_name(game, int(np.flatnonzero(game.ts.place == place)[0]))


def _events(game: Any, states: Sequence[Any], actions: Sequence[int]) -> list[str]:
    """Per state after reset: the action that led there and what changed on the floor at
    that step (doors closed or opened, the test agent's move), as short words."""
    out = [""]
    for k in range(1, len(states)):
        a, b = states[k - 1], states[k]
        words = [game.action_name(a.system, actions[k - 1])]
        if b.blocked_attempts > a.blocked_attempts:
            words.append("refused")
        before, after = floor_doors(game, a), floor_doors(game, b)
        if after - before:
            words.append(_door_words(game, set(after - before), "closed"))
        if before - after:
            words.append(_door_words(game, set(before - after), "opened"))
        if b.agent != a.agent:
            words.append(f"test agent to {agent_place_name(game, b.agent)}")
        out.append(", ".join(words))
    return out


def symbol_legend(game: Any, colours: Mapping[str, tuple[int, int, int]] | None = None) -> list[Any]:
    """Legend handles for the renderer's symbols in the engineer's view (what a frame
    shows), each proposition of the system objective that marks cells named by its mark's
    colour (``colours``, by name, as the frames were drawn), so a hazard reads as
    ``hazard``, not as unlabelled dots."""
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
        Line2D(
            [], [], marker="o", markerfacecolor="none", markeredgewidth=2, color=rgb(render.TEST_CELL), label="hidden test cell", linestyle="", markersize=9
        ),
    ]
    if game.ts.layout is not None and game.ts.layout.blocked:
        handles.append(Patch(facecolor=rgb(render.BLOCKED), label="blocked cell"))
    if strategy.static_obstacles.any():
        handles.append(Line2D([], [], color=rgb(render.WALL), lw=4, label="wall"))
    if (game.enforced & ~strategy.static_obstacles[None, :]).any():
        handles.append(Line2D([], [], color=rgb(render.DOOR), lw=4, label="door closed, in the system's view"))
        handles.append(Line2D([], [], color=rgb(render.DOOR_OUT_OF_VIEW), lw=4, label="door closed, out of view"))
    if game.has_agent:
        handles.append(Line2D([], [], marker="D", color=rgb(render.AGENT), label="test agent", linestyle="", markersize=9))
    if game.ts.kind == "fuel":
        handles.append(Line2D([], [], marker="P", color=rgb(render.REFUEL), label="refuel", linestyle="", markersize=9))
    shown = {**render.proposition_colours(render.all_propositions(game)), **(colours or {})}
    for name in system_propositions(game):
        if render.marked_places(game, name):  # a proposition of the goal cells only is the goal, drawn as such
            handles.append(Line2D([], [], marker="o", color=rgb(shown[name]), label=name, linestyle="", markersize=6))
    return handles


def frames_to_show(game: Any, states: Sequence[Any], limit: int = MAX_FRAMES, keep_step: int | None = None, loop: Any = None) -> list[int]:
    """Indices of the states a filmstrip shows: the start, every step where the system or
    the test agent moved, a door on the floor closed or opened or an action was refused,
    the end; a run that ended in ``loop`` (:class:`~experiments.evaluation.explain.Loop`)
    shows one round of it and its end; evenly sampled down to ``limit``, ``keep_step`` (the
    violation) always kept."""
    last = len(states) - 1
    upto = last if loop is None else min(last, loop.start + loop.period - 1)
    keep = [0]
    for k in range(1, upto + 1):
        a, b = states[k - 1], states[k]
        if (b.system, b.agent, b.blocked_attempts) != (a.system, a.agent, a.blocked_attempts) or (floor_doors(game, a) != floor_doors(game, b)):
            keep.append(k)
    if loop is not None:
        keep += [k for k in range(loop.start, upto + 1) if k not in keep]
        keep.sort()
    if keep[-1] != last:
        keep.append(last)
    if len(keep) > limit:
        fixed = set(range(loop.start, upto + 1)) if loop is not None else set()
        free = [k for k in keep if k not in fixed]
        room = max(2, limit - len(fixed))
        keep = sorted(fixed | {free[int(round(j))] for j in np.linspace(0, len(free) - 1, room)})
    if keep_step is not None and 0 <= keep_step < len(states) and keep_step not in keep:
        keep[min(range(1, len(keep) - 1), key=lambda i: abs(keep[i] - keep_step), default=len(keep) - 1)] = keep_step
    return sorted(set(keep))


def filmstrip(
    game: Any,
    states: Sequence[Any],
    actions: Sequence[int],
    title: str,
    path: Path,
    tile: int = 40,
    colours: Mapping[str, tuple[int, int, int]] | None = None,
    loop: Any = None,
    explanation: str = "",
) -> None:
    """Draw the filmstrip of a run (``states`` after reset and every step) to ``path``:
    ``title`` and ``explanation`` (what the run did, in one line) above the frames, a
    ``loop`` the run ended in shown once (:func:`frames_to_show`), the propositions in
    ``colours`` (by name)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flowtest_env.render import make_renderer

    from .violations import violation_of

    renderer = make_renderer(game, tile, "engineer", colours)
    broke = violation_of(game.artifact, [r.system for r in states]) if states and states[-1].outcome == "violated" else None
    shown = frames_to_show(game, states, keep_step=None if broke is None else broke.step, loop=loop)
    events = _events(game, states, actions)
    frames = [renderer.frame(states[i]) for i in shown]
    h, w = frames[0].shape[:2]
    n_cols = min(len(frames), 8 if w <= 320 else 4)
    n_rows = (len(frames) + n_cols - 1) // n_cols
    width = max((1.9 if w <= 320 else 3.4) * n_cols, 9.0)  # room for the title however few frames
    fw = min(width / n_cols, 3.4)  # a frame's width: few frames are drawn larger
    width = max(width, fw * n_cols)
    chars = int(width * 13)
    lines = wrap(title, chars)
    if explanation:
        lines += wrap(explanation[:1].upper() + explanation[1:] + ".", chars)
    if broke is not None:
        lines += wrap(broke.text().replace("broke", "The run broke the system objective's conjunct", 1), chars)
    lines.append("(… : steps left out before this frame, where nothing changed or to keep the strip short)")
    titles = [_frame_title(i, prev, events, states, loop, broke) for i, prev in zip(shown, [0, *shown], strict=False)]
    wrapped = ["\n".join(line for part in t.split("\n") for line in wrap(part, int(fw * 12))) for t in titles]
    title_lines = max(t.count("\n") + 1 for t in wrapped)
    top = 0.17 * len(lines) + 0.15  # inches of the strip's title
    frame_titles = 0.15 * title_lines + 0.12
    handles = symbol_legend(game, colours) if game.is_grid else []
    bottom = 0.2 * -(-len(handles) // 5) + 0.1 if handles else 0.0  # inches of the legend, 5 symbols a row
    height = fw * h / w * n_rows + frame_titles * n_rows + top + bottom
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(width, height), squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, i, img, text in zip(axes.ravel(), shown, frames, wrapped, strict=False):  # spare axes stay blank
        ax.imshow(img)
        if broke is not None and i == broke.step:
            ax.set_title(text, fontsize=8, color="#b00020", fontweight="bold")
            _frame_border(ax, "#b00020")
        elif loop is not None and loop.start <= i < loop.start + loop.period:
            ax.set_title(text, fontsize=8)
            _frame_border(ax, "#1a4d8f")
        else:
            ax.set_title(text, fontsize=8)
    fig.suptitle("\n".join(lines), fontsize=9)
    if handles:
        fig.legend(handles=handles, loc="lower center", ncol=min(5, len(handles)), fontsize=8, frameon=False)
    frame_h = fw * h / w
    fig.subplots_adjust(
        left=0.01,
        right=0.99,
        bottom=(bottom + 0.05) / height,
        top=1 - (top + frame_titles) / height,
        wspace=0.06 * n_cols / max(n_cols - 1, 1),
        hspace=frame_titles / frame_h,
    )
    fig.savefig(path, dpi=100)
    plt.close(fig)


def wrap(text: str, width: int) -> list[str]:
    """``text`` in lines of at most ``width`` characters, never breaking a cell ``(2, 3)``
    or a move's arrow apart."""
    kept = re.sub(r"\((\d+), (\d+)\)", "(\\1,\u00a0\\2)", text).replace(" -> ", "\u00a0->\u00a0")
    return textwrap.wrap(kept, width) or [""]


def _frame_title(i: int, prev: int, events: Sequence[str], states: Sequence[Any], loop: Any, broke: Any) -> str:
    """A frame's title: its step (``… `` when steps before it were left out), the action and
    what changed on the floor; the loop's round and end, the broken conjunct."""
    head = ("… " if i - prev > 1 else "") + f"step {i}"
    label = "start" if i == 0 else events[i]
    if broke is not None and i == broke.step:
        return f"{head}: {label}\nBROKE {broke.conjunct}\nat {broke.where}"
    if loop is not None and i == loop.start:
        return f"{head}: {label}\n" + ("it stays here from now on" if loop.period == 1 else f"the loop begins (a round of {loop.period} steps)")
    if loop is not None and i == len(states) - 1 and i >= loop.start + loop.period:
        if loop.period == 1:
            return f"{head}: the end\nstayed here {i - loop.start} steps, steps {loop.start}-{i}"
        return f"{head}: the end\nthe round went {(i - loop.start) // loop.period} times, steps {loop.start}-{i}"
    return f"{head}\n{label}"


def _frame_border(ax: Any, colour: str) -> None:
    for spine in ax.spines.values():
        spine.set_visible(True)
        spine.set_edgecolor(colour)
        spine.set_linewidth(3)
    ax.set_axis_on()
    ax.set_xticks([])
    ax.set_yticks([])


def test_picture(game: Any, path: Path, colours: Mapping[str, str] | None = None) -> None:
    """The test's restrictions per history, one panel each, its propositions in the legend
    (:func:`experiments.plots.plot_artifact`; ``colours`` by name, ``#rrggbb``), to ``path``
    (PNG): what the report's test card shows, its histories named neutrally (``q2``: what a
    history means gives the hidden test objective away). The format follows ``path``'s
    suffix (``.png``, ``.svg``, ``.pdf``)."""
    from experiments.plots import plot_artifact

    plot_artifact(game.artifact, path, dpi=90, header=False, max_cols=panels_per_row(game), reveal=False, colours=dict(colours) if colours else None)


def panels_per_row(game: Any) -> int:
    """How many history panels a test card's picture puts side by side: graphs one (a
    node-link panel is wide), grids up to 8 columns two, larger floors one, so each panel
    keeps cells and labels legible in a card at laptop width."""
    if not game.is_grid:
        return 1
    return 2 if game.ts.layout.cols <= 8 else 1


def start_picture(game: Any, path: Path, tile: int = 48) -> None:
    """The test at its start, engineer's view (hidden test cells shown), to ``path`` (PNG)."""
    import matplotlib.image

    from flowtest_env.render import make_renderer

    matplotlib.image.imsave(path, make_renderer(game, tile, "engineer").frame(game.reset()), format="png")
