"""``flowtest benchmark --pool NAME``: the learned baselines on a test pool, scored by a fixed
protocol on tests they never trained on, between a random floor and a reference ceiling.

The protocol (docs/benchmark-protocol.md has the reasons for each choice):

1. **The pool** (:func:`load_splits`): the first ``train_count`` tests of the pool's
   ``train`` split (the baselines train on them), the first ``validation_count`` of its
   ``validation`` split (the learning curves, i.e. model monitoring; no model selection is
   done) and the first ``test_count`` of its ``test`` split (held out: never seen in
   training). The splits are disjoint seed ranges (:mod:`flowtest_env.pools`); where the
   tests come from is pluggable (``source``, :data:`flowtest_env.scoring.PoolSource`).
   The tests that are scored are written to ``OUT/pool/<split>/seed<N>.json`` so every
   run in the report replays with ``flowtest evaluate --env <that file> ... --replay``.
2. **The baselines** (:func:`train_baseline`), per algorithm and training seed, on the
   train split, for ``steps`` time steps: with the native trainer (default,
   :mod:`agents.native_ppo`) masked PPO with the visited-places memory
   (``maskable-ppo``), with a GRU (``recurrent-ppo``) and with prioritized level replay
   over the train tests (``plr-ppo``); with ``--trainer sb3`` sb3-contrib's MaskablePPO
   and RecurrentPPO. Only ``maskable-ppo`` trains by default (the time budget); the others
   on request (``--algo``).
3. **The scores.** Every system on every split: the learned policies greedily (each test
   once) **and**, on the held-out tests, sampled (``runs`` seeded runs per test), every test x run of a split in
   one :class:`~flowtest_env.vector.PoolVectorEnv` batch (:mod:`flowtest_env.scoring`);
   ``random`` (the **floor**, ``runs`` runs per test, batched too); the **references**
   (the scripted replanner and the GR(1) system, correct systems that do not know the
   test: the **ceiling**; on fuel grids with doors a door can close after the fuel to go
   round it is spent, so they meet fewer than all tests there: docs/benchmark-protocol.md)
   and any system that is not batched through the single env, once per test.
   The floor and the ceiling are always scored: they define the scale.
4. **The statistics**: per split, the **normalized score** ``(met - floor) / (ceiling -
   floor)`` (0 = random, 1 = reference; floor and ceiling are the split's own), its
   interquartile mean over training seeds with a stratified-bootstrap 95 % interval (seeds
   resampled, and tests within each seed's stratum), the mean over the worst 10 % of the
   held-out tests, raw met, test objective realized, restrictions, steps, and the held-out
   gap (train met minus held-out met).
5. **The generalization curve** (:func:`generalization_curve`): the held-out normalized
   score of the first baseline trained on the first 16, 64, 256, 1,024 train tests
   (``curve_seeds`` seeds each, the same steps) and on all ``train_count`` (the main runs).
   Every training run (main and curve) is trained first, ``workers`` at a time in their own
   processes (:func:`train_all`; the models do not depend on it).
6. **The outputs** in ``OUT``: ``table.md`` and ``table.json`` (the results file,
   docs/benchmark-protocol.md), ``learning-curves.png``, ``generalization.png``, the
   evaluation report of :mod:`experiments.cli.evaluate` on a sample of each split's tests
   (``report.html``, ``report.md``, ``results.json``), the models and the scored tests.

Every number is seeded (the tests, training, the sampled runs, the bootstrap), so the same
command gives the same table; only the times differ.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from agents.checkpoint import mark_own_file
from synthesis.artifacts.artifact import TestArtifact
from synthesis.model.errors import ProblemError

from .arguments import nonnegative_int, positive_int
from .command import Command
from .episodes import Trace, make_env, run_episode
from .evaluate import Cell, check_sut_names, write_report
from .exits import EXIT_OK
from .outputs import json_safe, prepare_output_folder, print_json, write_atomically
from .report import TestInfo
from .train import ALGOS, DEFAULTS, TRAINERS, check_settings, make_model, make_training_vec_env, native_args, native_settings, require_native
from .training import learn, require_rl

BENCHMARK_MARKER = ".flowtest-benchmark"
"""The file that marks a folder as a benchmark's: ``--out`` refuses any other non-empty
folder, and any earlier benchmark, unless ``--force``."""

RESULTS_FORMAT = "flowtest-benchmark"
RESULTS_VERSION = 2
"""``table.json``'s ``format`` and ``version`` (docs/benchmark-protocol.md)."""

POOL_ENV_ID = "FlowTest-RandomGrid-v0"
"""The env the baselines train on (its ``pool``, ``split``, ``count`` options)."""

BENCH_ALGOS: tuple[str, ...] = (*ALGOS, "plr-ppo")
"""The baselines ``--algo`` may name: ``flowtest train``'s algorithms and PPO with
prioritized level replay (native trainer only)."""

DEFAULT_ALGOS: tuple[str, ...] = ("maskable-ppo",)
"""The baselines ``--sut ppo`` trains by default (the others on request: the time budget)."""

BASELINES: dict[str, dict[str, Any]] = {
    "maskable-ppo": {"algo": "maskable-ppo", "memory": "visited"},
    "recurrent-ppo": {"algo": "recurrent-ppo", "memory": "none", "batch_size": 1024, "n_epochs": 4, "lstm_hidden_size": 64},
}
"""Settings of each baseline with ``--trainer sb3``, over ``flowtest train``'s
:data:`~experiments.cli.train.DEFAULTS` (8 envs x 128 steps per rollout, learning rate 1e-3,
MLP 64 x 64, shaping 10 towards the system's own goal). MaskablePPO remembers the places
it visited (the memory wrapper; a reactive test answers the run's history, which the
observation does not show); RecurrentPPO has its LSTM instead, and trains on whole
rollouts (one minibatch of 1,024 steps, 4 epochs, 64 LSTM units) because sb3-contrib
steps an LSTM through every episode boundary of a minibatch in Python, which is its cost."""

NATIVE_BASELINES: dict[str, dict[str, Any]] = {
    "maskable-ppo": {"algo": "ppo", "memory": "visited", "device": "cpu"},
    "recurrent-ppo": {"algo": "recurrent-ppo", "device": "cpu"},
    "plr-ppo": {"algo": "ppo", "memory": "visited", "device": "cpu"},
}
"""Settings of each baseline with the native trainer (the default), over
:data:`~experiments.cli.train.NATIVE_DEFAULTS`: masked PPO with an MLP and the visited-places
memory, masked PPO with a GRU (its own memory), and the first with prioritized level replay
(:data:`LEVEL_SAMPLING`); on the CPU, so a seed gives the same table."""

LEVEL_SAMPLING: dict[str, str] = {"plr-ppo": "plr"}
"""The baselines that choose their training tests themselves (``NativeArgs.level_sampling``;
:class:`agents.native_ppo.LevelSampler`, the defaults of Jiang et al. 2021)."""

RANDOM = "random"
"""The floor: uniform over the legal actions (:func:`flowtest_env.scoring.random_policy`)."""

REFERENCES: tuple[str, ...] = ("scripted:replanner", "gr1")
"""Correct systems that do not know the test (they never act against their own objective);
the best of them on a split is that split's ceiling."""

DEFAULT_SUTS: tuple[str, ...] = ("ppo", RANDOM, *REFERENCES)
"""``--sut`` when none is given: the baselines of ``--algo``, the floor and the references."""

SPLIT_NAMES: tuple[str, ...] = ("train", "validation", "test")
"""The pool's splits, in the order the table shows them."""

REPORT_SPLITS: tuple[str, ...] = ("train", "test")
"""The splits the HTML report shows (a sample of their tests each)."""

RUN_SEED = 0
"""The seed of every scoring batch and single-env run (it matters to a sampled or random
policy; it is the ``--seed`` of the replay commands)."""

CURVE_TRAIN_TESTS = 256
"""The learning curves watch at most this many train tests (the first; the final score
uses ``train_eval_count``): each curve point plays them, inside the training time."""

WORST_SHARE = 0.1
"""The worst share of the held-out tests whose mean score the table shows (CVaR-style)."""

