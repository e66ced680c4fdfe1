"""Draw the pictures of the environment pages (``docs/envs/<name>.png``).

Usage::

    python -m experiments.tools.env_pictures [NAME ...] [--out docs/envs] [--tile 48]

Each picture is an ``rgb_array`` frame in the test engineer's view (the hidden test cells
shown) after a short scripted run chosen to show what the page describes: a door closed
in front of the goal, a restricted edge, the test agent in the way. The scripts are
action names (``N``, ``S``, ``E``, ``W``, ``stay`` on grids; ``-> state`` on graphs),
so they do not depend on action numbering; an action the mask refuses is an error,
since the page's caption would then describe a different picture.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np

SCRIPTS: dict[str, tuple[str, list[str], dict[str, object]]] = {
    "example1": ("FlowTest-Example1-v0", ["N"], {}),
    "small-reactive": ("FlowTest-SmallReactive-v0", ["N", "E"], {}),
    "beaver-rescue": ("FlowTest-BeaverRescue-v0", ["-> d1"], {"tile_size": 32}),
    "motion-primitives": ("FlowTest-MotionPrimitives-v0", ["-> p1", "-> jump1", "-> d1_j"], {"tile_size": 32}),
    "refueling": ("FlowTest-Refueling-v0", ["N", "N", "N", "E", "E", "S", "E", "N"], {}),
    "mars-exploration": ("FlowTest-MarsExploration-v0", ["N", "E", "E"], {}),
    "maze1": ("FlowTest-Maze1-v0", ["E", "E"], {}),
    "maze2": ("FlowTest-Maze2-v0", ["N", "N", "E"], {}),
    "patrolling": ("FlowTest-Patrolling-v0", ["W"], {}),
    "random-grid": ("FlowTest-RandomGrid-v0", ["stay"], {}),
}
"""Page name -> (env ID, the scripted actions, extra ``make`` arguments; graph pictures
are ``15 * tile_size`` pixels wide, so they keep 32)."""


class ScriptError(RuntimeError):
    """A scripted action that is unknown or masked in the state the script reached."""


def picture(env_id: str, actions: list[str], tile: int, **kwargs: object) -> tuple[np.ndarray, str]:
    """The engineer-view frame after ``actions``, and the ANSI text of the same state."""
    opts: dict[str, Any] = {"tile_size": tile, **kwargs}
    env = gym.make(env_id, render_mode="rgb_array", view="engineer", **opts)
    _, info = env.reset(seed=0)
    for name in actions:
        meanings = cast(Any, env.unwrapped).action_meanings()
        if name not in meanings:
            raise ScriptError(f"{env_id}: no action {name!r} at {info['system_state']} (actions: {meanings})")
        a = meanings.index(name)
        if not info["action_mask"][a]:
            raise ScriptError(f"{env_id}: action {name!r} is masked at {info['system_state']}")
        _, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            raise ScriptError(f"{env_id}: the run ended at {info['system_state']} before the script did")
    from flowtest_env.render import ansi

    u = cast(Any, env.unwrapped)
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    return frame, ansi(u.game, u.run, "engineer")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", help=f"pages (default: all of {', '.join(SCRIPTS)})")
    ap.add_argument("--out", type=Path, default=Path("docs/envs"), help="output folder")
    ap.add_argument("--tile", type=int, default=48, help="pixels per grid cell")
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import image

    import flowtest_env  # noqa: F401  (registers the IDs)
    from flowtest_env.artifacts import artifact_path

    names = args.names or list(SCRIPTS)
    unknown = [n for n in names if n not in SCRIPTS]
    if unknown:
        ap.error(f"unknown page(s) {', '.join(unknown)}; known: {', '.join(SCRIPTS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in names:
        env_id, actions, kwargs = SCRIPTS[name]
        if name != "random-grid" and not artifact_path(name).exists():
            print(f"{name}: skipped, no shipped artifact")
            continue
        frame, text = picture(env_id, actions, args.tile, **kwargs)
        path = args.out / f"{name}.png"
        image.imsave(path, frame)
        print(f"{name}: {frame.shape[1]}x{frame.shape[0]} -> {path}\n{text}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
