"""Evaluating systems under test: every system against every test, seeded runs, verdicts.

The library behind ``flowtest evaluate`` (:mod:`experiments.cli.evaluate` parses its
arguments and calls :func:`evaluate`, then :func:`experiments.evaluation.results.write_report`).
Every SUT (a policy name, :func:`agents.registry.make_policy`; your own planner as
``python:MODULE:NAME`` or ``cmd:COMMAND``, :mod:`agents.external`; or a Python object) plays
every test for ``episodes`` episodes; episode ``i`` uses seed ``S + i`` for both the env and
the policy, so each run can be replayed exactly with
``flowtest evaluate --env ID --sut POLICY --episodes 1 --seed S+i --replay``
(:func:`replay_command`; for a ``python:`` or ``cmd:`` planner run from the directory the
evaluation ran in: the replay command starts with ``cd DIR &&``, and carries ``--step-timeout``).

Each test is resolved once (:func:`experiments.evaluation.episodes.resolve_env`) and handed
on: its runs play its env, and the report draws its game; nothing builds it again.

A planner from outside FlowTest that crashes, hangs past ``step_timeout`` or answers an
action the test does not allow fails that run (a SUT failure whose reason says what
happened and where); the planner process is ended, the next run starts a fresh one, and every
run is played: a planner that is slow on one test is still scored on the others, and one that
never answers ends each of its runs with a timeout verdict after ``step_timeout`` seconds.

``testers`` chooses who plays the test's side: ``synthesized`` (default, the synthesized
test as the single-agent env plays it) or a learned tester ``ppo:PATH``
(:mod:`agents.testers`, played through :class:`agents.testers.VersusTesterEnv`); with another
tester than the synthesized one, or several, every pair also carries the tester's exhaustive
fairness check (:func:`flowtest_env.fairness.check_tester`).

Two kinds of failure are told apart (:mod:`experiments.evaluation.episodes`): a **SUT
failure** (the system objective violated, or not met within the step budget: the SUT's
fault) and a **test failure** (a FlowTest bug, reported loudly: a run that met the system
objective without realizing the test objective, or a system the test trapped).
"""

from __future__ import annotations

import json
import os
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from synthesis.model.errors import ProblemError

from .episodes import NamedEnv, Trace, make_tester_env, resolve_env, run_episode, sut_policy, versus_tester_env
from .explain import explain, fold
from .violations import violation_of_trace

if TYPE_CHECKING:
    from synthesis.options import SynthesisOptions

MAX_LISTED = 20
"""How many failures a results record lists (``n_failures`` counts all)."""

EXTERNAL_PREFIXES = ("python:", "cmd:")
"""Systems named from outside FlowTest: their names depend on the working directory."""


class EvaluationInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) during :func:`evaluate`: ``cells`` holds the (system, test) pairs
    played to the end before it, and ``total`` how many there were to play."""

    def __init__(self, cells: list[Cell], total: int) -> None:
        super().__init__()
        self.cells, self.total = cells, total


def replay_command(
    env_id: str, sut: str, seed: int, tester: str = "synthesized", step_timeout: float | None = None, cwd: str | None = None, trust_model: bool = False
) -> str:
    """The command that replays one run exactly (shell-quoted: a model path may hold spaces).

    A ``python:`` or ``cmd:`` planner is found from the directory the evaluation ran in
    (``cwd``, default the current one): its command starts with ``cd DIR &&``, and
    carries ``--step-timeout`` when one was given. With
    ``trust_model`` (the evaluation loaded stable-baselines3 zips, ``--trust-model``) a
    ``ppo:`` system or tester's command carries ``--trust-model`` too."""
    against = "" if tester == "synthesized" else f" --tester {shlex.quote(tester)}"
    timeout = f" --step-timeout {step_timeout:g}" if step_timeout is not None and sut.startswith(("cmd:", "python:")) else ""
    trust = " --trust-model" if trust_model and (sut.startswith("ppo:") or tester.startswith("ppo:")) else ""
    command = f"flowtest evaluate --env {shlex.quote(env_id)} --sut {shlex.quote(sut)}{against}{timeout}{trust} --episodes 1 --seed {seed} --replay"
    if sut.startswith(EXTERNAL_PREFIXES):
        return f"cd {shlex.quote(cwd or os.getcwd())} && {command}"
    return command