T95: dict[int, float] = {}


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class BenchmarkConfig:
    """What ``flowtest benchmark`` runs. The defaults are the protocol's and fit 30 minutes
    on 2 shared cores for a standard pool (docs/benchmark-protocol.md, *Budget*);
    :meth:`for_pool` takes a standard pool's smaller shipped split, as the command does."""

    pool: str
    suts: tuple[str, ...] = DEFAULT_SUTS
    algos: tuple[str, ...] = DEFAULT_ALGOS
    train_count: int = 4096
    validation_count: int = 256
    test_count: int = 1000
    train_eval_count: int = 1000
    steps: int = 1_000_000
    seeds: tuple[int, ...] = tuple(range(10))
    runs: int = 8
    curve_sizes: tuple[int, ...] = (16, 64, 256, 1024)
    curve_seeds: int = 2
    curve_points: int = 5
    trainer: str = "native"
    report_tests: int = 20
    bootstrap: int = 2000
    workers: int = field(default_factory=lambda: default_workers())

    @classmethod
    def for_pool(cls, pool: str, **settings: Any) -> BenchmarkConfig:
        """The configuration ``flowtest benchmark --pool POOL`` runs, with ``settings`` (any
        field) given: the split counts not given are :func:`default_counts`, so a standard
        pool that ships a smaller split is scored on all of it, as the command line does,
        instead of building the rest on demand (``BenchmarkConfig(pool)`` keeps the
        protocol's counts).

        Example::

            BenchmarkConfig.for_pool("reachability1/5x5/blocked/agent-v1").test_count  # 250
        """
        counts = default_counts(pool)
        for split in ("train", "validation", "test"):
            if settings.get(f"{split}_count") is None:
                settings[f"{split}_count"] = counts[split]
        return cls(pool, **settings)

    def baselines(self) -> list[str]:
        """The algorithms to train: ``--sut ppo`` stands for every ``--algo``; an
        algorithm may also be named itself (``--sut recurrent-ppo``)."""
        named = [s for s in self.suts if s in BENCH_ALGOS]
        algos = list(self.algos) if "ppo" in self.suts else []
        return list(dict.fromkeys(algos + named))

    def others(self) -> list[str]:
        """The systems scored as they are: the floor, the references, and any other
        (``ppo:PATH``, ``python:M:N``, ...), in that order."""
        given = [s for s in dict.fromkeys(self.suts) if s != "ppo" and s not in BENCH_ALGOS]
        return list(dict.fromkeys([RANDOM, *REFERENCES, *given]))

    def counts(self) -> dict[str, int]:
        """Tests loaded per split."""
        return {"train": self.train_count, "validation": self.validation_count, "test": self.test_count}

    def scored(self, split: str) -> int:
        """Tests scored per split (the train split: its first ``train_eval_count``)."""
        return min(self.train_count, self.train_eval_count) if split == "train" else self.counts()[split]

    def curve(self) -> list[int]:
        """The generalization curve's training-set sizes: ``curve_sizes`` below
        ``train_count``, then ``train_count`` (the main runs)."""
        return sorted({n for n in self.curve_sizes if 0 < n < self.train_count} | {self.train_count})


def _runs(n: int, what: str = "") -> str:
    """``"8 sampled runs"``, ``"1 sampled run"``."""
    return f"{n} {what}run{'s' if n != 1 else ''}"


def default_workers() -> int:
    """Training processes by default: one per CPU, at most 2 (each run uses one thread)."""
    return max(1, min(2, os.cpu_count() or 1))


def check_config(config: BenchmarkConfig) -> None:
    """Reject a configuration before any work.

    Raises
    ------
    ProblemError
        On a bad pool name, an unknown system, no system at all, or counts out of range.
    """
    from flowtest_env.pools import parse_pool, split_seeds

    try:
        if is_standard_pool(config.pool):
            from flowtest_env.standard_pools import standard_pool

            standard_pool(config.pool)  # a known id and version
        else:
            parse_pool(config.pool)
        for split, count in config.counts().items():
            split_seeds(split, count)
    except ValueError as exc:
        raise ProblemError(f"--pool {config.pool}: {exc}") from None
    if not config.suts:
        raise ProblemError("no system to benchmark: give --sut ppo and/or a system such as scripted:replanner")
    check_sut_names(config.others())
    from agents.ppo import check_trusted

    for sut in config.others():
        if sut.startswith("ppo:"):
            check_trusted(sut[4:])  # a pickled model is refused before any work
    if "ppo" in config.suts and not config.algos:
        raise ProblemError("--sut ppo needs at least one --algo")
    for algo in config.algos:
        if algo not in BENCH_ALGOS:
            raise ProblemError(f"unknown --algo {algo!r}; expected one of {', '.join(BENCH_ALGOS)}")
    if config.trainer not in TRAINERS:
        raise ProblemError(f"unknown --trainer {config.trainer!r}; expected one of {', '.join(TRAINERS)}")
    for name in ("runs", "train_eval_count", "report_tests", "bootstrap", "curve_points", "workers"):
        if int(getattr(config, name)) < 1:
            raise ProblemError(f"--{name.replace('_', '-')} must be at least 1")
    if config.baselines():
        if config.trainer == "sb3":
            require_rl()
        else:
            require_native()
        if not config.seeds:
            raise ProblemError("--seeds needs at least one training seed")
        if config.steps < 1:
            raise ProblemError("--steps must be at least 1")
        if config.curve_seeds < 0:
            raise ProblemError("--curve-seeds must not be negative")
        for algo in config.baselines():
            if config.trainer == "sb3":
                if algo not in BASELINES:
                    raise ProblemError(f"--algo {algo}: a baseline of the native trainer only (not --trainer sb3)")
                check_settings(baseline_settings(algo, "sb3"))
            else:
                baseline_settings(algo)


def default_counts(pool: str) -> dict[str, int]:
    """Tests per split when none is given: the protocol's (:class:`BenchmarkConfig`), or a
    standard pool's whole split where it plans fewer (its held-out split of 250 tests for a
    family that builds slowly), so the defaults load shipped records only and build nothing.

    Example::

        default_counts("reachability1/5x5/blocked/agent-v1")  # {'train': 4096, 'validation': 256, 'test': 250}
    """
    counts = BenchmarkConfig(pool).counts()
    if is_standard_pool(pool):
        from flowtest_env.standard_pools import standard_pool

        try:
            planned = standard_pool(pool).splits
        except ValueError:
            return counts  # an unknown id or version: check_config says so
        counts = {split: min(n, int(planned.get(split, n))) for split, n in counts.items()}
    return counts


def is_standard_pool(name: str) -> bool:
    """Whether ``name`` is written as a standard pool's id (``reachability1/5x5-v1``:
    :mod:`flowtest_env.standard_pools`, shipped records), which :func:`flowtest_env.pools.load_pool`
    loads like an on-demand pool name."""
    try:
        from flowtest_env.standard_pools import is_standard
    except ImportError:  # a FlowTest without standard pools
        return False
    return bool(is_standard(name))


def baseline_settings(algo: str, trainer: str = "native") -> dict[str, Any]:
    """The full training settings of a baseline: :data:`NATIVE_BASELINES` over
    ``NATIVE_DEFAULTS``, or with ``trainer="sb3"`` :data:`BASELINES` over ``DEFAULTS``."""
    if trainer == "sb3":
        return {**DEFAULTS, **BASELINES[algo]}
    settings = native_settings(NATIVE_BASELINES[algo])
    if algo in LEVEL_SAMPLING:
        settings = {**settings, "level_sampling": LEVEL_SAMPLING[algo]}
    return settings


# --------------------------------------------------------------------------- the pool


@dataclass
class Split:
    """The tests of one split of the pool: artifacts (all loaded), the files the scored
    ones were written to (the first ``len(files)``), and the label of its report column."""

    name: str
    label: str
    seeds: list[int]
    artifacts: list[TestArtifact]
    files: list[Path] = field(default_factory=list)

    @property
    def scored(self) -> list[TestArtifact]:
        """The tests this split is scored on."""
        return self.artifacts[:len(self.files)]


