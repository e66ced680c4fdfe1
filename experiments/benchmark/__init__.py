"""The benchmark protocol: the library behind ``flowtest benchmark --pool NAME``.

:func:`benchmark` trains the learned baselines on a test pool and scores them, the random
floor, the references and any other system on tests they never trained on, and writes
``table.md``, ``table.json``, the curves and the report (docs/benchmark-protocol.md).
:class:`BenchmarkConfig` is what it runs; :func:`run_benchmark` runs a checked configuration
into a prepared folder.

One job per module, in the protocol's order: :mod:`~experiments.benchmark.config` (the
configuration and its checks), :mod:`~experiments.benchmark.pool` (the splits),
:mod:`~experiments.benchmark.models` (saved models as batched policies),
:mod:`~experiments.benchmark.training_runs` (the training runs, several processes at once),
:mod:`~experiments.benchmark.scoring` (every system on every split, the generalization curve),
:mod:`~experiments.benchmark.statistics` (means, intervals, normalized scores),
:mod:`~experiments.benchmark.table` (``table.json`` and ``table.md``),
:mod:`~experiments.benchmark.resume` (the stored configuration and the finished runs ``--resume`` keeps),
:mod:`~experiments.benchmark.plots` (the pictures) and :mod:`~experiments.benchmark.protocol`
(the whole run).

Example::

    from experiments.benchmark import benchmark

    doc = benchmark("reachability1/5x5-v2", "bench", seeds=(0, 1, 2), steps=250_000)
    doc["headline"]["normalized_held_out"]["maskable-ppo"]["greedy"]["iqm"]
"""

from __future__ import annotations

from .config import (
    BENCH_ALGOS,
    DEFAULT_SUTS,
    POOL_ENV_ID,
    RANDOM,
    REFERENCES,
    SPLIT_NAMES,
    BenchmarkConfig,
    baseline_settings,
    check_config,
    command_of,
    default_counts,
)
from .models import batch_verdicts
from .pool import Split, games_and_budgets, load_splits
from .protocol import BENCHMARK_MARKER, OUTPUTS, benchmark, check_systems, prepare_benchmark_folder, run_benchmark
from .resume import CONFIG_FILE, config_document
from .scoring import score_systems, split_metrics
from .statistics import SystemRuns, mean_ci
from .table import benchmark_table, table_markdown
from .training_runs import train_baseline

__all__ = [
    "BENCHMARK_MARKER",
    "BENCH_ALGOS",
    "CONFIG_FILE",
    "DEFAULT_SUTS",
    "OUTPUTS",
    "POOL_ENV_ID",
    "RANDOM",
    "REFERENCES",
    "SPLIT_NAMES",
    "BenchmarkConfig",
    "Split",
    "SystemRuns",
    "baseline_settings",
    "batch_verdicts",
    "benchmark",
    "benchmark_table",
    "check_config",
    "check_systems",
    "config_document",
    "command_of",
    "default_counts",
    "games_and_budgets",
    "load_splits",
    "mean_ci",
    "prepare_benchmark_folder",
    "run_benchmark",
    "score_systems",
    "split_metrics",
    "table_markdown",
    "train_baseline",
]
