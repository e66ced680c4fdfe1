"""The NumPy vector env's outputs, bit for bit, as the step before the speed work gave them.

Every case steps a vector env on seeded random actions (legal ones, and with probability
0.3 any action at all: restricted moves, moves that do not exist) through many episode ends
(short step budgets force truncations too) and hashes everything the env returns, in
order: observations (dtype, shape and bytes), rewards, terminated, truncated and every info
(``action_mask``, ``system_state``, ``verdict``, ``final_obs``/``final_info``), and in
``DISABLED`` mode the masked resets' outputs. The digests in ``tests/data/vector_digests.json``
were recorded from the implementation of commit ``792e173`` (before the observation gather,
the fused step tables and the in-place outputs), so a faster step must give the same bytes.

The cases: every registered ID (flat observations), every grid built-in with grid
observations, the memory and shaping options, numeric infos, the accumulative setting, every
autoreset mode, and three standard pools (padded observations; fuel and a test agent among
them), drawn at random and assigned fixed.

To record the digests again after a deliberate change of the outputs (say so in the commit)::

    .venv/bin/python -m tests.flowtest_env.test_vector_golden --write
"""

from __future__ import annotations

import argparse
import hashlib
import json
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env
from flowtest_env.vector import PoolVectorEnv

DIGESTS = Path(__file__).resolve().parent.parent / "data" / "vector_digests.json"
GRID_IDS = ["FlowTest-Example1-v0", "FlowTest-SmallReactive-v0", "FlowTest-Refueling-v0", "FlowTest-Maze1-v0", "FlowTest-Maze2-v0", "FlowTest-Patrolling-v0"]
STANDARD = ["reachability1/5x5-v2", "safety2/5x5/fuel-v2", "reachability1/5x5/blocked/agent-v2"]


def _registered(env_id: str, mode: str = "NEXT_STEP", **kw: Any) -> Callable[[], Any]:
    return lambda: gym.make_vec(env_id, num_envs=7, vectorization_mode="vector_entry_point", autoreset_mode=mode, max_steps=25, **kw)


def _standard(pool: str, assignment: str, mode: str = "NEXT_STEP", **kw: Any) -> Callable[[], Any]:
    def make() -> Any:
        from flowtest_env.pools import load_pool

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tests = load_pool(pool, "train", 12)
        return PoolVectorEnv(9, tests, assignment=assignment, autoreset_mode=mode, obs_kind="padded", max_steps=30, **kw)

    return make


CASES: dict[str, Callable[[], Any]] = {
    **{f"{i}/flat": _registered(i) for i in flowtest_env.ENV_IDS if i != "FlowTest-RandomGrid-v0"},
    "FlowTest-RandomGrid-v0/flat": _registered("FlowTest-RandomGrid-v0", seeds=[0, 1, 2]),
    **{f"{i}/grid/same_step": _registered(i, "SAME_STEP", obs_kind="grid") for i in GRID_IDS},
    "FlowTest-Maze2-v0/memory+shaping/next_step": _registered("FlowTest-Maze2-v0", memory="visited", shaping=10.0),
    "FlowTest-Patrolling-v0/memory+shaping/same_step": _registered("FlowTest-Patrolling-v0", "SAME_STEP", memory="visited", shaping=5.0),
    "FlowTest-BeaverRescue-v0/memory/disabled": _registered("FlowTest-BeaverRescue-v0", "DISABLED", memory="visited"),
    "FlowTest-Refueling-v0/numeric/same_step": _registered("FlowTest-Refueling-v0", "SAME_STEP", numeric_infos=True),
    "FlowTest-Maze1-v0/numeric/disabled": _registered("FlowTest-Maze1-v0", "DISABLED", numeric_infos=True),
    "FlowTest-SmallReactive-v0/accumulative/next_step": _registered("FlowTest-SmallReactive-v0", setting="accumulative"),
    "FlowTest-Maze2-v0/accumulative+memory/same_step": _registered("FlowTest-Maze2-v0", "SAME_STEP", setting="accumulative", memory="visited"),
    **{f"{p}/random": _standard(p, "random") for p in STANDARD},
    "reachability1/5x5-v2/fixed/memory/same_step": _standard("reachability1/5x5-v2", "fixed", "SAME_STEP", memory="visited"),
    "safety2/5x5/fuel-v2/fixed/shaping/disabled": _standard("safety2/5x5/fuel-v2", "fixed", "DISABLED", shaping=10.0),
}


def _feed(h: Any, x: Any) -> None:
    """Hash ``x`` (arrays, dicts, sequences, scalars, ``None``) with its types and shapes."""
    if isinstance(x, dict):
        h.update(b"{")
        for k in sorted(x):
            h.update(repr(k).encode())
            _feed(h, x[k])
        h.update(b"}")
    elif isinstance(x, np.ndarray):
        h.update(f"{x.dtype.str}{x.shape}".encode())
        if x.dtype == object:
            for v in x.ravel().tolist():
                _feed(h, v)
        else:
            h.update(np.ascontiguousarray(x).tobytes())
    elif isinstance(x, (list, tuple)):
        h.update(b"[")
        for v in x:
            _feed(h, v)
        h.update(b"]")
    else:
        h.update(f"{type(x).__name__}:{x!r};".encode())


def digest(make: Callable[[], Any], steps: int = 150, seed: int = 5) -> tuple[str, int]:
    """The hash of everything a rollout of ``make()`` returns (see the module docstring),
    and the number of episode ends it went through."""
    env = make()
    mode = env.unwrapped.autoreset_mode
    rng = np.random.default_rng(seed)
    h = hashlib.sha256()
    obs, infos = env.reset(seed=seed)
    _feed(h, (obs, infos))
    n_actions = int(env.single_action_space.n)
    mask = infos["action_mask"]
    ends = 0
    for _ in range(steps):
        legal = np.argmax(rng.random(mask.shape) * (mask > 0), axis=1)
        anything = rng.integers(n_actions, size=mask.shape[0])
        actions = np.where(rng.random(mask.shape[0]) < 0.3, anything, legal)
        out = env.step(actions)
        _feed(h, out)
        mask = out[4]["action_mask"]
        ended = out[2] | out[3]
        ends += int(ended.sum())
        if mode == gym.vector.AutoresetMode.DISABLED and ended.any():
            obs, infos = env.reset(options={"reset_mask": ended})
            _feed(h, (obs, infos))
            mask = np.where(ended[:, None], infos["action_mask"], mask)
    env.close()
    return h.hexdigest(), ends


def _recorded() -> dict[str, str]:
    out: dict[str, str] = json.loads(DIGESTS.read_text())
    return out


def test_every_case_is_recorded() -> None:
    assert sorted(_recorded()) == sorted(CASES)


@pytest.mark.parametrize("case", sorted(CASES))
def test_outputs_are_the_recorded_ones(case: str, pool_cache: Path) -> None:
    found, ends = digest(CASES[case])
    assert ends >= 7, f"{case}: only {ends} episode ends"
    assert found == _recorded()[case], f"{case}: the vector env's outputs changed"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="record the vector env's output digests")
    ap.add_argument("--write", action="store_true", help=f"write {DIGESTS}")
    args = ap.parse_args(argv)
    old = _recorded() if DIGESTS.exists() else {}
    found = {case: digest(make)[0] for case, make in sorted(CASES.items())}
    for case, d in found.items():
        print(f"{'same' if old.get(case) == d else 'CHANGED'}  {case}")
    if args.write:
        DIGESTS.write_text(json.dumps(found, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
