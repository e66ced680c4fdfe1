"""FlowTest's synthesis: from a problem to a checked test (method.md).

The package is split by stage; each sub-package imports only from those before it:

* :mod:`synthesis.model` — transition systems, objectives, test strategies, errors;
* :mod:`synthesis.graphs` — the objectives' automata and the product graphs (method.md §3-4);
* :mod:`synthesis.problems` — the :class:`Problem` value, problem files, built-ins, random
  grids, size limits;
* :mod:`synthesis.routing` — the routing MILP, its heuristic and the HiGHS runner (§5);
* :mod:`synthesis.checks` — the independent checks of a test (Theorems 1, 2);
* :mod:`synthesis.agent` — the dynamic test agent (§7);
* :mod:`synthesis.pipeline` — :func:`synthesize`, the one entry point;
* :mod:`synthesis.artifacts` — the JSON summary, the versioned test artifact, cache keys.

What is exported here is the public API; everything else may move between versions.
"""

from .artifacts.artifact import TestArtifact, artifact_of, verify_artifact
from .artifacts.summary import summary_of
from .checks.verify import CheckReport
from .model.errors import CheckFailed, FlowTestError, InconsistentProblem, ProblemError, ProblemTooLarge
from .model.strategy import TestStrategy
from .model.systems import TransitionSystem
from .pipeline import SynthesisOptions, SynthesizedTest, synthesize
from .problems.builtins import BUILTINS
from .problems.files import load_problem_file
from .problems.load import load_problem
from .problems.problem import Problem, make_problem
from .routing.milp import RoutingResult
from .routing.solver_control import SolveControl

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
