"""Pictures of synthesized tests (:mod:`experiments.plots`): smoke tests and layout rules.

The pictures themselves are judged by eye; these tests make sure every kind of problem
(grid, fuel grid, graph; static, reactive, mixed; with a test-agent overlay) renders
without error to a real, non-trivial image, and pin the rules a reader relies on
(one panel per restricting history, a deterministic left-to-right graph layout).
"""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from experiments.plots import _fuel_note, check_plot_format, layered_positions, panels_of, plot_test
from synthesis.model.errors import InconsistentProblem, ProblemError
from synthesis.model.strategy import TestStrategy
from synthesis.pipeline import SynthesisOptions, SynthesizedTest, synthesize
from synthesis.problems.load import load_problem

DATA = Path(__file__).resolve().parents[1] / "data"

_CACHE: dict[str, SynthesizedTest] = {}


def synthesized(name: str) -> SynthesizedTest:
    """Synthesize once per test session.

    refueling takes many seconds to solve to optimality (its optimal picture is drawn
    by ``test_cli``); a picture only needs *a* checked test, so here it gets a short
    time limit, and the full solve if that finds nothing. (A time-limited solve that
    stops at flow 0 currently raises InconsistentProblem instead of TimeoutError.)
    """
    if name not in _CACHE:
        problem = load_problem(name)
        if name == "refueling":
            try:
                _CACHE[name] = synthesize(problem, SynthesisOptions(time_limit=2.0))
            except (TimeoutError, InconsistentProblem):
                _CACHE[name] = synthesize(problem)
        else:
            _CACHE[name] = synthesize(problem)
    return _CACHE[name]


