"""The benchmark's training runs (protocol step 2, docs/benchmark-protocol.md): each baseline
per seed (and per generalization-curve size) trained on the pool's train split, each with its
greedy learning curve. The runs are independent jobs (:func:`run_job`): :func:`train_all` runs
them one after another, in local processes or as Ray tasks (``--parallel``), with the same
models either way. Every finished run leaves its model and then its record
(:mod:`~experiments.benchmark.resume`), so ``--resume`` keeps it (:func:`finished_run`) and
trains only the rest."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Sequence
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
from .resume import read_record, write_record


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
    selected_step: int | None = None  # the step of the checkpoint kept (``--select validation``); None: the final model

    @property
    def sut(self) -> str:
        """The model as a system under test (``ppo:PATH``, what the replay commands use)."""
        return f"ppo:{self.path}"


def train_baseline(
    config: BenchmarkConfig,
    algo: str,
    seed: int,
    splits: dict[str, Split],
    out: Path,
    progress_bar: bool = False,
    train_tests: int | None = None,
    name: str | None = None,
) -> TrainedBaseline:
    """Train one baseline on the first ``train_tests`` (default: all ``train_count``) tests
    of the train split (``config.steps`` time steps, rounded up to whole rollouts),
    recording its greedy learning curve on the first train tests (at most :data:`CURVE_TRAIN_TESTS`) and the validation tests;
    save it to ``out/models/<name or algo-seedN>.zip``, then its record (``.json``: what
    ``--resume`` keeps, :func:`~experiments.benchmark.resume.write_record`)."""
    count = int(train_tests or config.train_count)
    path = model_path(out, algo, seed, name)
    if config.trainer == "native":
        b = _train_native_baseline(config, algo, seed, splits, path, _curve_every(config), progress_bar, count)
    else:
        b = _train_sb3_baseline(config, algo, seed, splits, path, progress_bar, count)
    _record(b, config)
    return b


def _record(b: TrainedBaseline, config: BenchmarkConfig) -> None:
    """Write the record of a finished run beside its model (what ``--resume`` keeps)."""
    write_record(
        b.path,
        config,
        {
            "algo": b.algo,
            "seed": b.seed,
            "train_tests": b.train_tests,
            "steps": b.steps,
            "seconds": b.seconds,
            "curve_seconds": b.curve_seconds,
            "curve": [[step, rates] for step, rates in b.curve],
            "selected_step": b.selected_step,
        },
    )


def model_path(out: Path, algo: str, seed: int, name: str | None = None) -> Path:
    """Where a training run's model goes: ``out/models/<name or algo-seedN>.zip``."""
    return (out / "models" / f"{name or f'{algo}-seed{seed}'}.zip").resolve()


def _curve_every(config: BenchmarkConfig) -> int:
    return max(1, math.ceil(config.steps / config.curve_points))


def _sb3_curve_games(splits: dict[str, Split], count: int) -> dict[str, tuple[list[Any], list[int]]]:
    """The tests an sb3 baseline's learning curve watches: the first scored train tests (at
    most :data:`CURVE_TRAIN_TESTS`, and no more than it trains on) and the validation tests."""
    shown = {"train": games_and_budgets(splits["train"]), "validation": games_and_budgets(splits["validation"])}
    keep = min(count, CURVE_TRAIN_TESTS)
    shown["train"] = (shown["train"][0][:keep], shown["train"][1][:keep])
    return shown


