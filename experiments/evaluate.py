"""``flowtest evaluate``: run systems under test against synthesized tests and report.

Every SUT (a policy name, :func:`agents.base.make_policy`) plays every env for
``--episodes`` episodes; episode ``i`` uses seed ``S + i`` for both the env and the
policy, so each run can be replayed exactly with
``flowtest evaluate --env ID --sut POLICY --episodes 1 --seed S+i --replay``.

Outputs in ``--out``:

* ``results.json`` — a list, one record per SUT x env: ``env``, ``sut``, ``episodes``,
  ``seed``, ``error`` (``null``, or why this SUT cannot play this env: the pair is
  reported, not run, and the others go on), ``system_objective_met_rate``, ``test_objective_realized_rate`` (among the
  runs that met the system objective; ``null`` if none did), ``violated``, ``open``,
  ``mean_restrictions``, ``mean_steps``, ``test_failures`` and ``failures`` (at most
  :data:`MAX_LISTED` listed, ``n_failures`` counts all; each with ``seed``, ``kind``,
  ``reason``, the ``verdict`` and its ``replay`` command).
* ``report.html`` — opens with an outcome matrix (systems x tests), then each test's
  picture and objectives, the failing runs as filmstrips with their replay commands, and
  every number (:mod:`experiments.report`); ``report.md`` — the matrix and one table per
  SUT, trace pictures and replay commands.
* ``traces/*.png`` — the trace pictures and filmstrips; ``tests/*.png`` — each test at
  its start.

``--tester`` chooses who plays the test's side: ``synthesized`` (default, the synthesized
test as the single-agent env plays it) or a learned tester ``ppo:PATH``
(:mod:`agents.testers`, played through :class:`agents.testers.VersusTesterEnv`). Records
carry ``tester``, ``trapped`` (runs a tester other than the synthesized one trapped: an
unfair test, not a FlowTest bug), ``sut_failures`` (faults caught: runs the SUT failed
by itself) and ``tester_fairness`` (the tester's exhaustive check,
:func:`flowtest_env.fairness.check_tester`; with more than one tester, or another one);
with several testers the report opens with a side-by-side table.

Two kinds of failure are told apart:

* a **SUT failure**: the system objective was violated, or not met within the step
  budget (``open``). The test never helps the SUT, so this is the SUT's fault.
* a **test failure** (a FlowTest bug, reported loudly): a run that met the system
  objective without realizing the test objective (the routing guarantee broke), or a
  *trapped* system: a run (violated, or still open when the step budget ran out) that
  stopped where no sequence of SUT actions can meet the system objective any more
  against the test as it really answers (its reactive restrictions, its test agent),
  although the static walls alone would still let the system through — the test, not
  the SUT, closed every way (:func:`can_still_meet`).
"""

from __future__ import annotations

import argparse
import html
import json
import shlex
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from synthesis.model.errors import ProblemError

from .cli import EXIT_OK, command, json_safe, nonnegative_int, positive_int, prepare_output_folder, write_atomically
from .report import GLOSSARY, TestInfo, fold_rows, outcome_class, render_html, test_name

REPORT_MARKER = ".flowtest-evaluation"
"""The file that marks a report folder as FlowTest's: ``--out`` refuses any other
non-empty folder unless ``--force``."""

MAX_LISTED = 20
"""How many failures a results record lists (``n_failures`` counts all)."""

EXIT_TEST_FAILED = 4
"""A test failure was found (a FlowTest bug), as ``flowtest synthesize``'s failed check."""


# --------------------------------------------------------------------------- runs


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

    @property
    def failed(self) -> bool:
        return self.kind != "pass"


def replay_command(env_id: str, sut: str, seed: int, tester: str = "synthesized") -> str:
    """The command that replays one run exactly (shell-quoted: a model path may hold spaces)."""
    against = "" if tester == "synthesized" else f" --tester {shlex.quote(tester)}"
    return (f"flowtest evaluate --env {shlex.quote(env_id)} --sut {shlex.quote(sut)}{against} "
            f"--episodes 1 --seed {seed} --replay")


