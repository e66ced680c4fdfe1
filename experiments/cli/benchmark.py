"""``flowtest benchmark --pool NAME``: the standard learned baselines on a test pool, scored
on tests they never trained on.

What it does, in order (each step a plain function below):

1. **The pool** (:func:`load_splits`): the first ``train_count`` tests of the pool's
   ``train`` split and the first ``test_count`` of its ``test`` split
   (:mod:`flowtest_env.pools`: the splits are seed ranges that never overlap), each
   written to ``OUT/pool/<split>/seed<N>.json`` so every run can be replayed with
   ``flowtest evaluate --env <that file> ... --replay``.
2. **The baselines** (:func:`train_baseline`), for every algorithm and training seed,
   trained on ``FlowTest-RandomGrid-v0`` drawing from the train split. With the native
   trainer (default, :mod:`agents.native_ppo`): masked PPO with an MLP and the
   visited-places memory (``maskable-ppo``) and masked PPO with a GRU (``recurrent-ppo``),
   :data:`NATIVE_BASELINES`; with ``--trainer sb3``: sb3-contrib's MaskablePPO with the
   memory wrapper (the ``memory="visited"`` env option,
   :class:`flowtest_env.wrappers.VisitedPlaces`) and RecurrentPPO (an LSTM, its own
   memory), :data:`BASELINES`. During training the learning curve is measured on the
   train tests and on the held-out tests by greedy play of every test once, all of them
   in one :class:`~flowtest_env.vector.PoolVectorEnv` batch (:func:`batch_verdicts`).
3. **The scores** (:func:`score_systems`): every system plays every test once through
   the single env, exactly as ``flowtest evaluate`` and its replay commands run it (a
   pool test is deterministic and so are the policies, so one run per test is the whole
   evaluation): the saved models, the references (the scripted replanner and the GR(1)
   system, correct by construction: they should meet every test) and any other system
   named with ``--sut``.
4. **The table** (:func:`benchmark_table`): per system, on the train and on the held-out
   tests, the share of tests whose system objective was met, the test objective realized
   among those (the synthesized test guarantees 100 %), the restrictions hit and the
   steps, with 95 % confidence intervals over the training seeds (Student's t); the
   **held-out gap**, train met minus held-out met, is the headline number.
5. **The outputs** in ``OUT``: ``table.md`` and ``table.json`` (the same numbers, with the
   curves and settings), ``learning-curves.png``, the evaluation report of
   :mod:`experiments.cli.evaluate` (``report.html``, ``report.md``, ``results.json``: a matrix
   of systems x splits, the failing runs with filmstrips and replay commands), the
   models (``models/``) and the pool tests (``pool/``).

Every number is seeded: the pool tests (a seed names a test), training (torch on one
thread, seeded envs), evaluation (deterministic policies on deterministic tests), so the
same command gives the same table; only the times differ.
"""

from __future__ import annotations

import argparse
import json
import math
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

POOL_ENV_ID = "FlowTest-RandomGrid-v0"
"""The env the baselines train on (its ``pool``, ``split``, ``count`` options)."""

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
}
"""Settings of each baseline with the native trainer (the default), over
:data:`~experiments.cli.train.NATIVE_DEFAULTS`: masked PPO with an MLP and the visited-places
memory, and masked PPO with a GRU (its own memory); on the CPU, so a seed gives the same
table."""

REFERENCES: tuple[str, ...] = ("scripted:replanner", "gr1")
"""Systems correct by construction: they should meet the system objective on every test."""

DEFAULT_SUTS: tuple[str, ...] = ("ppo", *REFERENCES)
"""``--sut`` when none is given: the baselines of ``--algo`` and the references."""

RUN_SEED = 0
"""The seed of every scoring run (the tests and the policies are deterministic; it
matters only to a random system, and it is the ``--seed`` of the replay commands)."""