def _train_sb3_baseline(config: BenchmarkConfig, algo: str, seed: int, splits: dict[str, Split], path: Path, progress_bar: bool, count: int) -> TrainedBaseline:
    """One baseline with stable-baselines3 on the first ``count`` train tests of the pool."""
    every = _curve_every(config)
    settings = baseline_settings(algo, "sb3")
    pool_options = {"pool": config.pool, "split": "train", "count": count}  # a standard pool: its shipped records
    env = make_training_vec_env(POOL_ENV_ID, seed, settings, pool_options)
    model = make_model(env, settings, seed)
    shown = _sb3_curve_games(splits, count)
    keep = (lambda m: write_atomically(path, lambda tmp: m.save(str(tmp)))) if config.select == "validation" else None
    recorder = CurveRecorder(every, settings["memory"], shown, keep)
    seconds = learn(model, config.steps, recorder, progress_bar)
    steps = int(model.num_timesteps)
    env.close()
    if keep is None:
        write_atomically(path, lambda tmp: model.save(str(tmp)))
    mark_own_file(path)  # loaded and scored below without --trust-model: this run wrote it
    if keep is not None:  # the best checkpoint was saved during the run: score that one
        from agents.ppo import load_model

        model = load_model(path)
    policies = _sb3_policies(model, splits["train"], count, settings["memory"])
    return TrainedBaseline(algo, seed, path, steps, seconds, recorder.seconds, recorder.points, count, policies, recorder.kept_step)


@dataclass(frozen=True)
class TrainingJob:
    """One training run of the benchmark: algorithm, seed, training tests, model name."""

    algo: str
    seed: int
    train_tests: int
    name: str


@dataclass(frozen=True)
class JobState:
    """What every training job reads: the configuration and the pool's splits (sent once to
    the workers: forked with them, or put in Ray's object store)."""

    config: BenchmarkConfig
    splits: dict[str, Split]


