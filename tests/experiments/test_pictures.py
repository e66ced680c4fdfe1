"""Pictures that tell the truth, in one visual language (issue 42 item 3): captions say what
changed on the floor (never a wall appearing or going on a static test; a door closed the
whole run stays drawn, pale out of the system's view); one colour per role and per
proposition name across every picture of a report; a loop shown once in a filmstrip and
legible on the path plot; the test cards name the step budget, name the histories neutrally
(what each means behind the reveal switch), fit a card at laptop width and keep their
labels inside the grid."""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib.image
import numpy as np
import pytest

from agents.registry import make_policy
from experiments.evaluation import evaluate, write_report
from experiments.evaluation.episodes import run_episode
from experiments.evaluation.explain import explain
from experiments.evaluation.filmstrip import _events, _frame_title, frames_to_show, panels_per_row, symbol_legend
from experiments.evaluation.filmstrip import test_picture as draw_test_picture
from experiments.evaluation.report import TestInfo, render_html
from experiments.evaluation.results import report_colours
from experiments.evaluation.trace_picture import step_labels
from flowtest_env import render
from tests.testing_reports import passing_record

HERE = Path(__file__).resolve().parent
FORGETFUL = f"python:{HERE / 'forgetful_planner.py'}:Forgetful"


def _game(env_id: str) -> Any:
    env: Any = gym.make("FlowTest-v0", test=env_id)
    return env.unwrapped.game


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


# --------------------------------------------------------------------------- captions


def test_no_report_of_a_static_test_speaks_of_walls_that_come_and_go(tmp_path: Path) -> None:
    """Walls never change: neither the report's text nor any frame's caption says a wall was
    shown or is gone, on a static test or a fuel grid whose walls hold at some fuel levels."""
    out = tmp_path / "report"
    cells = evaluate(["example1"], ["random", "scripted:greedy"], 6, seed=0)
    records = write_report(cells, out)
    assert sum(r["n_failures"] for r in records) >= 6
    for name in ("report.html", "report.md", "results.json"):
        text = (out / name).read_text()
        assert "wall gone" not in text and "wall shown" not in text, name
    for env_id in ("example1", "refueling"):
        env: Any = gym.make("FlowTest-v0", test=env_id)
        game = env.unwrapped.game
        policy = make_policy("random", env)
        for seed in range(4):
            t = run_episode(env, policy, env_id, "random", seed)
            events = _events(game, t.states, t.actions)
            assert not any("wall" in ev for ev in events), (env_id, seed, events)
            loop = explain(t).loop
            shown = frames_to_show(game, t.states, loop=loop)
            titles = [_frame_title(i, p, events, t.states, loop, None) for i, p in zip(shown, [0, *shown], strict=False)]
            assert not any("wall" in title for title in titles)


