"""``flowtest benchmark --sut``: your own method as one system with N seeds (issue 41 item 4),
and the training runs as independent jobs, serial, in processes or on Ray (item 7).

Tiny pools and budgets keep these fast; the acceptance run with a CleanRL-style loop is in
tests/docs/test_recipes.py.
"""

from __future__ import annotations

import importlib
import json
import shlex
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from experiments import benchmark as bench
from experiments.benchmark.systems import SystemSpec, parse_systems
from experiments.cli.cli import main
from synthesis.model.errors import ProblemError

pytest.importorskip("torch")

POOL = "safety2/4x4"
"""Tests that build in a fraction of a second, which a random walk fails (``G !p2``)."""

SMALL = ["--pool", POOL, "--train-count", "3", "--test-count", "4", "--validation-count", "2", "--bootstrap", "50"]


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return code, out, err


def _system(doc: dict[str, Any], name: str) -> dict[str, Any]:
    return next(e for e in doc["systems"] if e["name"] == name)


def _native_checkpoints(folder: Path, seeds: list[int]) -> list[Path]:
    """Tiny native models trained on the pool's train tests (a few hundred steps each)."""
    from experiments.training.system import train_native

    paths = []
    for seed in seeds:
        path = folder / f"seed{seed}.zip"
        train_native(
            "FlowTest-RandomGrid-v0",
            128,
            path,
            seed,
            progress_bar=False,
            eval_episodes=0,
            env_kwargs={"pool": POOL, "split": "train", "count": 3},
            eval_every=0,
            n_envs=8,
            n_steps=8,
            batch_size=64,
            net_arch=[16],
            device="cpu",
        )
        paths.append(path)
    return paths