T95: dict[int, float] = {}


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class BenchmarkConfig:
    """What ``flowtest benchmark`` runs (the defaults fit 30 minutes on 2 shared cores)."""

    pool: str
    suts: tuple[str, ...] = DEFAULT_SUTS
    algos: tuple[str, ...] = ALGOS
    train_count: int = 128
    test_count: int = 32
    steps: int = 80_000
    seeds: tuple[int, ...] = (0, 1, 2)
    curve_points: int = 10
    trainer: str = "native"

    def baselines(self) -> list[str]:
        """The algorithms to train: ``--sut ppo`` stands for every ``--algo``; an
        algorithm may also be named itself (``--sut recurrent-ppo``)."""
        named = [s for s in self.suts if s in ALGOS]
        algos = list(self.algos) if "ppo" in self.suts else []
        return list(dict.fromkeys(algos + named))

    def others(self) -> list[str]:
        """The systems scored as they are (references, ``random``, ``ppo:PATH``, ...)."""
        return [s for s in dict.fromkeys(self.suts) if s != "ppo" and s not in ALGOS]


def check_config(config: BenchmarkConfig) -> None:
    """Reject a configuration before any work.

    Raises
    ------
    ProblemError
        On a bad pool name, an unknown system, no system at all, or counts out of range.
    """
    from flowtest_env.pools import parse_pool, split_seeds

    try:
        parse_pool(config.pool)
        split_seeds("train", config.train_count)
        split_seeds("test", config.test_count)
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
        if algo not in ALGOS:
            raise ProblemError(f"unknown --algo {algo!r}; expected one of {', '.join(ALGOS)}")
    if config.trainer not in TRAINERS:
        raise ProblemError(f"unknown --trainer {config.trainer!r}; expected one of {', '.join(TRAINERS)}")
    if config.baselines():
        if config.trainer == "sb3":
            require_rl()
        else:
            require_native()
        if not config.seeds:
            raise ProblemError("--seeds needs at least one training seed")
        if config.steps < 1:
            raise ProblemError("--steps must be at least 1")
        if config.curve_points < 1:
            raise ProblemError("--curve-points must be at least 1")
        for algo in config.baselines():
            if config.trainer == "sb3":
                check_settings(baseline_settings(algo, "sb3"))
            else:
                baseline_settings(algo)


def baseline_settings(algo: str, trainer: str = "native") -> dict[str, Any]:
    """The full training settings of a baseline: :data:`NATIVE_BASELINES` over
    ``NATIVE_DEFAULTS``, or with ``trainer="sb3"`` :data:`BASELINES` over ``DEFAULTS``."""
    if trainer == "sb3":
        return {**DEFAULTS, **BASELINES[algo]}
    return native_settings(NATIVE_BASELINES[algo])


# --------------------------------------------------------------------------- the pool


@dataclass
class Split:
    """The tests of one split of the pool: artifacts, the files they were written to, and
    the label of the split's column in the report."""

    name: str
    label: str
    seeds: list[int]
    artifacts: list[TestArtifact]
    files: list[Path] = field(default_factory=list)


def load_splits(config: BenchmarkConfig, out: Path, progress: bool | None = None) -> dict[str, Split]:
    """The train and test splits of the pool (built on demand and cached, see
    :func:`flowtest_env.pools.load_pool`), each test written to
    ``out/pool/<split>/seed<N>.json``."""
    from flowtest_env.pools import load_pool, split_seeds

    splits = {}
    for name, count, what in (("train", config.train_count, "tests"), ("test", config.test_count, "held-out tests")):
        seeds = list(split_seeds(name, count))
        arts = load_pool(config.pool, name, count, progress=progress)
        split = Split(name, f"{config.pool} {name} ({count} {what})", seeds, arts)
        for seed, art in zip(seeds, arts, strict=True):
            path = (out / "pool" / name / f"seed{seed}.json").resolve()
            write_atomically(path, art.save)
            split.files.append(path)
        splits[name] = split
    return splits


# --------------------------------------------------------------------------- batch evaluation


