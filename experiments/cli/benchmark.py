"""``flowtest benchmark --pool NAME``: the learned baselines on a test pool, scored by a fixed
protocol on tests they never trained on, between a random floor and a reference ceiling.

This module parses the arguments into a :class:`~experiments.benchmark.BenchmarkConfig`,
checks it and the output folder, and calls the library (:mod:`experiments.benchmark`, whose
:mod:`~experiments.benchmark.protocol` describes the protocol step by step;
docs/benchmark-protocol.md has the reasons for each choice); it prints the table (or, with
``--json``, ``table.json``'s document alone) and where the files are.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from experiments import benchmark as library
from experiments.benchmark import BENCH_ALGOS, DEFAULT_SUTS, BenchmarkConfig, prepare_benchmark_folder, table_markdown
from experiments.benchmark.config import PARALLEL, SELECTIONS
from experiments.outputs import json_safe, print_json
from experiments.training.settings import TRAINERS

from .arguments import add_trust_model, apply_trust_model, nonnegative_int, positive_int
from .command import Command
from .exits import EXIT_OK


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``flowtest benchmark`` (defaults: :class:`BenchmarkConfig`)."""
    d = BenchmarkConfig("")
    p.add_argument(
        "--pool", required=True, metavar="NAME", help="the test pool: <family><n>/<size>x<size>[/<world>][/<kind>], e.g. reachability1/5x5 (flowtest_env.pools)"
    )
    p.add_argument(
        "--sut",
        action="extend",
        nargs="+",
        metavar="SYSTEM",
        help="systems (repeatable): ppo (train the baselines of --algo), maskable-ppo, recurrent-ppo, plr-ppo, counts-ppo, "
        "scripted:<name>, gr1, ppo:PATH, python:MODULE:NAME[(ARGS)] (a planner, or the loader of a batched "
        "policy marked batched = True), cmd:COMMAND; one system with a seed per file: 'ppo:runs/*.zip', "
        "'python:MODULE:NAME@runs/*.pt'; NAME=SYSTEM names a system, and NAME= repeated adds a seed per "
        "entry (docs/benchmark-protocol.md); random and the references are always scored "
        f"(default: {' '.join(DEFAULT_SUTS)})",
    )
    p.add_argument(
        "--algo",
        nargs="+",
        choices=BENCH_ALGOS,
        default=list(d.algos),
        help=f"the baselines --sut ppo trains (default: {' '.join(d.algos)}; plr-ppo, counts-ppo: native trainer only)",
    )
    p.add_argument("--train-count", type=positive_int, default=None, help=f"tests of the train split to train on (default {d.train_count})")
    p.add_argument(
        "--validation-count", type=positive_int, default=None, help=f"tests of the validation split, for the learning curves (default {d.validation_count})"
    )
    p.add_argument(
        "--test-count",
        type=positive_int,
        default=None,
        help=f"held-out tests of the test split to score on (default {d.test_count}, or all of a standard "
        "pool's where it ships fewer: 250 for reachability1/5x5/blocked/agent-v2)",
    )
    p.add_argument("--train-eval-count", type=positive_int, default=d.train_eval_count, help=f"train tests scored (the first N; default {d.train_eval_count})")
    p.add_argument("--steps", type=positive_int, default=d.steps, help=f"training time steps per baseline and seed (default {d.steps})")
    p.add_argument(
        "--seeds", nargs="+", type=nonnegative_int, default=list(d.seeds), help="training seeds; the intervals are over them and the tests (default 0..9)"
    )
    p.add_argument("--runs", type=positive_int, default=d.runs, help=f"sampled runs per test of a stochastic policy (and of random) (default {d.runs})")
    p.add_argument(
        "--curve-sizes",
        nargs="*",
        type=positive_int,
        default=list(d.curve_sizes),
        help=f"training-set sizes of the generalization curve besides --train-count (default {' '.join(map(str, d.curve_sizes))}; none: give the flag alone)",
    )
    p.add_argument(
        "--curve-seeds",
        type=nonnegative_int,
        default=d.curve_seeds,
        help=f"training seeds per generalization-curve size (the first N of --seeds; default {d.curve_seeds})",
    )
    p.add_argument(
        "--curve-points",
        type=positive_int,
        default=d.curve_points,
        help=f"learning-curve measurements per training run, besides the start (default {d.curve_points})",
    )
    p.add_argument("--report-tests", type=positive_int, default=d.report_tests, help=f"tests of each split the HTML report shows (default {d.report_tests})")
    p.add_argument("--bootstrap", type=positive_int, default=d.bootstrap, help=f"bootstrap replicates of the intervals (default {d.bootstrap})")
    p.add_argument(
        "--workers",
        type=positive_int,
        default=d.workers,
        help=f"training runs at once with --parallel processes (and the CPUs of a local Ray) (default "
        f"{d.workers}: one per CPU, at most 2); the models do not depend on it",
    )
    p.add_argument(
        "--parallel",
        choices=PARALLEL,
        default=d.parallel,
        help="where the training runs go: serial (one after another, with a progress bar), processes "
        "(--workers local processes; default) or ray (Ray tasks: the cluster RAY_ADDRESS names, else a "
        "local Ray); the table is the same either way",
    )
    p.add_argument(
        "--trainer", choices=TRAINERS, default=d.trainer, help="who trains the baselines: native (FlowTest's batched PPO, default) or sb3 (stable-baselines3)"
    )
    p.add_argument(
        "--select",
        choices=SELECTIONS,
        default=d.select,
        help="the model of each training run that is scored: validation (the curve evaluation with the best greedy met "
        "on the validation tests; default) or final (the last)",
    )
    add_trust_model(p, "load stable-baselines3 zips given as --sut ppo:PATH, which unpickles them (code from the file runs); native checkpoints never need it")
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output folder (table.md, table.json, learning-curves.png, generalization.png, report.html, "
        "models/, pool/, benchmark-config.json); an existing non-empty folder is refused unless --force "
        "or --resume",
    )
    p.add_argument("--force", action="store_true", help="start over: overwrite the files of an earlier benchmark in --out")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue a stopped benchmark in --out: its finished training runs are kept, the rest trained "
        "and everything scored (the same settings only: they are compared with the stored ones)",
    )
    p.add_argument("--json", action="store_true", help="print table.json's document (only it) on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def run(args: argparse.Namespace) -> int:
    """``flowtest benchmark``: check everything, run, print the table (or the JSON)."""
    from synthesis.routing.solver_control import stdout_guard

    given = {f"{split}_count": getattr(args, f"{split}_count") for split in ("train", "validation", "test")}
    config = BenchmarkConfig.for_pool(
        args.pool,
        suts=tuple(args.sut or DEFAULT_SUTS),
        algos=tuple(dict.fromkeys(args.algo)),
        **{k: v for k, v in given.items() if v is not None},
        train_eval_count=args.train_eval_count,
        steps=args.steps,
        seeds=tuple(dict.fromkeys(args.seeds)),
        runs=args.runs,
        curve_sizes=tuple(args.curve_sizes),
        curve_seeds=args.curve_seeds,
        curve_points=args.curve_points,
        trainer=args.trainer,
        select=args.select,
        report_tests=args.report_tests,
        bootstrap=args.bootstrap,
        workers=args.workers,
        parallel=args.parallel,
    )
    apply_trust_model(args)
    library.check_config(config)
    library.check_systems(config)  # every ppo: model loaded before any work
    prepare_benchmark_folder(args.out, args.force, config, args.resume)
    dropped = config.left_out_curve_sizes()
    if dropped and config.baselines():
        sys.stderr.write(
            f"flowtest: warning: curve sizes {' '.join(map(str, dropped))} (--curve-sizes) are above "
            f"--train-count {config.train_count}: left out of the generalization curve\n"
        )

    def say(message: str) -> None:
        if not args.quiet:
            sys.stderr.write(f"flowtest: {message}\n")
            sys.stderr.flush()

    with stdout_guard():  # stdout holds our table or JSON only, whatever a library prints meanwhile
        doc = library.run_benchmark(config, args.out, say, progress_bar=not args.quiet and sys.stderr.isatty(), resume=args.resume)
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


COMMAND = Command(
    "benchmark",
    "train the learned baselines on a test pool and score them on held-out tests, between a random floor and a reference ceiling",
    add_arguments,
    run,
)