def run_job(state: JobState, job: TrainingJob) -> tuple[TrainedBaseline, bytes]:
    """One training job, anywhere (this process, a worker process, a Ray worker on another
    machine): train into a folder of its own and return the run without its policies, with
    the model file's bytes (the caller writes them into the benchmark's folder and loads
    the policies from there)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="flowtest-job-") as scratch:
        b = train_baseline(state.config, job.algo, job.seed, state.splits, Path(scratch), False, train_tests=job.train_tests, name=job.name)
        data = b.path.read_bytes()
    b.policies = {}
    return b, data


_WORKER_STATE: list[JobState] = []
"""The state a forked worker process reads (set before the fork)."""


def _forked_job(job: TrainingJob) -> tuple[TrainedBaseline, bytes]:
    return run_job(_WORKER_STATE[0], job)


def finished_run(config: BenchmarkConfig, job: TrainingJob, splits: dict[str, Split], out: Path) -> TrainedBaseline | None:
    """The run ``job`` as an earlier, stopped run of this benchmark finished it (its record,
    :func:`~experiments.benchmark.resume.read_record`, and its model with its batched
    policies), or ``None`` when it has to be trained: no record of this configuration, a model
    that is not the file recorded, or (``--trainer sb3``) a stable-baselines3 zip this process
    may not unpickle (kept only with ``--trust-model``)."""
    path = model_path(out, job.algo, job.seed, job.name)
    policies: dict[str, Any]
    rec = read_record(path, config)
    if rec is None or (rec.get("algo"), rec.get("seed"), rec.get("train_tests")) != (job.algo, job.seed, job.train_tests):
        return None
    if config.trainer == "native":
        from agents.native.checkpoint import load_native

        native = load_native(path)
        policies = {"greedy": native.batch_policy(True), "sampled": native.batch_policy(False)}
    else:
        from agents.checkpoint import pickled_models_trusted
        from agents.ppo import load_model

        if not pickled_models_trusted():
            return None
        model = load_model(path)
        where = model_where(model, _sb3_curve_games(splits, job.train_tests)["train"][0], baseline_settings(job.algo, "sb3")["memory"])
        policies = {"greedy": ModelBatchPolicy(model, where, True), "sampled": ModelBatchPolicy(model, where, False)}
    curve = [(int(step), {k: float(v) for k, v in rates.items()}) for step, rates in rec["curve"]]
    selected = rec.get("selected_step")
    return TrainedBaseline(
        job.algo,
        job.seed,
        path,
        int(rec["steps"]),
        float(rec["seconds"]),
        float(rec["curve_seconds"]),
        curve,
        job.train_tests,
        policies,
        None if selected is None else int(selected),
    )


def train_all(
    config: BenchmarkConfig,
    jobs: Sequence[TrainingJob],
    splits: dict[str, Split],
    out: Path,
    say: Callable[[str], None],
    progress_bar: bool = False,
    resume: bool = False,
) -> list[TrainedBaseline]:
    """Train every job, in ``config.workers`` processes at once (native trainer; each run
    is seeded and single-threaded, so the models are the same however many run at once),
    in order otherwise; the results in the jobs' order, each with its batched policies. With
    ``resume``, the runs an earlier, stopped run of the same configuration finished are kept
    (:func:`finished_run`) and only the others are trained."""
    kept: dict[str, TrainedBaseline] = {}
    if resume:
        for job in jobs:
            b = finished_run(config, job, splits, out)
            if b is not None:
                kept[job.name] = b
        if kept:
            say(f"resuming: keeping {len(kept)} finished training run{'s' if len(kept) != 1 else ''} of {len(jobs)} ({', '.join(kept)})")
    todo = [job for job in jobs if job.name not in kept]
    trained = {job.name: b for job, b in zip(todo, _train_jobs(config, todo, splits, out, say, progress_bar), strict=True)}
    return [kept.get(job.name) or trained[job.name] for job in jobs]


def _train_jobs(
    config: BenchmarkConfig, jobs: Sequence[TrainingJob], splits: dict[str, Split], out: Path, say: Callable[[str], None], progress_bar: bool = False
) -> list[TrainedBaseline]:
    """Train ``jobs`` (:func:`train_all`'s training) where ``config.parallel`` says: ``serial``
    (one after another in this process, with the progress bar), ``processes``
    (``config.workers`` local processes at once) or ``ray`` (Ray tasks: on the cluster
    ``RAY_ADDRESS`` names, else on a local Ray of ``config.workers`` CPUs). Each run is seeded
    and single-threaded, so the models, and the table, are the same wherever they ran.

    Example::

        config = BenchmarkConfig.for_pool("reachability1/5x5-v2", parallel="ray", seeds=tuple(range(10)))
        trained = train_all(config, jobs, splits, Path("bench"), print)
    """
    if config.parallel == "serial" or (config.parallel == "processes" and (config.workers <= 1 or len(jobs) <= 1)):
        done = []
        for job in jobs:
            say(f"training {job.algo} seed {job.seed} on {job.train_tests} train tests ({config.steps:,} steps)")
            b = train_baseline(config, job.algo, job.seed, splits, out, progress_bar, train_tests=job.train_tests, name=job.name)
            _say_trained(b, say)
            done.append(b)
        return done
    algos = ", ".join(dict.fromkeys(j.algo for j in jobs))
    where = f"{config.workers} processes" if config.parallel == "processes" else "Ray tasks"
    say(f"training {algos}: {len(jobs)} runs ({config.steps:,} steps each) in {where}")
    state = JobState(config, splits)
    finished = _in_processes(state, jobs, config.workers) if config.parallel == "processes" else _on_ray(state, jobs, config.workers)
    results: list[TrainedBaseline | None] = [None] * len(jobs)
    for i, (b, data) in finished:
        kept = results[i] = _keep(b, data, out, config, splits)
        _say_trained(kept, say)
    return [b for b in results if b is not None]


def _keep(b: TrainedBaseline, data: bytes, out: Path, config: BenchmarkConfig, splits: dict[str, Split]) -> TrainedBaseline:
    """A finished job's model written into ``out/models`` (by this process: it is loaded
    without --trust-model) and its batched policies loaded from there."""
    path = (out / "models" / b.path.name).resolve()
    write_atomically(path, lambda tmp: tmp.write_bytes(data))
    b.path = path
    _record(b, config)  # the model first, then its record
    if config.trainer == "native":
        from agents.native.checkpoint import load_native

        native = load_native(path)
        b.policies = {"greedy": native.batch_policy(True), "sampled": native.batch_policy(False)}
        return b
    from agents.ppo import load_model

    mark_own_file(path)
    b.policies = _sb3_policies(load_model(path), splits["train"], b.train_tests, baseline_settings(b.algo, "sb3")["memory"])
    return b


def _sb3_policies(model: Any, train: Split, count: int, memory: str) -> dict[str, Any]:
    """A stable-baselines3 model's batched policies, greedy and sampled, with its memory."""
    from flowtest_env.game import TestGame

    where = model_where(model, [TestGame(a) for a in train.artifacts[: min(count, CURVE_TRAIN_TESTS)]], memory)
    return {"greedy": ModelBatchPolicy(model, where, True), "sampled": ModelBatchPolicy(model, where, False)}


