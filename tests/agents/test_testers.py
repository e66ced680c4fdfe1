"""Testers other than the synthesized one: legal play, the exhaustive fairness check, and
learned (PPO) testers loaded by name and compared with the synthesized test."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agents.base import PolicyError
from agents.registry import make_policy
from agents.testers import SynthesizedTester, TesterView, VersusTesterEnv, make_tester, problem_of
from experiments.cli.cli import main
from flowtest_env.artifacts import artifact_path
from flowtest_env.envs import BUILTIN_ENVS
from flowtest_env.fairness import can_still_meet, check_tester
from flowtest_env.multiagent import raw_env

PROBLEMS = [n for n in BUILTIN_ENVS if artifact_path(n).exists()]
TESTED = ["maze1", "maze2", "patrolling", "small-reactive", "beaver-rescue", "motion-primitives"]


def planted_trap(env: raw_env) -> int:
    """A hand-made small-reactive tester with a planted trap: it always closes both doors
    into T (E of the top middle cell, N of the bottom right cell) and nothing else; each
    restriction leaves other moves open, so every choice is legal."""
    return {1: 1 << 2, 5: 1 << 0}.get(env.run.system, 0)


@pytest.mark.parametrize("problem", [p for p in TESTED if p in PROBLEMS])
def test_synthesized_tester_is_fair_and_guaranteed_exhaustively(problem: str) -> None:
    env = raw_env(problem=problem)
    report = check_tester(env, SynthesizedTester())
    assert report.nodes > 1
    assert report.illegal == 0
    assert report.fair, report.summary()
    assert report.guaranteed, report.summary()


def test_fairness_check_finds_a_planted_trap() -> None:
    env = raw_env(problem="small-reactive")
    report = check_tester(env, planted_trap)
    assert report.illegal == 0
    assert not report.fair
    assert report.traps == report.nodes  # T is closed from the start: every state is a trap
    assert report.trap_path == [] and report.trap_state is not None
    # the witness path is a real run: replayed against the tester it ends in the trap
    against = VersusTesterEnv("small-reactive", planted_trap, max_steps=10)
    policy = make_policy("scripted:replanner", against)
    obs, info = against.reset(seed=0)
    policy.reset(0)
    done = False
    while not done:
        obs, _, term, trunc, info = against.step(policy.act(obs, info))
        done = term or trunc
    assert info["verdict"]["system_objective"] == "open"
    assert against.trapped()


def test_fairness_check_finds_a_trap_reached_only_by_some_system_moves() -> None:
    """Close the doors into T only once the system has visited I2 (history changed):
    the start is not a trap, some runs are, and the shortest witness is a real run."""
    env = raw_env(problem="small-reactive")
    h0 = env.game.reset(agent_first_move=False).history

    def late_trap(e: raw_env) -> int:
        return 0 if e.run.history == h0 else planted_trap(e)

    report = check_tester(env, late_trap)
    assert 0 < report.traps < report.nodes
    assert report.trap_path  # a non-empty witness
    game = env.game
    run = game.reset(agent_first_move=False)
    env.run = run
    run.override = late_trap(env)
    for a in report.trap_path:
        assert game.action_mask(run)[a]
        game.system_step(run, a)
        env.run = run
        run.override = late_trap(env)
    assert not can_still_meet(env, late_trap, run, tester_next=False)
    assert can_still_meet(env, SynthesizedTester(), game.reset(agent_first_move=False), tester_next=True)


def test_versus_env_with_the_synthesized_tester_matches_the_single_agent_env() -> None:
    from experiments.evaluation.episodes import env_named as make_env
    from experiments.evaluation.episodes import run_episode

    for env_id in ("FlowTest-Maze2-v0", "FlowTest-SmallReactive-v0"):
        single = make_env(env_id)
        problem = single.unwrapped.problem
        versus = VersusTesterEnv(problem, "synthesized", max_steps=problem_of(env_id)[1])
        for sut in ("scripted:replanner", "random"):
            a = run_episode(single, make_policy(sut, single), env_id, sut, 3)
            b = run_episode(versus, make_policy(sut, versus), env_id, sut, 3, tester="synthesized")
            assert a.actions == b.actions
            assert a.verdict == b.verdict
            assert b.kind == a.kind != "test"


def test_tester_view_steps_the_fixed_system() -> None:
    env = TesterView("maze2", "scripted:replanner")
    obs, info = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape
    rng = np.random.default_rng(0)
    done, steps = False, 0
    while not done:
        mask = info["action_mask"]
        assert np.array_equal(mask.astype(bool), env.action_masks())
        obs, reward, term, trunc, info = env.step(int(rng.choice(np.flatnonzero(mask))))
        done, steps = term or trunc, steps + 1
        if not done:
            assert reward == 0.0
    assert reward in (1.0, -1.0) or info["verdict"]["system_objective"] != "met"
    assert steps <= env.ma.max_cycles


def test_unknown_tester_is_a_policy_error(tmp_path: Path) -> None:
    env = raw_env(problem="maze2")
    with pytest.raises(PolicyError, match="unknown tester"):
        make_tester("gr1", env)
    with pytest.raises(PolicyError, match="no learned tester for 'maze2'"):
        make_tester(f"ppo:{tmp_path}", env)


# --------------------------------------------------------------------------- learned testers


@pytest.fixture(scope="module")
def learned(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of learned testers for maze2 and small-reactive (tiny training budgets:
    what they learned does not matter here, only that they load and play by the rules)."""
    pytest.importorskip("sb3_contrib")
    from experiments.training.tester import train_tester

    folder = tmp_path_factory.mktemp("testers")
    for problem in ("maze2", "small-reactive"):
        summary = train_tester(
            problem, 128, folder / f"{problem}.zip", seed=1, progress_bar=False, eval_episodes=1, n_envs=1, n_steps=128, batch_size=64, n_epochs=1
        )
        assert summary["steps"] == 128
        assert Path(summary["model"]).exists() and Path(summary["curve"]).exists()
        assert summary["fairness"]["illegal"] == 0
    return folder


