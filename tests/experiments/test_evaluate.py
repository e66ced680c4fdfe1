"""``flowtest evaluate``: results, report, replay commands that reproduce failures."""

from __future__ import annotations

import io
import json
import shlex
from pathlib import Path

import gymnasium as gym
import pytest

from agents.registry import make_policy
from experiments.cli.cli import main
from experiments.evaluation import evaluate, replay, write_report
from experiments.evaluation.episodes import run_episode
from flowtest_env.fairness import can_still_meet_in_game as can_still_meet
from flowtest_env.game import TestGame

FAULTY_CASES = [
    ("scripted:committed", "FlowTest-SmallReactive-v0"),
    ("scripted:fuel-blind", "FlowTest-Refueling-v0"),
    ("scripted:greedy", "FlowTest-BeaverRescue-v0"),
]


def test_evaluate_writes_results_report_and_pictures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "evaluate",
            "--env",
            "FlowTest-SmallReactive-v0",
            "FlowTest-BeaverRescue-v0",
            "--sut",
            "scripted:replanner",
            "scripted:committed",
            "--episodes",
            "2",
            "--seed",
            "3",
            "--out",
            str(tmp_path),
            "-q",
        ]
    )
    assert code == 0
    records = json.loads((tmp_path / "results.json").read_text())
    assert len(records) == 4
    for r in records:
        for key in ("env", "sut", "episodes", "system_objective_met_rate", "test_objective_realized_rate", "failures"):
            assert key in r
        for pic in r["pictures"].values():
            assert (tmp_path / pic).stat().st_size > 5000
    good = [r for r in records if r["sut"] == "scripted:replanner"]
    assert all(r["system_objective_met_rate"] == 1.0 and r["test_objective_realized_rate"] == 1.0 for r in good)
    bad = [r for r in records if r["sut"] == "scripted:committed"]
    assert all(r["failures"] and r["failures"][0]["seed"] in (3, 4) for r in bad)
    md = (tmp_path / "report.md").read_text()
    assert "## scripted:committed" in md and "--replay" in md
    assert "<table>" in (tmp_path / "report.html").read_text()
    assert "report:" in capsys.readouterr().out


@pytest.mark.parametrize("sut,env_id", FAULTY_CASES)
def test_replay_command_reproduces_the_failure(sut: str, env_id: str, tmp_path: Path) -> None:
    cells = evaluate([env_id], [sut], 3, seed=11)
    records = write_report(cells, tmp_path)
    failures = records[0]["failures"]
    assert len(failures) == 3  # every run fails; runs after the first start from a used policy
    for failure in failures:
        args = shlex.split(failure["replay"])
        assert args[:2] == ["flowtest", "evaluate"] and "--replay" in args
        seed = int(args[args.index("--seed") + 1])
        trace = replay(args[args.index("--env") + 1], args[args.index("--sut") + 1], seed, io.StringIO())
        assert trace.verdict == failure["verdict"]
        assert trace.kind == failure["kind"] == "sut"
        original = next(t for t in cells[0].traces if t.seed == seed)
        assert trace.actions == original.actions
        assert [r.key() for r in trace.states] == [r.key() for r in original.states]


def _trapping_env(env_id: str, *, free: int) -> gym.Env:
    """``env_id`` whose test restricts every move out of every state but ``free`` in every
    history: a broken test that traps the SUT once it has left ``free``. Its game still
    judges runs by the correct test's table, so a trapped run stays ``open``."""
    env = gym.make(env_id)
    u = env.unwrapped
    game = TestGame(u.game.artifact, u.game.setting)  # a copy: the built-in game is shared
    stay = 1 << game.stay_action
    game.restricted_bits = [[0 if s == free else bits & ~stay for s, bits in enumerate(game.exists_bits)] for _ in game.restricted_bits]
    u.games = [game]
    return env


def test_trapped_run_that_ends_open_is_a_test_failure() -> None:
    env_id = "FlowTest-SmallReactive-v0"
    env = _trapping_env(env_id, free=int(gym.make(env_id).unwrapped.game.ts.initial))
    t = run_episode(env, make_policy("scripted:replanner", env), env_id, "scripted:replanner", 0)
    assert t.verdict["system_objective"] == "open" and t.verdict["steps"] == env.unwrapped.max_steps
    assert len({r.system for r in t.states}) == 2  # it left the start, then could not move
    assert t.kind == "test" and t.reason.startswith("trapped")
    assert not can_still_meet(env.unwrapped.game, env.unwrapped.run)


