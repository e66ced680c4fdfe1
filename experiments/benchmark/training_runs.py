"""The benchmark's training runs (protocol step 2, docs/benchmark-protocol.md): each baseline
per seed (and per generalization-curve size) trained on the pool's train split, several at once
in their own processes, each with its greedy learning curve."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.checkpoint import mark_own_file
from experiments.outputs import write_atomically
from experiments.training.rl import learn
from experiments.training.settings import native_args
from experiments.training.system import make_model, make_training_vec_env

from .config import CURVE_TRAIN_TESTS, POOL_ENV_ID, BenchmarkConfig, baseline_settings
from .models import CurveRecorder, ModelBatchPolicy, model_where
from .pool import Split, games_and_budgets


@dataclass
class TrainedBaseline:
    """One trained model: algorithm, seed, training tests, where it is saved, its curve and
    time, and its batched policies (greedy and sampled)."""

    algo: str
    seed: int
    path: Path
    steps: int
    seconds: float
    curve_seconds: float
    curve: list[tuple[int, dict[str, float]]]
    train_tests: int = 0
    policies: dict[str, Any] = field(default_factory=dict)

    @property
    def sut(self) -> str:
        """The model as a system under test (``ppo:PATH``, what the replay commands use)."""
        return f"ppo:{self.path}"


def train_baseline(config: BenchmarkConfig, algo: str, seed: int, splits: dict[str, Split], out: Path,
                   progress_bar: bool = False, train_tests: int | None = None, name: str | None = None) -> TrainedBaseline:
    """Train one baseline on the first ``train_tests`` (default: all ``train_count``) tests
    of the train split (``config.steps`` time steps, rounded up to whole rollouts),
    recording its greedy learning curve on the first train tests (at most :data:`CURVE_TRAIN_TESTS`) and the validation tests;
    save it to ``out/models/<name or algo-seedN>.zip``."""
    count = int(train_tests or config.train_count)
    every = max(1, math.ceil(config.steps / config.curve_points))
    path = (out / "models" / f"{name or f'{algo}-seed{seed}'}.zip").resolve()
    if config.trainer == "native":
        return _train_native_baseline(config, algo, seed, splits, path, every, progress_bar, count)
    settings = baseline_settings(algo, "sb3")
    pool_options = {"pool": config.pool, "split": "train", "count": count}  # a standard pool: its shipped records
    env = make_training_vec_env(POOL_ENV_ID, seed, settings, pool_options)
    model = make_model(env, settings, seed)
    shown = {"train": games_and_budgets(splits["train"]), "validation": games_and_budgets(splits["validation"])}
    keep = min(count, CURVE_TRAIN_TESTS)
    shown["train"] = (shown["train"][0][:keep], shown["train"][1][:keep])
    recorder = CurveRecorder(every, settings["memory"], shown)
    seconds = learn(model, config.steps, recorder, progress_bar)
    write_atomically(path, lambda tmp: model.save(str(tmp)))
    mark_own_file(path)  # scored below without --trust-model: this run wrote it
    env.close()
    where = model_where(model, shown["train"][0], settings["memory"])
    policies = {"greedy": ModelBatchPolicy(model, where, True), "sampled": ModelBatchPolicy(model, where, False)}
    return TrainedBaseline(algo, seed, path, int(model.num_timesteps), seconds, recorder.seconds, recorder.points, count,
                           policies)


@dataclass(frozen=True)
class TrainingJob:
    """One training run of the benchmark: algorithm, seed, training tests, model name."""

    algo: str
    seed: int
    train_tests: int
    name: str


_JOB_STATE: dict[str, Any] = {}
"""What a forked training worker reads (the config, the splits, the folder), set before the fork."""


def _run_job(job: TrainingJob) -> TrainedBaseline:
    """A training worker: train one job and return it without its policies (the parent
    loads them from the saved checkpoint)."""
    b = train_baseline(_JOB_STATE["config"], job.algo, job.seed, _JOB_STATE["splits"], _JOB_STATE["out"], False,
                       train_tests=job.train_tests, name=job.name)
    b.policies = {}
    return b


def train_all(config: BenchmarkConfig, jobs: Sequence[TrainingJob], splits: dict[str, Split], out: Path,
              say: Callable[[str], None], progress_bar: bool = False) -> list[TrainedBaseline]:
    """Train every job, in ``config.workers`` processes at once (native trainer; each run
    is seeded and single-threaded, so the models are the same however many run at once),
    in order otherwise; the results in the jobs' order, each with its batched policies."""
    if config.workers <= 1 or config.trainer != "native" or len(jobs) <= 1:
        done = []
        for job in jobs:
            say(f"training {job.algo} seed {job.seed} on {job.train_tests} train tests ({config.steps:,} steps)")
            b = train_baseline(config, job.algo, job.seed, splits, out, progress_bar, train_tests=job.train_tests,
                               name=job.name)
            _say_trained(b, say)
            done.append(b)
        return done
    import multiprocessing

    from agents.native.checkpoint import load_native

    _JOB_STATE.update(config=config, splits=splits, out=out)
    algos = ", ".join(dict.fromkeys(j.algo for j in jobs))
    say(f"training {algos}: {len(jobs)} runs ({config.steps:,} steps each) in {config.workers} processes")
    results: list[TrainedBaseline] = []
    pool = multiprocessing.get_context("fork").Pool(config.workers, initializer=_worker_signals)
    try:
        for b in pool.imap(_run_job, jobs):
            model = load_native(b.path)
            b.policies = {"greedy": model.batch_policy(True), "sampled": model.batch_policy(False)}
            _say_trained(b, say)
            results.append(b)
    except BaseException:
        pool.terminate()  # stop the runs under way now, not at their end
        raise
    else:
        pool.close()
    finally:
        _JOB_STATE.clear()
    pool.join()
    return results