def batch_verdicts(model: Any, games: Sequence[Any], memory: str, budgets: Sequence[int]) -> dict[str, np.ndarray]:
    """Let the deterministic policy of ``model`` (a saved model as :func:`agents.ppo.load_model`
    gives it: native or stable-baselines3) play every test of ``games`` once, all at once in
    one :class:`~flowtest_env.vector.PoolVectorEnv` (env ``i`` plays test ``i``), and return
    the verdict arrays: ``system_objective`` (``"met"``, ``"violated"``, ``"open"``),
    ``test_objective_realized``, ``restrictions``, ``steps``
    (:func:`agents.native_ppo.batch_verdicts`).

    Each test ends where the single env would end it: at its outcome, or at its own step
    budget ``budgets[i]`` (``"open"``). ``memory`` is the model's (``"visited"`` appends
    the places visited, as :class:`~flowtest_env.wrappers.VisitedPlaces`); a recurrent
    model carries its state, a maskable one gets the masks.

    Raises
    ------
    ValueError
        If the tests do not share where the observation holds the system's place.
    """
    from agents.native_ppo import batch_verdicts as play_all
    from agents.native_ppo import shared_position_slice

    where = shared_position_slice(games, "flat") if memory == "visited" else None
    kind = type(model).__name__
    recurrent = bool(getattr(model, "recurrent", kind == "RecurrentPPO"))
    maskable = bool(getattr(model, "maskable", kind == "MaskablePPO"))
    state: list[Any] = [None]

    def act(x: np.ndarray, masks: np.ndarray, starts: np.ndarray) -> np.ndarray:
        kw: dict[str, Any] = {"deterministic": True}
        if maskable:
            kw["action_masks"] = masks
        if recurrent:
            kw["state"], kw["episode_start"] = state[0], starts
        actions, state[0] = model.predict(x, **kw)
        return np.asarray(actions)

    return play_all(act, games, budgets, where, seed=RUN_SEED)