def test_open_run_with_a_way_left_is_the_suts_failure() -> None:
    env_id = "FlowTest-Maze2-v0"
    env = gym.make(env_id)
    t = run_episode(env, make_policy("scripted:committed", env), env_id, "scripted:committed", 0)
    assert t.verdict["system_objective"] == "open"
    assert can_still_meet(env.unwrapped.game, env.unwrapped.run)
    assert t.kind == "sut" and "within" in t.reason


def test_trapped_runs_are_reported_loudly(tmp_path: Path) -> None:
    from experiments.evaluation.runs import Cell

    env_id = "FlowTest-SmallReactive-v0"
    env = _trapping_env(env_id, free=int(gym.make(env_id).unwrapped.game.ts.initial))
    policy = make_policy("random", env)
    traces = [run_episode(env, policy, env_id, "random", seed) for seed in range(2)]
    records = write_report([Cell(env_id, "random", traces, 0, 0.0)], tmp_path)
    assert records[0]["test_failures"] == 2
    assert all(f["kind"] == "test" and f["reason"].startswith("trapped") for f in records[0]["failures"])
    assert "FLOWTEST BUG" in (tmp_path / "report.md").read_text()


def test_replay_through_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "scripted:committed", "--episodes", "1", "--seed", "0", "--replay"])
    out = capsys.readouterr().out
    assert code == 0 and "verdict:" in out and "step   0" in out


def test_test_failure_is_reported_loudly(tmp_path: Path) -> None:
    cells = evaluate(["FlowTest-SmallReactive-v0"], ["scripted:replanner"], 1)
    t = cells[0].traces[0]
    t.kind, t.reason = "test", "met the system objective without realizing the test objective"
    write_report(cells, tmp_path)
    assert "FLOWTEST BUG" in (tmp_path / "report.md").read_text()
    assert "FLOWTEST BUG" in (tmp_path / "report.html").read_text()


def test_unknown_env_is_invalid_input(tmp_path: Path) -> None:
    assert main(["evaluate", "--env", "FlowTest-Nope-v0", "--sut", "random", "--out", str(tmp_path), "-q"]) == 2


def test_an_inconsistent_problem_among_several_envs_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """With several ``--env``, the message of the one with no test says which it is."""
    behind = tmp_path / "behind.toml"
    behind.write_text(
        'name = "behind"\n[system]\ngrid = """\nS . X D\n"""\nstart = "S"\nterminal = ["D"]\n'
        '[labels]\ndock = ["D"]\nspill = ["X"]\n[objectives]\nsystem = "F dock & G !spill"\n'
        'test = "F dock"\n[environment]\nkind = "reactive"\n'
    )
    code = main(["evaluate", "--env", "small-reactive", str(behind), "--sut", "random", "--out", str(tmp_path / "r"), "-q"])
    err = capsys.readouterr().err
    assert code == 3 and err.startswith(f"error: --env {behind}: inconsistent problem (unreachable): the goal is "), err
    assert "Traceback" not in err


def test_unknown_sut_is_invalid_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["evaluate", "--env", "FlowTest-SmallReactive-v0", "--sut", "scripted:nope", "--out", str(tmp_path), "-q"])
    assert code == 2 and "error: --sut scripted:nope" in capsys.readouterr().err


def test_replay_command_quotes_a_model_path_with_spaces() -> None:
    from experiments.evaluation.runs import replay_command

    cmd = replay_command("FlowTest-Maze2-v0", "ppo:/tmp/my models/m.zip", 7)
    assert shlex.split(cmd)[4:6] == ["--sut", "ppo:/tmp/my models/m.zip"]