def _models_trusted() -> bool:
    """Whether this process loads stable-baselines3 zips (``--trust-model``)."""
    from agents.checkpoint import pickled_models_trusted

    return pickled_models_trusted()


NOT_REPLAYABLE = "# no replay command: this system was given to evaluate() as a Python object; name it python:MODULE:NAME to get one"


def sut_label(sut: Any) -> str:
    """The name a system under test goes by in records and reports: its name, or for a
    Python object the ``python:MODULE:NAME`` that names it (:func:`agents.external.spec_of`),
    its ``name`` attribute, or its type."""
    if isinstance(sut, str):
        return sut
    from agents.external import spec_of

    name = getattr(sut, "name", None)
    if isinstance(name, str) and name:
        return name
    return spec_of(sut) or f"python object {getattr(sut, '__qualname__', type(sut).__name__)}"


def tester_fairness(env_id: str, tester: str) -> dict[str, Any] | None:
    """The exhaustive fairness check of ``tester`` on ``env_id``'s game
    (:func:`flowtest_env.fairness.check_tester`), ``None`` for an env without one fixed game."""
    from agents.base import PolicyError
    from agents.testers import VersusTesterEnv, problem_of
    from flowtest_env.fairness import check_tester

    try:
        problem, _ = problem_of(env_id)
        env = VersusTesterEnv(problem, tester)
    except PolicyError:
        return None
    return check_tester(env.ma, env.tester).summary()


@dataclass
class Cell:
    """The results of one SUT on one env: its runs (:class:`~experiments.evaluation.episodes.Trace`),
    why it was not run or stopped early, and the test it played (``test``, the resolved env:
    what the report draws), as :meth:`record` writes them to ``results.json``."""

    env_id: str
    sut: str
    traces: list[Trace]
    seed: int
    seconds: float
    pictures: dict[str, str] = field(default_factory=dict)
    tester: str = "synthesized"
    fairness: dict[str, Any] | None = None
    error: str | None = None  # why this SUT cannot play this env (no runs then)
    stopped: str | None = None  # why fewer runs than asked (kept for older records; every run is played now)
    replayable: bool = True  # False for a system given as a Python object without a name
    step_timeout: float | None = None
    problem: str = ""  # the test's problem name, for a report written without the tests' pictures
    cwd: str = field(default_factory=os.getcwd)
    trust_model: bool = field(default_factory=lambda: _models_trusted())
    test: NamedEnv | None = field(default=None, repr=False, compare=False)  # the test played (its game drawn)

    def replay(self, trace: Trace) -> str:
        """The replay command of one of this cell's runs."""
        if not self.replayable:
            return NOT_REPLAYABLE
        return replay_command(trace.env_id, self.sut, trace.seed, self.tester, self.step_timeout, self.cwd, self.trust_model)

    def record(self) -> dict[str, Any]:
        """The ``results.json`` record (``error`` says why a pair has no runs)."""
        n = len(self.traces)
        met = [t for t in self.traces if t.verdict["system_objective"] == "met"]
        fails = [t for t in self.traces if t.failed]
        explained = [explain(t) for t in fails]
        outcomes = fold([(t.seed, t.kind, e) for t, e in zip(fails, explained, strict=True)], [t.env_id for t in fails])
        first = {(t.env_id, t.seed): t for t in reversed(fails)}
        return {
            "env": self.env_id,
            "sut": self.sut,
            "episodes": n,
            "seed": self.seed,
            "system_objective_met_rate": len(met) / n if n else None,
            "test_objective_realized_rate": (sum(t.verdict["test_objective_realized"] for t in met) / len(met) if met else None),
            "violated": sum(t.verdict["system_objective"] == "violated" for t in self.traces),
            "open": sum(t.verdict["system_objective"] == "open" for t in self.traces),
            "mean_restrictions": float(np.mean([t.verdict["restrictions"] for t in self.traces])) if n else None,
            "mean_steps": float(np.mean([t.verdict["steps"] for t in self.traces])) if n else None,
            "test_failures": sum(t.kind == "test" for t in self.traces),
            "tester": self.tester,
            "trapped": sum(t.kind == "trap" for t in self.traces),
            "sut_failures": sum(t.kind == "sut" for t in self.traces),
            "tester_fairness": self.fairness,
            "n_failures": len(fails),
            "failures": [
                {
                    "seed": t.seed,
                    "kind": t.kind,
                    "reason": t.reason,
                    "verdict": t.verdict,
                    "replay": self.replay(t),
                    "violation": violation_of_trace(t),
                    "explanation": e.to_dict(),
                }
                for t, e in zip(fails[:MAX_LISTED], explained, strict=False)
            ],
            "outcomes": [{**o.to_dict(), "replay": self.replay(first[(o.tests[0], o.seeds[0])])} for o in outcomes],
            "pictures": self.pictures,
            "seconds": round(self.seconds, 3),
            "error": self.error,
            "stopped": self.stopped,
        }


