"""Each registered environment's docstring says what its spaces are, and says it right.

The docstrings (Gymnasium's ``## Action Space`` / ``## Observation Space`` sections, what
``help()`` and documentation generators show) are held to the environments built from
the registry (``flowtest_env.REGISTRATIONS``): an env with a fixed test states its
``Discrete(n)``, its flat ``float32[...]`` shape and, on grids, its ``uint8[C, H, W]``
image shape and the planes it names; every figure in those sections must be the env's
own. ``FlowTest-v0`` plays any test, so its docstring states rules instead of figures;
those rules are checked against every built-in. A docstring that goes stale after an
encoding or an artifact changes fails here with the figure it should give.
"""

from __future__ import annotations

import importlib
import inspect
import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import flowtest_env
from flowtest_env.envs import BUILTIN_ENVS, FlowTestEnv

FIGURE = {
    "discrete": re.compile(r"Discrete\((\d+)\)"),
    "float32": re.compile(r"float32\[(\d+(?:, \d+)*)\]"),
    "uint8": re.compile(r"uint8\[(\d+(?:, \d+)*)\]"),
}


def entry_class(env_id: str) -> type:
    """The class a registered ID's ``entry_point`` names."""
    module, _, name = flowtest_env.REGISTRATIONS[env_id]["entry_point"].partition(":")
    cls = getattr(importlib.import_module(module), name)
    assert isinstance(cls, type)
    return cls


def section(doc: str, title: str) -> str:
    """The text of a docstring's ``## title`` section."""
    parts = re.split(r"^## ", doc, flags=re.M)
    for part in parts[1:]:
        head, _, body = part.partition("\n")
        if head.strip() == title:
            return body
    raise AssertionError(f"the docstring has no '## {title}' section")


def figures(text: str, kind: str) -> set[tuple[int, ...]]:
    return {tuple(int(x) for x in m.group(1).split(", ")) for m in FIGURE[kind].finditer(text)}


def doc_of(env_id: str) -> str:
    return inspect.cleandoc(entry_class(env_id).__doc__ or "")


FIXED = sorted(i for i in flowtest_env.REGISTRATIONS if i != flowtest_env.ANY_TEST_ID)


def test_every_registered_id_is_checked_here() -> None:
    assert set(FIXED) | {flowtest_env.ANY_TEST_ID} == set(flowtest_env.REGISTRATIONS)
    assert set(FIXED) == set(flowtest_env.ENV_IDS)
    # one class per ID with a fixed test: each carries its own documentation
    assert len({entry_class(i) for i in FIXED}) == len(FIXED)


@pytest.mark.parametrize("env_id", FIXED)
def test_docstring_states_the_spaces_of_its_env(env_id: str) -> None:
    doc = doc_of(env_id)
    act, obs = section(doc, "Action Space"), section(doc, "Observation Space")
    env = gym.make(env_id)
    assert isinstance(env.action_space, spaces.Discrete)
    n = int(env.action_space.n)
    assert figures(act, "discrete") == {(n,)}, f"{env_id}: the action space section should say ``Discrete({n})``"
    flat = env.observation_space
    assert isinstance(flat, spaces.Box) and flat.dtype == np.float32
    shape = ", ".join(map(str, flat.shape))
    assert figures(obs, "float32") == {tuple(flat.shape)}, f"{env_id}: the observation section should say ``float32[{shape}]``"
    game = env.unwrapped.game
    if not game.is_grid:
        assert not figures(obs, "uint8") and "only" in obs, f"{env_id} is a graph: its observation is flat only"
        return
    grid_env = gym.make(env_id, obs_kind="grid")
    grid = grid_env.observation_space
    assert isinstance(grid, spaces.Box) and grid.dtype == np.uint8
    gshape = ", ".join(map(str, grid.shape))
    assert figures(obs, "uint8") == {tuple(grid.shape)}, f"{env_id}: the observation section should say ``uint8[{gshape}]``"
    planes = re.search(r"\bwith\s+(.*?)\s+planes?\b", obs, flags=re.S)
    if planes:
        named = set(re.findall(r"``(\w+)``", planes.group(1)))
        channels = set(grid_env.unwrapped.encoder.channels)
        assert named and named <= channels, f"{env_id}: planes {sorted(named - channels)} are not channels {sorted(channels)}"


def test_the_any_test_docstring_rules_hold_for_every_builtin() -> None:
    """``FlowTest-v0``'s docstring gives rules, not figures: ``Discrete(5)`` on grids,
    ``Discrete(k + 1)`` on graphs (``k`` the largest out-degree), a ``float32`` vector in
    ``[0, 1]``, ``obs_kind="padded"`` one shape for every grid test, ``obs_kind="grid"`` a
    ``uint8[C, H, W]`` image of the grid."""
    assert entry_class(flowtest_env.ANY_TEST_ID) is FlowTestEnv
    doc = doc_of(flowtest_env.ANY_TEST_ID)
    act, obs = section(doc, "Action Space"), section(doc, "Observation Space")
    for claim in ("``Discrete(5)`` on grids", "``Discrete(k + 1)``", "``k`` the largest out-degree"):
        assert claim in " ".join(act.split()), f"FlowTestEnv's action space section no longer says {claim}"
    for claim in ('``obs_kind="flat"`` (default): a ``float32`` vector in ``[0, 1]``', "one flat shape for every grid test", "``uint8[C, H, W]``"):
        assert claim in " ".join(obs.split()), f"FlowTestEnv's observation section no longer says {claim}"
    padded = set()
    for name in BUILTIN_ENVS:
        env = gym.make(flowtest_env.ANY_TEST_ID, test=name)
        game = env.unwrapped.game
        assert isinstance(env.action_space, spaces.Discrete)
        if game.is_grid:
            assert env.action_space.n == 5, name
        else:
            k = int(np.bincount(game.ts.src, minlength=game.ts.n_states).max())
            assert env.action_space.n == k + 1, name
        flat = env.observation_space
        assert isinstance(flat, spaces.Box) and flat.dtype == np.float32 and len(flat.shape) == 1
        assert np.all(flat.low == 0) and np.all(flat.high == 1), name
        if game.is_grid:
            grid = gym.make(flowtest_env.ANY_TEST_ID, test=name, obs_kind="grid").observation_space
            lay = game.ts.layout
            assert lay is not None and grid.dtype == np.uint8 and grid.shape[1:] == (lay.rows, lay.cols), name
            padded.add(gym.make(flowtest_env.ANY_TEST_ID, test=name, obs_kind="padded").observation_space.shape)
    assert len(padded) == 1
