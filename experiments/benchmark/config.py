"""The benchmark's configuration: what ``flowtest benchmark`` runs, checked before any work.

:class:`BenchmarkConfig` holds every setting (its defaults are the protocol's,
docs/benchmark-protocol.md); :func:`check_config` refuses a bad one as invalid input;
:func:`command_of` writes the command that runs it. The constants name the protocol's
systems (the baselines, the :data:`RANDOM` floor, the :data:`REFERENCES`), the pool's splits
and the seed of every scored run.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

from experiments.training.rl import require_native, require_rl
from experiments.training.settings import ALGOS, DEFAULTS, TRAINERS, check_settings, native_settings
from synthesis.model.errors import ProblemError

from .systems import SystemSpec, check_systems, parse_systems

POOL_ENV_ID = "FlowTest-RandomGrid-v0"
"""The env the baselines train on (its ``pool``, ``split``, ``count`` options)."""

BENCH_ALGOS: tuple[str, ...] = (*ALGOS, "plr-ppo", "counts-ppo")
"""The baselines ``--algo`` may name: ``flowtest train``'s algorithms, PPO with
prioritized level replay and PPO with the counting memory (native trainer only)."""

DEFAULT_ALGOS: tuple[str, ...] = ("maskable-ppo",)
"""The baselines ``--sut ppo`` trains by default (the others on request: the time budget)."""

BASELINES: dict[str, dict[str, Any]] = {
    "maskable-ppo": {"algo": "maskable-ppo", "memory": "visited"},
    "recurrent-ppo": {"algo": "recurrent-ppo", "memory": "none", "batch_size": 1024, "n_epochs": 4, "lstm_hidden_size": 64},
}
"""Settings of each baseline with ``--trainer sb3``, over ``flowtest train``'s
:data:`~experiments.training.settings.DEFAULTS` (8 envs x 128 steps per rollout, learning rate 1e-3,
MLP 64 x 64, shaping 10 towards the system's own goal). MaskablePPO remembers the places
it visited (the memory wrapper; a reactive test answers the run's history, which the
observation does not show); RecurrentPPO has its LSTM instead, and trains on whole
rollouts (one minibatch of 1,024 steps, 4 epochs, 64 LSTM units) because sb3-contrib
steps an LSTM through every episode boundary of a minibatch in Python, which is its cost."""

NATIVE_BASELINES: dict[str, dict[str, Any]] = {
    "maskable-ppo": {"algo": "ppo", "memory": "visited", "device": "cpu"},
    "recurrent-ppo": {"algo": "recurrent-ppo", "device": "cpu"},
    "plr-ppo": {"algo": "ppo", "memory": "visited", "device": "cpu"},
    "counts-ppo": {"algo": "ppo", "memory": "counts", "device": "cpu"},
}
"""Settings of each baseline with the native trainer (the default), over
:data:`~experiments.training.settings.NATIVE_DEFAULTS`: masked PPO with an MLP and the visited-places
memory, masked PPO with a GRU (its own memory), the first with prioritized level replay
(:data:`LEVEL_SAMPLING`), and the first with the counting memory (how often each place was
occupied, capped at 4: ``flowtest_env.memory``), under which a greedy policy's observation
keeps changing in a two-cell loop, so it can leave it; on the CPU, so a seed gives the same table."""

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

SELECTIONS: tuple[str, ...] = ("validation", "final")
"""Which model of a training run is scored (``--select``): the checkpoint of the curve
evaluation with the best greedy met on the validation tests (the latest of equals; the
protocol's default), or the final one."""

CURVE_TRAIN_TESTS = 256
"""The learning curves watch at most this many train tests (the first; the final score
uses ``train_eval_count``): each curve point plays them, inside the training time."""


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
    select: str = "validation"
    report_tests: int = 20
    bootstrap: int = 2000
    workers: int = field(default_factory=lambda: default_workers())
    parallel: str = "processes"

    @classmethod
    def for_pool(cls, pool: str, **settings: Any) -> BenchmarkConfig:
        """The configuration ``flowtest benchmark --pool POOL`` runs, with ``settings`` (any
        field) given: the split counts not given are :func:`default_counts`, so a standard
        pool that ships a smaller split is scored on all of it, as the command line does,
        instead of building the rest on demand (``BenchmarkConfig(pool)`` keeps the
        protocol's counts).

        Example::

            BenchmarkConfig.for_pool("reachability1/5x5/blocked/agent-v2").test_count  # 250
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
        """The names of the systems scored as they are (:meth:`systems`)."""
        return [s.name for s in self.systems()]

    def systems(self) -> list[SystemSpec]:
        """The systems scored as they are: the floor, the references, and any other
        (``ppo:PATH``, ``ppo:runs/*.zip``, ``NAME=python:M:F(...)``, ...; one seed per member,
        :mod:`~experiments.benchmark.systems`), in that order.

        Raises
        ------
        ProblemError
            On a ``NAME=`` that names a system already scored, or a pattern matching no file.
        """
        given = [s for s in self.suts if s != "ppo" and s not in BENCH_ALGOS and s not in (RANDOM, *REFERENCES)]
        fixed = [SystemSpec(RANDOM, "floor", (RANDOM,)), *(SystemSpec(r, "reference", (r,)) for r in REFERENCES)]
        return fixed + parse_systems(given, reserved=["ppo", RANDOM, *REFERENCES, *BENCH_ALGOS])

    def counts(self) -> dict[str, int]:
        """Tests loaded per split."""
        return {"train": self.train_count, "validation": self.validation_count, "test": self.test_count}

    def scored(self, split: str) -> int:
        """Tests scored per split (the train split: its first ``train_eval_count``)."""
        return min(self.train_count, self.train_eval_count) if split == "train" else self.counts()[split]

    def left_out_curve_sizes(self) -> list[int]:
        """The ``curve_sizes`` above ``train_count``, which the generalization curve leaves out
        (``train_count`` itself is on it anyway)."""
        return [n for n in self.curve_sizes if n > self.train_count]

    def curve(self) -> list[int]:
        """The generalization curve's training-set sizes: ``curve_sizes`` below
        ``train_count``, then ``train_count`` (the main runs)."""
        return sorted({n for n in self.curve_sizes if 0 < n < self.train_count} | {self.train_count})


PARALLEL: tuple[str, ...] = ("serial", "processes", "ray")
"""Where the training runs go (``--parallel``): one after another in this process, ``workers``
local processes at once, or Ray tasks (a local Ray, or the cluster ``RAY_ADDRESS`` names).
The models, and so the table, do not depend on it."""


def require_ray() -> None:
    """Refuse ``--parallel ray`` without Ray installed, as invalid input.

    Raises
    ------
    ProblemError
        If ``ray`` cannot be imported.
    """
    import importlib.util

    if importlib.util.find_spec("ray") is None:
        raise ProblemError("--parallel ray needs Ray: pip install 'ray[default]'")


def runs_text(n: int, what: str = "") -> str:
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
    from flowtest_env.pools import parse_pool, pool_seeds

    try:
        if is_standard_pool(config.pool):
            from flowtest_env.standard_pools import standard_pool

            standard_pool(config.pool)  # a known id and version
        else:
            parse_pool(config.pool)
        for split, count in config.counts().items():
            pool_seeds(config.pool, split, count)
    except ValueError as exc:
        raise ProblemError(f"--pool {config.pool}: {exc}") from None
    if not config.suts:
        raise ProblemError("no system to benchmark: give --sut ppo and/or a system such as scripted:replanner")
    check_systems(config.systems())
    if config.parallel not in PARALLEL:
        raise ProblemError(f"unknown --parallel {config.parallel!r}; expected one of {', '.join(PARALLEL)}")
    if config.parallel == "ray" and config.baselines():
        require_ray()
    if "ppo" in config.suts and not config.algos:
        raise ProblemError("--sut ppo needs at least one --algo")
    for algo in config.algos:
        if algo not in BENCH_ALGOS:
            raise ProblemError(f"unknown --algo {algo!r}; expected one of {', '.join(BENCH_ALGOS)}")
    if config.trainer not in TRAINERS:
        raise ProblemError(f"unknown --trainer {config.trainer!r}; expected one of {', '.join(TRAINERS)}")
    if config.select not in SELECTIONS:
        raise ProblemError(f"unknown --select {config.select!r}; expected one of {', '.join(SELECTIONS)}")
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

        default_counts("reachability1/5x5/blocked/agent-v2")  # {'train': 4096, 'validation': 256, 'test': 250}
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
    for name in (
        "train_count",
        "validation_count",
        "test_count",
        "train_eval_count",
        "steps",
        "runs",
        "curve_seeds",
        "curve_points",
        "report_tests",
        "bootstrap",
    ):
        if getattr(config, name) != getattr(d, name):
            words += [f"--{name.replace('_', '-')}", str(getattr(config, name))]
    if config.seeds != d.seeds:
        words += ["--seeds", *map(str, config.seeds)]
    if config.curve_sizes != d.curve_sizes:
        words += ["--curve-sizes", *map(str, config.curve_sizes)]
    if config.trainer != d.trainer:
        words += ["--trainer", config.trainer]
    if config.select != d.select:
        words += ["--select", config.select]
    words += ["--out", out]
    return " ".join(shlex.quote(w) for w in words)