def check_sut_names(suts: Sequence[Any]) -> None:
    """Reject a SUT name no factory knows (a typo), a ``python:`` module or name that is
    missing, or a ``cmd:`` program that is not found, before anything runs (Python
    objects are checked when they are built).

    Raises
    ------
    ProblemError
        On an unknown or unusable name.
    """
    from agents.base import PolicyError
    from agents.external import check_spec
    from agents.registry import KNOWN, policy_names
    from agents.scripted import SCRIPTED

    known = set(policy_names())
    for sut in suts:
        if not isinstance(sut, str):
            continue
        prefix, _, arg = sut.strip().partition(":")
        if prefix not in known:
            raise ProblemError(f"--sut {sut}: unknown policy; known: {KNOWN}")
        if prefix == "scripted" and (arg or "replanner") not in SCRIPTED:
            raise ProblemError(f"--sut {sut}: unknown scripted SUT {arg!r}; known: {', '.join(SCRIPTED)}")
        try:
            check_spec(prefix, arg)
        except PolicyError as exc:
            raise ProblemError(f"--sut {sut}: {exc}") from None


def check_suts_can_play(tests: Sequence[NamedEnv], suts: Sequence[Any], step_timeout: float | None = None) -> None:
    """Refuse a SUT that can play none of ``tests`` (a missing model, a typo): bad input,
    before any run or any file. A SUT that cannot play some of them is a report row
    (:func:`evaluate` gives its pair an ``error``), not an error.

    Raises
    ------
    ProblemError
        The first reason a SUT could not play, for a SUT that can play none of the tests.
    """
    for sut in suts:
        first: ProblemError | None = None
        for test in tests:
            try:
                close = getattr(sut_policy(sut, test.env, step_timeout), "close", None)
                if callable(close):
                    close()
                break
            except ProblemError as exc:
                first = first or exc
        else:
            assert first is not None
            raise first


def resolve_envs(env_ids: Sequence[str | NamedEnv], synthesis: SynthesisOptions | None = None) -> list[NamedEnv]:
    """Each distinct test of ``env_ids`` resolved once (:func:`~experiments.evaluation.episodes.resolve_env`;
    a :class:`NamedEnv` already resolved is kept as it is), in their order. A problem file's
    test comes from its cache (which ``flowtest synthesize`` fills), else is synthesized under
    ``synthesis``: its time limit, and its ``progress`` and ``control``, which hear the cached test
    found or every stage of the synthesis (``flowtest evaluate`` shows them as ``flowtest
    synthesize`` does).

    Raises
    ------
    ProblemError
        If a name stands for no test.
    InconsistentProblem
        If it names a problem without a test (among several, the message says which ``--env``).

    Example
    -------
    >>> from experiments.evaluation import resolve_envs
    >>> from synthesis import SynthesisOptions
    >>> tests = resolve_envs(["small-reactive", "maze2"], SynthesisOptions(time_limit=60, progress=print))
    >>> [(t.env_id, t.problem, t.max_steps > 0) for t in tests]
    [('small-reactive', 'small-reactive', True), ('maze2', 'maze2', True)]
    >>> for t in tests:
    ...     t.env.close()
    """
    several = len(env_ids) > 1
    named: dict[str, NamedEnv] = {}
    for e in env_ids:
        key = e.env_id if isinstance(e, NamedEnv) else e
        if key not in named:
            named[key] = e if isinstance(e, NamedEnv) else resolve_env(e, several, synthesis)
    return list(named.values())


