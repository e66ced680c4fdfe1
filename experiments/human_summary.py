"""The few lines a person reads after ``flowtest synthesize`` (without ``--json``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from synthesis.artifacts.summary import stop_note
from synthesis.problems.diagnose import implied
from synthesis.routing.caps.messages import caps_text


def _state_text(ts: Any, s: int) -> str:
    """A state as people write it: ``(r,c)``, ``(r,c)@fuel`` or the state's name."""
    key = ts.states[s]
    if ts.kind == "grid":
        return f"({key[0]},{key[1]})"
    if ts.kind == "fuel":
        (r, c), f = key
        return f"({r},{c})@{f}"
    return str(key)


def _place_text(ts: Any, p: int) -> str:
    place = ts.places[p]
    if isinstance(place, tuple) and len(place) == 2:
        return f"({place[0]},{place[1]})"
    return str(place)


def _limited(items: Sequence[str], limit: int = 10) -> str:
    if len(items) <= limit:
        return ", ".join(items)
    return ", ".join(items[:limit]) + f", ... ({len(items) - limit} more)"


def _moves_text(ts: Any, mask: np.ndarray) -> list[str]:
    """Restricted moves as ``a -> b``, one per move (fuel levels kept apart)."""
    return [f"{_state_text(ts, int(ts.src[m]))} -> {_state_text(ts, int(ts.dst[m]))}" for m in np.flatnonzero(mask)]


def _walls_text(ts: Any, mask: np.ndarray) -> list[str]:
    """Blocked moves merged by place: ``a | b`` when both directions are blocked."""
    pairs = {(int(ts.place[ts.src[m]]), int(ts.place[ts.dst[m]])) for m in np.flatnonzero(mask)}
    out: list[str] = []
    for a, b in sorted(pairs, key=lambda ab: (str(ts.places[ab[0]]), str(ts.places[ab[1]]))):
        if (b, a) in pairs:
            if str(ts.places[a]) < str(ts.places[b]):
                out.append(f"{_place_text(ts, a)} | {_place_text(ts, b)}")
        else:
            out.append(f"{_place_text(ts, a)} -> {_place_text(ts, b)}")
    return out


def _uses(summary: dict[str, Any]) -> str:
    """``"2 walls, 1 door (caps: at most 3 doors)"``: the physical restrictions first."""
    walls, doors = summary.get("n_walls", 0), summary.get("n_doors", 0)
    text = f"{walls} wall{'s' if walls != 1 else ''}, {doors} door{'s' if doors != 1 else ''}"
    caps = summary.get("caps")
    if caps:
        text += f" (caps: {caps_text(caps)})"
    return text


def _pair_text(ts: Any, a: Any, b: Any) -> str:
    """Two places of the JSON summary as people write them: ``(r,c) | (r,c)``."""

    def one(p: Any) -> str:
        return f"({p[0]},{p[1]})" if isinstance(p, list) and len(p) == 2 else str(p)

    return f"{one(a)} | {one(b)}"


def human_summary(test: Any, summary: dict[str, Any]) -> str:
    """A few lines a person reads after ``flowtest synthesize`` (without ``--json``)."""
    p, ts, strategy = test.problem, test.problem.system, test.strategy
    stats = summary["stats"]
    gap = stats.get("mip_gap")
    if summary["status"] == "optimal":
        status = "optimal (proven, gap 0)"
    else:
        status = f"{summary['status']} ({'no bound yet' if gap is None else f'gap {gap:.2%}'})"
    lines = [
        f"{p.name}: {p.kind} test, {status}{stop_note(summary)}",
        f"  objectives   system: {p.system_objective.text}   test: {p.test_objective.text}",
        f"  flow         {summary['flow']} (edge-disjoint ways through the test)",
        f"  uses         {_uses(summary)}",
        f"  cuts         {summary['n_cuts']} edges of the product graph (the walls and doors above, per history"
        f"{' and fuel level' if ts.kind == 'fuel' else ''})",
    ]
    one_way = summary.get("physical", {}).get("one_way_walls", [])
    if one_way:
        lines.append(
            f"  one-way      {len(one_way)} wall(s) block one way only (a move back stays open): {_limited([_pair_text(ts, a, b) for a, b in one_way])}"
        )
    reactive = strategy.restrictions & ~strategy.static_obstacles[None, :]
    histories = [q for q in range(strategy.n_hist) if reactive[q].any()]
    if histories:
        lines.append("  restrictions by history (moves the test blocks while the history holds):")
        for q in histories:
            lines.append(f"    {test.spec.history_name(q)} [{test.spec.describe(q)}]: {_limited(_moves_text(ts, reactive[q]))}")
    elif p.kind != "static":
        lines.append("  restrictions none")
    walls = _walls_text(ts, strategy.static_obstacles)
    lines.append(f"  static walls {_limited(walls) if walls else 'none'}")
    if test.agent is not None and "counterexamples" in summary:
        lines.append(f"  test agent   {summary['counterexamples']} counterexample(s)")
    graph = stats["graph"]
    lines.append(
        f"  model        graph {graph['nodes']} nodes / {graph['edges']} edges; MILP {stats['binary_vars']} binary, "
        f"{stats['continuous_vars']} continuous, {stats['constraints']} constraints"
    )
    if "backend" in stats:
        packages = {
            "highs": "HiGHS, highspy",
            "cpsat": "OR-Tools CP-SAT, ortools",
        }
        package = packages.get(stats["backend"], stats["backend"])
        lines.append(f"  solver       {stats['backend']} ({package} {stats.get('solver_version', '?')})")
    gap_text = "" if summary["status"] == "optimal" or gap is None else f", gap {gap:.2%}"
    loop = stats.get("agent_seconds")
    if loop:  # the counterexample-guided loop: many MILP solves, GR(1) games, the closed-loop check
        n = summary.get("agent_strategy", {}).get("iterations", len(getattr(test.agent, "iterations", ())))
        lines.append(
            f"  time         graphs {loop['graphs']:.2f} s, agent loop {loop['total'] - loop['graphs']:.2f} s "
            f"({n} MILP solve(s) {loop['milp']:.2f} s, games and GR(1) {loop['game'] + loop['gr1']:.2f} s, checks "
            f"{loop['verify']:.2f} s){gap_text}; total {loop['total']:.2f} s"
        )
    else:
        lines.append(f"  time         graphs {stats['graph_seconds']:.2f} s, solve {stats['solve_seconds']:.2f} s{gap_text}")
    lines.append(f"  check        bypass flow {summary['bypass_flow']} (must be 0), feasibility flows ok")
    if implied(test.products):
        lines.append(
            f"  note         the system objective `{p.system_objective.text}` already implies the test objective "
            f"`{p.test_objective.text}`: every correct system passes this test, which needs no restriction; "
            "ask the test for something the system objective does not"
        )
    return "\n".join(lines)
