"""Learnable out of the box, honestly: the SUT's memory and the reward shaping are public
wrappers and env options (off unless asked), the fixed-shape observation plays many tests,
and ``flowtest evaluate`` reports a pair that cannot play as a row, never aborting."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import flowtest_env  # noqa: F401
from agents.checkpoint import trust_pickled_models
from flowtest_env.encoding import EncodingError
from flowtest_env.wrappers import DistanceShaping, VisitedPlaces


@pytest.fixture(autouse=True)
def _no_lasting_trust() -> Iterator[None]:
    """A test that trusts SB3 zips (``--trust-model``) leaves the process as it found it."""
    yield
    trust_pickled_models(False)


def _rollout(env: gym.Env, actions: list[int]) -> tuple[list[np.ndarray], list[float]]:
    obs, info = env.reset(seed=0)
    seen, rewards = [obs], []
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        seen.append(obs)
        rewards.append(float(r))
        if term or trunc:
            break
    return seen, rewards


MOVES = [0, 0, 2, 2, 1, 1, 3, 3, 0, 2]


def test_memory_wrapper_and_env_option_agree_and_remember_only_own_places() -> None:
    plain = gym.make("FlowTest-Maze2-v0")
    wrapped = VisitedPlaces(gym.make("FlowTest-Maze2-v0"))
    option = gym.make("FlowTest-Maze2-v0", memory="visited")
    n = plain.observation_space.shape[0]
    assert wrapped.observation_space == option.observation_space
    assert wrapped.observation_space.shape[0] > n
    a, _ = _rollout(wrapped, MOVES)
    b, _ = _rollout(option, MOVES)
    p, _ = _rollout(plain, MOVES)
    for x, y, z in zip(a, b, p, strict=True):
        np.testing.assert_array_equal(x, y)
        np.testing.assert_array_equal(x[:n], z)  # the env's own observation is unchanged
    pos = flowtest_env.wrappers.position_slice(plain.unwrapped.encoder)
    visited = np.maximum.accumulate(np.stack([z[pos] for z in p]), axis=0)
    np.testing.assert_array_equal(np.stack([x[n:] for x in a]), visited)
    # a new episode forgets
    obs, _ = wrapped.reset(seed=1)
    np.testing.assert_array_equal(obs[n:], obs[pos])
    assert wrapped.action_masks().dtype == bool


def test_shaping_is_off_unless_asked_and_potential_based() -> None:
    plain = gym.make("FlowTest-Maze2-v0")
    _, r0 = _rollout(plain, MOVES)
    _, r1 = _rollout(gym.make("FlowTest-Maze2-v0", shaping=10.0, shaping_gamma=0.9), MOVES)
    _, r2 = _rollout(DistanceShaping(gym.make("FlowTest-Maze2-v0"), scale=10.0, gamma=0.9), MOVES)
    assert r1 == pytest.approx(r2)
    assert r1 != pytest.approx(r0)
    # the shaping term is gamma * phi' - phi, phi from the SUT's distance on G_sys only
    env = gym.make("FlowTest-Maze2-v0", shaping=10.0, shaping_gamma=0.9).unwrapped
    env.reset(seed=0)
    phi0 = env._potential(env.game, env.run)
    _, r, _, _, _ = env.step(MOVES[0])
    phi1 = env._potential(env.game, env.run)
    plain.reset(seed=0)
    _, base, _, _, _ = plain.step(MOVES[0])
    assert r == pytest.approx(base + 0.9 * phi1 - phi0)
    with pytest.raises(ValueError, match="memory"):
        gym.make("FlowTest-Maze2-v0", memory="everything")
    with pytest.raises(ValueError, match="flat"):
        VisitedPlaces(gym.make("FlowTest-Maze2-v0", obs_kind="grid"))


@pytest.mark.parametrize(
    "env_id", ["FlowTest-RandomGrid-v0", "FlowTest-Maze2-v0", "FlowTest-Example1-v0", "FlowTest-Refueling-v0", "FlowTest-Maze1-v0", "FlowTest-Patrolling-v0"]
)
def test_padded_observation_has_one_shape(env_id: str) -> None:
    env = gym.make(env_id, obs_kind="padded")
    ref = gym.make("FlowTest-SmallReactive-v0", obs_kind="padded")
    assert env.observation_space == ref.observation_space
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    enc = env.unwrapped.encoder
    # the system's own cell is where the env says it is, inside the padded grid
    pos = obs[enc.position_slice()].reshape(enc.pad_to, enc.pad_to)
    r, c = info["system_state"][0] if env.unwrapped.game.ts.kind == "fuel" else info["system_state"]
    assert pos[r, c] == 1.0 and pos.sum() == 1.0


def test_padded_refuses_graphs_and_big_grids() -> None:
    with pytest.raises(EncodingError, match="graph"):
        gym.make("FlowTest-BeaverRescue-v0", obs_kind="padded")
    with pytest.raises(EncodingError, match="larger than pad_to=4"):
        gym.make("FlowTest-Maze2-v0", obs_kind="padded", pad_to=4)


def rl(module: str) -> None:
    """Skip unless the ``rl`` extra is installed."""
    pytest.importorskip(module)


def test_train_flags_are_used_saved_and_play_many_tests(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rl("sb3_contrib")
    from experiments.cli.cli import main

    model = tmp_path / "m.zip"
    code = main(
        [
            "train",
            "FlowTest-Maze2-v0",
            "--trainer",
            "sb3",
            "--steps",
            "256",
            "--out",
            str(model),
            "--eval-episodes",
            "2",
            "-q",
            "--n-envs",
            "2",
            "--n-steps",
            "64",
            "--batch-size",
            "64",
            "--net-arch",
            "16,16",
            "--shaping",
            "0",
            "--obs-kind",
            "padded",
            "--learning-rate",
            "0.0005",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0
    assert "--shaping 0" in err and "--net-arch 16,16" in err
    assert "obs_kind=padded" in out and "shaping=0" in out
    saved = json.loads(model.with_suffix(".json").read_text())
    assert saved["settings"]["net_arch"] == [16, 16] and saved["settings"]["learning_rate"] == 0.0005
    assert saved["env_options"] == {"memory": "visited", "shaping": 0.0, "shaping_gamma": 0.99, "obs_kind": "padded", "pad_to": 8}
    out_dir = tmp_path / "report"
    trust_pickled_models(True)  # an SB3 zip: `flowtest evaluate --trust-model`
    code = main(
        [
            "evaluate",
            "--env",
            "FlowTest-Maze2-v0",
            "example1",
            "beaver-rescue",
            "--sut",
            f"ppo:{model}",
            "scripted:replanner",
            "--episodes",
            "1",
            "--out",
            str(out_dir),
            "-q",
        ]
    )
    assert code == 0
    records = {(r["env"], r["sut"]): r for r in json.loads((out_dir / "results.json").read_text())}
    assert len(records) == 6
    bad = records[("beaver-rescue", f"ppo:{model}")]
    assert bad["episodes"] == 0 and "graph" in bad["error"]
    assert records[("example1", f"ppo:{model}")]["episodes"] == 1 and records[("example1", f"ppo:{model}")]["error"] is None
    assert records[("beaver-rescue", "scripted:replanner")]["system_objective_met_rate"] == 1.0
    assert "not run:" in (out_dir / "report.md").read_text()
    assert "not run: " in (out_dir / "report.html").read_text()


def test_flat_model_on_another_test_is_a_row(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rl("sb3_contrib")
    from experiments.cli.cli import main

    model = tmp_path / "flat.zip"
    assert (
        main(
            [
                "train",
                "small-reactive",
                "--steps",
                "128",
                "--out",
                str(model),
                "--eval-episodes",
                "0",
                "-q",
                "--n-envs",
                "1",
                "--n-steps",
                "128",
                "--batch-size",
                "64",
            ]
        )
        == 0
    )  # the native trainer
    code = main(["evaluate", "--env", "FlowTest-Maze2-v0", "small-reactive", "--sut", f"ppo:{model}", "--episodes", "1", "--out", str(tmp_path / "r"), "-q"])
    out = capsys.readouterr().out
    assert code == 0
    assert "FlowTest-Maze2-v0" in out and "not run: model" in out and "'maze2' gives" in out


def test_unknown_sut_name_is_invalid_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from experiments.cli.cli import main

    assert main(["evaluate", "--env", "maze2", "--sut", "nosuch", "--out", str(tmp_path / "x")]) == 2
    assert "unknown policy" in capsys.readouterr().err


def test_recurrent_ppo_trains_and_plays(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rl("sb3_contrib")
    from experiments.cli.cli import main

    model = tmp_path / "lstm.zip"
    assert (
        main(
            [
                "train",
                "small-reactive",
                "--trainer",
                "sb3",
                "--algo",
                "recurrent-ppo",
                "--steps",
                "128",
                "--out",
                str(model),
                "--eval-episodes",
                "2",
                "-q",
                "--n-envs",
                "1",
                "--n-steps",
                "128",
                "--batch-size",
                "64",
                "--memory",
                "none",
                "--net-arch",
                "16",
            ]
        )
        == 0
    )
    trust_pickled_models(True)  # an SB3 zip: `flowtest evaluate --trust-model`
    assert main(["evaluate", "--env", "small-reactive", "--sut", f"ppo:{model}", "--episodes", "2", "--out", str(tmp_path / "r"), "-q"]) == 0
    from agents.ppo import load_model

    assert type(load_model(model)).__name__ == "RecurrentPPO"