class CurveRecorder:
    """An SB3 callback that measures the learning curve: the share of the train tests and
    of the held-out tests whose system objective the deterministic policy meets
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
    """One trained model: algorithm, seed, where it is saved, its curve and time."""

    algo: str
    seed: int
    path: Path
    steps: int
    seconds: float
    curve_seconds: float
    curve: list[tuple[int, dict[str, float]]]

    @property
    def sut(self) -> str:
        """The model as a system under test (``ppo:PATH``, what the replay commands use)."""
        return f"ppo:{self.path}"


def _games_and_budgets(split: Split) -> tuple[list[Any], list[int]]:
    from flowtest_env.envs import default_max_steps
    from flowtest_env.game import TestGame

    games = [TestGame(a) for a in split.artifacts]
    return games, [default_max_steps(g) for g in games]


def train_baseline(
    config: BenchmarkConfig, algo: str, seed: int, splits: dict[str, Split], out: Path, progress_bar: bool = False
) -> TrainedBaseline:
    """Train one baseline on the train split (``config.steps`` time steps, rounded up to
    whole rollouts), recording its learning curve on the train and the held-out tests;
    save it to ``out/models/<algo>-seed<seed>.zip``."""
    every = max(1, math.ceil(config.steps / config.curve_points))
    path = (out / "models" / f"{algo}-seed{seed}.zip").resolve()
    pool_options = {"pool": config.pool, "split": "train", "count": config.train_count}
    if config.trainer == "native":
        return _train_native_baseline(config, algo, seed, splits, path, every, progress_bar)
    settings = baseline_settings(algo, "sb3")
    env = make_training_vec_env(POOL_ENV_ID, seed, settings, pool_options)
    model = make_model(env, settings, seed)
    recorder = CurveRecorder(every, settings["memory"], {name: _games_and_budgets(s) for name, s in splits.items()})

    seconds = learn(model, config.steps, recorder, progress_bar)
    write_atomically(path, lambda tmp: model.save(str(tmp)))
    mark_own_file(path)  # scored below without --trust-model: this run wrote it
    env.close()
    return TrainedBaseline(algo, seed, path, int(model.num_timesteps), seconds, recorder.seconds, recorder.points)


def _train_native_baseline(config: BenchmarkConfig, algo: str, seed: int, splits: dict[str, Split], path: Path,
                           every: int, progress_bar: bool) -> TrainedBaseline:
    """One baseline with the native trainer on the train split's tests (the env plays
    exactly them), its greedy curve measured by the trainer on the train and held-out tests."""
    from agents.native_ppo import save_policy
    from agents.native_ppo import train as native_train
    from flowtest_env.game import TestGame

    settings = baseline_settings(algo)
    pool_options = {"pool": config.pool, "split": "train", "count": config.train_count}
    args = native_args(settings, POOL_ENV_ID, pool_options, config.steps, seed, eval_every=every)
    heldout = [TestGame(a) for a in splits["test"].artifacts]
    result = native_train(args, heldout=heldout, progress_bar=progress_bar)
    write_atomically(path, lambda tmp: save_policy(tmp, result.agent, result.settings))
    names = {"train": "train", "heldout": "test"}
    curve = [(step, {names[k]: v["met"] for k, v in rates.items()}) for step, rates in result.evaluations]
    return TrainedBaseline(algo, seed, path, result.steps, result.seconds, result.eval_seconds, curve)


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


def score_systems(suts: Sequence[str], split: Split) -> dict[str, list[Trace]]:
    """Every system plays every test of ``split`` once (seed :data:`RUN_SEED`), through
    the single env of the test's file, as ``flowtest evaluate --env FILE`` runs it.

    Raises
    ------
    ProblemError
        If a system cannot play the pool's tests (a model of another observation shape).
    """
    from agents.base import PolicyError

    factories = {sut: _policy_factory(sut) for sut in suts}
    traces: dict[str, list[Trace]] = {sut: [] for sut in suts}
    for path in split.files:
        env = make_env(str(path))
        for sut, factory in factories.items():
            try:
                policy = factory(env)
            except PolicyError as exc:
                raise ProblemError(f"--sut {sut} cannot play the pool's tests: {exc}") from None
            traces[sut].append(run_episode(env, policy, str(path), sut, RUN_SEED))
        env.close()
    return traces


def split_metrics(traces: Sequence[Trace]) -> dict[str, Any]:
    """The numbers of one system on one split: ``met`` (share of the tests whose system
    objective was met), ``realized`` (share of those that realized the test objective;
    ``None`` if none met), ``restrictions`` (mean restricted decisions per run),
    ``steps`` (mean steps of the runs that met; ``None`` if none), and counts."""
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


# --------------------------------------------------------------------------- the table


def benchmark_table(
    config: BenchmarkConfig,
    splits: dict[str, Split],
    trained: Sequence[TrainedBaseline],
    traces: dict[str, dict[str, list[Trace]]],
) -> dict[str, Any]:
    """The benchmark's numbers (``table.json``): per system its per-seed metrics on both
    splits, their means with confidence intervals, and the held-out gap (train met minus
    held-out met, per seed); the headline is each baseline's gap."""
    systems: list[dict[str, Any]] = []
    groups: list[tuple[str, str, list[tuple[int | None, str]]]] = []
    for algo in config.baselines():
        runs: list[tuple[int | None, str]] = [(b.seed, b.sut) for b in trained if b.algo == algo]
        groups.append((algo, "baseline", runs))
    for sut in config.others():
        groups.append((sut, "reference" if sut in REFERENCES else "system", [(None, sut)]))
    for name, kind, runs in groups:
        per_seed = []
        for seed, sut in runs:
            row: dict[str, Any] = {"seed": seed, "sut": sut, **{s: split_metrics(traces[s][sut]) for s in splits}}
            row["gap"] = None if row["train"]["met"] is None or row["test"]["met"] is None else row["train"]["met"] - row["test"]["met"]
            per_seed.append(row)
        summary: dict[str, Any] = {}
        for s in splits:
            summary[s] = {key: mean_ci([r[s][key] for r in per_seed]) for key in ("met", "realized", "restrictions", "steps")}
            summary[s]["test_failures"] = sum(r[s]["test_failures"] for r in per_seed)
        summary["gap"] = mean_ci([r["gap"] for r in per_seed])
        entry: dict[str, Any] = {"name": name, "kind": kind, "runs": per_seed, **summary}
        if kind == "baseline":
            mine = [b for b in trained if b.algo == name]
            entry["settings"] = baseline_settings(name, config.trainer)
            entry["training"] = [
                {"seed": b.seed, "steps": b.steps, "seconds": round(b.seconds, 1), "curve_seconds": round(b.curve_seconds, 1),
                 "model": str(b.path), "curve": [[step, rates.get("train"), rates.get("test")] for step, rates in b.curve]}
                for b in mine
            ]
        systems.append(entry)
    return {
        "pool": config.pool,
        "splits": {s: {"count": len(sp.seeds), "seeds": [sp.seeds[0], sp.seeds[-1]]} for s, sp in splits.items()},
        "config": {"steps": config.steps, "seeds": list(config.seeds), "algos": config.baselines(), "trainer": config.trainer,
                   "curve_points": config.curve_points, "suts": list(config.suts)},
        "headline": {"held_out_gap": {e["name"]: e["gap"] for e in systems if e["kind"] == "baseline"}},
        "systems": systems,
    }


