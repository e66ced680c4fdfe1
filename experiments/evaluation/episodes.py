"""Running systems under test through tests, one seeded episode at a time.

What the evaluation (:mod:`experiments.evaluation.runs`), the benchmark's single-env runs and
the trainers' success rate (:mod:`experiments.training`) all need: the env a name stands for
(:func:`env_named`, :func:`make_tester_env`), the SUT a name stands for (:func:`sut_policy`),
one run (:func:`run_episode`, a :class:`Trace`, which keeps the game it was played on, so
nothing drawn or explained afterwards builds the test again) and what its outcome means
(:func:`classify`). Episode ``i`` of a series uses seed ``S + i`` for both the env and the
policy, so each run can be replayed exactly.

Two kinds of failure are told apart:

* a **SUT failure**: the system objective was violated, or not met within the step
  budget (``open``). The test never helps the SUT, so this is the SUT's fault.
* a **test failure** (a FlowTest bug, reported loudly): a run that met the system
  objective without realizing the test objective (the routing guarantee broke), or a
  *trapped* system: a run (violated, or still open when the step budget ran out) that
  stopped where no sequence of SUT actions can meet the system objective any more
  against the test as it really answers (its reactive restrictions, its test agent),
  although the static walls alone would still let the system through — the test, not
  the SUT, closed every way (:func:`flowtest_env.fairness.can_still_meet_in_game`).

With a tester other than the synthesized one (:mod:`agents.testers`) a run that ends
where the system can no longer meet its objective is ``trap``: an unfair test, not a
FlowTest bug.

A planner from outside FlowTest (``python:``, ``cmd:``, :mod:`agents.external`) that
crashes, hangs or answers an action the test does not allow fails its run: a SUT failure
whose reason says what happened (``Trace.planner_error``), the run stopped where it was.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from synthesis.model.errors import InconsistentProblem, ProblemError

if TYPE_CHECKING:
    from synthesis.options import SynthesisOptions


@dataclass
class Trace:
    """One run: the seed, the run states after reset and every step, actions, verdict."""

    env_id: str
    sut: str
    seed: int
    states: list[Any] = field(default_factory=list)
    actions: list[int] = field(default_factory=list)
    verdict: dict[str, Any] = field(default_factory=dict)
    kind: str = "pass"
    reason: str = ""
    tester: str = "synthesized"
    planner_error: str = ""  # what a planner from outside FlowTest did wrong (it failed the run)
    game: Any = field(default=None, repr=False, compare=False)
    """The :class:`~flowtest_env.game.TestGame` the run was played on (``None`` for a trace
    made by hand): its pictures and its violation are drawn from it."""

    @property
    def failed(self) -> bool:
        return self.kind != "pass"


@dataclass(frozen=True)
class NamedEnv:
    """One test as a name resolved it, once (:func:`resolve_env`): the name (``--env``), the
    env built from it, and what the report reads of it (the game, the step budget, the
    problem's name). The runs play ``env``; the pictures, the report and the failures'
    explanations read ``game``: nothing after the resolution builds the test again."""

    env_id: str
    env: Any
    game: Any
    """The :class:`~flowtest_env.game.TestGame` the env plays."""
    max_steps: int
    """The env's step budget."""
    problem: str
    """The test's problem name."""

    @classmethod
    def of(cls, env_id: str, env: Any) -> NamedEnv:
        """``env`` (built from ``env_id``) with what the report reads of it."""
        u = env.unwrapped
        return cls(env_id, env, u.game, int(u.max_steps), str(u.game.artifact.name))


def resolve_env(env_id: str, among_several: bool = False, synthesis: SynthesisOptions | None = None) -> NamedEnv:
    """:func:`env_named` of ``env_id``, kept with its name; among several envs
    (``among_several``), an inconsistent problem's message says which ``--env`` it was.
    A problem file's test comes from its cache, else is synthesized under ``synthesis`` (its
    budgets; its ``progress`` hears the cached test found or the synthesis's stages:
    :func:`load_problem_files`).

    Raises
    ------
    ProblemError
        If ``env_id`` names no test.
    InconsistentProblem
        If it names a problem that has no test.
    """
    try:
        load_problem_files([env_id], synthesis)
        return NamedEnv.of(env_id, env_named(env_id))
    except InconsistentProblem as exc:
        if not among_several:
            raise
        raise InconsistentProblem(exc.reason, str(exc), source=f"--env {env_id}") from None


def load_problem_files(env_ids: Sequence[str], synthesis: SynthesisOptions | None = None) -> None:
    """Load the test of each problem file among ``env_ids`` (a name that is no registered ID,
    built-in or artifact file, :func:`flowtest_env.sources.is_problem_file`): from its cache
    entry, which ``flowtest synthesize`` fills too, else synthesized under ``synthesis``
    (:func:`flowtest_env.sources.load_test`: its time limit, and a ``progress`` that hears the
    cached test found or every stage of the synthesis, so no synthesis runs unseen). The tests
    stay in memory, where the envs built from those names (:func:`env_named`) find them; with
    ``synthesis`` ``None`` there is nothing to say, and the envs load them as they are built.

    Raises
    ------
    ProblemError
        If a problem file is not a valid problem.
    InconsistentProblem
        If it has no test.
    """
    if synthesis is None:
        return
    import gymnasium as gym

    from flowtest_env.sources import is_problem_file, load_test

    for env_id in env_ids:
        if env_id not in gym.registry and is_problem_file(env_id):
            load_test(env_id, synthesis)


def make_tester_env(env_id: str, tester: str) -> Any:
    """The env ``env_id`` with ``tester`` on the environment side: :func:`env_named` for
    ``synthesized`` (the synthesized test as the single-agent env plays it), else
    :func:`versus_tester_env`.

    Raises
    ------
    ProblemError
        On an unknown env or tester, or a tester that cannot play ``env_id``.
    """
    if tester == "synthesized":
        return env_named(env_id)
    env_named(env_id).close()  # an unknown ID is reported as env_named reports it
    return versus_tester_env(env_id, tester)


def versus_tester_env(env_id: str, tester: str) -> Any:
    """:class:`agents.testers.VersusTesterEnv`: ``tester`` against the system on the problem
    and step budget of ``env_id`` (a name known to stand for a test).

    Raises
    ------
    ProblemError
        On an unknown tester, or one that cannot play ``env_id``.
    """
    from agents.base import PolicyError
    from agents.testers import VersusTesterEnv, problem_of

    try:
        problem, max_steps = problem_of(env_id)
        return VersusTesterEnv(problem, tester, max_steps=max_steps)
    except PolicyError as exc:
        raise ProblemError(f"--tester {tester}: {exc}") from None


def env_named(env_id: str, **options: Any) -> Any:
    """The environment a name stands for (what ``--env`` takes): a registered Gymnasium ID
    (``FlowTest-Maze2-v0``, through ``gymnasium.make``), else :func:`flowtest_env.make_env`
    of a built-in name, a problem file (synthesized once, then cached) or an artifact file.
    ``options`` are env options (``memory``, ``obs_kind``, ...).

    Raises
    ------
    ProblemError
        If ``env_id`` is none of these (or the file is not a valid problem or artifact).
    """
    import gymnasium as gym

    import flowtest_env

    if env_id in gym.registry:
        known = ", ".join(flowtest_env.ENV_IDS)
        spec = gym.spec(env_id)
        entry = spec.entry_point if isinstance(spec.entry_point, str) else getattr(spec.entry_point, "__module__", "")
        if not str(entry).startswith("flowtest_env"):
            raise ProblemError(f"{env_id!r} is not a FlowTest environment; known: {known}")
        try:
            env = gym.make(env_id, **options)
        except gym.error.Error as exc:
            raise ProblemError(f"environment {env_id!r}: {exc}") from None
        if not isinstance(env.unwrapped, flowtest_env.FlowTestEnv):
            env.close()
            raise ProblemError(f"{env_id!r} is not a FlowTest environment; known: {known}")
        return env
    try:
        return flowtest_env.make_env(env_id, **options)
    except ProblemError as exc:
        if Path(env_id).suffix or Path(env_id).exists():
            raise
        known = ", ".join(flowtest_env.ENV_IDS)
        raise ProblemError(f"unknown environment {env_id!r}: not a registered ID ({known}), a built-in name or a file") from exc


def game_of_trace(trace: Trace) -> Any:
    """The :class:`~flowtest_env.game.TestGame` ``trace`` was played on: the one it keeps,
    else (a trace made without one) the game of the test its ``env_id`` names, built.

    Raises
    ------
    ProblemError
        If the trace keeps no game and its ``env_id`` names no test.
    """
    if trace.game is not None:
        return trace.game
    env = env_named(trace.env_id)
    game = env.unwrapped.game
    env.close()
    return game


def classify(env: Any, verdict: dict[str, Any]) -> tuple[str, str]:
    """``(kind, reason)`` of a finished run: ``pass``, ``sut`` (a SUT failure) or ``test``
    (a FlowTest bug); see the module docstring."""
    from flowtest_env.fairness import can_still_meet_in_game

    met = verdict["system_objective"] == "met"
    u = env.unwrapped
    if hasattr(u, "trapped"):  # another tester than the synthesized one: no guarantee to break
        if met:
            return "pass", ""
        if u.trapped():
            return "trap", "trapped: the tester closed every way to the goal (an unfair test)"
        if verdict["system_objective"] == "violated":
            return "sut", "violated the system objective"
        return "sut", f"did not meet the system objective within the step budget of {verdict['steps']} steps"
    if met and not verdict["test_objective_realized"]:
        return "test", "met the system objective without realizing the test objective"
    if met:
        return "pass", ""
    game, run = u.game, u.run
    if not can_still_meet_in_game(game, run) and _reachable_past_walls(game, run.history, run.system):
        return "test", "trapped: the test's restrictions closed every way to the goal"
    if verdict["system_objective"] == "violated":
        return "sut", "violated the system objective"
    return "sut", f"did not meet the system objective within the step budget of {verdict['steps']} steps"


_WALL_GAMES: dict[int, Any] = {}


def _reachable_past_walls(game: Any, history: int, state: int) -> bool:
    """Whether the system objective is reachable from ``(state, history)`` when only the
    static walls are enforced (the game with an external tester computes exactly this)."""
    from flowtest_env.game import TestGame

    key = id(game.artifact)
    walls = _WALL_GAMES.get(key)
    if walls is None:
        walls = _WALL_GAMES[key] = TestGame(game.artifact, game.setting, external_tester=True)
    return not walls.doomed[history][state]


def run_episode(env: Any, policy: Any, env_id: str, sut: str, seed: int, record: bool = True, tester: str = "synthesized") -> Trace:
    """Play one seeded episode; the trace keeps copies of the run states when ``record``.

    A planner that fails (:class:`agents.external.PlannerError`: it crashed, hung or
    answered an action the test does not allow) ends the run there: the trace is a SUT
    failure whose ``reason`` and ``planner_error`` say what happened."""
    from agents.external import PlannerError

    obs, info = env.reset(seed=seed)
    u = env.unwrapped
    trace = Trace(env_id, sut, seed, tester=tester, game=u.game)
    if record:
        trace.states.append(u.run.copy())
    try:
        policy.reset(seed)
        while True:
            action = int(policy.act(obs, info))
            obs, _, terminated, truncated, info = env.step(action)
            trace.actions.append(action)
            if record:
                trace.states.append(u.run.copy())
            if terminated or truncated:
                break
    except PlannerError as exc:
        trace.verdict = dict(u.game.verdict(u.run))
        trace.kind, trace.planner_error = "sut", str(exc)
        trace.reason = f"the planner failed: {exc}"
        return trace
    trace.verdict = dict(info["verdict"])
    trace.kind, trace.reason = classify(env, trace.verdict)
    end = getattr(policy, "episode_end", None)
    if callable(end):
        end(trace.verdict)
    return trace


def sut_policy(sut: Any, env: Any, step_timeout: float | None = None) -> Any:
    """The SUT called ``sut`` for ``env`` (:func:`agents.registry.make_policy`: a name, or a
    Policy or planner object), its errors (unknown name, a missing module or program, a
    model that does not fit the env) reported as invalid input.

    Raises
    ------
    ProblemError
        If ``sut`` names no policy or one that cannot play ``env``.
    """
    from agents.base import PolicyError
    from agents.registry import make_policy

    try:
        return make_policy(sut, env, step_timeout=step_timeout)
    except PolicyError as exc:
        raise ProblemError(f"--sut {sut}: {exc}") from None