@pytest.mark.parametrize("problem", ["maze2", "small-reactive"])
def test_learned_tester_loads_and_plays_legal_moves_only(learned: Path, problem: str) -> None:
    env = VersusTesterEnv(problem, f"ppo:{learned / problem}.zip")
    tester = env.tester
    assert tester.name.startswith("ppo:")
    played = []

    def checked(e: raw_env) -> int:
        a = tester(e)
        assert e.tester_mask()[a], f"illegal tester move {a}"
        played.append(a)
        return a

    env.tester = checked
    for sut in ("random", "scripted:replanner"):
        policy = make_policy(sut, env)
        for seed in range(3):
            obs, info = env.reset(seed=seed)
            policy.reset(seed)
            done = False
            while not done:
                obs, _, term, trunc, info = env.step(policy.act(obs, info))
                done = term or trunc
    assert played
    # and at every reachable state, not only the sampled ones
    report = check_tester(env.ma, tester)
    assert report.illegal == 0 and report.nodes > 1


def test_learned_tester_of_another_problem_is_refused(learned: Path) -> None:
    with pytest.raises(PolicyError, match="trained on 'maze2'"):
        VersusTesterEnv("small-reactive", f"ppo:{learned / 'maze2'}.zip")
    with pytest.raises(PolicyError, match="is not a tester"):
        from experiments.training.settings import DEFAULTS
        from experiments.training.system import make_model, make_training_vec_env

        sut_model = make_model(make_training_vec_env("FlowTest-Maze2-v0", 0, {**DEFAULTS, "n_envs": 1}), DEFAULTS, 0)
        from agents.testers import PPOTester

        PPOTester(sut_model, "sut", raw_env(problem="maze2"))


def test_evaluate_compares_testers(learned: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    code = main(
        [
            "evaluate",
            "--env",
            "FlowTest-Maze2-v0",
            "FlowTest-SmallReactive-v0",
            "--tester",
            "synthesized",
            f"ppo:{learned}",
            "--sut",
            "scripted:replanner",
            "scripted:committed",
            "--episodes",
            "2",
            "--out",
            str(out),
            "-q",
        ]
    )
    assert code == 0
    records = json.loads((out / "results.json").read_text())
    assert len(records) == 2 * 2 * 2
    assert {r["tester"] for r in records} == {"synthesized", f"ppo:{learned}"}
    for r in records:
        assert r["tester_fairness"] is not None
        assert r["trapped"] + r["sut_failures"] + r["test_failures"] == r["n_failures"]
        if r["tester"] == "synthesized":
            assert r["tester_fairness"]["fair"] and r["tester_fairness"]["guaranteed"]
            assert r["trapped"] == 0
        for f in r["failures"]:
            if r["tester"] != "synthesized":
                assert f"--tester ppo:{learned}" in f["replay"]
    report = (out / "report.md").read_text()
    assert "## Testers side by side" in report
    assert "Testers side by side" in (out / "report.html").read_text()


def test_train_tester_command_refuses_to_overwrite(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = tmp_path / "t.zip"
    model.write_text("mine")
    assert main(["train-tester", "maze2", "--steps", "1", "--out", str(model), "-q"]) == 2
    assert "exists" in capsys.readouterr().err
    assert model.read_text() == "mine"
    assert main(["train-tester", "no-such-problem", "--steps", "1", "--out", str(tmp_path / "x.zip"), "-q"]) == 2