def _pct(stat: dict[str, Any]) -> str:
    if stat["mean"] is None:
        return "–"
    ci = "" if stat["ci95"] is None else f" ± {100 * stat['ci95']:.1f}"
    return f"{100 * stat['mean']:.1f} %{ci}"


def _num(stat: dict[str, Any]) -> str:
    if stat["mean"] is None:
        return "–"
    ci = "" if stat["ci95"] is None else f" ± {stat['ci95']:.1f}"
    return f"{stat['mean']:.1f}{ci}"


def _gap(stat: dict[str, Any]) -> str:
    if stat["mean"] is None:
        return "–"
    ci = "" if stat["ci95"] is None else f" ± {100 * stat['ci95']:.1f}"
    return f"{100 * stat['mean']:+.1f} pp{ci}"


TABLE_COLUMNS = ["system", "kind", "seeds", "train: met", "held-out: met", "held-out gap", "held-out: realized (of met)",
                 "held-out: restrictions", "held-out: steps (met runs)"]


def table_rows(doc: dict[str, Any]) -> list[list[str]]:
    """The rows of ``table.md`` (see :data:`TABLE_COLUMNS`)."""
    rows = []
    for e in doc["systems"]:
        seeds = ", ".join(str(r["seed"]) for r in e["runs"]) if e["kind"] == "baseline" else "–"
        rows.append([e["name"], e["kind"], seeds, _pct(e["train"]["met"]), _pct(e["test"]["met"]), _gap(e["gap"]),
                     _pct(e["test"]["realized"]), _num(e["test"]["restrictions"]), _num(e["test"]["steps"])])
    return rows


def headline_text(doc: dict[str, Any]) -> str:
    """One line: each baseline's held-out gap."""
    parts = [f"{name} {_gap(stat)}" for name, stat in doc["headline"]["held_out_gap"].items()]
    return "held-out gap (train met - held-out met): " + ("; ".join(parts) if parts else "no baseline trained")


def table_markdown(doc: dict[str, Any]) -> str:
    """``table.md``: the headline, the table, and what the columns mean."""
    tr, te = doc["splits"]["train"], doc["splits"]["test"]
    cfg = doc["config"]
    lines = [
        f"# FlowTest benchmark: {doc['pool']}", "",
        f"**{headline_text(doc)}**", "",
        f"Train split: {tr['count']} tests (seeds {tr['seeds'][0]}-{tr['seeds'][1]}); held-out: the test split, "
        f"{te['count']} tests (seeds {te['seeds'][0]}-{te['seeds'][1]}), never seen in training. Baselines: "
        f"{cfg['steps']:,} time steps per run, training seeds {', '.join(map(str, cfg['seeds']))}; the final model "
        "is scored (no model selection).", "",
        "| " + " | ".join(TABLE_COLUMNS) + " |", "|" + "---|" * len(TABLE_COLUMNS),
    ]
    lines += ["| " + " | ".join(row) + " |" for row in table_rows(doc)]
    lines += [
        "",
        "Each system plays each test once (the tests and the policies are deterministic). *Met*: share of the tests "
        "whose system objective was met. *Realized (of met)*: share of those runs that also realized the hidden test "
        "objective (the synthesized test guarantees 100 %). *Restrictions*: mean number of decisions taken while a "
        "move was restricted. *Steps*: mean steps of the runs that met. ± is the half-width of the 95 % confidence "
        "interval of the mean over training seeds (Student's t). *Held-out gap*: train met minus held-out met, in "
        "percentage points, per seed, then averaged.",
    ]
    bugs = [e["name"] for e in doc["systems"] if e["train"]["test_failures"] or e["test"]["test_failures"]]
    if bugs:
        lines += ["", f"**FLOWTEST BUG: a test failed its guarantee for {', '.join(bugs)}; see report.html.**"]
    return "\n".join(lines) + "\n"


COLORS = {"maskable-ppo": "#1f77b4", "recurrent-ppo": "#d62728"}