def png_size(path: Path) -> tuple[int, int]:
    """Width and height from a PNG's IHDR chunk (and a check that it is a PNG)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.mark.parametrize(
    "name",
    [
        "example1",
        "small-reactive",
        "beaver-rescue",
        "motion-primitives",
        "refueling",
        str(DATA / "ok_grid.toml"),
        str(DATA / "ok_mixed.toml"),
        str(DATA / "ok_graph.toml"),
    ],
)
def test_plot_builtin_and_files(name: str, tmp_path: Path) -> None:
    path = tmp_path / "test.png"
    assert plot_test(synthesized(name), path) == path
    width, height = png_size(path)
    assert width >= 400 and height >= 250
    assert path.stat().st_size > 10_000  # a drawn picture, not an empty canvas


@pytest.mark.parametrize("suffix", [".svg", ".pdf"])
def test_vector_formats(suffix: str, tmp_path: Path) -> None:
    path = tmp_path / f"test{suffix}"
    plot_test(synthesized("small-reactive"), path)
    head = path.read_bytes()[:5]
    assert head == (b"%PDF-" if suffix == ".pdf" else b"<?xml")


def test_unsupported_format(tmp_path: Path) -> None:
    with pytest.raises(ProblemError, match=r"\.png"):
        check_plot_format(tmp_path / "test.gif")
    with pytest.raises(ProblemError):
        plot_test(synthesized("small-reactive"), tmp_path / "test")
    assert not (tmp_path / "test").exists()


def test_one_panel_per_restricting_history() -> None:
    test = synthesized("small-reactive")
    panels = panels_of(test)
    reactive = test.strategy.restrictions & ~test.strategy.static_obstacles[None, :]
    restricting = [q for q in range(test.strategy.n_hist) if reactive[q].any()]
    assert len(panels) == len(restricting) >= 1
    for panel, q in zip(panels, restricting, strict=True):
        assert test.spec.history_name(q) in panel.title and test.spec.describe(q) in panel.title
        assert np.array_equal(panel.restricted, reactive[q])


def test_static_problem_has_one_static_panel() -> None:
    panels = panels_of(synthesized("example1"))
    assert len(panels) == 1 and "static" in panels[0].title
    assert not panels[0].restricted.any()  # static walls are drawn as walls, not as one-way markers


def test_graph_layout_is_layered_and_deterministic() -> None:
    ts = load_problem("beaver-rescue").system
    pos = layered_positions(ts)
    assert pos == layered_positions(ts)
    x = {ts.places[p]: xy[0] for p, xy in pos.items()}
    assert x["init"] == 0.0
    assert x["goal"] == max(x.values())
    assert x["d1"] == x["d2"] < x["beaver"] < x["p1"] == x["p2"] < x["goal"]
    assert len(set(pos.values())) == len(pos)  # no two states on top of each other


def test_fuel_restriction_notes_fuel_levels() -> None:
    ts = load_problem("refueling").system
    moves = np.flatnonzero(ts.place[ts.src] != ts.place[ts.dst])
    m = int(moves[0])
    a, b = int(ts.place[ts.src[m]]), int(ts.place[ts.dst[m]])
    mask = np.zeros(ts.n_moves, dtype=bool)
    mask[m] = True
    same = np.flatnonzero((ts.place[ts.src] == a) & (ts.place[ts.dst] == b))
    if same.size > 1:
        state: Any = ts.states[int(ts.src[m])]  # (cell, fuel) on a fuel grid
        assert _fuel_note(ts, mask, a, b) == f"fuel {state[1]}"
    mask[same] = True
    assert _fuel_note(ts, mask, a, b) is None  # every level: a plain one-way marker


def test_fuel_grid_with_reactive_restrictions(tmp_path: Path) -> None:
    """A fuel grid whose restrictions depend on the history and the fuel level still draws."""
    test = synthesized("refueling")
    ts = test.problem.system
    restr = np.zeros_like(test.strategy.restrictions)
    restr[0, :: max(1, ts.n_moves // 7)] = True
    strategy = TestStrategy(np.zeros(ts.n_moves, dtype=bool), restr, "instantaneous")
    path = tmp_path / "fuel.png"
    plot_test(dataclasses.replace(test, strategy=strategy), path, dpi=50)
    png_size(path)


@pytest.mark.parametrize("name", ["small-reactive", "beaver-rescue"])
def test_agent_overlay(name: str, tmp_path: Path) -> None:
    test = synthesized(name)
    ts = test.problem.system
    cells = np.array([0, 1, len(ts.places) - 1])  # places of T, as synthesis.test_agent.loop keeps them
    # parks as synthesis.model.agent_system.Park (a name, entries into `cells`) and as plain cells/places
    parks: list[Any] = [SimpleNamespace(name="above", entries=(0, 1)), (2, 5) if ts.kind == "grid" else 0]
    plain, overlaid, via_test = tmp_path / "plain.png", tmp_path / "agent.png", tmp_path / "via_test.png"
    plot_test(test, plain, dpi=50)
    plot_test(test, overlaid, agent=SimpleNamespace(cells=cells, parks=parks), dpi=50)
    duck: Any = SimpleNamespace(cells=cells, parks=[])  # any object with cells, as plot_test documents
    plot_test(dataclasses.replace(test, agent=duck), via_test, dpi=50)
    assert plain.read_bytes() != overlaid.read_bytes()
    assert plain.read_bytes() != via_test.read_bytes()
    # the artifact's form: cells as written in the problem, parks with the cells they are entered from
    places: list[Any] = list(ts.places)
    as_written = [list(places[int(p)]) if ts.kind == "grid" else places[int(p)] for p in cells]
    mapping = tmp_path / "mapping.png"
    plot_test(test, mapping, agent={"cells": as_written, "parks": [{"name": "P", "from": as_written[:1]}]}, dpi=50)
    png_size(mapping)
    # an agent object without cells is ignored
    ignored = tmp_path / "ignored.png"
    plot_test(test, ignored, agent=SimpleNamespace(strategy="table"), dpi=50)
    png_size(ignored)


def test_an_artifact_is_drawn_with_its_synthesized_tests_panels(tmp_path: Path) -> None:
    """plot_artifact (the report's test cards) reads a loaded artifact as plot_test reads
    the synthesized test it was made from: the same panels, titles and restrictions."""
    from experiments.plots import artifact_view, plot_artifact
    from synthesis.artifacts.artifact import TestArtifact, artifact_of
    from synthesis.artifacts.summary import summary_of

    for name in ("small-reactive", "example1", "beaver-rescue", str(DATA / "ok_mixed.toml")):
        test = synthesized(name)
        art = TestArtifact.from_dict(artifact_of(test, summary_of(test)).to_dict())
        mine, theirs = panels_of(artifact_view(art)), panels_of(test)
        assert [p.title for p in mine] == [p.title for p in theirs], name
        assert all(np.array_equal(a.restricted, b.restricted) for a, b in zip(mine, theirs, strict=True))
        with_header, without = tmp_path / "a.png", tmp_path / "b.png"
        plot_artifact(art, with_header)
        plot_artifact(art, without, header=False)
        assert png_size(with_header)[1] > png_size(without)[1] > 150  # the header is the picture's title only


def test_propositions_are_named_with_where_they_hold() -> None:
    """Each proposition gets a legend line: the token that names exactly its cells, else
    its cells; on fuel grids the fuel levels where it holds; a colour of its own."""
    from experiments.plots import proposition_legend

    legend = {p: (where, colour) for p, where, colour in proposition_legend(load_problem("small-reactive").system)}
    assert legend["goal"][0] == "cell T" and legend["I1"][0] == "cell I1" and legend["I2"][0] == "cell I2"
    assert len({c for _, c in legend.values()}) == 3 and all(c.startswith("#") for _, c in legend.values())
    fuel = {p: where for p, where, _ in proposition_legend(load_problem("refueling").system)}
    assert fuel["unsafe"].endswith("at fuel 0") and fuel["low"].endswith("at fuel 1") and fuel["goal"] == "cell T"
    graph = {p: (where, colour) for p, where, colour in proposition_legend(load_problem("beaver-rescue").system)}
    assert graph["beaver"] == ("state beaver", "")  # graphs write propositions under their nodes


def test_a_mixed_picture_draws_the_static_area_typed_in(tmp_path: Path) -> None:
    """The borders of ``[environment] static`` (each once, whichever way it was typed) are drawn
    dashed in every panel, with a legend line, whether or not a wall was put there."""
    from experiments.plots import _static_area

    test = synthesized(str(DATA / "ok_mixed.toml"))
    ts = test.problem.system
    cells = {tuple(map(int, ts.places[a])) for pair in _static_area(test) for a in pair}
    borders = {frozenset((tuple(map(int, ts.places[a])), tuple(map(int, ts.places[b])))) for a, b in _static_area(test)}
    typed = [((0, 1), (0, 2)), ((0, 2), (0, 1)), ((1, 2), (1, 1)), ((1, 0), (2, 0)), ((0, 1), (0, 0)), ((2, 1), (1, 1))]
    assert borders == {frozenset(p) for p in typed} and cells <= {c for p in typed for c in p}
    assert _static_area(synthesized("small-reactive")) == set()  # only a mixed test has one
    path = plot_test(test, tmp_path / "mixed.svg")
    assert "static area (walls only here)" in path.read_text()