def make_tester_env(env_id: str, tester: str) -> Any:
    """The env ``env_id`` with ``tester`` on the environment side: :func:`make_env` for
    ``synthesized`` (the synthesized test as the single-agent env plays it), else
    :class:`agents.testers.VersusTesterEnv` on the same problem and step budget.

    Raises
    ------
    ProblemError
        On an unknown tester, or one that cannot play ``env_id``.
    """
    if tester == "synthesized":
        return make_env(env_id)
    from agents.base import PolicyError
    from agents.testers import VersusTesterEnv, problem_of

    make_env(env_id).close()  # an unknown ID is reported as make_env reports it
    try:
        problem, max_steps = problem_of(env_id)
        return VersusTesterEnv(problem, tester, max_steps=max_steps)
    except PolicyError as exc:
        raise ProblemError(f"--tester {tester}: {exc}") from None


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


def make_env(env_id: str, **options: Any) -> Any:
    """The environment named by ``env_id``: a registered Gymnasium ID
    (``FlowTest-Maze2-v0``), else ``gymnasium.make("FlowTest-v0", test=env_id)``: a
    built-in name, a problem file (synthesized once, then cached) or an artifact file.
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
        return gym.make(flowtest_env.ANY_TEST_ID, test=env_id, **options)
    except ProblemError as exc:
        if Path(env_id).suffix or Path(env_id).exists():
            raise
        known = ", ".join(flowtest_env.ENV_IDS)
        raise ProblemError(
            f"unknown environment {env_id!r}: not a registered ID ({known}), a built-in name or a file"
        ) from exc


def classify(env: Any, verdict: dict[str, Any]) -> tuple[str, str]:
    """``(kind, reason)`` of a finished run: ``pass``, ``sut`` (a SUT failure) or ``test``
    (a FlowTest bug); see the module docstring."""
    met = verdict["system_objective"] == "met"
    u = env.unwrapped
    if hasattr(u, "trapped"):  # another tester than the synthesized one: no guarantee to break
        if met:
            return "pass", ""
        if u.trapped():
            return "trap", "trapped: the tester closed every way to the goal (an unfair test)"
        if verdict["system_objective"] == "violated":
            return "sut", "violated the system objective"
        return "sut", f"did not meet the system objective within {verdict['steps']} steps"
    if met and not verdict["test_objective_realized"]:
        return "test", "met the system objective without realizing the test objective"
    if met:
        return "pass", ""
    game, run = u.game, u.run
    if not can_still_meet(game, run) and _reachable_past_walls(game, run.history, run.system):
        return "test", "trapped: the test's restrictions closed every way to the goal"
    if verdict["system_objective"] == "violated":
        return "sut", "violated the system objective"
    return "sut", f"did not meet the system objective within {verdict['steps']} steps"


def can_still_meet(game: Any, run: Any) -> bool:
    """Whether some sequence of legal SUT actions from ``run`` meets the system objective,
    against the test as it really answers: its restrictions per history and its test
    agent moving by the synthesized strategy (no step budget).

    The test is deterministic, so this is a search over the run states
    ``(system, history, agent, memory)`` reachable from ``run``; ``run`` is not changed.
    A run that ends where this is false, although the static walls alone would let the
    system through (:func:`_reachable_past_walls`), was trapped by the test.
    """
    if run.outcome == "met":
        return True
    if run.done:
        return False
    seen = {run.key()}
    frontier = [run.copy()]
    while frontier:
        nxt = []
        for r in frontier:
            for a in np.flatnonzero(game.action_mask(r)):
                r2 = r.copy()
                game.step(r2, int(a))
                if r2.outcome == "met":
                    return True
                k = r2.key()
                if r2.done or k in seen:
                    continue
                seen.add(k)
                nxt.append(r2)
        frontier = nxt
    return False


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


def run_episode(env: Any, policy: Any, env_id: str, sut: str, seed: int, record: bool = True,
                tester: str = "synthesized") -> Trace:
    """Play one seeded episode; the trace keeps copies of the run states when ``record``."""
    obs, info = env.reset(seed=seed)
    policy.reset(seed)
    u = env.unwrapped
    trace = Trace(env_id, sut, seed, tester=tester)
    if record:
        trace.states.append(u.run.copy())
    while True:
        action = int(policy.act(obs, info))
        obs, _, terminated, truncated, info = env.step(action)
        trace.actions.append(action)
        if record:
            trace.states.append(u.run.copy())
        if terminated or truncated:
            break
    trace.verdict = dict(info["verdict"])
    trace.kind, trace.reason = classify(env, trace.verdict)
    return trace


@dataclass
class Cell:
    """The results of one SUT on one env."""

    env_id: str
    sut: str
    traces: list[Trace]
    seed: int
    seconds: float
    pictures: dict[str, str] = field(default_factory=dict)
    tester: str = "synthesized"
    fairness: dict[str, Any] | None = None
    error: str | None = None  # why this SUT cannot play this env (no runs then)

    def record(self) -> dict[str, Any]:
        """The ``results.json`` record (``error`` says why a pair has no runs)."""
        n = len(self.traces)
        met = [t for t in self.traces if t.verdict["system_objective"] == "met"]
        fails = [t for t in self.traces if t.failed]
        return {
            "env": self.env_id,
            "sut": self.sut,
            "episodes": n,
            "seed": self.seed,
            "system_objective_met_rate": len(met) / n if n else None,
            "test_objective_realized_rate": (
                sum(t.verdict["test_objective_realized"] for t in met) / len(met) if met else None
            ),
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
                    "replay": replay_command(self.env_id, self.sut, t.seed, self.tester),
                }
                for t in fails[:MAX_LISTED]
            ],
            "pictures": self.pictures,
            "seconds": round(self.seconds, 3),
            "error": self.error,
        }


def check_sut_names(suts: Sequence[str]) -> None:
    """Reject a SUT name no factory knows (a typo), before anything runs.

    Raises
    ------
    ProblemError
        On an unknown name.
    """
    from agents.base import policy_names
    from agents.scripted import SCRIPTED

    known = set(policy_names())
    for sut in suts:
        prefix, _, arg = sut.strip().partition(":")
        if prefix not in known:
            raise ProblemError(f"--sut {sut}: unknown policy; known: random, scripted:<name>, gr1, ppo:PATH")
        if prefix == "scripted" and (arg or "replanner") not in SCRIPTED:
            raise ProblemError(f"--sut {sut}: unknown scripted SUT {arg!r}; known: {', '.join(SCRIPTED)}")


def _policy(sut: str, env: Any) -> Any:
    """:func:`agents.base.make_policy`, its errors (unknown name, a model that does not fit
    the env) reported as invalid input."""
    from agents.base import PolicyError, make_policy

    try:
        return make_policy(sut, env)
    except PolicyError as exc:
        raise ProblemError(f"--sut {sut}: {exc}") from None


def evaluate(
    env_ids: Sequence[str],
    suts: Sequence[str],
    episodes: int,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    testers: Sequence[str] = ("synthesized",),
) -> list[Cell]:
    """Run every SUT against every env (``episodes`` seeded runs each), once per tester
    (``synthesized``: the synthesized test; ``ppo:PATH``: a learned tester,
    :mod:`agents.testers`). With more than one tester, every cell also carries the
    tester's exhaustive fairness check on the env's game. Each (SUT, test) pair runs on its
    own: a SUT that cannot play an env (a model trained on another observation shape, a
    graph for a grid policy) gives a :class:`Cell` with the reason in ``error`` and the
    run goes on.

    Raises
    ------
    ProblemError
        Before anything runs, if an env or a SUT name is invalid input (not a test, an
        unknown policy), or ``episodes < 1``.
    """
    from agents.base import PolicyError, make_policy

    if episodes < 1:
        raise ProblemError("--episodes must be at least 1")
    check_sut_names(suts)
    envs = {env_id: make_env(env_id) for env_id in dict.fromkeys(env_ids)}
    cells: list[Cell] = []
    for env in envs.values():
        env.close()
    total = len(envs) * len(suts) * len(testers)
    k = 0
    for env_id in envs:
        for tester in testers:
            env = make_tester_env(env_id, tester)
            fairness = tester_fairness(env_id, tester) if len(testers) > 1 or tester != "synthesized" else None
            against = "" if tester == "synthesized" else f" against {tester}"
            for sut in suts:
                k += 1
                t0 = time.perf_counter()
                try:
                    policy = make_policy(sut, env)
                except PolicyError as exc:
                    cells.append(Cell(env_id, sut, [], seed, time.perf_counter() - t0, tester=tester, fairness=fairness,
                                      error=str(exc)))
                    if progress is not None:
                        progress(f"[{k}/{total}] {sut} on {env_id}{against}: cannot play it: {exc}")
                    continue
                traces = []
                for i in range(episodes):
                    traces.append(run_episode(env, policy, env_id, sut, seed + i, tester=tester))
                    if progress is not None and (i + 1 == episodes or (i + 1) % max(1, episodes // 10) == 0):
                        progress(f"[{k}/{total}] {sut} on {env_id}{against}: {i + 1}/{episodes} episodes")
                cells.append(Cell(env_id, sut, traces, seed, time.perf_counter() - t0, tester=tester, fairness=fairness))
            env.close()
    return cells


# --------------------------------------------------------------------------- pictures


def _slug(text: str) -> str:
    return "".join(ch if ch.isalnum() else "-" for ch in text).strip("-").lower()


def _trace_legend(ax: Any, game: Any) -> list[Any]:
    """Legend entries for the path markers and the renderer's symbols, so a newcomer can
    read a trace picture without the env docs."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from flowtest_env import render

    def rgb(c: tuple[int, int, int]) -> tuple[float, ...]:
        return tuple(x / 255 for x in c)

    handles, _ = ax.get_legend_handles_labels()
    marker = {"linestyle": "", "markersize": 10}
    handles += [
        Line2D([], [], marker="o", color=rgb(render.SYSTEM), label="system under test", **marker),
        Patch(facecolor=rgb(render.GOAL), label="goal"),
        Line2D([], [], marker="o", markerfacecolor="none", markeredgewidth=2, color=rgb(render.TEST_CELL),
               label="hidden test cell", **marker),
        Patch(facecolor=rgb(render.BLOCKED), label="blocked cell"),
        Line2D([], [], color=rgb(render.WALL), lw=4, label="wall"),
    ]
    if game.artifact.kind == "agent":
        handles.append(Line2D([], [], marker="D", color=rgb(render.AGENT), label="test agent", **marker))
    return handles


