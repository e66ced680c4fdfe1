"""FlowTest's synthesis: from a problem to a checked test (docs/method.md).

The package is split by stage; each sub-package imports only from those before it:

* :mod:`synthesis.model` — transition systems, objectives, test strategies, errors;
* :mod:`synthesis.graphs` — the objectives' automata and the product graphs (docs/method.md §3-4);
* :mod:`synthesis.problems` — the :class:`Problem` value, problem files, built-ins, random
  grids, size limits;
* :mod:`synthesis.routing` — the routing MILP, its heuristic and the HiGHS runner (§5);
* :mod:`synthesis.checks` — the independent checks of a test (Theorems 1, 2);
* :mod:`synthesis.test_agent` — the dynamic test agent (§7);
* :mod:`synthesis.options` — :class:`SynthesisOptions`, what a synthesis may spend and choose;
* :mod:`synthesis.pipeline` — :func:`synthesize`, the one entry point;
* :mod:`synthesis.synthesized_test` — :class:`SynthesizedTest`, what it returns (it imports no
  solver, so what only reads a test, an artifact or an environment, loads none);
* :mod:`synthesis.artifacts` — the JSON summary, the versioned test artifact, cache keys.

What is exported here is the public API; everything else may move between versions. The
names are imported on first use, not with the package.
"""

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .artifacts.artifact import TestArtifact, artifact_of, verify_artifact
    from .artifacts.summary import summary_of
    from .checks.verify import CheckReport
    from .model.errors import CheckFailed, FlowTestError, InconsistentProblem, ProblemError, ProblemTooLarge
    from .model.strategy import TestStrategy
    from .model.systems import TransitionSystem
    from .options import SynthesisOptions
    from .pipeline import synthesize
    from .problems.builtins import BUILTINS
    from .problems.files import load_problem_file
    from .problems.load import load_problem
    from .problems.problem import Problem, make_problem
    from .routing.result import RoutingResult
    from .routing.solve_status import SolveControl
    from .synthesized_test import SynthesizedTest

_PUBLIC: dict[str, str] = {
    "BUILTINS": ".problems.builtins",
    "CheckFailed": ".model.errors",
    "CheckReport": ".checks.verify",
    "FlowTestError": ".model.errors",
    "InconsistentProblem": ".model.errors",
    "Problem": ".problems.problem",
    "ProblemError": ".model.errors",
    "ProblemTooLarge": ".model.errors",
    "RoutingResult": ".routing.result",
    "SolveControl": ".routing.solve_status",
    "SynthesisOptions": ".options",
    "SynthesizedTest": ".synthesized_test",
    "TestArtifact": ".artifacts.artifact",
    "TestStrategy": ".model.strategy",
    "TransitionSystem": ".model.systems",
    "artifact_of": ".artifacts.artifact",
    "load_problem": ".problems.load",
    "load_problem_file": ".problems.files",
    "make_problem": ".problems.problem",
    "summary_of": ".artifacts.summary",
    "synthesize": ".pipeline",
    "verify_artifact": ".artifacts.artifact",
}
"""Where each public name lives: imported on first use (PEP 562), so importing one module of
the package (say ``synthesis.routing.backends.cpsat_pool`` at the start of ``flowtest synthesize``)
does not load all of them with NumPy, SciPy and HiGHS, and reading a test
(``synthesis.artifacts.artifact``, the environments) loads no solver."""


def __getattr__(name: str) -> Any:
    """A public name of :data:`__all__`, imported from its module on first use."""
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "BUILTINS",
    "CheckFailed",
    "CheckReport",
    "FlowTestError",
    "InconsistentProblem",
    "Problem",
    "ProblemError",
    "ProblemTooLarge",
    "RoutingResult",
    "SolveControl",
    "SynthesisOptions",
    "SynthesizedTest",
    "TestArtifact",
    "TestStrategy",
    "TransitionSystem",
    "artifact_of",
    "load_problem",
    "load_problem_file",
    "make_problem",
    "summary_of",
    "synthesize",
    "verify_artifact",
]