def _worker_signals() -> None:
    """A training worker leaves Ctrl-C and SIGTERM to the command, which stops it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _say_trained(b: TrainedBaseline, say: Callable[[str], None]) -> None:
    final = b.curve[-1][1]
    say(f"  {b.algo} seed {b.seed} on {b.train_tests} tests: {b.seconds:.0f} s; greedy: met "
        f"{100 * final['train']:.0f} % of train, {100 * final['validation']:.0f} % of validation tests")


def _train_native_baseline(config: BenchmarkConfig, algo: str, seed: int, splits: dict[str, Split], path: Path,
                           every: int, progress_bar: bool, count: int) -> TrainedBaseline:
    """One baseline with the native trainer on the first ``count`` train tests (a
    :class:`~flowtest_env.vector.PoolVectorEnv` of exactly the loaded tests), its greedy
    curve measured by the trainer on the scored train tests and the validation tests."""
    from agents.native.checkpoint import save_policy
    from agents.native.evaluation import BatchActor
    from agents.native_ppo import train as native_train
    from flowtest_env.game import TestGame
    from flowtest_env.vector import PoolVectorEnv

    settings = baseline_settings(algo)
    pool_options = {"pool": config.pool, "split": "train", "count": count}
    args = native_args(settings, POOL_ENV_ID, pool_options, config.steps, seed, eval_every=every)
    if "level_sampling" in settings:
        args = dataclasses.replace(args, level_sampling=settings["level_sampling"])
    env = PoolVectorEnv(args.num_envs, [TestGame(a) for a in splits["train"].artifacts[:count]], obs_kind=args.obs_kind)
    monitor = [TestGame(a) for a in splits["validation"].scored]
    try:
        result = native_train(args, heldout=monitor, progress_bar=progress_bar,
                              evaluate_train=min(count, config.scored("train"), CURVE_TRAIN_TESTS), env=env)
    finally:
        env.close()
    write_atomically(path, lambda tmp: save_policy(tmp, result.agent, result.settings))
    names = {"train": "train", "heldout": "validation"}
    curve = [(step, {names[k]: v["met"] for k, v in rates.items()}) for step, rates in result.evaluations]
    pos = result.settings.get("position")
    where = slice(int(pos[0]), int(pos[1])) if pos else None
    policies = {"greedy": BatchActor(result.agent, where, True, memory=args.memory),
                "sampled": BatchActor(result.agent, where, False, memory=args.memory)}
    return TrainedBaseline(algo, seed, path, result.steps, result.seconds, result.eval_seconds, curve, count, policies)
