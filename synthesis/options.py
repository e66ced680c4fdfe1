"""The options of a synthesis: what it may spend, how it runs, what it may choose beyond the problem.

:class:`SynthesisOptions` is plain frozen data, checked field by field by the rules of
:data:`SYNTHESIS_RULES` (:func:`synthesis.pipeline.check_options` applies them before any
work). It lives apart from :mod:`synthesis.pipeline`, which imports every routing backend and
the solvers, so that what only names options (a pool's provenance, the command line's
parsers) loads no solver.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

from .model.option_rules import COUNT, SETTING, Rule
from .problems.limits import MAX_GRAPH_EDGES
from .routing.options import RULES, Budgets, ModelOptions, RunOptions, default_of


@dataclass(frozen=True, kw_only=True)
class SynthesisOptions(Budgets, RunOptions):
    """What a synthesis may spend, how it runs, and what it may choose beyond the problem.

    The budgets (``time_limit``, ``after_first``, ``mip_rel_gap``, ``node_limit``,
    ``work_limit``, ``threads``, ``random_seed``) and the run options (``backend``,
    ``progress``, ``control``) are the routing model's own groups
    (:class:`~synthesis.routing.options.Budgets`, :class:`~synthesis.routing.options.RunOptions`:
    their docstrings say what each does), passed on to it by :func:`~synthesis.pipeline.milp_options`, with two
    fallbacks: ``time_limit=None`` is the problem's time limit, ``threads=None`` is one thread
    (so the answer is the same on every machine). Every field is checked by
    :func:`~synthesis.pipeline.check_options` before any work, by the rules the routing options, problem files
    and the command line share.

    Attributes
    ----------
    closed_loop
        :attr:`~synthesis.routing.options.ModelOptions.closed_loop`: also forbid restrictions that
        trap the system off entry nodes.
    setting
        How reactive obstacles are shown (:data:`~synthesis.model.strategy.SETTINGS`; ``None``:
        the problem's, else ``"instantaneous"``).
    agent_iterations
        Bound on the counterexample-guided loop of an agent problem (``None``: the test
        agent's ``max_iterations``).
    max_graph_edges
        Refuse problems whose product graph may exceed this many edges, before building
        anything (:mod:`synthesis.problems.limits`; ``None``: no limit).
    caps
        Caps on the physical restrictions a test may use (``max_walls``, ``max_doors``,
        ``max_restrictions``); each key given here replaces the problem's (:func:`~synthesis.pipeline.caps_of`).

    Example
    -------
    >>> from synthesis import SynthesisOptions, load_problem, synthesize
    >>> test = synthesize(load_problem("small-reactive"), SynthesisOptions(node_limit=10_000, caps={"max_walls": 4}))
    >>> test.routing.status, test.caps
    ('optimal', {'max_walls': 4})
    """

    closed_loop: bool = default_of(ModelOptions, "closed_loop")
    setting: str | None = None
    agent_iterations: int | None = None
    max_graph_edges: int | None = MAX_GRAPH_EDGES
    caps: dict[str, int] | None = None


SYNTHESIS_RULES: Mapping[str, Rule] = {
    **RULES,
    "setting": SETTING,
    "agent_iterations": COUNT,
    "max_graph_edges": COUNT,
    "caps": replace(RULES["caps"], optional=True),
}
"""The rule of each field of :class:`SynthesisOptions`: the routing options' (:data:`~synthesis.routing.options.RULES`)
and the synthesis's own."""
