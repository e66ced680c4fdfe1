"""The JSON summary of a synthesized test: the contract of ``flowtest synthesize --json``."""

from __future__ import annotations

from typing import Any

import numpy as np


def summary_of(test: Any) -> dict:
    """The problem-format.md JSON object of a :class:`~synthesis.pipeline.SynthesizedTest`."""
    p, spec, prods, r = test.problem, test.spec, test.products, test.routing
    ts, g = p.system, prods.virtual
    hist = spec.history_name
    w = ts.to_json_state
    cuts = [
        {"from": [w(int(g.state[g.src[e]])), hist(int(g.hist[g.src[e]]))], "to": [w(int(g.state[g.dst[e]])), hist(int(g.hist[g.dst[e]]))]}
        for e in r.cut_edges
    ]
    restrictions = {
        hist(q): [[w(int(ts.src[m])), w(int(ts.dst[m]))] for m in np.flatnonzero(test.strategy.restrictions[q])]
        for q in range(test.strategy.n_hist)
        if test.strategy.restrictions[q].any()
    }
    static = [[w(int(ts.src[m])), w(int(ts.dst[m]))] for m in np.flatnonzero(test.strategy.static_obstacles)]
    stats = dict(r.stats)
    out: dict = {
        "problem": p.name,
        "environment": p.kind,
        "status": r.status,
        "stopped_by": stats.pop("stopped_by", None),
        "deterministic": stats.pop("deterministic", False),
        "flow": r.flow,
        "n_cuts": int(r.cut_edges.size),
        "cuts": cuts,
        "restrictions": restrictions,
        "static_obstacles": static,
        "bypass_flow": test.checks.bypass_flow,
        "stats": {
            "transition_system": {"states": ts.n_states, "transitions": ts.n_moves},
            "automaton": {"states": spec.dba.n_states, "transitions": spec.dba.n_transitions},
            "graph": {"nodes": g.n_nodes, "edges": g.n_edges},
            "system_graph": {"nodes": prods.system.n_nodes, "edges": prods.system.n_edges},
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
        "histories": {hist(h): spec.describe(h) for h in range(spec.dba.n_states)},
    }
    if test.agent is not None:
        out.update(test.agent.summary())
    return out


def stop_note(summary: dict) -> str:
    """What a person should know after the status: what stopped a solve short of its
    proof, and whether the answer would be the same on another machine ("" if nothing)."""
    stopped = summary.get("stopped_by")
    if stopped == "time_limit":
        return "; time limit reached: the answer depends on this machine's speed and load"
    if stopped == "node_limit":
        return "; node limit reached (deterministic)"
    if not summary.get("deterministic", True):
        return "; wall-clock budget set: not guaranteed the same on another machine"
    return ""
