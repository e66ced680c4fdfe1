"""The library recipes of docs/recipes.md (docs/recipes/*.py), each run for a few hundred
steps, so a release of a library that breaks one is seen. RLlib needs gymnasium 1.2.2 and
runs in a venv of its own (slow, skipped where that venv cannot be built)."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
RECIPES = ROOT / "docs" / "recipes"

pytestmark = [
    pytest.mark.filterwarnings("ignore::DeprecationWarning"),
    pytest.mark.filterwarnings("ignore::FutureWarning"),
    pytest.mark.filterwarnings("ignore::UserWarning"),
]


def _recipe(name: str, *needs: str) -> ModuleType:
    for library in needs:
        pytest.importorskip(library)
    spec = importlib.util.spec_from_file_location(f"recipe_{name}", RECIPES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # as an import does: a dataclass of the recipe looks its module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(autouse=True)
def _one_torch_thread() -> Any:
    """The recipes' nets are tiny: one thread beats several on a shared machine."""
    torch = pytest.importorskip("torch")
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.mark.parametrize("mode", ["SAME_STEP", "DISABLED"])
def test_torchrl_vector_env_recipe(mode: str) -> None:
    """TorchRL's plain GymWrapper takes the vector env (numeric_infos=True, no FlowTest
    adapter) in SAME_STEP and DISABLED mode; PPO trains through many episode ends, never
    taking an action the mask forbids."""
    r = _recipe("torchrl_vector", "torchrl", "tensordict")
    stats = r.main(mode=mode, num_envs=8, steps=512, frames_per_batch=256)
    assert stats["steps"] >= 512
    assert stats["episodes"] >= 5
    assert stats["illegal_actions"] == 0


@pytest.mark.parametrize("api", ["parallel", "aec"])
def test_torchrl_pettingzoo_recipe(api: str) -> None:
    """PettingZooWrapper runs the parallel and AEC games through several episode ends
    (numeric infos), the synthesized tester holding tester_0: every met run realizes the
    test objective (small-reactive's guarantee)."""
    r = _recipe("torchrl_pettingzoo", "torchrl", "tensordict")
    stats = r.main(api=api, steps=256, frames_per_batch=128)
    assert stats["steps"] >= 256
    assert stats["episodes"] >= 3
    assert stats["met"] >= 1
    assert stats["test_objective_realized"] == stats["met"]


@pytest.mark.slow  # importing tianshou alone takes 10-20 s here (numba)
def test_tianshou_aec_recipe() -> None:
    """Tianshou's multi-agent DQN over PettingZooEnv (same_spaces: one padded space), the
    synthesized tester a fixed algorithm, through several episode ends."""
    r = _recipe("tianshou_aec", "tianshou")
    stats = r.main(steps=256, num_envs=4, max_cycles=12)
    assert stats["steps"] >= 256
    assert stats["episodes"] >= 1
    assert stats["updates"] >= 4


def test_sb3_recipe() -> None:
    r = _recipe("sb3_maskable_ppo", "stable_baselines3", "sb3_contrib")
    stats = r.main(num_envs=8, steps=512)
    assert stats["steps"] >= 512
    assert stats["episodes"] >= 5 and stats["met"] >= 1


def test_cleanrl_recipe() -> None:
    r = _recipe("cleanrl_ppo")
    stats = r.main(num_envs=8, steps=512)
    assert stats["steps"] >= 512
    assert stats["episodes"] >= 5 and stats["met"] >= 1


POOL = "safety2/4x4"
"""A pool whose tests build in a fraction of a second (tests/experiments/test_benchmark.py's)."""