def load_splits(config: BenchmarkConfig, out: Path, progress: bool | None = None,
                source: Callable[[str, str, int], Sequence[TestArtifact]] | None = None) -> dict[str, Split]:
    """The train, validation and test splits of the pool (``source(pool, split, count)``;
    default :func:`flowtest_env.pools.load_pool`, built on demand and cached), each scored
    test written to ``out/pool/<split>/seed<N>.json``.

    Raises
    ------
    ProblemError
        If the source gives fewer tests than asked.
    """
    from flowtest_env.pools import load_pool, split_seeds

    def default(pool: str, split: str, count: int) -> Sequence[TestArtifact]:
        return load_pool(pool, split, count, progress=progress)

    load = source or default
    splits = {}
    for name in SPLIT_NAMES:
        count = config.counts()[name]
        seeds = list(split_seeds(name, count))
        arts = list(load(config.pool, name, count))
        if len(arts) < count:
            raise ProblemError(f"--pool {config.pool}: its {name} split has {len(arts)} tests, fewer than the {count} asked")
        what = "held-out tests" if name == "test" else "tests"
        split = Split(name, f"{config.pool} {name} ({config.scored(name)} of {count} {what})", seeds, arts[:count])
        for seed, art in zip(seeds[:config.scored(name)], split.artifacts, strict=False):
            path = (out / "pool" / name / f"seed{seed}.json").resolve()
            write_atomically(path, art.save)
            split.files.append(path)
        splits[name] = split
    return splits


def _games_and_budgets(split: Split) -> tuple[list[Any], list[int]]:
    from flowtest_env.envs import default_max_steps
    from flowtest_env.game import TestGame

    games = [TestGame(a) for a in split.scored]
    return games, [default_max_steps(g) for g in games]


# --------------------------------------------------------------------------- batched models