def trace_picture(trace: Trace, path: Path) -> None:
    """Draw a run: on grids the engineer's view (walls, hidden test cells) at the end of
    the run with the SUT's path numbered step by step; on graphs a strip of frames."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flowtest_env.render import make_renderer

    env = make_env(trace.env_id)
    game = env.unwrapped.game
    env.close()
    tile = 48
    renderer = make_renderer(game, tile, "engineer")
    v = trace.verdict
    against = "" if trace.tester == "synthesized" else f" vs tester {trace.tester}"
    title = (
        f"{trace.sut} on {trace.env_id}{against} (seed {trace.seed})\n"
        f"system objective {v['system_objective']}, test objective "
        f"{'realized' if v['test_objective_realized'] else 'not realized'}, {v['steps']} steps, "
        f"{v['restrictions']} restricted decisions"
    )
    if game.is_grid:
        fig, ax = plt.subplots(figsize=(7, 7.6))
        ax.imshow(renderer.frame(trace.states[-1]))
        cells = [game.ts.places[int(game.ts.place[r.system])] for r in trace.states]
        xs = np.array([(c[1] + 0.5) * tile for c in cells], dtype=float)
        ys = np.array([(c[0] + 0.5) * tile for c in cells], dtype=float)
        # keep consecutive duplicates (waits) out of the line, jitter revisits slightly
        ax.plot(xs, ys, "-", color="#1f3b99", lw=2.5, alpha=0.8, zorder=3)
        ax.plot(xs[0], ys[0], "o", ms=14, color="#2ca02c", zorder=4, label="start")
        ax.plot(xs[-1], ys[-1], "X", ms=16, color="#d62728" if trace.failed else "#1f3b99", zorder=4, label="end")
        seen: dict[tuple[float, float], int] = {}
        last = None
        for step, (x, y) in enumerate(zip(xs, ys)):
            if last == (x, y):
                continue
            last = (x, y)
            n = seen.get((x, y), 0)
            seen[(x, y)] = n + 1
            if n < 3:
                ax.annotate(str(step), (x + (n - 1) * tile * 0.22, y - tile * 0.28), color="black", fontsize=9,
                            ha="center", va="center", zorder=5,
                            bbox={"boxstyle": "round,pad=0.12", "fc": "white", "ec": "none", "alpha": 0.8})
        ax.legend(handles=_trace_legend(ax, game), loc="upper center", bbox_to_anchor=(0.5, -0.01), ncol=4,
                  fontsize=8, frameon=False)
        ax.set_axis_off()
        ax.set_title(title, fontsize=10)
    else:
        # frames where the system moved (plus start and end), at most six, in two rows
        moves = [0] + [i for i in range(1, len(trace.states)) if trace.states[i].system != trace.states[i - 1].system]
        moves.append(len(trace.states) - 1)
        moves = sorted(set(moves))
        if len(moves) > 6:
            moves = [moves[int(round(j))] for j in np.linspace(0, len(moves) - 1, 6)]
        n_cols = min(3, len(moves))
        n_rows = (len(moves) + n_cols - 1) // n_cols
        fig, axes = plt.subplots(n_rows, n_cols, figsize=(4.6 * n_cols, 4.6 * n_rows + 0.8), squeeze=False)
        for ax in axes.ravel():
            ax.set_axis_off()
        for ax, i in zip(axes.ravel(), moves):
            ax.imshow(renderer.frame(trace.states[i]))
            ax.set_title(f"step {i}: at {game.ts.states[trace.states[i].system]}", fontsize=12)
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --------------------------------------------------------------------------- reports


def _pct(x: float | None) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def test_infos(env_ids: Sequence[str], out: Path) -> list[TestInfo]:
    """Draw each test at its start into ``out/tests/`` and collect what the report shows
    of it (problem, kind, objectives, step budget)."""
    from .filmstrip import start_picture

    (out / "tests").mkdir(exist_ok=True)
    infos = []
    for env_id in env_ids:
        env = make_env(env_id)
        u = env.unwrapped
        game = u.game
        env.close()
        name = f"tests/{_slug(env_id)}.png"
        write_atomically(out / name, lambda tmp, game=game: start_picture(game, tmp))
        art = game.artifact
        infos.append(TestInfo(
            env_id=env_id, problem=str(art.name), kind=str(art.kind),
            system_objective=str(art.objectives.get("system", "")), test_objective=str(art.objectives.get("test", "")),
            max_steps=int(u.max_steps), picture=name,
        ))
    return infos


def _filmstrip(trace: Trace, path: Path) -> None:
    from .filmstrip import filmstrip

    env = make_env(trace.env_id)
    game = env.unwrapped.game
    env.close()
    v = trace.verdict
    title = (f"{trace.sut} on {trace.env_id}, seed {trace.seed}: {trace.reason or v['system_objective']} "
             f"(system objective {v['system_objective']}, {v['steps']} steps)")
    filmstrip(game, trace.states, trace.actions, title, path)


def write_report(cells: Sequence[Cell], out: Path) -> list[dict[str, Any]]:
    """Write ``results.json``, ``report.md``, ``report.html``, the trace pictures and
    filmstrips (``traces/``) and a picture of each test (``tests/``)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "traces").mkdir(exist_ok=True)
    for cell in cells:
        cell_name = test_name({"env": cell.env_id, "tester": cell.tester})
        typical = next((t for t in cell.traces if not t.failed), None)
        failing = next((t for t in cell.traces if t.failed), None)
        for label, tr in (("typical", typical), ("failing", failing)):
            if tr is None:
                continue
            name = f"traces/{_slug(cell.sut)}--{_slug(cell_name)}--{label}.png"
            write_atomically(out / name, lambda tmp, tr=tr: trace_picture(tr, tmp))
            cell.pictures[label] = name
        if failing is not None:
            name = f"traces/{_slug(cell.sut)}--{_slug(cell_name)}--filmstrip.png"
            write_atomically(out / name, lambda tmp, tr=failing: _filmstrip(tr, tmp))
            cell.pictures["filmstrip"] = name
    tests = test_infos(list(dict.fromkeys(c.env_id for c in cells)), out)
    records = [cell.record() for cell in cells]
    write_atomically(out / "results.json", lambda tmp: tmp.write_text(json.dumps(json_safe(records), indent=1) + "\n"))
    md, body = _markdown(records), render_html(records, tests, (TESTER_COLUMNS, tester_comparison_rows(records)))
    write_atomically(out / "report.md", lambda tmp: tmp.write_text(md))
    write_atomically(out / "report.html", lambda tmp: tmp.write_text(body))
    return records