def evaluate(
    env_ids: Sequence[str | NamedEnv],
    suts: Sequence[Any],
    episodes: int,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    testers: Sequence[str] = ("synthesized",),
    step_timeout: float | None = None,
) -> list[Cell]:
    """Run every SUT against every env (``episodes`` seeded runs each), once per tester
    (``synthesized``: the synthesized test; ``ppo:PATH``: a learned tester,
    :mod:`agents.testers`). With more than one tester, every cell also carries the
    tester's exhaustive fairness check on the env's game. Each (SUT, test) pair runs on its
    own: a SUT that cannot play an env (a model trained on another observation shape, a
    graph for a grid policy) gives a :class:`Cell` with the reason in ``error``, and a
    planner that fails a run (crashes, hangs past ``step_timeout``, answers an action the
    test does not allow) stops its pair with that run as a failure; the others go on.

    A SUT is a name (``"scripted:replanner"``, ``"python:my_planner:Bfs"``,
    ``"cmd:python3 planner.py"``) or a Python object: a :class:`agents.base.Policy`, or
    a planner (a function ``act(observation, mask)``, a class or factory of planners;
    :mod:`agents.external`).

    An env is a name (a registered ID, a built-in name, a problem or an artifact file) or a
    :class:`NamedEnv` a caller resolved before (:func:`resolve_envs`): each is resolved once,
    its runs play its env and every :class:`Cell` carries it for the report. Envs resolved
    here are closed at the end; those handed in stay the caller's.

    Raises
    ------
    ProblemError
        Before anything runs, if an env or a SUT name is invalid input (not a test, an
        unknown policy, a missing module or program), or ``episodes < 1``.
    EvaluationInterrupted
        On Ctrl-C (a ``KeyboardInterrupt``), with the pairs played to the end.

    Examples
    --------
    >>> from experiments.evaluation import evaluate
    >>> def greedy(observation, mask):
    ...     return observation["allowed"][0]
    >>> cells = evaluate(["small-reactive"], [greedy, "scripted:replanner"], episodes=3)
    >>> [(cell.sut, cell.record()["system_objective_met_rate"]) for cell in cells]
    [('python object greedy', 0.0), ('scripted:replanner', 1.0)]
    """
    if episodes < 1:
        raise ProblemError("--episodes must be at least 1")
    check_sut_names(suts)
    from synthesis.options import SynthesisOptions

    # a problem file synthesized here says its stages to the same progress as the runs
    tests = resolve_envs(env_ids, None if progress is None else SynthesisOptions(progress=progress))
    given = {id(e) for e in env_ids if isinstance(e, NamedEnv)}
    cells: list[Cell] = []
    total = len(tests) * len(suts) * len(testers)
    try:
        _play(tests, suts, testers, episodes, seed, progress, step_timeout, cells, total)
    except KeyboardInterrupt:
        raise EvaluationInterrupted(cells, total) from None
    finally:
        for test in tests:
            if id(test) not in given:
                test.env.close()
    return cells


