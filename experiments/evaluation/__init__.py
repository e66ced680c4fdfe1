"""Evaluating systems under test against tests: the library behind ``flowtest evaluate``.

:func:`evaluate` plays every system against every test (seeded runs, verdicts, the two kinds
of failure told apart) and returns one :class:`Cell` per pair; :func:`write_report` writes
their ``results.json``, ``report.md``, ``report.html`` and pictures; :func:`replay` prints one
run step by step. A test is resolved once (:func:`resolve_envs`) and handed on to the runs and
the report.

The modules, one job each: :mod:`~experiments.evaluation.episodes` (one seeded run, what its
outcome means), :mod:`~experiments.evaluation.runs` (every pair), :mod:`~experiments.evaluation.results`
(the files), :mod:`~experiments.evaluation.report` (the HTML page),
:mod:`~experiments.evaluation.violations` (what broke in a violated run),
:mod:`~experiments.evaluation.explain` (what a failing run did, in one line), and the pictures
:mod:`~experiments.evaluation.trace_picture` and :mod:`~experiments.evaluation.filmstrip`.

Example::

    from experiments.evaluation import evaluate, write_report

    cells = evaluate(["FlowTest-Maze2-v0", "mine.toml"], ["scripted:replanner", "python:my_planner:act"], episodes=10)
    records = write_report(cells, Path("report"))    # results.json, report.md, report.html
"""

from __future__ import annotations

from .episodes import NamedEnv, Trace, env_named, load_problem_files, resolve_env, run_episode
from .results import REPORT_MARKER, test_failure_records, write_partial_report, write_report
from .runs import Cell, EvaluationInterrupted, check_sut_names, check_suts_can_play, evaluate, replay, replay_command, resolve_envs

__all__ = [
    "REPORT_MARKER",
    "Cell",
    "EvaluationInterrupted",
    "NamedEnv",
    "Trace",
    "check_sut_names",
    "check_suts_can_play",
    "env_named",
    "evaluate",
    "load_problem_files",
    "replay",
    "replay_command",
    "resolve_env",
    "resolve_envs",
    "run_episode",
    "test_failure_records",
    "write_partial_report",
    "write_report",
]
