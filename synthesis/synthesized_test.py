"""A synthesized test: what :func:`synthesis.synthesize` returns (docs/method.md §5-§7).

:class:`SynthesizedTest` holds the problem, its automata and product graphs (§3-§4), the
routing result (the cuts ``C`` and the flow ``F``, §5), the test strategy (the restrictions
``C(q)``, §6), the independent checks it passed and, for a test agent, the agent's strategy
(§7). It lives apart from :mod:`synthesis.pipeline`, which imports every routing backend and
the solvers, so that what only reads a test (the artifact, the summary, a rebuilt pool test,
the environments) imports no solver.

Example
-------
>>> from synthesis import SynthesizedTest, load_problem, synthesize
>>> test = synthesize(load_problem("small-reactive"))
>>> isinstance(test, SynthesizedTest), test.routing.flow, test.cut_edges_outside_intermediate.size
(True, 2, 4)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .checks.verify import CheckReport
from .graphs.automata import SpecificationProduct
from .graphs.products import Products
from .model.strategy import TestStrategy
from .problems.problem import Problem
from .routing.result import RoutingResult
from .test_agent.realize import AgentSynthesis


@dataclass(frozen=True)
class SynthesizedTest:
    """A synthesized, checked test: everything an environment or a report needs.

    Attributes
    ----------
    problem
        The problem it was synthesized for.
    spec, products
        Its specification product ``B_pi`` and product graphs (docs/method.md §3-§4).
    routing
        The routing MILP's answer: the cuts, the flow, the solve statistics (§5).
    strategy
        The test strategy: the restrictions per history (§6).
    checks
        The independent checks it passed (bypass flow 0, the flow, feasibility).
    graph_seconds
        Seconds spent building the automata and product graphs.
    agent
        The test agent's synthesized strategy (agent problems only, §7).
    extra_stats
        Figures beyond the routing's (an agent synthesis's timings).
    caps
        The caps on physical restrictions it was synthesized under.
    """

    __test__ = False

    problem: Problem
    spec: SpecificationProduct
    products: Products
    routing: RoutingResult
    strategy: TestStrategy
    checks: CheckReport
    graph_seconds: float
    agent: AgentSynthesis | None = None
    extra_stats: dict[str, Any] = field(default_factory=dict)
    caps: dict[str, int] = field(default_factory=dict)

    @property
    def cut_edges_outside_intermediate(self) -> np.ndarray:
        """The cut set C: cut edges of G outside ``E(I)``."""
        e = self.routing.cut_edges
        out: np.ndarray = e[~self.products.touches_intermediate[e]]
        return out
