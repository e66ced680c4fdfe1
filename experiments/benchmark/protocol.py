"""The benchmark protocol, whole: ``flowtest benchmark --pool NAME`` as a Python call.

The learned baselines on a test pool, scored by a fixed protocol on tests they never trained
on, between a random floor and a reference ceiling (docs/benchmark-protocol.md has the reasons
for each choice):

1. **The pool** (:func:`~experiments.benchmark.pool.load_splits`): the first ``train_count``
   tests of the pool's ``train`` split (the baselines train on them), the first
   ``validation_count`` of its ``validation`` split (the learning curves, and with
   ``select="validation"``, the default, the choice of each run's scored checkpoint: its best
   greedy validation met) and the first ``test_count`` of its ``test`` split
   (held out: never seen in training). The splits are disjoint seed ranges
   (:mod:`flowtest_env.pools`); where the tests come from is pluggable (``source``,
   :data:`flowtest_env.scoring.PoolSource`). The tests that are scored are written to
   ``OUT/pool/<split>/seed<N>.json`` so every run in the report replays with
   ``flowtest evaluate --env <that file> ... --replay``.
2. **The baselines** (:func:`~experiments.benchmark.training_runs.train_baseline`), per
   algorithm and training seed, on the train split, for ``steps`` time steps: with the native
   trainer (default, :mod:`agents.native_ppo`) masked PPO with the visited-places memory
   (``maskable-ppo``), with a GRU (``recurrent-ppo``) and with prioritized level replay over
   the train tests (``plr-ppo``); with ``--trainer sb3`` sb3-contrib's MaskablePPO and
   RecurrentPPO. Only ``maskable-ppo`` trains by default (the time budget); the others on
   request (``--algo``).
3. **The scores** (:mod:`~experiments.benchmark.scoring`). Every system on every split: the
   learned policies greedily (each test once) **and**, on the held-out tests, sampled
   (``runs`` seeded runs per test), every test x run of a split in one
   :class:`~flowtest_env.vector.PoolVectorEnv` batch (:mod:`flowtest_env.scoring`); ``random``
   (the **floor**, ``runs`` runs per test, batched too); the **references** (the scripted
   replanner and the GR(1) system, correct systems that do not know the test: the
   **ceiling**; on fuel grids with doors a door can close after the fuel to go round it is
   spent, so they meet fewer than all tests there: docs/benchmark-protocol.md) and any system
   that is not batched through the single env, once per test. The floor and the ceiling are
   always scored: they define the scale.
4. **The statistics** (:mod:`~experiments.benchmark.statistics`): per split and mode, the
   **normalized score** ``(met - floor) / (ceiling - floor)`` (0 = random, 1 = reference; floor
   and ceiling are the split's own), with 5 seeds or more its interquartile mean over seeds
   with the seed-and-test bootstrap's 95 % interval (seeds resampled, the tests resampled once
   per replicate for every seed, the floor and the reference: a crossed design), with fewer
   the mean and a t interval (preliminary); the **headline** is the sampled play's
   (a deterministic system's greedy), greedy beside it; the **tail** (the mean met share of
   the hardest 10 % of the tests: a CVaR), raw met, test objective realized, restrictions,
   steps, and the held-out gap (train met minus held-out met, greedy).
5. **The generalization curve** (:func:`~experiments.benchmark.scoring.generalization_curve`):
   the held-out normalized score of the first baseline trained on the first 16, 64, 256, 1,024
   train tests (``curve_seeds`` seeds each, the same steps) and on all ``train_count`` (the
   main runs). Every training run (main and curve) is trained first, ``workers`` at a time in
   their own processes (:func:`~experiments.benchmark.training_runs.train_all`; the models do
   not depend on it).
6. **The outputs** in ``OUT``: ``table.md`` and ``table.json`` (the results file,
   docs/benchmark-protocol.md; :mod:`~experiments.benchmark.table`), ``scores.npz`` (every
   system's per-run score matrix, seeds x tests, as rliable reads it:
   :func:`~experiments.benchmark.statistics.score_matrices`), ``learning-curves.png``,
   ``generalization.png`` (:mod:`~experiments.benchmark.plots`), the evaluation report of
   :mod:`experiments.evaluation` on a sample of each split's tests (``report.html``,
   ``report.md``, ``results.json``), the models and the scored tests.
7. **Stopping and resuming** (:mod:`~experiments.benchmark.resume`): the configuration is
   stored before any work and every finished training run leaves its model and record, so a
   stopped benchmark is continued with ``resume`` (``--resume``), to the same table.

Every number is seeded (the tests, training, the sampled runs, the bootstrap), so the same
configuration gives the same table; only the times differ.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

from experiments.evaluation import Cell, write_report
from experiments.evaluation.report import TestInfo
from experiments.outputs import json_safe, prepare_output_folder, write_atomically
from synthesis.artifacts.artifact import TestArtifact
from synthesis.model.errors import ProblemError

from .config import REPORT_SPLITS, RUN_SEED, BenchmarkConfig, check_config
from .plots import plot_generalization, plot_learning_curves
from .pool import Split, load_splits
from .resume import CONFIG_FILE, check_same_config, remove_temporaries, write_config
from .scoring import generalization_curve, score_all
from .statistics import SCORES_FILE, scale_of, score_matrices
from .table import benchmark_table, commit, table_markdown
from .training_runs import TrainingJob, train_all

BENCHMARK_MARKER = ".flowtest-benchmark"
"""The file that marks a folder as a benchmark's: ``--out`` refuses any other non-empty
folder, and any earlier benchmark, unless ``--force``."""


def _split_infos(splits: dict[str, Split], out: Path, shown: int) -> list[TestInfo]:
    """What the report shows of each split's column: the first test's picture and the
    pool's objectives (the same formulas for every test of a pool)."""
    from experiments.evaluation.filmstrip import start_picture
    from flowtest_env.envs import default_max_steps
    from flowtest_env.game import TestGame

    infos = []
    for name in REPORT_SPLITS:
        split = splits[name]
        art = split.artifacts[0]
        game = TestGame(art)
        picture = f"tests/{split.name}-split-first.png"
        write_atomically(out / picture, partial(start_picture, game))
        infos.append(
            TestInfo(
                env_id=_report_label(split, shown),
                problem=f"{art.name} (the first of {len(split.seeds)})",
                kind=str(art.kind),
                system_objective=str(art.objectives.get("system", "")),
                test_objective=str(art.objectives.get("test", "")),
                max_steps=default_max_steps(game),
                picture=picture,
            )
        )
    return infos