def test_failure_records(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The records with a test failure (a FlowTest bug)."""
    return [r for r in records if r["test_failures"]]


def _fair_text(f: dict[str, Any] | None) -> str:
    if f is None:
        return "–"
    return "fair" if f["fair"] else f"{f['traps']} trap states"


def tester_comparison_rows(records: Sequence[dict[str, Any]]) -> list[list[str]]:
    """Rows of the testers-side-by-side table (empty unless more than one tester): per
    env, tester and SUT, the test objective realized among successful runs, trapped runs,
    faults caught (runs the SUT failed by itself), mean restrictions, and the tester's
    exhaustive checks (fair: no reachable trap; guaranteed: no run meets the goal without
    the test objective)."""
    testers = list(dict.fromkeys(r.get("tester", "synthesized") for r in records))
    if len(testers) < 2:
        return []
    rows = []
    for r in records:
        f = r.get("tester_fairness")
        guaranteed = "–" if f is None else ("yes" if f["guaranteed"] else "no")
        rows.append([
            r["env"], r.get("tester", "synthesized"), r["sut"], str(r["episodes"]),
            _pct(r["test_objective_realized_rate"]), str(r.get("trapped", 0)), str(r.get("sut_failures", 0)),
            f"{r['mean_restrictions']:.1f}", _fair_text(f), guaranteed,
        ])
    return rows


TESTER_COLUMNS = ["test", "tester", "system", "runs", "realized (among met)", "trapped runs", "faults caught",
                  "restrictions", "fairness (exhaustive)", "guaranteed (exhaustive)"]


def tester_comparison_markdown(records: Sequence[dict[str, Any]]) -> list[str]:
    """The testers-side-by-side section of ``report.md`` (no lines for one tester)."""
    rows = tester_comparison_rows(records)
    if not rows:
        return []
    lines = ["## Testers side by side", "",
             "Realized: share of the runs meeting the system objective that realized the test objective. Trapped: "
             "runs that ended where no system play could still meet the objective against the tester (an unfair "
             "test). Faults caught: runs the system failed by itself. Fairness and guarantee are decided by an "
             "exhaustive search over the tester's choices and all system moves (`flowtest_env.fairness`).", "",
             "| " + " | ".join(TESTER_COLUMNS) + " |", "|" + "---|" * len(TESTER_COLUMNS)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return lines + [""]


def _markdown(records: Sequence[dict[str, Any]]) -> str:
    lines = ["# FlowTest evaluation", ""]
    bugs = test_failure_records(records)
    if bugs:
        lines += ["> **FLOWTEST BUG: a test failed its guarantee.** A run met the system objective without "
                  "realizing the test objective, or the test trapped the system. Please report it with the "
                  "replay commands below.", ""]
        for r in bugs:
            for f in r["failures"]:
                if f["kind"] == "test":
                    lines.append(f"- {r['sut']} on {r['env']}: {f['reason']} — `{f['replay']}`")
        lines.append("")
    envs = list(dict.fromkeys(test_name(r) for r in records))
    by = {(r["sut"], test_name(r)): r for r in records}
    lines += ["| system under test | " + " | ".join(envs) + " |", "|---" * (len(envs) + 1) + "|"]
    for group in fold_rows(records, envs):
        cells = []
        for env in envs:
            r = by.get((group[0], env))
            if r is None:
                cells.append("–")
                continue
            if r["error"]:
                cells.append("not run (see below)")
                continue
            met = round((r["system_objective_met_rate"] or 0) * r["episodes"])
            cells.append(f"{met}/{r['episodes']} met ({outcome_class(r)})")
        lines.append(f"| {', '.join(group)} | " + " | ".join(cells) + " |")
    lines.append("")
    lines += [f"- **{word}**: {html.unescape(text).replace('<b>', '').replace('</b>', '')}" for word, text in GLOSSARY]
    lines.append("")
    lines += [
        "System objective met: share of runs; test objective realized: share of the runs that met the "
        "system objective (the test guarantees 100 %). Restrictions: mean number of decisions taken "
        "with a restricted move. A failure is the SUT's unless marked *test*.",
        "",
    ]
    lines += tester_comparison_markdown(records)
    for sut in dict.fromkeys(r["sut"] for r in records):
        lines += [f"## {sut}", "", "| test | runs | met | realized | violated | open | restrictions | steps | failures |",
                  "|---|---|---|---|---|---|---|---|---|"]
        rows = [r for r in records if r["sut"] == sut]
        for r in rows:
            if r["error"]:
                lines.append(f"| {test_name(r)} | 0 | not run: {r['error']} |  |  |  |  |  |  |")
                continue
            lines.append(
                f"| {test_name(r)} | {r['episodes']} | {_pct(r['system_objective_met_rate'])} "
                f"| {_pct(r['test_objective_realized_rate'])} | {r['violated']} | {r['open']} "
                f"| {r['mean_restrictions']:.1f} | {r['mean_steps']:.1f} | {r['n_failures']}"
                f"{' (' + str(r['test_failures']) + ' test)' if r['test_failures'] else ''} |"
            )
        lines.append("")
        for r in rows:
            pics = r["pictures"]
            if r["failures"]:
                f = r["failures"][0]
                lines += [f"**{test_name(r)}** — first failure ({f['kind']}): {f['reason']}. Replay:", "",
                          f"    {f['replay']}", ""]
            for label in ("typical", "failing"):
                if label in pics:
                    lines.append(f"![{label} run of {sut} on {r['env']}]({pics[label]})")
            lines.append("")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- command line


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--env", nargs="+", required=True, metavar="ENV",
                   help="environments: registered IDs (FlowTest-Maze2-v0), built-in names (maze2), problem files "
                        "(mine.toml, synthesized once and cached) or artifact files (flowtest synthesize --out)")
    p.add_argument("--sut", nargs="+", required=True, metavar="POLICY",
                   help="systems under test: scripted:replanner, scripted:committed, scripted:fuel-blind, "
                        "scripted:greedy, random, gr1, ppo:PATH")
    p.add_argument("--tester", nargs="+", default=["synthesized"], metavar="TESTER",
                   help="who plays the test: synthesized (default), ppo:PATH (a learned tester, flowtest "
                        "train-tester); several give a side-by-side comparison")
    p.add_argument("--episodes", type=positive_int, default=10, help="runs per SUT and env (default 10)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seed of the first run; run i uses seed+i (default 0)")
    p.add_argument("--out", type=Path, help="report folder (required unless --replay); a folder holding files "
                   "FlowTest did not write is refused unless --force")
    p.add_argument("--force", action="store_true", help="write into an --out folder that holds other files")
    p.add_argument("--replay", action="store_true", help="print every step of the runs instead of a report")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def replay(env_id: str, sut: str, seed: int, stream: Any = None, tester: str = "synthesized") -> Trace:
    """Replay one run and print it step by step (state, legal actions, action, verdict)
    to ``stream`` (standard output by default)."""
    stream = sys.stdout if stream is None else stream
    env = make_tester_env(env_id, tester)
    policy = _policy(sut, env)
    trace = run_episode(env, policy, env_id, sut, seed, tester=tester)
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


@command("evaluate", "run systems under test against synthesized tests and write a report", _arguments)
def run_evaluate(args: argparse.Namespace) -> int:
    """Evaluate (or replay); exit 4 if a test failed its guarantee (a FlowTest bug)."""
    if args.replay:
        bug = False
        for env_id in args.env:
            for tester in args.tester:
                for sut in args.sut:
                    for i in range(args.episodes):
                        bug |= replay(env_id, sut, args.seed + i, tester=tester).kind == "test"
        return EXIT_TEST_FAILED if bug else EXIT_OK
    if args.out is None:
        raise ProblemError("--out is required (or use --replay)")
    # refuse bad IDs and SUTs before any run or any file: a SUT that can play none of the
    # tests is bad input (a missing model, a typo); one that cannot play some is a report row
    check_sut_names(args.sut)
    envs = [make_env(env_id) for env_id in dict.fromkeys(args.env)]
    for sut in args.sut:
        first: ProblemError | None = None
        for env in envs:
            try:
                _policy(sut, env)
                break
            except ProblemError as exc:
                first = first or exc
        else:
            assert first is not None
            raise first
    for env in envs:
        env.close()
    prepare_output_folder(args.out, REPORT_MARKER, args.force, "report folder")

    def progress(msg: str) -> None:
        if not args.quiet:
            sys.stderr.write(msg + "\n")
            sys.stderr.flush()

    cells = evaluate(args.env, args.sut, args.episodes, args.seed, progress, testers=args.tester)
    progress("drawing trace pictures")
    records = write_report(cells, args.out)
    for r in records:
        if r["error"]:
            sys.stdout.write(f"{r['sut']:24s} {test_name(r):30s} not run: {r['error']}\n")
            continue
        trapped = f"  trapped {r['trapped']}" if r["tester"] != "synthesized" else ""
        sys.stdout.write(
            f"{r['sut']:24s} {test_name(r):30s} met {_pct(r['system_objective_met_rate']):>6s}  "
            f"realized {_pct(r['test_objective_realized_rate']):>6s}  failures {r['n_failures']}{trapped}\n"
        )
    bugs = test_failure_records(records)
    if bugs:
        sys.stderr.write("flowtest: FLOWTEST BUG: a test failed its guarantee; see the report\n")
    sys.stdout.write(f"report: {(args.out / 'report.html').resolve()}\n")
    return EXIT_TEST_FAILED if bugs else EXIT_OK


DEMO_PPO_STEPS = 16_384
"""Training steps of the demo's PPO system (about ten seconds; ``python -m
experiments.bench_ppo`` measures how many it needs, see docs/benchmarks.md)."""


def _rl_installed() -> bool:
    import importlib.util

    return all(importlib.util.find_spec(m) is not None for m in ("torch", "stable_baselines3", "sb3_contrib"))


def run_evaluation_demo(out_dir: str | Path, episodes: int = 5, progress: Callable[[str], None] | None = None) -> Path:
    """The demo hook: evaluate the correct, faulty and GR(1) SUTs on ``FlowTest-Maze2-v0``,
    and, when the ``rl`` extra is installed, a PPO SUT: the model at
    ``<out_dir>/ppo-maze2.zip``, trained there first (:data:`DEMO_PPO_STEPS` steps, seed 0)
    if there is none. Write the report and return the path of ``report.html``."""
    out = Path(out_dir)
    suts = ["scripted:replanner", "gr1", "scripted:committed", "scripted:fuel-blind", "scripted:greedy", "random"]
    model = (out / "ppo-maze2.zip").resolve()  # absolute: the replay commands work from anywhere
    if not model.exists() and _rl_installed():
        from .train import train

        if progress is not None:
            progress(f"training a PPO system under test on FlowTest-Maze2-v0 ({DEMO_PPO_STEPS} steps)")
        train("FlowTest-Maze2-v0", DEMO_PPO_STEPS, model, seed=0, progress_bar=False, eval_episodes=0)
    if model.exists():
        suts.append(f"ppo:{model}")
    cells = evaluate(["FlowTest-Maze2-v0"], suts, episodes, 0, progress)
    write_report(cells, out)
    return out / "report.html"


# `flowtest train` lives in its own module; importing it here registers it with the single cli hook.
from . import train as _train  # noqa: E402,F401