def test_a_door_closed_the_whole_loop_is_drawn_in_every_frame_and_never_opens() -> None:
    """The planner that forgets a door loops in front of it: from the step the door closed
    on, every caption leaves it closed and every frame draws it, orange where the system sees
    it and pale out of its view."""
    (cell,) = evaluate(["small-reactive"], [FORGETFUL], 1, seed=0)
    t = cell.traces[0]
    game = t.game
    events = _events(game, t.states, t.actions)
    closed_at = next(k for k, ev in enumerate(events) if "doors closed" in ev or "door (1, 2) -> (0, 2) closed" in ev)
    assert not any("opened" in ev for ev in events[closed_at + 1 :])
    renderer = render.make_renderer(game, 32, "engineer")
    size = 32
    door = next(
        int(m)
        for m in np.flatnonzero(game.enforced[t.states[-1].history])
        if game.cells[game.place_list[int(game.ts.src[m])]] == (1, 2) and game.ts.action[m] == "N"
    )
    assert game.cells[game.place_list[int(game.ts.dst[door])]] == (0, 2)
    seen = set()
    for run in t.states[closed_at:]:
        frame = renderer.frame(run)
        pixel = tuple(int(x) for x in frame[1 * size + 1, 2 * size + size // 2])  # the N edge of (1, 2)
        assert pixel in (render.DOOR, render.DOOR_OUT_OF_VIEW), (run.steps, pixel)
        seen.add(pixel)
    assert seen == {render.DOOR, render.DOOR_OUT_OF_VIEW}  # in view at (1, 2), out of view at (1, 1)
    assert "door closed, out of view" in [h.get_label() for h in symbol_legend(game)]


# --------------------------------------------------------------------------- one visual language


def test_each_role_has_one_colour_in_every_picture() -> None:
    """Start teal, goal green, the system red, the test agent blue, walls black, doors orange,
    hidden test cells purple: distinct, the same in the frames and the test pictures, and no
    proposition's colour near any of them."""
    from experiments import plots

    roles = list(render.ROLE_COLOURS.values())
    assert len(set(roles)) == len(roles)
    for colour in render.PALETTE:
        assert min(float(np.linalg.norm(np.subtract(colour, role))) for role in roles) > 60, colour
    assert plots.GOAL == render.hex_colour(render.tint(render.GOAL, 0.45))
    assert plots.START == render.hex_colour(render.tint(render.START, 0.6))
    assert plots.RESTRICTED == render.hex_colour(render.DOOR) and plots.AGENT_BLOCK == render.hex_colour(render.AGENT)
    assert plots.PROP_COLOURS == tuple(render.hex_colour(c) for c in render.PALETTE)


def _hex_rgb(colour: str) -> tuple[int, int, int]:
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


def _has_colour(png: Path, colour: tuple[int, int, int]) -> bool:
    pixels = np.rint(matplotlib.image.imread(png)[..., :3] * 255).astype(int)
    return bool((np.abs(pixels - np.array(colour)).max(axis=-1) <= 1).any())


def test_a_proposition_keeps_its_colour_across_the_tests_of_a_report(tmp_path: Path) -> None:
    """``goal`` is the second of example1's propositions and the third of small-reactive's:
    one report gives it one colour on both cards, in both pictures and in the frames' legends."""
    out = tmp_path / "report"
    cells = evaluate(["example1", "small-reactive"], ["scripted:replanner"], 1, seed=0)
    write_report(cells, out)
    page = (out / "report.html").read_text()
    swatches = re.findall(r"background:(#[0-9a-f]{6})'></span>goal</td>", page)
    assert len(swatches) == 2 and swatches[0] == swatches[1]
    colour = _hex_rgb(swatches[0])
    pictures = re.findall(r"<img src='(tests/[^']+\.png)'", page)
    assert len(pictures) == 2 and all(_has_colour(out / p, colour) for p in pictures)
    shared = report_colours(cells)
    assert shared["goal"] == colour
    for env_id in ("example1", "small-reactive"):
        assert render.make_renderer(_game(env_id), 16, "engineer", shared).colours["goal"] == colour


# --------------------------------------------------------------------------- loops


def test_a_filmstrip_shows_a_loop_once_and_says_how_long_it_lasted() -> None:
    (cell,) = evaluate(["small-reactive"], [FORGETFUL], 1, seed=0)
    t = cell.traces[0]
    loop = explain(t).loop
    assert loop is not None and loop.period == 2
    shown = frames_to_show(t.game, t.states, loop=loop)
    assert shown == [*range(0, loop.start + loop.period), len(t.states) - 1]
    everything = frames_to_show(t.game, t.states)
    assert len(everything) > 2 * len(shown)  # without the loop: the sampled back-and-forth
    events = _events(t.game, t.states, t.actions)
    last = _frame_title(shown[-1], shown[-2], events, t.states, loop, None)
    assert last.startswith(f"… step {len(t.states) - 1}: the end") and f"steps {loop.start}-{len(t.states) - 1}" in last
    assert "the loop begins" in _frame_title(loop.start, loop.start - 1, events, t.states, loop, None)


def test_the_path_plot_labels_each_cell_once() -> None:
    cells = [(1, 0), (0, 0), (0, 1), (1, 1)] + [(0, 1), (1, 1)] * 20
    labels = step_labels(cells)
    assert set(labels) == {(1, 0), (0, 0), (0, 1), (1, 1)}
    assert labels[(1, 0)] == "0" and labels[(0, 0)] == "1"
    assert labels[(0, 1)] == "2, 4 … 42\n21 visits" and labels[(1, 1)] == "3, 5 … 43\n21 visits"
    assert step_labels([(0, 0), (0, 0), (0, 1), (0, 1), (0, 0)]) == {(0, 0): "0, 4", (0, 1): "2"}  # waits: no new visit


# --------------------------------------------------------------------------- test cards


def test_a_card_names_the_step_budget_and_its_histories_neutrally(tmp_path: Path) -> None:
    """The panels are titled ``history q1``, never what q1 has seen (that gives the hidden
    test objective away): the meanings are behind the reveal switch, with the objective."""
    from experiments.evaluation.report import test_infos
    from experiments.plots import plot_artifact

    (info,) = test_infos(["small-reactive"], tmp_path)
    assert info.histories and all(re.fullmatch(r"q\d+", name) for name, _ in info.histories)
    assert any(meaning.startswith("saw ") for _, meaning in info.histories)
    game = _game("small-reactive")
    neutral, revealed = tmp_path / "neutral.png", tmp_path / "revealed.png"
    plot_artifact(game.artifact, neutral, dpi=90, header=False, max_cols=panels_per_row(game), reveal=False)
    plot_artifact(game.artifact, revealed, dpi=90, header=False, max_cols=panels_per_row(game), reveal=True)
    card_png = (tmp_path / info.picture).read_bytes()
    assert card_png == neutral.read_bytes() and card_png != revealed.read_bytes()
    page = render_html([passing_record("small-reactive")], [info])
    card = page[page.index("<div class='test'") : page.index("</details></div>")]
    before, hidden = card.split("<details>")
    assert "a step budget of 50 steps a run" in before and "steps per run" not in page
    assert "saw " not in before and "F I1 &amp; F I2" not in before
    for name, meaning in info.histories:
        assert f"<tr><td>{name}</td><td>{meaning}</td></tr>" in hidden
    assert f"<a href='{info.picture}' title='open the picture at full size'><img src='{info.picture}'" in before


WARD = """
name = "ward-porter"
[system]
grid = \"\"\"
.  .  t  .  T
.  #  t  #  .
t  t  t0 t  t
.  #  t  #  I1
S  .  t  .  .
\"\"\"
start = "S"
terminal = ["T"]
[labels]
goal = ["T"]
I1 = ["I1"]
[objectives]
system = "F goal"
test = "F I1"
[environment]
kind = "agent"
[environment.agent]
cells = ["t", "t0"]
start = "t0"
parks = [
    {name = "stairwell-north", from = [[0, 2]]},
    {name = "elevator-lobby", from = [[4, 2]]},
    {name = "nurse-station-west", from = [[2, 0]]},
    {name = "supply-room", from = [[2, 4]]},
]
first = "agent"
"""

HOSPITAL = """
name = "hospital-ward"
[system]
grid = \"\"\"
S  .  .  .  .  .  .  .  .  .
.  #  .  #  #  .  #  #  #  .
.  #  N  .  .  .  .  .  #  .
.  #  .  #  #  .  #  .  #  .
.  .  .  .  .  .  #  .  .  .
.  #  #  .  #  .  #  #  #  .
.  .  .  .  X  X  .  .  .  .
.  #  .  .  X  X  .  #  .  .
.  .  L  .  .  .  .  .  .  P
\"\"\"
start = "S"
terminal = ["P"]
[labels]
pharmacy = ["P"]
sterile = ["X"]
nurse = ["N"]
lobby = ["L"]
[objectives]
system = "F pharmacy & G !sterile"
test = "F nurse & F lobby"
[environment]
kind = "reactive"
"""


@pytest.fixture(scope="module")
def floors(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("floors")
    games = {}
    for name, text in (("ward", WARD), ("hospital", HOSPITAL)):
        (root / f"{name}.toml").write_text(text)
        games[name] = _game(str(root / f"{name}.toml"))
    return games


CARD_WIDTH = 600
"""The pixels a test card's picture has at 1366x768 (two cards a row in a 1280 px page)."""


def test_multi_history_pictures_fit_a_card_at_laptop_width(tmp_path: Path, floors: dict[str, Any]) -> None:
    """A test card's picture is never wider than its card at 1366 px, so it is not shrunk:
    a 3x2 floor puts two panels a row, a 10x9 floor one, with cells of 40 px or more."""
    for game, cols, per_row in ((_game("small-reactive"), 3, 2), (floors["hospital"], 10, 1)):
        assert panels_per_row(game) == per_row
        path = tmp_path / "card.png"
        draw_test_picture(game, path)
        width, _ = png_size(path)
        assert width <= CARD_WIDTH and width / per_row / (cols + 1) >= 40, (width, cols)


def test_park_labels_stay_inside_their_boxes_and_the_picture(floors: dict[str, Any]) -> None:
    """Parks with long names get a tag in their box (``P1``) that the legend spells out; every
    label of a panel lies inside its cell, so none runs off the grid."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from experiments.plot_agent import _agent_overlay
    from experiments.plots import _grid_figure, artifact_view, panels_of

    view = artifact_view(floors["ward"].artifact)
    fig = _grid_figure(view, panels_of(view, reveal=False), _agent_overlay(view, None), 2, False)
    canvas = FigureCanvasAgg(fig)
    canvas.draw()  # type: ignore[no-untyped-call]
    renderer = canvas.get_renderer()  # type: ignore[no-untyped-call]
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "P3 = park nurse-station-west" in legend and "P2 = park elevator-lobby" in legend
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        texts = [t for t in ax.texts if t.get_text()]
        assert {"P1", "P2", "P3", "P4"} <= {t.get_text() for t in texts}
        for t in texts:
            box = t.get_window_extent(renderer)
            x, y = t.get_position()
            cell = ax.transData.transform([(np.floor(x), np.floor(y)), (np.floor(x) + 1, np.floor(y) + 1)])
            lo, hi = cell.min(axis=0), cell.max(axis=0)
            assert lo[0] - 1 <= box.x0 and box.x1 <= hi[0] + 1 and lo[1] - 1 <= box.y0 and box.y1 <= hi[1] + 1, t.get_text()


def test_the_cards_take_the_colours_the_report_gives_them(tmp_path: Path) -> None:
    """A report's test cards take the colours the report gives them, names of other tests included."""
    from experiments.evaluation.report import test_infos

    colours = render.proposition_colours(["I", "I1", "I2", "goal", "zone"])
    (info,) = test_infos(["small-reactive"], tmp_path, colours)
    assert {name: colour for name, _, colour in info.propositions} == {name: render.hex_colour(colours[name]) for name in ("I1", "I2", "goal")}
    assert isinstance(info, TestInfo)