def plot_learning_curves(doc: dict[str, Any], path: Path) -> None:
    """Share of tests met against time steps, per baseline: on the train tests (solid)
    and the held-out tests (dashed), the mean over seeds with its 95 % band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for e in doc["systems"]:
        if e["kind"] != "baseline" or not e["training"]:
            continue
        color = COLORS.get(e["name"], None)
        steps = [p[0] for p in e["training"][0]["curve"]]
        for col, split, style in ((1, "train", "-"), (2, "held-out", "--")):
            runs = [[p[col] for p in t["curve"]] for t in e["training"] if len(t["curve"]) == len(steps)]
            stats = [mean_ci([r[k] for r in runs]) for k in range(len(steps))]
            mean = np.array([100 * s["mean"] for s in stats])
            ax.plot(steps, mean, style, color=color, lw=2, label=f"{e['name']}, {split} tests")
            if len(runs) > 1:
                half = np.array([100 * (s["ci95"] or 0.0) for s in stats])
                ax.fill_between(steps, np.clip(mean - half, 0, 100), np.clip(mean + half, 0, 100), color=color, alpha=0.12)
    refs = [e["name"] for e in doc["systems"] if e["kind"] == "reference" and e["test"]["met"]["mean"] is not None]
    if refs:
        best = min(next(e for e in doc["systems"] if e["name"] == r)["test"]["met"]["mean"] for r in refs)
        ax.axhline(100 * best, color="#2ca02c", lw=1, ls=":", label=f"{', '.join(refs)} (held-out)")
    ax.set_xlabel("time steps")
    ax.set_ylabel("tests whose system objective is met (%)")
    ax.set_ylim(-3, 103)
    ax.grid(alpha=0.3)
    ax.set_title(f"{doc['pool']}: {doc['splits']['train']['count']} train tests, "
                 f"{doc['splits']['test']['count']} held-out tests (mean over seeds, 95 % band)", fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --------------------------------------------------------------------------- the whole run


def _split_infos(splits: dict[str, Split], out: Path) -> list[TestInfo]:
    """What the report shows of each split's column: the first test's picture and the
    pool's objectives (the same formulas for every test of a pool)."""
    from flowtest_env.envs import default_max_steps
    from flowtest_env.game import TestGame

    from .filmstrip import start_picture

    infos = []
    for split in splits.values():
        art = split.artifacts[0]
        game = TestGame(art)
        name = f"tests/{split.name}-split-first.png"
        write_atomically(out / name, partial(start_picture, game))
        infos.append(TestInfo(
            env_id=split.label, problem=f"{art.name} (the first of {len(split.seeds)})", kind=str(art.kind),
            system_objective=str(art.objectives.get("system", "")), test_objective=str(art.objectives.get("test", "")),
            max_steps=default_max_steps(game), picture=name,
        ))
    return infos


def run_benchmark(config: BenchmarkConfig, out: Path, say: Callable[[str], None] = lambda _: None,
                  progress_bar: bool = False) -> dict[str, Any]:
    """Run the benchmark (see the module docstring) into the folder ``out`` (created; it
    is not checked here: the command checks it first) and return ``table.json``'s document."""
    t_start = time.perf_counter()
    check_config(config)
    out.mkdir(parents=True, exist_ok=True)
    say(f"loading the pool {config.pool}: {config.train_count} train and {config.test_count} held-out tests")
    t0 = time.perf_counter()
    splits = load_splits(config, out, progress=progress_bar)
    pool_seconds = time.perf_counter() - t0
    trained = []
    for algo in config.baselines():
        for seed in config.seeds:
            say(f"training {algo} seed {seed} on the train split ({config.steps:,} steps)")
            b = train_baseline(config, algo, seed, splits, out, progress_bar)
            final = b.curve[-1][1]
            say(f"  {b.seconds:.0f} s; met {100 * final['train']:.0f} % of train, {100 * final['test']:.0f} % of held-out tests")
            trained.append(b)
    suts = [b.sut for b in trained] + config.others()
    traces: dict[str, dict[str, list[Trace]]] = {}
    t0 = time.perf_counter()
    for name, split in splits.items():
        say(f"scoring {len(suts)} systems on the {len(split.files)} tests of the {name} split")
        traces[name] = score_systems(suts, split)
    score_seconds = time.perf_counter() - t0
    doc = benchmark_table(config, splits, trained, traces)
    say("writing the table, the learning curves and the report")
    cells = [Cell(split.label, sut, traces[name][sut], RUN_SEED, 0.0) for sut in suts for name, split in splits.items()]
    write_report(cells, out, _split_infos(splits, out))
    doc["seconds"] = {"pool": round(pool_seconds, 1), "training": round(sum(b.seconds for b in trained), 1),
                      "scoring": round(score_seconds, 1), "total": round(time.perf_counter() - t_start, 1)}
    doc["outputs"] = {k: str((out / v).resolve()) for k, v in OUTPUTS.items()}
    if trained:
        write_atomically(out / OUTPUTS["curves"], lambda tmp: plot_learning_curves(doc, tmp))
    else:
        doc["outputs"].pop("curves")
    write_text(out / OUTPUTS["table_md"], table_markdown(doc))
    write_text(out / OUTPUTS["table_json"], json.dumps(json_safe(doc), indent=1) + "\n")
    return doc


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""

    def write(tmp: Path) -> None:
        tmp.write_text(text)

    write_atomically(path, write)


