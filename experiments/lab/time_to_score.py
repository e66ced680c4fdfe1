"""Time to a score: how long each trainer takes to fit a standard pool's train tests and to
reach its held-out plateau, side by side in one run, on one machine.

    python -m experiments.lab.time_to_score --seeds 0 1 2 --out tts.json

Trainers, each with its own defaults, on the same pool (``--pool``, default
``reachability1/5x5-v2``):

* ``native``: :mod:`agents.native_ppo` with ``flowtest train``'s native settings
  (:func:`experiments.training.settings.native_settings`; ``--native-set KEY=VALUE`` changes
  one, e.g. ``--native-set n_epochs=4``);
* ``sb3``: sb3-contrib's MaskablePPO with ``flowtest train --trainer sb3``'s settings
  (:data:`experiments.training.settings.DEFAULTS`: 8 single envs x 128 steps, minibatches of
  256, 10 epochs, MLP 64 x 64, shaping 10), through :mod:`experiments.training.system`;
* ``cleanrl``: the CleanRL-style recipe (``--cleanrl-recipe``, default
  ``docs/recipes/cleanrl_ppo.py``: its ``Args`` and ``train``, a model saved with
  ``save_model``) with its own defaults. It has no hook for evaluations during a run, so it
  trains once per budget (``--cleanrl-budgets``), each run from scratch, and each budget's
  saved model is one point of its curve (a user who picks that budget gets that model).
  A recipe without ``Args``/``train``/``save_model`` is skipped, saying so.

Two phases, each over ``--seeds``, the trainers interleaved (seed 0 of each, then seed 1,
...) so that the machine's load falls on every side alike:

* **fit** (a): training on the first ``--fit-count`` (128) train tests until the greedy
  policy meets ``--target`` (95 %) of them (evaluated every ``--fit-every`` steps), or the
  trainer's ``--fit-budget``;
* **held-out** (b): training on the first ``--train-count`` (4,096, the protocol's) train
  tests for the trainer's ``--budget``, the greedy held-out met on the first
  ``--test-count`` (1,000) tests of the ``test`` split every ``--eval-every`` steps. Its
  normalized score is ``(met - floor) / (ceiling - floor)`` with the random floor measured
  here (8 runs a test) and the reference ceiling ``--ceiling`` (1.0 on the continuity pool:
  docs/pools.md). A run's **plateau** is the mean of its last ``--plateau-points``
  evaluations, its interval the 95 % binomial interval over the tests; the time to the
  plateau is the first evaluation inside it. The common target is sb3's plateau (the lower
  end of its interval, over its seeds): the time each trainer takes to reach it.

Times are **training seconds** (wall clock, the trainer's setup and every evaluation
excluded; the setup is reported beside), with CPU seconds of the process beside them (less
sensitive to the other jobs on a shared machine), and steps per second. The output JSON holds
every curve, the command, the machine (``lscpu``'s model name) and the load before and after.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from experiments.benchmark.statistics import binomial_half_width, still_rising

POOL_ENV_ID = "FlowTest-RandomGrid-v0"
TRAINERS = ("native", "sb3", "cleanrl")
Act = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""A greedy batched policy on observations with its memory: ``(x, masks, starts) -> actions``."""


@dataclass
class Point:
    """One evaluation: training seconds and CPU seconds so far, env steps, greedy met per split."""

    seconds: float
    cpu: float
    steps: int
    met: dict[str, float]


@dataclass
class Run:
    """One trainer, one seed, one phase: its curve, setup seconds and steps per second."""

    trainer: str
    seed: int
    phase: str
    points: list[Point] = field(default_factory=list)
    setup: float = 0.0
    steps_per_second: float = 0.0
    settings: dict[str, Any] = field(default_factory=dict)