def _report_label(split: Split, shown: int) -> str:
    return f"{split.label.rsplit(' (', 1)[0]} (report: the first {min(shown, len(split.files))} tests)"


def run_benchmark(
    config: BenchmarkConfig,
    out: Path,
    say: Callable[[str], None] = lambda _: None,
    progress_bar: bool = False,
    source: Callable[[str, str, int], Sequence[TestArtifact]] | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """Run the benchmark (see the module docstring) into the folder ``out`` (created; it
    is not checked here: the command checks it first, :func:`prepare_benchmark_folder`) and
    return ``table.json``'s document. ``source`` loads the pool's tests (default
    :func:`flowtest_env.pools.load_pool`). With ``resume``, the training runs an earlier,
    stopped run of the same configuration finished in ``out`` are kept
    (:mod:`~experiments.benchmark.resume`); the table is the same as an uninterrupted run's."""
    t_start = time.perf_counter()
    check_config(config)
    code = commit()  # the code this run uses (the tree may move on while it runs)
    out.mkdir(parents=True, exist_ok=True)
    if resume:
        started = check_same_config(out, config).get("commit")
        remove_temporaries(out)
        if started != code:
            say(
                f"warning: resuming a benchmark started with FlowTest commit {started or 'unknown'}, now "
                f"{code or 'unknown'}: its finished runs are kept as they are"
            )
    elif not (out / CONFIG_FILE).exists():
        write_config(out, config, code)
    say(f"loading the pool {config.pool}: {config.train_count} train, {config.validation_count} validation and {config.test_count} held-out tests")
    t0 = time.perf_counter()
    splits = load_splits(config, out, progress=progress_bar, source=source)
    pool_seconds = time.perf_counter() - t0
    check_systems_play(config, splits)
    jobs = [TrainingJob(algo, seed, config.train_count, f"{algo}-seed{seed}") for algo in config.baselines() for seed in config.seeds]
    if config.baselines():
        first = config.baselines()[0]
        jobs += [
            TrainingJob(first, seed, n, f"curve-{first}-{n}-seed{seed}")
            for n in config.curve()
            if n != config.train_count
            for seed in config.seeds[: config.curve_seeds]
        ]
    t0 = time.perf_counter()
    trained = train_all(config, jobs, splits, out, say, progress_bar, resume)
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
    doc["commit"] = code
    say("writing the table, the curves and the report")
    cells = []
    for name in REPORT_SPLITS:
        label = _report_label(splits[name], config.report_tests)
        for sut, runs in traces[name].items():
            cells.append(Cell(label, sut, runs[: config.report_tests], RUN_SEED, 0.0))
    cells.sort(key=lambda c: c.sut)
    write_report(cells, out, _split_infos(splits, out, config.report_tests))
    doc["seconds"] = {
        "pool": round(pool_seconds, 1),
        "training": round(train_seconds, 1),
        "training_cpu": round(sum(b.seconds for b in trained), 1),
        "scoring": round(score_seconds, 1),
        "generalization": round(curve_seconds, 1),
        "total": round(time.perf_counter() - t_start, 1),
    }
    doc["outputs"] = {k: str((out / v).resolve()) for k, v in OUTPUTS.items()}
    if any(e["kind"] == "baseline" and e.get("training") for e in doc["systems"]):
        write_atomically(out / OUTPUTS["curves"], lambda tmp: plot_learning_curves(doc, tmp))
    else:
        doc["outputs"].pop("curves")
    if doc["generalization"]:
        write_atomically(out / OUTPUTS["generalization"], lambda tmp: plot_generalization(doc, tmp))
    else:
        doc["outputs"].pop("generalization")
    write_scores(out / OUTPUTS["scores"], doc)
    write_text(out / OUTPUTS["table_md"], table_markdown(doc))
    write_text(out / OUTPUTS["table_json"], json.dumps(json_safe(doc), indent=1) + "\n")
    return doc


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""

    def write(tmp: Path) -> None:
        tmp.write_text(text)

    write_atomically(path, write)


def write_scores(path: Path, doc: dict[str, Any]) -> None:
    """Write the per-run score matrices of ``doc`` (:func:`~experiments.benchmark.statistics.score_matrices`)
    to ``path`` as an uncompressed ``.npz``, atomically."""
    import numpy as np

    matrices: dict[str, Any] = dict(score_matrices(doc))

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.savez(f, allow_pickle=False, **matrices)

    write_atomically(path, write)


OUTPUTS = {
    "table_md": "table.md",
    "table_json": "table.json",
    "scores": SCORES_FILE,
    "curves": "learning-curves.png",
    "generalization": "generalization.png",
    "report": "report.html",
}
"""The main files a benchmark writes into ``--out``."""


def prepare_benchmark_folder(out: Path, force: bool, config: BenchmarkConfig | None = None, resume: bool = False) -> None:
    """Make ``out`` a benchmark folder (:data:`BENCHMARK_MARKER`), refusing to overwrite: an
    existing non-empty ``out`` needs ``force`` (``--force``: start over), whoever wrote it, or
    ``resume`` (``--resume``: continue the benchmark in it, which must have been started with
    the same ``config``, :func:`~experiments.benchmark.resume.check_same_config`). With
    ``config``, a new benchmark's configuration is written in it
    (:data:`~experiments.benchmark.resume.CONFIG_FILE`) before any work.

    Raises
    ------
    ProblemError
        If ``out`` holds files and neither ``force`` nor ``resume`` is given, if there is
        nothing of this configuration to resume, or if ``out`` cannot be written.
    """
    if force and resume:
        raise ProblemError("--resume continues the benchmark in --out and --force starts it over: give one of them")
    used = False
    if out.is_dir():
        try:
            used = any(out.iterdir())
        except OSError as exc:
            raise ProblemError(f"cannot read the benchmark folder {str(out)!r}: {exc.strerror or exc}") from None
    if used and resume:
        if config is None:
            raise ProblemError("--resume needs the configuration to compare with the stored one")
        if not (out / BENCHMARK_MARKER).exists():
            raise ProblemError(
                f"benchmark folder {str(out)!r} holds files FlowTest did not write: there is no benchmark to resume in it; choose another folder"
            )
        check_same_config(out, config)
    elif used and not force:
        if (out / BENCHMARK_MARKER).exists():
            raise ProblemError(
                f"benchmark folder {str(out)!r} already holds an earlier benchmark; use --resume to continue "
                "it (the same settings), --force to start over, or choose another folder"
            )
        raise ProblemError(f"benchmark folder {str(out)!r} already holds files; use --force to overwrite, or choose another folder")
    prepare_output_folder(out, BENCHMARK_MARKER, force, "benchmark folder")
    if config is not None and not (used and resume):
        write_config(out, config, commit())


def check_systems(config: BenchmarkConfig) -> None:
    """Load every saved model given as a system (``--sut ppo:PATH``) before any work: a file
    that is not a model, or a checkpoint that fails its checks, is one error line before the
    folder is made and the pool loaded, not after minutes of scoring.

    Raises
    ------
    ProblemError
        Naming the system and why it cannot be loaded.
    """
    from agents.ppo import load_model

    for sut in _members(config):
        if sut.startswith("ppo:"):
            try:
                load_model(sut[4:])
            except ValueError as exc:  # PolicyError, CheckpointError
                raise ProblemError(f"--sut {sut}: {exc}") from None


def _members(config: BenchmarkConfig) -> list[str]:
    """Every SUT the systems given by ``--sut`` stand for (a glob's files one by one)."""
    return [m for spec in config.systems() if spec.kind == "system" for m in spec.members]


def check_systems_play(config: BenchmarkConfig, splits: dict[str, Split]) -> None:
    """Every saved model and batched ``python:`` policy given as a system plays the pool's
    first held-out test once, before any training or scoring: a model trained on tests of
    another observation shape is one error line now, not a traceback after the training runs.

    Raises
    ------
    ProblemError
        Naming the system and what went wrong.
    """
    from flowtest_env.game import TestGame
    from flowtest_env.scoring import play_batch

    from .scoring import score_systems
    from .systems import member_policies

    test = splits["test"]
    first = Split(test.name, test.label, test.seeds[:1], test.artifacts[:1], test.files[:1])
    games = [TestGame(first.artifacts[0])]
    for sut in _members(config):
        if not sut.startswith(("ppo:", "python:")):
            continue
        try:
            member = member_policies(sut, games)
            if member is None:
                if sut.startswith("ppo:"):
                    score_systems([sut], first)  # a stable-baselines3 zip through the single env
                continue
            for policy in member.policies.values():
                play_batch(policy, games, 1, RUN_SEED, options=member.options)
        except ProblemError:
            raise
        except Exception as exc:  # the policy's own failure, whatever it is: one line
            raise ProblemError(f"--sut {sut} cannot play the pool's tests: {type(exc).__name__}: {exc}") from None


def benchmark(
    pool: str | BenchmarkConfig,
    out: str | Path,
    *,
    force: bool = False,
    resume: bool = False,
    say: Callable[[str], None] = lambda _: None,
    progress_bar: bool = False,
    source: Callable[[str, str, int], Sequence[TestArtifact]] | None = None,
    **settings: Any,
) -> dict[str, Any]:
    """Run the benchmark protocol (see the module docstring) on ``pool`` into the folder
    ``out`` and return ``table.json``'s document: what ``flowtest benchmark --pool POOL --out
    OUT`` does, with ``settings`` as its options (any field of :class:`BenchmarkConfig`:
    ``suts``, ``algos``, ``train_count``, ``steps``, ``seeds``, ...; the split counts not given
    are :meth:`BenchmarkConfig.for_pool`'s, as the command's). ``pool`` may be a whole
    :class:`BenchmarkConfig` instead (then no ``settings``). Everything is checked before any
    work, every ``ppo:`` model loaded; ``out`` is refused when it holds files, unless ``force``
    (start over) or ``resume`` (continue a stopped benchmark of the same configuration in
    it, keeping its finished training runs). ``say`` gets the progress
    lines; ``source(pool, split, count)`` loads the pool's tests (default
    :func:`flowtest_env.pools.load_pool`).

    Raises
    ------
    ProblemError
        On a bad configuration (:func:`check_config`) or output folder
        (:func:`prepare_benchmark_folder`).

    Examples
    --------
    The floor and the references alone (no training) on 6 tests of each split:

    >>> import tempfile
    >>> from pathlib import Path
    >>> from experiments.benchmark import benchmark
    >>> out = Path(tempfile.mkdtemp()) / "bench"
    >>> doc = benchmark("safety2/4x4", out, suts=("random", "scripted:replanner"), train_count=6,
    ...                 validation_count=3, test_count=6)
    >>> doc["scale"]["test"]["ceiling"], doc["scale"]["test"]["floor"] < 1.0
    (1.0, True)
    >>> sorted(p.name for p in out.glob("table.*"))
    ['table.json', 'table.md']
    """
    if isinstance(pool, BenchmarkConfig):
        if settings:
            raise ProblemError(f"benchmark(): settings {sorted(settings)} given with a whole BenchmarkConfig")
        config = pool
    else:
        config = BenchmarkConfig.for_pool(pool, **settings)
    check_config(config)
    check_systems(config)
    prepare_benchmark_folder(Path(out), force, config, resume)
    return run_benchmark(config, Path(out), say, progress_bar, source, resume)