class ModelBatchPolicy:
    """A saved model (native or stable-baselines3, as :func:`agents.ppo.load_model` gives
    it) as a batched policy of :mod:`flowtest_env.scoring`: greedy (``deterministic``) or
    sampled, adding the visited-places memory when the model has it (``where``: the SUT's
    place in the observation) and carrying a recurrent state. Sampling is seeded by
    ``reset`` (torch's global generator, which stable-baselines3 samples from)."""

    def __init__(self, model: Any, where: slice | None, deterministic: bool = True) -> None:
        kind = type(model).__name__
        self.model, self.where, self.deterministic = model, where, deterministic
        self.recurrent = bool(getattr(model, "recurrent", kind == "RecurrentPPO"))
        self.maskable = bool(getattr(model, "maskable", kind == "MaskablePPO"))
        self.state: Any = None
        self.seen: np.ndarray | None = None

    def reset(self, num_runs: int, seed: int) -> None:
        import torch

        torch.manual_seed(int(seed))
        self.state, self.seen = None, None

    def __call__(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        obs = np.asarray(observations, dtype=np.float32)
        starts = np.full(obs.shape[0], self.seen is None)
        if self.where is not None:
            here = obs[:, self.where]
            self.seen = here.copy() if self.seen is None else np.maximum(self.seen, here)
            obs = np.concatenate([obs, self.seen], axis=1)
        elif self.seen is None:
            self.seen = np.zeros((obs.shape[0], 0), dtype=np.float32)
        kw: dict[str, Any] = {"deterministic": self.deterministic}
        if self.maskable:
            kw["action_masks"] = masks
        if self.recurrent:
            kw["state"], kw["episode_start"] = self.state, starts
        actions, self.state = self.model.predict(obs, **kw)
        return np.asarray(actions)


def _model_where(model: Any, games: Sequence[Any], memory: str) -> slice | None:
    from flowtest_env.encoding import make_encoder
    from flowtest_env.wrappers import shared_position_slice

    if memory != "visited":
        return None
    return shared_position_slice([make_encoder(g, "flat") for g in games])


def batch_verdicts(model: Any, games: Sequence[Any], memory: str, budgets: Sequence[int]) -> dict[str, np.ndarray]:
    """Let the deterministic policy of ``model`` (a saved model as :func:`agents.ppo.load_model`
    gives it: native or stable-baselines3) play every test of ``games`` once, all at once in
    one :class:`~flowtest_env.vector.PoolVectorEnv`, and return the verdict arrays
    (``system_objective``, ``test_objective_realized``, ``restrictions``, ``steps``), one
    entry per test. Each test ends at its outcome or its own step budget ``budgets[i]``
    (the tests' :func:`~flowtest_env.envs.default_max_steps`, which the batch uses).

    Raises
    ------
    ValueError
        If the tests do not share where the observation holds the system's place.
    """
    from flowtest_env.envs import default_max_steps
    from flowtest_env.scoring import play_batch

    if list(budgets) != [default_max_steps(g) for g in games]:
        raise ValueError("the batch plays each test to its own default step budget")
    policy = ModelBatchPolicy(model, _model_where(model, games, memory), deterministic=True)
    return {k: v[0] for k, v in play_batch(policy, games, 1, RUN_SEED).items()}


class CurveRecorder:
    """An SB3 callback that measures the learning curve: the share of the train tests and
    of the validation tests whose system objective the deterministic policy meets
    (:func:`batch_verdicts`), for the model as it is after learning from ``step`` time
    steps: at the start, at the first rollout after every ``every`` steps, and at the end.
    It only reads the model: training goes exactly as without it."""

    def __init__(self, every: int, memory: str, splits: dict[str, tuple[list[Any], list[int]]]) -> None:
        from stable_baselines3.common.callbacks import BaseCallback

        recorder = self
        self.points: list[tuple[int, dict[str, float]]] = []
        self.seconds = 0.0

        def measure(model: Any, step: int) -> None:
            t0 = time.perf_counter()
            rates = {}
            for name, (games, budgets) in splits.items():
                v = batch_verdicts(model, games, memory, budgets)
                rates[name] = float(np.mean(v["system_objective"] == "met"))
            recorder.points.append((step, rates))
            recorder.seconds += time.perf_counter() - t0

        class Callback(BaseCallback):
            def __init__(self) -> None:
                super().__init__()
                self.next = 0

            def _on_rollout_start(self) -> None:  # the model has learned from num_timesteps steps
                if self.num_timesteps >= self.next:
                    measure(self.model, self.num_timesteps)
                    while self.next <= self.num_timesteps:
                        self.next += every

            def _on_step(self) -> bool:
                return True

            def _on_training_end(self) -> None:
                measure(self.model, self.num_timesteps)

        self.callback = Callback()


# --------------------------------------------------------------------------- training


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
    shown = {"train": _games_and_budgets(splits["train"]), "validation": _games_and_budgets(splits["validation"])}
    keep = min(count, CURVE_TRAIN_TESTS)
    shown["train"] = (shown["train"][0][:keep], shown["train"][1][:keep])
    recorder = CurveRecorder(every, settings["memory"], shown)
    seconds = learn(model, config.steps, recorder, progress_bar)
    write_atomically(path, lambda tmp: model.save(str(tmp)))
    mark_own_file(path)  # scored below without --trust-model: this run wrote it
    env.close()
    where = _model_where(model, shown["train"][0], settings["memory"])
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
    policies = {"greedy": BatchActor(result.agent, where, True), "sampled": BatchActor(result.agent, where, False)}
    return TrainedBaseline(algo, seed, path, result.steps, result.seconds, result.eval_seconds, curve, count, policies)


# --------------------------------------------------------------------------- scoring


def _policy_factory(sut: str) -> Callable[[Any], Any]:
    """Make the SUT for an env; a saved model is loaded once, not once per test."""
    from agents.base import PolicyError
    from agents.registry import make_policy

    if sut.startswith("ppo:"):
        from agents.ppo import PPOPolicy, load_model

        try:
            model = load_model(sut[4:])
        except PolicyError as exc:
            raise ProblemError(f"--sut {sut}: {exc}") from None
        return lambda env: PPOPolicy(model, sut, env)
    return lambda env: make_policy(sut, env)


def score_systems(suts: Sequence[str], split: Split, limit: int | None = None) -> dict[str, list[Trace]]:
    """Every system plays every scored test of ``split`` (the first ``limit`` of them when
    given) once (seed :data:`RUN_SEED`), through the single env of the test's file, as
    ``flowtest evaluate --env FILE`` runs it.

    Raises
    ------
    ProblemError
        If a system cannot play the pool's tests (a model of another observation shape).
    """
    from agents.base import PolicyError

    factories = {sut: _policy_factory(sut) for sut in suts}
    traces: dict[str, list[Trace]] = {sut: [] for sut in suts}
    for path in split.files[:limit]:
        env = make_env(str(path))
        for sut, factory in factories.items():
            try:
                policy = factory(env)
            except PolicyError as exc:
                raise ProblemError(f"--sut {sut} cannot play the pool's tests: {exc}") from None
            traces[sut].append(run_episode(env, policy, str(path), sut, RUN_SEED))
            close = getattr(policy, "close", None)
            if callable(close):
                close()
        env.close()
    return traces


def batched_system(sut: str, runs: int) -> dict[str, Any] | None:
    """The batched policies of a system that has them (``{"greedy": policy, "sampled":
    policy}``, either may be missing), or ``None`` when it plays through the single env:
    ``random`` (sampled only), a native checkpoint ``ppo:PATH`` (both), and a
    ``python:MODULE:NAME`` object marked ``batched = True`` (a class is instantiated with
    no argument; its ``deterministic`` attribute, default true, says whether it is greedy).

    Raises
    ------
    ProblemError
        If the named object cannot be loaded.
    """
    from agents.base import PolicyError
    from flowtest_env.scoring import random_policy

    if sut == RANDOM:
        return {"sampled": random_policy()}
    if sut.startswith("ppo:"):
        from agents.checkpoint import CheckpointError, is_native_checkpoint

        if not is_native_checkpoint(sut[4:]):
            return None
        from agents.native.checkpoint import load_native

        try:
            model = load_native(sut[4:])
        except CheckpointError as exc:
            raise ProblemError(f"--sut {sut}: {exc}") from None
        return {"greedy": model.batch_policy(True), "sampled": model.batch_policy(False)}
    if sut.startswith("python:"):
        from agents.external import resolve

        try:
            obj = resolve(sut[len("python:"):])
        except PolicyError as exc:
            raise ProblemError(f"--sut {sut}: {exc}") from None
        if not getattr(obj, "batched", False):
            return None
        policy = obj() if isinstance(obj, type) else obj
        return {"greedy" if getattr(policy, "deterministic", True) else "sampled": policy}
    return None


def verdict_metrics(v: dict[str, np.ndarray]) -> dict[str, Any]:
    """The numbers of one policy on one split from verdict arrays ``[runs, tests]``: ``met``
    (share of runs met), ``realized`` (share of the met runs that realized the test
    objective), ``restrictions`` (mean per run), ``steps`` (mean of the met runs),
    ``violated``, ``open``, ``test_failures`` (met runs that did not realize the test
    objective: a FlowTest bug), ``runs`` and ``tests``, and ``per_test`` (share of each
    test's runs met)."""
    from flowtest_env.scoring import summarize

    s = summarize(v)
    met = np.asarray(v["system_objective"]) == "met"
    realized = np.asarray(v["test_objective_realized"], dtype=bool)
    return {"tests": s.tests, "runs": s.runs, "met": s.met, "realized": s.realized, "restrictions": s.restrictions,
            "steps": s.steps, "violated": s.violated, "open": s.open, "test_failures": int((met & ~realized).sum()),
            "per_test": list(s.per_test_met)}


def trace_verdicts(traces: Sequence[Trace]) -> dict[str, np.ndarray]:
    """The verdict arrays ``[1, tests]`` of single-env runs."""
    return {k: np.array([[t.verdict[k] for t in traces]], dtype=object if k == "system_objective" else None)
            for k in ("system_objective", "test_objective_realized", "restrictions", "steps")}


def split_metrics(traces: Sequence[Trace]) -> dict[str, Any]:
    """The numbers of one system on one split from single-env runs: ``met`` (share of the
    tests whose system objective was met), ``realized`` (share of those that realized the
    test objective; ``None`` if none met), ``restrictions`` (mean restricted decisions per
    run), ``steps`` (mean steps of the runs that met; ``None`` if none), and counts."""
    met = [t for t in traces if t.verdict["system_objective"] == "met"]
    n = len(traces)
    return {
        "tests": n,
        "met": len(met) / n if n else None,
        "realized": sum(bool(t.verdict["test_objective_realized"]) for t in met) / len(met) if met else None,
        "restrictions": float(np.mean([t.verdict["restrictions"] for t in traces])) if n else None,
        "steps": float(np.mean([t.verdict["steps"] for t in met])) if met else None,
        "violated": sum(t.verdict["system_objective"] == "violated" for t in traces),
        "open": sum(t.verdict["system_objective"] == "open" for t in traces),
        "test_failures": sum(t.kind == "test" for t in traces),
    }


# --------------------------------------------------------------------------- statistics


def t_quantile(df: int) -> float:
    """The 0.975 quantile of Student's t with ``df`` degrees of freedom."""
    if df not in T95:
        from scipy.stats import t

        T95[df] = float(t.ppf(0.975, df))
    return T95[df]


def mean_ci(values: Sequence[float | None]) -> dict[str, Any]:
    """``mean`` and ``ci95`` (the half-width of the 95 % confidence interval of the mean,
    Student's t; ``None`` for fewer than two values) of the values that are not ``None``,
    with the values themselves."""
    xs = [float(v) for v in values if v is not None]
    if not xs:
        return {"mean": None, "ci95": None, "values": list(values)}
    mean = float(np.mean(xs))
    ci = t_quantile(len(xs) - 1) * float(np.std(xs, ddof=1)) / math.sqrt(len(xs)) if len(xs) > 1 else None
    return {"mean": mean, "ci95": ci, "values": list(values)}


def normalized_summary(per_seed_tests: Sequence[Sequence[float]], floor: float | None, ceiling: float | None,
                       reps: int, seed: int = 0) -> dict[str, Any]:
    """The normalized score of one policy on one split from its per-test met shares
    ``[seeds][tests]``: ``iqm`` (the interquartile mean over seeds of each seed's normalized
    score) with its stratified-bootstrap 95 % interval ``low``, ``high``
    (:func:`flowtest_env.scoring.stratified_bootstrap`), ``mean`` over seeds, the
    ``worst10`` (the mean normalized score of the worst 10 % of the tests, each test's met
    averaged over seeds) and its raw ``worst10_met``; ``None`` values when there is no scale
    (no floor or ceiling, or the ceiling not above the floor)."""
    from flowtest_env.scoring import normalized, stratified_bootstrap, worst_share_mean

    m = np.asarray(per_seed_tests, dtype=np.float64)
    worst = worst_share_mean(m.mean(axis=0), WORST_SHARE)
    out: dict[str, Any] = {"iqm": None, "low": None, "high": None, "mean": None, "worst10": normalized(worst, floor, ceiling),
                           "worst10_met": worst, "seeds": int(m.shape[0]), "tests": int(m.shape[1])}
    if floor is None or ceiling is None or not ceiling > floor:
        return out
    z = (m - floor) / (ceiling - floor)
    point, low, high = stratified_bootstrap(z, reps=reps, seed=seed)
    out.update(iqm=point, low=low, high=high, mean=float(z.mean()))
    return out


# --------------------------------------------------------------------------- the table


@dataclass
class SystemRuns:
    """What one system did: per seed (or once) and split, the metrics of its greedy and
    sampled play (``None`` where it has no such mode)."""

    name: str
    kind: str  # baseline, floor, reference, system
    runs: list[dict[str, Any]]  # {"seed", "sut", split: {"greedy": metrics|None, "sampled": metrics|None}}


def scale_of(systems: Sequence[SystemRuns]) -> dict[str, dict[str, Any]]:
    """Per split, the floor (random's met) and the ceiling (the best reference's met)."""
    scale: dict[str, dict[str, Any]] = {}
    floor = next((s for s in systems if s.kind == "floor"), None)
    refs = [s for s in systems if s.kind == "reference"]
    for split in SPLIT_NAMES:
        f = floor.runs[0][split]["sampled"]["met"] if floor and floor.runs[0].get(split) else None
        best, who = None, None
        for r in refs:
            if r.runs[0].get(split):
                met = r.runs[0][split]["greedy"]["met"]
                if best is None or met > best:
                    best, who = met, r.name
        scale[split] = {"floor": f, "ceiling": best, "ceiling_from": who}
    return scale


def _mode_summary(runs: Sequence[dict[str, Any]], split: str, mode: str, scale: dict[str, Any], reps: int) -> dict[str, Any] | None:
    rows = [r[split][mode] for r in runs if r.get(split) and r[split].get(mode)]
    if not rows:
        return None
    out: dict[str, Any] = {key: mean_ci([r[key] for r in rows]) for key in ("met", "realized", "restrictions", "steps")}
    out["runs_per_test"] = rows[0]["runs"]
    out["test_failures"] = sum(r["test_failures"] for r in rows)
    out["normalized"] = normalized_summary([r["per_test"] for r in rows], scale["floor"], scale["ceiling"], reps)
    return out


def system_entry(s: SystemRuns, scale: dict[str, dict[str, Any]], reps: int) -> dict[str, Any]:
    """A system's entry in ``table.json`` (docs/benchmark-protocol.md, *The results file*)."""
    entry: dict[str, Any] = {"name": s.name, "kind": s.kind, "runs": []}
    for r in s.runs:
        row: dict[str, Any] = {"seed": r["seed"], "sut": r["sut"]}
        for split in SPLIT_NAMES:
            if not r.get(split):
                continue
            main = r[split]["greedy"] or r[split]["sampled"]
            row[split] = {k: main[k] for k in ("met", "realized", "restrictions", "steps", "test_failures")}
            row[split]["greedy"] = r[split]["greedy"]
            row[split]["sampled"] = r[split]["sampled"]
        tr, te = row.get("train"), row.get("test")
        row["gap"] = None if tr is None or te is None or tr["met"] is None or te["met"] is None else tr["met"] - te["met"]
        entry["runs"].append(row)
    for split in SPLIT_NAMES:
        greedy = _mode_summary(s.runs, split, "greedy", scale[split], reps)
        sampled = _mode_summary(s.runs, split, "sampled", scale[split], reps)
        main = greedy or sampled
        if main is None:
            continue
        entry[split] = {k: main[k] for k in ("met", "realized", "restrictions", "steps", "test_failures")}
        entry[split]["headline_mode"] = "greedy" if greedy else "sampled"
        entry[split]["greedy"], entry[split]["sampled"] = greedy, sampled
    entry["gap"] = mean_ci([r["gap"] for r in entry["runs"]])
    return entry


def command_of(config: BenchmarkConfig, out: str = "OUT") -> str:
    """The ``flowtest benchmark`` command that runs ``config`` (every setting that is not
    the default spelled out), for the results file and the leaderboard."""
    import shlex

    d = BenchmarkConfig(config.pool)
    words = ["flowtest", "benchmark", "--pool", config.pool]
    if config.suts != d.suts:
        words += ["--sut", *config.suts]
    if config.algos != d.algos:
        words += ["--algo", *config.algos]
    for name in ("train_count", "validation_count", "test_count", "train_eval_count", "steps", "runs", "curve_seeds",
                 "curve_points", "report_tests", "bootstrap"):
        if getattr(config, name) != getattr(d, name):
            words += [f"--{name.replace('_', '-')}", str(getattr(config, name))]
    if config.seeds != d.seeds:
        words += ["--seeds", *map(str, config.seeds)]
    if config.curve_sizes != d.curve_sizes:
        words += ["--curve-sizes", *map(str, config.curve_sizes)]
    if config.trainer != d.trainer:
        words += ["--trainer", config.trainer]
    words += ["--out", out]
    return " ".join(shlex.quote(w) for w in words)


def _commit() -> str | None:
    try:
        root = Path(__file__).resolve().parents[2]
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=False)
        return out.stdout.strip() or None if out.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def machine() -> dict[str, Any]:
    """Where the benchmark ran: platform, processor, CPU count, load average at the end."""
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "load_average": load, "python": platform.python_version()}


