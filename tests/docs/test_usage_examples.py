"""Every public entry point shows its typical call in its docstring, and that example runs.

:data:`ENTRY_POINTS` is the one list of what a user imports: the synthesis front
(:mod:`synthesis`: loading problems, :func:`~synthesis.synthesize` and its options, the
summary, the artifact, the independent checks, the routing step alone), the environments (the registered IDs
through ``gymnasium.make``/``make_vec``, the vector env and pools, the options, the
observation layout, the step-by-step runtime, the PettingZoo envs, the torch vector env),
the systems under test (policies by name, your own planner, the native trainer) and the
Python call behind ``flowtest evaluate``. Each docstring holds a doctest (``>>>`` lines
with the output a reader can check); this test runs it in a fresh namespace, so an example
that drifts from the code, or leans on a name it did not import, fails here.

Examples that need torch (the ``rl`` extra) are skipped where torch is not installed;
examples that write files write them into a temporary folder they make themselves.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
from types import ModuleType
from typing import Any

import pytest

ENTRY_POINTS: tuple[str, ...] = (
    # synthesis: from a problem to a checked test
    "synthesis.load_problem",
    "synthesis.load_problem_file",
    "synthesis.make_problem",
    "synthesis.synthesize",
    "synthesis.SynthesisOptions",
    "synthesis.summary_of",
    "synthesis.artifact_of",
    "synthesis.TestArtifact",
    "synthesis.verify_artifact",
    "synthesis.checks.verify.check_test",
    "synthesis.routing.solve.solve_routing",
    # flowtest_env: a test as an environment
    "flowtest_env",
    "flowtest_env.make_env",
    "flowtest_env.load_test",
    "flowtest_env.EnvConfig",
    "flowtest_env.observation_layout",
    "flowtest_env.wrappers.VisitedPlaces",
    "flowtest_env.vector.PoolVectorEnv",
    "flowtest_env.vector.PoolVectorEnv.set_test_chooser",
    "flowtest_env.pools.load_pool",
    "flowtest_env.runtime.TestRuntime",
    "flowtest_env.multiagent.env",
    "flowtest_env.multiagent.parallel_env",
    "flowtest_env.scoring.score_policy",
    "flowtest_env.torch_vector.make_vec",
    # agents: the systems under test
    "agents.registry.make_policy",
    "agents.external",
    "agents.external.planner_policy",
    "agents.native_ppo.train",
    "agents.checkpoint.trust_pickled_models",
    # the library under the command line: evaluation and the benchmark protocol
    "experiments.evaluation.evaluate",
    "experiments.evaluation.write_report",
    "experiments.evaluation.replay",
    "experiments.benchmark.benchmark",
)
"""The dotted names of the public entry points, each of which must carry a running example."""

NEEDS_TORCH = ("flowtest_env.torch_vector", "agents.native_ppo")
"""Modules that import torch (the ``rl`` extra): their examples are skipped without it."""

OPTIONS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def resolve(dotted: str) -> tuple[Any, ModuleType]:
    """The object a dotted name names, and the module it is taken from (the longest
    importable prefix, then attributes)."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            module = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError as exc:
            if exc.name is None or not ".".join(parts[:cut]).startswith(exc.name):
                raise  # a module the entry point's own module imports is missing
            continue
        obj: Any = module
        for name in parts[cut:]:
            obj = getattr(obj, name)
        return obj, module
    raise AssertionError(f"{dotted}: no importable module")


def examples_of(dotted: str) -> doctest.DocTest:
    """The doctest of one entry point's own docstring (not of its members), with a fresh namespace."""
    if dotted.startswith(NEEDS_TORCH):
        pytest.importorskip("torch")
    obj, module = resolve(dotted)
    found = doctest.DocTestFinder(recurse=False).find(obj, dotted, module=inspect.getmodule(obj) or module, globs={})
    assert len(found) == 1 and found[0].examples, f"{dotted}: its docstring has no doctest example (an `Examples` section with >>> lines)"
    return found[0]


def test_the_list_names_each_entry_point_once() -> None:
    assert len(set(ENTRY_POINTS)) == len(ENTRY_POINTS)


def test_the_main_exports_are_covered() -> None:
    """The functions and option classes a user starts from are in the list (the error types and
    plain data types they return are not entry points)."""
    import flowtest_env
    import synthesis

    starts = {
        "load_problem",
        "load_problem_file",
        "make_problem",
        "synthesize",
        "SynthesisOptions",
        "summary_of",
        "artifact_of",
        "TestArtifact",
        "verify_artifact",
    }
    assert starts <= set(synthesis.__all__)
    assert {f"synthesis.{n}" for n in starts} <= set(ENTRY_POINTS)
    env_starts = {"make_env", "load_test", "EnvConfig", "observation_layout"}
    assert env_starts <= set(flowtest_env.__all__)
    assert {f"flowtest_env.{n}" for n in env_starts} <= set(ENTRY_POINTS)


@pytest.mark.parametrize("dotted", ENTRY_POINTS)
def test_entry_point_example_runs(dotted: str) -> None:
    test = examples_of(dotted)
    shown = [ex for ex in test.examples if not ex.options.get(doctest.SKIP)]
    assert shown, f"{dotted}: every example line is skipped; at least one must run"
    assert any(ex.want.strip() and ex.want.strip() != "..." for ex in shown), (
        f"{dotted}: the example prints nothing a reader can check (give the output of the typical call)"
    )
    report: list[str] = []
    runner = doctest.DocTestRunner(optionflags=OPTIONS)
    result = runner.run(test, out=report.append, clear_globs=True)
    assert result.failed == 0, f"{dotted}: {result.failed} of {result.attempted} example lines fail:\n" + "".join(report)
