"""The JSON summary of a synthesized test: the contract of ``flowtest synthesize --json``."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..checks.physical import physical_counts
from ..graphs.automata import SpecificationProduct
from ..graphs.products import Products
from ..model.strategy import TestStrategy
from ..problems.problem import Problem
from ..synthesized_test import SynthesizedTest

DERIVED_KEYS: tuple[str, ...] = (
    "problem",
    "environment",
    "n_walls",
    "n_doors",
    "n_one_way_walls",
    "physical",
    "cuts",
    "restrictions",
    "static_obstacles",
    "bypass_flow",
    "histories",
)
"""Summary fields that come back from the problem, its product graphs and the test's cuts
(:func:`derived_summary`); the rest says how the solver got there."""
DERIVED_STATS: tuple[str, ...] = ("transition_system", "automaton", "graph", "system_graph")
"""``stats`` fields that come back the same way (graph sizes)."""


def derived_summary(
    problem: Problem, spec: SpecificationProduct, products: Products, cut_edges: np.ndarray, strategy: TestStrategy, bypass_flow: int
) -> dict[str, Any]:
    """The summary fields of :data:`DERIVED_KEYS` (and ``stats`` of :data:`DERIVED_STATS`) of
    a test: what its problem, product graphs, cut edges of G and strategy determine."""
    ts, g = problem.system, products.virtual
    hist = spec.history_name
    w = ts.to_json_state
    cuts = [
        {"from": [w(int(g.state[g.src[e]])), hist(int(g.hist[g.src[e]]))], "to": [w(int(g.state[g.dst[e]])), hist(int(g.hist[g.dst[e]]))]} for e in cut_edges
    ]
    restrictions = {
        hist(q): [[w(int(ts.src[m])), w(int(ts.dst[m]))] for m in np.flatnonzero(strategy.restrictions[q])]
        for q in range(strategy.n_hist)
        if strategy.restrictions[q].any()
    }
    static = [[w(int(ts.src[m])), w(int(ts.dst[m]))] for m in np.flatnonzero(strategy.static_obstacles)]
    counts = physical_counts(ts, strategy)

    def place(p: int) -> object:
        x = ts.places[p]
        return list(x) if isinstance(x, tuple) else x

    return {
        "problem": problem.name,
        "environment": problem.kind,
        "n_walls": len(counts.walls),
        "n_doors": len(counts.doors),
        "n_one_way_walls": len(counts.one_way_walls),
        "physical": {
            key: [[place(a), place(b)] for a, b in pairs]
            for key, pairs in (("walls", counts.walls), ("doors", counts.doors), ("one_way_walls", counts.one_way_walls))
        },
        "cuts": cuts,
        "restrictions": restrictions,
        "static_obstacles": static,
        "bypass_flow": bypass_flow,
        "stats": {
            "transition_system": {"states": ts.n_states, "transitions": ts.n_moves},
            "automaton": {"states": spec.dba.n_states, "transitions": spec.dba.n_transitions},
            "graph": {"nodes": g.n_nodes, "edges": g.n_edges},
            "system_graph": {"nodes": products.system.n_nodes, "edges": products.system.n_edges},
        },
        "histories": {hist(h): spec.describe(h) for h in range(spec.dba.n_states)},
    }


def summary_of(test: SynthesizedTest) -> dict[str, Any]:
    """The problem-format.md JSON object of a :class:`~synthesis.synthesized_test.SynthesizedTest`.

    Examples
    --------
    >>> from synthesis import load_problem, summary_of, synthesize
    >>> summary = summary_of(synthesize(load_problem("small-reactive")))
    >>> summary["status"], summary["flow"], summary["n_cuts"], summary["n_doors"], summary["bypass_flow"]
    ('optimal', 2, 4, 3, 0)
    """
    p, spec, prods, r = test.problem, test.spec, test.products, test.routing
    d = derived_summary(p, spec, prods, r.cut_edges, test.strategy, test.checks.bypass_flow)
    stats = dict(r.stats)
    out: dict[str, Any] = {
        "problem": d["problem"],
        "environment": d["environment"],
        "status": r.status,
        "stopped_by": stats.pop("stopped_by", None),
        "deterministic": stats.pop("deterministic", False),
        "flow": r.flow,
        "n_walls": d["n_walls"],
        "n_doors": d["n_doors"],
        "n_one_way_walls": d["n_one_way_walls"],
        "n_cuts": int(r.cut_edges.size),
        "physical": d["physical"],
        "cuts": d["cuts"],
        "restrictions": d["restrictions"],
        "static_obstacles": d["static_obstacles"],
        "bypass_flow": d["bypass_flow"],
        "stats": {
            **d["stats"],
            "binary_vars": stats.pop("binary_vars"),
            "continuous_vars": stats.pop("continuous_vars"),
            "constraints": stats.pop("constraints"),
            "graph_seconds": test.graph_seconds,
            "solve_seconds": stats.pop("solve_seconds"),
            "mip_gap": stats.pop("mip_gap"),
            "model_seconds": stats.pop("graph_seconds"),
            **stats,
            **test.extra_stats,
        },
        "histories": d["histories"],
    }
    caps = test.caps or dict(p.caps)
    if caps:
        out["caps"] = caps
    if test.agent is not None:
        out.update(test.agent.summary())
    return out


def without_timings(x: Any) -> Any:
    """A JSON value without its timing fields (keys ending in ``_seconds``, ``timings``):
    what stays the same between two runs of one deterministic synthesis."""
    if isinstance(x, dict):
        return {k: without_timings(v) for k, v in x.items() if not k.endswith("_seconds") and k != "timings"}
    if isinstance(x, list):
        return [without_timings(v) for v in x]
    return x


def stop_note(summary: dict[str, Any]) -> str:
    """What a person should know after the status: what stopped a solve short of its
    proof, and whether the answer would be the same on another machine ("" if nothing)."""
    stopped = summary.get("stopped_by")
    if stopped == "time_limit":
        return "; time limit reached: the answer depends on this machine's speed and load"
    if stopped == "node_limit":
        return "; node limit reached (deterministic)"
    if stopped == "work_limit":
        return "; work limit reached (deterministic)"
    if not summary.get("deterministic", True):
        return "; wall-clock budget set: not guaranteed the same on another machine"
    return ""