def test_demo_evaluation_includes_a_ppo_system(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("sb3_contrib")
    import experiments.demo as ev

    monkeypatch.setattr(ev, "DEMO_PPO_STEPS", 256)  # the demo trains 16384 steps; here only the plumbing
    report = ev.run_evaluation_demo(tmp_path, episodes=1)
    assert report.exists() and (tmp_path / "ppo-maze2.zip").exists()
    records = json.loads((tmp_path / "results.json").read_text())
    ppo = [r for r in records if r["sut"].startswith("ppo:")]
    assert len(ppo) == 1 and Path(ppo[0]["sut"][4:]).is_absolute()
    for r in records:
        assert r["test_failures"] == 0, r


@pytest.mark.slow
def test_demo_ppo_system_passes_maze2(tmp_path: Path) -> None:
    pytest.importorskip("sb3_contrib")
    from experiments.demo import run_evaluation_demo

    run_evaluation_demo(tmp_path, episodes=2)
    records = json.loads((tmp_path / "results.json").read_text())
    ppo = next(r for r in records if r["sut"].startswith("ppo:"))
    assert ppo["system_objective_met_rate"] == 1.0 and ppo["test_objective_realized_rate"] == 1.0


def test_replay_commands_carry_trust_model_for_trusted_model_zips() -> None:
    from experiments.evaluation.runs import replay_command

    trusted = replay_command("FlowTest-Maze2-v0", "ppo:m.zip", 7, trust_model=True)
    assert "--trust-model" in shlex.split(trusted)
    assert "--trust-model" not in replay_command("FlowTest-Maze2-v0", "ppo:m.zip", 7)
    assert "--trust-model" not in replay_command("FlowTest-Maze2-v0", "gr1", 7, trust_model=True)  # no model there


def test_evaluate_accepts_trust_model(tmp_path: Path) -> None:
    code = main(["evaluate", "--env", "small-reactive", "--sut", "gr1", "--episodes", "1", "--trust-model", "--replay"])
    from agents.checkpoint import trust_pickled_models

    trust_pickled_models(False)  # the flag sets it for the process; leave the next test as it found it
    assert code == 0


@pytest.fixture
def env_builds(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every construction of a single-agent env (:class:`flowtest_env.envs.FlowTestEnv`,
    whatever builds it: ``gymnasium.make``, :func:`flowtest_env.make_env`), by its class."""
    from flowtest_env.envs import FlowTestEnv

    built: list[str] = []
    init = FlowTestEnv.__init__

    def counting(self: FlowTestEnv, *args: object, **kwargs: object) -> None:
        built.append(type(self).__name__)
        init(self, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(FlowTestEnv, "__init__", counting)
    return built


def test_one_pair_of_one_episode_builds_its_test_once(tmp_path: Path, env_builds: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """``flowtest evaluate --env FlowTest-Maze2-v0 --sut scripted:replanner`` resolves its test
    once and hands it on: the SUT check, the run, the trace picture, the test's card and the
    report read that one env and its game (it was built five times). A failing system on the
    same test (its filmstrip and the broken conjunct drawn too) builds nothing more."""
    code = main(["evaluate", "--env", "FlowTest-Maze2-v0", "--sut", "scripted:replanner", "--episodes", "1", "--out", str(tmp_path / "one"), "-q"])
    assert code == 0, capsys.readouterr().err
    assert len(env_builds) == 1, env_builds
    env_builds.clear()
    code = main(["evaluate", "--env", "FlowTest-Maze2-v0", "--sut", "scripted:replanner", "random", "--episodes", "1", "--out", str(tmp_path / "two"), "-q"])
    records = json.loads((tmp_path / "two" / "results.json").read_text())
    assert code == 0 and [r["n_failures"] for r in records] == [0, 1]  # the failing pictures were drawn
    assert "filmstrip" in records[1]["pictures"]
    assert len(env_builds) == 1, env_builds


def test_the_python_api_builds_each_test_once(tmp_path: Path, env_builds: list[str]) -> None:
    """:func:`experiments.evaluation.evaluate` and :func:`~experiments.evaluation.write_report`
    on two tests and two systems: one env per test, whatever the systems, runs and pictures."""
    cells = evaluate(["small-reactive", "FlowTest-Maze2-v0"], ["scripted:replanner", "random"], episodes=2)
    write_report(cells, tmp_path)
    assert sorted(env_builds) == ["FlowTestEnv", "Maze2Env"], env_builds