def benchmark_table(config: BenchmarkConfig, splits: dict[str, Split], systems: Sequence[SystemRuns],
                    trained: Sequence[TrainedBaseline], curve: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """The benchmark's results document (``table.json``; docs/benchmark-protocol.md)."""
    scale = scale_of(systems)
    entries = [system_entry(s, scale, config.bootstrap) for s in systems]
    for e in entries:
        if e["kind"] != "baseline":
            continue
        mine = [b for b in trained if b.algo == e["name"] and b.train_tests == config.train_count]
        e["settings"] = baseline_settings(e["name"], config.trainer)
        e["training"] = [
            {"seed": b.seed, "steps": b.steps, "seconds": round(b.seconds, 1), "curve_seconds": round(b.curve_seconds, 1),
             "model": str(b.path), "curve": [[step, rates.get("train"), rates.get("validation")] for step, rates in b.curve]}
            for b in mine
        ]
    baselines = [e for e in entries if e["kind"] == "baseline"]
    headline = {
        "normalized_held_out": {e["name"]: {m: (e["test"][m] or {}).get("normalized") for m in ("greedy", "sampled")}
                                for e in baselines if "test" in e},
        "held_out_gap": {e["name"]: e["gap"] for e in baselines},
    }
    return {
        "format": RESULTS_FORMAT, "version": RESULTS_VERSION,
        "pool": config.pool,
        "command": command_of(config),
        "splits": {s: {"count": len(sp.artifacts), "scored": len(sp.files), "seeds": [sp.seeds[0], sp.seeds[-1]]}
                   for s, sp in splits.items()},
        "config": {"steps": config.steps, "seeds": list(config.seeds), "algos": config.baselines(), "trainer": config.trainer,
                   "runs": config.runs, "curve_points": config.curve_points, "curve_sizes": config.curve(),
                   "curve_seeds": config.curve_seeds, "suts": list(config.suts), "bootstrap": config.bootstrap,
                   "train_eval_count": config.train_eval_count, "report_tests": config.report_tests},
        "budget": {"steps_per_run": config.steps,
                   "training_runs": len(trained),
                   "training_steps": int(sum(b.steps for b in trained))},
        "scale": scale,
        "headline": headline,
        "systems": entries,
        "generalization": curve or [],
        "commit": _commit(),
        "machine": machine(),
    }


def _pct(stat: dict[str, Any] | None) -> str:
    if not stat or stat["mean"] is None:
        return "–"
    ci = "" if stat["ci95"] is None else f" ± {100 * stat['ci95']:.1f}"
    return f"{100 * stat['mean']:.1f} %{ci}"


def _gap(stat: dict[str, Any]) -> str:
    if stat["mean"] is None:
        return "–"
    ci = "" if stat["ci95"] is None else f" ± {100 * stat['ci95']:.1f}"
    return f"{100 * stat['mean']:+.1f} pp{ci}"


def _norm(n: dict[str, Any] | None) -> str:
    if not n or n.get("iqm") is None:
        return "–"
    return f"{n['iqm']:.2f} [{n['low']:.2f}, {n['high']:.2f}]"


def _mode(e: dict[str, Any], split: str, mode: str) -> dict[str, Any] | None:
    s = e.get(split)
    return None if s is None else s.get(mode)


TABLE_COLUMNS = ["system", "kind", "seeds", "held-out normalized, greedy: IQM [95 % CI]", "held-out normalized, sampled",
                 "held-out met, greedy", "held-out met, sampled", "worst 10 % held-out (normalized)", "validation met",
                 "train met", "held-out gap", "held-out realized (of met)"]


def table_rows(doc: dict[str, Any]) -> list[list[str]]:
    """The rows of ``table.md`` (see :data:`TABLE_COLUMNS`)."""
    rows = []
    for e in doc["systems"]:
        seeds = ", ".join(str(r["seed"]) for r in e["runs"]) if e["kind"] == "baseline" else "–"
        g, s = _mode(e, "test", "greedy"), _mode(e, "test", "sampled")
        head = g or s
        worst = "–"
        if head and head["normalized"]["worst10"] is not None:
            worst = f"{head['normalized']['worst10']:.2f} ({100 * head['normalized']['worst10_met']:.1f} % met)"
        rows.append([e["name"], e["kind"], seeds, _norm(g["normalized"] if g else None), _norm(s["normalized"] if s else None),
                     _pct(g["met"] if g else None), _pct(s["met"] if s else None), worst,
                     _pct(e["validation"]["met"] if "validation" in e else None), _pct(e["train"]["met"] if "train" in e else None),
                     _gap(e["gap"]), _pct(e["test"]["realized"] if "test" in e else None)])
    return rows


def headline_text(doc: dict[str, Any]) -> str:
    """One line: each baseline's held-out normalized score (IQM and interval), greedy."""
    parts = []
    for name, modes in doc["headline"]["normalized_held_out"].items():
        parts.append(f"{name} {_norm(modes.get('greedy'))} greedy, {_norm(modes.get('sampled'))} sampled")
    return "held-out normalized score (0 = random, 1 = reference): " + ("; ".join(parts) if parts else "no baseline trained")


def table_markdown(doc: dict[str, Any]) -> str:
    """``table.md``: the headline, the budget, the table, the curve and what the columns mean."""
    sp, cfg, sc = doc["splits"], doc["config"], doc["scale"]

    def frac(x: float | None) -> str:
        return "–" if x is None else f"{100 * x:.1f} %"

    lines = [
        f"# FlowTest benchmark: {doc['pool']}", "",
        f"**{headline_text(doc)}**", "",
        f"Splits: train {sp['train']['count']} tests (the first {sp['train']['scored']} scored), validation "
        f"{sp['validation']['count']}, held-out test {sp['test']['count']} (never seen in training). "
        f"Scale per split (met): floor = random ({_runs(cfg['runs'])} per test) "
        + ", ".join(f"{s} {frac(sc[s]['floor'])}" for s in SPLIT_NAMES)
        + "; ceiling = the best reference " + ", ".join(f"{s} {frac(sc[s]['ceiling'])}" for s in SPLIT_NAMES) + ".", "",
        f"**Budget**: {cfg['steps']:,} time steps per training run, {doc['budget']['training_runs']} runs "
        f"({doc['budget']['training_steps']:,} steps in all, trainer {cfg['trainer']}); training seeds "
        f"{', '.join(map(str, cfg['seeds']))}; the final model is scored (no model selection).", "",
        "| " + " | ".join(TABLE_COLUMNS) + " |", "|" + "---|" * len(TABLE_COLUMNS),
    ]
    lines += ["| " + " | ".join(row) + " |" for row in table_rows(doc)]
    if doc["generalization"]:
        lines += ["", "## Generalization curve (held-out normalized score against training tests)", "",
                  "| training tests | seeds | greedy: IQM [95 % CI] | sampled: IQM [95 % CI] | train met (greedy) |",
                  "|---|---|---|---|---|"]
        for p in doc["generalization"]:
            lines.append(f"| {p['train_tests']:,} | {len(p['seeds'])} | {_norm(p['greedy'])} | {_norm(p['sampled'])} | "
                         f"{frac(p['train_met'])} |")
    lines += [
        "",
        "*Normalized*: (met - floor) / (ceiling - floor) on the split, 0 = random, 1 = the reference; IQM: the "
        "interquartile mean over training seeds of each seed's score; [95 % CI]: stratified bootstrap (seeds resampled, "
        f"tests resampled within each seed), {cfg['bootstrap']} replicates. *Greedy*: each test played once by the most "
        f"likely action; *sampled*: {_runs(cfg['runs'], 'seeded ')} per test drawn from the policy. *Worst 10 %*: the mean "
        "over the 10 % of held-out tests the policy met least often. *Met*: share of runs whose system objective was "
        "met (± 95 % t-interval over seeds). *Realized (of met)*: share of those that also realized the hidden test "
        "objective (the synthesized test guarantees 100 %). *Held-out gap*: train met minus held-out met per seed.",
    ]
    bugs = [e["name"] for e in doc["systems"] if any(e.get(s, {}).get("test_failures") for s in SPLIT_NAMES)]
    if bugs:
        lines += ["", f"**FLOWTEST BUG: a test failed its guarantee for {', '.join(bugs)}; see report.html.**"]
    return "\n".join(lines) + "\n"


COLORS = {"maskable-ppo": "#1f77b4", "recurrent-ppo": "#d62728", "plr-ppo": "#9467bd"}


def plot_learning_curves(doc: dict[str, Any], path: Path) -> None:
    """Share of tests met against time steps, per baseline: on the scored train tests
    (solid) and the validation tests (dashed), the mean over seeds with its 95 % band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for e in doc["systems"]:
        if e["kind"] != "baseline" or not e.get("training"):
            continue
        color = COLORS.get(e["name"], None)
        steps = [p[0] for p in e["training"][0]["curve"]]
        for col, split, style in ((1, "train", "-"), (2, "validation", "--")):
            runs = [[p[col] for p in t["curve"]] for t in e["training"] if len(t["curve"]) == len(steps)]
            stats = [mean_ci([r[k] for r in runs]) for k in range(len(steps))]
            if any(s["mean"] is None for s in stats):
                continue
            mean = np.array([100 * s["mean"] for s in stats])
            ax.plot(steps, mean, style, color=color, lw=2, label=f"{e['name']}, {split} tests")
            if len(runs) > 1:
                half = np.array([100 * (s["ci95"] or 0.0) for s in stats])
                ax.fill_between(steps, np.clip(mean - half, 0, 100), np.clip(mean + half, 0, 100), color=color, alpha=0.12)
    floor = doc["scale"]["validation"]["floor"]
    if floor is not None:
        ax.axhline(100 * floor, color="#7f7f7f", lw=1, ls=":", label="random (validation)")
    ceiling = doc["scale"]["validation"]["ceiling"]
    if ceiling is not None:
        ax.axhline(100 * ceiling, color="#2ca02c", lw=1, ls=":", label="reference (validation)")
    ax.set_xlabel("time steps")
    ax.set_ylabel("tests whose system objective is met (%)")
    ax.set_ylim(-3, 103)
    ax.grid(alpha=0.3)
    ax.set_title(f"{doc['pool']}: greedy play during training (mean over seeds, 95 % band)", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_generalization(doc: dict[str, Any], path: Path) -> None:
    """The held-out normalized score (IQM with its 95 % interval) against the number of
    training tests (log scale), greedy and sampled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = doc["generalization"]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for mode, color in (("greedy", "#1f77b4"), ("sampled", "#ff7f0e")):
        xs = [p["train_tests"] for p in pts if p[mode]["iqm"] is not None]
        if not xs:
            continue
        ys = np.array([p[mode]["iqm"] for p in pts if p[mode]["iqm"] is not None])
        lo = np.array([p[mode]["low"] for p in pts if p[mode]["iqm"] is not None])
        hi = np.array([p[mode]["high"] for p in pts if p[mode]["iqm"] is not None])
        ax.plot(xs, ys, "o-", color=color, lw=2, label=f"{pts[0]['algo']}, {mode}")
        ax.fill_between(xs, lo, hi, color=color, alpha=0.15)
    ax.axhline(0.0, color="#7f7f7f", lw=1, ls=":", label="random (0)")
    ax.axhline(1.0, color="#2ca02c", lw=1, ls=":", label="reference (1)")
    ax.set_xscale("log", base=2)
    ax.set_xlabel("training tests")
    ax.set_ylabel("held-out normalized score (IQM, 95 % CI)")
    ax.grid(alpha=0.3)
    ax.set_title(f"{doc['pool']}: generalization ({doc['splits']['test']['count']} held-out tests)", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --------------------------------------------------------------------------- the whole run


def _split_infos(splits: dict[str, Split], out: Path, shown: int) -> list[TestInfo]:
    """What the report shows of each split's column: the first test's picture and the
    pool's objectives (the same formulas for every test of a pool)."""
    from flowtest_env.envs import default_max_steps
    from flowtest_env.game import TestGame

    from .filmstrip import start_picture

    infos = []
    for name in REPORT_SPLITS:
        split = splits[name]
        art = split.artifacts[0]
        game = TestGame(art)
        picture = f"tests/{split.name}-split-first.png"
        write_atomically(out / picture, partial(start_picture, game))
        infos.append(TestInfo(
            env_id=_report_label(split, shown), problem=f"{art.name} (the first of {len(split.seeds)})", kind=str(art.kind),
            system_objective=str(art.objectives.get("system", "")), test_objective=str(art.objectives.get("test", "")),
            max_steps=default_max_steps(game), picture=picture,
        ))
    return infos


def _report_label(split: Split, shown: int) -> str:
    return f"{split.label.rsplit(' (', 1)[0]} (report: the first {min(shown, len(split.files))} tests)"


def score_all(config: BenchmarkConfig, splits: dict[str, Split], trained: Sequence[TrainedBaseline],
              say: Callable[[str], None]) -> tuple[list[SystemRuns], dict[str, dict[str, list[Trace]]]]:
    """Score every system on every split (module docstring, step 3); return the systems'
    runs and the single-env traces (for the report)."""
    from flowtest_env.game import TestGame
    from flowtest_env.scoring import play_batch

    games = {name: [TestGame(a) for a in split.scored] for name, split in splits.items()}

    def batched(policies: dict[str, Any]) -> dict[str, Any]:
        row: dict[str, Any] = {}
        for split in SPLIT_NAMES:
            row[split] = {"greedy": None, "sampled": None}
            for mode, policy in policies.items():
                if mode == "sampled" and "greedy" in policies and split != "test":
                    continue  # a policy with a greedy mode is sampled on the held-out tests only (the time budget)
                v = play_batch(policy, games[split], 1 if mode == "greedy" else config.runs, RUN_SEED)
                row[split][mode] = verdict_metrics(v)
        return row

    systems: list[SystemRuns] = []
    for algo in config.baselines():
        runs = []
        for b in (b for b in trained if b.algo == algo and b.train_tests == config.train_count):
            say(f"scoring {algo} seed {b.seed} (greedy, and {_runs(config.runs, 'sampled ')} per test)")
            runs.append({"seed": b.seed, "sut": b.sut, **batched(b.policies)})
        systems.append(SystemRuns(algo, "baseline", runs))
    single: list[str] = []
    for sut in config.others():
        policies = batched_system(sut, config.runs)
        kind = "floor" if sut == RANDOM else "reference" if sut in REFERENCES else "system"
        if policies is None:
            single.append(sut)
            systems.append(SystemRuns(sut, kind, []))
            continue
        say(f"scoring {sut} in one batch per split")
        systems.append(SystemRuns(sut, kind, [{"seed": None, "sut": sut, **batched(policies)}]))
    traces: dict[str, dict[str, list[Trace]]] = {}
    report_suts = [RANDOM] + [b.sut for b in _report_models(config, trained)]
    for name, split in splits.items():
        say(f"scoring {', '.join(single) or 'no system'} through the single env on the {len(split.files)} {name} tests"
            + (" and the report's sample" if name in REPORT_SPLITS else ""))
        traces[name] = score_systems(single, split)
        if name in REPORT_SPLITS:
            traces[name].update(score_systems(report_suts, split, config.report_tests))
    for s in systems:
        if s.name in single:
            s.runs.append({"seed": None, "sut": s.name, **{n: {"greedy": verdict_metrics(trace_verdicts(traces[n][s.name])),
                                                                "sampled": None} for n in SPLIT_NAMES}})
    return systems, traces


def _report_models(config: BenchmarkConfig, trained: Sequence[TrainedBaseline]) -> list[TrainedBaseline]:
    """The models the report shows: each baseline's first seed."""
    out = []
    for algo in config.baselines():
        first = next((b for b in trained if b.algo == algo and b.train_tests == config.train_count), None)
        if first is not None:
            out.append(first)
    return out


def generalization_curve(config: BenchmarkConfig, splits: dict[str, Split], trained: list[TrainedBaseline],
                         main: SystemRuns | None, scale: dict[str, Any], say: Callable[[str], None]) -> list[dict[str, Any]]:
    """The generalization curve (module docstring, step 5): per training-set size, the
    held-out normalized score (greedy and sampled) of the first baseline's runs on that
    many train tests (already trained), and its greedy met on its own training tests."""
    from flowtest_env.game import TestGame
    from flowtest_env.scoring import play_batch

    if main is None or not main.runs:
        return []
    algo = main.name
    held = [TestGame(a) for a in splits["test"].scored]
    points = []
    for n in config.curve():
        if n == config.train_count:
            rows = [(r["test"]["greedy"]["per_test"], r["test"]["sampled"]["per_test"], r["train"]["greedy"]["met"])
                    for r in main.runs]
            seeds = [int(r["seed"]) for r in main.runs]
        else:
            rows = []
            runs = [b for b in trained if b.algo == algo and b.train_tests == n]
            seeds = [b.seed for b in runs]
            own = [TestGame(a) for a in splits["train"].artifacts[:min(n, config.scored("train"))]]
            if runs:
                say(f"generalization curve: scoring {len(runs)} runs of {algo} on {n} train tests")
            for b in runs:
                g = play_batch(b.policies["greedy"], held, 1, RUN_SEED)
                s = play_batch(b.policies["sampled"], held, config.runs, RUN_SEED)
                tr = play_batch(b.policies["greedy"], own, 1, RUN_SEED)
                rows.append((verdict_metrics(g)["per_test"], verdict_metrics(s)["per_test"], verdict_metrics(tr)["met"]))
        if not rows:
            continue
        points.append({
            "algo": algo, "train_tests": n, "seeds": seeds,
            "greedy": normalized_summary([r[0] for r in rows], scale["floor"], scale["ceiling"], config.bootstrap),
            "sampled": normalized_summary([r[1] for r in rows], scale["floor"], scale["ceiling"], config.bootstrap),
            "train_met": float(np.mean([r[2] for r in rows])),
        })
    return points


def run_benchmark(config: BenchmarkConfig, out: Path, say: Callable[[str], None] = lambda _: None,
                  progress_bar: bool = False,
                  source: Callable[[str, str, int], Sequence[TestArtifact]] | None = None) -> dict[str, Any]:
    """Run the benchmark (see the module docstring) into the folder ``out`` (created; it
    is not checked here: the command checks it first) and return ``table.json``'s document.
    ``source`` loads the pool's tests (default :func:`flowtest_env.pools.load_pool`)."""
    t_start = time.perf_counter()
    check_config(config)
    commit = _commit()  # the code this run uses (the tree may move on while it runs)
    out.mkdir(parents=True, exist_ok=True)
    say(f"loading the pool {config.pool}: {config.train_count} train, {config.validation_count} validation and "
        f"{config.test_count} held-out tests")
    t0 = time.perf_counter()
    splits = load_splits(config, out, progress=progress_bar, source=source)
    pool_seconds = time.perf_counter() - t0
    jobs = [TrainingJob(algo, seed, config.train_count, f"{algo}-seed{seed}")
            for algo in config.baselines() for seed in config.seeds]
    if config.baselines():
        first = config.baselines()[0]
        jobs += [TrainingJob(first, seed, n, f"curve-{first}-{n}-seed{seed}")
                 for n in config.curve() if n != config.train_count for seed in config.seeds[:config.curve_seeds]]
    t0 = time.perf_counter()
    trained = train_all(config, jobs, splits, out, say, progress_bar)
    train_seconds = time.perf_counter() - t0
    if trained and config.trainer == "native":
        import torch

        torch.set_num_threads(1)  # as the trainer: on shared cores one thread plays the batches fastest
    t0 = time.perf_counter()
    systems, traces = score_all(config, splits, trained, say)
    score_seconds = time.perf_counter() - t0
    scale = scale_of(systems)
    main = next((s for s in systems if s.kind == "baseline"), None)
    t0 = time.perf_counter()
    curve = generalization_curve(config, splits, trained, main, scale["test"], say)
    curve_seconds = time.perf_counter() - t0
    doc = benchmark_table(config, splits, systems, trained, curve)
    doc["commit"] = commit
    say("writing the table, the curves and the report")
    cells = []
    for name in REPORT_SPLITS:
        label = _report_label(splits[name], config.report_tests)
        for sut, runs in traces[name].items():
            cells.append(Cell(label, sut, runs[:config.report_tests], RUN_SEED, 0.0))
    cells.sort(key=lambda c: c.sut)
    write_report(cells, out, _split_infos(splits, out, config.report_tests))
    doc["seconds"] = {"pool": round(pool_seconds, 1), "training": round(train_seconds, 1),
                      "training_cpu": round(sum(b.seconds for b in trained), 1),
                      "scoring": round(score_seconds, 1), "generalization": round(curve_seconds, 1),
                      "total": round(time.perf_counter() - t_start, 1)}
    doc["outputs"] = {k: str((out / v).resolve()) for k, v in OUTPUTS.items()}
    if any(e["kind"] == "baseline" and e.get("training") for e in doc["systems"]):
        write_atomically(out / OUTPUTS["curves"], lambda tmp: plot_learning_curves(doc, tmp))
    else:
        doc["outputs"].pop("curves")
    if doc["generalization"]:
        write_atomically(out / OUTPUTS["generalization"], lambda tmp: plot_generalization(doc, tmp))
    else:
        doc["outputs"].pop("generalization")
    write_text(out / OUTPUTS["table_md"], table_markdown(doc))
    write_text(out / OUTPUTS["table_json"], json.dumps(json_safe(doc), indent=1) + "\n")
    return doc


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""

    def write(tmp: Path) -> None:
        tmp.write_text(text)

    write_atomically(path, write)


OUTPUTS = {"table_md": "table.md", "table_json": "table.json", "curves": "learning-curves.png",
           "generalization": "generalization.png", "report": "report.html"}
"""The main files a benchmark writes into ``--out``."""


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``flowtest benchmark`` (defaults: :class:`BenchmarkConfig`)."""
    d = BenchmarkConfig("")
    p.add_argument("--pool", required=True, metavar="NAME",
                   help="the test pool: <family><n>/<size>x<size>[/<world>][/<kind>], e.g. reachability1/5x5 (flowtest_env.pools)")
    p.add_argument("--sut", action="extend", nargs="+", metavar="SYSTEM",
                   help="systems (repeatable): ppo (train the baselines of --algo), maskable-ppo, recurrent-ppo, plr-ppo, "
                        "scripted:<name>, gr1, ppo:PATH, python:MODULE:NAME (a planner, or a batched policy marked "
                        "batched = True), cmd:COMMAND; random and the references are always scored "
                        f"(default: {' '.join(DEFAULT_SUTS)})")
    p.add_argument("--algo", nargs="+", choices=BENCH_ALGOS, default=list(d.algos),
                   help=f"the baselines --sut ppo trains (default: {' '.join(d.algos)}; plr-ppo: native trainer only)")
    p.add_argument("--train-count", type=positive_int, default=None,
                   help=f"tests of the train split to train on (default {d.train_count})")
    p.add_argument("--validation-count", type=positive_int, default=None,
                   help=f"tests of the validation split, for the learning curves (default {d.validation_count})")
    p.add_argument("--test-count", type=positive_int, default=None,
                   help=f"held-out tests of the test split to score on (default {d.test_count}, or all of a standard "
                        "pool's where it ships fewer: 250 for reachability1/5x5/blocked/agent-v1)")
    p.add_argument("--train-eval-count", type=positive_int, default=d.train_eval_count,
                   help=f"train tests scored (the first N; default {d.train_eval_count})")
    p.add_argument("--steps", type=positive_int, default=d.steps,
                   help=f"training time steps per baseline and seed (default {d.steps})")
    p.add_argument("--seeds", nargs="+", type=nonnegative_int, default=list(d.seeds),
                   help="training seeds; the intervals are over them and the tests (default 0..9)")
    p.add_argument("--runs", type=positive_int, default=d.runs,
                   help=f"sampled runs per test of a stochastic policy (and of random) (default {d.runs})")
    p.add_argument("--curve-sizes", nargs="*", type=positive_int, default=list(d.curve_sizes),
                   help="training-set sizes of the generalization curve besides --train-count "
                        f"(default {' '.join(map(str, d.curve_sizes))}; none: give the flag alone)")
    p.add_argument("--curve-seeds", type=nonnegative_int, default=d.curve_seeds,
                   help=f"training seeds per generalization-curve size (the first N of --seeds; default {d.curve_seeds})")
    p.add_argument("--curve-points", type=positive_int, default=d.curve_points,
                   help=f"learning-curve measurements per training run, besides the start (default {d.curve_points})")
    p.add_argument("--report-tests", type=positive_int, default=d.report_tests,
                   help=f"tests of each split the HTML report shows (default {d.report_tests})")
    p.add_argument("--bootstrap", type=positive_int, default=d.bootstrap,
                   help=f"bootstrap replicates of the intervals (default {d.bootstrap})")
    p.add_argument("--workers", type=positive_int, default=d.workers,
                   help=f"training runs at once, one process each (native trainer; default {d.workers}: one per CPU, "
                        "at most 2); the models do not depend on it")
    p.add_argument("--trainer", choices=TRAINERS, default=d.trainer,
                   help="who trains the baselines: native (FlowTest's batched PPO, default) or sb3 (stable-baselines3)")
    p.add_argument("--trust-model", action="store_true",
                   help="load stable-baselines3 zips given as --sut ppo:PATH, which unpickles them (code from the file "
                        "runs); native checkpoints never need it")
    p.add_argument("--out", type=Path, required=True,
                   help="output folder (table.md, table.json, learning-curves.png, generalization.png, report.html, "
                        "models/, pool/); an existing non-empty folder is refused unless --force")
    p.add_argument("--force", action="store_true", help="overwrite the files of an earlier benchmark in --out")
    p.add_argument("--json", action="store_true", help="print table.json's document (only it) on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def _check_out(out: Path, force: bool) -> None:
    """Refuse to overwrite: an existing non-empty ``out`` needs ``--force``."""
    if out.is_dir() and not force:
        try:
            used = any(out.iterdir())
        except OSError as exc:
            raise ProblemError(f"cannot read the benchmark folder {str(out)!r}: {exc.strerror or exc}") from None
        if used:
            what = "an earlier benchmark" if (out / BENCHMARK_MARKER).exists() else "files"
            raise ProblemError(f"benchmark folder {str(out)!r} already holds {what}; use --force to overwrite, "
                               "or choose another folder")
    prepare_output_folder(out, BENCHMARK_MARKER, force, "benchmark folder")


def run(args: argparse.Namespace) -> int:
    """``flowtest benchmark``: check everything, run, print the table (or the JSON)."""
    from synthesis.routing.solver_control import stdout_guard

    given = {f"{split}_count": getattr(args, f"{split}_count") for split in ("train", "validation", "test")}
    config = BenchmarkConfig.for_pool(
        args.pool, suts=tuple(args.sut or DEFAULT_SUTS), algos=tuple(dict.fromkeys(args.algo)),
        **{k: v for k, v in given.items() if v is not None},
        train_eval_count=args.train_eval_count, steps=args.steps, seeds=tuple(dict.fromkeys(args.seeds)), runs=args.runs,
        curve_sizes=tuple(args.curve_sizes), curve_seeds=args.curve_seeds, curve_points=args.curve_points,
        trainer=args.trainer, report_tests=args.report_tests, bootstrap=args.bootstrap, workers=args.workers,
    )
    if args.trust_model:
        from agents.checkpoint import trust_pickled_models

        trust_pickled_models(True)
    check_config(config)
    _check_out(args.out, args.force)
    dropped = [n for n in config.curve_sizes if n > config.train_count]  # train_count is on the curve anyway
    if dropped and config.baselines():
        sys.stderr.write(f"flowtest: warning: curve sizes {' '.join(map(str, dropped))} (--curve-sizes) are above "
                         f"--train-count {config.train_count}: left out of the generalization curve\n")

    def say(message: str) -> None:
        if not args.quiet:
            sys.stderr.write(f"flowtest: {message}\n")
            sys.stderr.flush()

    with stdout_guard():  # stdout holds our table or JSON only, whatever a library prints meanwhile
        doc = run_benchmark(config, args.out, say, progress_bar=not args.quiet and sys.stderr.isatty())
    if args.json:
        print_json(json_safe(doc))
        return EXIT_OK
    sys.stdout.write(table_markdown(doc).split("\n", 2)[2])
    sys.stdout.write(f"\ntime: {doc['seconds']['total']:.0f} s\n")
    for key in ("table_md", "table_json", "curves", "generalization", "report"):
        if key in doc["outputs"]:
            sys.stdout.write(f"{key.replace('_', '.')}: {doc['outputs'][key]}\n")
    sys.stdout.flush()
    return EXIT_OK


COMMAND = Command("benchmark", "train the learned baselines on a test pool and score them on held-out tests, "
                               "between a random floor and a reference ceiling", add_arguments, run)