def test_sut_patterns_and_names_make_systems_with_a_seed_per_member(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A glob is one system with one member per matching file, sorted; ``python:M:F@GLOB``
    calls the loader with each file; ``NAME=`` repeated adds members; a plain entry is one
    run without a seed; the recorded command gives the entries back word for word."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "runs").mkdir()
    for name in ("b.zip", "a.zip", "c.pt", "a.pt"):
        (tmp_path / "runs" / name).write_bytes(b"")
    specs = parse_systems(
        ["ppo:runs/*.zip", "mine=python:pkg.mod:load@runs/*.pt", "mine=python:pkg.mod:load('x y.pt', n=2)", "gr1", "gr1"], reserved=["random"]
    )
    assert specs == [
        SystemSpec("ppo:runs/*.zip", "system", ("ppo:runs/a.zip", "ppo:runs/b.zip"), True),
        SystemSpec("mine", "system", ("python:pkg.mod:load('runs/a.pt')", "python:pkg.mod:load('runs/c.pt')", "python:pkg.mod:load('x y.pt', n=2)"), True),
        SystemSpec("gr1", "system", ("gr1",), False),
    ]
    assert specs[0].seeds == [0, 1] and specs[2].seeds == [None]
    with pytest.raises(ProblemError, match="matches no file"):
        parse_systems(["ppo:nothing/*.zip"], reserved=[])
    with pytest.raises(ProblemError, match="names a system the benchmark scores already"):
        parse_systems(["random=scripted:greedy"], reserved=["random"])
    suts = ("scripted:replanner", "mine=ppo:runs/*.zip", 'python:m:load("it\'s here.pt")')
    command = bench.command_of(bench.BenchmarkConfig(POOL, suts=suts))
    words = shlex.split(command)  # what a shell gives the rerun: the entries as they were, never globbed
    assert words[words.index("--sut") + 1 : words.index("--out")] == list(suts)


def test_a_glob_of_checkpoints_is_one_system_scored_per_seed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``NAME=ppo:runs/*.zip``: one system, one run per file with seeds 0..N-1, each run the
    same numbers as that file scored alone; the normalized score and the met share are
    summarized over those seeds (a seed-and-test interval, a t-interval), as a baseline's."""
    a, b = _native_checkpoints(tmp_path, [0, 1])
    code, stdout, err = run(
        ["benchmark", *SMALL, "--sut", f"mine=ppo:{tmp_path}/seed*.zip", f"ppo:{a}", f"ppo:{b}", "--out", str(tmp_path / "b"), "--json", "-q"], capsys
    )
    assert code == 0, err
    doc = json.loads(stdout)
    mine = _system(doc, "mine")
    assert mine["kind"] == "system"
    assert [(r["seed"], r["sut"]) for r in mine["runs"]] == [(0, f"ppo:{a}"), (1, f"ppo:{b}")]
    for r, alone in zip(mine["runs"], (_system(doc, f"ppo:{a}"), _system(doc, f"ppo:{b}")), strict=True):
        assert alone["runs"][0]["seed"] is None
        for split in ("train", "validation", "test"):
            assert r[split]["greedy"] == alone["runs"][0][split]["greedy"]
        assert r["test"]["sampled"] == alone["runs"][0]["test"]["sampled"] and r["test"]["sampled"]["runs"] == 8
    for mode in ("greedy", "sampled"):
        summary = mine["test"][mode]
        assert summary["normalized"]["seeds"] == 2 and summary["normalized"]["tests"] == 4
        assert summary["met"]["values"] == [r["test"][mode]["met"] for r in mine["runs"]]
        assert summary["met"]["mean"] == pytest.approx(np.mean(summary["met"]["values"]))
        assert summary["met"]["ci95"] is not None  # an interval over the two seeds


def _policy_module(tmp_path: Path, name: str) -> None:
    """A module with a batched policy's loader that records the width of what it is shown."""
    (tmp_path / f"{name}.py").write_text(
        "import numpy as np\n\n"
        "WIDTHS = {}\n\n"
        "class Policy:\n"
        "    batched = True\n\n"
        "    def __init__(self, memory, label=''):\n"
        "        self.label = label or memory\n"
        "        if memory != 'default':\n"
        "            self.env_options = {'memory': memory}\n\n"
        "    def reset(self, num_runs, seed):\n"
        "        self.rng = np.random.default_rng(seed)\n\n"
        "    def act(self, observations, masks, deterministic):\n"
        "        WIDTHS.setdefault(self.label, set()).add(observations.shape[1])\n"
        "        if deterministic:\n"
        "            return np.argmax(masks, axis=1)\n"
        "        return np.argmax(np.where(masks, self.rng.random(masks.shape), -1.0), axis=1)\n\n"
        "def broken(path):\n"
        "    raise FileNotFoundError(path)\n\n"
        "broken.batched = True\n\n"
        "def not_a_policy():\n"
        "    return 42\n\n"
        "not_a_policy.batched = True\n"
    )


def test_a_python_policy_with_arguments_gets_its_env_options(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """``python:M:F(ARGS)``: the loader is called with the literal arguments (kept in the
    recorded command); one ``act`` gives the greedy and the sampled runs; a policy that
    declares ``env_options={"memory": "visited"}`` is shown the observations with the
    visited places, one that declares nothing the plain ones."""
    from flowtest_env.encoding import make_encoder
    from flowtest_env.game import TestGame
    from flowtest_env.pools import load_pool
    from flowtest_env.wrappers import position_slice

    _policy_module(tmp_path, "declares_options")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    suts = [
        "python:declares_options:Policy('visited')",
        "python:declares_options:Policy(memory='default', label='plain')",
        "both=python:declares_options:Policy('none', label='a')",
        "both=python:declares_options:Policy('none', label='b')",
    ]
    code, stdout, err = run(["benchmark", *SMALL, "--sut", *suts, "--out", str(tmp_path / "b"), "--json", "-q"], capsys)
    assert code == 0, err
    doc = json.loads(stdout)
    words = shlex.split(doc["command"])
    assert words[words.index("--sut") + 1 : words.index("--sut") + 1 + len(suts)] == suts  # kept for the rerun
    assert words[words.index("--sut") + 1 + len(suts)].startswith("--")
    enc = make_encoder(TestGame(load_pool(POOL, "train", 1)[0]), "flat")
    plain, memory = int(enc.space.shape[0]), position_slice(enc).stop - position_slice(enc).start
    widths = importlib.import_module("declares_options").WIDTHS
    assert widths == {"visited": {plain + memory}, "plain": {plain}, "a": {plain}, "b": {plain}}
    both = _system(doc, "both")
    assert [r["seed"] for r in both["runs"]] == [0, 1] and both["test"]["sampled"]["normalized"]["seeds"] == 2
    visited = _system(doc, suts[0])
    assert visited["runs"][0]["test"]["sampled"]["runs"] == 8 and visited["runs"][0]["test"]["greedy"]["runs"] == 1
    sys.modules.pop("declares_options", None)


@pytest.mark.parametrize(
    "sut, says",
    [
        ("mine=ppo:nothing/*.zip", "matches no file"),
        ("gr1=scripted:greedy", "names a system the benchmark scores already"),
        ("python:bad_loaders:broken('gone.pt')", "its loader raised FileNotFoundError: gone.pt"),
        ("python:bad_loaders:not_a_policy", "returned a int, not a batched policy"),
        ("python:bad_loaders:broken(open('x'))", "must be Python literals"),
    ],
)
def test_bad_systems_are_one_error_line_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, sut: str, says: str
) -> None:
    _policy_module(tmp_path, "bad_loaders")
    monkeypatch.chdir(tmp_path)
    code, stdout, err = run(["benchmark", *SMALL, "--sut", sut, "--out", str(tmp_path / "b")], capsys)
    assert code == 2 and stdout == ""
    assert err.count("\n") == 1 and err.startswith("error: ") and says in err, err
    assert not (tmp_path / "b").exists()
    sys.modules.pop("bad_loaders", None)


def test_a_planner_takes_literal_arguments(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``python:M:Factory(ARGS)`` for a single-env planner: the factory gets exactly the
    arguments (in the planner's own process), not the test's description."""
    import gymnasium as gym

    import flowtest_env  # noqa: F401
    from agents.registry import make_policy

    (tmp_path / "planner_args.py").write_text(
        "class Nth:\n"
        "    def __init__(self, n, *, last=False):\n"
        "        self.n, self.last = n, last\n\n"
        "    def act(self, observation, mask):\n"
        "        allowed = observation['allowed']\n"
        "        return allowed[-1] if self.last else allowed[min(self.n, len(allowed) - 1)]\n"
    )
    monkeypatch.chdir(tmp_path)
    env = gym.make("FlowTest-SmallReactive-v0")
    obs, info = env.reset(seed=0)
    allowed = [i for i, ok in enumerate(info["action_mask"]) if ok]
    for spec, want in (("python:planner_args:Nth(0)", allowed[0]), ("python:planner_args:Nth(0, last=True)", allowed[-1])):
        policy = make_policy(spec, env)
        policy.reset(0)
        assert policy.name == spec and policy.act(obs, info) == want
        policy.close()


def _tables(tmp_path: Path, capsys: pytest.CaptureFixture[str], parallel: str, workers: str = "2") -> dict[str, Any]:
    code, stdout, err = run(
        [
            "benchmark",
            *SMALL,
            "--sut",
            "ppo",
            "--steps",
            "512",
            "--seeds",
            "0",
            "1",
            "--curve-points",
            "1",
            "--curve-sizes",
            "2",
            "--curve-seeds",
            "1",
            "--parallel",
            parallel,
            "--workers",
            workers,
            "--out",
            str(tmp_path / parallel),
            "--json",
            "-q",
        ],
        capsys,
    )
    assert code == 0, err
    doc = json.loads(stdout)
    for e in doc["systems"]:  # what may differ: where the models were written, how long they took
        for r in e["runs"]:
            r.pop("sut")
        for t in e.get("training", []):
            t.pop("seconds"), t.pop("curve_seconds"), t.pop("model")
    return doc


def _same_tables(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert a["systems"] == b["systems"]
    assert a["generalization"] == b["generalization"]
    assert a["budget"] == b["budget"]


def test_training_runs_in_processes_give_the_serial_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The runs of a benchmark (seeds x baselines x curve sizes) are independent jobs: two
    worker processes give the same table as one run after another."""
    serial, processes = _tables(tmp_path, capsys, "serial"), _tables(tmp_path, capsys, "processes")
    _same_tables(serial, processes)
    assert [r["seed"] for r in _system(serial, "maskable-ppo")["runs"]] == [0, 1]
    assert len(list((tmp_path / "processes" / "models").glob("*.zip"))) == 3


@pytest.mark.slow  # a local Ray starts in 10-20 s here
def test_training_runs_on_ray_give_the_serial_table(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("ray")
    _same_tables(_tables(tmp_path, capsys, "serial"), _tables(tmp_path, capsys, "ray"))


def test_parallel_is_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run(["benchmark", *SMALL, "--parallel", "threads", "--out", str(tmp_path / "b")], capsys)
    assert code == 2 and "invalid choice: 'threads'" in err
    with pytest.raises(ProblemError, match="unknown --parallel"):
        bench.check_config(bench.BenchmarkConfig(POOL, suts=("ppo",), parallel="threads"))