def load_now() -> list[float]:
    return [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else []


def machine() -> dict[str, Any]:
    """The CPU model (``lscpu``), cores, Python and library versions."""
    model = platform.processor()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        model = next((line.split(":", 1)[1].strip() for line in out.splitlines() if line.startswith("Model name")), model)
    except (OSError, subprocess.SubprocessError):
        pass
    import torch

    return {
        "cpu_model": model,
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "platform": platform.platform(),
    }


# ---------------------------------------------------------------- evaluation


@dataclass
class Splits:
    """The tests a phase evaluates on (games) and the memory layout they share."""

    games: dict[str, list[Any]]
    where: slice

    def met(self, act: Act, memory: str) -> dict[str, float]:
        """Greedy met of ``act`` on every split (each test once, to its own budget)."""
        from agents.native.evaluation import batch_verdicts
        from flowtest_env.envs import default_max_steps

        out = {}
        for name, games in self.games.items():
            v = batch_verdicts(
                act, games, [default_max_steps(g) for g in games], self.where if memory != "none" else None, memory=memory if memory != "none" else "visited"
            )
            out[name] = float(np.mean(v["system_objective"] == "met"))
        return out


def splits_for(pool: str, names: dict[str, tuple[str, int]]) -> Splits:
    from flowtest_env.encoding import make_encoder
    from flowtest_env.game import TestGame
    from flowtest_env.pools import load_pool
    from flowtest_env.wrappers import shared_position_slice

    games = {name: [TestGame(a) for a in load_pool(pool, split, count)] for name, (split, count) in names.items()}
    every = [g for gs in games.values() for g in gs]
    return Splits(games, shared_position_slice([make_encoder(g, "flat") for g in every]))


def random_floor(pool: str, count: int) -> float:
    """The protocol's floor: a uniform random legal policy's met on the held-out tests, 8 runs a test."""
    from flowtest_env.scoring import random_policy, score_policy

    return float(score_policy(random_policy(), pool=pool, split="test", count=count, runs=8, seed=0).met)


# ---------------------------------------------------------------- the trainers


def run_native(
    seed: int,
    phase: str,
    pool_options: dict[str, Any],
    splits: Splits,
    every: int,
    budget: int,
    until: Callable[[dict[str, float]], bool],
    overrides: dict[str, Any],
) -> Run:
    """The native trainer with ``flowtest train``'s settings (and ``overrides``)."""
    from agents.native_ppo import train
    from experiments.training.settings import native_args, native_settings

    settings = native_settings(overrides)
    args = native_args(settings, POOL_ENV_ID, pool_options, budget, seed, eval_every=every)
    held = [g for name, gs in splits.games.items() if name != "train" for g in gs]
    cpu0, wall0 = time.process_time(), time.perf_counter()
    cpu_at: list[float] = []

    def stop(step: int, rates: dict[str, dict[str, float]]) -> bool:
        cpu_at.append(time.process_time())
        return until({k: v["met"] for k, v in rates.items()})

    result = train(args, heldout=held, progress_bar=False, until=stop, evaluate_train=phase == "fit")
    wall = time.perf_counter() - wall0
    if len(cpu_at) < len(result.evaluations):  # the final evaluation (no until call): the CPU seconds at the end
        cpu_at.append(time.process_time())
    setup = wall - result.seconds - result.eval_seconds
    run = Run("native", seed, phase, setup=round(setup, 2), steps_per_second=round(result.steps_per_second, 1), settings=settings)
    names = {"train": "train", "heldout": next((n for n in splits.games if n != "train"), "heldout")}
    for (step, rates), sec, cpu in zip(result.evaluations, result.eval_times, cpu_at, strict=False):
        run.points.append(Point(round(sec, 2), round(cpu - cpu0, 2), step, {names[k]: v["met"] for k, v in rates.items()}))
    return run


def run_sb3(seed: int, phase: str, pool_options: dict[str, Any], splits: Splits, every: int, budget: int, until: Callable[[dict[str, float]], bool]) -> Run:
    """MaskablePPO with ``flowtest train --trainer sb3``'s settings; evaluated from a callback
    every ``every`` steps (its time excluded)."""
    from stable_baselines3.common.callbacks import BaseCallback

    from experiments.training.settings import DEFAULTS
    from experiments.training.system import make_model, make_training_vec_env

    settings = dict(DEFAULTS)
    t_setup = time.perf_counter()
    env = make_training_vec_env(POOL_ENV_ID, seed, settings, pool_options)
    model = make_model(env, settings, seed)
    setup = time.perf_counter() - t_setup
    run = Run("sb3", seed, phase, setup=round(setup, 2), settings=settings)

    def act(x: np.ndarray, masks: np.ndarray, starts: np.ndarray) -> np.ndarray:
        actions, _ = model.predict(x, deterministic=True, action_masks=masks)
        return np.asarray(actions)

    clock = {"start": 0.0, "cpu": 0.0, "eval": 0.0, "eval_cpu": 0.0, "next": 0}

    def evaluate(steps: int) -> bool:
        t, c = time.perf_counter(), time.process_time()
        met = splits.met(act, settings["memory"])
        run.points.append(Point(round(t - clock["start"] - clock["eval"], 2), round(c - clock["cpu"] - clock["eval_cpu"], 2), steps, met))
        clock["eval"] += time.perf_counter() - t
        clock["eval_cpu"] += time.process_time() - c
        return until(met)

    class Evaluate(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps < clock["next"]:
                return True
            while clock["next"] <= self.num_timesteps:
                clock["next"] += every
            return not evaluate(int(self.num_timesteps))

    clock["start"], clock["cpu"] = time.perf_counter(), time.process_time()
    if not evaluate(0):
        clock["next"] = every
        model.learn(total_timesteps=budget, callback=Evaluate())
        if run.points[-1].steps != model.num_timesteps:
            evaluate(int(model.num_timesteps))
    seconds = run.points[-1].seconds
    run.steps_per_second = round(run.points[-1].steps / seconds, 1) if seconds > 0 else 0.0
    env.close()
    return run


def cleanrl_recipe(path: Path) -> Any | None:
    """The recipe module at ``path`` if it has what this benchmark needs (``Args`` with
    ``save_model``, ``train``), else ``None``."""
    spec = importlib.util.spec_from_file_location("cleanrl_recipe", path)
    if spec is None or spec.loader is None:
        return None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    args = getattr(module, "Args", None)
    if args is None or not callable(getattr(module, "train", None)) or "save_model" not in getattr(args, "__dataclass_fields__", {}):
        return None
    return module


def cleanrl_actor(saved: dict[str, Any]) -> Callable[[Any], Any]:
    """The recipe's saved actor (``actor.<i>.weight``/``bias`` linear layers with tanh between
    them) as a function of a float tensor batch."""
    import torch

    state = saved["agent"]
    layers = sorted({int(k.split(".")[1]) for k in state if k.startswith("actor.") and k.endswith(".weight")})

    def actor(x: Any) -> Any:
        for i, k in enumerate(layers):
            x = torch.nn.functional.linear(x, state[f"actor.{k}.weight"], state[f"actor.{k}.bias"])
            if i < len(layers) - 1:
                x = torch.tanh(x)
        return x

    return actor


def run_cleanrl(
    recipe: Any, seed: int, phase: str, pool: str, count: int, splits: Splits, budgets: Sequence[int], until: Callable[[dict[str, float]], bool]
) -> Run:
    """The recipe once per budget (smallest first), each from scratch; each saved model one point."""
    import torch

    run = Run("cleanrl", seed, phase)
    cpu_total = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for budget in budgets:
            path = Path(tmp) / f"b{budget}.pt"
            args = recipe.Args(pool=pool, count=count, seed=seed, total_timesteps=int(budget), save_model=str(path), threads=1)
            c = time.process_time()
            stats = recipe.train(args)
            cpu = time.process_time() - c
            run.settings = {k: v for k, v in asdict(args).items() if k not in ("save_model", "total_timesteps")}
            saved = torch.load(path, map_location="cpu", weights_only=True)
            actor = cleanrl_actor(saved)
            memory = str(saved.get("env_options", {}).get("memory", args.memory))

            def act(x: np.ndarray, masks: np.ndarray, starts: np.ndarray, actor: Callable[[Any], Any] = actor) -> np.ndarray:
                with torch.no_grad():
                    logits = actor(torch.as_tensor(x, dtype=torch.float32)).masked_fill(~torch.as_tensor(masks, dtype=torch.bool), -torch.inf)
                out: np.ndarray = torch.argmax(logits, dim=-1).numpy()
                return out

            met = splits.met(act, memory)
            cpu_total = cpu  # each budget is its own run: its own time
            run.points.append(Point(round(float(stats["seconds"]), 2), round(cpu_total, 2), int(stats["steps"]), met))
            run.steps_per_second = round(float(stats["steps_per_s"]), 1)
            if until(met):
                break
    return run


# ---------------------------------------------------------------- the figures


def first_time(run: Run, split: str, level: float) -> Point | None:
    """The first evaluation of ``run`` whose ``split`` met is at least ``level``."""
    return next((p for p in run.points if p.met.get(split, -1.0) >= level - 1e-12), None)


INDEPENDENT_BUDGETS = ("cleanrl",)
"""Trainers whose curve points are separate runs, one per budget (not one run's
evaluations): their plateau is their largest budget's score alone."""


def plateau(run: Run, split: str, points: int, n_tests: int) -> dict[str, float]:
    """The mean of the last ``points`` evaluations (a trainer of :data:`INDEPENDENT_BUDGETS`:
    the last point alone, its largest budget's model) and its 95 % interval over ``n_tests``
    tests; ``rising`` (1.0 or 0.0): the last evaluation is above the one before by more than
    that half-width, so the run had not levelled off."""
    used = 1 if run.trainer in INDEPENDENT_BUDGETS else points
    mets = [p.met[split] for p in run.points]
    mean = float(np.mean(mets[-used:]))
    half = binomial_half_width(mean, n_tests)
    return {"met": mean, "low": mean - half, "high": mean + half, "rising": float(still_rising(mets, n_tests))}


def summarize(runs: list[Run], target: float, held: str, n_held: int, points: int, floor: float, ceiling: float) -> dict[str, Any]:
    """Per trainer: times to the fit target; plateaus, times to them and to sb3's plateau."""
    out: dict[str, Any] = {"fit": {}, "heldout": {}}
    for trainer in TRAINERS:
        fit = [r for r in runs if r.trainer == trainer and r.phase == "fit"]
        if fit:
            hits = [first_time(r, "train", target) for r in fit]
            out["fit"][trainer] = {
                "seconds": [h.seconds if h else None for h in hits],
                "cpu": [h.cpu if h else None for h in hits],
                "steps": [h.steps if h else None for h in hits],
                "steps_per_second": [r.steps_per_second for r in fit],
                "setup": [r.setup for r in fit],
                "seeds": [r.seed for r in fit],
            }
    held_runs = {t: [r for r in runs if r.trainer == t and r.phase == "heldout"] for t in TRAINERS}
    plateaus = {t: [plateau(r, held, points, n_held) for r in rs] for t, rs in held_runs.items() if rs}
    ref = plateaus.get("sb3")
    common = float(np.mean([p["low"] for p in ref])) if ref else None
    for trainer, rs in held_runs.items():
        if not rs:
            continue
        ps = plateaus[trainer]
        own = [next((p for p in r.points if p.met[held] >= pl["low"] - 1e-12), None) for r, pl in zip(rs, ps, strict=True)]
        to_common = [first_time(r, held, common) if common is not None else None for r in rs]
        out["heldout"][trainer] = {
            "plateau_met": [round(p["met"], 4) for p in ps],
            "still_rising": [bool(p["rising"]) for p in ps],
            "plateau_normalized": [round((p["met"] - floor) / (ceiling - floor), 4) for p in ps],
            "seconds_to_plateau": [h.seconds if h else None for h in own],
            "cpu_to_plateau": [h.cpu if h else None for h in own],
            "steps_to_plateau": [h.steps if h else None for h in own],
            "seconds_to_sb3_plateau": [h.seconds if h else None for h in to_common],
            "steps_to_sb3_plateau": [h.steps if h else None for h in to_common],
            "steps_per_second": [r.steps_per_second for r in rs],
            "seeds": [r.seed for r in rs],
        }
    out["heldout_target"] = {"sb3_plateau_low_met": common, "floor": floor, "ceiling": ceiling}
    return out


def _median(xs: Sequence[float | None]) -> str:
    vals = [x for x in xs if x is not None]
    if not vals:
        return "not reached"
    missed = len(xs) - len(vals)
    return f"{float(np.median(vals)):.1f}" + (f" ({missed} of {len(xs)} not reached)" if missed else "")


def print_table(summary: dict[str, Any]) -> None:
    """The headline times, medians over seeds."""
    print("fit: training seconds to 95 % greedy met on the train tests (median over seeds; CPU s; steps/s)")
    for t, s in summary["fit"].items():
        print(f"  {t:8s} {_median(s['seconds']):>24s} s   cpu {_median(s['cpu']):>10s}   {_median(s['steps_per_second'])} steps/s")
    print("held-out: seconds to the own plateau, to sb3's plateau; plateau met (normalized)")
    for t, s in summary["heldout"].items():
        print(
            f"  {t:8s} {_median(s['seconds_to_plateau']):>12s} s  {_median(s['seconds_to_sb3_plateau']):>12s} s   "
            f"met {[round(100 * x, 1) for x in s['plateau_met']]} norm {s['plateau_normalized']}"
            + (f", still rising in {sum(s['still_rising'])} of {len(s['still_rising'])}" if any(s.get("still_rising", [])) else "")
        )


# ---------------------------------------------------------------- the command


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pool", default="reachability1/5x5-v2")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--trainers", nargs="+", choices=TRAINERS, default=list(TRAINERS))
    ap.add_argument("--phases", nargs="+", choices=("fit", "heldout"), default=["fit", "heldout"])
    ap.add_argument("--target", type=float, default=0.95, help="greedy met on the fit tests (default 0.95)")
    ap.add_argument("--fit-count", type=int, default=128)
    ap.add_argument("--fit-every", type=int, default=16_384)
    ap.add_argument("--fit-budget", type=int, nargs=2, metavar=("NATIVE", "SB3"), default=[1_500_000, 1_000_000])
    ap.add_argument("--train-count", type=int, default=4096)
    ap.add_argument("--test-count", type=int, default=1000)
    ap.add_argument("--eval-every", type=int, default=65_536)
    ap.add_argument("--budget", type=int, nargs=2, metavar=("NATIVE", "SB3"), default=[1_500_000, 500_000])
    ap.add_argument("--plateau-points", type=int, default=3)
    ap.add_argument("--ceiling", type=float, default=1.0)
    ap.add_argument("--cleanrl-recipe", type=Path, default=Path(__file__).resolve().parents[2] / "docs" / "recipes" / "cleanrl_ppo.py")
    ap.add_argument("--cleanrl-fit-budgets", type=int, nargs="+", default=[65_536, 131_072, 262_144, 524_288, 1_048_576])
    ap.add_argument("--cleanrl-budgets", type=int, nargs="+", default=[131_072, 262_144, 524_288, 1_048_576])
    ap.add_argument(
        "--native-set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a native setting (flowtest train's names: n_epochs=4, net_arch=64,64, memory=counts)",
    )
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument(
        "--summarize", type=Path, default=None, metavar="JSON", help="recompute the summary of an earlier run's --out file (no training) and write it back"
    )
    return ap.parse_args(argv)


def resummarize(path: Path, a: argparse.Namespace) -> int:
    """Recompute ``path``'s summary from its stored curves (the same rules as a run)."""
    doc = json.loads(path.read_text())
    runs = [Run(**{**r, "points": [Point(**p) for p in r["points"]]}) for r in doc["runs"]]
    target = doc.get("summary", {}).get("heldout_target") or {}
    floor = float(target.get("floor", float("nan")))
    doc["summary"] = summarize(runs, a.target, "heldout", a.test_count, a.plateau_points, floor, float(target.get("ceiling", a.ceiling)))
    path.write_text(json.dumps(doc, indent=1) + "\n")
    print_table(doc["summary"])
    return 0


def native_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``KEY=VALUE`` settings as values (``64,64`` a list of ints, numbers as numbers)."""
    out: dict[str, Any] = {}
    for item in items:
        key, _, value = item.partition("=")
        v: Any = value
        if "," in value:
            v = [int(x) for x in value.split(",")]
        else:
            for kind in (int, float):
                try:
                    v = kind(value)
                    break
                except ValueError:
                    continue
        out[key] = v
    return out


def main(argv: Sequence[str] | None = None) -> int:
    a = parse(argv)
    if a.summarize is not None:
        return resummarize(a.summarize, a)
    import torch

    torch.set_num_threads(1)
    doc: dict[str, Any] = {
        "command": " ".join([sys.executable, "-m", "experiments.lab.time_to_score", *(argv or sys.argv[1:])]),
        "machine": machine(),
        "load_before": load_now(),
        "runs": [],
    }
    recipe = cleanrl_recipe(a.cleanrl_recipe) if "cleanrl" in a.trainers else None
    trainers = [t for t in a.trainers if t != "cleanrl" or recipe is not None]
    if "cleanrl" in a.trainers and recipe is None:
        doc["cleanrl_skipped"] = f"{a.cleanrl_recipe} has no Args with save_model and train(): no model to evaluate"
        print(f"cleanrl skipped: {doc['cleanrl_skipped']}", file=sys.stderr)
    overrides = native_overrides(a.native_set)
    runs: list[Run] = []
    t0 = time.perf_counter()
    held = "heldout"
    floor = float("nan")
    for phase in a.phases:
        if phase == "fit":
            count, names = a.fit_count, {"train": ("train", a.fit_count)}

            def until(met: dict[str, float]) -> bool:
                return bool(met["train"] >= a.target)

            budgets = {"native": a.fit_budget[0], "sb3": a.fit_budget[1]}
            every = a.fit_every
            cleanrl_budgets = a.cleanrl_fit_budgets
        else:
            count, names = a.train_count, {held: ("test", a.test_count)}

            def until(met: dict[str, float]) -> bool:
                return False

            budgets = {"native": a.budget[0], "sb3": a.budget[1]}
            every = a.eval_every
            cleanrl_budgets = a.cleanrl_budgets
            floor = random_floor(a.pool, a.test_count)
        splits = splits_for(a.pool, names)
        pool_options = {"pool": a.pool, "split": "train", "count": count}
        for seed in a.seeds:
            for trainer in trainers:
                t = time.perf_counter()
                if trainer == "native":
                    run = run_native(seed, phase, pool_options, splits, every, budgets["native"], until, overrides)
                elif trainer == "sb3":
                    run = run_sb3(seed, phase, pool_options, splits, every, budgets["sb3"], until)
                else:
                    run = run_cleanrl(recipe, seed, phase, a.pool, count, splits, cleanrl_budgets, until)
                runs.append(run)
                last = run.points[-1]
                print(
                    f"[{time.perf_counter() - t0:7.0f} s] {phase} {trainer} seed {seed}: {last.steps} steps in {last.seconds:.1f} s "
                    f"({run.steps_per_second:.0f} steps/s), met {last.met}; wall {time.perf_counter() - t:.0f} s, load {load_now()}",
                    file=sys.stderr,
                    flush=True,
                )
                doc["runs"] = [asdict(r) for r in runs]
                if a.out is not None:
                    a.out.write_text(json.dumps(doc, indent=1) + "\n")
    doc["load_after"] = load_now()
    doc["wall_seconds"] = round(time.perf_counter() - t0, 1)
    doc["summary"] = summarize(runs, a.target, held, a.test_count, a.plateau_points, floor, a.ceiling)
    if a.out is not None:
        a.out.write_text(json.dumps(doc, indent=1) + "\n")
    print_table(doc["summary"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