def _play(
    tests: Sequence[NamedEnv],
    suts: Sequence[Any],
    testers: Sequence[str],
    episodes: int,
    seed: int,
    progress: Callable[[str], None] | None,
    step_timeout: float | None,
    cells: list[Cell],
    total: int,
) -> None:
    """:func:`evaluate`'s loop: each pair played to the end is appended to ``cells``. The
    synthesized tester plays each test's own env; another tester its own
    :func:`~experiments.evaluation.episodes.versus_tester_env`, closed after its pairs."""
    from agents.base import PolicyError
    from agents.external import spec_of
    from agents.registry import make_policy

    k = 0
    for test in tests:
        env_id = test.env_id
        for tester in testers:
            env = test.env if tester == "synthesized" else versus_tester_env(env_id, tester)
            problem = test.problem
            fairness = tester_fairness(env_id, tester) if len(testers) > 1 or tester != "synthesized" else None
            against = "" if tester == "synthesized" else f" against {tester}"
            for sut in suts:
                k += 1
                label = sut_label(sut)
                replayable = isinstance(sut, str) or (label.startswith("python:") and label == spec_of(sut))
                cell = Cell(
                    env_id, label, [], seed, 0.0, tester=tester, fairness=fairness, replayable=replayable, step_timeout=step_timeout, problem=problem, test=test
                )
                t0 = time.perf_counter()
                try:
                    policy = make_policy(sut, env, step_timeout=step_timeout)
                except PolicyError as exc:
                    cell.error, cell.seconds = str(exc), time.perf_counter() - t0
                    cells.append(cell)
                    if progress is not None:
                        progress(f"[{k}/{total}] {label} on {env_id}{against}: cannot play it: {exc}")
                    continue
                try:
                    for i in range(episodes):
                        trace = run_episode(env, policy, env_id, label, seed + i, tester=tester)
                        cell.traces.append(trace)
                        if trace.planner_error and progress is not None:
                            progress(f"[{k}/{total}] {label} on {env_id}{against}: the planner failed in run {i + 1} of {episodes}: {trace.planner_error}")
                        if progress is not None and (i + 1 == episodes or (i + 1) % max(1, episodes // 10) == 0):
                            progress(f"[{k}/{total}] {label} on {env_id}{against}: {i + 1}/{episodes} episodes")
                finally:
                    close = getattr(policy, "close", None)
                    if callable(close) and policy is not sut:
                        close()
                cell.seconds = time.perf_counter() - t0
                cells.append(cell)
            if env is not test.env:
                env.close()


def replay(env_id: str, sut: str, seed: int, stream: Any = None, tester: str = "synthesized", step_timeout: float | None = None) -> Trace:
    """Replay one run and print it step by step (state, legal actions, action, verdict)
    to ``stream`` (standard output by default): what ``flowtest evaluate --replay`` prints.

    Raises
    ------
    ProblemError
        If ``env_id``, ``sut`` or ``tester`` is invalid input.

    Examples
    --------
    >>> import io
    >>> from experiments.evaluation import replay
    >>> out = io.StringIO()
    >>> replay("small-reactive", "scripted:replanner", seed=0, stream=out).verdict["system_objective"]
    'met'
    >>> out.getvalue().splitlines()[0]
    'scripted:replanner on small-reactive, seed 0'
    """
    stream = sys.stdout if stream is None else stream
    env = make_tester_env(env_id, tester)
    policy = sut_policy(sut, env, step_timeout)
    try:
        trace = run_episode(env, policy, env_id, sut, seed, tester=tester)
    finally:
        close = getattr(policy, "close", None)
        if callable(close):
            close()
    game = env.unwrapped.game
    against = "" if tester == "synthesized" else f" against tester {tester}"
    stream.write(f"{sut} on {env_id}{against}, seed {seed}\n")
    for k, a in enumerate(trace.actions):
        r = trace.states[k]
        mask = game.action_mask(r)
        legal = ",".join(game.action_name(r.system, i) for i in np.flatnonzero(mask))
        stream.write(f"step {k:3d}  {json.dumps(game.state_json(r.system))}  legal [{legal}]  -> {game.action_name(r.system, a)}\n")
    stream.write(f"verdict: {json.dumps(trace.verdict)}\n")
    stream.write(f"outcome: {trace.kind}{': ' + trace.reason if trace.reason else ''}\n")
    env.close()
    return trace