def _in_processes(state: JobState, jobs: Sequence[TrainingJob], workers: int) -> Iterator[tuple[int, tuple[TrainedBaseline, bytes]]]:
    """``(index, result)`` of each job, run in ``workers`` forked processes, in the jobs' order."""
    import multiprocessing

    _WORKER_STATE[:] = [state]
    pool = multiprocessing.get_context("fork").Pool(workers, initializer=_worker_signals)
    try:
        yield from enumerate(pool.imap(_forked_job, jobs))
    except BaseException:
        pool.terminate()  # stop the runs under way now, not at their end
        raise
    else:
        pool.close()
    finally:
        _WORKER_STATE.clear()
    pool.join()


RAY_POLL = 0.2
"""Seconds between looks at the Ray tasks (so Ctrl-C is taken at once)."""


def _on_ray(state: JobState, jobs: Sequence[TrainingJob], workers: int) -> Iterator[tuple[int, tuple[TrainedBaseline, bytes]]]:
    """``(index, result)`` of each job, run as Ray tasks (one CPU each), in the order they finish."""
    import os

    import ray  # the optional parallel path: Ray is not a core dependency

    started = not ray.is_initialized()
    if started:
        if os.environ.get("RAY_ADDRESS"):
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    pending: dict[Any, int] = {}
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(run_job)
        shared = ray.put(state)
        pending = {remote.remote(shared, job): i for i, job in enumerate(jobs)}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1, timeout=RAY_POLL)
            for ref in done:
                yield pending.pop(ref), ray.get(ref)
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    finally:
        if started:
            ray.shutdown()


def _worker_signals() -> None:
    """A training worker leaves Ctrl-C and SIGTERM to the command, which stops it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _say_trained(b: TrainedBaseline, say: Callable[[str], None]) -> None:
    final = b.curve[-1][1]
    say(
        f"  {b.algo} seed {b.seed} on {b.train_tests} tests: {b.seconds:.0f} s; greedy: met "
        f"{100 * final['train']:.0f} % of train, {100 * final['validation']:.0f} % of validation tests"
    )


def _train_native_baseline(
    config: BenchmarkConfig, algo: str, seed: int, splits: dict[str, Split], path: Path, every: int, progress_bar: bool, count: int
) -> TrainedBaseline:
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
    watch: dict[str, Any] = {"validation": monitor} if config.select == "validation" else {"heldout": monitor}  # validation: the trainer keeps the best
    try:
        result = native_train(args, progress_bar=progress_bar, evaluate_train=min(count, config.scored("train"), CURVE_TRAIN_TESTS), env=env, **watch)
    finally:
        env.close()
    write_atomically(path, lambda tmp: save_policy(tmp, result.agent, result.settings))
    names = {"train": "train", "heldout": "validation", "validation": "validation"}
    curve = [(step, {names[k]: v["met"] for k, v in rates.items()}) for step, rates in result.evaluations]
    pos = result.settings.get("position")
    where = slice(int(pos[0]), int(pos[1])) if pos else None
    policies = {"greedy": BatchActor(result.agent, where, True, memory=args.memory), "sampled": BatchActor(result.agent, where, False, memory=args.memory)}
    return TrainedBaseline(algo, seed, path, result.steps, result.seconds, result.eval_seconds, curve, count, policies, result.selected_step)