def test_recipes_save_models_the_benchmark_scores_with_their_seeds(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 41's acceptance: a policy trained by an outside loop (the CleanRL-style recipe, 3
    seeds) is scored by ``flowtest benchmark`` as one system with 3 seeds and the seed
    interval, with no adapter written by the user; the SB3 and TorchRL recipes' saved models
    too (``--pool``, the memory env option kept in the file and given back by the scorer)."""
    from experiments.cli.cli import main

    pytest.importorskip("torchrl")
    pytest.importorskip("sb3_contrib")
    cleanrl, sb3, torchrl = _recipe("cleanrl_ppo"), _recipe("sb3_maskable_ppo"), _recipe("torchrl_vector")
    runs = tmp_path / "runs"
    for seed in (0, 1, 2):
        stats = cleanrl.main(pool=POOL, count=3, num_envs=8, num_steps=16, steps=256, seed=seed, save_model=str(runs / f"cleanrl-seed{seed}.pt"))
        assert stats["steps"] >= 256
    for seed in (0, 1):
        sb3.main(num_envs=8, steps=256, seed=seed, pool=POOL, count=3, save=str(runs / f"sb3-seed{seed}.zip"))
        torchrl.main(num_envs=8, steps=256, frames_per_batch=128, seed=seed, pool=POOL, count=3, save=str(runs / f"torchrl-seed{seed}.pt"))
    saved = torch_load(runs / "cleanrl-seed0.pt")
    assert saved["env_options"] == {"memory": "visited"}  # the observation's options travel with the model
    capsys.readouterr()  # what the libraries printed while training
    code = main(
        [
            "benchmark",
            "--pool",
            POOL,
            "--train-count",
            "3",
            "--test-count",
            "4",
            "--validation-count",
            "2",
            "--bootstrap",
            "100",
            "--trust-model",
            "--sut",
            f"cleanrl=python:{RECIPES / 'cleanrl_ppo.py'}:load@{runs}/cleanrl-seed*.pt",
            f"sb3=ppo:{runs}/sb3-seed*.zip",
            f"torchrl=python:{RECIPES / 'torchrl_vector.py'}:load@{runs}/torchrl-seed*.pt",
            "--out",
            str(tmp_path / "bench"),
            "--json",
            "-q",
        ]
    )
    out, err = capsys.readouterr()
    assert code == 0, err
    doc = json.loads(out)
    systems = {e["name"]: e for e in doc["systems"]}
    for name, seeds in (("cleanrl", 3), ("sb3", 2), ("torchrl", 2)):
        e = systems[name]
        assert e["kind"] == "system" and [r["seed"] for r in e["runs"]] == list(range(seeds))
        for mode, runs_per_test in (("greedy", 1), ("sampled", 8)):
            summary = e["test"][mode]
            assert summary["runs_per_test"] == runs_per_test
            n = summary["normalized"]
            assert (n["seeds"], n["tests"]) == (seeds, 4)  # the seed-and-test interval of the protocol
            assert n["low"] <= n["point"] <= n["high"]
            assert len(summary["met"]["values"]) == seeds and summary["met"]["ci95"] is not None
    first = systems["cleanrl"]["runs"][0]["sut"]
    assert first == f"python:{RECIPES / 'cleanrl_ppo.py'}:load({str(runs / 'cleanrl-seed0.pt')!r})"


def torch_load(path: Path) -> Any:
    import torch

    return torch.load(path, weights_only=True)


def _rllib_python(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Python with RLlib 2.60 and FlowTest: $FLOWTEST_RLLIB_VENV if set, else a venv
    built from requirements/rllib.txt (skips if it cannot be built, e.g. offline)."""
    given = os.environ.get("FLOWTEST_RLLIB_VENV")
    venv = Path(given) if given else tmp_path_factory.mktemp("rllib") / "venv"
    python = venv / "bin" / "python"
    if not python.exists():
        steps = [
            [sys.executable, "-m", "venv", str(venv)],
            [str(python), "-m", "pip", "install", "-q", "torch==2.13.0"],
            [str(python), "-m", "pip", "install", "-q", "-r", str(ROOT / "requirements" / "rllib.txt")],
            [str(python), "-m", "pip", "install", "-q", "--no-deps", "-e", str(ROOT)],
        ]
        for cmd in steps:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=1800)
            if r.returncode != 0:
                pytest.skip(f"cannot build the RLlib venv ({' '.join(cmd[2:5])}): {r.stderr.strip().splitlines()[-1:]}")
    return python


@pytest.mark.slow
def test_rllib_recipe_in_its_own_venv(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The RLlib recipe in a venv with gymnasium 1.2.2: PPO trains system_0 through
    several episode ends, the synthesized tester a fixed RLModule."""
    python = _rllib_python(tmp_path_factory)
    code = "import json, sys; sys.path.insert(0, 'docs/recipes'); import rllib_recipe as r; print('RESULT', json.dumps(r.main(steps=256)))"
    run = subprocess.run([str(python), "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    line = [ln for ln in run.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    stats = json.loads(line[len("RESULT ") :])
    assert stats["steps"] >= 256
    assert stats["episodes"] >= 3