OUTPUTS = {"table_md": "table.md", "table_json": "table.json", "curves": "learning-curves.png", "report": "report.html"}
"""The main files a benchmark writes into ``--out``."""


# --------------------------------------------------------------------------- command line


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``flowtest benchmark`` (defaults: :class:`BenchmarkConfig`)."""
    d = BenchmarkConfig("")
    p.add_argument("--pool", required=True, metavar="NAME",
                   help="the test pool: <family><n>/<size>x<size>[/static], e.g. reaction2/5x5 (flowtest_env.pools)")
    p.add_argument("--sut", action="extend", nargs="+", metavar="SYSTEM",
                   help="systems (repeatable): ppo (train the baselines of --algo), maskable-ppo, recurrent-ppo, "
                        "scripted:replanner, gr1, random, scripted:<name>, ppo:PATH "
                        f"(default: {' '.join(DEFAULT_SUTS)})")
    p.add_argument("--algo", nargs="+", choices=ALGOS, default=list(d.algos),
                   help=f"the baselines --sut ppo trains (default: {' '.join(d.algos)})")
    p.add_argument("--train-count", type=positive_int, default=d.train_count,
                   help=f"tests of the train split to train on (default {d.train_count})")
    p.add_argument("--test-count", type=positive_int, default=d.test_count,
                   help=f"held-out tests of the test split to score on (default {d.test_count})")
    p.add_argument("--steps", type=positive_int, default=d.steps,
                   help=f"training time steps per baseline and seed (default {d.steps})")
    p.add_argument("--seeds", nargs="+", type=nonnegative_int, default=list(d.seeds),
                   help=f"training seeds; the confidence intervals are over them (default {' '.join(map(str, d.seeds))})")
    p.add_argument("--curve-points", type=positive_int, default=d.curve_points,
                   help=f"learning-curve measurements per training run, besides the start (default {d.curve_points})")
    p.add_argument("--trainer", choices=TRAINERS, default=d.trainer,
                   help="who trains the baselines: native (FlowTest's batched PPO, default) or sb3 (stable-baselines3)")
    p.add_argument("--trust-model", action="store_true",
                   help="load stable-baselines3 zips given as --sut ppo:PATH, which unpickles them (code from the file "
                        "runs); native checkpoints never need it")
    p.add_argument("--out", type=Path, required=True,
                   help="output folder (table.md, table.json, learning-curves.png, report.html, models/, pool/); "
                        "an existing non-empty folder is refused unless --force")
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

    config = BenchmarkConfig(
        pool=args.pool, suts=tuple(args.sut or DEFAULT_SUTS), algos=tuple(dict.fromkeys(args.algo)),
        train_count=args.train_count, test_count=args.test_count, steps=args.steps,
        seeds=tuple(dict.fromkeys(args.seeds)), curve_points=args.curve_points, trainer=args.trainer,
    )
    if args.trust_model:
        from agents.checkpoint import trust_pickled_models

        trust_pickled_models(True)
    check_config(config)
    _check_out(args.out, args.force)

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
    for key in ("table_md", "table_json", "curves", "report"):
        if key in doc["outputs"]:
            sys.stdout.write(f"{key.replace('_', '.')}: {doc['outputs'][key]}\n")
    sys.stdout.flush()
    return EXIT_OK


COMMAND = Command("benchmark", "train the learned baselines on a test pool and score them on held-out tests", add_arguments, run)
