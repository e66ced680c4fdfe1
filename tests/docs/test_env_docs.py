"""The environment pages (``docs/envs/``) state what the environments are: one page per
registered ID, and every figure a page gives (spaces, step budget, registered kwargs,
the shipped test's size) is the env's own.

A page that disagrees after an artifact is rebuilt or an encoding changes fails here,
with the sentence or figure it should say.
"""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env
from flowtest_env.artifacts import artifact_path, builtin_game
from flowtest_env.envs import BUILTIN_ENVS
from flowtest_env.game import TestGame

DOCS = Path(__file__).resolve().parents[2] / "docs" / "envs"
PAGES = {f"FlowTest-{stem}-v0": name for name, (stem, _) in BUILTIN_ENVS.items()} | {"FlowTest-RandomGrid-v0": "random-grid"}


def _count(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def shipped_test_sentence(game: TestGame) -> str:
    """The sentence a built-in's page gives about its shipped test, from the artifact."""
    art = game.artifact
    s = art.summary
    static = art.strategy.static_obstacles
    n_static, n_walls = int(static.sum()), int(game.permanent_wall.sum())
    if n_static == 0:
        walls = "no static obstacle"
    elif n_walls == n_static:
        walls = f"{_count(n_static, 'static obstacle move')}, all walls of the map"
    elif n_walls == 0:
        walls = f"{_count(n_static, 'static obstacle move')}, each at some fuel levels of its cell only"
    else:
        walls = f"{_count(n_static, 'static obstacle move')}, {n_walls} of them walls of the map"
    reactive = art.strategy.blocked & ~static[None, :]
    n_reactive = int(reactive.sum())
    if n_reactive == 0:
        react = "no reactive restriction"
    else:
        n_hist = int(reactive.any(axis=1).sum())
        react = f"{_count(n_reactive, 'reactive restriction')} in {n_hist} of the {art.histories.n_states} histories"
        if art.kind == "agent":
            react += ", realized by the test agent standing in the way"
    return (
        f"The shipped test (`flowtest_env/artifacts/{art.name}.json`): flow {s['flow']}, "
        f"{_count(s['n_cuts'], 'cut edge')} of the product graph; {walls}; {react}."
    )


def _page(env_id: str) -> str:
    path = DOCS / f"{PAGES[env_id]}.md"
    assert path.exists(), f"no page {path} for {env_id}"
    return path.read_text()


def test_one_page_per_registered_id_and_an_index() -> None:
    assert set(PAGES) == set(flowtest_env.ENV_IDS)
    index = (DOCS / "index.md").read_text()
    for env_id, page in PAGES.items():
        assert f"`{env_id}`" in index and f"({page}.md)" in index, f"index.md does not list {env_id}"
        assert _page(env_id).startswith(f"# {env_id}\n")
    assert (DOCS / "multiagent.md").exists()


@pytest.mark.parametrize("env_id", sorted(PAGES))
def test_page_figures_are_the_envs(env_id: str) -> None:
    name = PAGES[env_id]
    text = _page(env_id)
    spec = gym.spec(env_id)
    assert f"`{env_id}` with kwargs `{spec.kwargs}`" in text
    assert f"`max_steps` = {spec.kwargs['max_steps']} steps" in text
    if name != "random-grid" and not artifact_path(name).exists():
        assert "not shipped" in text, f"{name}: the page must say the artifact is not shipped yet"
        return
    env = gym.make(env_id)
    assert f"**Action space**: `Discrete({env.action_space.n})`" in text
    flat = env.observation_space
    assert f"`Box(0, 1, {flat.shape}, float32)`" in text
    game = env.unwrapped.game
    if game.is_grid:
        grid = gym.make(env_id, obs_kind="grid")
        assert f"`Box(0, 255, {grid.observation_space.shape}, uint8)`" in text
        channels = ", ".join(f"`{c}`" for c in grid.unwrapped.encoder.channels)
        assert f"channels {channels}." in text
    else:
        assert "uint8)`" not in text, f"{name} is a graph: it has no grid observation"
    if name != "random-grid":
        assert shipped_test_sentence(builtin_game(name)) in text, f"{name}: the page should say: {shipped_test_sentence(builtin_game(name))}"
        objectives = game.artifact.objectives
        assert f"`phi_sys = {objectives['system']}`, hidden `phi_test = {objectives['test']}`" in text
    picture = re.search(r"!\[[^\]]*\]\(([^)]+\.png)\)", text)
    assert picture and (DOCS / picture.group(1)).exists(), f"{name}: the page's picture is missing"


def test_pictures_are_the_scripted_frames() -> None:
    """Each page's picture is what ``python -m experiments.tools.env_pictures`` draws today."""
    from matplotlib import image

    from experiments.tools.env_pictures import SCRIPTS, picture

    for name, (env_id, actions, kwargs) in SCRIPTS.items():
        if name not in ("random-grid",) and not artifact_path(name).exists():
            continue
        frame, _ = picture(env_id, actions, 48, **kwargs)
        shipped = (image.imread(DOCS / f"{name}.png")[..., :3] * 255).round().astype(np.uint8)
        assert shipped.shape == frame.shape and np.array_equal(shipped, frame), (
            f"docs/envs/{name}.png is not today's frame; run python -m experiments.tools.env_pictures {name}"
        )


@pytest.mark.parametrize("env_id", sorted(PAGES))
def test_page_says_what_the_observation_lacks_and_how_to_add_it(env_id: str) -> None:
    """Each page names the memory, shaping and fixed-shape options, and each works on its env."""
    text = _page(env_id)
    assert "## What the observation lacks" in text
    section = text.split("## What the observation lacks", 1)[1].split("\n## ", 1)[0]
    for needle in ("VisitedPlaces(env)", f'gym.make("{env_id}", memory="visited")', "--algo recurrent-ppo", "DistanceShaping", 'obs_kind="padded"'):
        assert needle in section, f"{env_id}: the page does not say {needle}"
    plain = gym.make(env_id)
    with_memory = gym.make(env_id, memory="visited", shaping=10.0)
    assert with_memory.observation_space.shape[0] > plain.observation_space.shape[0]
    obs, _ = with_memory.reset(seed=0)
    assert with_memory.observation_space.contains(obs)
    grid = plain.unwrapped.game.is_grid
    assert ("needs a grid" in section) == (not grid)
    if grid:
        assert gym.make(env_id, obs_kind="padded").observation_space.shape == (14 * 8 * 8 + 5,)
