"""The benchmark's scores (protocol steps 3 and 5, docs/benchmark-protocol.md): every system
on every split, batched where it can be (:mod:`flowtest_env.scoring`), else through the single
env of each test's file as ``flowtest evaluate`` plays it; and the generalization curve."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from experiments.evaluation import Trace, env_named, run_episode
from synthesis.model.errors import ProblemError

from .config import RANDOM, REPORT_SPLITS, RUN_SEED, SPLIT_NAMES, BenchmarkConfig, runs_text
from .pool import Split
from .statistics import Scale, SystemRuns, normalized_summary
from .systems import member_policies
from .training_runs import TrainedBaseline


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
        env = env_named(str(path))
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
    return {
        "tests": s.tests,
        "runs": s.runs,
        "met": s.met,
        "realized": s.realized,
        "restrictions": s.restrictions,
        "steps": s.steps,
        "violated": s.violated,
        "open": s.open,
        "test_failures": int((met & ~realized).sum()),
        "per_test": list(s.per_test_met),
    }


def trace_verdicts(traces: Sequence[Trace]) -> dict[str, np.ndarray]:
    """The verdict arrays ``[1, tests]`` of single-env runs."""
    return {
        k: np.array([[t.verdict[k] for t in traces]], dtype=object if k == "system_objective" else None)
        for k in ("system_objective", "test_objective_realized", "restrictions", "steps")
    }


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


def score_all(
    config: BenchmarkConfig, splits: dict[str, Split], trained: Sequence[TrainedBaseline], say: Callable[[str], None]
) -> tuple[list[SystemRuns], dict[str, dict[str, list[Trace]]]]:
    """Score every system on every split (module docstring, step 3); return the systems'
    runs and the single-env traces (for the report)."""
    from flowtest_env.game import TestGame
    from flowtest_env.scoring import play_batch

    games = {name: [TestGame(a) for a in split.scored] for name, split in splits.items()}

    def batched(policies: dict[str, Any], options: dict[str, Any] | None = None) -> dict[str, Any]:
        row: dict[str, Any] = {}
        for split in SPLIT_NAMES:
            row[split] = {"greedy": None, "sampled": None}
            for mode, policy in policies.items():
                if mode == "sampled" and "greedy" in policies and split != "test":
                    continue  # a policy with a greedy mode is sampled on the held-out tests only (the time budget)
                v = play_batch(policy, games[split], 1 if mode == "greedy" else config.runs, RUN_SEED, options=options)
                row[split][mode] = verdict_metrics(v)
        return row

    systems: list[SystemRuns] = []
    for algo in config.baselines():
        runs = []
        for b in (b for b in trained if b.algo == algo and b.train_tests == config.train_count):
            say(f"scoring {algo} seed {b.seed} (greedy, and {runs_text(config.runs, 'sampled ')} per test)")
            runs.append({"seed": b.seed, "sut": b.sut, **batched(b.policies)})
        systems.append(SystemRuns(algo, "baseline", runs))
    single: list[str] = []
    played_alone: list[dict[str, Any]] = []  # the runs of members that play through the single env, filled below
    for spec in config.systems():  # one run per member (seed) of each system
        runs = []
        for seed, sut in zip(spec.seeds, spec.members, strict=True):
            member = member_policies(sut, games["train"])
            if member is None:
                single.append(sut)
                played_alone.append({"seed": seed, "sut": sut})
                runs.append(played_alone[-1])
                continue
            say(f"scoring {sut} in one batch per split" + ("" if seed is None else f" ({spec.name} seed {seed})"))
            runs.append({"seed": seed, "sut": sut, **batched(member.policies, member.options)})
        systems.append(SystemRuns(spec.name, spec.kind, runs))
    single = list(dict.fromkeys(single))
    traces: dict[str, dict[str, list[Trace]]] = {}
    report_suts = [RANDOM] + [b.sut for b in _report_models(config, trained)]
    for name, split in splits.items():
        say(
            f"scoring {', '.join(single) or 'no system'} through the single env on the {len(split.files)} {name} tests"
            + (" and the report's sample" if name in REPORT_SPLITS else "")
        )
        traces[name] = score_systems(single, split)
        if name in REPORT_SPLITS:
            traces[name].update(score_systems(report_suts, split, config.report_tests))
    for run in played_alone:
        run.update({n: {"greedy": verdict_metrics(trace_verdicts(traces[n][run["sut"]])), "sampled": None} for n in SPLIT_NAMES})
    return systems, traces


def _report_models(config: BenchmarkConfig, trained: Sequence[TrainedBaseline]) -> list[TrainedBaseline]:
    """The models the report shows: each baseline's first seed."""
    out = []
    for algo in config.baselines():
        first = next((b for b in trained if b.algo == algo and b.train_tests == config.train_count), None)
        if first is not None:
            out.append(first)
    return out


def generalization_curve(
    config: BenchmarkConfig, splits: dict[str, Split], trained: list[TrainedBaseline], main: SystemRuns | None, scale: Scale, say: Callable[[str], None]
) -> list[dict[str, Any]]:
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
            rows = [(r["test"]["greedy"]["per_test"], r["test"]["sampled"]["per_test"], r["train"]["greedy"]["met"]) for r in main.runs]
            seeds = [int(r["seed"]) for r in main.runs]
        else:
            rows = []
            runs = [b for b in trained if b.algo == algo and b.train_tests == n]
            seeds = [b.seed for b in runs]
            own = [TestGame(a) for a in splits["train"].artifacts[: min(n, config.scored("train"))]]
            if runs:
                say(f"generalization curve: scoring {len(runs)} runs of {algo} on {n} train tests")
            for b in runs:
                g = play_batch(b.policies["greedy"], held, 1, RUN_SEED)
                s = play_batch(b.policies["sampled"], held, config.runs, RUN_SEED)
                tr = play_batch(b.policies["greedy"], own, 1, RUN_SEED)
                rows.append((verdict_metrics(g)["per_test"], verdict_metrics(s)["per_test"], verdict_metrics(tr)["met"]))
        if not rows:
            continue
        points.append(
            {
                "algo": algo,
                "train_tests": n,
                "seeds": seeds,
                "greedy": normalized_summary([r[0] for r in rows], scale, config.bootstrap),
                "sampled": normalized_summary([r[1] for r in rows], scale, config.bootstrap),
                "train_met": float(np.mean([r[2] for r in rows])),
            }
        )
    return points
